"""Reads ``experiment.*`` of the dynamics jobs:

- :class:`DynamicsCycleSettings` (``experiment=dynamics_cycle``): each analysed robot's cycle setup;
- :class:`DatasheetSettings` (``experiment=datasheet`` and the top-level ``source``): a preset, or a ga_reconfig run
  directory whose design space and motor are rebuilt from its stored config (:func:`source_run`).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Mapping, Optional
import os

from .ga_reconfig_run import ga_reconfig_build
from .readers import ConfigError, check_fits, read_choice, read_field, read_settings, read_vector, setting
from .robot import robot_from_config
from .. import io, presets
from ..trajectory import MOTION_LAWS

__all__ = ["DynamicsCycleSettings", "dynamics_cycle_spec", "DatasheetSettings", "source_run", "datasheet_settings",
           "CycleSetupBlock", "GaMotionBlock", "DatasheetMotorBlock"]


def _presets():
    return presets.PRESETS


def _motion_laws():
    return MOTION_LAWS


def _centre(path: str, v: Any) -> list:
    return read_vector(path, v, 3)


def _preset_names(path: str, v: Any) -> tuple:
    return tuple(read_choice(f"{path} entry", name, _presets()) for name in (v or []))


@dataclasses.dataclass(frozen=True, kw_only=True)
class CycleSetupBlock:
    """``experiment.setups.<robot>``: where the standard cycle sits (centre, m, z down), its heading (deg), its
    nominal duration (s) and the arm-side actuator limits (N m, rad/s)."""
    centre: list = setting(read=_centre)
    heading_deg: float = setting(0.0, unit="deg")
    duration: float = setting(lo=0, lo_open=True, unit="s")
    torque_limit: float = setting(lo=0, lo_open=True, unit="N m")
    speed_limit: float = setting(lo=0, lo_open=True, unit="rad/s")


def _setups(path: str, v: Any) -> dict:
    if not isinstance(v, Mapping):
        raise ConfigError(f"{path} must be a mapping of robot name (or default) -> cycle setup, got {v!r}")
    return {str(k): read_settings(CycleSetupBlock, b, f"{path}.{k}") for k, b in v.items()}


@dataclasses.dataclass(frozen=True, kw_only=True)
class GaMotionBlock:
    """``experiment.ga_motion``: the GA paper's test motion, its amplitude (rad) and duration (s)."""
    amplitude: float = setting(lo=0, lo_open=True, unit="rad")
    duration: float = setting(lo=0, lo_open=True, unit="s")


@dataclasses.dataclass(frozen=True, kw_only=True)
class DynamicsCycleSettings:
    """``experiment=dynamics_cycle``: the presets analysed besides the config robot (named ``cfg_name``, derived
    from ``robot.name``), the inverse-dynamics formulation, cycle samples, motion law and blend, each robot's cycle
    setup (:meth:`setup`: its own block or ``default``), the GA paper's motion (rad, s), the moving-R amplitude
    (m)."""

    name: str = setting("dynamics_cycle")
    robots: tuple = setting((), read=_preset_names)
    method: str = setting("virtual_work", choices=("virtual_work", "lagrange"))
    n_samples: int = setting(lo=11)
    law: str = setting("poly5", choices=_motion_laws)
    blend: float = setting(lo=0, hi=1, hi_open=True)
    setups: dict = setting({}, read=_setups)
    ga_motion: GaMotionBlock = setting()
    recon_R_amplitude: float = setting(lo=0, unit="m")
    cfg_name: str = "robot"              # derived: the config robot's name (robot.name)

    @property
    def ga_amplitude(self) -> float:
        return self.ga_motion.amplitude

    @property
    def ga_duration(self) -> float:
        return self.ga_motion.duration

    def analysed(self) -> list:
        """The names of the analysed robots, each once: the config robot's, then ``robots``."""
        return list(dict.fromkeys([self.cfg_name, *self.robots]))

    def setup(self, name: str) -> CycleSetupBlock:
        """The cycle setup of the analysed robot ``name``: its own block, else ``default``."""
        return self.setups[name if name in self.setups else "default"]


def dynamics_cycle_spec(e, cfg=None, robot=None, recon=None) -> DynamicsCycleSettings:
    """``experiment.*`` of dynamics_cycle (:class:`DynamicsCycleSettings`), with what needs more than the block:
    the robot's mass model, its name (``cfg_name``), a setup for every analysed robot, the moving R within the
    robot's R range (``recon``) and the cycles' memory."""
    if robot is not None and robot.mass is None:
        raise ConfigError("experiment=dynamics_cycle needs a mass model: add a `mass:` block to the robot config "
                          f"(robot.mass), robot {(cfg or {}).get('robot', {}).get('name')!r} has none")
    s = read_settings(DynamicsCycleSettings, e, "experiment")
    if cfg is not None:
        s = dataclasses.replace(s, cfg_name=str(cfg.get("robot", {}).get("name", "robot")))
    names = s.analysed()
    for name in names:
        if name not in s.setups and "default" not in s.setups:
            raise ConfigError(f"experiment.setups.{name} (or experiment.setups.default) is required")
    amp = s.recon_R_amplitude
    if recon is not None and amp != 0.0:
        R0, lo, hi = float(recon.robot.base_radius), float(recon.R_min), float(recon.R_max)
        if not (lo <= R0 - amp and R0 + amp <= hi + 1e-12):
            raise ConfigError(f"experiment.recon_R_amplitude={amp!r} m takes R = {R0} +- {amp} m outside "
                              f"[{lo}, {hi}] m")
    # positions, velocities and accelerations of every analysed robot's cycle (float64), at least
    check_fits("experiment.n_samples", s.n_samples, 72.0 * s.n_samples * len(names), f"{len(names)} cycles of "
               f"{s.n_samples} samples")
    return s


def _payloads(path: str, v: Any) -> tuple:
    out = tuple(read_field(f"{path}[{i}]", p, lo=0, unit="kg") for i, p in enumerate(v or []))
    if not out:
        raise ConfigError(f"{path} must list at least one payload (kg)")
    return out


def _cylinder_grid(path: str, v: Any) -> tuple:
    grid = list(v or [])
    if len(grid) != 3:
        raise ConfigError(f"{path} must be [rings, angles, levels], got {grid!r}")
    return tuple(read_field(f"{path}[{i}]", g, kind="int", lo=2) for i, g in enumerate(grid))


def _point(path: str, v: Any) -> tuple:
    return tuple(read_vector(path, v, 3))


@dataclasses.dataclass(frozen=True, kw_only=True)
class DatasheetMotorBlock:
    """``experiment.motor`` of the datasheet (a preset source's drive, motor side): the keyword arguments of
    :class:`deltajax.Motor` (:meth:`kwargs`)."""
    peak_torque: float = setting(lo=0, lo_open=True, unit="N m")
    rated_torque: float = setting(lo=0, lo_open=True, unit="N m")
    max_speed: float = setting(lo=0, lo_open=True, unit="rad/s")
    corner_speed: float = setting(lo=0, lo_open=True, unit="rad/s")
    rotor_inertia: float = setting(0.0, lo=0, unit="kg m^2")
    efficiency: float = setting(1.0, lo=0, lo_open=True, hi=1)

    def kwargs(self) -> dict:
        return dataclasses.asdict(self)

    def _check(self, path: str) -> None:
        for lo_k, hi_k, unit in (("rated_torque", "peak_torque", "N m"), ("corner_speed", "max_speed", "rad/s")):
            if getattr(self, lo_k) > getattr(self, hi_k):
                raise ConfigError(f"{path}.{lo_k}={getattr(self, lo_k)!r} {unit} must be <= {path}.{hi_k}="
                                  f"{getattr(self, hi_k)!r} {unit}")


@dataclasses.dataclass(frozen=True, kw_only=True)
class DatasheetSettings:
    """``experiment=datasheet`` (kg, s, m, N m, rad/s) and, derived, the top-level ``source`` with its ``kind``
    ("preset" or "run_dir") and, for a run directory, its design space and motor settings."""

    name: str = setting("datasheet")
    payloads: tuple = setting(read=_payloads)
    vendor_dwell: float = setting(lo=0, unit="s")
    hd_ratio: float = setting(lo=0, lo_open=True, unit="1")
    volume_h: float = setting(lo=0, lo_open=True, unit="m")
    n_samples: int = setting(lo=3)
    cylinder_grid: tuple = setting(read=_cylinder_grid)
    centre: Optional[tuple] = setting(None, read=_point)
    R: Optional[float] = setting(None, lo=0, lo_open=True, unit="m")
    motor: DatasheetMotorBlock = setting()
    gear_ratio: float = setting(lo=0, lo_open=True, unit="motor speed / arm speed")
    # derived: the top-level source (a preset name or an absolute run directory) and what it brings
    source: str = ""
    kind: str = ""
    source_space: Any = None            # kind "run_dir": the source run's design space, rebuilt from its settings
    source_motor: Optional[dict] = None  # kind "run_dir": the source run's motor settings


def source_run(src: str) -> tuple:
    """(design space, motor settings) of the ga_reconfig run in directory ``src`` (its stored config rebuilt)."""
    import yaml

    try:
        attrs = io.read(os.path.join(src, "results.h5"), max_elements=0).attrs
        cfg = yaml.safe_load(attrs["config"])
    except (OSError, KeyError, ValueError, yaml.YAMLError) as err:
        raise ConfigError(f"source={src!r}: its results.h5 cannot be read as a run ({type(err).__name__}: "
                          f"{err})") from None
    if not isinstance(cfg, Mapping) or (cfg.get("experiment") or {}).get("name") != "ga_reconfig":
        name = (cfg.get("experiment") or {}).get("name") if isinstance(cfg, Mapping) else None
        raise ConfigError(f"source={src!r} is a {name!r} run, not ga_reconfig")
    robot, recon = robot_from_config(cfg["robot"])
    s, space = ga_reconfig_build(cfg["experiment"], robot, recon)[:2]
    return space, dataclasses.asdict(s.motor)


def datasheet_settings(e, cfg=None, robot=None, recon=None) -> DatasheetSettings:
    """``experiment.*`` and the top-level ``source`` of the datasheet job (kg, s, m, N m, rad/s).

    ``source``: a :data:`deltajax.presets.PRESETS` name (with ``experiment.motor`` and ``experiment.gear_ratio``) or
    a ga_reconfig run directory (its baseline and recommended designs with the run's own motor and gear ratios).
    """
    src = (cfg or {}).get("source")
    if src is None or str(src) == "":
        raise ConfigError("source is required: a preset name (" + ", ".join(sorted(presets.PRESETS))
                          + ") or a ga_reconfig run directory (containing results.h5)")
    src = str(src)
    if src in presets.PRESETS:
        kind = "preset"
    elif os.path.isfile(os.path.join(os.path.expanduser(src), "results.h5")):
        kind = "run_dir"
        src = os.path.abspath(os.path.expanduser(src))
    else:
        raise ConfigError(f"source={src!r} is neither a preset ({', '.join(sorted(presets.PRESETS))}) nor a run "
                          "directory with a results.h5")
    s = read_settings(DatasheetSettings, e, "experiment")
    return dataclasses.replace(s, source=src, kind=kind, **(
        dict(zip(("source_space", "source_motor"), source_run(src))) if kind == "run_dir" else {}))
