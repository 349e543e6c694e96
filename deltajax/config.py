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


# ---- ga_reconfig: the designer's problem reads and checks its own block (every field, unknown keys included) ----
def _v_ga_reconfig(e, cfg, robot, recon) -> None:
    # The job's reader is the one parser of this block (deltajax/jobs/ga_reconfig.py); calling it here
    # rejects a bad value before the run directory is claimed. Moving the reader below config.py is part of the
    # layout issue (#10).
    from .jobs.ga_reconfig import build

    build(e, robot, recon)  # every field, the design space, the GA settings and the problem; nothing compiles
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
