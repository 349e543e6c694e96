"""Reads ``experiment.*`` of the dynamics jobs:

- :class:`DynamicsCycleSettings` (``experiment=dynamics_cycle``): each analysed robot's cycle setup;
- :class:`DatasheetSettings` (``experiment=datasheet`` and the top-level ``source``): a preset, or a ga_reconfig run
  directory whose design space and motor are rebuilt from its stored config (:func:`source_run`).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Mapping, Optional

from .ga_reconfig import ga_reconfig_build
from .readers import ConfigError, check_fits, read_choice, read_field, read_vector
from .robot import robot_from_config

__all__ = ["DynamicsCycleSettings", "dynamics_cycle_spec", "DatasheetSettings", "source_run", "datasheet_settings"]


def _cycle_setup(s, path: str) -> dict:
    out = dict(centre=read_vector(f"{path}.centre", s.get("centre"), 3),
               heading_deg=read_field(f"{path}.heading_deg", s.get("heading_deg"), unit="deg"))
    for k, unit in (("duration", "s"), ("torque_limit", "N m"), ("speed_limit", "rad/s")):
        out[k] = read_field(f"{path}.{k}", s.get(k), lo=0, lo_open=True, unit=unit)
    return out


@dataclasses.dataclass(frozen=True)
class DynamicsCycleSettings:
    """``experiment=dynamics_cycle``: the inverse-dynamics formulation, cycle samples, motion law and blend, the
    presets analysed besides the config robot (named ``cfg_name``), each robot's cycle setup (centre m, heading
    deg, duration s, torque N m and speed rad/s limits), the GA paper's motion (rad, s), the moving-R amplitude (m)."""

    method: str
    n_samples: int
    law: str
    blend: float
    robots: tuple
    cfg_name: str
    setups: dict
    ga_amplitude: float
    ga_duration: float
    recon_R_amplitude: float


def dynamics_cycle_spec(e, cfg=None, robot=None, recon=None) -> DynamicsCycleSettings:
    """``experiment.*`` of dynamics_cycle; ``setups`` holds one entry per analysed robot name (its own block or
    ``default``), the config robot's under ``cfg_name``."""
    from .. import presets
    from ..trajectory import MOTION_LAWS

    if robot is not None and robot.mass is None:
        raise ConfigError("experiment=dynamics_cycle needs a mass model: add a `mass:` block to the robot config "
                          f"(robot.mass), robot {(cfg or {}).get('robot', {}).get('name')!r} has none")
    robots = list(e.get("robots") or [])
    for name in robots:
        read_choice("experiment.robots entry", name, presets.PRESETS)
    cfg_name = "robot" if cfg is None else str(cfg.get("robot", {}).get("name", "robot"))
    blocks = e.get("setups") or {}
    setups = {}
    for name in [cfg_name] + robots:
        key = name if name in blocks else "default"
        if key not in blocks:
            raise ConfigError(f"experiment.setups.{name} (or experiment.setups.default) is required")
        setups[name] = _cycle_setup(blocks.get(key), f"experiment.setups.{key}")
    gm = e.get("ga_motion") or {}
    amp = read_field("experiment.recon_R_amplitude", e.get("recon_R_amplitude"), lo=0, unit="m")
    if recon is not None and amp != 0.0:
        R0, lo, hi = float(recon.robot.base_radius), float(recon.R_min), float(recon.R_max)
        if not (lo <= R0 - amp and R0 + amp <= hi + 1e-12):
            raise ConfigError(f"experiment.recon_R_amplitude={amp!r} m takes R = {R0} +- {amp} m outside "
                              f"[{lo}, {hi}] m")
    n_samples = read_field("experiment.n_samples", e.get("n_samples"), kind="int", lo=11)
    # positions, velocities and accelerations of every analysed robot's cycle (float64), at least
    check_fits("experiment.n_samples", n_samples, 72.0 * n_samples * len(setups), f"{len(setups)} cycles of "
          f"{n_samples} samples")
    return DynamicsCycleSettings(
                method=read_choice("experiment.method", e.get("method"), ("virtual_work", "lagrange")),
                n_samples=n_samples,
                law=read_choice("experiment.law", e.get("law"), MOTION_LAWS),
                blend=read_field("experiment.blend", e.get("blend"), lo=0, hi=1, hi_open=True),
                robots=tuple(robots), cfg_name=cfg_name, setups=setups,
                ga_amplitude=read_field("experiment.ga_motion.amplitude", gm.get("amplitude"), lo=0, lo_open=True,
                                    unit="rad"),
                ga_duration=read_field("experiment.ga_motion.duration", gm.get("duration"), lo=0, lo_open=True, unit="s"),
                recon_R_amplitude=amp)


@dataclasses.dataclass(frozen=True)
class DatasheetSettings:
    """``experiment=datasheet`` and the top-level ``source`` (kg, s, m, N m, rad/s); ``kind``: "preset" or
    "run_dir"."""

    source: str
    kind: str
    payloads: tuple
    vendor_dwell: float
    hd_ratio: float
    volume_h: float
    n_samples: int
    cylinder_grid: tuple
    centre: Optional[tuple]
    R: Optional[float]
    motor: dict
    gear_ratio: float
    source_space: Any = None            # kind "run_dir": the source run's design space, rebuilt from its settings
    source_motor: Optional[dict] = None  # kind "run_dir": the source run's motor settings


def source_run(src: str) -> tuple:
    """(design space, motor settings) of the ga_reconfig run in directory ``src`` (its stored config rebuilt)."""
    import os

    import yaml

    from .. import io

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
    import os

    from .. import presets

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
    pos = lambda k, unit: read_field(f"experiment.{k}", e.get(k), lo=0, lo_open=True, unit=unit)  # noqa: E731
    payloads = [read_field(f"experiment.payloads[{i}]", p, lo=0, unit="kg") for i, p in enumerate(e.get("payloads") or [])]
    if not payloads:
        raise ConfigError("experiment.payloads must list at least one payload (kg)")
    grid = e.get("cylinder_grid") or []
    if len(grid) != 3:
        raise ConfigError(f"experiment.cylinder_grid must be [rings, angles, levels], got {list(grid)!r}")
    mcfg = e.get("motor") or {}
    motor = {k: read_field(f"experiment.motor.{k}", mcfg.get(k), lo=0, lo_open=(k != "rotor_inertia"), unit=u)
             for k, u in (("peak_torque", "N m"), ("rated_torque", "N m"), ("max_speed", "rad/s"),
                          ("corner_speed", "rad/s"), ("rotor_inertia", "kg m^2"), ("efficiency", "1"))}
    for lo_k, hi_k, unit in (("rated_torque", "peak_torque", "N m"), ("corner_speed", "max_speed", "rad/s")):
        if motor[lo_k] > motor[hi_k]:
            raise ConfigError(f"experiment.motor.{lo_k}={motor[lo_k]!r} {unit} must be <= experiment.motor.{hi_k}="
                              f"{motor[hi_k]!r} {unit}")
    if motor["efficiency"] > 1:
        raise ConfigError(f"experiment.motor.efficiency must be in (0, 1], got {motor['efficiency']!r}")
    centre = e.get("centre")
    R = e.get("R")
    return DatasheetSettings(
        source=src, kind=kind, payloads=tuple(payloads),
        vendor_dwell=read_field("experiment.vendor_dwell", e.get("vendor_dwell"), lo=0, unit="s"),
        hd_ratio=pos("hd_ratio", "1"), volume_h=pos("volume_h", "m"),
        n_samples=read_field("experiment.n_samples", e.get("n_samples"), kind="int", lo=3),
        cylinder_grid=tuple(read_field(f"experiment.cylinder_grid[{i}]", g, kind="int", lo=2)
                            for i, g in enumerate(grid)),
        centre=None if centre is None else tuple(read_vector("experiment.centre", centre, 3)),
        R=None if R is None else read_field("experiment.R", R, lo=0, lo_open=True, unit="m"),
        motor=motor, gear_ratio=pos("gear_ratio", "motor speed / arm speed"),
        **(dict(zip(("source_space", "source_motor"), source_run(src))) if kind == "run_dir" else {}))
