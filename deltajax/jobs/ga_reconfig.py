"""Experiment ``ga_reconfig`` (the main job): which Delta should a designer build for this task?

    python -m deltajax.run experiment=ga_reconfig
    python -m deltajax.run experiment=ga_reconfig experiment.pareto.population_size=48 experiment.pareto.generations=40
    python -m deltajax.run experiment=ga_reconfig hydra.run.dir=<dir of a killed run>      # resume

The problem, as a designer states it (``configs/experiment/ga_reconfig.yaml``): serve a task cylinder with the
standard 25/305/25 mm pick-and-place cycle and a payload, using given servo motors through a gearbox whose
ratio is a design variable; **maximise picks per minute and the regular workspace** (the largest cylinder of
a given H/D inside the good workspace) **subject to** the task cylinder lying in the good workspace, the
passive joints within their cone limits and the links clear over the task and along the cycle, the motors
within their torque-speed envelope and thermal (RMS) rating, and a size budget (:mod:`deltajax.constraints`,
:mod:`deltajax.optimize.designer`). A weighted sum stays available (``objectives.mode=weighted``).

Stages (each checkpointed in ``results.h5`` or recomputed deterministically; a rerun into the same
``hydra.run.dir`` resumes after the last finished stage and a finished run is a no-op):

1. **baseline**: the franco2026 design with the configured motor and gear ratio.
2. **ga**: evosax GA on the primary objective (feasibility first), checkpointed every ``checkpoint_every``
   generations (``ga/checkpoint``, kept after every resume) and resumed bit-identically after a kill.
3. **pareto**: NSGA-II (pymoo) over the objectives, every point feasible, seeded with the baseline, the
   GA's best and the GA's last population; hypervolume against a stated reference.
4. **verify**: every front point, the baseline and the GA best re-evaluated on the fine grids (task, cycle,
   regular workspace, R samples); the recommendation is the knee of the verified-feasible front (or the best
   on the primary objective), reported with its fixed-R variant (R frozen at its operating R).
5. **summary** (printed and in group ``summary``), then the plots ``ga_pareto.png`` / ``ga_convergence.png``
   drawn from the stored results.

The GA paper's claims are *not* compared here (different metrics); see docs/REPRODUCTION.md §5.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import re
from pathlib import Path
from typing import Any, Mapping, Optional

import numpy as np

from ..config import ConfigError

__all__ = ["run", "build", "settings_from_config", "Settings", "STAGES"]

#: Hasanlu 2025 (abstract, conclusions): improvements of the optimised design over the baseline (%); compared
#: in docs/REPRODUCTION.md only (a different problem and different metrics).
PAPER_CLAIMS = {"volume": 15.0, "peak_torque": -12.0, "peak_speed": 8.0}
STAGES = ("ga", "pareto", "verify", "results", "plots")

# -- configuration: every field validated before anything compiles ------------------------------------------------

_KEYS = {
    "": {"name", "resume", "stop_after", "design", "task", "good_workspace", "joints", "links", "motor", "cycle",
         "regular_workspace", "objectives", "constraints", "ga", "pareto", "recommend", "verify",
         "reconfig"},  # rtmode: experiment.reconfig is checked by deltajax.optimize.operating
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


def _plain(x: Any) -> Any:
    from omegaconf import DictConfig, ListConfig, OmegaConf

    if isinstance(x, (DictConfig, ListConfig)):
        return OmegaConf.to_container(x, resolve=True)
    return x


def _block(e: Mapping[str, Any], name: str) -> dict:
    v = e.get(name) if name else e
    where = f"experiment.{name}" if name else "experiment"
    if not isinstance(v, Mapping):
        raise ConfigError(f"{where} must be a mapping, got {v!r}")
    extra = set(v) - _KEYS[name]
    if extra:
        raise ConfigError(f"{where}: unknown keys {sorted(extra)}; known: {sorted(_KEYS[name])}")
    missing = _KEYS[name] - set(v)
    if missing and name not in ("",):
        raise ConfigError(f"{where}: missing keys {sorted(missing)}")
    return dict(v)


def _num(b: Mapping[str, Any], key: str, where: str, *, lo: Optional[float] = None, hi: Optional[float] = None,
         lo_open: bool = False, integer: bool = False, allow_none: bool = False) -> Any:
    v = b.get(key)
    path = f"experiment.{where}.{key}"
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


def _flag(b, key, where):
    v = b.get(key)
    if not isinstance(v, bool):
        raise ConfigError(f"experiment.{where}.{key} must be true or false, got {v!r}")
    return v


def _choice(b, key, where, options):
    v = b.get(key)
    if v not in options:
        raise ConfigError(f"experiment.{where}.{key} must be one of {list(options)}, got {v!r}")
    return v


@dataclasses.dataclass(frozen=True)
class Settings:
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
    reconfig: dict = dataclasses.field(default_factory=dict)  # rtmode: operating.settings_from_block


def _operating_settings(e: Mapping[str, Any]) -> dict:  # rtmode
    from ..optimize.operating import OperatingError, settings_from_block

    try:
        return settings_from_block(e.get("reconfig"))
    except OperatingError as err:
        raise ConfigError(str(err)) from None


def _operating_spec(s: "Settings"):  # rtmode: the screw linkage is sized for the design space's R range
    from ..optimize.operating import OperatingError, spec_from_settings

    b = s.bounds
    rr = (b["R_min"][0], b["R_max"][1]) if "R_min" in b and "R_max" in b else None
    try:
        return spec_from_settings(s.reconfig, rr)
    except OperatingError as err:
        raise ConfigError(str(err)) from None


def settings_from_config(ectx: Mapping[str, Any]) -> Settings:
    """Validate every field of ``experiment`` (one ``ConfigError`` line naming field and value)."""
    from ..indices import INDEX_NAMES
    from ..optimize.designer import CONSTRAINT_NAMES, OBJECTIVES

    e = _block(_plain(ectx), "")
    resume = e.get("resume", "auto")
    if resume not in ("auto", "never", "must"):
        raise ConfigError(f"experiment.resume must be auto, never or must, got {resume!r}")
    sa = e.get("stop_after")
    if sa is not None and (isinstance(sa, bool) or not isinstance(sa, int) or sa < 1):
        raise ConfigError(f"experiment.stop_after must be null or an integer >= 1, got {sa!r}")
    d = _block(e, "design")
    n_R = _num(d, "n_R", "design", lo=2, integer=True)
    if not isinstance(d.get("bounds"), Mapping) or not d["bounds"]:
        raise ConfigError(f"experiment.design.bounds must be a non-empty mapping, got {d.get('bounds')!r}")
    t = _block(e, "task")
    task = {k: _num(t, k, "task", lo=0, lo_open=True) for k in ("diameter", "height", "z_top")}
    task.update({k: _num(t, k, "task", lo=1, integer=True) for k in ("n_r", "n_phi")})
    task["n_z"] = _num(t, "n_z", "task", lo=2, integer=True)
    gw = _block(e, "good_workspace")
    good = {"index": _choice(gw, "index", "good_workspace", INDEX_NAMES),
            "threshold": _num(gw, "threshold", "good_workspace", lo=0), "beta": _num(gw, "beta", "good_workspace",
                                                                                     lo=0, hi=1)}
    j = _block(e, "joints")
    joints = {"kind": _choice(j, "kind", "joints", ("ball", "universal")),
              "limit_deg": _num(j, "limit_deg", "joints", lo=0, lo_open=True, hi=180),
              "elbow_neutral_deg": _num(j, "elbow_neutral_deg", "joints", lo=-180, hi=180),
              "platform_neutral_deg": _num(j, "platform_neutral_deg", "joints", lo=-180, hi=180)}
    lk = _block(e, "links")
    links = {k: _num(lk, k, "links", lo=0, hi=1) for k in ("forearm_radius", "upper_arm_radius", "clearance")}
    links["plate_overhang"] = _num(lk, "plate_overhang", "links", lo=-1, hi=1)
    mo = _block(e, "motor")
    motor = {k: _num(mo, k, "motor", lo=0, lo_open=True) for k in ("peak_torque", "rated_torque", "max_speed",
                                                                   "corner_speed", "gear_ratio")}
    motor["rotor_inertia"] = _num(mo, "rotor_inertia", "motor", lo=0)
    motor["efficiency"] = _num(mo, "efficiency", "motor", lo=0, lo_open=True, hi=1)
    if motor["rated_torque"] > motor["peak_torque"]:
        raise ConfigError(f"experiment.motor.rated_torque={motor['rated_torque']!r} N m must be <= "
                          f"experiment.motor.peak_torque={motor['peak_torque']!r} N m")
    if motor["corner_speed"] > motor["max_speed"]:
        raise ConfigError(f"experiment.motor.corner_speed={motor['corner_speed']!r} rad/s must be <= "
                          f"experiment.motor.max_speed={motor['max_speed']!r} rad/s")
    c = _block(e, "cycle")
    cycle = {"payload": _num(c, "payload", "cycle", lo=0), "dwell": _num(c, "dwell", "cycle", lo=0),
             "duration": _num(c, "duration", "cycle", lo=0, lo_open=True),
             "n_samples": _num(c, "n_samples", "cycle", lo=5, integer=True),
             "law": _choice(c, "law", "cycle", ("poly5", "cycloidal", "modified_trapezoid")),
             "n_R_operating": _num(c, "n_R_operating", "cycle", lo=1, integer=True)}
    if cycle["n_samples"] % 2 == 0:
        raise ConfigError(f"experiment.cycle.n_samples must be odd (a sample at the place point), "
                          f"got {cycle['n_samples']}")
    rw = _block(e, "regular_workspace")
    regular = {"hd_ratio": _num(rw, "hd_ratio", "regular_workspace", lo=0, lo_open=True),
               "r_max": _num(rw, "r_max", "regular_workspace", lo=0, lo_open=True),
               "z_min": _num(rw, "z_min", "regular_workspace", lo=0),
               "z_max": _num(rw, "z_max", "regular_workspace", lo=0, lo_open=True),
               "n_r": _num(rw, "n_r", "regular_workspace", lo=2, integer=True),
               "n_phi": _num(rw, "n_phi", "regular_workspace", lo=2, integer=True),
               "n_z": _num(rw, "n_z", "regular_workspace", lo=2, integer=True)}
    if not regular["z_min"] < regular["z_max"]:
        raise ConfigError(f"experiment.regular_workspace.z_min={regular['z_min']!r} m must be < "
                          f"z_max={regular['z_max']!r} m")
    if task["z_top"] + task["height"] > regular["z_max"] or task["z_top"] < regular["z_min"] or \
            task["diameter"] / 2 > regular["r_max"]:
        raise ConfigError(f"experiment.task (z {task['z_top']!r}..{task['z_top'] + task['height']!r} m, radius "
                          f"{task['diameter'] / 2!r} m) must lie inside experiment.regular_workspace's grid "
                          f"(z {regular['z_min']!r}..{regular['z_max']!r} m, r <= {regular['r_max']!r} m)")
    o = _block(e, "objectives")
    mode = _choice(o, "mode", "objectives", ("pareto", "weighted"))
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
        weights[k] = _num(wts, k, "objectives.weights", lo=0)
    if mode == "weighted" and not any(w > 0 for w in weights.values()):
        raise ConfigError("experiment.objectives.weights: all weights are zero (objectives.mode=weighted)")
    if mode == "pareto" and len(names) < 2:
        raise ConfigError(f"experiment.objectives.names needs >= 2 objectives for mode=pareto, got {names!r}")
    cs = _block(e, "constraints")
    cons = {k: _flag(cs, k, "constraints") for k in ("task_in_good_workspace", "passive_joints", "interference")}
    cons["min_picks_per_min"] = _num(cs, "min_picks_per_min", "constraints", lo=0)
    cons["max_arm_sum"] = _num(cs, "max_arm_sum", "constraints", lo=0, lo_open=True, allow_none=True)
    assert set(CONSTRAINT_NAMES) >= {"task_in_good_workspace", "passive_joints", "interference"}
    ga = dict(e.get("ga") or {})
    p = _block(e, "pareto")
    pareto = {"enabled": _flag(p, "enabled", "pareto"),
              "population_size": _num(p, "population_size", "pareto", lo=4, integer=True),
              "generations": _num(p, "generations", "pareto", lo=1, integer=True),
              "ref_min_factor": _num(p, "ref_min_factor", "pareto", lo=1, lo_open=True)}
    recommend = e.get("recommend")
    if recommend not in ("knee", "primary"):
        raise ConfigError(f"experiment.recommend must be knee or primary, got {recommend!r}")
    v = _block(e, "verify")
    verify = {k: _num(v, k, "verify", lo=1, integer=True) for k in v}
    for k in ("n_R", "task_n_z", "rw_n_r", "rw_n_phi", "rw_n_z"):
        if verify[k] < 2:
            raise ConfigError(f"experiment.verify.{k} must be >= 2, got {verify[k]!r}")
    if verify["cycle_samples"] < 5 or verify["cycle_samples"] % 2 == 0:
        raise ConfigError(f"experiment.verify.cycle_samples must be odd and >= 5, got {verify['cycle_samples']!r}")
    return Settings(resume=resume, stop_after=sa, n_R=n_R, bounds=dict(d["bounds"]), task=task, good=good,
                    joints=joints, links=links, motor=motor, cycle=cycle, regular=regular, mode=mode,
                    objectives=tuple(names), primary=primary, weights=weights, constraints=cons, ga=ga,
                    pareto=pareto, recommend=recommend, verify=verify, reconfig=_operating_settings(e))


def _problem(s: Settings, *, fine: bool = False):
    """The designer's problem (coarse for the search, ``fine=True`` for verification)."""
    import math as m

    from .. import constraints as C
    from ..optimize.designer import DesignerProblem

    joints = C.JointModel(limit=m.radians(s.joints["limit_deg"]), elbow_neutral=m.radians(s.joints["elbow_neutral_deg"]),
                          platform_neutral=m.radians(s.joints["platform_neutral_deg"]), kind=s.joints["kind"])
    links = C.LinkModel(**s.links)
    good = C.GoodSpec(joints=joints, links=links, threshold=s.good["threshold"], index=s.good["index"],
                      beta=s.good["beta"])
    motor = C.Motor(**{k: v for k, v in s.motor.items() if k != "gear_ratio"})
    task, cycle, regular = dict(s.task), dict(s.cycle), dict(s.regular)
    n_op = s.cycle["n_R_operating"]
    if fine:
        v = s.verify
        task.update(n_r=v["task_n_r"], n_phi=v["task_n_phi"], n_z=v["task_n_z"])
        cycle["n_samples"] = v["cycle_samples"]
        regular.update(n_r=v["rw_n_r"], n_phi=v["rw_n_phi"], n_z=v["rw_n_z"])
        n_op = v["n_R_operating"]
    enabled = [k for k in ("task_in_good_workspace", "passive_joints", "interference") if s.constraints[k]]
    enabled.append("cycle_rate")
    if s.constraints["max_arm_sum"] is not None:
        enabled.append("size_budget")
    return DesignerProblem.build(task=task, cycle=cycle, motor=motor, joints=joints, links=links, good=good,
                                 regular=regular, n_R_operating=n_op, min_picks=s.constraints["min_picks_per_min"],
                                 max_arm_sum=s.constraints["max_arm_sum"], enabled=enabled,
                                 operating=_operating_spec(s))  # rtmode


def build(ectx: Mapping[str, Any], robot, recon, *, n_R: Optional[int] = None):
    """(settings, design space, coarse problem, GA config) from the experiment config, all validated.

    The baseline is the configured robot (reconfigurable if it has an R range) with the motor's rotor inertia
    and the baseline gear ratio ``motor.gear_ratio`` in its mass model.
    """
    import equinox as eqx
    import jax.numpy as jnp

    from ..optimize import DesignSpace, DesignSpaceError, GAConfig, GAError
    from ..constraints import ConstraintError

    s = settings_from_config(ectx)
    base = recon if recon is not None else robot
    rob = base.robot if recon is not None else base
    if rob.mass is None:
        raise ConfigError("robot.mass is required by experiment=ga_reconfig (the cycle rate needs dynamics)")
    dt = rob.mass.gear_ratio.dtype
    rob = eqx.tree_at(lambda r: (r.mass.gear_ratio, r.mass.rotor_inertia), rob,
                      (jnp.asarray(s.motor["gear_ratio"], dt), jnp.asarray(s.motor["rotor_inertia"], dt)))
    base = eqx.tree_at(lambda r: r.robot, base, rob) if recon is not None else rob
    try:
        space = DesignSpace.from_bounds(base, s.bounds, n_R=s.n_R if n_R is None else n_R,
                                        prefix="experiment.design.bounds")
        ga = GAConfig.from_mapping(s.ga, seed=0)
        pb = _problem(s)
    except (DesignSpaceError, GAError, ConstraintError, ValueError) as err:
        raise ConfigError(str(err)) from None
    return s, space, pb, ga


# -- results file: checkpoint, restaging, stage bookkeeping ------------------------------------------------------

def _history_name(k: str) -> str:
    return k.replace("/", "__")


def _load_checkpoint(path) -> Any:
    """The GA checkpoint stored in a results.h5, or None."""
    from ..io import load

    if not Path(path).exists():
        return None
    data = load(path)
    ck = data.get("ga", {}).get("checkpoint")
    if not ck:
        return None
    attrs = ck["attrs"]
    state = {k: v for k, v in ck["state"].items() if re.fullmatch(r"leaf_\d{3}", k)}
    hist = {k.replace("__", "/"): v for k, v in ck["history"].items()
            if k not in ("attrs", "units", "generation", "gene")}
    return {"fingerprint": attrs["fingerprint"], "generations_done": int(attrs["generations_done"]),
            "state": state, "key": ck["key"], "history": hist, "population": ck["population"],
            "fitness": ck["fitness"]}


def _put_checkpoint(res, ck: Mapping[str, Any]) -> None:
    g = "ga/checkpoint"
    for k, v in ck["state"].items():
        res.put(f"{g}/state", k, v, units="1")
    res.put(g, "key", ck["key"], units="1")
    n = int(ck["generations_done"])
    res.put_axis(f"{g}/history", "generation", np.arange(1, n + 1), units="1")
    for k, v in ck["history"].items():
        v = np.asarray(v)
        dims = ("generation",) + (("gene",) if v.ndim == 2 else ())
        res.put(f"{g}/history", _history_name(k), v, units="1", dims=dims)
    res.put(g, "population", ck["population"], units="1", dims=("member", "gene"))
    res.put(g, "fitness", ck["fitness"], units="1", dims=("member",))
    res.set_attrs(g, fingerprint=ck["fingerprint"], generations_done=int(ck["generations_done"]))


_H5_INTERNAL = {"units", "CLASS", "NAME", "REFERENCE_LIST", "DIMENSION_LIST", "_Netcdf4Dimid", "_Netcdf4Coordinates"}


def _restage(res, path: Path) -> None:
    """Stage everything an existing results.h5 holds into ``res`` (so the next flush keeps it)."""
    import h5py

    def walk(g, prefix):
        if prefix:
            res.set_attrs(prefix, **{k: _attr(v) for k, v in g.attrs.items() if k not in _H5_INTERNAL})
        for name, item in g.items():
            full = f"{prefix}/{name}" if prefix else name
            if isinstance(item, h5py.Group):
                walk(item, full)
                continue
            data = item.asstr()[()] if h5py.check_string_dtype(item.dtype) is not None else item[()]
            if isinstance(data, (str, bytes)):
                data = np.asarray(data, dtype=object)
            if item.is_scale:
                dims = (name,)
            else:
                dims = []
                for i in range(item.ndim):
                    scales = list(item.dims[i].values())
                    dims.append(scales[0].name.rsplit("/", 1)[-1] if scales else f"{name}_dim{i}")
                dims = tuple(dims)
            attrs = {k: _attr(v) for k, v in item.attrs.items() if k not in _H5_INTERNAL}
            units = item.attrs.get("units", "1")
            res.put(prefix, name, data, units=_attr(units), dims=dims, attrs=attrs)

    with h5py.File(path, "r") as f:
        for k, v in f.attrs.items():
            if k not in ("start_time",):
                res.attrs.setdefault(k, _attr(v))
        walk(f, "")


def _attr(v):
    if isinstance(v, bytes):
        return v.decode()
    if isinstance(v, np.generic):
        return v.item()
    return v


def _job_fingerprint(cfg) -> str:
    """Hash of everything that determines this run's results (not resume/stop_after/progress/plots)."""
    from omegaconf import OmegaConf

    c = OmegaConf.to_container(cfg, resolve=True)
    e = dict(c.get("experiment", {}))
    e.pop("resume", None)
    e.pop("stop_after", None)
    blob = json.dumps({"experiment": e, "robot": c.get("robot"), "seed": c.get("seed"),
                       "precision": c.get("precision")}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def _stages_done(path: Path) -> tuple[Optional[str], list]:
    import h5py

    if not path.exists():
        return None, []
    try:
        with h5py.File(path, "r") as f:
            fp = _attr(f.attrs.get("ga_reconfig_fingerprint", ""))
            st = _attr(f.attrs.get("ga_reconfig_stages", ""))
    except OSError as err:
        raise ConfigError(f"{path} exists but cannot be read ({err}); move it away or choose another "
                          "hydra.run.dir") from None
    return (fp or None), [x for x in str(st).split(",") if x]


# -- the job -----------------------------------------------------------------------------------------------------

def run(ctx) -> None:
    import time

    import jax
    import jax.numpy as jnp

    from ..optimize import GAError, run_ga
    from ..optimize.designer import (CONSTRAINT_NAMES, DESIGN_SENSE, DESIGN_UNITS, FEASIBILITY_TOL, evaluate_designer,
                                     knee_point)
    from ..io import load
    from ..optimize.pareto import hypervolume, non_dominated, nsga2, padded_batch

    e = ctx.cfg.experiment
    s, space, pb, ga_cfg = build(e, ctx.robot, ctx.recon)        # validated before anything compiles
    ga_cfg = dataclasses.replace(ga_cfg, seed=int(ctx.cfg.seed))
    res = ctx.results
    path = ctx.run_dir / "results.h5"
    fp = _job_fingerprint(ctx.cfg)
    old_fp, done = _stages_done(path)
    if old_fp is not None and old_fp != fp:
        raise ConfigError(f"{path} holds a ga_reconfig run with different settings (fingerprint {old_fp} vs "
                          f"{fp}); choose another hydra.run.dir (nothing was changed)")
    if path.exists() and old_fp is None and s.resume != "never":
        ck0 = _load_checkpoint(path)
        if ck0 is None:
            raise ConfigError(f"{path} exists but holds no ga_reconfig run; choose another hydra.run.dir "
                              "(nothing was changed)")
    if s.resume == "never":
        done = []
    elif path.exists():
        _restage(res, path)                                      # nothing already on disk is ever dropped
    if s.resume == "must" and "ga" not in done and _load_checkpoint(path) is None:
        raise ConfigError(f"experiment.resume=must but {path} holds no GA checkpoint")
    res.set_attrs(ga_reconfig_fingerprint=fp)
    if "plots" in done:
        ctx.log(f"{path} holds a complete ga_reconfig run (stages {','.join(done)}); nothing to do")
        return

    def mark(stage):
        done.append(stage)
        res.set_attrs(ga_reconfig_stages=",".join(done))
        res.flush()

    t_start = time.perf_counter()
    timings = {}

    def lap(name):
        nonlocal t_start
        now = time.perf_counter()
        timings[name] = now - t_start
        t_start = now
        ctx.log(f"[{name}: {timings[name]:.1f} s]")

    ctx.log(f"design space: {dict(zip(space.names, zip(space.lower, space.upper)))} ({space.dim} genes, "
            f"{'reconfigurable' if space.reconfigurable else 'fixed'}, n_R={space.n_R}); "
            f"{len(pb.task_points)} task samples, {pb.cycle.n_samples} cycle samples, regular-workspace grid "
            f"{pb.rw_points.shape[:3]}")

    objs = list(s.objectives)
    sense = np.asarray([DESIGN_SENSE[o] for o in objs], float)
    need_regular = any(o.startswith("regular") for o in objs)
    P_eval = max(s.pareto["population_size"], 2)
    eval_coarse = jax.jit(jax.vmap(lambda g: evaluate_designer(pb, space.decode(g))))
    batch_eval = padded_batch(eval_coarse, P_eval)
    base_genes = space.baseline_genes()
    if not space.baseline_inside():
        ctx.log("note: the baseline lies outside the bounds; its clipped genes are used as the GA seed")

    # (1) baseline (coarse: normalises the objectives) --------------------------------------------------------
    base = {k: np.asarray(v[0]) for k, v in batch_eval(base_genes[None, :]).items()}
    for o in objs:
        if not (np.isfinite(base[o]) and base[o] != 0):
            raise ConfigError(f"experiment.objectives.names: the baseline's {o} is {float(base[o])!r}, which "
                              "cannot normalise it; loosen the constraints or move the task")
    scale = sense / np.abs(np.asarray([float(base[o]) for o in objs]))
    ctx.log("baseline: " + ", ".join(f"{k}={float(v):.4g}" for k, v in base.items() if np.ndim(v) == 0))
    if not bool(base["feasible"]):
        bad = [n for n, g in zip(CONSTRAINT_NAMES, base["g"]) if g > 0]
        ctx.log(f"warning: the baseline violates {bad}; the recommendation is compared with it all the same")
    lap("baseline")

    # (2) GA on the primary objective (or the weighted sum), checkpointed -------------------------------------
    if s.mode == "weighted":
        wvec = np.asarray([s.weights.get(o, 0.0) for o in objs]) * scale
        ga_what = "weighted sum " + " + ".join(f"{s.weights.get(o, 0.0):g} x {o}" for o in objs)
    else:
        wvec = np.where(np.asarray(objs) == s.primary, scale, 0.0)
        ga_what = f"primary objective {s.primary}"
    ga_regular = need_regular and bool(np.any(wvec[[o.startswith("regular") for o in objs]] != 0))
    wj = jnp.asarray(wvec)

    def fitness(genes):
        m = jax.vmap(lambda g: evaluate_designer(pb, space.decode(g), regular=ga_regular))(genes)
        f = sum(wj[i] * m[o] for i, o in enumerate(objs) if wvec[i] != 0)
        f = jnp.where(jnp.isfinite(f), jnp.clip(f, -1e2, 1e2), 1e2)
        fit = jnp.where(m["violation"] > 0, 1e3 + m["violation"], f)      # feasibility first (Deb's rules)
        aux = {"feasible": m["feasible"], "violation": m["violation"], "picks_per_min": m["picks_per_min"]}
        return fit, aux

    ck = None if s.resume == "never" else _load_checkpoint(path)
    extra = {"space": [space.names, space.lower, space.upper, space.n_R, space.reconfigurable], "job": fp}
    if "ga" in done:
        ctx.log("GA stage already finished in this run directory: reusing its checkpoint")
    elif ck is not None:
        ctx.log(f"resuming the GA from generation {ck['generations_done']} of {path}")
    else:
        ctx.log(f"starting the GA ({ga_what}) from generation 0")

    def save(c):
        _put_checkpoint(res, c)
        res.flush()

    bar = ctx.progress(total=ga_cfg.generations, desc=f"GA {ga_cfg.algorithm}")
    if ck is not None:
        bar.update(int(ck["generations_done"]))
    try:
        gres = run_ga(fitness, space.dim, ga_cfg, init_genes=base_genes, checkpoint=ck, save_checkpoint=save,
                      stop_after=s.stop_after, fingerprint_extra=extra, progress=bar.update)
    except GAError as err:
        raise ConfigError(f"{err} ({path})") from None
    finally:
        bar.close()
    if gres.generations_done < ga_cfg.generations:
        ctx.log(f"stopped after {gres.generations_done} generations (experiment.stop_after); rerun with "
                f"hydra.run.dir={ctx.run_dir} to resume")
        return
    best = gres.best_genes
    if "ga" not in done:
        h = gres.history
        res.put_axis("ga", "generation", np.arange(1, gres.generations_done + 1), units="1")
        for k, v in h.items():
            if k == "gen_best_genes":
                res.put("ga", k, v, units="1", dims=("generation", "gene"))
            elif k.startswith("aux/"):
                res.put("ga", f"gen_best_{k[4:]}", np.asarray(v, float), units=DESIGN_UNITS.get(k[4:], "1"),
                        dims=("generation",))
            else:
                res.put("ga", k, v, units="1", dims=("generation",))
        res.put_axis("ga", "gene", np.arange(space.dim), units="1")
        res.put("ga", "gene_names", np.asarray(space.names, dtype=object), units="1", dims=("gene",))
        res.put("ga", "lower", np.asarray(space.lower), units="mixed", dims=("gene",),
                attrs={"units_per_gene": ",".join(space.units(n) for n in space.names)})
        res.put("ga", "upper", np.asarray(space.upper), units="mixed", dims=("gene",))
        res.put("ga", "best_genes", best, units="1", dims=("gene",))
        res.put("ga", "best_params", np.asarray(space.to_params(jnp.asarray(best))), units="mixed", dims=("gene",),
                attrs={"units_per_gene": ",".join(space.units(n) for n in space.names)})
        res.put("ga", "baseline_genes", base_genes, units="1", dims=("gene",))
        res.set_attrs("ga", algorithm=ga_cfg.algorithm, population_size=ga_cfg.population_size,
                      generations=ga_cfg.generations, sigma=ga_cfg.sigma, seed=ga_cfg.seed,
                      fitness_best=gres.best_fitness, objective=ga_what, resumed_from=gres.resumed_from,
                      fingerprint=gres.fingerprint, constraint_handling="feasibility_first (1e3 + violation)")
        mark("ga")
    ctx.log(f"GA best ({ga_what}): fitness {gres.best_fitness:.5g}, {space.describe(best)}")
    lap("ga")

    # (3) Pareto front (NSGA-II) --------------------------------------------------------------------------------
    ref = np.where(sense < 0, 0.0, s.pareto["ref_min_factor"])         # in normalised objective space
    front_X, extra_X = None, np.zeros((0, space.dim))
    if s.pareto["enabled"]:
        if "pareto" in done:
            front_X = np.asarray(load(path)["pareto"]["genes"])
            extra_X = np.asarray(load(path)["pareto"]["population_feasible_genes"]).reshape(-1, space.dim)
            ctx.log(f"Pareto stage already finished: {len(front_X)} points")
        else:
            def pareto_eval(X):
                m = batch_eval(np.asarray(X))
                F = np.stack([np.asarray(m[o], float) for o in objs], axis=1) * scale
                return F, np.asarray(m["g"]) - FEASIBILITY_TOL   # pymoo: G <= 0 feasible

            pbar = ctx.progress(total=s.pareto["generations"], desc="NSGA-II")
            front = nsga2(pareto_eval, space.dim, len(objs), n_constr=len(CONSTRAINT_NAMES),
                          pop_size=s.pareto["population_size"], n_gen=s.pareto["generations"], seed=int(ctx.cfg.seed),
                          initial=np.concatenate([base_genes[None], best[None], gres.final_population]),
                          ref=ref, progress=pbar.update)
            pbar.close()
            front_X = front.X
            # feasible members of the final population that are not on the search front: more candidates for
            # the fine-grid verification (a point on a constraint's edge on the coarse grids may fail there)
            pfeas = np.all(front.pop_G <= 0, axis=1)
            extra_X = np.asarray([x for x in front.pop_X[pfeas] if not np.any(np.all(front.X == x, axis=1))])
            res.put("pareto", "population_feasible_genes", extra_X.reshape(-1, space.dim), units="1",
                    dims=("population_point", "gene"),
                    attrs={"meaning": "feasible final-population designs off the search front (verified too)"})
            res.put_axis("pareto", "point", np.arange(len(front.X)), units="1")
            res.put_axis("pareto", "gene", np.arange(space.dim), units="1")
            res.put_axis("pareto", "objective", np.arange(len(objs)), units="1")
            res.put("pareto", "objective_names", np.asarray(objs, dtype=object), units="1", dims=("objective",))
            res.put("pareto", "genes", front.X, units="1", dims=("point", "gene"))
            res.put("pareto", "F_search", front.F, units="1", dims=("point", "objective"),
                    attrs={"meaning": "minimised objectives on the search grids: sense x metric / |baseline metric|"})
            res.put("pareto", "hypervolume_history", front.history_hv, units="1", dims=("generation",))
            res.set_attrs("pareto", n_evals=front.n_evals, algorithm="pymoo NSGA-II",
                          population_size=s.pareto["population_size"], generations=s.pareto["generations"])
            mark("pareto")
            ctx.log(f"NSGA-II: {len(front.X)} feasible non-dominated points after {front.n_evals} evaluations")
    lap("pareto")

    # (4) verification on the fine grids, recommendation ---------------------------------------------------------
    if "verify" not in done:
        space_v = dataclasses.replace(space, n_R=s.verify["n_R"]) if space.reconfigurable else space
        pv = _problem(s, fine=True)
        ev = jax.jit(jax.vmap(lambda g: evaluate_designer(pv, space_v.decode(g))))
        cand = [base_genes, best] + ([] if front_X is None else list(front_X)) + list(extra_X)
        mv = {k: np.asarray(v) for k, v in padded_batch(ev, 8)(np.stack(cand)).items()}
        # objectives normalised by the *verified* baseline (so the baseline alone has hypervolume 1 when all
        # objectives are maximised); the search's coarse baseline where the fine one cannot normalise
        bv = np.asarray([float(mv[o][0]) for o in objs])
        scale_v = np.where(np.isfinite(bv) & (bv != 0), sense / np.where(bv != 0, np.abs(bv), 1.0), scale)
        Fv = np.stack([mv[o] for o in objs], axis=1) * scale_v
        feas = mv["feasible"].astype(bool)
        n_front = 0 if front_X is None else len(front_X)
        # the verified front: non-dominated among every feasible design evaluated on the fine grids (the search
        # front, the GA's best and the baseline itself)
        ok_all = np.flatnonzero(feas & np.all(np.isfinite(Fv), axis=1))
        ok_front = np.arange(2, 2 + n_front)[feas[2:2 + n_front]]
        nd = ok_all[non_dominated(Fv[ok_all])] if len(ok_all) else np.zeros((0,), int)
        nd = nd[np.lexsort(Fv[nd].T[::-1])] if len(nd) else nd
        # recommendation: knee of the verified front, or the best on the primary objective
        j_primary = objs.index(s.primary)
        if len(nd) == 0:
            rec = -1
        elif s.recommend == "knee" and len(nd) >= 3:
            rec = int(nd[knee_point(Fv[nd])])
        else:
            rec = int(nd[np.argmin(Fv[nd, j_primary])])
        hv = hypervolume(Fv[nd], ref) if len(nd) else 0.0
        hv_base = hypervolume(Fv[:1], ref)
        names = (["baseline", "ga_best"] + [f"pareto_{i}" for i in range(n_front)]
                 + [f"population_{i}" for i in range(len(extra_X))])
        res.put_axis("verify", "design", np.arange(len(cand)), units="1")
        res.put_axis("verify", "gene", np.arange(space.dim), units="1")
        res.put_axis("verify", "constraint", np.arange(len(CONSTRAINT_NAMES)), units="1")
        res.put_axis("verify", "objective", np.arange(len(objs)), units="1")
        res.put("verify", "design_name", np.asarray(names, dtype=object), units="1", dims=("design",))
        res.put("verify", "constraint_names", np.asarray(CONSTRAINT_NAMES, dtype=object), units="1",
                dims=("constraint",))
        res.put("verify", "genes", np.stack(cand), units="1", dims=("design", "gene"))
        params = np.asarray(jax.vmap(space.to_params)(jnp.asarray(np.stack(cand))))
        res.put("verify", "params", params, units="mixed", dims=("design", "gene"),
                attrs={"gene_names": ",".join(space.names), "units_per_gene": ",".join(space.units(n) for n in
                                                                                        space.names)})
        for k, v in mv.items():
            if k == "g":
                res.put("verify", "constraint_values", v, units="1", dims=("design", "constraint"),
                        attrs={"meaning": "normalised constraint values, <= 0 satisfied (see "
                                          "deltajax.optimize.designer)"})
            else:
                res.put("verify", k, v.astype(float) if v.dtype != bool else v.astype(np.uint8),
                        units=DESIGN_UNITS.get(k, "1"), dims=("design",))
        res.put("verify", "front", nd, units="1", dims=("front_point",),
                attrs={"meaning": "indices (design axis) of the verified Pareto front, sorted by the first objective"})
        res.put("verify", "F", Fv, units="1", dims=("design", "objective"),
                attrs={"meaning": "minimised objectives: sense x metric / |verified baseline metric|"})
        res.set_attrs("verify", recommended=rec, recommend_rule=s.recommend, hypervolume=hv,
                      hypervolume_baseline_only=hv_base,
                      hypervolume_reference="objectives normalised by the baseline verified on the fine grids "
                                            "(sense x metric / |baseline|); "
                                            "reference point 0 for maximised objectives (zero picks/min, zero "
                                            f"volume), {s.pareto['ref_min_factor']} x baseline for minimised ones",
                      reference_point=ref, objectives=",".join(objs),
                      grids=f"task {s.verify['task_n_r']}x{s.verify['task_n_phi']}x{s.verify['task_n_z']}, cycle "
                            f"{s.verify['cycle_samples']} samples, regular grid {s.verify['rw_n_z']}x"
                            f"{s.verify['rw_n_r']}x{s.verify['rw_n_phi']}, n_R {s.verify['n_R']}, operating-R "
                            f"candidates {s.verify['n_R_operating']}")
        n_bad = n_front - len(ok_front)
        ctx.log(f"verified on the fine grids: {len(ok_front)} of {n_front} search-front points and "
                f"{int(feas[2 + n_front:].sum())} of {len(extra_X)} other feasible population members feasible"
                + (f" ({n_bad} failed the fine check and were dropped)" if n_bad else "")
                + f"; verified front (with the GA best and the baseline as candidates): {len(nd)} points, "
                  f"hypervolume {hv:.4g} (baseline alone {hv_base:.4g})")
        mark("verify")
    lap("verify")

    # (5) summary (results before plots) ------------------------------------------------------------------------
    if "results" not in done:
        _summary(ctx, res, load(path), space, objs, s)
        res.set_attrs("ga_reconfig", **{f"time_{k}_s": v for k, v in timings.items()})
        mark("results")                                          # results on disk before any plot
    data = load(path)
    _print_summary(ctx, data)
    _plots(ctx, data, objs, s)
    mark("plots")


SUMMARY_METRICS = ("picks_per_min", "regular_volume", "regular_diameter", "peak_utilisation", "rms_utilisation",
                   "speed_utilisation", "task_good_fraction", "task_index_min", "joint_margin_deg",
                   "interference_margin", "cycle_time", "R_operating", "gear_ratio", "arm_sum")
#: The fixed-R variant (R frozen at the operating R) differs from the reconfigurable design only here.
FIXED_R_METRIC = {"regular_volume": "regular_volume_fixed", "regular_diameter": "regular_diameter_fixed"}
# rtmode: with experiment.reconfig.mode=path the cycle runs with R(t); its fixed-R variant runs it at the per-task R
FIXED_R_METRIC.update({m: f"{m}_fixed" for m in ("picks_per_min", "cycle_time", "peak_utilisation", "rms_utilisation",
                                                 "speed_utilisation", "joint_margin_deg", "interference_margin")})
#: rtmode: rows added to the summary in mode=path (the R drive's margins, units in DESIGN_UNITS)
PATH_SUMMARY_METRICS = ("R_path_min", "R_path_max", "path_index_mean", "cycle_time_drive", "R_speed_margin",
                        "R_accel_margin", "R_force_margin", "screw_torque_peak", "screw_torque_margin")
FIXED_R_METRIC.update({"path_index_mean": "path_index_mean_fixed", "R_path_min": "R_operating",
                       "R_path_max": "R_operating"})


def _fixed_value(V, m: str, i: int) -> float:  # rtmode
    """The fixed-R variant's value of summary metric m (NaN for the R drive's margins: its R does not move)."""
    if m in PATH_SUMMARY_METRICS and m not in FIXED_R_METRIC:
        return float("nan")
    return float(V[FIXED_R_METRIC.get(m, m)][i])


def _summary(ctx, res, data, space, objs, s) -> None:
    """Stage baseline vs recommended design, per metric with units and direction, and the parameters of each
    design (``data``: the results file as loaded after the verify stage)."""
    from ..optimize.designer import DESIGN_SENSE, DESIGN_UNITS

    V = data["verify"]
    metrics = SUMMARY_METRICS + (PATH_SUMMARY_METRICS if s.reconfig.get("mode") == "path" else ())  # rtmode
    rec = int(V["attrs"]["recommended"])
    if rec < 0:
        ctx.log("no feasible design was found on the fine grids: no recommendation (loosen the constraints)")
        res.set_attrs("summary", recommended="none")
        return
    names = list(V["design_name"])
    params = V["params"]
    res.put_axis("summary", "metric", np.arange(len(metrics)), units="1")
    res.put("summary", "metric_name", np.asarray(metrics, dtype=object), units="1", dims=("metric",))
    res.put("summary", "metric_units", np.asarray([DESIGN_UNITS[m] for m in metrics], dtype=object),
            units="1", dims=("metric",))
    direction = [{-1: "higher is better", 1: "lower is better"}.get(DESIGN_SENSE.get(m, 0), "describes the design")
                 for m in metrics]
    res.put("summary", "direction", np.asarray(direction, dtype=object), units="1", dims=("metric",))
    for col, i in (("baseline", 0), ("recommended", rec)):
        res.put("summary", col, np.asarray([float(V[m][i]) for m in metrics]), units="mixed",
                dims=("metric",), attrs={"design": names[i], "units_see": "metric_units",
                                         "variant": "reconfigurable (R chosen per point for the workspace"
                                                    + ("; the cycle run with R(t), experiment.reconfig.mode=path)"
                                                       if s.reconfig.get("mode") == "path" else ")")})
        res.put("summary", f"{col}_fixed_R", np.asarray([_fixed_value(V, m, i)
                                                         for m in metrics]), units="mixed",
                dims=("metric",), attrs={"design": names[i], "units_see": "metric_units",
                                         "variant": "fixed R = the operating R chosen for the task"})
    res.put_axis("summary", "parameter", np.arange(space.dim), units="1")
    res.put("summary", "parameter_name", np.asarray(space.names, dtype=object), units="1", dims=("parameter",))
    res.put("summary", "parameter_units", np.asarray([space.units(n) for n in space.names], dtype=object),
            units="1", dims=("parameter",))
    res.put("summary", "baseline_params", params[0], units="mixed", dims=("parameter",))
    res.put("summary", "recommended_params", params[rec], units="mixed", dims=("parameter",))
    res.set_attrs("summary", recommended=names[rec], rule=s.recommend, objectives=",".join(objs),
                  fixed_R_variant="R frozen at the operating R chosen for the task (same constraints); its picks/min "
                                  "and margins equal the reconfigurable design's at that R (mode per_task; with "
                                  "mode=path the reconfigurable design runs the cycle with R(t)), its regular "
                                  "workspace is the good set at that R alone (base plate as the reconfigurable "
                                  "design's)", operating_mode=s.reconfig.get("mode", "per_task"),
                  evaluation="fine verification grids (group verify)")


def _print_summary(ctx, data) -> None:
    S = data.get("summary")
    if not S or "metric_name" not in S:
        return
    names = list(S["metric_name"])
    units = list(S["metric_units"])
    dirs = list(S["direction"])
    b, r = S["baseline"], S["recommended"]
    bf, rf = S["baseline_fixed_R"], S["recommended_fixed_R"]
    rec = S["attrs"]["recommended"]
    ctx.log(f"baseline (franco2026 + motor) vs recommended design ({rec}), fine verification grids; "
            "reconfigurable (R per point) | fixed R (R frozen at the operating R):")
    ctx.log(f"  {'metric':20s} {'units':6s} {'baseline':>9s} {'recommended':>11s} {'change':>8s} | "
            f"{'base fixR':>9s} {'rec fixR':>9s}  direction")
    for n, u, d, x, y, xf, yf in zip(names, units, dirs, b, r, bf, rf):
        ch = f"{100 * (y - x) / x:+7.1f}%" if np.isfinite(x) and x > 0 and np.isfinite(y) and y > 0 else "     -  "
        ctx.log(f"  {n:20s} {u:6s} {x:9.4g} {y:11.4g} {ch:>8s} | {xf:9.4g} {yf:9.4g}  {d}")
    pn, pu = list(S["parameter_name"]), list(S["parameter_units"])
    ctx.log("  parameters: " + "; ".join(f"{n} [{u}] {x:.4g} -> {y:.4g}" for n, u, x, y in
                                          zip(pn, pu, S["baseline_params"], S["recommended_params"])))
    if S["attrs"].get("operating_mode", "per_task") == "path":  # rtmode
        ctx.log("  reconfigurable: the cycle runs with R(t) within the R drive's limits (experiment.reconfig); "
                "fixed R: at the per-task R. Both columns differ in the cycle metrics and the regular workspace: "
                "that difference is what the R actuator buys")
    else:
        ctx.log("  the fixed-R variants run the task at the same R, so only the regular workspace differs: that "
                "difference is what the R actuator buys")


def _plots(ctx, data, objs, s) -> None:
    """Plots drawn from the staged results only (so a resumed run draws the same figures)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..optimize.designer import DESIGN_UNITS

    G = data.get("ga", {})
    if "best_fitness" in G:
        fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
        bf = np.asarray(G["best_fitness"])
        gens = np.arange(1, len(bf) + 1)
        ax[0].plot(gens, np.where(bf < 1e3, bf, np.nan), label="best so far (feasible)")
        gb = np.asarray(G["gen_best_fitness"])
        ax[0].plot(gens, np.where(gb < 1e3, gb, np.nan), ".", label="best of generation")
        ax[0].set_xlabel("generation")
        ax[0].set_ylabel("fitness (minimised; baseline = -1 per objective)")
        ax[0].legend(fontsize=8)
        ax[0].set_title(str(G["attrs"].get("objective", "")), fontsize=9)
        ax[1].plot(gens, np.asarray(G["gen_feasible_fraction"]))
        ax[1].set_ylim(0, 1.02)
        ax[1].set_xlabel("generation")
        ax[1].set_ylabel("feasible fraction of the population")
        ctx.savefig(fig, "ga_convergence")
    V = data.get("verify")
    if V is None or len(objs) < 2:
        return
    o0, o1 = objs[0], objs[1]
    x, y = np.asarray(V[o0], float), np.asarray(V[o1], float)
    feas = np.asarray(V["feasible"]).astype(bool)
    front = np.asarray(V["front"], int).reshape(-1)
    rec = int(V["attrs"]["recommended"])
    sx = 1e3 if DESIGN_UNITS[o0] == "m^3" else 1.0
    sy = 1e3 if DESIGN_UNITS[o1] == "m^3" else 1.0
    ux = "dm^3 (L)" if sx == 1e3 else DESIGN_UNITS[o0]
    uy = "dm^3 (L)" if sy == 1e3 else DESIGN_UNITS[o1]
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    others = np.setdiff1d(np.arange(2, len(x)), front)
    dom, bad = others[feas[others]], others[~feas[others]]
    if len(dom):
        ax.plot(x[dom] * sx, y[dom] * sy, "o", mfc="none", color="0.55", ms=5, label="candidates, feasible, dominated")
    if len(bad):
        ax.plot(x[bad] * sx, y[bad] * sy, "x", color="0.55", ms=5,
                label="candidates feasible on the search grids, infeasible on the fine grids")
    if len(front):
        o = front[np.argsort(x[front])]
        ax.step(x[o] * sx, y[o] * sy, "-", where="pre", color="C0", lw=1, alpha=0.6)
        ax.plot(x[o] * sx, y[o] * sy, "o", color="C0", ms=6, label="Pareto front (verified, all feasible)")
    ax.plot(x[0] * sx, y[0] * sy, "k*", ms=14, label="baseline franco2026" + ("" if feas[0] else " (infeasible)"))
    if feas[1]:
        ax.plot(x[1] * sx, y[1] * sy, "s", color="C2", ms=8, mfc="none", mew=2, label=f"GA best on {s.primary}")
    if rec >= 0:
        ax.plot(x[rec] * sx, y[rec] * sy, "D", color="C3", ms=10, label="recommended (" + s.recommend + ")")
        if "regular_volume_fixed" == o1 or o1 == "regular_volume":
            yf = float(V["regular_volume_fixed"][rec]) * sy if o1 == "regular_volume" else None
            if yf is not None:
                ax.plot(x[rec] * sx, yf, "v", color="C3", ms=9, mfc="none", mew=1.5,
                        label="recommended, fixed R (operating R)")
    ax.set_xlabel(f"{o0} [{ux}]  (higher is better)" if o0 in ("picks_per_min", "regular_volume") else
                  f"{o0} [{ux}]")
    ax.set_ylabel(f"{o1} [{uy}]  (higher is better)" if o1 in ("picks_per_min", "regular_volume") else
                  f"{o1} [{uy}]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    hv = V["attrs"].get("hypervolume", float("nan"))
    ax.set_title(f"All designs verified on the fine grids. Hypervolume of the front {hv:.3g}\n"
                 f"(objectives / baseline, reference at 0: the baseline alone spans 1)", fontsize=9)
    ctx.savefig(fig, "ga_pareto")
