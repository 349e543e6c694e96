"""The designer's workflow, stage by stage (the library behind ``experiment=ga_reconfig``).

Each stage is a function of validated settings (:func:`deltajax.config.ga_reconfig_settings`), the design
space, the designer's problem and what earlier stages returned; the job (:mod:`deltajax.jobs.ga_reconfig`)
only orders them, stores their outputs in ``results.h5`` and draws the plots.

1. :func:`setup`: design space (baseline = the configured robot with the motor's gearbox), search problem,
   GA settings.
2. :func:`screen`: a scrambled-Sobol quasi-random screen of the gene box on the search grids *without* the
   regular workspace (feasibility does not depend on it; ~30x cheaper per design), whose best feasible designs
   on the primary objective seed the GA; :func:`screen_front`: its feasible non-dominated set on the job's
   objectives (regular workspace evaluated for the feasible designs only) seeds NSGA-II (a hybrid: quasi-random
   screen + evolutionary search).
3. GA (:func:`ga_fitness`, run by :func:`deltajax.optimize.run_ga` with checkpoints), NSGA-II (:func:`pareto_eval`).
4. :func:`refine_designs`: optax Adam on the primary objective plus a constraint penalty from each winner;
   an iterate replaces nothing: it is added as a candidate only if it is feasible on the search grids and no
   objective is worse than at its start while the primary improves. A non-finite gradient raises.
5. :func:`verify`: every candidate on the fine grids, with the regular workspace found by rays
   (:func:`deltajax.optimize.certify.ray_cylinders`) (progress bar), the verified front, the floor step
   (:func:`deltajax.optimize.floor.solve_floor`, rule ``floor``: the rule's answer solved for from the verified
   front with :func:`descent_paths`), and :func:`recommend` (rule ``floor``, ``band``, ``knee`` or ``primary``).

The run's state in ``results.h5`` (GA checkpoint, stages, restaging, the job's fingerprint, continuing an earlier
run) is the application's business: :mod:`deltajax.jobs.designer_state`. Nothing here reads the config or a file.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, Mapping, Optional, Sequence

import numpy as np
import equinox as eqx
import jax.numpy as jnp
import jax

# the compiled programs and the refine descent live in their own modules; these names stay importable from here
from .descent import DESCENT_ROWS, RefineOutcome, descent_paths, refine_designs
from .programs import (batch_evaluator, content_key, design_metrics, objective_matrix, shared_program,
                       stable_key)
from .. import constraints as C
from .designer import DesignerProblem, FEASIBILITY_TOL, knee_point
from .certify import RAY_DENSITY
from .operating import OperatingError, spec_from_settings
from ..constraints import ConstraintError
from . import DesignSpace, DesignSpaceError
from .pareto import non_dominated


__all__ = ["SetupError", "setup", "designer_problem", "required_margins", "screen", "screen_front", "ga_fitness", "ga_fitness_key",
           "pareto_eval",
           "refine_designs", "RefineOutcome", "descent_paths", "verify", "floor_limits", "recommend",
           "RECOMMEND_RULES", "DESCENT_ROWS", "design_metrics", "batch_evaluator", "objective_matrix",
           "STORED_METRIC", "VERIFY_BATCH"]

RECOMMEND_RULES = ("floor", "band", "knee", "primary")   # the rules of :func:`recommend`

#: The name under which ``verify`` stores a metric of the fine-grid evaluation (written by
#: :func:`deltajax.jobs.designer_store.store_verify`, read back by :func:`deltajax.jobs.designer_state.carry_earlier`); others keep their own.
STORED_METRIC = {"g": "constraint_values"}


class SetupError(ValueError):
    """The design space, GA settings or problem cannot be built from the settings (message names the field)."""


# -- setup ---------------------------------------------------------------------------------------------------

def required_margins(s) -> dict:
    """``experiment.robust.margins`` of settings ``s`` (:class:`deltajax.config.ga_reconfig.MarginsBlock`;
    every margin 0 where the run states none)."""
    return dataclasses.asdict(s.robust.margins)


def designer_problem(s, *, fine: bool = False, nominal: bool = False):
    """The designer's problem (coarse search grids, or the fine verification grids with ``fine=True``).

    Every constraint tightened by the run's required margins (:func:`required_margins`: the index threshold
    raised, the passive joints' limit lowered, the links' clearance raised, the motor's peak and rated torque
    derated), unless ``nominal``: the constraints as stated (what the tolerance stage's Monte Carlo judges a built
    robot by). With no margin set both are the same problem."""
    mg = {k: 0.0 for k in required_margins(s)} if nominal else required_margins(s)
    links_kw = dataclasses.asdict(s.links)
    if mg["clearance_mm"]:
        links_kw["clearance"] = links_kw["clearance"] + 1e-3 * mg["clearance_mm"]
    motor_kw = {k: v for k, v in dataclasses.asdict(s.motor).items() if k != "gear_ratio"}
    if mg["motor_percent"]:
        for k in ("peak_torque", "rated_torque"):
            motor_kw[k] = motor_kw[k] * (1.0 - mg["motor_percent"] / 100.0)
    joints = C.JointModel(limit=math.radians(s.joints.limit_deg - mg["joint_deg"]),
                          elbow_neutral=math.radians(s.joints.elbow_neutral_deg),
                          platform_neutral=math.radians(s.joints.platform_neutral_deg), kind=s.joints.kind)
    links = C.LinkModel(**links_kw)
    good = C.GoodSpec(joints=joints, links=links, threshold=s.good_workspace.threshold + mg["index"], index=s.good_workspace.index,
                      beta=s.good_workspace.beta)
    motor = C.Motor(**motor_kw)
    task, cycle, regular = dataclasses.asdict(s.task), dataclasses.asdict(s.cycle), s.regular_workspace.grid()
    n_op = s.cycle.n_R_operating
    # the continuous regular-workspace measure: full settings on the fine grids, the lighter search settings
    # (experiment.regular_workspace.search_refine) on the search grids, or the grid's measure there
    # the verification finds it by rays (deltajax.optimize.certify.ray_cylinders; verify.rw_n_phi rays per level,
    # verify.rw_n_z levels per pass, verify.rw_n_r samples along a ray)

    v = s.verify
    rays = tuple(RAY_DENSITY._replace(n_phi=v.rw_n_phi, n_z=v.rw_n_z, n_along=v.rw_n_r))
    refine = {"rw_refine": True, "rw_rays": rays} if fine else (
        {"rw_refine": True, "rw_refine_steps": s.search_refine[0], "rw_refine_samples": s.search_refine[1]}
        if s.search_refine else {"rw_refine": False})
    if fine:
        task.update(n_r=v.task_n_r, n_phi=v.task_n_phi, n_z=v.task_n_z)
        cycle["n_samples"] = v.cycle_samples
        regular.update(n_r=v.rw_n_r, n_phi=v.rw_n_phi, n_z=v.rw_n_z)
        n_op = v.n_R_operating
    enabled = [k for k in s.constraints.GEOMETRIC if getattr(s.constraints, k)]
    enabled.append("cycle_rate")
    if s.constraints.max_arm_sum is not None:
        enabled.append("size_budget")
    return DesignerProblem.build(task=task, cycle=cycle, motor=motor, joints=joints, links=links, good=good,
                                 regular=regular, n_R_operating=n_op, min_picks=s.constraints.min_picks_per_min,
                                 max_arm_sum=s.constraints.max_arm_sum, enabled=enabled,
                                 operating=operating_spec(s),  # rtmode
                                 **refine)


def operating_spec(s):  # rtmode: the screw linkage is sized for the design space's R range
    """The R(t) operating spec of ``experiment.reconfig`` (None in the default per-task mode)."""
    b = s.design.bounds
    rr = (b["R_min"][0], b["R_max"][1]) if "R_min" in b and "R_max" in b else None
    try:
        return spec_from_settings(s.reconfig, rr)
    except OperatingError as err:
        raise SetupError(str(err)) from None


def setup(s, robot, recon, *, n_R: Optional[int] = None):
    """(design space, coarse problem) for settings ``s``. The baseline is the configured robot
    (reconfigurable if it has an R range) with the motor's rotor inertia and the gear ratio
    ``motor.gear_ratio`` in its mass model. Raises :class:`SetupError` (one line naming the field)."""
    base = recon if recon is not None else robot
    rob = base.robot if recon is not None else base
    if rob.mass is None:
        raise SetupError("robot.mass is required by experiment=ga_reconfig (the cycle rate needs dynamics)")
    dt = rob.mass.gear_ratio.dtype
    rob = eqx.tree_at(lambda r: (r.mass.gear_ratio, r.mass.rotor_inertia), rob,
                      (jnp.asarray(s.motor.gear_ratio, dt), jnp.asarray(s.motor.rotor_inertia, dt)))
    base = eqx.tree_at(lambda r: r.robot, base, rob) if recon is not None else rob
    try:
        space = DesignSpace.from_bounds(base, s.design.bounds, n_R=s.design.n_R if n_R is None else n_R,
                                        prefix="experiment.design.bounds")
        pb = designer_problem(s)
    except (DesignSpaceError, ConstraintError, ValueError) as err:
        raise SetupError(str(err)) from None
    return space, pb


# -- screen ----------------------------------------------------------------------------------------------------

def screen(evaluate_cheap: Callable[[np.ndarray], dict], space, primary: str, sense_primary: float, log2_size: int,
           *, seed: int = 0, batch: int = 256, progress: Optional[Callable[[int], Any]] = None) -> dict:
    """Scrambled-Sobol screen of 2^log2_size designs on the search grids without the regular workspace.

    Returns ``{"X": genes, "feasible": bool, primary: values, "order": indices of the feasible designs, best
    primary first}``. Only the feasible designs' primary objective ranks them (``sense_primary`` -1: higher is
    better); ``evaluate_cheap`` (:func:`batch_evaluator` with ``regular=False``) skips the regular workspace, so a
    regular-workspace primary cannot be screened.
    """
    from scipy.stats import qmc

    X = qmc.Sobol(d=space.dim, scramble=True, seed=seed).random_base2(int(log2_size))
    parts = []
    for s0 in range(0, len(X), batch):
        parts.append(evaluate_cheap(X[s0:s0 + batch]))
        if progress is not None:
            progress(len(X[s0:s0 + batch]))
    m = {k: np.concatenate([p[k] for p in parts]) for k in ("feasible", primary, "violation")}
    feas = m["feasible"].astype(bool) & np.isfinite(m[primary])
    idx = np.flatnonzero(feas)
    order = idx[np.argsort(sense_primary * m[primary][idx], kind="stable")]
    return {"X": X, "feasible": feas, primary: m[primary], "violation": m["violation"], "order": order}


def screen_front(evaluate: Callable[[np.ndarray], dict], sc: Mapping[str, Any], objs: Sequence[str],
                 scale: np.ndarray, *, cap: int = 1024, layers: bool = False) -> np.ndarray:
    """Genes of the feasible non-dominated set of a :func:`screen` on the job's objectives.

    The screen's feasible designs (at most ``cap``, best primary first) are evaluated with ``evaluate`` (the
    search grids *with* the regular workspace); their feasible non-dominated set, sorted by the first objective,
    is returned ((k, dim)). ``layers=True``: every feasible design, in non-dominated-sorting order (the front,
    then the front of the rest, ...; each layer sorted by the first objective). It seeds NSGA-II, whose other
    seeds (the GA's population) crowd the primary's end.
    """
    X = np.asarray(sc["X"])[np.asarray(sc["order"])[:cap]]
    if len(X) == 0:
        return np.zeros((0, np.asarray(sc["X"]).shape[1]))
    m = evaluate(X)
    F = objective_matrix(m, objs, scale)
    rest = np.flatnonzero(m["feasible"].astype(bool) & np.all(np.isfinite(F), axis=1))
    out = []
    while len(rest):
        nd = rest[non_dominated(F[rest])]
        out.append(nd[np.argsort(F[nd, 0], kind="stable")])
        if not layers:
            break
        rest = np.setdiff1d(rest, nd)
    return X[np.concatenate(out)] if out else X[:0]


# -- GA and NSGA-II --------------------------------------------------------------------------------------------

def ga_fitness(pb, space, objs: Sequence[str], wvec: np.ndarray):
    """GA fitness ``genes (P, d) -> (fitness, aux)``: the weighted objectives ``wvec`` (normalised, minimised),
    feasibility first (Deb's rules: infeasible = 1e3 + violation). The regular workspace is computed only when
    a regular-workspace objective has a non-zero weight."""
    objs, wvec = tuple(objs), np.asarray(wvec, float)
    regular = any(o.startswith("regular") and w != 0 for o, w in zip(objs, wvec))

    def build():
        wj = jnp.asarray(wvec)

        one = design_metrics(pb, space, regular=regular)   # traced once for the GA's init and its chunks

        def fitness(genes):
            m = jax.vmap(one)(genes)
            f = sum(wj[i] * m[o] for i, o in enumerate(objs) if wvec[i] != 0)
            f = jnp.where(jnp.isfinite(f), jnp.clip(f, -1e2, 1e2), 1e2)
            fit = jnp.where(m["violation"] > 0, 1e3 + m["violation"], f)
            return fit, {"feasible": m["feasible"], "violation": m["violation"], "picks_per_min": m["picks_per_min"]}

        return fitness

    # one function object per content: run_ga's compiled engine is cached per fitness function
    return shared_program("ga_fitness", pb, space, (objs, content_key(wvec)), build)


def ga_fitness_key(pb, space, objs: Sequence[str], wvec: np.ndarray):
    """The content of :func:`ga_fitness` (``run_ga``'s ``program_key``), or None if it is not known by value."""
    return stable_key(pb, space, ("ga_fitness", tuple(objs), content_key(np.asarray(wvec, float))))


def pareto_eval(evaluate: Callable[[np.ndarray], dict], objs: Sequence[str], scale: np.ndarray):
    """pymoo's ``X -> (F, G)`` from a batch evaluator (G <= 0 feasible, up to the feasibility tolerance)."""
    def f(X):
        m = evaluate(np.asarray(X))
        return objective_matrix(m, objs, scale), np.asarray(m["g"]) - FEASIBILITY_TOL

    return f



#: Designs per call of the verification's evaluator (verify and the floor step share its program): its ray searches
#: loop until the slowest design of a call is done, so fewer per call wait less; on the default run's 42
#: candidates 4 cost ~20 % fewer CPU-seconds than 8, and 2 or 1 no fewer (docs/BENCHMARKS.md)
VERIFY_BATCH = 4


def verify(pb_fine, space, cand: np.ndarray, *, batch: int = VERIFY_BATCH,
           progress: Optional[Callable[[int], Any]] = None) -> dict:
    """Every metric of every candidate on the fine grids (``progress`` gets the number of designs per batch)."""
    ev = batch_evaluator(pb_fine, space, batch)
    parts = []
    for s0 in range(0, len(cand), batch):
        parts.append(ev(cand[s0:s0 + batch]))
        if progress is not None:
            progress(len(cand[s0:s0 + batch]))
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def floor_limits(n_obj: int, j_primary: int, floor: float, sense: Sequence[float]) -> np.ndarray:
    """The floor on each non-primary normalised minimised objective (baseline -1 for a maximised one, +1 for a
    minimised one): ``<= -floor`` (maximised), ``<= 1 / floor`` (minimised); the primary's entry is +inf."""
    sg = np.asarray(sense, float)
    lim = np.where(sg < 0, -float(floor), 1.0 / float(floor))
    lim[j_primary] = np.inf
    return lim


def recommend(F: np.ndarray, front: np.ndarray, rule: str, j_primary: int, *, band: float = 0.02,
              floor: float = 1.2, sense: Optional[Sequence[float]] = None) -> int:
    """Index (into ``F``'s rows) of the recommended design on a verified front (``front``: row indices).

    ``F``: minimised objectives normalised by the baseline (sense x metric / |baseline|), so a maximised
    objective's baseline is -1 and a minimised one's +1.
    * ``floor``: the best primary objective among front points at least ``floor`` times as good as the baseline
      on every other objective (maximised: metric >= floor x baseline; minimised: metric <= baseline / floor);
      when no point reaches the floors, the point closest to them (smallest largest shortfall, ties: the better
      primary). ``sense``: -1 (maximised) / +1 (minimised) per objective (default: all maximised, the job's
      objectives). A fixed threshold, not one set by the front itself: adding or moving a far point of the front
      never changes which point is chosen, so two runs whose fronts agree near the floor agree.
    * ``band``: among front points whose primary objective is within ``band`` (relative) of the front's best,
      the best on the other objectives in order (lexicographic; ties: the better primary). Its edge moves with
      the front's best: a faster far point can move the choice a long way.
    * ``knee``: :func:`deltajax.optimize.designer.knee_point` (front normalised over itself; falls back to
      ``primary`` with fewer than 3 points).
    * ``primary``: the best primary objective.
    -1 when the front is empty.
    """
    front = np.asarray(front, int).reshape(-1)
    if len(front) == 0:
        return -1
    Ff = F[front]
    if rule == "knee" and len(front) >= 3:
        return int(front[knee_point(Ff)])
    best = Ff[:, j_primary].min()
    others = [j for j in range(F.shape[1]) if j != j_primary]
    if rule == "floor":
        # floor on a normalised minimised objective f (baseline -1 or +1): f <= -floor (maximised), <= 1/floor
        lim = floor_limits(F.shape[1], j_primary, floor, np.full(F.shape[1], -1.0) if sense is None else sense)[others]
        short = np.max(Ff[:, others] - lim[None, :], axis=1, initial=-np.inf) if others else np.zeros(len(Ff))
        ok = short <= 0
        if ok.any():
            i = np.flatnonzero(ok)[np.argmin(Ff[ok, j_primary])]
        else:
            i = np.lexsort((Ff[:, j_primary], short))[0]
        return int(front[i])
    if rule == "band":
        # objectives are minimised and normalised: -1 is the baseline for a maximised one; "within band of the
        # best" means primary <= best + band x |best|
        inside = Ff[:, j_primary] <= best + band * abs(best)
        keys = [Ff[:, j_primary]] + [Ff[:, j] for j in reversed(others)]
        order = np.lexsort(keys)                             # last key first: objectives in order, then primary
        return int(front[[i for i in order if inside[i]][0]])
    return int(front[np.argmin(Ff[:, j_primary])])
