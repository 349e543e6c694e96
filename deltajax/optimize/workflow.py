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
5. :func:`verify`: every candidate on the fine grids, with the continuous regular-workspace measure
   (:func:`deltajax.constraints.refine_cylinder`) (progress bar), the verified front, the floor step
   (:func:`deltajax.optimize.floor.solve_floor`, rule ``floor``: the rule's answer solved for from the verified
   front with :func:`descent_paths`), and :func:`recommend` (rule ``floor``, ``band``, ``knee`` or ``primary``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import re
from pathlib import Path
from typing import Any, Callable, Mapping, Optional, Sequence

import numpy as np

__all__ = ["SetupError", "setup", "designer_problem", "screen", "screen_front", "ga_fitness", "pareto_eval",
           "refine_designs", "RefineOutcome", "descent_paths", "verify", "floor_limits", "recommend",
           "load_checkpoint", "put_checkpoint", "restage", "stages_done", "job_fingerprint", "RECOMMEND_RULES"]

RECOMMEND_RULES = ("band", "knee", "primary")


class SetupError(ValueError):
    """The design space, GA settings or problem cannot be built from the settings (message names the field)."""


# -- setup ---------------------------------------------------------------------------------------------------

def designer_problem(s, *, fine: bool = False):
    """The designer's problem (coarse search grids, or the fine verification grids with ``fine=True``)."""
    from .. import constraints as C
    from .designer import DesignerProblem

    joints = C.JointModel(limit=math.radians(s.joints["limit_deg"]),
                          elbow_neutral=math.radians(s.joints["elbow_neutral_deg"]),
                          platform_neutral=math.radians(s.joints["platform_neutral_deg"]), kind=s.joints["kind"])
    links = C.LinkModel(**s.links)
    good = C.GoodSpec(joints=joints, links=links, threshold=s.good["threshold"], index=s.good["index"],
                      beta=s.good["beta"])
    motor = C.Motor(**{k: v for k, v in s.motor.items() if k != "gear_ratio"})
    task, cycle, regular = dict(s.task), dict(s.cycle), dict(s.regular)
    n_op = s.cycle["n_R_operating"]
    # the continuous regular-workspace measure: full settings on the fine grids, the lighter search settings
    # (experiment.regular_workspace.search_refine) on the search grids, or the grid's measure there
    refine = {"rw_refine": True} if fine else (
        {"rw_refine": True, "rw_refine_steps": s.search_refine[0], "rw_refine_samples": s.search_refine[1]}
        if s.search_refine else {"rw_refine": False})
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
                                 operating=operating_spec(s),  # rtmode
                                 **refine)


def operating_spec(s):  # rtmode: the screw linkage is sized for the design space's R range
    """The R(t) operating spec of ``experiment.reconfig`` (None in the default per-task mode)."""
    from .operating import OperatingError, spec_from_settings

    b = s.bounds
    rr = (b["R_min"][0], b["R_max"][1]) if "R_min" in b and "R_max" in b else None
    try:
        return spec_from_settings(s.reconfig, rr)
    except OperatingError as err:
        raise SetupError(str(err)) from None


def setup(s, robot, recon, *, n_R: Optional[int] = None):
    """(design space, coarse problem, GA config) for settings ``s``. The baseline is the configured robot
    (reconfigurable if it has an R range) with the motor's rotor inertia and the gear ratio
    ``motor.gear_ratio`` in its mass model. Raises :class:`SetupError` (one line naming the field)."""
    import equinox as eqx
    import jax.numpy as jnp

    from ..constraints import ConstraintError
    from . import DesignSpace, DesignSpaceError, GAConfig, GAError

    base = recon if recon is not None else robot
    rob = base.robot if recon is not None else base
    if rob.mass is None:
        raise SetupError("robot.mass is required by experiment=ga_reconfig (the cycle rate needs dynamics)")
    dt = rob.mass.gear_ratio.dtype
    rob = eqx.tree_at(lambda r: (r.mass.gear_ratio, r.mass.rotor_inertia), rob,
                      (jnp.asarray(s.motor["gear_ratio"], dt), jnp.asarray(s.motor["rotor_inertia"], dt)))
    base = eqx.tree_at(lambda r: r.robot, base, rob) if recon is not None else rob
    try:
        space = DesignSpace.from_bounds(base, s.bounds, n_R=s.n_R if n_R is None else n_R,
                                        prefix="experiment.design.bounds")
        ga = GAConfig.from_mapping(s.ga, seed=0)
        pb = designer_problem(s)
    except (DesignSpaceError, GAError, ConstraintError, ValueError) as err:
        raise SetupError(str(err)) from None
    return space, pb, ga


# -- compiled per-design programs, shared by value -----------------------------------------------------------------
# Every run builds its problem and design space afresh, and a jitted closure over a fresh object is traced and
# compiled again (a toy run traces its stages for ~40 CPU-s before any compile). The stages' programs are kept
# here under the *content* of the problem and space they close over, so a resumed run, a rerun or another run
# with the same grids in the same process reuses them: the same content gives the same program, hence the same
# numbers as compiling it afresh.
_PROGRAMS: dict = {}
_PROGRAMS_MAX = 16


def _content_key(x) -> Any:
    """A hashable value of everything ``x`` holds (dataclasses and equinox modules field by field, arrays by
    dtype, shape and bytes); an object it cannot see into is keyed by identity (never a false match: the cached
    program keeps it alive)."""
    if isinstance(x, (np.ndarray, np.generic)) or type(x).__module__.startswith("jax"):
        try:
            a = np.asarray(x)
        except Exception:  # noqa: BLE001 - not an array after all (e.g. a tracer): identity
            return ("id", id(x))
        if a.dtype != object:
            return ("array", a.dtype.str, a.shape, a.tobytes())
        return ("objects", a.shape, tuple(_content_key(v) for v in a.reshape(-1)))
    if x is None or isinstance(x, (bool, int, float, complex, str, bytes)):
        return (type(x).__name__, repr(x))
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return (type(x).__module__, type(x).__qualname__,
                tuple((f.name, _content_key(getattr(x, f.name))) for f in dataclasses.fields(x)))
    if isinstance(x, (tuple, list)):
        return (type(x).__qualname__, tuple(_content_key(v) for v in x))
    if isinstance(x, Mapping):
        return ("mapping", tuple(sorted((repr(k), _content_key(v)) for k, v in x.items())))
    return ("id", id(x))


def _shared(kind: str, pb, space, settings: tuple, build: Callable[[], Any]) -> Any:
    """The program ``build()`` for (``kind``, the content of ``pb`` and ``space``, ``settings``), built once per
    process (least recently used dropped beyond ``_PROGRAMS_MAX``)."""
    key = (kind, _content_key(pb), _content_key(space), settings)
    if key in _PROGRAMS:
        _PROGRAMS[key] = _PROGRAMS.pop(key)          # most recently used last
    else:
        _PROGRAMS[key] = build()
        while len(_PROGRAMS) > _PROGRAMS_MAX:
            _PROGRAMS.pop(next(iter(_PROGRAMS)))
    return _PROGRAMS[key]


def batch_evaluator(pb, space, batch: int, *, regular: bool = True) -> Callable[[np.ndarray], dict]:
    """``genes (n, d) -> {metric: (n,)}`` host arrays, compiled once for ``batch`` rows (and shared by every
    evaluator of the same problem, space and settings in this process)."""
    def build():
        import jax

        from .designer import evaluate_designer
        from .pareto import padded_batch

        f = jax.jit(jax.vmap(lambda g: evaluate_designer(pb, space.decode(g), regular=regular)))
        call = padded_batch(f, batch)
        return lambda X: {k: np.asarray(v) for k, v in call(np.asarray(X)).items()}

    return _shared("batch_evaluator", pb, space, (int(batch), bool(regular)), build)


def objective_matrix(m: Mapping[str, np.ndarray], objs: Sequence[str], scale: np.ndarray) -> np.ndarray:
    """Minimised, normalised objectives (n, k): sense x metric / |baseline metric|."""
    return np.stack([np.asarray(m[o], float) for o in objs], axis=1) * scale


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
    from .pareto import non_dominated

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
    import jax
    import jax.numpy as jnp

    from .designer import evaluate_designer

    objs, wvec = tuple(objs), np.asarray(wvec, float)
    regular = any(o.startswith("regular") and w != 0 for o, w in zip(objs, wvec))

    def build():
        wj = jnp.asarray(wvec)

        def fitness(genes):
            m = jax.vmap(lambda g: evaluate_designer(pb, space.decode(g), regular=regular))(genes)
            f = sum(wj[i] * m[o] for i, o in enumerate(objs) if wvec[i] != 0)
            f = jnp.where(jnp.isfinite(f), jnp.clip(f, -1e2, 1e2), 1e2)
            fit = jnp.where(m["violation"] > 0, 1e3 + m["violation"], f)
            return fit, {"feasible": m["feasible"], "violation": m["violation"], "picks_per_min": m["picks_per_min"]}

        return fitness

    # one function object per content: run_ga's compiled engine is cached per fitness function
    return _shared("ga_fitness", pb, space, (objs, _content_key(wvec)), build)


def pareto_eval(evaluate: Callable[[np.ndarray], dict], objs: Sequence[str], scale: np.ndarray):
    """pymoo's ``X -> (F, G)`` from a batch evaluator (G <= 0 feasible, up to the feasibility tolerance)."""
    from .designer import FEASIBILITY_TOL

    def f(X):
        m = evaluate(np.asarray(X))
        return objective_matrix(m, objs, scale), np.asarray(m["g"]) - FEASIBILITY_TOL

    return f


# -- optax refinement --------------------------------------------------------------------------------------------

DESCENT_ROWS = 8   # rows of one compiled refine descent (the job's REFINE_MAX winners)


@dataclasses.dataclass
class RefineOutcome:
    """Refinement of each winner (rows): ``genes_before/after``, ``F_before/after`` (normalised minimised
    objectives on the search grids), ``accepted`` (an iterate was feasible, no objective worse and the primary
    strictly better), ``step`` (which iterate, 0 = the start), ``loss_history`` (steps, n)."""

    genes_before: np.ndarray
    genes_after: np.ndarray
    F_before: np.ndarray
    F_after: np.ndarray
    accepted: np.ndarray
    step: np.ndarray
    loss_history: np.ndarray


def descent_paths(pb, space, genes: np.ndarray, objs: Sequence[str], scale: np.ndarray, primary: str, *,
                  steps: int = 20, learning_rate: float = 0.01, penalty: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """Projected Adam (optax) on ``scale_primary x primary + penalty x sum(max(g, 0))`` from each row of ``genes``
    (the gene box [0, 1]^d): ``(loss history (n, steps), iterates (n, steps + 1, d), the start first)``.

    One compiled program per (problem, space, settings), run in padded batches of :data:`DESCENT_ROWS` rows (the
    refinement and :func:`deltajax.optimize.floor.solve_floor` share it). Raises ``FloatingPointError`` on any
    non-finite gradient (never zeroed)."""
    import jax
    import jax.numpy as jnp
    import optax
    from optax import projections

    from .designer import FEASIBILITY_TOL, evaluate_designer
    from .pareto import padded_batch

    genes = np.clip(np.asarray(genes, float).reshape(-1, space.dim), 0.0, 1.0)
    sp = float(scale[list(objs).index(primary)])
    reg = primary.startswith("regular")

    def loss(g):
        m = evaluate_designer(pb, space.decode(g), regular=reg)
        return sp * m[primary] + penalty * jnp.sum(jnp.maximum(m["g"] - FEASIBILITY_TOL, 0.0))

    def build():
        opt = optax.adam(learning_rate)
        # forward mode: 6 genes, and it compiles faster than reverse mode through the kernel (26 vs 34 CPU-s)
        vg = jax.jacfwd(lambda g: (loss(g), loss(g)), has_aux=True)

        @jax.jit
        def descend(G0):
            def one(g0):
                def body(carry, _):
                    g, st = carry
                    grad, val = vg(g)
                    upd, st = opt.update(grad, st, g)
                    g = projections.projection_box(optax.apply_updates(g, upd), 0.0, 1.0)
                    return (g, st), (val, g, jnp.all(jnp.isfinite(grad)))
                _, (hist, path, fin) = jax.lax.scan(body, (g0, opt.init(g0)), None, length=steps)
                return hist, path, fin
            return jax.vmap(one)(G0)
        return descend

    descend = _shared("refine_descent", pb, space, (primary, repr(sp), reg, int(steps), repr(float(learning_rate)),
                                                    repr(float(penalty))), build)
    # in batches of DESCENT_ROWS rows (padded): one compiled descent for any number of starts (the job refines
    # at most 8; a stage with fewer, e.g. without a Pareto front, reuses it)
    hist, path, fin = padded_batch(descend, DESCENT_ROWS)(genes)
    if not fin.all():
        i, k = (int(v[0]) for v in np.nonzero(~fin))
        raise FloatingPointError(f"refine: non-finite gradient of the designer's loss for design {i} at step {k} "
                                 f"(genes {path[i, max(k - 1, 0)].tolist() if k else genes[i].tolist()}); "
                                 "the refinement never zeroes a broken gradient")
    return np.asarray(hist), np.concatenate([genes[:, None, :], np.asarray(path)], axis=1)


def refine_designs(pb, space, genes: np.ndarray, objs: Sequence[str], scale: np.ndarray, primary: str, *,
                   steps: int = 20, learning_rate: float = 0.01, penalty: float = 10.0, top: int = 3,
                   evaluate: Optional[Callable] = None, evaluate_cheap: Optional[Callable] = None,
                   progress: Optional[Callable[[int], Any]] = None) -> RefineOutcome:
    """:func:`descent_paths` from each row of ``genes``, then an acceptance rule on the true constraints.

    The cycle rate carries implicit-function derivatives (:func:`deltajax.constraints.cycle_rate`); the task
    coverage is a step function (zero derivative), so the true constraints decide: every iterate is evaluated
    without the regular workspace, the ``top`` best feasible iterates that improve the primary are evaluated
    with it, and the best of those with no objective worse than the start is kept. Raises
    ``FloatingPointError`` on any non-finite gradient (never zeroed).
    """
    genes = np.clip(np.asarray(genes, float).reshape(-1, space.dim), 0.0, 1.0)
    n, d = genes.shape
    jp = list(objs).index(primary)
    sp = float(scale[jp])
    hist, cand = descent_paths(pb, space, genes, objs, scale, primary, steps=steps, learning_rate=learning_rate,
                               penalty=penalty)
    if progress is not None:
        progress(1)
    evaluate_cheap = evaluate_cheap or batch_evaluator(pb, space, 64, regular=False)
    evaluate = evaluate or batch_evaluator(pb, space, 16)
    cheap = evaluate_cheap(cand.reshape(-1, d))
    P = np.asarray(cheap[primary], float).reshape(n, steps + 1) * sp                # minimised
    ok = cheap["feasible"].astype(bool).reshape(n, steps + 1) & np.isfinite(P)
    better = ok & (P < P[:, :1])
    better[:, 0] = False
    picks = []
    for i in range(n):
        idx = np.flatnonzero(better[i])
        picks.append([0] + list(idx[np.argsort(P[i, idx], kind="stable")][:top]))
    rows = [(i, k) for i in range(n) for k in picks[i]]
    full = evaluate(np.stack([cand[i, k] for i, k in rows]))
    F = objective_matrix(full, objs, scale)
    feas = full["feasible"].astype(bool)
    if progress is not None:
        progress(1)
    F_before, F_after = np.zeros((n, len(objs))), np.zeros((n, len(objs)))
    after, step, acc = genes.copy(), np.zeros(n, int), np.zeros(n, bool)
    r = 0
    for i in range(n):
        k_rows = list(range(r, r + len(picks[i])))
        r += len(picks[i])
        F0 = F[k_rows[0]]
        F_before[i] = F_after[i] = F0
        for j, k in zip(k_rows[1:], picks[i][1:]):          # best primary first
            if feas[j] and np.all(F[j] <= F0 + 1e-12) and F[j][jp] < F0[jp]:
                after[i], step[i], acc[i], F_after[i] = cand[i, k], k, True, F[j]
                break
    return RefineOutcome(genes_before=genes, genes_after=after, F_before=F_before, F_after=F_after, accepted=acc,
                         step=step, loss_history=hist.T)


# -- verification and recommendation ------------------------------------------------------------------------------

def verify(pb_fine, space, cand: np.ndarray, *, batch: int = 8,
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
    from .designer import knee_point

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


# -- results-file bookkeeping (checkpoint, restaging, stages) -------------------------------------------------------

_H5_INTERNAL = {"units", "CLASS", "NAME", "REFERENCE_LIST", "DIMENSION_LIST", "_Netcdf4Dimid", "_Netcdf4Coordinates"}


def _history_name(k: str) -> str:
    return k.replace("/", "__")


def load_checkpoint(path) -> Any:
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


def put_checkpoint(res, ck: Mapping[str, Any]) -> None:
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


def _attr(v):
    if isinstance(v, bytes):
        return v.decode()
    if isinstance(v, np.generic):
        return v.item()
    return v


def restage(res, path: Path) -> None:
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
            res.put(prefix, name, data, units=_attr(item.attrs.get("units", "1")), dims=dims, attrs=attrs)

    with h5py.File(path, "r") as f:
        for k, v in f.attrs.items():
            if k not in ("start_time",):
                res.attrs.setdefault(k, _attr(v))
        walk(f, "")


def job_fingerprint(cfg) -> str:
    """Hash of everything that determines a run's results (not resume/stop_after/progress/plots)."""
    from omegaconf import OmegaConf

    c = OmegaConf.to_container(cfg, resolve=True)
    e = dict(c.get("experiment", {}))
    e.pop("resume", None)
    e.pop("stop_after", None)
    blob = json.dumps({"experiment": e, "robot": c.get("robot"), "seed": c.get("seed"),
                       "precision": c.get("precision")}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def stages_done(path: Path) -> tuple[Optional[str], list]:
    """(fingerprint, finished stages) recorded in ``path``; (None, []) when there is no file. Raises OSError
    (with the path) when it exists but cannot be read."""
    import h5py

    if not path.exists():
        return None, []
    with h5py.File(path, "r") as f:
        fp = _attr(f.attrs.get("ga_reconfig_fingerprint", ""))
        st = _attr(f.attrs.get("ga_reconfig_stages", ""))
    return (fp or None), [x for x in str(st).split(",") if x]
