"""Reads ``experiment.*`` of ``experiment=reconfig_motion`` into :class:`ReconfigMotionSettings`: the R drive limits,
the reconfiguration mechanism (its fields: :data:`MECHANISM_FIELDS`), the spline refinement and each case's cycle.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping, Optional

import jax.numpy as jnp

from ..geometry import GeometryError, ReconfigurableDelta
from .readers import check_fits, ConfigError, read_choice, read_settings, read_vector, setting
from ..indices import INDEX_NAMES
from ..motion import AGGREGATES, BOUNDARIES, RDriveLimits
from ..mechanism import DirectRadial, example_screw_linkage, MECHANISMS
from ..trajectory import MOTION_LAWS
from .. import trajectory as tr

__all__ = ["MECHANISM_FIELDS", "ReconfigMotionSettings", "reconfig_motion_spec", "DriveBlock", "MechanismBlock",
           "RefineBlock", "AdeptCaseBlock", "TaskCaseBlock"]


def _index_names():
    return INDEX_NAMES


def _aggregates():
    return AGGREGATES


def _boundaries():
    return BOUNDARIES


def _mechanisms():
    return MECHANISMS


def _motion_laws():
    return MOTION_LAWS


def _sign(path: str, v: Any) -> int:
    if isinstance(v, bool) or v not in (1, -1):
        raise ConfigError(f"{path} must be one of 1, -1, got {v!r}")
    return int(v)


@dataclasses.dataclass(frozen=True, kw_only=True)
class DriveBlock:
    """``experiment.drive``: the limits of the R drive at the R joint (:class:`deltajax.RDriveLimits`)."""
    speed: float = setting(lo=0, lo_open=True, unit="m/s")
    acceleration: float = setting(lo=0, lo_open=True, unit="m/s^2")
    force: float = setting(lo=0, lo_open=True, unit="N")


def _drive(path: str, v: Any):
    return RDriveLimits(**dataclasses.asdict(read_settings(DriveBlock, v, path)))


@dataclasses.dataclass(frozen=True, kw_only=True)
class MechanismBlock:
    """``experiment.mechanism``: the reconfiguration mechanism's kind and the arguments of
    :func:`deltajax.mechanism.example_screw_linkage` / :class:`deltajax.mechanism.DirectRadial` it sets, in the
    units the config writes them in (``lead`` in m per screw turn; the linkage stores a pitch in m/rad). Unset
    (None): the mechanism's own default."""
    kind: str = setting("screw_linkage", choices=_mechanisms)
    lead: Optional[float] = setting(None, lo=0, lo_open=True, unit="m")
    d2: Optional[float] = setting(None, lo=0, lo_open=True, unit="m")
    d3: Optional[float] = setting(None, unit="m")
    sweep_deg: Optional[float] = setting(None, lo=0, hi=90, lo_open=True, hi_open=True, unit="deg")
    efficiency: Optional[float] = setting(None, lo=0, hi=1, lo_open=True)
    back_efficiency: Optional[float] = setting(None, lo=0, hi=1, lo_open=True)
    gear_ratio: Optional[float] = setting(None, lo=0, lo_open=True)
    assembly: Optional[int] = setting(None, read=_sign)
    nut_side: Optional[int] = setting(None, read=_sign)

    def kwargs(self) -> dict:
        """The arguments set (the mechanism's keyword arguments)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if f.name != "kind" and getattr(self, f.name) is not None}


def _mechanism(path: str, v: Any) -> MechanismBlock:
    return MechanismBlock() if v is None else read_settings(MechanismBlock, v, path)


#: the settings of experiment.mechanism besides its kind (:class:`MechanismBlock`, whose metadata checks them)
MECHANISM_FIELDS = tuple(f.name for f in dataclasses.fields(MechanismBlock) if f.name != "kind")


@dataclasses.dataclass(frozen=True, kw_only=True)
class RefineBlock:
    """``experiment.refine``: the optax spline refinement of the DP's R(t) (learning rate in m per Adam step)."""
    enabled: bool = setting(True)
    n_ctrl: int = setting(16, lo=6)
    steps: int = setting(150, lo=1)
    learning_rate: float = setting(2e-4, lo=0, lo_open=True)


@dataclasses.dataclass(frozen=True, kw_only=True)
class AdeptCaseBlock:
    """``experiment.cases.<name>`` of ``kind: adept``: the standard 25/305/25 mm cycle (centre m, z down; heading
    deg; duration s), its blend, motion law and samples, and the DP's boundary condition."""
    kind: str = setting(choices=("adept", "task"))
    centre: list = setting(read=lambda path, v: read_vector(path, v, 3))
    heading_deg: float = setting(unit="deg")
    duration: float = setting(lo=0, lo_open=True, unit="s")
    blend: float = setting(0.5, lo=0, hi=1, hi_open=True)
    law: str = setting("poly5", choices=_motion_laws)
    n_samples: int = setting(lo=3)
    boundary: str = setting("free", choices=_boundaries)

    def samples(self) -> int:
        return self.n_samples


def _points(path: str, v: Any) -> list:
    return [read_vector(f"{path}[{i}]", q, 3) for i, q in enumerate(v or [])]


@dataclasses.dataclass(frozen=True, kw_only=True)
class TaskCaseBlock:
    """``experiment.cases.<name>`` of ``kind: task``: rest-to-rest moves through task points (m, z down), each
    segment's duration (s), samples and motion law, open or closed, and the DP's boundary condition."""
    kind: str = setting(choices=("adept", "task"))
    points: list = setting([], read=_points)
    segment_duration: float = setting(lo=0, lo_open=True, unit="s")
    samples_per_segment: int = setting(lo=2)
    law: str = setting("poly5", choices=_motion_laws)
    boundary: str = setting("free", choices=_boundaries)
    closed: bool = setting(False)

    def samples(self) -> int:
        return self.samples_per_segment * max(1, len(self.points))


def _cases(path: str, v: Any) -> dict:
    if not isinstance(v, Mapping) or not v:
        raise ConfigError(f"{path} must list at least one case")
    out = {}
    for name, c in v.items():
        p = f"{path}.{name}"
        kind = read_choice(f"{p}.kind", c.get("kind") if isinstance(c, Mapping) else None, ("adept", "task"))
        out[str(name)] = read_settings(AdeptCaseBlock if kind == "adept" else TaskCaseBlock, c, p)
    return out


@dataclasses.dataclass(frozen=True, kw_only=True)
class ReconfigMotionSettings:
    """``experiment=reconfig_motion``: the selection criterion and aggregate, the k~ parameters, the R step (m),
    the R drive limits (``drive``: :class:`deltajax.RDriveLimits`), the arms' torque (N m) and speed (rad/s)
    limits, the reconfiguration mechanism's settings, the spline refinement and the cases. Derived by
    :func:`reconfig_motion_spec` from the robot: its R samples at ``R_step`` (``recon``), the mechanism (``mech``,
    and its range check ``mech_info``) and each case's (Cartesian cycle, boundary condition) (``cycles``)."""

    name: str = setting("reconfig_motion")
    criterion: str = setting("k_tilde", choices=_index_names)
    aggregate: str = setting("integral", choices=_aggregates)
    b_v: float = setting(lo=0, lo_open=True)
    b_f: float = setting(lo=0, lo_open=True)
    beta: float = setting(0.5, lo=0, hi=1, lo_open=True, hi_open=True)
    R_step: float = setting(lo=0, lo_open=True, unit="m")
    drive: Any = setting(read=_drive)
    torque_limit: float = setting(lo=0, lo_open=True, unit="N m")
    speed_limit: float = setting(lo=0, lo_open=True, unit="rad/s")
    # read by its own reader so that its structured config holds the keys written (each unset one: the default)
    mechanism: MechanismBlock = setting(MechanismBlock(), read=_mechanism)
    refine: RefineBlock = setting(RefineBlock())
    cases: dict = setting(read=_cases)
    # derived (from the robot): see the docstring
    recon: Any = None
    mech: Any = None
    mech_info: Optional[dict] = None
    cycles: Optional[dict] = None


def reconfig_motion_spec(e, cfg=None, robot=None, recon=None, dtype=None) -> ReconfigMotionSettings:
    """``experiment.*`` of reconfig_motion (:class:`ReconfigMotionSettings`), with what needs the robot: its R
    samples at ``R_step``, the mechanism over its R range, each case's Cartesian cycle (``dtype``) and the DP's
    memory."""
    if recon is None:
        raise ConfigError("experiment=reconfig_motion needs a reconfigurable robot: robot.R_range is null")
    if recon.robot.mass is None:
        raise ConfigError("experiment=reconfig_motion needs a mass model: robot.mass is null")
    s = read_settings(ReconfigMotionSettings, e, "experiment")
    try:  # the DP's R samples: the robot's range at experiment.R_step
        R = ReconfigurableDelta.from_range(recon.robot, float(recon.R_min), float(recon.R_max), s.R_step)
    except GeometryError as err:
        raise ConfigError(f"experiment.R_step={s.R_step!r} m: {err}") from None
    # the DP's table: every R sample at every time sample of a case (3 at least)
    check_fits("experiment.R_step", s.R_step, 3 * 8.0 * R.n_R, f"{R.n_R:.3g} R samples at each time sample",
               unit="m")
    mech, mech_info = None, None
    try:
        if s.mechanism.kind == "direct":
            mech = DirectRadial(**s.mechanism.kwargs())
        else:
            R0, R1 = float(recon.R_min), float(recon.R_max)
            mech = example_screw_linkage(R0, R1, **s.mechanism.kwargs())
            mech_info = mech.check_range(R0, R1)
    except (TypeError, ValueError) as err:
        raise ConfigError(f"experiment.mechanism: {err}") from None
    dtype = jnp.result_type(float) if dtype is None else dtype
    cycles = {}
    for name, c in s.cases.items():
        p = f"experiment.cases.{name}"
        # the cycle's samples (position, velocity, acceleration) and the DP's table over them and the R samples
        key = "n_samples" if c.kind == "adept" else "samples_per_segment"
        n_t = c.samples()
        check_fits(f"{p}.{key}", getattr(c, key), n_t * (72.0 + 8.0 * R.n_R),
                   f"{n_t} cycle samples x {R.n_R} R samples (the DP's table)")
        try:
            if c.kind == "adept":
                cyc = tr.adept_cycle(c.centre, heading=math.radians(c.heading_deg), duration=c.duration, law=c.law,
                                     blend=c.blend, n_samples=c.n_samples, dtype=dtype)
            else:
                cyc = tr.task_path(c.points, segment_duration=c.segment_duration, law=c.law,
                                   samples_per_segment=c.samples_per_segment, closed=c.closed, dtype=dtype)
        except ValueError as err:
            if isinstance(err, ConfigError):
                raise
            raise ConfigError(f"{p}: {err}") from None
        cycles[name] = (cyc, c.boundary)
    return dataclasses.replace(s, recon=R, mech=mech, mech_info=mech_info, cycles=cycles)
