"""Reads ``experiment.*`` of ``experiment=reconfig_motion`` into :class:`ReconfigMotionSettings`: the R drive limits,
the reconfiguration mechanism (its fields: :data:`MECHANISM_FIELDS`), the spline refinement and each case's cycle.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Optional

from ..geometry import GeometryError, ReconfigurableDelta
from .readers import ConfigError, check_fits, read_choice, read_field, read_vector

__all__ = ["MECHANISM_FIELDS", "ReconfigMotionSettings", "reconfig_motion_spec"]


#: the numeric settings of experiment.mechanism (deltajax.mechanism.example_screw_linkage / DirectRadial), with the
#: ranges the mechanism needs, checked in the units the config writes them in
MECHANISM_FIELDS = {
    "lead": dict(lo=0, lo_open=True, unit="m"), "d2": dict(lo=0, lo_open=True, unit="m"), "d3": dict(unit="m"),
    "sweep_deg": dict(lo=0, hi=90, lo_open=True, hi_open=True, unit="deg"),
    "efficiency": dict(lo=0, hi=1, lo_open=True), "back_efficiency": dict(lo=0, hi=1, lo_open=True),
    "gear_ratio": dict(lo=0, lo_open=True), "assembly": dict(kind="int", choices=(1, -1)),
    "nut_side": dict(kind="int", choices=(1, -1)),
}


@dataclasses.dataclass(frozen=True)
class ReconfigMotionSettings:
    """``experiment=reconfig_motion``: the selection criterion and aggregate, the k~ parameters, the R step (m) and
    the robot's R samples at it (``recon``), the arms' torque (N m) and speed (rad/s) limits, the R drive limits
    (:class:`deltajax.RDriveLimits`), the reconfiguration mechanism (and its range check), the spline
    refinement, and each case's (Cartesian cycle, boundary condition)."""

    criterion: str
    aggregate: str
    b_v: float
    b_f: float
    R_step: float
    torque_limit: float
    speed_limit: float
    beta: float
    drive: Any
    recon: Any
    mech: Any
    refine: dict
    cases: dict
    mech_info: Optional[dict] = None


def reconfig_motion_spec(e, cfg=None, robot=None, recon=None, dtype=None) -> ReconfigMotionSettings:
    """``experiment.*`` of reconfig_motion as plain values and library objects: the R drive limits
    (:class:`deltajax.RDriveLimits`), the reconfiguration mechanism, and each case's Cartesian cycle."""
    import jax.numpy as jnp

    from .. import trajectory as tr
    from ..indices import INDEX_NAMES
    from ..mechanism import MECHANISMS, DirectRadial, example_screw_linkage
    from ..motion import AGGREGATES, BOUNDARIES, RDriveLimits

    if recon is None:
        raise ConfigError("experiment=reconfig_motion needs a reconfigurable robot: robot.R_range is null")
    if recon.robot.mass is None:
        raise ConfigError("experiment=reconfig_motion needs a mass model: robot.mass is null")
    pos = lambda k, unit="": read_field(f"experiment.{k}", e.get(k), lo=0, lo_open=True, unit=unit)  # noqa: E731
    out = dict(criterion=read_choice("experiment.criterion", e.get("criterion", "k_tilde"), INDEX_NAMES),
               aggregate=read_choice("experiment.aggregate", e.get("aggregate", "integral"), AGGREGATES),
               b_v=pos("b_v"), b_f=pos("b_f"), R_step=pos("R_step", "m"), torque_limit=pos("torque_limit", "N m"),
               speed_limit=pos("speed_limit", "rad/s"),
               beta=read_field("experiment.beta", e.get("beta", 0.5), lo=0, hi=1, lo_open=True, hi_open=True))
    d = e.get("drive")
    if d is None:
        raise ConfigError("experiment.drive is required (speed m/s, acceleration m/s^2, force N)")
    lim = {k: read_field(f"experiment.drive.{k}", d.get(k), lo=0, lo_open=True, unit=unit)
           for k, unit in (("speed", "m/s"), ("acceleration", "m/s^2"), ("force", "N"))}
    out["drive"] = RDriveLimits(**lim)
    try:  # the DP's R samples: the robot's range at experiment.R_step
        out["recon"] = ReconfigurableDelta.from_range(recon.robot, float(recon.R_min), float(recon.R_max),
                                                      out["R_step"])
    except GeometryError as err:
        raise ConfigError(f"experiment.R_step={out['R_step']!r} m: {err}") from None
    # the DP's table: every R sample at every time sample of a case (3 at least)
    check_fits("experiment.R_step", out["R_step"], 3 * 8.0 * out["recon"].n_R,
          f"{out['recon'].n_R:.3g} R samples at each time sample", unit="m")
    mech = dict(e.get("mechanism") or {})
    kind = read_choice("experiment.mechanism.kind", mech.pop("kind", "screw_linkage"), MECHANISMS)
    for k, v in mech.items():  # in the units the config gives them (the linkage stores lead as a pitch in m/rad)
        if k in MECHANISM_FIELDS:
            rule = dict(MECHANISM_FIELDS[k])
            choices = rule.pop("choices", None)
            mech[k] = read_field(f"experiment.mechanism.{k}", v, **rule)
            if choices is not None and mech[k] not in choices:
                raise ConfigError(f"experiment.mechanism.{k} must be one of {', '.join(map(str, choices))}, "
                                  f"got {v!r}")
    try:
        if kind == "direct":
            out["mech"] = DirectRadial(**mech)
        else:
            R0, R1 = float(recon.R_min), float(recon.R_max)
            out["mech"] = example_screw_linkage(R0, R1, **mech)
            out["mech_info"] = out["mech"].check_range(R0, R1)
    except (TypeError, ValueError) as err:
        raise ConfigError(f"experiment.mechanism: {err}") from None
    ref = e.get("refine") or {}
    out["refine"] = dict(enabled=read_field("experiment.refine.enabled", ref.get("enabled", True), kind="bool"),
                         n_ctrl=read_field("experiment.refine.n_ctrl", ref.get("n_ctrl", 16), kind="int", lo=6),
                         steps=read_field("experiment.refine.steps", ref.get("steps", 150), kind="int", lo=1),
                         learning_rate=read_field("experiment.refine.learning_rate", ref.get("learning_rate", 2e-4),
                                              lo=0, lo_open=True))
    cases = e.get("cases")
    if not cases:
        raise ConfigError("experiment.cases must list at least one case")
    dtype = jnp.result_type(float) if dtype is None else dtype
    out["cases"] = {}
    for name, c in cases.items():
        p = f"experiment.cases.{name}"
        kind = read_choice(f"{p}.kind", c.get("kind"), ("adept", "task"))
        boundary = read_choice(f"{p}.boundary", c.get("boundary", "free"), BOUNDARIES)
        law = read_choice(f"{p}.law", c.get("law", "poly5"), tr.MOTION_LAWS)
        # the cycle's samples (position, velocity, acceleration) and the DP's table over them and the R samples
        key = "n_samples" if kind == "adept" else "samples_per_segment"
        per = read_field(f"{p}.{key}", c.get(key), kind="int", lo=3 if kind == "adept" else 2)
        n_t = per * (1 if kind == "adept" else max(1, len(c.get("points") or [])))
        check_fits(f"{p}.{key}", per, n_t * (72.0 + 8.0 * out["recon"].n_R),
              f"{n_t} cycle samples x {out['recon'].n_R} R samples (the DP's table)")
        try:
            if kind == "adept":
                cyc = tr.adept_cycle(read_vector(f"{p}.centre", c.get("centre"), 3),
                                     heading=math.radians(read_field(f"{p}.heading_deg", c.get("heading_deg"), unit="deg")),
                                     duration=read_field(f"{p}.duration", c.get("duration"), lo=0, lo_open=True, unit="s"),
                                     law=law, blend=read_field(f"{p}.blend", c.get("blend", 0.5), lo=0, hi=1, hi_open=True),
                                     n_samples=read_field(f"{p}.n_samples", c.get("n_samples"), kind="int", lo=3),
                                     dtype=dtype)
            else:
                pts = [read_vector(f"{p}.points[{i}]", q, 3) for i, q in enumerate(c.get("points") or [])]
                cyc = tr.task_path(pts, segment_duration=read_field(f"{p}.segment_duration", c.get("segment_duration"),
                                                                lo=0, lo_open=True, unit="s"),
                                   law=law, samples_per_segment=read_field(f"{p}.samples_per_segment",
                                                                       c.get("samples_per_segment"), kind="int", lo=2),
                                   closed=read_field(f"{p}.closed", c.get("closed", False), kind="bool"), dtype=dtype)
        except ValueError as err:
            if isinstance(err, ConfigError):
                raise
            raise ConfigError(f"{p}: {err}") from None
        out["cases"][name] = (cyc, boundary)
    return ReconfigMotionSettings(**out)
