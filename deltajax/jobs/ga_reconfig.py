"""Experiment ``ga_reconfig`` (the main job): which Delta should a designer build for this task?

    python -m deltajax.run experiment=ga_reconfig
    python -m deltajax.run experiment=ga_reconfig experiment.pareto.population_size=48 experiment.pareto.generations=40
    python -m deltajax.run experiment=ga_reconfig hydra.run.dir=<dir of a killed run>      # resume
    python -m deltajax.run experiment=ga_reconfig experiment.continue_from=<a finished run> <larger budget>

The problem (``configs/experiment/ga_reconfig.yaml``, read by :func:`deltajax.config.ga_reconfig_settings`):
serve a task cylinder with the 25/305/25 mm cycle and a payload, with given servo motors through a gearbox
whose ratio is a design variable; maximise picks per minute and the regular workspace subject to the task
in the good workspace, passive joints, interference, motor envelope and RMS rating, and a size budget.

Stages (the library: :mod:`deltajax.optimize.workflow`; each stored in ``results.h5``, a rerun into the same
``hydra.run.dir`` resumes after the last finished one and a finished run is a no-op):
baseline -> screen (Sobol, seeds the GA) -> ga (checkpointed) -> pareto (NSGA-II) -> refine (optax) ->
verify (fine grids, the regular workspace found by rays, recommendation) -> certify (the baseline and the
recommendation: worst cases searched at the verification's density and at twice it, margins in units,
:mod:`deltajax.optimize.certify`; the recommendation re-derived with the certified figures) -> tolerance (Monte
Carlo over manufacturing and model tolerances on the certified answer, :mod:`deltajax.optimize.robust`;
``experiment.robust``: the robust recommendation) -> results (summary) ->
plots -> report (``report.html``, the self-contained run report of :mod:`deltajax.runreport`). ``experiment.continue_from`` (more budget for
a finished run, :func:`deltajax.config.ga_reconfig_run.earlier_run`): its verified front seeds the GA and NSGA-II and
joins the verified candidates with its stored metrics, so the recommendation cannot be one its recommendation
dominates.
The GA paper's claims are *not* compared here (different metrics); see docs/REPRODUCTION.md §5.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import jax.numpy as jnp

from ..config import ConfigError, GaReconfigSettings as Settings, ga_reconfig_build, ga_reconfig_settings
from . import designer_report as R, designer_state as ST, designer_store as DS
from .stages import Runner, Stage, State, Stop, release_memory, resize_bar
from ..optimize.designer import CONSTRAINT_NAMES, DESIGN_SENSE, DESIGN_UNITS, FEASIBILITY_TOL
from ..io import load, load_groups, write_atomic
from ..optimize import certify as CE, GAError, robust as RB, run_ga, workflow as W
from ..rundir import CheckpointError
from ..optimize.pareto import hypervolume, non_dominated, nsga2
from ..optimize.floor import solve_floor
from ..tracing import forget
from .. import export, tolerance as TL
from ..optimize.certify import overlay
from .datasheet import run_designs, write
from ..runreport import report_path, write_report

__all__ = ["run", "build", "settings_from_config", "Settings", "STAGES"]

SCREEN_FRONT_EVAL = 1024  # at most this many feasible screen designs (best primary first) get the regular workspace
REFINE_MAX = 8          # winners refined: the GA's best and the front's best 7 on the primary objective
settings_from_config = ga_reconfig_settings
build = ga_reconfig_build


def run(ctx) -> None:
    """The main job: its settings and problem built once, then the two lists of stages (:data:`SEARCH`, whose
    stages hand on in memory, and :data:`ANSWER`, whose stages read the results file) on the stage engine."""
    setup = ctx.settings                     # built and checked once, before anything compiled
    s, space, earlier = setup.settings, setup.space, setup.earlier
    runner, path, fp = Runner(ctx, "ga_reconfig"), ctx.run_dir / "results.h5", setup.fingerprint
    runner.checkpoint("ga", **ST.GA_CHECKPOINT)     # the GA commits its generations through the stage engine
    done = runner.open(fp, resume=s.resume)
    if "report" in done:
        ctx.log(f"{path} holds a complete ga_reconfig run (stages {','.join(done)}); nothing to do")
        return
    objs = list(s.objectives.names)
    sense = np.asarray([DESIGN_SENSE[o] for o in objs], float)
    carried = earlier.genes if earlier is not None else np.zeros((0, space.dim))
    st = State(ctx=ctx, res=ctx.results, path=path, fp=fp, s=s, space=space, pb=setup.problem, seed=ctx.seed,
               ga_cfg=setup.ga, earlier=earlier, objs=objs,
               primary=s.objectives.primary, jp=objs.index(s.objectives.primary), sense=sense, carried=carried,
               base_genes=space.baseline_genes(), scr_front=np.zeros((0, space.dim)),
               front_X=np.zeros((0, space.dim)), extra_X=np.zeros((0, space.dim)),
               refined=np.zeros((0, space.dim)), ref=np.where(sense < 0, 0.0, s.pareto.ref_min_factor),
               stored=_stored(path, done))
    st.seeds = np.concatenate([st.base_genes[None], carried])
    if runner.run(SEARCH, st):
        runner.run(ANSWER, st)


def _stored(path, done) -> dict:
    return load(path, verify=True) if path.exists() and done else {}


# -- the search: stages that hand on in memory ----------------------------------------------------------------------

def _prepare(st: State) -> None:
    """The evaluators and the baseline on the search grids (it normalises the objectives)."""
    ctx, s, space, pb, objs = st.ctx, st.s, st.space, st.pb, st.objs
    st.ev = W.batch_evaluator(pb, space, max(s.pareto.population_size, 2))
    st.ev_cheap = W.batch_evaluator(pb, space, 64, regular=False)   # screen, refinement (no regular workspace)
    if st.earlier is not None:
        ctx.log(f"continuing {st.earlier.path}: its {len(st.carried)} verified front designs seed the GA and NSGA-II "
                "and join the verified candidates with their verified metrics (so this run's recommendation is "
                "never one that the earlier run's recommendation dominates)")
    ctx.log(f"design space: {dict(zip(space.names, zip(space.lower, space.upper)))} ({space.dim} genes, n_R="
            f"{space.n_R}); {len(pb.task_points)} task samples, {pb.cycle.n_samples} cycle samples, regular grid "
            f"{pb.rw_points.shape[:3]}")
    base = {k: v[0] for k, v in st.ev(st.base_genes[None]).items()}
    for o in objs:
        if not (np.isfinite(base[o]) and base[o] != 0):
            raise ConfigError(f"experiment.objectives.names: the baseline's {o} is {float(base[o])!r}, which "
                              "cannot normalise it; loosen the constraints or move the task")
    st.base = base
    st.scale = st.sense / np.abs(np.asarray([float(base[o]) for o in objs]))
    if not bool(base["feasible"]):
        bad = [n for n, g in zip(CONSTRAINT_NAMES, base["g"]) if g > FEASIBILITY_TOL]
        # a coarse-grid estimate that only steers the search (the baseline still normalises the objectives and
        # seeds the GA); the fine grids can find it feasible, and the table at the end is on the fine grids
        ctx.log(f"note: on the coarse search grids the baseline violates {bad}; the verified table at the end (fine "
                "grids) is authoritative for every design, the baseline included")


def _screen(st: State) -> None:
    """Sobol designs without the regular workspace; the best feasible ones seed the GA, the feasible non-dominated
    ones (regular workspace evaluated for them only) seed NSGA-II."""
    ctx, res, s, space, primary = st.ctx, st.res, st.s, st.space, st.primary
    bar = ctx.progress(total=2 ** s.screen.log2_size, desc="screen (Sobol)")
    sc = W.screen(st.ev_cheap, space, primary, st.sense[st.jp], s.screen.log2_size, seed=st.seed,
                  progress=bar.update)
    bar.close()
    top = sc["X"][sc["order"][:max(int(s.screen.seed_fraction * st.ga_cfg.population_size), 1)]]
    res.put_axis("screen", "seed_design", np.arange(len(top)), units="1")
    res.put_axis("screen", "gene", np.arange(space.dim), units="1")
    res.put("screen", "top_genes", top, units="1", dims=("seed_design", "gene"))
    res.put("screen", "top_primary", sc[primary][sc["order"][:len(top)]], units=DESIGN_UNITS[primary],
            dims=("seed_design",))
    res.set_attrs("screen", designs=len(sc["X"]), feasible=int(sc["feasible"].sum()), sampler="scrambled "
                  f"Sobol (scipy.stats.qmc), seed {st.seed}", grids="search grids, regular workspace skipped")
    # the screen's feasible non-dominated set on the job's objectives (regular workspace evaluated for the feasible
    # designs only) seeds NSGA-II: the GA's population crowds the primary's end of the front
    st.scr_front = W.screen_front(st.ev, sc, st.objs, st.scale, cap=SCREEN_FRONT_EVAL, layers=True)
    res.put_axis("screen", "front_design", np.arange(len(st.scr_front)), units="1")
    res.put("screen", "front_genes", st.scr_front, units="1", dims=("front_design", "gene"),
            attrs={"meaning": "feasible screen designs in non-dominated-sorting order on the search grids "
                              "(the first population_size/2 seed NSGA-II)"})
    ctx.log(f"screen: {len(sc['X'])} Sobol designs, {int(sc['feasible'].sum())} feasible; best {primary} "
            f"{sc[primary][sc['order'][0]] if len(sc['order']) else float('nan'):.4g}; "
            f"its feasible designs ranked by non-dominated sorting on {st.objs} seed NSGA-II")
    st.seeds = np.concatenate([st.seeds, top])


def _screen_load(st: State) -> None:
    scr = st.stored["screen"]
    if "front_genes" not in scr:  # staged by a deltajax before the NSGA-II seeding
        raise CheckpointError(f"{st.res.path}: its finished screen stage has no screen/front_genes (written by an "
                              "older deltajax); resume it with that version, or start a new run directory")
    st.scr_front = np.asarray(scr["front_genes"]).reshape(-1, st.space.dim)
    st.seeds = np.concatenate([st.seeds, np.asarray(scr["top_genes"]).reshape(-1, st.space.dim)])


def _ga_result(st: State, finished: bool) -> None:
    """The GA on the primary objective (or the weighted sum), run or resumed from its checkpoint in the results
    file (the runner's: verified, of this run, committed every ``checkpoint_every`` generations; a finished GA is
    read back from it); :class:`Stop` after ``experiment.stop_after`` generations."""
    ctx, s, space, objs, primary, ga_cfg = st.ctx, st.s, st.space, st.objs, st.primary, st.ga_cfg
    wvec = (np.asarray([s.objectives.weights.get(o, 0.0) for o in objs]) * st.scale if s.objectives.mode == "weighted"
            else np.where(np.asarray(objs) == primary, st.scale, 0.0))
    st.ga_what = ("weighted sum " + " + ".join(f"{s.objectives.weights.get(o, 0.0):g} x {o}" for o in objs)
                  if s.objectives.mode == "weighted" else f"primary objective {primary}")
    checkpoint = st.runner.checkpoints["ga"]
    ck = None if s.resume == "never" else checkpoint.load()
    ctx.log("GA stage already finished: reusing its checkpoint" if finished else
            f"resuming the GA from generation {ck['generations_done']}" if ck else f"starting the GA ({st.ga_what})")
    bar = ctx.progress(total=ga_cfg.generations, desc=f"GA {ga_cfg.algorithm}")
    bar.update(int(ck["generations_done"]) if ck else 0)

    try:
        gres = run_ga(W.ga_fitness(st.pb, space, objs, wvec), space.dim, ga_cfg, init_genes=st.seeds, checkpoint=ck,
                      save_checkpoint=checkpoint.commit, stop_after=s.stop_after, progress=bar.update,
                      program_key=W.ga_fitness_key(st.pb, space, objs, wvec))
    except GAError as err:
        raise ConfigError(f"{err} ({st.path})") from None
    finally:
        bar.close()
    if gres.generations_done < ga_cfg.generations:
        raise Stop(f"stopped after {gres.generations_done} generations (experiment.stop_after); rerun with "
                   f"hydra.run.dir={ctx.run_dir} to resume")
    st.gres, st.best = gres, gres.best_genes
    if finished:
        ctx.log(f"GA best ({st.ga_what}): fitness {gres.best_fitness:.5g}, {space.describe(st.best)}")


def _ga(st: State) -> None:
    _ga_result(st, finished=False)
    DS.store_ga(st.res, st.gres, st.space, st.ga_cfg, st.ga_what, st.base_genes, st.seeds,
               float(st.base[st.primary]), np.asarray(st.space.to_params(jnp.asarray(st.best))), st.fp)
    st.ctx.log(f"GA best ({st.ga_what}): fitness {st.gres.best_fitness:.5g}, {st.space.describe(st.best)}")


def _pareto(st: State) -> None:
    """NSGA-II on the job's objectives, seeded with the baseline, the GA's best and final population, a continued
    run's front and the screen's non-dominated designs."""
    s, space = st.s, st.space
    bar = st.ctx.progress(total=s.pareto.generations, desc="NSGA-II")
    front = nsga2(W.pareto_eval(st.ev, st.objs, st.scale), space.dim, len(st.objs), n_constr=len(CONSTRAINT_NAMES),
                  pop_size=s.pareto.population_size, n_gen=s.pareto.generations, seed=st.seed,
                  initial=np.concatenate([st.base_genes[None], st.best[None], st.carried,
                                          st.scr_front[:s.pareto.population_size // 2],
                                          st.gres.final_population]), ref=st.ref,
                  progress=bar.update)
    bar.close()
    st.front_X = front.X
    pfeas = np.all(front.pop_G <= 0, axis=1)
    extra = np.asarray([x for x in front.pop_X[pfeas] if not np.any(np.all(front.X == x, axis=1))])
    st.extra_X = extra.reshape(-1, space.dim)
    DS.store_pareto(st.res, front, st.extra_X, st.objs, s)
    st.ctx.log(f"NSGA-II: {len(front.X)} feasible non-dominated points after {front.n_evals} evaluations")


def _pareto_load(st: State) -> None:
    st.front_X = np.asarray(st.stored["pareto"]["genes"]).reshape(-1, st.space.dim)
    st.extra_X = np.asarray(st.stored["pareto"]["population_feasible_genes"]).reshape(-1, st.space.dim)


def _refine(st: State) -> None:
    """optax refinement of the winners: the GA's best and the front's best on the primary objective."""
    s, sense, jp, primary = st.s, st.sense, st.jp, st.primary
    bar = st.ctx.progress(total=2, desc="refine (optax)")
    # the front is sorted by the first objective: its best on the primary objective
    prim = (st.ev if primary.startswith("regular") else st.ev_cheap)(st.front_X)[primary] if len(st.front_X) else []
    order = np.argsort(sense[jp] * np.nan_to_num(prim, nan=-sense[jp] * np.inf))
    winners = np.concatenate([st.best[None], st.front_X[order[:REFINE_MAX - 1]]])
    ro = W.refine_designs(st.pb, st.space, winners, st.objs, st.scale, primary,
                          steps=s.refine.steps, learning_rate=s.refine.learning_rate,
                          penalty=s.refine.penalty, evaluate=st.ev, evaluate_cheap=st.ev_cheap,
                          progress=bar.update)
    bar.close()
    st.refined = ro.genes_after[ro.accepted]
    DS.store_refine(st.res, ro, st.refined, st.space, st.objs, s)
    gain = (ro.F_after[:, jp] / ro.F_before[:, jp] - 1.0)[ro.accepted] * 100
    st.ctx.log(f"refine: {int(ro.accepted.sum())} of {len(ro.accepted)} winners improved ({primary} "
               f"+{np.max(gain) if len(gain) else 0.0:.2f} % at most, every constraint kept)")


def _refine_load(st: State) -> None:
    st.refined = np.asarray(st.stored["refine"]["accepted_genes"]).reshape(-1, st.space.dim)


def _verify(st: State) -> None:
    """Every candidate on the fine grids (the regular workspace found by rays), a continued run's front joined with
    the metrics it verified, the floor step, and the recommendation by the job's rule."""
    ctx, s, space, earlier, carried = st.ctx, st.s, st.space, st.earlier, st.carried
    space_v = dataclasses.replace(space, n_R=s.verify.n_R) if space.reconfigurable else space
    pb_fine = W.designer_problem(s, fine=True)
    cand = np.concatenate([st.base_genes[None], st.best[None], st.front_X, st.refined, st.extra_X])
    names = (["baseline", "ga_best"] + [f"pareto_{i}" for i in range(len(st.front_X))]
             + [f"refined_{i}" for i in range(len(st.refined))] + [f"population_{i}" for i in range(len(st.extra_X))])
    ga_best_name = "ga_best"
    if earlier is not None:     # a design the earlier run verified (e.g. a seed the GA kept) keeps its name there
        keep = [i for i in range(len(cand)) if i == 0 or not np.any(np.all(carried == cand[i], axis=1))]
        cand, names = cand[keep], [names[i] for i in keep]
        same = np.flatnonzero(np.all(carried == st.best, axis=1))
        ga_best_name = earlier.names[same[0]] if len(same) else ga_best_name
    bar = ctx.progress(total=len(cand), desc="verify (fine grids)")
    mv = W.verify(pb_fine, space_v, cand, progress=bar.update)
    bar.close()
    if earlier is not None:                                     # the earlier run's front, as it verified it
        try:
            mv = ST.carry_earlier(mv, earlier, st.objs)
        except W.SetupError as err:
            raise ConfigError(str(err)) from None
        cand, names = np.concatenate([cand, carried]), names + list(earlier.names)
    n_before_floor = len(cand)
    bv = np.asarray([float(mv[o][0]) for o in st.objs])           # normalised by the *verified* baseline
    scale_v = np.where(np.isfinite(bv) & (bv != 0), st.sense / np.abs(np.where(bv != 0, bv, 1)), st.scale)
    Fv, ok, nd = _front_of(mv, st.objs, scale_v)
    if s.recommend == "floor" and s.floor_solve.enabled:
        cand, names, mv, Fv, ok, nd = _floor_step(st, cand, names, mv, Fv, nd, pb_fine, space_v, scale_v)
    elif s.floor_solve.enabled:
        ctx.log(f"floor step: skipped (it solves for the floor rule's answer; experiment.recommend={s.recommend})")
    rec = W.recommend(Fv, nd, s.recommend, st.jp, band=s.recommend_band, floor=s.recommend_floor, sense=st.sense)
    hv = hypervolume(Fv[nd], st.ref) if len(nd) else 0.0
    DS.store_verify(st.res, space, cand, names, mv, Fv, nd, rec, hv, hypervolume(Fv[:1], st.ref), st.ref, st.objs, s)
    st.res.set_attrs("verify", ga_best_design=ga_best_name)
    if earlier is not None:
        st.res.set_attrs("verify", continued_from=str(earlier.path), continued_from_fingerprint=earlier.fingerprint,
                         carried_designs=",".join(earlier.names))
        if earlier.recommended >= 0 and rec >= 0:
            e_rec = n_before_floor - len(carried) + earlier.recommended
            ctx.log(f"continued run: the earlier recommendation {names[e_rec]} ("
                    + ", ".join(f"{o} {float(mv[o][e_rec]):.5g}" for o in st.objs) + f") -> {names[rec]} ("
                    + ", ".join(f"{o} {float(mv[o][rec]):.5g}" for o in st.objs) + ")"
                    + (": kept, nothing verified here does better by the rule" if rec == e_rec else ""))
    ctx.log(f"verified on the fine grids: {len(cand)} candidates, {len(ok)} feasible; front {len(nd)} points, "
            f"hypervolume {hv:.4g}; recommended: {names[rec] if rec >= 0 else 'none'} ({R.rule_text(s)})")


def _front_of(mv, objs, scale_v):
    """(objective matrix, feasible rows with finite objectives, their non-dominated rows in lexicographic order)."""
    Fv = W.objective_matrix(mv, objs, scale_v)
    ok = np.flatnonzero(mv["feasible"].astype(bool) & np.all(np.isfinite(Fv), axis=1))
    nd = ok[non_dominated(Fv[ok])] if len(ok) else np.zeros((0,), int)
    return Fv, ok, (nd[np.lexsort(Fv[nd].T[::-1])] if len(nd) else nd)


def _floor_step(st, cand, names, mv, Fv, nd, pb_fine, space_v, scale_v):
    """The floor rule's answer solved for (:func:`deltajax.optimize.floor.solve_floor`): descents from the verified
    front points that meet the floor, their iterates verified on the fine grids and joined to the candidates."""
    s, ctx = st.s, st.ctx
    bar = ctx.progress(total=s.floor_solve.rounds + 1, desc="floor step")
    fo = solve_floor(st.pb, st.space, cand, Fv, nd, st.objs, st.scale, st.primary,
                     W.floor_limits(len(st.objs), st.jp, s.recommend_floor, st.sense), evaluate=st.ev,
                     evaluate_cheap=st.ev_cheap, evaluate_fine=W.batch_evaluator(pb_fine, space_v, W.VERIFY_BATCH),
                     steps=s.refine.steps, learning_rate=s.refine.learning_rate,
                     penalty=s.refine.penalty, rounds=s.floor_solve.rounds,
                     n_fine=s.floor_solve.candidates, progress=bar.update)
    bar.close()
    # an iterate equal to a design already verified (e.g. one a continued run carried from the earlier run, whose
    # own floor step descended from the same start) is not verified twice under two names
    fresh = np.flatnonzero([not np.any(np.all(cand == g, axis=1)) for g in fo.genes])
    if len(fresh) < len(fo.genes):
        fo = dataclasses.replace(fo, genes=fo.genes[fresh], start=fo.start[fresh], step=fo.step[fresh],
                                 metrics={k: v[fresh] for k, v in fo.metrics.items()}, predicted=fo.predicted[fresh])
    if len(fo.genes):
        first = len(cand)
        cand = np.concatenate([cand, fo.genes])
        names = names + [f"floor_{i}" for i in range(len(fo.genes))]
        mv = {k: np.concatenate([mv[k], fo.metrics[k]]) for k in mv}
        DS.store_floor(st.res, fo, names, first, st.objs, s)
    Fv, ok, nd = _front_of(mv, st.objs, scale_v)
    ctx.log(f"floor step: descents from {len(fo.starts)} verified front points that meet the floor, "
            f"{fo.n_predicted} iterates predicted to meet it, {len(fo.genes)} verified on the fine grids")
    return cand, names, mv, Fv, ok, nd


# -- the answer: stages that read the results file ------------------------------------------------------------------

def _results(st: State) -> None:
    R.summary(st.ctx, st.res, load(st.path), st.space, st.objs, st.s)
    st.res.set_attrs("ga_reconfig", **{f"time_{k}_s": v for k, v in st.runner.timings.items()})


def _plots(st: State) -> None:
    data = load(st.path)
    R.print_summary(st.ctx, data)
    R.plots(st.ctx, data, st.objs, st.s)
    st.ctx.write_figures()                  # the stage is done once its figures are on disk, not before


#: The search: stages whose results the next ones read from memory (a finished stage's are read back first).
SEARCH = (
    Stage("prepare", _prepare, record=False),
    Stage("screen", _screen, load=_screen_load,
          when=lambda st: st.s.screen.enabled and not st.primary.startswith("regular")),
    Stage("ga", _ga, load=lambda st: _ga_result(st, finished=True)),
    Stage("pareto", _pareto, load=_pareto_load, when=lambda st: st.s.pareto.enabled),
    Stage("refine", _refine, load=_refine_load, when=lambda st: st.s.refine.enabled),
    Stage("verify", _verify),
)


def _certify(st: State, *, max_rounds: int = 4) -> None:
    """The certify stage (:mod:`deltajax.optimize.certify`): the baseline and the recommendation certified (worst
    cases searched at the verification's density and at twice it, the change stated); the recommendation re-derived
    by the job's rule from the verified metrics with the certified ones in place (floor from the certified
    baseline), and certified in turn, until the rule's answer is a certified design
    (:func:`deltajax.optimize.certify.certify_by_rule`: a design's task and cycle figures first, its regular
    workspace only if the rule stays with it; at most ``max_rounds`` designs with their regular workspace).
    Group ``certify`` (:func:`deltajax.jobs.designer_store.store_certify`); ``verify``'s ``recommended`` becomes
    the certified recommendation (``recommended_verified`` keeps the verification's)."""
    ctx, res, s, space, objs, sense, jp = st.ctx, st.res, st.s, st.space, st.objs, st.sense, st.jp
    V = load(st.path, "verify")
    space_v = dataclasses.replace(space, n_R=s.verify.n_R) if space.reconfigurable else space
    pb = W.designer_problem(s, fine=True)
    names = [str(n) for n in np.asarray(V["design_name"]).reshape(-1)]
    genes = np.asarray(V["genes"], float).reshape(len(names), -1)
    R_op = np.asarray(V["R_operating"], float).reshape(-1)
    mv = {k: np.array(V[k], dtype=float, copy=True).reshape(-1) for k in set(CE.CERTIFIED_METRICS) | {"arm_sum"}
          if k in V}
    feas = np.asarray(V["feasible"]).astype(bool).reshape(-1).copy()
    rec0 = int(V["attrs"]["recommended"])
    cert: dict = {}
    path = s.reconfig.get("mode", "per_task") == "path"
    bar = ctx.progress(total=2, desc="certify (worst cases, doubled density)")

    def certify(i, regular):
        resize_bar(bar, max(bar.total, len(cert) + 1))   # the rule may move on to more designs than planned
        # the first density's rays: the verification's (same problem, rays, operating R; in mv until certified)
        c = CE.certify_design(pb, space_v.decode(jnp.asarray(genes[i])), R_op[i],
                              regular_first={k: mv[k][i] for k in CE.REGULAR_FIGURES},
                              max_extra_doublings=int(s.verify.certify_doublings), regular=regular)
        release_memory()                 # each design's densest programs free ~1 GiB that glibc would keep
        if i not in cert:
            bar.update(1)
        cert[i] = c
        for k in CE.CERTIFIED_METRICS:
            if not (path and k in CE.CYCLE_METRICS):    # mode=path: the cycle's certified figures are the fixed R's
                mv[k][i] = c[k]
        feas[i] = bool(CE.feasible_certified({k: np.asarray(v[i]) for k, v in mv.items()}, pb))
        ctx.log(f"certified {names[i]}: {CE.describe(c)}" + ("" if feas[i] else "; infeasible once certified"))

    def choose():
        nonlocal front, Fv
        bv = np.asarray([mv[o][0] for o in objs])
        Fv = W.objective_matrix(mv, objs, sense / np.abs(np.where(bv != 0, bv, 1.0)))
        ok = np.flatnonzero(feas & np.all(np.isfinite(Fv), axis=1))
        nd = ok[non_dominated(Fv[ok])] if len(ok) else np.zeros((0,), int)
        front = nd[np.lexsort(Fv[nd].T[::-1])] if len(nd) else nd
        return W.recommend(Fv, front, s.recommend, jp, band=s.recommend_band, floor=s.recommend_floor, sense=sense)

    front, Fv = np.zeros((0,), int), None
    rec, _ = CE.certify_by_rule(choose, certify, max_full=max_rounds)
    resize_bar(bar, len(cert))           # fewer than planned when the baseline was the answer
    bar.close()
    forget("certified")         # no later stage calls the certify programs: their compiled code goes (~0.3 GiB each)
    floor = (float(s.recommend_floor) * mv["regular_volume"][0]
             if s.recommend == "floor" and "regular_volume" in objs else None)
    marg = CE.design_margins(mv, threshold=pb.good.threshold, min_picks=pb.min_picks, max_arm_sum=pb.max_arm_sum,
                             volume_floor=floor)
    DS.store_certify(res, names, cert, feas, marg, front, Fv, rec, rec0, floor, s)
    if path:
        res.set_attrs("certify", cycle_variant="fixed_R")
    res.set_attrs("verify", recommended=int(rec), recommended_verified=int(rec0))
    if rec != rec0:
        ctx.log(f"certified recommendation: {names[rec] if rec >= 0 else 'none'} (the verification's was "
                f"{names[rec0] if rec0 >= 0 else 'none'})")


def _tolerance(st: State) -> None:
    """The tolerance stage (:mod:`deltajax.tolerance`, :mod:`deltajax.optimize.robust`): the Monte Carlo of the
    baseline and the recommendation on the verification problem (group ``tolerance``) and, with ``experiment.robust.enabled``, the robust
    recommendation (group ``tolerance/robust``; ``verify``'s ``recommended`` becomes it, ``recommended_nominal``
    keeps the nominal one)."""
    ctx, res, s, space, sense, jp = st.ctx, st.res, st.s, st.space, st.sense, st.jp
    V = overlay(load_groups(st.path, ("verify", "certify")))   # what verify and certify stored
    space_v = dataclasses.replace(space, n_R=s.verify.n_R) if space.reconfigurable else space
    pb_fine = W.designer_problem(s, fine=True, nominal=True)   # a built robot is judged by the stated constraints
    tol = R.tolerances_of(s)
    text = TL.describe(tol)
    names = [str(n) for n in V["design_name"]]
    genes = np.asarray(V["genes"], float).reshape(len(names), -1)
    rec = int(V["attrs"]["recommended"])
    n_s = int(s.tolerance.samples)

    def analyse_rows(rows, seed):
        bar = ctx.progress(total=len(rows) * (n_s + 1), desc=f"tolerance (Monte Carlo, seed {seed})")
        try:
            return TL.analyse(pb_fine, space_v, genes[list(rows)], tol, samples=n_s, seed=seed, progress=bar.update)
        finally:
            bar.close()

    ctx.log(f"tolerance: {n_s} Monte Carlo samples of {text}")
    rows = [0] + ([rec] if rec > 0 else [])
    a = analyse_rows(rows, int(s.tolerance.seed))
    entries = [("baseline", 0, 0)] + ([("recommended", rows.index(rec), rec)] if rec >= 0 else [])
    results = [a]
    if s.robust.enabled:
        Fv = np.asarray(V["F"], float).reshape(len(names), -1)

        def rule(nd):
            return W.recommend(Fv, nd, s.recommend, jp, band=s.recommend_band, floor=s.recommend_floor, sense=sense)

        known = {r: TL.select([a], [(0, i)]) for i, r in enumerate(rows)}
        rc = RB.robust_choice(analyse_rows, Fv, np.asarray(V["feasible"]).astype(bool), rule,
                              float(s.robust.probability), int(s.tolerance.seed), int(s.robust.confirm_seed),
                              int(s.robust.max_candidates), known=known, log=ctx.log)
        DS.store_robust(res, rc, names, rec, V, s, text)
        entries = [e for e in entries if e[0] != "recommended"]
        if rec >= 0:
            entries.append(("nominal_recommended", rows.index(rec), rec))
        if rc.chosen >= 0:
            results.append(rc.results[rc.chosen])
            entries.append(("recommended", (len(results) - 1, 0), rc.chosen))
            res.set_attrs("verify", recommended=int(rc.chosen), recommended_nominal=rec,
                          recommended_by=R.robust_text(s))
            ctx.log(f"robust recommendation: {names[rc.chosen]} (every constraint holds in "
                    f"{100 * rc.p_selection[rc.checked.index(rc.chosen)]:.1f} % of the samples, "
                    f"{100 * float(rc.confirm['p_all'][0]):.1f} % of a fresh Monte Carlo, seed "
                    f"{s.robust.confirm_seed}); nominal: {names[rec]}; {len(rc.checked)} candidates checked")
        else:
            res.set_attrs("verify", recommended_nominal=rec)
            if rec >= 0:
                entries.append(("recommended", rows.index(rec), rec))
            ctx.log(f"WARNING robust: no verified candidate holds every constraint in >= "
                    f"{100 * s.robust.probability:g} % of the samples ({len(rc.checked)} checked"
                    + (", every feasible one" if rc.exhausted else "") + "); the recommendation stays the nominal "
                    f"one ({names[rec] if rec >= 0 else 'none'}), which does not meet experiment.robust.probability; "
                    "to search for designs that hold with a margin, set experiment.robust.margins (group "
                    "tolerance's metric_percentiles show how far each constraint moves under the tolerances)")
    sel = TL.select(results, [(e[1] if isinstance(e[1], tuple) else (0, e[1])) for e in entries])
    roles = [e[0] for e in entries]
    DS.store_tolerance(res, roles, [names[e[2]] for e in entries], [e[2] for e in entries], sel, text)
    frozen = None
    if space.reconfigurable:    # the stricter question: each built robot run at its design's nominal operating R
        frozen = TL.analyse(pb_fine, space_v, genes[[e[2] for e in entries]], tol, samples=n_s,
                            seed=int(s.tolerance.seed), operating_R="nominal")
        DS.store_frozen(res, roles, [names[e[2]] for e in entries], [e[2] for e in entries], frozen, text)
    for line in R.headline_lines(dict(sel, role=roles, design_name=[names[e[2]] for e in entries],
                                       attrs={"samples": n_s}, frozen_R=frozen), roles):
        ctx.log(line)


def _export(st: State) -> None:
    """The baseline's and the recommendation's datasheets (group ``datasheet``, ``datasheet_<design>.png``, each at
    its operating R) and the recommendation's models: ``recommended.xml`` (MJCF), ``recommended.urdf`` and its
    loop-closure sidecar ``recommended.loops.json`` (:mod:`deltajax.export`)."""
    ctx = st.ctx
    summary = load_groups(st.path, ("summary",)).get("summary") or {}
    if "metric_name" not in summary:     # the results stage found no feasible design: nothing to take out
        ctx.log("export: no recommended design (no feasible candidate on the fine grids), so no datasheets and no "
                "model files")
        return
    designs = run_designs(st.space, summary, dataclasses.asdict(st.s.motor))
    write(ctx, designs)
    ctx.write_figures()
    recommended = [d for d in designs if d[0] == "recommended"]
    if not recommended:
        ctx.log("export: no recommended design (no feasible candidate), so no model files")
        return
    _, robot, motor, n, _ = recommended[0]
    name = "deltajax_recommended"
    text, loops = export.urdf(robot, motor=motor, gear_ratio=n, name=name)
    files = {"recommended.xml": export.mjcf(robot, motor=motor, gear_ratio=n, name=name),
             "recommended.urdf": text,
             "recommended.loops.json": json.dumps(dict(loops, urdf="recommended.urdf"), indent=1) + "\n"}
    for fname, content in files.items():
        write_atomic(ctx.run_dir / fname, content.encode())
    ctx.log(f"export -> {ctx.run_dir}: " + ", ".join(files))


def _report(st: State) -> None:
    """The run report (``report.html`` beside results.h5), drawn from the results on disk."""
    st.ctx.log(f"report -> {write_report(st.path, report_path(st.ctx.run_dir))}")


#: The answer: stages that read what the search stored (so a resumed run answers the same). A run that went past
#: a stage's place before the stage existed stays as it was (its later stages read what it had).
ANSWER = (
    Stage("certify", _certify, when=lambda st: not {"tolerance", "results"} & set(st.runner.done)),
    Stage("tolerance", _tolerance, when=lambda st: st.s.tolerance.enabled and "results" not in st.runner.done),
    Stage("results", _results),
    Stage("plots", _plots),
    Stage("export", _export),   # done once the datasheets are in results.h5, their figures and the models on disk
    Stage("report", _report),   # done once report.html is on disk
)
#: The main job's recorded stages, in order.
STAGES = tuple(x.name for x in SEARCH + ANSWER if x.record)
