"""Build library objects from (Hydra/OmegaConf or plain dict) configuration, validating first.

Every error raised here names the config field and the value, before anything is compiled.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Dict, Mapping, Optional, Tuple

from .geometry import Delta, GeometryError, ReconfigurableDelta
from .mass import FOREARM_MODELS, MASS_FIELDS, MassError, MassModel, check_field

__all__ = ["ConfigError", "robot_from_config", "mass_from_config", "validate_config", "check_keys", "valid_keys",
           "register_schemas", "TOP_LEVEL_KEYS",
           "EXPERIMENT_VALIDATORS", "EXPERIMENT_SCHEMAS"]


class ConfigError(ValueError):
    """Invalid configuration; the message names the field (dotted path) and the value."""


def _get(cfg: Mapping[str, Any], key: str, prefix: str, default: Any = ...):
    if key in cfg and cfg[key] is not None:
        return cfg[key]
    if default is ...:
        raise ConfigError(f"{prefix}.{key} is required")
    return default


def _number(cfg: Mapping[str, Any], key: str, prefix: str, default: Any = ...) -> Optional[float]:
    v = _get(cfg, key, prefix, default)
    if v is None:
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ConfigError(f"{prefix}.{key} must be a number, got {v!r}") from None
    if math.isnan(f):
        raise ConfigError(f"{prefix}.{key} must not be NaN")
    return f


def robot_from_config(cfg: Mapping[str, Any], prefix: str = "robot") -> Tuple[Delta, Optional[ReconfigurableDelta]]:
    """Build the robot described by a ``configs/robot/*.yaml`` entry.

    Fields: ``base_radius``, ``platform_radius``, ``upper_arm``, ``forearm`` (m), ``theta_min_deg``,
    ``theta_max_deg`` (deg, ``null`` = unlimited), optional ``R_range: {min, max, step}`` (m) for a
    reconfigurable robot and optional ``mass`` (used by the dynamics).

    Returns:
        (fixed robot, reconfigurable robot or ``None``). The fixed robot has R = ``base_radius``.

    Raises:
        ConfigError: a missing or invalid field; the message names ``robot.<field>`` and the value.
    """
    kw = {}
    for key in ("base_radius", "platform_radius", "upper_arm", "forearm"):
        kw[key] = _number(cfg, key, prefix)
    lo = _number(cfg, "theta_min_deg", prefix, None)
    hi = _number(cfg, "theta_max_deg", prefix, None)
    mass_cfg = cfg.get("mass") if hasattr(cfg, "get") else None
    mass = None
    if mass_cfg is not None:
        mass = mass_from_config(mass_cfg, kw, prefix=f"{prefix}.mass")
    try:
        robot = Delta.from_degrees(theta_min_deg=lo, theta_max_deg=hi, mass=mass, **kw)
    except GeometryError as e:
        raise ConfigError(f"{prefix}: {e}") from None
    rng = cfg.get("R_range") if hasattr(cfg, "get") else None
    if rng is None:
        return robot, None
    p = f"{prefix}.R_range"
    r_min, r_max, r_step = _number(rng, "min", p), _number(rng, "max", p), _number(rng, "step", p)
    try:
        recon = ReconfigurableDelta.from_range(robot, r_min, r_max, r_step)
    except GeometryError as e:
        raise ConfigError(f"{p}: {e}") from None
    return robot, recon


def check_reach_over_range(cfg: Mapping[str, Any], recon: ReconfigurableDelta, prefix: str = "robot") -> None:
    """Something must be reachable at every R of ``robot.R_range`` (for jobs that use the range).

    The "can reach nothing" test of :class:`deltajax.Delta` is monotone in R, so both ends suffice.
    """
    rb, rng = recon.robot, cfg.get("R_range")
    for end, R in (("min", float(recon.R_min)), ("max", float(recon.R_max))):
        try:
            Delta(base_radius=R, platform_radius=rb.platform_radius, upper_arm=rb.upper_arm, forearm=rb.forearm,
                  theta_min=rb.theta_min, theta_max=rb.theta_max, mass=rb.mass)
        except GeometryError as e:
            raise ConfigError(f"{prefix}.R_range.{end}={rng.get(end)!r} m: at R = {R:g} m the {e}") from None


# =============================================================================================================
# Validation of every experiment field, before anything is computed (called by run.execute after the robot)
# =============================================================================================================
#: Top-level keys of the composed config (configs/config.yaml and the `# @package _global_` experiment files).
TOP_LEVEL_KEYS = ("robot", "experiment", "seed", "precision", "plots", "progress", "compilation_cache", "fresh",
                  "shard", "n_shards", "beta")

def _field(path: str, v: Any, *, kind: str = "float", lo: Optional[float] = None, hi: Optional[float] = None,
           lo_open: bool = False, hi_open: bool = False, none: bool = False) -> Any:
    """Check one value; ``kind`` is "float" (finite number), "int" or "bool". Returns it as a Python value."""
    if v is None:
        if none:
            return None
        raise ConfigError(f"{path} is required, got null")
    if kind == "bool":
        if not isinstance(v, bool):
            raise ConfigError(f"{path} must be true or false, got {v!r}")
        return v
    if isinstance(v, bool):
        raise ConfigError(f"{path} must be {'an integer' if kind == 'int' else 'a number'}, got {v!r}")
    if kind == "int":
        if isinstance(v, float) and v.is_integer():
            v = int(v)
        if not isinstance(v, int):
            raise ConfigError(f"{path} must be an integer, got {v!r}")
    else:
        try:
            v = float(v)
        except (TypeError, ValueError):
            raise ConfigError(f"{path} must be a number, got {v!r}") from None
        if not math.isfinite(v):
            raise ConfigError(f"{path} must be a finite number, got {v!r}")
    bad_lo = lo is not None and (v <= lo if lo_open else v < lo)
    bad_hi = hi is not None and (v >= hi if hi_open else v > hi)
    if bad_lo or bad_hi:
        left = "" if lo is None else ("(" if lo_open else "[") + f"{lo:g}"
        right = "" if hi is None else f"{hi:g}" + (")" if hi_open else "]")
        if lo is not None and hi is None:
            rng = f"{'>' if lo_open else '>='} {lo:g}"
        elif hi is not None and lo is None:
            rng = f"{'<' if hi_open else '<='} {hi:g}"
        else:
            rng = f"in {left}, {right}"
        raise ConfigError(f"{path} must be {rng}, got {v!r}")
    return v


def _choice(path: str, v: Any, options) -> str:
    if v not in tuple(options):
        raise ConfigError(f"{path} must be one of {sorted(options)}, got {v!r}")
    return v


def _names(path: str, v: Any, options, *, min_len: int = 0) -> list:
    items = list(v or [])
    for x in items:
        _choice(f"{path} entry", x, options)
    if len(items) < min_len:
        raise ConfigError(f"{path} must list at least {min_len} of {sorted(options)}, got {items!r}")
    return items


def _vector(path: str, v: Any, n: int) -> list:
    try:
        items = [float(t) for t in v]
    except (TypeError, ValueError):
        raise ConfigError(f"{path} must be a list of {n} numbers, got {v!r}") from None
    if len(items) != n or not all(math.isfinite(t) for t in items):
        raise ConfigError(f"{path} must be a list of {n} finite numbers, got {v!r}")
    return items


def _validate_top(cfg: Mapping[str, Any]) -> None:
    _field("seed", cfg.get("seed"), kind="int")
    _choice("precision", cfg.get("precision"), ("float64", "float32"))
    for k in ("plots", "progress", "fresh"):
        if k in cfg:
            _field(k, cfg.get(k), kind="bool")
    n_shards = _field("n_shards", cfg.get("n_shards", 1), kind="int", lo=1)
    _field("shard", cfg.get("shard", 0), kind="int", lo=0, hi=n_shards - 1)


def _v_workspace_grid(e, cfg, robot, recon) -> None:
    from .indices import INDEX_NAMES

    g = e.get("grid") or {}
    _field("experiment.grid.h", g.get("h"), lo=0, lo_open=True)
    for k in ("x", "y", "z"):
        if g.get(k) is not None:
            lo, hi = _vector(f"experiment.grid.{k}", g.get(k), 2)
            if not hi >= lo:
                raise ConfigError(f"experiment.grid.{k} must be [lo, hi] with lo <= hi (m), got {[lo, hi]!r}")
    if g.get("bounds") is not None:
        b = g.get("bounds")
        if not hasattr(b, "__len__") or len(b) != 3:
            raise ConfigError(f"experiment.grid.bounds must be null or [[x0,x1],[y0,y1],[z0,z1]] (m), got {b!r}")
        for i, k in enumerate("xyz"):
            lo, hi = _vector(f"experiment.grid.bounds[{i}]", b[i], 2)
            if not hi > lo:
                raise ConfigError(f"experiment.grid.bounds[{i}] ({k}) must have lo < hi (m), got {[lo, hi]!r}")
    _field("experiment.b_v", e.get("b_v"), lo=0, lo_open=True)
    _field("experiment.b_f", e.get("b_f"), lo=0, lo_open=True)
    _field("experiment.beta", e.get("beta"), lo=0, hi=1, lo_open=True, hi_open=True)
    _names("experiment.store", e.get("store"), INDEX_NAMES)
    _field("experiment.chunk_points", e.get("chunk_points"), kind="int", lo=1)
    _choice("experiment.backend", e.get("backend", "auto"), ("auto", "jax", "numba"))
    dev = e.get("devices", "all")
    if dev not in ("all", None):
        _field("experiment.devices", dev, kind="int", lo=1)
    _field("experiment.checkpoint_s", e.get("checkpoint_s"), lo=0)
    _field("experiment.resume", e.get("resume", True), kind="bool")
    _field("experiment.stop_after", e.get("stop_after"), kind="int", lo=1, none=True)


def _v_paper_grid(e, cfg, robot, recon) -> None:
    _field("experiment.h", e.get("h"), lo=0, lo_open=True)
    _field("experiment.chunk_points", e.get("chunk_points"), kind="int", lo=1)
    _field("experiment.checkpoint", e.get("checkpoint", True), kind="bool")
    if recon is None:
        raise ConfigError(f"experiment={e.get('name')} needs a reconfigurable robot: robot.R_range is null")


def _v_reconfig_indices(e, cfg, robot, recon) -> None:
    from .indices import INDEX_NAMES

    _v_paper_grid(e, cfg, robot, recon)
    _field("beta", cfg.get("beta"), lo=0, hi=1, lo_open=True, hi_open=True)
    _field("experiment.b_v", e.get("b_v"), lo=0, lo_open=True)
    _field("experiment.b_f", e.get("b_f"), lo=0, lo_open=True)
    _choice("experiment.criterion", e.get("criterion"), INDEX_NAMES)
    _choice("experiment.mode", e.get("mode"), ("fast", "exact"))
    _choice("experiment.slice_index", e.get("slice_index"), INDEX_NAMES)
    _names("experiment.store_fields", e.get("store_fields"), INDEX_NAMES)
    for i, z in enumerate(e.get("slices_z") or []):
        _field(f"experiment.slices_z[{i}]", z)


def _v_indices_examples(e, cfg, robot, recon) -> None:
    _field("experiment.R_step", e.get("R_step"), lo=0, lo_open=True)
    for i, p in enumerate(e.get("points") or []):
        _vector(f"experiment.points[{i}]", p, 3)
    _field("experiment.b_v", e.get("b_v"), lo=0, lo_open=True)
    _field("experiment.b_f", e.get("b_f"), lo=0, lo_open=True)
    _field("experiment.beta", e.get("beta"), lo=0, hi=1, lo_open=True, hi_open=True)
    _choice("experiment.matrix", e.get("matrix"), ("theta3x3", "full3x4"))


def _v_bench_kernel(e, cfg, robot, recon) -> None:
    for k in ("n_points", "n_baseline", "block", "repeats"):
        _field(f"experiment.{k}", e.get(k), kind="int", lo=1)
    _field("experiment.R", e.get("R"), lo=0, lo_open=True)
    _names("experiment.dtypes", e.get("dtypes"), ("float32", "float64"), min_len=1)


def _v_dynamics_cycle(e, cfg, robot, recon) -> None:
    from .trajectory import MOTION_LAWS

    _choice("experiment.method", e.get("method"), ("virtual_work", "lagrange"))
    _field("experiment.n_samples", e.get("n_samples"), kind="int", lo=2)
    _choice("experiment.law", e.get("law"), MOTION_LAWS)
    _field("experiment.blend", e.get("blend"), lo=0, hi=1, hi_open=True)
    for name, s in (e.get("setups") or {}).items():
        p = f"experiment.setups.{name}"
        _vector(f"{p}.centre", s.get("centre"), 3)
        _field(f"{p}.heading_deg", s.get("heading_deg"))
        for k in ("duration", "torque_limit", "speed_limit"):
            _field(f"{p}.{k}", s.get(k), lo=0, lo_open=True)
    gm = e.get("ga_motion") or {}
    _field("experiment.ga_motion.amplitude", gm.get("amplitude"), lo=0, lo_open=True)
    _field("experiment.ga_motion.duration", gm.get("duration"), lo=0, lo_open=True)
    _field("experiment.recon_R_amplitude", e.get("recon_R_amplitude"), lo=0)


def _v_boundary_search(e, cfg, robot, recon) -> None:
    _vector("experiment.centre", e.get("centre"), 3)
    for k in ("eps", "rho_max", "grid_h", "sweep_step_deg"):
        _field(f"experiment.{k}", e.get(k), lo=0, lo_open=True)
    for i, s in enumerate(e.get("steps_deg") or []):
        _field(f"experiment.steps_deg[{i}]", s, lo=0, lo_open=True)
    for i, z in enumerate(e.get("centre_sweep_z") or []):
        _field(f"experiment.centre_sweep_z[{i}]", z)
    _field("experiment.profile_samples", e.get("profile_samples"), kind="int", lo=2)
    _field("experiment.timing_repeats", e.get("timing_repeats"), kind="int", lo=1)
    _field("experiment.half_space", e.get("half_space", True), kind="bool")


# ---- ga_reconfig: the designer's problem (every field, unknown keys included); owner: designer ----
# The one reader of experiment.* for experiment=ga_reconfig (the job and the validator call it); the design space,
# GA settings and problem are then built by deltajax.optimize.workflow.setup (errors there become ConfigError here).

_GA_KEYS = {
    "": {"name", "resume", "stop_after", "design", "task", "good_workspace", "joints", "links", "motor", "cycle",
         "regular_workspace", "objectives", "constraints", "screen", "ga", "pareto", "refine", "recommend",
         "recommend_band", "verify"},
    "screen": {"enabled", "log2_size", "seed_fraction"},
    "refine": {"enabled", "steps", "learning_rate", "penalty"},
    "design": {"n_R", "bounds"},
    "task": {"diameter", "height", "z_top", "n_r", "n_phi", "n_z"},
    "good_workspace": {"index", "threshold", "beta"},
    "joints": {"kind", "limit_deg", "elbow_neutral_deg", "platform_neutral_deg"},
    "links": {"forearm_radius", "upper_arm_radius", "clearance", "plate_overhang"},
    "motor": {"peak_torque", "rated_torque", "max_speed", "corner_speed", "rotor_inertia", "efficiency",
              "gear_ratio"},
    "cycle": {"payload", "dwell", "duration", "n_samples", "law", "n_R_operating"},
    "regular_workspace": {"hd_ratio", "r_max", "z_min", "z_max", "n_r", "n_phi", "n_z"},
    "objectives": {"mode", "names", "primary", "weights"},
    "constraints": {"task_in_good_workspace", "passive_joints", "interference", "min_picks_per_min",
                    "max_arm_sum"},
    "pareto": {"enabled", "population_size", "generations", "ref_min_factor"},
    "verify": {"n_R", "n_R_operating", "task_n_r", "task_n_phi", "task_n_z", "cycle_samples", "rw_n_r", "rw_n_phi",
               "rw_n_z"},
}


def _ga_plain(x: Any) -> Any:
    from omegaconf import DictConfig, ListConfig, OmegaConf

    if isinstance(x, (DictConfig, ListConfig)):
        return OmegaConf.to_container(x, resolve=True)
    return x


def _ga_block(e: Mapping[str, Any], name: str) -> dict:
    v = e.get(name) if name else e
    where = f"experiment.{name}" if name else "experiment"
    if not isinstance(v, Mapping):
        raise ConfigError(f"{where} must be a mapping, got {v!r}")
    extra = set(v) - _GA_KEYS[name]
    if extra:
        raise ConfigError(f"{where}: unknown keys {sorted(extra)}; known: {sorted(_GA_KEYS[name])}")
    missing = _GA_KEYS[name] - set(v)
    if missing and name not in ("",):
        raise ConfigError(f"{where}: missing keys {sorted(missing)}")
    return dict(v)


def _ga_num(b: Mapping[str, Any], key: str, where: str, *, lo: Optional[float] = None, hi: Optional[float] = None,
         lo_open: bool = False, integer: bool = False, allow_none: bool = False) -> Any:
    v = b.get(key)
    path = f"experiment.{where}.{key}" if where else f"experiment.{key}"
    if v is None and allow_none:
        return None
    if isinstance(v, bool) or v is None or isinstance(v, (list, dict, str)):
        raise ConfigError(f"{path} must be a number, got {v!r}")
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ConfigError(f"{path} must be a number, got {v!r}") from None
    if not math.isfinite(f):
        raise ConfigError(f"{path} must be finite, got {v!r}")
    if integer and not f.is_integer():
        raise ConfigError(f"{path} must be an integer, got {v!r}")
    if lo is not None and (f < lo or (lo_open and f == lo)):
        raise ConfigError(f"{path} must be {'>' if lo_open else '>='} {lo:g}, got {v!r}")
    if hi is not None and f > hi:
        raise ConfigError(f"{path} must be <= {hi:g}, got {v!r}")
    return int(f) if integer else f


def _ga_flag(b, key, where):
    v = b.get(key)
    if not isinstance(v, bool):
        raise ConfigError(f"experiment.{where}.{key} must be true or false, got {v!r}")
    return v


def _ga_choice(b, key, where, options):
    v = b.get(key)
    if v not in options:
        raise ConfigError(f"experiment.{where}.{key} must be one of {list(options)}, got {v!r}")
    return v


@dataclasses.dataclass(frozen=True)
class GaReconfigSettings:
    """Validated plain settings of the job (SI units; angles in degrees where the name says so)."""

    resume: str
    stop_after: Optional[int]
    n_R: int
    bounds: dict
    task: dict
    good: dict
    joints: dict
    links: dict
    motor: dict
    cycle: dict
    regular: dict
    mode: str
    objectives: tuple
    primary: str
    weights: dict
    constraints: dict
    ga: dict
    pareto: dict
    recommend: str
    verify: dict
    screen: dict = dataclasses.field(default_factory=lambda: {"enabled": False, "log2_size": 0, "seed_fraction": 0.0})
    refine: dict = dataclasses.field(default_factory=lambda: {"enabled": False, "steps": 0, "learning_rate": 0.0,
                                                               "penalty": 0.0})
    recommend_band: float = 0.02


def ga_reconfig_settings(ectx: Mapping[str, Any]) -> GaReconfigSettings:
    """Validate every field of ``experiment`` (one ``ConfigError`` line naming field and value)."""
    from .indices import INDEX_NAMES
    from .optimize.designer import CONSTRAINT_NAMES, OBJECTIVES

    e = _ga_block(_ga_plain(ectx), "")
    resume = e.get("resume", "auto")
    if resume not in ("auto", "never", "must"):
        raise ConfigError(f"experiment.resume must be auto, never or must, got {resume!r}")
    sa = e.get("stop_after")
    if sa is not None and (isinstance(sa, bool) or not isinstance(sa, int) or sa < 1):
        raise ConfigError(f"experiment.stop_after must be null or an integer >= 1, got {sa!r}")
    d = _ga_block(e, "design")
    n_R = _ga_num(d, "n_R", "design", lo=2, integer=True)
    if not isinstance(d.get("bounds"), Mapping) or not d["bounds"]:
        raise ConfigError(f"experiment.design.bounds must be a non-empty mapping, got {d.get('bounds')!r}")
    t = _ga_block(e, "task")
    task = {k: _ga_num(t, k, "task", lo=0, lo_open=True) for k in ("diameter", "height", "z_top")}
    task.update({k: _ga_num(t, k, "task", lo=1, integer=True) for k in ("n_r", "n_phi")})
    task["n_z"] = _ga_num(t, "n_z", "task", lo=2, integer=True)
    gw = _ga_block(e, "good_workspace")
    good = {"index": _ga_choice(gw, "index", "good_workspace", INDEX_NAMES),
            "threshold": _ga_num(gw, "threshold", "good_workspace", lo=0), "beta": _ga_num(gw, "beta", "good_workspace",
                                                                                     lo=0, hi=1)}
    j = _ga_block(e, "joints")
    joints = {"kind": _ga_choice(j, "kind", "joints", ("ball", "universal")),
              "limit_deg": _ga_num(j, "limit_deg", "joints", lo=0, lo_open=True, hi=180),
              "elbow_neutral_deg": _ga_num(j, "elbow_neutral_deg", "joints", lo=-180, hi=180),
              "platform_neutral_deg": _ga_num(j, "platform_neutral_deg", "joints", lo=-180, hi=180)}
    lk = _ga_block(e, "links")
    links = {k: _ga_num(lk, k, "links", lo=0, hi=1) for k in ("forearm_radius", "upper_arm_radius", "clearance")}
    links["plate_overhang"] = _ga_num(lk, "plate_overhang", "links", lo=-1, hi=1)
    mo = _ga_block(e, "motor")
    motor = {k: _ga_num(mo, k, "motor", lo=0, lo_open=True) for k in ("peak_torque", "rated_torque", "max_speed",
                                                                   "corner_speed", "gear_ratio")}
    motor["rotor_inertia"] = _ga_num(mo, "rotor_inertia", "motor", lo=0)
    motor["efficiency"] = _ga_num(mo, "efficiency", "motor", lo=0, lo_open=True, hi=1)
    if motor["rated_torque"] > motor["peak_torque"]:
        raise ConfigError(f"experiment.motor.rated_torque={motor['rated_torque']!r} N m must be <= "
                          f"experiment.motor.peak_torque={motor['peak_torque']!r} N m")
    if motor["corner_speed"] > motor["max_speed"]:
        raise ConfigError(f"experiment.motor.corner_speed={motor['corner_speed']!r} rad/s must be <= "
                          f"experiment.motor.max_speed={motor['max_speed']!r} rad/s")
    c = _ga_block(e, "cycle")
    cycle = {"payload": _ga_num(c, "payload", "cycle", lo=0), "dwell": _ga_num(c, "dwell", "cycle", lo=0),
             "duration": _ga_num(c, "duration", "cycle", lo=0, lo_open=True),
             "n_samples": _ga_num(c, "n_samples", "cycle", lo=5, integer=True),
             "law": _ga_choice(c, "law", "cycle", ("poly5", "cycloidal", "modified_trapezoid")),
             "n_R_operating": _ga_num(c, "n_R_operating", "cycle", lo=1, integer=True)}
    if cycle["n_samples"] % 2 == 0:
        raise ConfigError(f"experiment.cycle.n_samples must be odd (a sample at the place point), "
                          f"got {cycle['n_samples']}")
    rw = _ga_block(e, "regular_workspace")
    regular = {"hd_ratio": _ga_num(rw, "hd_ratio", "regular_workspace", lo=0, lo_open=True),
               "r_max": _ga_num(rw, "r_max", "regular_workspace", lo=0, lo_open=True),
               "z_min": _ga_num(rw, "z_min", "regular_workspace", lo=0),
               "z_max": _ga_num(rw, "z_max", "regular_workspace", lo=0, lo_open=True),
               "n_r": _ga_num(rw, "n_r", "regular_workspace", lo=2, integer=True),
               "n_phi": _ga_num(rw, "n_phi", "regular_workspace", lo=2, integer=True),
               "n_z": _ga_num(rw, "n_z", "regular_workspace", lo=2, integer=True)}
    if not regular["z_min"] < regular["z_max"]:
        raise ConfigError(f"experiment.regular_workspace.z_min={regular['z_min']!r} m must be < "
                          f"z_max={regular['z_max']!r} m")
    if task["z_top"] + task["height"] > regular["z_max"] or task["z_top"] < regular["z_min"] or \
            task["diameter"] / 2 > regular["r_max"]:
        raise ConfigError(f"experiment.task (z {task['z_top']!r}..{task['z_top'] + task['height']!r} m, radius "
                          f"{task['diameter'] / 2!r} m) must lie inside experiment.regular_workspace's grid "
                          f"(z {regular['z_min']!r}..{regular['z_max']!r} m, r <= {regular['r_max']!r} m)")
    o = _ga_block(e, "objectives")
    mode = _ga_choice(o, "mode", "objectives", ("pareto", "weighted"))
    names = o.get("names")
    if not isinstance(names, (list, tuple)) or not names:
        raise ConfigError(f"experiment.objectives.names must be a non-empty list from {list(OBJECTIVES)}, got "
                          f"{names!r}")
    for nm in names:
        if nm not in OBJECTIVES:
            raise ConfigError(f"experiment.objectives.names: unknown objective {nm!r}; known: {list(OBJECTIVES)}")
    if len(set(names)) != len(names):
        raise ConfigError(f"experiment.objectives.names has duplicates: {names!r}")
    primary = o.get("primary")
    if primary not in names:
        raise ConfigError(f"experiment.objectives.primary must be one of experiment.objectives.names {names!r}, "
                          f"got {primary!r}")
    wts = o.get("weights")
    if not isinstance(wts, Mapping):
        raise ConfigError(f"experiment.objectives.weights must be a mapping, got {wts!r}")
    weights = {}
    for k in wts:
        if k not in names:
            raise ConfigError(f"experiment.objectives.weights.{k}: not in experiment.objectives.names {names!r}")
        weights[k] = _ga_num(wts, k, "objectives.weights", lo=0)
    if mode == "weighted" and not any(w > 0 for w in weights.values()):
        raise ConfigError("experiment.objectives.weights: all weights are zero (objectives.mode=weighted)")
    if mode == "pareto" and len(names) < 2:
        raise ConfigError(f"experiment.objectives.names needs >= 2 objectives for mode=pareto, got {names!r}")
    cs = _ga_block(e, "constraints")
    cons = {k: _ga_flag(cs, k, "constraints") for k in ("task_in_good_workspace", "passive_joints", "interference")}
    cons["min_picks_per_min"] = _ga_num(cs, "min_picks_per_min", "constraints", lo=0)
    cons["max_arm_sum"] = _ga_num(cs, "max_arm_sum", "constraints", lo=0, lo_open=True, allow_none=True)
    assert set(CONSTRAINT_NAMES) >= {"task_in_good_workspace", "passive_joints", "interference"}
    ga = dict(e.get("ga") or {})
    p = _ga_block(e, "pareto")
    pareto = {"enabled": _ga_flag(p, "enabled", "pareto"),
              "population_size": _ga_num(p, "population_size", "pareto", lo=4, integer=True),
              "generations": _ga_num(p, "generations", "pareto", lo=1, integer=True),
              "ref_min_factor": _ga_num(p, "ref_min_factor", "pareto", lo=1, lo_open=True)}
    recommend = e.get("recommend")
    if recommend not in ("band", "knee", "primary"):
        raise ConfigError(f"experiment.recommend must be band, knee or primary, got {recommend!r}")
    band = _ga_num(e, "recommend_band", "", lo=0, hi=1) if "recommend_band" in e else 0.02
    sc = _ga_block(e, "screen")
    screen = {"enabled": _ga_flag(sc, "enabled", "screen"),
              "log2_size": _ga_num(sc, "log2_size", "screen", lo=0, hi=24, integer=True),
              "seed_fraction": _ga_num(sc, "seed_fraction", "screen", lo=0, hi=1)}
    rf = _ga_block(e, "refine")
    refine = {"enabled": _ga_flag(rf, "enabled", "refine"),
              "steps": _ga_num(rf, "steps", "refine", lo=1, integer=True),
              "learning_rate": _ga_num(rf, "learning_rate", "refine", lo=0, lo_open=True, hi=1),
              "penalty": _ga_num(rf, "penalty", "refine", lo=0)}
    v = _ga_block(e, "verify")
    verify = {k: _ga_num(v, k, "verify", lo=1, integer=True) for k in v}
    for k in ("n_R", "task_n_z", "rw_n_r", "rw_n_phi", "rw_n_z"):
        if verify[k] < 2:
            raise ConfigError(f"experiment.verify.{k} must be >= 2, got {verify[k]!r}")
    if verify["cycle_samples"] < 5 or verify["cycle_samples"] % 2 == 0:
        raise ConfigError(f"experiment.verify.cycle_samples must be odd and >= 5, got {verify['cycle_samples']!r}")
    return GaReconfigSettings(resume=resume, stop_after=sa, n_R=n_R, bounds=dict(d["bounds"]), task=task, good=good,
                    joints=joints, links=links, motor=motor, cycle=cycle, regular=regular, mode=mode,
                    objectives=tuple(names), primary=primary, weights=weights, constraints=cons, ga=ga,
                    pareto=pareto, recommend=recommend, verify=verify, screen=screen, refine=refine,
                    recommend_band=band)


def _v_ga_reconfig(e, cfg, robot, recon) -> None:
    ga_reconfig_build(e, robot, recon)  # every field, the design space, the GA settings, the problem; nothing compiles


def ga_reconfig_build(ectx: Mapping[str, Any], robot, recon, *, n_R: Optional[int] = None):
    """(settings, design space, coarse problem, GA config, baseline design) of experiment=ga_reconfig, validated
    (one ConfigError line naming the field and the value)."""
    from .optimize.workflow import SetupError, setup

    s = ga_reconfig_settings(ectx)
    try:
        return (s,) + tuple(setup(s, robot, recon, n_R=n_R))
    except SetupError as err:
        raise ConfigError(str(err)) from None
# ---- end of ga_reconfig block ----


#: Experiments that use the robot's R range (the others only use the fixed robot, R = base_radius).
R_RANGE_EXPERIMENTS = ("reconfig_workspace", "reconfig_indices", "indices_examples", "ga_reconfig", "dynamics_cycle")

#: experiment name -> validator(experiment cfg, whole cfg, robot, recon); experiments not listed get the
#: top-level checks only (their job validates its own fields).
EXPERIMENT_VALIDATORS = {
    "workspace_grid": _v_workspace_grid,
    "reconfig_workspace": _v_paper_grid,
    "reconfig_indices": _v_reconfig_indices,
    "indices_examples": _v_indices_examples,
    "bench_kernel": _v_bench_kernel,
    "dynamics_cycle": _v_dynamics_cycle,
    "boundary_search": _v_boundary_search,
    "ga_reconfig": _v_ga_reconfig,
}


def validate_config(cfg: Mapping[str, Any], robot=None, recon=None) -> None:
    """Check every field of the composed config before anything is computed.

    Top-level keys (unknown ones rejected, types and ranges), then the experiment block with its validator
    (types, ranges, NaN, cross-field rules). The robot block is checked by :func:`robot_from_config`.

    Raises:
        ConfigError: one line naming the field (dotted path) and the value.
    """
    check_keys(cfg)
    _validate_top(cfg)
    e = cfg.get("experiment") or {}
    if recon is not None and e.get("name") in R_RANGE_EXPERIMENTS:
        check_reach_over_range(cfg.get("robot"), recon)
    check = EXPERIMENT_VALIDATORS.get(e.get("name"))
    if check is not None:
        check(e, cfg, robot, recon)


from .schemas import EXPERIMENT_SCHEMAS, RobotSchema, register_schemas  # noqa: E402 - after ConfigError


def _schema_fields(schema) -> dict:
    import typing

    hints = typing.get_type_hints(schema)
    return {f.name: hints[f.name] for f in dataclasses.fields(schema)}


def _unwrap(tp):
    """The dataclass inside Optional[...] / Dict[str, ...] annotations: (dataclass or None, is_dict)."""
    import typing

    args = typing.get_args(tp)
    origin = typing.get_origin(tp)
    if origin is typing.Union:
        inner = [a for a in args if a is not type(None)]
        return _unwrap(inner[0]) if len(inner) == 1 else (None, False)
    if origin in (dict, Dict) and len(args) == 2 and dataclasses.is_dataclass(args[1]):
        return args[1], True
    if dataclasses.is_dataclass(tp):
        return tp, False
    return None, False


def _check_keys(node: Any, schema, path: str) -> None:
    if not hasattr(node, "keys"):
        return
    fields = _schema_fields(schema)
    for k in node.keys():
        if k not in fields:
            raise ConfigError(f"{path}.{k} is not a setting of {path}; valid keys: {sorted(fields)}")
        sub, is_dict = _unwrap(fields[k])
        v = node.get(k)
        if sub is None or v is None:
            continue
        if is_dict:
            for name in v.keys():
                _check_keys(v.get(name), sub, f"{path}.{k}.{name}")
        else:
            _check_keys(v, sub, f"{path}.{k}")


def check_keys(cfg: Mapping[str, Any]) -> None:
    """Reject keys that no schema knows, including those added with ``+key=value`` (Hydra adds them even to a
    structured config), listing the valid keys of that block.

    Raises:
        ConfigError: one line naming the unknown key and the valid ones.
    """
    extra = [k for k in cfg.keys() if k not in TOP_LEVEL_KEYS]
    if extra:
        raise ConfigError(f"unknown top-level key(s) {extra}; valid keys: {list(TOP_LEVEL_KEYS)}")
    if cfg.get("robot") is not None:
        _check_keys(cfg.get("robot"), RobotSchema, "robot")
    e = cfg.get("experiment")
    schema = EXPERIMENT_SCHEMAS.get(e.get("name")) if e is not None else None
    if schema is not None:
        _check_keys(e, schema, "experiment")


def valid_keys(full_key: str, experiment: Optional[str] = None) -> Optional[list]:
    """The valid keys of the block holding ``full_key`` (e.g. ``"robot.forarm"`` -> the robot's keys), from the
    schemas; ``None`` when no schema covers it. For error messages of Hydra's composition, which name the
    unknown key but not the valid ones (``Key 'forarm' not in 'RobotSchema'``)."""
    parts = full_key.split(".")
    if len(parts) == 1:
        return list(TOP_LEVEL_KEYS)
    schema = RobotSchema if parts[0] == "robot" else EXPERIMENT_SCHEMAS.get(experiment or "")
    if parts[0] not in ("robot", "experiment") or schema is None:
        return None
    for name in parts[1:-1]:
        fields = _schema_fields(schema)
        if name not in fields:
            return None
        sub, is_dict = _unwrap(fields[name])
        if sub is None or is_dict:
            return None
        schema = sub
    return sorted(_schema_fields(schema))


def mass_from_config(mass_cfg: Mapping[str, Any], geometry_kwargs: Optional[Mapping[str, Any]] = None,
                     prefix: str = "robot.mass") -> MassModel:
    """Build a :class:`MassModel` from a ``mass:`` config block, validating every field first.

    Fields: those of :class:`MassModel` (``upper_arm_mass`` required, the others default as documented;
    ``forearm_model`` is ``rigid_rod`` or ``point_split``) plus,
    instead of ``upper_arm_inertia_factor``, an absolute ``upper_arm_inertia`` (kg m^2 about the upper arm's
    centre of mass), converted with the config's ``upper_arm`` length L1 (taken from ``geometry_kwargs``).

    Args:
        mass_cfg: mapping (OmegaConf or dict).
        geometry_kwargs: the robot's geometry (``upper_arm`` in m) for the inertia conversion.
        prefix: dotted path used in error messages.

    Raises:
        ConfigError: unknown, missing, non-numeric or out-of-range field; the message names
            ``<prefix>.<field>`` and the value.
    """
    known = {name for name, _u, _k in MASS_FIELDS} | {"upper_arm_inertia", "forearm_model"}
    keys = list(mass_cfg.keys())
    for k in keys:
        if k not in known:
            raise ConfigError(f"{prefix}.{k} is not a mass-model field (known: {sorted(known)})")
    kinds = {name: kind for name, _u, kind in MASS_FIELDS}
    values: dict[str, Any] = {}
    for k in keys:
        v = mass_cfg[k]
        if v is None:
            continue
        if k == "forearm_model":
            if v not in FOREARM_MODELS:
                raise ConfigError(f"{prefix}.forearm_model must be one of {list(FOREARM_MODELS)}, got {v!r}")
            values[k] = str(v)
            continue
        if isinstance(v, bool):
            raise ConfigError(f"{prefix}.{k} must be a number, got {v!r}")
        try:
            f = float(v)
        except (TypeError, ValueError):
            raise ConfigError(f"{prefix}.{k} must be a number, got {v!r}") from None
        msg = check_field(k, kinds.get(k, "nonneg"), f)
        if msg is not None:
            raise ConfigError(f"{prefix}.{msg}")
        values[k] = f
    if values.get("forearm_model") == "point_split" and "forearm_inertia_factor" in values:
        raise ConfigError(f"{prefix}.forearm_inertia_factor={values['forearm_inertia_factor']!r} applies to "
                          "forearm_model: rigid_rod only (point_split's inertia is that of its two end masses)")
    if "upper_arm_mass" not in values:
        raise ConfigError(f"{prefix}.upper_arm_mass is required")
    if "upper_arm_inertia" in values:
        if "upper_arm_inertia_factor" in values:
            raise ConfigError(f"{prefix}: give upper_arm_inertia or upper_arm_inertia_factor, not both")
        inertia = values.pop("upper_arm_inertia")
        L1 = None if geometry_kwargs is None else geometry_kwargs.get("upper_arm")
        m = values["upper_arm_mass"]
        if L1 is None or not float(L1) > 0:
            raise ConfigError(f"{prefix}.upper_arm_inertia needs the robot's upper_arm length, got {L1!r}")
        if inertia > 0 and m == 0:
            raise ConfigError(f"{prefix}.upper_arm_inertia={inertia!r} kg m^2 needs upper_arm_mass > 0")
        values["upper_arm_inertia_factor"] = 0.0 if m == 0 else inertia / (m * float(L1) ** 2)
    try:
        return MassModel(**values)
    except MassError as e:  # the rigid-rod inertia bound couples two fields; the message names them
        raise ConfigError(f"{prefix}.{e}") from None
