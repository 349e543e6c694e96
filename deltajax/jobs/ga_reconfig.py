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
a finished run, :func:`deltajax.jobs.designer_state.earlier_run`): its verified front seeds the GA and NSGA-II and
joins the verified candidates with its stored metrics, so the recommendation cannot be one its recommendation
dominates.
The GA paper's claims are *not* compared here (different metrics); see docs/REPRODUCTION.md §5.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..config import ConfigError, GaReconfigSettings as Settings, ga_reconfig_build, ga_reconfig_settings
from ..io import ChecksumError
from ..rundir import CheckpointError
from . import designer_state as ST

__all__ = ["run", "build", "settings_from_config", "Settings", "STAGES"]

STAGES = ("screen", "ga", "pareto", "refine", "verify", "certify", "tolerance", "results", "plots", "report")
SCREEN_FRONT_EVAL = 1024  # at most this many feasible screen designs (best primary first) get the regular workspace
REFINE_MAX = 8          # winners refined: the GA's best and the front's best 7 on the primary objective
settings_from_config = ga_reconfig_settings
build = ga_reconfig_build


def _claim(ctx, s, path, fp, W):
    """Stages already finished in ``path`` (everything on disk staged into the results), or refuse."""
    old_fp, done = None, []
    try:
        old_fp, done = ST.stages_done(path)                        # verified attributes (integrity record)
    except ChecksumError as err:
        raise CheckpointError(f"cannot resume: {err}; add fresh=true to start over") from None
    except OSError as err:
        raise ConfigError(f"{path} exists but cannot be read ({err}); move it away or choose another "
                          "hydra.run.dir") from None
    if old_fp is not None and old_fp != fp:
        raise ConfigError(f"{path} holds a ga_reconfig run with different settings (fingerprint {old_fp} vs "
                          f"{fp}); choose another hydra.run.dir (nothing was changed)")
    if path.exists() and old_fp is None and s.resume != "never" and ST.load_checkpoint(path) is None:
        raise ConfigError(f"{path} exists but holds no ga_reconfig run; choose another hydra.run.dir "
                          "(nothing was changed)")
    if s.resume == "never":
        return []
    if path.exists():
        try:
            ST.restage(ctx.results, path)       # verified, and nothing already on disk is ever dropped
        except ChecksumError as err:
            raise CheckpointError(f"cannot resume: {err}; add fresh=true to start over") from None
    if s.resume == "must" and "ga" not in done and ST.load_checkpoint(path) is None:
        raise ConfigError(f"experiment.resume=must but {path} holds no GA checkpoint")
    return done


def run(ctx) -> None:
    import jax.numpy as jnp

    from ..io import load
    from ..optimize import GAError, run_ga
    from . import designer_report as R
    from ..optimize import workflow as W
    from ..optimize.designer import CONSTRAINT_NAMES, DESIGN_SENSE, DESIGN_UNITS, FEASIBILITY_TOL
    from ..optimize.pareto import hypervolume, non_dominated, nsga2

    # -- spec ---------------------------------------------------------------------------------------------------
    s, space, pb, ga_cfg = build(ctx.cfg.experiment, ctx.robot, ctx.recon)    # validated before anything compiles
    ga_cfg = dataclasses.replace(ga_cfg, seed=int(ctx.cfg.seed))
    res, path, seed = ctx.results, ctx.run_dir / "results.h5", int(ctx.cfg.seed)
    try:   # more budget for a finished run: its verified front seeds the searches and joins the candidates
        earlier = None if s.continue_from is None else ST.earlier_run(s.continue_from, ctx.cfg)
    except W.SetupError as err:
        raise ConfigError(str(err)) from None
    fp = ST.job_fingerprint(ctx.cfg)
    done = _claim(ctx, s, path, fp, W)
    res.set_attrs(ga_reconfig_fingerprint=fp)
    if "report" in done:
        ctx.log(f"{path} holds a complete ga_reconfig run (stages {','.join(done)}); nothing to do")
        return
    stored = load(path, verify=True) if path.exists() and done else {}
    timings, t0 = {}, [time.perf_counter(), time.process_time()]

    def mark(stage):
        done.append(stage)
        res.set_attrs(ga_reconfig_stages=",".join(done))
        res.flush()
        timings[stage] = time.perf_counter() - t0[0]
        cpu = time.process_time() - t0[1]                   # CPU-s of this process (all threads): on a shared
        t0[0], t0[1] = time.perf_counter(), time.process_time()   # machine the figure to compare, not the wall
        ctx.log(f"[{stage}: {timings[stage]:.1f} s, {cpu:.1f} CPU-s]")

    if "plots" in done:     # stopped after its figures (or finished before the later stages existed)
        _finish(ctx, path, space, s, done, mark)
        return

    objs, primary = list(s.objectives), s.primary
    jp = objs.index(primary)
    sense = np.asarray([DESIGN_SENSE[o] for o in objs], float)
    ev = W.batch_evaluator(pb, space, max(s.pareto["population_size"], 2))
    ev_cheap = W.batch_evaluator(pb, space, 256, regular=False)       # screen and refinement (no regular workspace)
    base_genes = space.baseline_genes()
    carried = earlier.genes if earlier is not None else np.zeros((0, space.dim))
    if earlier is not None:
        ctx.log(f"continuing {earlier.path}: its {len(carried)} verified front designs seed the GA and NSGA-II and "
                "join the verified candidates with their verified metrics (so this run's recommendation is never "
                "one that the earlier run's recommendation dominates)")
    ctx.log(f"design space: {dict(zip(space.names, zip(space.lower, space.upper)))} ({space.dim} genes, n_R="
            f"{space.n_R}); {len(pb.task_points)} task samples, {pb.cycle.n_samples} cycle samples, regular grid "
            f"{pb.rw_points.shape[:3]}")

    # -- compute: baseline (coarse; normalises the objectives) ----------------------------------------------------
    base = {k: v[0] for k, v in ev(base_genes[None]).items()}
    for o in objs:
        if not (np.isfinite(base[o]) and base[o] != 0):
            raise ConfigError(f"experiment.objectives.names: the baseline's {o} is {float(base[o])!r}, which "
                              "cannot normalise it; loosen the constraints or move the task")
    scale = sense / np.abs(np.asarray([float(base[o]) for o in objs]))
    if not bool(base["feasible"]):
        bad = [n for n, g in zip(CONSTRAINT_NAMES, base["g"]) if g > FEASIBILITY_TOL]
        # a coarse-grid estimate that only steers the search (the baseline still normalises the objectives and
        # seeds the GA); the fine grids can find it feasible, and the table at the end is on the fine grids
        ctx.log(f"note: on the coarse search grids the baseline violates {bad}; the verified table at the end (fine "
                "grids) is authoritative for every design, the baseline included")

    # -- screen: Sobol designs without the regular workspace, the best feasible ones seed the GA ------------------
    seeds = np.concatenate([base_genes[None], carried])
    scr_front = np.zeros((0, space.dim))
    if s.screen["enabled"] and not primary.startswith("regular"):
        if "screen" in done:
            top = np.asarray(stored["screen"]["top_genes"]).reshape(-1, space.dim)
            if "front_genes" not in stored["screen"]:  # staged by a deltajax before the NSGA-II seeding
                raise CheckpointError(f"{ctx.results.path}: its finished screen stage has no screen/front_genes "
                                      "(written by an older deltajax); resume it with that version, or start a "
                                      "new run directory")
            scr_front = np.asarray(stored["screen"]["front_genes"]).reshape(-1, space.dim)
        else:
            bar = ctx.progress(total=2 ** s.screen["log2_size"], desc="screen (Sobol)")
            sc = W.screen(ev_cheap, space, primary, sense[jp], s.screen["log2_size"], seed=seed, progress=bar.update)
            bar.close()
            top = sc["X"][sc["order"][:max(int(s.screen["seed_fraction"] * ga_cfg.population_size), 1)]]
            res.put_axis("screen", "seed_design", np.arange(len(top)), units="1")
            res.put_axis("screen", "gene", np.arange(space.dim), units="1")
            res.put("screen", "top_genes", top, units="1", dims=("seed_design", "gene"))
            res.put("screen", "top_primary", sc[primary][sc["order"][:len(top)]], units=DESIGN_UNITS[primary],
                    dims=("seed_design",))
            res.set_attrs("screen", designs=len(sc["X"]), feasible=int(sc["feasible"].sum()), sampler="scrambled "
                          f"Sobol (scipy.stats.qmc), seed {seed}", grids="search grids, regular workspace skipped")
            # the screen's feasible non-dominated set on the job's objectives (regular workspace evaluated for the
            # feasible designs only) seeds NSGA-II: the GA's population crowds the primary's end of the front
            scr_front = W.screen_front(ev, sc, objs, scale, cap=SCREEN_FRONT_EVAL, layers=True)
            res.put_axis("screen", "front_design", np.arange(len(scr_front)), units="1")
            res.put("screen", "front_genes", scr_front, units="1", dims=("front_design", "gene"),
                    attrs={"meaning": "feasible screen designs in non-dominated-sorting order on the search grids "
                                      "(the first population_size/2 seed NSGA-II)"})
            ctx.log(f"screen: {len(sc['X'])} Sobol designs, {int(sc['feasible'].sum())} feasible; best {primary} "
                    f"{sc[primary][sc['order'][0]] if len(sc['order']) else float('nan'):.4g}; "
                    f"its feasible designs ranked by non-dominated sorting on {objs} seed NSGA-II")
            mark("screen")
        seeds = np.concatenate([seeds, top])

    # -- compute: GA on the primary objective (or the weighted sum), checkpointed --------------------------------
    wvec = (np.asarray([s.weights.get(o, 0.0) for o in objs]) * scale if s.mode == "weighted"
            else np.where(np.asarray(objs) == primary, scale, 0.0))
    ga_what = ("weighted sum " + " + ".join(f"{s.weights.get(o, 0.0):g} x {o}" for o in objs)
               if s.mode == "weighted" else f"primary objective {primary}")
    ck = None if s.resume == "never" else ST.load_checkpoint(path)
    ctx.log("GA stage already finished: reusing its checkpoint" if "ga" in done else
            f"resuming the GA from generation {ck['generations_done']}" if ck else f"starting the GA ({ga_what})")
    bar = ctx.progress(total=ga_cfg.generations, desc=f"GA {ga_cfg.algorithm}")
    bar.update(int(ck["generations_done"]) if ck else 0)

    def save(c):
        ST.put_checkpoint(res, c)
        res.flush()

    try:
        gres = run_ga(W.ga_fitness(pb, space, objs, wvec), space.dim, ga_cfg, init_genes=seeds, checkpoint=ck,
                      save_checkpoint=save, stop_after=s.stop_after, progress=bar.update,
                      program_key=W.ga_fitness_key(pb, space, objs, wvec),
                      fingerprint_extra={"space": [space.names, space.lower, space.upper, space.n_R,
                                                   space.reconfigurable], "job": fp})
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
        res.put_axis("ga", "generation", np.arange(1, gres.generations_done + 1), units="1")
        for k, v in gres.history.items():
            if k == "gen_best_genes":
                res.put("ga", k, v, units="1", dims=("generation", "gene"))
            elif k.startswith("aux/"):
                res.put("ga", f"gen_best_{k[4:]}", np.asarray(v, float), units=DESIGN_UNITS.get(k[4:], "1"),
                        dims=("generation",))
            else:
                res.put("ga", k, v, units="1", dims=("generation",))
        res.put_axis("ga", "gene", np.arange(space.dim), units="1")
        gene_units = {"units_per_gene": ",".join(space.units(n) for n in space.names)}
        res.put("ga", "gene_names", np.asarray(space.names, dtype=object), units="1", dims=("gene",))
        res.put("ga", "lower", np.asarray(space.lower), units="mixed", dims=("gene",), attrs=gene_units)
        res.put("ga", "upper", np.asarray(space.upper), units="mixed", dims=("gene",))
        res.put("ga", "best_genes", best, units="1", dims=("gene",))
        res.put("ga", "best_params", np.asarray(space.to_params(jnp.asarray(best))), units="mixed", dims=("gene",),
                attrs=gene_units)
        res.put("ga", "baseline_genes", base_genes, units="1", dims=("gene",))
        res.set_attrs("ga", algorithm=ga_cfg.algorithm, population_size=ga_cfg.population_size,
                      generations=ga_cfg.generations, sigma=ga_cfg.sigma, seed=ga_cfg.seed,
                      fitness_best=gres.best_fitness, objective=ga_what, resumed_from=gres.resumed_from,
                      fingerprint=gres.fingerprint, seeded_with=len(seeds), baseline_primary=float(base[primary]),
                      constraint_handling="feasibility_first (1e3 + violation)")
        mark("ga")
    ctx.log(f"GA best ({ga_what}): fitness {gres.best_fitness:.5g}, {space.describe(best)}")

    # -- compute: NSGA-II front ---------------------------------------------------------------------------------
    ref = np.where(sense < 0, 0.0, s.pareto["ref_min_factor"])           # in normalised objective space
    front_X, extra_X = np.zeros((0, space.dim)), np.zeros((0, space.dim))
    if s.pareto["enabled"] and "pareto" in done:
        front_X = np.asarray(stored["pareto"]["genes"]).reshape(-1, space.dim)
        extra_X = np.asarray(stored["pareto"]["population_feasible_genes"]).reshape(-1, space.dim)
    elif s.pareto["enabled"]:
        bar = ctx.progress(total=s.pareto["generations"], desc="NSGA-II")
        front = nsga2(W.pareto_eval(ev, objs, scale), space.dim, len(objs), n_constr=len(CONSTRAINT_NAMES),
                      pop_size=s.pareto["population_size"], n_gen=s.pareto["generations"], seed=seed,
                      initial=np.concatenate([base_genes[None], best[None], carried,
                                              scr_front[:s.pareto["population_size"] // 2],
                                              gres.final_population]), ref=ref,
                      progress=bar.update)
        bar.close()
        front_X = front.X
        pfeas = np.all(front.pop_G <= 0, axis=1)
        extra_X = np.asarray([x for x in front.pop_X[pfeas] if not np.any(np.all(front.X == x, axis=1))])
        extra_X = extra_X.reshape(-1, space.dim)
        res.put_axis("pareto", "point", np.arange(len(front.X)), units="1")
        res.put_axis("pareto", "gene", np.arange(space.dim), units="1")
        res.put_axis("pareto", "objective", np.arange(len(objs)), units="1")
        res.put("pareto", "population_feasible_genes", extra_X, units="1", dims=("population_point", "gene"),
                attrs={"meaning": "feasible final-population designs off the search front (verified too)"})
        res.put("pareto", "genes", front.X, units="1", dims=("point", "gene"))
        res.put("pareto", "F_search", front.F, units="1", dims=("point", "objective"),
                attrs={"meaning": "minimised objectives on the search grids: sense x metric / |baseline metric|"})
        res.put("pareto", "objective_names", np.asarray(objs, dtype=object), units="1", dims=("objective",))
        res.put("pareto", "hypervolume_history", front.history_hv, units="1", dims=("generation",))
        res.set_attrs("pareto", n_evals=front.n_evals, algorithm="pymoo NSGA-II",
                      population_size=s.pareto["population_size"], generations=s.pareto["generations"])
        ctx.log(f"NSGA-II: {len(front.X)} feasible non-dominated points after {front.n_evals} evaluations")
        mark("pareto")

    # -- compute: optax refinement of the winners (GA best and front points) --------------------------------------
    refined = np.zeros((0, space.dim))
    if s.refine["enabled"] and "refine" in done:
        refined = np.asarray(stored["refine"]["accepted_genes"]).reshape(-1, space.dim)
    elif s.refine["enabled"]:
        bar = ctx.progress(total=2, desc="refine (optax)")
        # the GA's best and the front's best on the primary objective (the front is sorted by the first objective)
        prim = (ev if primary.startswith("regular") else ev_cheap)(front_X)[primary] if len(front_X) else []
        order = np.argsort(sense[jp] * np.nan_to_num(prim, nan=-sense[jp] * np.inf))
        winners = np.concatenate([best[None], front_X[order[:REFINE_MAX - 1]]])
        ro = W.refine_designs(pb, space, winners, objs, scale, primary,
                              steps=s.refine["steps"], learning_rate=s.refine["learning_rate"],
                              penalty=s.refine["penalty"], evaluate=ev, evaluate_cheap=ev_cheap,
                              progress=bar.update)
        bar.close()
        refined = ro.genes_after[ro.accepted]
        res.put_axis("refine", "winner", np.arange(len(ro.accepted)), units="1")
        res.put_axis("refine", "gene", np.arange(space.dim), units="1")
        res.put_axis("refine", "objective", np.arange(len(objs)), units="1")
        res.put_axis("refine", "accepted_design", np.arange(len(refined)), units="1")
        for k in ("genes_before", "genes_after", "F_before", "F_after"):
            res.put("refine", k, getattr(ro, k), units="1", dims=("winner", "gene" if "genes" in k else "objective"))
        res.put("refine", "accepted", ro.accepted.astype(np.uint8), units="1", dims=("winner",))
        res.put("refine", "accepted_genes", refined, units="1", dims=("accepted_design", "gene"))
        res.set_attrs("refine", rule="accepted iff feasible on the search grids, no objective worse, primary better",
                      steps=s.refine["steps"], learning_rate=s.refine["learning_rate"], penalty=s.refine["penalty"])
        gain = (ro.F_after[:, jp] / ro.F_before[:, jp] - 1.0)[ro.accepted] * 100
        ctx.log(f"refine: {int(ro.accepted.sum())} of {len(ro.accepted)} winners improved ({primary} "
                f"+{np.max(gain) if len(gain) else 0.0:.2f} % at most, every constraint kept)")
        mark("refine")

    # -- compute: verification on the fine grids, the floor step, recommendation --------------------------------------
    if "verify" not in done:
        space_v = dataclasses.replace(space, n_R=s.verify["n_R"]) if space.reconfigurable else space
        pb_fine = W.designer_problem(s, fine=True)
        cand = np.concatenate([base_genes[None], best[None], front_X, refined, extra_X])
        names = (["baseline", "ga_best"] + [f"pareto_{i}" for i in range(len(front_X))]
                 + [f"refined_{i}" for i in range(len(refined))] + [f"population_{i}" for i in range(len(extra_X))])
        ga_best_name = "ga_best"
        if earlier is not None:     # a design the earlier run verified (e.g. a seed the GA kept) keeps its name there
            keep = [i for i in range(len(cand)) if i == 0 or not np.any(np.all(carried == cand[i], axis=1))]
            cand, names = cand[keep], [names[i] for i in keep]
            same = np.flatnonzero(np.all(carried == best, axis=1))
            ga_best_name = earlier.names[same[0]] if len(same) else ga_best_name
        bar = ctx.progress(total=len(cand), desc="verify (fine grids)")
        mv = W.verify(pb_fine, space_v, cand, progress=bar.update)
        bar.close()
        if earlier is not None:                                     # the earlier run's front, as it verified it
            try:
                mv = ST.carry_earlier(mv, earlier, objs)
            except W.SetupError as err:
                raise ConfigError(str(err)) from None
            cand, names = np.concatenate([cand, carried]), names + list(earlier.names)
        n_before_floor = len(cand)
        bv = np.asarray([float(mv[o][0]) for o in objs])           # normalised by the *verified* baseline
        scale_v = np.where(np.isfinite(bv) & (bv != 0), sense / np.abs(np.where(bv != 0, bv, 1)), scale)

        def front_of(mv):
            Fv = W.objective_matrix(mv, objs, scale_v)
            ok = np.flatnonzero(mv["feasible"].astype(bool) & np.all(np.isfinite(Fv), axis=1))
            nd = ok[non_dominated(Fv[ok])] if len(ok) else np.zeros((0,), int)
            return Fv, ok, (nd[np.lexsort(Fv[nd].T[::-1])] if len(nd) else nd)

        Fv, ok, nd = front_of(mv)
        if s.recommend == "floor" and s.floor_solve["enabled"]:
            from ..optimize.floor import solve_floor
            bar = ctx.progress(total=s.floor_solve["rounds"] + 1, desc="floor step")
            fo = solve_floor(pb, space, cand, Fv, nd, objs, scale, primary,
                             W.floor_limits(len(objs), jp, s.recommend_floor, sense), evaluate=ev,
                             evaluate_cheap=ev_cheap, evaluate_fine=W.batch_evaluator(pb_fine, space_v, 8),
                             steps=s.refine["steps"], learning_rate=s.refine["learning_rate"],
                             penalty=s.refine["penalty"], rounds=s.floor_solve["rounds"],
                             n_fine=s.floor_solve["candidates"], progress=bar.update)
            bar.close()
            # an iterate equal to a design already verified (e.g. one a continued run carried from the earlier run,
            # whose own floor step descended from the same start) is not verified twice under two names
            fresh = np.flatnonzero([not np.any(np.all(cand == g, axis=1)) for g in fo.genes])
            if len(fresh) < len(fo.genes):
                fo = dataclasses.replace(fo, genes=fo.genes[fresh], start=fo.start[fresh], step=fo.step[fresh],
                                         metrics={k: v[fresh] for k, v in fo.metrics.items()},
                                         predicted=fo.predicted[fresh])
            if len(fo.genes):
                first = len(cand)
                cand = np.concatenate([cand, fo.genes])
                names += [f"floor_{i}" for i in range(len(fo.genes))]
                mv = {k: np.concatenate([mv[k], fo.metrics[k]]) for k in mv}
                Fv, ok, nd = front_of(mv)
                R.store_floor(res, fo, names, first, objs, s)
            ctx.log(f"floor step: descents from {len(fo.starts)} verified front points that meet the floor, "
                    f"{fo.n_predicted} iterates predicted to meet it, {len(fo.genes)} verified on the fine grids")
        elif s.floor_solve["enabled"]:
            ctx.log(f"floor step: skipped (it solves for the floor rule's answer; experiment.recommend={s.recommend})")
        rec = W.recommend(Fv, nd, s.recommend, jp, band=s.recommend_band, floor=s.recommend_floor, sense=sense)
        hv = hypervolume(Fv[nd], ref) if len(nd) else 0.0
        # -- write ----------------------------------------------------------------------------------------------
        R.store_verify(res, space, cand, names, mv, Fv, nd, rec, hv, hypervolume(Fv[:1], ref), ref, objs, s)
        res.set_attrs("verify", ga_best_design=ga_best_name)
        if earlier is not None:
            res.set_attrs("verify", continued_from=str(earlier.path), continued_from_fingerprint=earlier.fingerprint,
                          carried_designs=",".join(earlier.names))
            if earlier.recommended >= 0 and rec >= 0:
                e_rec = n_before_floor - len(carried) + earlier.recommended
                ctx.log(f"continued run: the earlier recommendation {names[e_rec]} ("
                        + ", ".join(f"{o} {float(mv[o][e_rec]):.5g}" for o in objs) + f") -> {names[rec]} ("
                        + ", ".join(f"{o} {float(mv[o][rec]):.5g}" for o in objs) + ")"
                        + (": kept, nothing verified here does better by the rule" if rec == e_rec else ""))
        ctx.log(f"verified on the fine grids: {len(cand)} candidates, {len(ok)} feasible; front {len(nd)} points, "
                f"hypervolume {hv:.4g}; recommended: {names[rec] if rec >= 0 else 'none'} ({R.rule_text(s)})")
        mark("verify")

    # a run that went past verify before this stage existed stays as it was (its tolerance stage read the verified
    # answer)
    if "certify" not in done and "tolerance" not in done and "results" not in done:
        _certify(ctx, res, load(path)["verify"], s, space, objs, sense, jp)
        mark("certify")

    if s.tolerance["enabled"] and "tolerance" not in done:   # reads what verify and certify stored
        from ..optimize.certify import overlay

        _tolerance(ctx, res, overlay(load(path)), s, space, objs, sense, jp)
        mark("tolerance")

    if "results" not in done:
        R.summary(ctx, res, load(path), space, objs, s)
        res.set_attrs("ga_reconfig", **{f"time_{k}_s": v for k, v in timings.items()})
        mark("results")                                               # results on disk before any plot
    # -- plot ---------------------------------------------------------------------------------------------------
    data = load(path)
    R.print_summary(ctx, data)
    R.plots(ctx, data, objs, s)
    ctx.write_figures()                      # the stage is done once its figures are on disk, not before
    mark("plots")
    _finish(ctx, path, space, s, done, mark)


def _certify(ctx, res, V, s, space, objs, sense, jp, *, max_rounds: int = 4) -> None:
    """The certify stage (:mod:`deltajax.optimize.certify`): the baseline and the recommendation certified (worst
    cases searched at the verification's density and at twice it, the change stated); the recommendation re-derived
    by the job's rule from the verified metrics with the certified ones in place (floor from the certified
    baseline), and certified in turn, until the rule's answer is a certified design (at most ``max_rounds``).
    Group ``certify`` (:func:`deltajax.jobs.designer_report.store_certify`); ``verify``'s ``recommended`` becomes
    the certified recommendation (``recommended_verified`` keeps the verification's)."""
    import jax.numpy as jnp

    from . import designer_report as R
    from ..optimize import certify as CE
    from ..optimize import workflow as W
    from ..optimize.pareto import non_dominated

    space_v = dataclasses.replace(space, n_R=s.verify["n_R"]) if space.reconfigurable else space
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

    def run(i):
        if i in cert or i < 0:
            return
        c = CE.certify_design(pb, space_v.decode(jnp.asarray(genes[i])), R_op[i])
        cert[i] = c
        bar.update(1)
        for k in CE.CERTIFIED_METRICS:
            if not (path and k in CE.CYCLE_METRICS):    # mode=path: the cycle's certified figures are the fixed R's
                mv[k][i] = c[k]
        feas[i] = bool(CE.feasible_certified({k: np.asarray(v[i]) for k, v in mv.items()}, pb))
        ctx.log(f"certified {names[i]}: " + ", ".join(
            f"{k} {c[k]:.5g} (doubling moved it {c[k + '_change']:.2g}, tolerance {c[k + '_tolerance']:g})"
            for k in CE.TOLERANCES) + ("" if c["converged"] else "; NOT within every tolerance")
            + ("" if feas[i] else "; infeasible once certified"))

    run(0)
    rec, front, Fv = rec0, np.zeros((0,), int), None
    for _ in range(max_rounds):
        bv = np.asarray([mv[o][0] for o in objs])
        Fv = W.objective_matrix(mv, objs, sense / np.abs(np.where(bv != 0, bv, 1.0)))
        ok = np.flatnonzero(feas & np.all(np.isfinite(Fv), axis=1))
        nd = ok[non_dominated(Fv[ok])] if len(ok) else np.zeros((0,), int)
        front = nd[np.lexsort(Fv[nd].T[::-1])] if len(nd) else nd
        rec = W.recommend(Fv, front, s.recommend, jp, band=s.recommend_band, floor=s.recommend_floor, sense=sense)
        if rec < 0 or rec in cert:
            break
        run(rec)
    bar.close()
    floor = (float(s.recommend_floor) * mv["regular_volume"][0]
             if s.recommend == "floor" and "regular_volume" in objs else None)
    marg = CE.design_margins(mv, threshold=pb.good.threshold, min_picks=pb.min_picks, max_arm_sum=pb.max_arm_sum,
                             volume_floor=floor)
    R.store_certify(res, names, cert, feas, marg, front, Fv, rec, rec0, floor, s)
    if path:
        res.set_attrs("certify", cycle_variant="fixed_R")
    res.set_attrs("verify", recommended=int(rec), recommended_verified=int(rec0))
    if rec != rec0:
        ctx.log(f"certified recommendation: {names[rec] if rec >= 0 else 'none'} (the verification's was "
                f"{names[rec0] if rec0 >= 0 else 'none'})")


def _tolerance(ctx, res, V, s, space, objs, sense, jp) -> None:
    """The tolerance stage (:mod:`deltajax.tolerance`, :mod:`deltajax.optimize.robust`): the Monte Carlo of the
    baseline and the recommendation on the verification problem (group ``tolerance``) and, with ``experiment.robust.enabled``, the robust
    recommendation (group ``tolerance/robust``; ``verify``'s ``recommended`` becomes it, ``recommended_nominal``
    keeps the nominal one)."""
    from .. import tolerance as TL
    from . import designer_report as R
    from ..optimize import robust as RB
    from ..optimize import workflow as W

    space_v = dataclasses.replace(space, n_R=s.verify["n_R"]) if space.reconfigurable else space
    pb_fine = W.designer_problem(s, fine=True)
    tol = R.tolerances_of(s)
    text = TL.describe(tol)
    names = [str(n) for n in V["design_name"]]
    genes = np.asarray(V["genes"], float).reshape(len(names), -1)
    rec = int(V["attrs"]["recommended"])
    n_s = int(s.tolerance["samples"])

    def analyse_rows(rows, seed):
        bar = ctx.progress(total=len(rows) * (n_s + 1), desc=f"tolerance (Monte Carlo, seed {seed})")
        try:
            return TL.analyse(pb_fine, space_v, genes[list(rows)], tol, samples=n_s, seed=seed, progress=bar.update)
        finally:
            bar.close()

    ctx.log(f"tolerance: {n_s} Monte Carlo samples of {text}")
    rows = [0] + ([rec] if rec > 0 else [])
    a = analyse_rows(rows, int(s.tolerance["seed"]))
    entries = [("baseline", 0, 0)] + ([("recommended", rows.index(rec), rec)] if rec >= 0 else [])
    results = [a]
    if s.robust["enabled"]:
        Fv = np.asarray(V["F"], float).reshape(len(names), -1)

        def rule(nd):
            return W.recommend(Fv, nd, s.recommend, jp, band=s.recommend_band, floor=s.recommend_floor, sense=sense)

        known = {r: TL.select([a], [(0, i)]) for i, r in enumerate(rows)}
        rc = RB.robust_choice(analyse_rows, Fv, np.asarray(V["feasible"]).astype(bool), rule,
                              float(s.robust["probability"]), int(s.tolerance["seed"]), int(s.robust["confirm_seed"]),
                              int(s.robust["max_candidates"]), known=known, log=ctx.log)
        R.store_robust(res, rc, names, rec, V, s, text)
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
                    f"{s.robust['confirm_seed']}); nominal: {names[rec]}; {len(rc.checked)} candidates checked")
        else:
            res.set_attrs("verify", recommended_nominal=rec)
            if rec >= 0:
                entries.append(("recommended", rows.index(rec), rec))
            ctx.log(f"WARNING robust: no verified candidate holds every constraint in >= "
                    f"{100 * s.robust['probability']:g} % of the samples ({len(rc.checked)} checked"
                    + (", every feasible one" if rc.exhausted else "") + "); the recommendation stays the nominal "
                    f"one ({names[rec] if rec >= 0 else 'none'}), which does not meet experiment.robust.probability")
    sel = TL.select(results, [(e[1] if isinstance(e[1], tuple) else (0, e[1])) for e in entries])
    roles = [e[0] for e in entries]
    R.store_tolerance(res, roles, [names[e[2]] for e in entries], [e[2] for e in entries], sel, text)
    frozen = None
    if space.reconfigurable:    # the stricter question: each built robot run at its design's nominal operating R
        frozen = TL.analyse(pb_fine, space_v, genes[[e[2] for e in entries]], tol, samples=n_s,
                            seed=int(s.tolerance["seed"]), operating_R="nominal")
        R.store_frozen(res, roles, [names[e[2]] for e in entries], [e[2] for e in entries], frozen, text)
    for line in R.headline_lines(dict(sel, role=roles, design_name=[names[e[2]] for e in entries],
                                       attrs={"samples": n_s}, frozen_R=frozen), roles):
        ctx.log(line)


def _finish(ctx, path, space, s, done, mark) -> None:
    """The stages after the figures: the export (marked once the datasheets are in results.h5 and their figures
    and the model files on disk), then the report (marked once report.html is on disk)."""
    from ..io import load

    if "export" not in done:
        _export(ctx, space, load(path)["summary"], s.motor)
        mark("export")
    _report(ctx, path)
    mark("report")


def _export(ctx, space, summary, motor_settings) -> None:
    """The baseline's and the recommendation's datasheets (group ``datasheet``, ``datasheet_<design>.png``, each at
    its operating R) and the recommendation's models: ``recommended.xml`` (MJCF), ``recommended.urdf`` and its
    loop-closure sidecar ``recommended.loops.json`` (:mod:`deltajax.export`)."""
    import json

    from .. import export
    from ..io import write_atomic
    from .datasheet import run_designs, write

    designs = run_designs(space, summary, motor_settings)
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


def _report(ctx, path) -> None:
    """The run report (``report.html`` beside results.h5), drawn from the results on disk."""
    from ..runreport import report_path, write_report

    ctx.log(f"report -> {write_report(path, report_path(ctx.run_dir))}")
