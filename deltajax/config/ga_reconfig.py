"""The reader of ``experiment.*`` for ``experiment=ga_reconfig`` (the designer's problem): every field, unknown
keys included. The design space, GA settings and problem are then built by :mod:`deltajax.optimize.workflow`
(errors there become :class:`ConfigError` here), once per run, into the job's :class:`GaReconfigSetup`, with the
run's identity (:func:`job_fingerprint`) and, for ``experiment.continue_from``, the finished run it continues
(:func:`earlier_run`: only :data:`BUDGET_SETTINGS` may differ)."""

from __future__ import annotations

import dataclasses
import hashlib
import math
import json
from pathlib import Path
from typing import Any, Mapping, Optional

import numpy as np

from ..rundir import config_differences, recorded
from .readers import ConfigError, check_fits, read_choice, read_field

__all__ = ["GaReconfigSettings", "GaReconfigSetup", "ga_reconfig_settings", "ga_reconfig_build", "validate_ga_reconfig",
           "validate_ga_reconfig_run_dir", "DESIGN_POINT_BYTES", "RECOMMEND_RULES", "job_fingerprint",
           "BUDGET_SETTINGS", "problem_differences", "EarlierRun", "continued_file", "earlier_run", "reconfig_settings",
           "RECONFIG_KEYS", "DRIVE_UNITS", "tolerances_of", "ga_config"]

# ---- ga_reconfig: the designer's problem (every field, unknown keys included); owner: designer ----
# The one reader of experiment.* for experiment=ga_reconfig (the job and the validator call it); the design space,
# GA settings and problem are then built by deltajax.optimize.workflow.setup (errors there become ConfigError here).

_GA_KEYS = {
    "": {"name", "resume", "stop_after", "continue_from", "design", "task", "good_workspace", "joints", "links",
         "motor", "cycle", "regular_workspace", "objectives", "constraints", "screen", "ga", "pareto", "refine",
         "recommend", "recommend_band", "recommend_floor", "floor_solve", "verify", "tolerance", "robust",
         "reconfig"},  # rtmode: experiment.reconfig is checked by deltajax.optimize.operating
    "screen": {"enabled", "log2_size", "seed_fraction"},
    "refine": {"enabled", "steps", "learning_rate", "penalty"},
    "floor_solve": {"enabled", "rounds", "candidates"},
    "design": {"n_R", "bounds"},
    "task": {"diameter", "height", "z_top", "n_r", "n_phi", "n_z"},
    "good_workspace": {"index", "threshold", "beta"},
    "joints": {"kind", "limit_deg", "elbow_neutral_deg", "platform_neutral_deg"},
    "links": {"forearm_radius", "upper_arm_radius", "clearance", "plate_overhang"},
    "motor": {"peak_torque", "rated_torque", "max_speed", "corner_speed", "rotor_inertia", "efficiency",
              "gear_ratio"},
    "cycle": {"payload", "dwell", "duration", "n_samples", "law", "n_R_operating"},
    "regular_workspace": {"hd_ratio", "r_max", "z_min", "z_max", "n_r", "n_phi", "n_z", "search_refine",
                          "search_refine_steps", "search_refine_samples"},
    "objectives": {"mode", "names", "primary", "weights"},
    "constraints": {"task_in_good_workspace", "passive_joints", "interference", "min_picks_per_min",
                    "max_arm_sum"},
    "pareto": {"enabled", "population_size", "generations", "ref_min_factor"},
    "tolerance": {"enabled", "samples", "seed", "distribution", "length_mm", "joint_offset_deg", "mass_percent",
                  "motor_percent"},
    "robust": {"enabled", "probability", "confirm_seed", "max_candidates", "margins"},
    "verify": {"n_R", "n_R_operating", "task_n_r", "task_n_phi", "task_n_z", "cycle_samples", "rw_n_r", "rw_n_phi",
               "rw_n_z", "certify_doublings"},
}

# keys a config may omit (their defaults are applied where they are read)
_GA_OPTIONAL = {"regular_workspace": {"search_refine", "search_refine_steps", "search_refine_samples"},
                "robust": {"margins"}, "verify": {"certify_doublings"}}

#: ``experiment.robust.margins``: the margin every constraint must hold by in a robust run's search, verification
#: and certification (name -> unit, upper bound): the good-workspace index threshold raised by ``index``, the
#: passive joints' limit lowered by ``joint_deg``, the links' required clearance raised by ``clearance_mm``, the
#: motor's peak and rated torque derated by ``motor_percent`` (the cycle is planned with that torque headroom).
#: 0 (the default): the constraint as stated.
ROBUST_MARGINS = {"index": ("", None), "joint_deg": ("deg", 180.0), "clearance_mm": ("mm", 1000.0),
                  "motor_percent": ("%", 100.0)}

#: a lower bound of the memory of one evaluated point of a design (one 3x3 Jacobian in float32), for the refusal
#: of populations that cannot be evaluated at once
DESIGN_POINT_BYTES = 9 * 4

from ..optimize.certify import MAX_EXTRA_DOUBLINGS  # noqa: E402  the certify stage's default
from ..optimize.workflow import RECOMMEND_RULES  # noqa: E402  the one list (the rules of workflow.recommend)


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
        raise ConfigError(f"{where}: unknown keys {', '.join(sorted(extra))}; valid keys: "
                          f"{', '.join(sorted(_GA_KEYS[name]))}")
    missing = _GA_KEYS[name] - set(v) - _GA_OPTIONAL.get(name, set())
    if missing and name not in ("",):
        raise ConfigError(f"{where}: missing keys {', '.join(sorted(missing))}")
    return dict(v)


def _ga_num(b: Mapping[str, Any], key: str, where: str, *, lo: Optional[float] = None, hi: Optional[float] = None,
            lo_open: bool = False, integer: bool = False, allow_none: bool = False, unit: str = "") -> Any:
    path = f"experiment.{where}.{key}" if where else f"experiment.{key}"
    return read_field(path, b.get(key), kind="int" if integer else "float", lo=lo, hi=hi, lo_open=lo_open,
                  none=allow_none, unit=unit)


def _ga_flag(b, key, where):
    return read_field(f"experiment.{where}.{key}", b.get(key), kind="bool")


def _ga_choice(b, key, where, options):
    return read_choice(f"experiment.{where}.{key}", b.get(key), options)


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
    recommend_floor: float = 1.2
    # recommend=floor: the epsilon-constraint step (deltajax.optimize.floor.solve_floor); absent: off
    floor_solve: dict = dataclasses.field(default_factory=lambda: {"enabled": False, "rounds": 0, "candidates": 0})
    # continuous regular workspace in the search: () off, else ((bisection, golden-section steps), (rings, angles,
    # levels) of the unit cylinder) for deltajax.constraints.refine_cylinder (the verification keeps its defaults)
    search_refine: tuple = ()
    reconfig: dict = dataclasses.field(default_factory=dict)  # rtmode: reconfig_settings
    # the tolerance stage (deltajax.tolerance: Monte Carlo over manufacturing and model tolerances); absent: off
    tolerance: dict = dataclasses.field(default_factory=lambda: {"enabled": False})
    # the robust recommendation (holds every constraint in >= probability of the Monte Carlo samples); absent: off
    robust: dict = dataclasses.field(default_factory=lambda: {"enabled": False})
    # a finished run (its directory or results.h5) this run continues with more budget; None: a new search
    continue_from: Optional[str] = None


#: the keys of ``experiment.reconfig`` and the units of its drive limits
RECONFIG_KEYS = {"mode", "aggregate", "n_R", "segments", "drive", "mechanism", "motor_torque"}
DRIVE_UNITS = {"speed": "m/s", "acceleration": "m/s^2", "force": "N"}


def _num(b: Mapping[str, Any], key: str, where: str, unit: str) -> float:
    v = b.get(key)
    if v is None:
        return math.inf
    if isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v) or not v > 0:
        raise ConfigError(f"{where}.{key} must be a number > 0 {unit} or null (no limit), got {v!r}")
    return float(v)


def reconfig_settings(block: Optional[Mapping[str, Any]], where: str = "experiment.reconfig") -> dict:
    """Validate the ``experiment.reconfig`` block (plain values; ``None``: all defaults) into a plain dict.

    Raises:
        ConfigError: one line naming the field and the value in its unit.
    """
    from ..motion import AGGREGATES
    from ..optimize.operating import MECHANISM_NAMES, MODES

    b = {} if block is None else block
    if not isinstance(b, Mapping):
        raise ConfigError(f"{where} must be a mapping, got {b!r}")
    for k in b:
        if k not in RECONFIG_KEYS:
            raise ConfigError(f"{where}.{k}: unknown key; valid keys: {sorted(RECONFIG_KEYS)}")
    out = {}
    for name, options, default in (("mode", MODES, "per_task"), ("aggregate", AGGREGATES, "integral"),
                                   ("mechanism", MECHANISM_NAMES, "none")):
        v = b.get(name, default)
        if v not in options:
            raise ConfigError(f"{where}.{name} must be one of {list(options)}, got {v!r}")
        out[name] = v
    for name, default, lo in (("n_R", 17, 3), ("segments", 8, 3)):
        v = b.get(name, default)
        if isinstance(v, bool) or not isinstance(v, int) or v < lo:
            raise ConfigError(f"{where}.{name} must be an integer >= {lo}, got {v!r}")
        out[name] = v
    d = b.get("drive") or {}
    if not isinstance(d, Mapping):
        raise ConfigError(f"{where}.drive must be a mapping with keys {list(DRIVE_UNITS)}, got {d!r}")
    for k in d:
        if k not in DRIVE_UNITS:
            raise ConfigError(f"{where}.drive.{k}: unknown key; valid keys: {list(DRIVE_UNITS)}")
    out["drive"] = {k: _num(d, k, f"{where}.drive", u) for k, u in DRIVE_UNITS.items()}
    out["motor_torque"] = _num(b, "motor_torque", where, "N m")
    if out["mechanism"] == "none" and math.isfinite(out["motor_torque"]):
        raise ConfigError(f"{where}.motor_torque={out['motor_torque']!r} N m needs {where}.mechanism="
                             f"screw_linkage (got mechanism=none)")
    return out


def tolerances_of(block: Mapping[str, Any]):
    """The :class:`deltajax.tolerance.Tolerances` of a checked ``experiment.tolerance`` block (mm, deg, %)."""
    from ..tolerance import ToleranceError, Tolerances

    try:
        return Tolerances(length=float(block["length_mm"]) * 1e-3, joint_offset_deg=float(block["joint_offset_deg"]),
                          mass=float(block["mass_percent"]) / 100.0, motor=float(block["motor_percent"]) / 100.0,
                          distribution=str(block["distribution"]))
    except ToleranceError as err:
        raise ConfigError(f"experiment.tolerance: {err}") from None


def _operating_settings(e: Mapping[str, Any]) -> dict:  # rtmode
    return reconfig_settings(e.get("reconfig"))


def ga_reconfig_settings(ectx: Mapping[str, Any]) -> GaReconfigSettings:
    """Validate every field of ``experiment`` (one ``ConfigError`` line naming field and value)."""
    from ..indices import INDEX_NAMES, INDEX_RANGES
    from ..optimize.designer import CONSTRAINT_NAMES, OBJECTIVES

    e = _ga_block(_ga_plain(ectx), "")
    resume = e.get("resume", "auto")
    if resume not in ("auto", "never", "must"):
        raise ConfigError(f"experiment.resume must be auto, never or must, got {resume!r}")
    sa = e.get("stop_after")
    if sa is not None and (isinstance(sa, bool) or not isinstance(sa, int) or sa < 1):
        raise ConfigError(f"experiment.stop_after must be null or an integer >= 1, got {sa!r}")
    cont = e.get("continue_from")
    if cont is not None and (not isinstance(cont, str) or not cont.strip()):
        raise ConfigError(f"experiment.continue_from must be null or the path of a finished ga_reconfig run "
                          f"(its directory or results.h5), got {cont!r}")
    d = _ga_block(e, "design")
    n_R = _ga_num(d, "n_R", "design", lo=2, integer=True)
    if not isinstance(d.get("bounds"), Mapping) or not d["bounds"]:
        raise ConfigError(f"experiment.design.bounds must be a non-empty mapping, got {d.get('bounds')!r}")
    t = _ga_block(e, "task")
    task = {k: _ga_num(t, k, "task", lo=0, lo_open=True, unit="m") for k in ("diameter", "height", "z_top")}
    task["n_r"] = _ga_num(t, "n_r", "task", lo=1, integer=True)
    task["n_phi"] = _ga_num(t, "n_phi", "task", lo=2, integer=True)   # both ends of the 60 deg wedge
    task["n_z"] = _ga_num(t, "n_z", "task", lo=2, integer=True)
    gw = _ga_block(e, "good_workspace")
    index = _ga_choice(gw, "index", "good_workspace", INDEX_NAMES)
    lo, hi = INDEX_RANGES[index]  # a threshold outside the index's range selects every point or none
    good = {"index": index, "threshold": _ga_num(gw, "threshold", "good_workspace", lo=lo, hi=hi),
            "beta": _ga_num(gw, "beta", "good_workspace", lo=0, hi=1)}
    j = _ga_block(e, "joints")
    joints = {"kind": _ga_choice(j, "kind", "joints", ("ball", "universal")),
              "limit_deg": _ga_num(j, "limit_deg", "joints", lo=0, lo_open=True, hi=180, unit="deg"),
              "elbow_neutral_deg": _ga_num(j, "elbow_neutral_deg", "joints", lo=-180, hi=180, unit="deg"),
              "platform_neutral_deg": _ga_num(j, "platform_neutral_deg", "joints", lo=-180, hi=180, unit="deg")}
    lk = _ga_block(e, "links")
    links = {k: _ga_num(lk, k, "links", lo=0, hi=1) for k in ("forearm_radius", "upper_arm_radius", "clearance")}
    links["plate_overhang"] = _ga_num(lk, "plate_overhang", "links", lo=-1, hi=1)
    mo = _ga_block(e, "motor")
    motor_units = {"peak_torque": "N m", "rated_torque": "N m", "max_speed": "rad/s", "corner_speed": "rad/s",
                   "gear_ratio": ""}
    motor = {k: _ga_num(mo, k, "motor", lo=0, lo_open=True, unit=u) for k, u in motor_units.items()}
    motor["rotor_inertia"] = _ga_num(mo, "rotor_inertia", "motor", lo=0, unit="kg m^2")
    motor["efficiency"] = _ga_num(mo, "efficiency", "motor", lo=0, lo_open=True, hi=1)
    if motor["rated_torque"] > motor["peak_torque"]:
        raise ConfigError(f"experiment.motor.rated_torque={motor['rated_torque']!r} N m must be <= "
                          f"experiment.motor.peak_torque={motor['peak_torque']!r} N m")
    if motor["corner_speed"] > motor["max_speed"]:
        raise ConfigError(f"experiment.motor.corner_speed={motor['corner_speed']!r} rad/s must be <= "
                          f"experiment.motor.max_speed={motor['max_speed']!r} rad/s")
    c = _ga_block(e, "cycle")
    cycle = {"payload": _ga_num(c, "payload", "cycle", lo=0, unit="kg"),
             "dwell": _ga_num(c, "dwell", "cycle", lo=0, unit="s"),
             "duration": _ga_num(c, "duration", "cycle", lo=0, lo_open=True, unit="s"),
             "n_samples": _ga_num(c, "n_samples", "cycle", lo=5, integer=True),
             "law": _ga_choice(c, "law", "cycle", ("poly5", "cycloidal", "modified_trapezoid")),
             "n_R_operating": _ga_num(c, "n_R_operating", "cycle", lo=1, integer=True)}
    if cycle["n_samples"] % 2 == 0:
        raise ConfigError(f"experiment.cycle.n_samples must be odd (a sample at the place point), "
                          f"got {cycle['n_samples']}")
    rw = _ga_block(e, "regular_workspace")
    regular = {"hd_ratio": _ga_num(rw, "hd_ratio", "regular_workspace", lo=0, lo_open=True),
               "r_max": _ga_num(rw, "r_max", "regular_workspace", lo=0, lo_open=True, unit="m"),
               "z_min": _ga_num(rw, "z_min", "regular_workspace", lo=0, unit="m"),
               "z_max": _ga_num(rw, "z_max", "regular_workspace", lo=0, lo_open=True, unit="m"),
               "n_r": _ga_num(rw, "n_r", "regular_workspace", lo=2, integer=True),
               "n_phi": _ga_num(rw, "n_phi", "regular_workspace", lo=2, integer=True),
               "n_z": _ga_num(rw, "n_z", "regular_workspace", lo=2, integer=True)}
    search_refine = ()
    if read_field("experiment.regular_workspace.search_refine", rw.get("search_refine", False), kind="bool"):
        steps, samples = rw.get("search_refine_steps", [10, 8]), rw.get("search_refine_samples", [3, 2, 3])
        for key, v, n, lo in (("search_refine_steps", steps, 2, 1), ("search_refine_samples", samples, 3, 2)):
            if not (isinstance(v, (list, tuple)) and len(v) == n and all(isinstance(x, int) and not
                                                                         isinstance(x, bool) and x >= lo for x in v)):
                raise ConfigError(f"experiment.regular_workspace.{key} must be a list of {n} integers >= {lo}, "
                                  f"got {v!r}")
        search_refine = (tuple(steps), tuple(samples))
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
    cons["max_arm_sum"] = _ga_num(cs, "max_arm_sum", "constraints", lo=0, lo_open=True, allow_none=True, unit="m")
    assert set(CONSTRAINT_NAMES) >= {"task_in_good_workspace", "passive_joints", "interference"}
    ga = dict(e.get("ga") or {})
    p = _ga_block(e, "pareto")
    pareto = {"enabled": _ga_flag(p, "enabled", "pareto"),
              "population_size": _ga_num(p, "population_size", "pareto", lo=4, integer=True),
              "generations": _ga_num(p, "generations", "pareto", lo=1, integer=True),
              "ref_min_factor": _ga_num(p, "ref_min_factor", "pareto", lo=1, lo_open=True)}
    # every member of a generation is evaluated at once on the search grids: refuse a population that cannot fit
    per_design = n_R * (task["n_r"] * task["n_phi"] * task["n_z"] + regular["n_r"] * regular["n_phi"] *
                        regular["n_z"]) + cycle["n_R_operating"] * cycle["n_samples"]
    for path, size in (("experiment.ga.population_size", ga.get("population_size")),
                       ("experiment.pareto.population_size", pareto["population_size"])):
        if isinstance(size, (int, float)) and not isinstance(size, bool) and size > 0:
            check_fits(path, size, float(size) * per_design * DESIGN_POINT_BYTES,
                  f"{size:.3g} designs x {per_design} evaluated points each at once (a 3x3 Jacobian per point)")
    recommend = e.get("recommend")
    if recommend not in RECOMMEND_RULES:
        raise ConfigError(f"experiment.recommend must be one of {', '.join(RECOMMEND_RULES)}, got {recommend!r}")
    band = _ga_num(e, "recommend_band", "", lo=0, hi=1) if "recommend_band" in e else 0.02
    floor = _ga_num(e, "recommend_floor", "", lo=0, lo_open=True) if "recommend_floor" in e else 1.2
    sc = _ga_block(e, "screen")
    screen = {"enabled": _ga_flag(sc, "enabled", "screen"),
              "log2_size": _ga_num(sc, "log2_size", "screen", lo=0, hi=24, integer=True),
              "seed_fraction": _ga_num(sc, "seed_fraction", "screen", lo=0, hi=1)}
    rf = _ga_block(e, "refine")
    refine = {"enabled": _ga_flag(rf, "enabled", "refine"),
              "steps": _ga_num(rf, "steps", "refine", lo=1, integer=True),
              "learning_rate": _ga_num(rf, "learning_rate", "refine", lo=0, lo_open=True, hi=1),
              "penalty": _ga_num(rf, "penalty", "refine", lo=0)}
    optional = {}                       # absent blocks keep GaReconfigSettings' defaults (the step off)
    if "floor_solve" in e:
        fs = _ga_block(e, "floor_solve")
        optional["floor_solve"] = {"enabled": _ga_flag(fs, "enabled", "floor_solve"),
                                   "rounds": _ga_num(fs, "rounds", "floor_solve", lo=1, integer=True),
                                   "candidates": _ga_num(fs, "candidates", "floor_solve", lo=1, integer=True)}
    if "tolerance" in e:
        optional["tolerance"] = _tolerance_settings(e)
    if "robust" in e:
        rb = _ga_block(e, "robust")
        optional["robust"] = {"enabled": _ga_flag(rb, "enabled", "robust"),
                              "probability": _ga_num(rb, "probability", "robust", lo=0, lo_open=True, hi=1),
                              "confirm_seed": _ga_num(rb, "confirm_seed", "robust", lo=0, hi=2 ** 32 - 1,
                                                      integer=True),
                              "max_candidates": _ga_num(rb, "max_candidates", "robust", lo=1, integer=True),
                              "margins": _robust_margins(rb.get("margins"), joints, good)}
        tl = optional.get("tolerance", {"enabled": False})
        if optional["robust"]["enabled"] and not tl["enabled"]:
            raise ConfigError("experiment.robust.enabled=true needs the tolerance stage: set "
                              "experiment.tolerance.enabled=true")
        if optional["robust"]["enabled"] and optional["robust"]["confirm_seed"] == tl["seed"]:
            raise ConfigError(f"experiment.robust.confirm_seed={optional['robust']['confirm_seed']!r} must differ "
                              f"from experiment.tolerance.seed (the confirmation is a fresh Monte Carlo)")
    v = _ga_block(e, "verify")
    verify = {k: _ga_num(v, k, "verify", lo=1, integer=True) for k in v if k != "certify_doublings"}
    # the certify stage's further doublings while a figure moves more than its tolerance (absent: the default)
    verify["certify_doublings"] = (MAX_EXTRA_DOUBLINGS if v.get("certify_doublings") is None else
                                   _ga_num(v, "certify_doublings", "verify", lo=0, hi=4, integer=True))
    for k in ("n_R", "task_n_phi", "task_n_z", "rw_n_r", "rw_n_phi", "rw_n_z"):
        if verify[k] < 2:
            raise ConfigError(f"experiment.verify.{k} must be >= 2, got {verify[k]!r}")
    if verify["cycle_samples"] < 5 or verify["cycle_samples"] % 2 == 0:
        raise ConfigError(f"experiment.verify.cycle_samples must be odd and >= 5, got {verify['cycle_samples']!r}")
    # the verification's fine grids, one design at least evaluated at once
    fine = verify["n_R"] * (verify["task_n_r"] * verify["task_n_phi"] * verify["task_n_z"] + verify["rw_n_r"] *
                            verify["rw_n_phi"] * verify["rw_n_z"]) + verify["n_R_operating"] * verify["cycle_samples"]
    check_fits("experiment.verify", verify, float(fine) * DESIGN_POINT_BYTES, f"{fine:.3g} evaluated points of a design")
    return GaReconfigSettings(resume=resume, stop_after=sa, n_R=n_R, bounds=dict(d["bounds"]), task=task, good=good,
                    joints=joints, links=links, motor=motor, cycle=cycle, regular=regular, mode=mode,
                    objectives=tuple(names), primary=primary, weights=weights, constraints=cons, ga=ga,
                    pareto=pareto, recommend=recommend, verify=verify, screen=screen, refine=refine,
                    recommend_band=band, recommend_floor=floor, search_refine=search_refine,
                    reconfig=_operating_settings(e), continue_from=cont, **optional)


def _robust_margins(m: Any, joints: Mapping[str, Any], good: Mapping[str, Any]) -> dict:
    """``experiment.robust.margins`` (:data:`ROBUST_MARGINS`; absent or a missing key: 0). A margin must leave the
    tightened constraint satisfiable: the joint limit stays > 0, the index threshold < 1, the motor torque > 0."""
    from ..indices import INDEX_RANGES

    out = dict.fromkeys(ROBUST_MARGINS, 0.0)
    if m is None:
        return out
    m = _ga_plain(m)
    if not isinstance(m, Mapping):
        raise ConfigError(f"experiment.robust.margins must be a mapping of {', '.join(ROBUST_MARGINS)}, got {m!r}")
    extra = set(m) - set(ROBUST_MARGINS)
    if extra:
        raise ConfigError(f"experiment.robust.margins: unknown keys {', '.join(sorted(extra))}; valid keys: "
                          f"{', '.join(ROBUST_MARGINS)}")
    for k, (unit, hi) in ROBUST_MARGINS.items():
        if k in m:
            out[k] = read_field(f"experiment.robust.margins.{k}", m[k], lo=0, hi=hi, hi_open=hi is not None,
                                unit=unit)
    if out["joint_deg"] > 0 and out["joint_deg"] >= joints["limit_deg"]:
        raise ConfigError(f"experiment.robust.margins.joint_deg must be < experiment.joints.limit_deg "
                          f"({joints['limit_deg']:g} deg), got {out['joint_deg']!r} deg")
    top = INDEX_RANGES[good["index"]][1]
    if out["index"] > 0 and top is not None and good["threshold"] + out["index"] >= top:
        raise ConfigError(f"experiment.robust.margins.index must be < {top:g} - experiment.good_workspace.threshold "
                          f"({top - good['threshold']:g}; the index {good['index']} is at most {top:g}), "
                          f"got {out['index']!r}")
    return out


def _tolerance_settings(e: Mapping[str, Any]) -> dict:
    """``experiment.tolerance``: the Monte Carlo of :mod:`deltajax.tolerance` (lengths in mm, masses and motor
    constants in percent)."""
    t = _ga_block(e, "tolerance")
    out = {"enabled": _ga_flag(t, "enabled", "tolerance"),
           "samples": _ga_num(t, "samples", "tolerance", lo=1, hi=10 ** 7, integer=True),
           "seed": _ga_num(t, "seed", "tolerance", lo=0, hi=2 ** 32 - 1, integer=True),
           "distribution": _ga_choice(t, "distribution", "tolerance", ("uniform", "normal")),
           "length_mm": _ga_num(t, "length_mm", "tolerance", lo=0, hi=10, unit="mm"),
           "joint_offset_deg": _ga_num(t, "joint_offset_deg", "tolerance", lo=0, hi=5, unit="deg"),
           "mass_percent": _ga_num(t, "mass_percent", "tolerance", lo=0, hi=50, unit="%"),
           "motor_percent": _ga_num(t, "motor_percent", "tolerance", lo=0, hi=50, unit="%")}
    tolerances_of(out)          # the Monte Carlo's own invariants, before anything compiles
    return out


def ga_config(block: Mapping[str, Any], seed: int = 0):
    """The :class:`deltajax.optimize.GAConfig` of ``experiment.ga`` (unknown keys refused; its invariants checked
    by :meth:`GAConfig.validate`, named here by their config path)."""
    from ..optimize.ga import GAConfig, GAError

    known = {f.name for f in dataclasses.fields(GAConfig)} - {"seed"}
    extra = set(block) - known
    if extra:
        raise ConfigError(f"experiment.ga: unknown keys {sorted(extra)}; known: {sorted(known)}")
    kw = {k: block[k] for k in block}
    for k in ("population_size", "generations", "checkpoint_every"):
        if k in kw and isinstance(kw[k], float) and float(kw[k]).is_integer():
            kw[k] = int(kw[k])
    try:
        return GAConfig(seed=int(seed), **kw).validate()
    except (GAError, TypeError) as err:
        raise ConfigError(str(err).replace("GAConfig.", "experiment.ga.", 1)) from None


# ---- the run's identity and continuing a finished run (experiment.continue_from) ----

def job_fingerprint(cfg) -> str:
    """Hash of everything that determines a run's results (not resume/stop_after/progress/plots)."""
    from omegaconf import OmegaConf

    c = OmegaConf.to_container(cfg, resolve=True) if OmegaConf.is_config(cfg) else dict(cfg)
    e = dict(c.get("experiment", {}))
    e.pop("resume", None)
    e.pop("stop_after", None)
    blob = json.dumps({"experiment": e, "robot": c.get("robot"), "seed": c.get("seed"),
                       "precision": c.get("precision")}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]



#: Settings a continued run may change: the search's budget (besides :data:`deltajax.rundir.NEUTRAL`, which never
#: change the numbers). Everything else (robot, precision, the problem, the verification grids, the recommendation
#: rule) must equal the earlier run's, so that its verified metrics hold here.
BUDGET_SETTINGS = ("seed", "experiment.continue_from", "experiment.screen", "experiment.ga",
                   "experiment.pareto.enabled", "experiment.pareto.population_size", "experiment.pareto.generations",
                   "experiment.refine", "experiment.floor_solve",
                   # the tolerance analysis reads the verified designs and changes none of their numbers
                   "experiment.tolerance", "experiment.robust.enabled", "experiment.robust.probability",
                   "experiment.robust.confirm_seed", "experiment.robust.max_candidates")
# (experiment.robust.margins is not a budget setting: it tightens the problem the earlier run verified)


def problem_differences(old: Mapping[str, Any], new: Mapping[str, Any]) -> list:
    """The settings (dotted key, there, here) in which two runs' configurations pose different problems: every
    difference but :data:`BUDGET_SETTINGS`; an unset margin and a zero one (``experiment.robust.margins``) are the
    same constraint (a run made before margins existed poses the problem a run with zero margins does)."""
    return [d for d in config_differences(old, new, ignore=BUDGET_SETTINGS)
            if not (d[0].startswith("experiment.robust.margins.") and {d[1], d[2]} <= {"<unset>", 0, 0.0})]


@dataclasses.dataclass(frozen=True)
class EarlierRun:
    """The verified front of a finished ``ga_reconfig`` run that a run continues (:func:`earlier_run`)."""

    path: Path                 # its results.h5
    fingerprint: str           # its ga_reconfig_fingerprint
    names: tuple               # its front points' names there, each prefixed "earlier_"
    genes: np.ndarray          # (k, d) their genes
    rows: np.ndarray           # (k,) their rows on its verify group's design axis
    verify: Mapping[str, Any]  # its verify group as loaded (metrics on the fine grids)
    recommended: int           # index into names/genes of its recommendation (-1: none)


def continued_file(where: str) -> Path:
    """The results file that ``experiment.continue_from`` names (a run directory or a results.h5)."""
    p = Path(str(where)).expanduser()
    return p / "results.h5" if p.is_dir() or not p.suffix else p


def earlier_run(where: str, cfg) -> EarlierRun:
    """The finished run ``where`` (its run directory or results.h5) that this run (config ``cfg``) continues with
    more budget. Raises :class:`ConfigError` (one line naming ``experiment.continue_from``) when it is missing,
    unfinished, or a run of another problem: only :data:`BUDGET_SETTINGS` may differ. Reads the file only
    (nothing compiles)."""
    import yaml
    from omegaconf import OmegaConf

    from ..io import load
    from ..rundir import describe_differences

    key = "experiment.continue_from"
    p = continued_file(where)
    if not p.is_file():
        raise ConfigError(f"{key}: {where} is neither a run directory holding a results.h5 nor a results file")
    try:
        fp, done = recorded(p, "ga_reconfig")
        data = load(p)
        old = yaml.safe_load(data["attrs"]["config"])
    except (OSError, KeyError, ValueError, yaml.YAMLError) as err:
        raise ConfigError(f"{key}: {p} cannot be read as a ga_reconfig run ({type(err).__name__}: {err})") from None
    if not fp or not isinstance(old, Mapping) or old.get("experiment", {}).get("name") != "ga_reconfig":
        raise ConfigError(f"{key}: {p} holds no ga_reconfig run")
    if "verify" not in done:
        raise ConfigError(f"{key}: the run in {p} has not finished its verification (stages done: "
                         f"{','.join(done) or 'none'}); resume it first (rerun with hydra.run.dir={p.parent})")
    new = OmegaConf.to_container(cfg, resolve=True)
    diffs = problem_differences(old, new)
    if diffs:
        raise ConfigError(f"{key}: {p} is a run of another problem ({describe_differences(diffs)}); a continued run "
                         "may change only the search budget (seed, experiment.screen, .ga, .pareto population_size "
                         "and generations, .refine, .floor_solve, .tolerance, .robust but its margins)")
    V = data["verify"]
    rows = np.asarray(V["front"], int).reshape(-1)
    genes = np.asarray(V["genes"], float)
    names = [str(n) for n in np.asarray(V["design_name"]).reshape(-1)[rows]]
    rec = int(V["attrs"]["recommended"])
    # "earlier_" on every carried name (a chain of continuations gives earlier_earlier_..., names stay unique)
    return EarlierRun(path=p.resolve(), fingerprint=fp, names=tuple(f"earlier_{n}" for n in names),
                      genes=genes.reshape(-1, genes.shape[-1])[rows], rows=rows, verify=V,
                      recommended=int(np.flatnonzero(rows == rec)[0]) if rec in rows else -1)



@dataclasses.dataclass(frozen=True)
class GaReconfigSetup:
    """What the main job runs on, built once per run from its settings: the settings, the design space, the
    coarse (search) problem, the GA's configuration and, for ``experiment.continue_from``, the earlier run
    (:class:`EarlierRun`; None for a new search)."""

    settings: GaReconfigSettings
    space: Any
    problem: Any
    ga: Any
    earlier: Any = None
    fingerprint: str = ""    # the run's identity (:func:`job_fingerprint`)


def validate_ga_reconfig(e, cfg, robot, recon) -> GaReconfigSetup:
    """The main job's :class:`GaReconfigSetup`: every field, the design space, the GA settings, the problem and a
    continued run's earlier run (finished, of the same problem; its file only)."""
    s, space, pb, ga = ga_reconfig_build(e, robot, recon)
    earlier = None
    if s.continue_from is not None:
        earlier = earlier_run(s.continue_from, cfg)
    return GaReconfigSetup(settings=s, space=space, problem=pb, ga=dataclasses.replace(ga, seed=int(cfg.get("seed"))),
                           earlier=earlier, fingerprint=job_fingerprint(cfg))


def validate_ga_reconfig_run_dir(e, run_dir) -> None:
    """The run directory is not the run that ``experiment.continue_from`` reads (with fresh=true its claim would
    delete what this run continues)."""
    from pathlib import Path

    cont = e.get("continue_from")
    if cont is not None and continued_file(cont).resolve() == (Path(run_dir) / "results.h5").resolve():
        raise ConfigError(f"experiment.continue_from={cont} is this run's own directory; continue into another "
                          "hydra.run.dir (to resume a run, rerun into its directory without continue_from)")


def ga_reconfig_build(ectx: Mapping[str, Any], robot, recon, *, n_R: Optional[int] = None):
    """(settings, design space, coarse problem, GA config) of experiment=ga_reconfig, validated (one ConfigError
    line naming the field and the value)."""
    from ..optimize.workflow import SetupError, setup

    s = ga_reconfig_settings(ectx)
    try:
        space, pb = setup(s, robot, recon, n_R=n_R)
    except SetupError as err:
        raise ConfigError(str(err)) from None
    return s, space, pb, ga_config(s.ga)
# ---- end of ga_reconfig block ----

