"""Evidence that the main job's answer is right: seed stability, budget monotonicity, and a quasi-random scan.

    python experiments/bench_designer.py --out outputs/bench_designer            # 5 seeds x 2 budgets + 2^17 scan
    python experiments/bench_designer.py --seeds 0 1 --scan-log2 12             # quicker

For each seed the default ``experiment=ga_reconfig`` runs twice: at its default budget and at a larger one
(``--large``: GA and NSGA-II populations / generations). From the results files (fine-grid verification):

(a) **stability**: the recommended design's objectives across seeds (spread = (max - min) / median per
    objective, stated against ``--tol``);
(b) **more budget never loses**: for each seed, the large run's recommendation is not dominated by the small
    run's recommendation (fine-grid objectives). Two ways to spend the larger budget: an independent run
    (``large_seed*``: a new random search, which can land elsewhere on a flat stretch of the front) and the default
    run *continued* with it (``continued_seed*``: ``experiment.continue_from=<default run>``, whose verified front
    joins the candidates, so the answer cannot be dominated by the earlier one: checked, with the hypervolume);
(c) **the optimiser beats a quasi-random scan of the same problem**: a scrambled Sobol sample
    (``scipy.stats.qmc``, seed 12345: not the job's own screen) of 2^scan_log2 designs of the same gene box,
    evaluated with the job's own coarse evaluator in two passes: every design without the regular workspace
    (feasibility and picks/min do not depend on it; ~30x cheaper), then the feasible ones with it. Reported:
    feasible count, the best feasible primary objective vs the job's (GA best alone, and the best of every
    design the job verified: GA, refined winners, front), and the hypervolume of the scan's feasible
    non-dominated set vs the job's (both on the coarse grids, normalised by the same baseline, reference 0),
    and how many scan designs dominate the recommendation on the coarse grids.

Load and CPU time are printed with the figures (on a shared machine compare ratios); the measured cost of its runs
and of the scan is in docs/BENCHMARKS.md. Run the jobs one at a time on a shared machine: ``--skip-runs`` analyses
what is in ``--out``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np


def _cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    c = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime + c.ru_utime + c.ru_stime


def _objectives(path, which):
    """(objective names, verified objective values of design ``which`` ('recommended' or an index), params)."""
    from deltajax.io import load

    d = load(path)
    V = d["verify"]
    objs = str(V["attrs"]["objectives"]).split(",")
    i = int(V["attrs"]["recommended"]) if which == "recommended" else int(which)
    return objs, np.asarray([float(V[o][i]) for o in objs]), np.asarray(V["params"][i]), d


def _complete(path):
    import h5py

    if not Path(path).exists():
        return False
    with h5py.File(path, "r") as f:
        return "verify" in str(f.attrs.get("ga_reconfig_stages", "")).split(",")


def dominates(a, b, sense):
    """a dominates b (sense -1: higher is better)."""
    fa, fb = np.asarray(a) * sense, np.asarray(b) * sense
    return bool(np.all(fa <= fb) and np.any(fa < fb))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="outputs/bench_designer")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--large", nargs="*", default=["experiment.ga.population_size=48", "experiment.ga.generations=32",
                                                   "experiment.screen.log2_size=13",
                                                   "experiment.pareto.population_size=48",
                                                   "experiment.pareto.generations=30"])
    ap.add_argument("--scan-log2", type=int, default=17, help="Sobol scan of 2^k designs (>= 17 for 1e5)")
    ap.add_argument("--skip-runs", action="store_true",
                    help="do not start runs: analyse the complete ones found in --out (seeds without one are skipped)")
    ap.add_argument("--no-scan", action="store_true",
                    help="skip the scan: (a), (b) and each run's fine-grid front figures only")
    ap.add_argument("--scan-only", action="store_true", help="only compute the scan (saved to <out>/scan_<k>.npz)")
    ap.add_argument("--cache", default=None, help="XLA compilation cache folder for the runs (default: <out>/xla)")
    ap.add_argument("--fine-top", type=int, default=16,
                    help="the scan's best designs on the primary verified on the fine grids (besides its front)")
    ap.add_argument("--tol", type=float, default=0.05, help="stated stability tolerance (relative spread)")
    ap.add_argument("--large-seeds", type=int, nargs="*", default=None,
                    help="seeds also run at the larger budget (default: all of --seeds)")
    ap.add_argument("--no-continued", action="store_true",
                    help="skip the default runs continued with the larger budget (experiment.continue_from)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    load0 = os.getloadavg()
    t0, c0 = time.perf_counter(), _cpu()
    runs = {}
    large_seeds = args.seeds if args.large_seeds is None else args.large_seeds
    budgets = [("default", [], args.seeds), ("large", list(args.large), large_seeds)]
    if not args.no_continued:
        budgets.append(("continued", list(args.large), large_seeds))
    for budget, extra, seeds in budgets:
        for s in seeds:
            # a finished run directory is a no-op for the job, a killed one resumes: always just rerun
            d = out / f"{budget}_seed{s}"
            if budget == "continued":
                if ("default", s) not in runs:
                    continue
                extra = list(args.large) + [f"experiment.continue_from={runs[('default', s)].parent}"]
            if args.skip_runs or args.scan_only:
                if _complete(d / "results.h5"):
                    runs[(budget, s)] = d / "results.h5"
                continue
            cmd = [sys.executable, "-m", "deltajax.run", "experiment=ga_reconfig", f"seed={s}", "plots=false",
                   "progress=false", f"hydra.run.dir={d}", f"compilation_cache={args.cache or out / 'xla'}", *extra]
            t1, c1 = time.perf_counter(), _cpu()
            subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
            rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 2 ** 20
            print(f"{budget} seed {s}: {time.perf_counter() - t1:.0f} s wall, {_cpu() - c1:.0f} CPU-s, load "
                  f"{os.getloadavg()[0]:.1f}; largest child RSS so far {rss:.2f} GB", flush=True)
            runs[(budget, s)] = d / "results.h5"
    t_runs, c_runs = time.perf_counter() - t0, _cpu() - c0

    # (c) quasi-random scan of the same problem with the job's coarse evaluator (two passes)
    import jax
    from hydra import compose, initialize_config_dir
    from scipy.stats import qmc

    jax.config.update("jax_enable_x64", True)
    from deltajax.config import ga_reconfig_build, robot_from_config
    from deltajax.io import load
    from deltajax.optimize.pareto import hypervolume, non_dominated
    from deltajax.optimize.workflow import batch_evaluator, objective_matrix
    from deltajax.run import CONFIG_DIR

    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(config_name="config", overrides=["experiment=ga_reconfig"])
    robot, recon = robot_from_config(cfg.robot)
    s, space, pb, _ = ga_reconfig_build(cfg.experiment, robot, recon)
    from deltajax.optimize.designer import DESIGN_SENSE

    objs = list(s.objectives.names)
    sense = np.asarray([DESIGN_SENSE[o] for o in objs], float)
    report = {"objectives": objs, "seeds": args.seeds, "large": args.large, "load_before": load0}
    if not args.no_scan:   # the scan (c); --no-scan: only (a), (b) and the runs' own fine-grid figures
        ev = batch_evaluator(pb, space, 64)
        ev_cheap = batch_evaluator(pb, space, 1024, regular=False)
        X = qmc.Sobol(d=space.dim, scramble=True, seed=12345).random_base2(args.scan_log2)
        t1, c1 = time.perf_counter(), _cpu()
        base = {k: v[0] for k, v in ev(space.baseline_genes()[None, :]).items()}
        cached = out / f"scan_{args.scan_log2}.npz"
        if cached.exists() and not args.scan_only:
            z = np.load(cached)
            feas, prim, Xf = z["feas"], z["prim"], z["Xf"]
            Mf = {o: z[f"Mf_{o}"] for o in objs} if len(Xf) else None
            Mf = dict(Mf, feasible=np.ones(len(Xf), bool)) if Mf is not None else None
            t_scan, c_scan, c_cheap = float(z["t_scan"]), float(z["c_scan"]), float(z["c_cheap"])
            # a cached scan is used only as far as today's evaluator reproduces it: the cheap pass (feasibility and the
            # primary objective, no regular workspace) on 64 designs; the regular pass on 64 of its feasible designs, and
            # when that does not match (the search's regular-workspace measure changed) it is recomputed for every
            # feasible design and the cache rewritten
            idx = np.linspace(0, len(X) - 1, 64).astype(int)
            chk0 = ev_cheap(X[idx])
            dev0 = float(np.nanmax(np.abs(chk0[s.objectives.primary] - prim[idx]) / np.maximum(np.abs(prim[idx]), 1e-300)))
            if not (np.array_equal(chk0["feasible"].astype(bool), feas[idx]) and dev0 <= 1e-9):
                raise SystemExit(f"{cached}: its cheap pass does not match today's evaluator (max rel. deviation "
                                 f"{dev0:.3g}); delete it")
            if len(Xf):
                chk = ev(Xf[:64])
                dev = max(float(np.nanmax(np.abs(chk[o] - Mf[o][:64]) / np.maximum(np.abs(Mf[o][:64]), 1e-300)))
                          for o in objs)
                if not np.all(chk["feasible"].astype(bool)):
                    raise SystemExit(f"{cached}: feasible designs of its regular pass are not feasible today; delete it")
                if dev > 1e-9:
                    print(f"scan: {cached}'s cheap pass reproduced (64 designs); its regular pass is not (max rel. "
                          f"deviation {dev:.3g}: the regular-workspace measure changed): recomputing it for its "
                          f"{len(Xf)} feasible designs", flush=True)
                    c2, t2 = _cpu(), time.perf_counter()
                    parts = [ev(Xf[i:i + 1024]) for i in range(0, len(Xf), 1024)]
                    Mf = {k: np.concatenate([p_[k] for p_ in parts]) for k in parts[0]}
                    c_scan = c_cheap + _cpu() - c2
                    t_scan = float(z["t_cheap"]) + time.perf_counter() - t2 if "t_cheap" in z.files else float("nan")
                    np.savez(cached, feas=feas, prim=prim, Xf=Xf, t_scan=t_scan, c_scan=c_scan, c_cheap=c_cheap,
                             t_cheap=float(z["t_cheap"]) if "t_cheap" in z.files else float("nan"),
                             **{f"Mf_{o}": Mf[o] for o in objs})
                    cf = out / f"scan_{args.scan_log2}_fine.npz"
                    if cf.exists():
                        cf.unlink()                      # its coarse non-dominated set changed with the measure
                    print(f"scan: regular pass {_cpu() - c2:.0f} CPU-s / {time.perf_counter() - t2:.0f} s wall", flush=True)
                else:
                    print(f"scan: reused {cached} (64 designs re-evaluated: max rel. deviation {dev:.2g})", flush=True)
            else:
                print(f"scan: reused {cached}", flush=True)
        else:
            feas = None
        if feas is None:
            parts = [ev_cheap(X[i:i + 8192]) for i in range(0, len(X), 8192)]
            feas = np.concatenate([p["feasible"] for p in parts]).astype(bool)
            prim = np.concatenate([p[s.objectives.primary] for p in parts])
            t_cheap, c_cheap = time.perf_counter() - t1, _cpu() - c1
            Xf = X[feas]
            Mf = ev(Xf) if len(Xf) else None
            t_scan, c_scan = time.perf_counter() - t1, _cpu() - c1
            np.savez(out / f"scan_{args.scan_log2}.npz", feas=feas, prim=prim, Xf=Xf, t_scan=t_scan, c_scan=c_scan,
                     c_cheap=c_cheap, t_cheap=t_cheap, **{f"Mf_{o}": Mf[o] for o in objs} if len(Xf) else {})
            print(f"scan: {len(X)} Sobol designs, {int(feas.sum())} feasible, {t_scan:.0f} s wall / {c_scan:.0f} CPU-s "
                  f"(cheap pass {c_cheap:.0f} CPU-s); load {os.getloadavg()}", flush=True)
        if args.scan_only:
            return
    # (a) stability and (b) budget, over the seeds with a complete run
    rec = {k: _objectives(p, "recommended") for k, p in runs.items()}
    for budget in ("default", "large", "continued"):
        seeds_b = [sd for sd in (args.seeds if budget == "default" else large_seeds) if (budget, sd) in rec]
        if not seeds_b:
            continue
        M = np.stack([rec[(budget, sd)][1] for sd in seeds_b])
        med = np.median(M, axis=0)
        spread = (M.max(axis=0) - M.min(axis=0)) / np.abs(med)
        report[f"{budget}_seeds"] = seeds_b
        report[f"{budget}_recommended"] = M.tolist()
        report[f"{budget}_params"] = np.stack([rec[(budget, sd)][2] for sd in seeds_b]).tolist()
        report[f"{budget}_spread"] = spread.tolist()
        # where on its verified front (sorted by the first objective) each seed's recommendation sits: a rule that
        # flips between the front's ends would show as positions 0 and n-1 across seeds
        pos = []
        for sd in seeds_b:
            V = rec[(budget, sd)][3]["verify"]
            fr = [int(i) for i in np.asarray(V["front"]).reshape(-1)]
            r_ = int(V["attrs"]["recommended"])
            pos.append([fr.index(r_) if r_ in fr else -1, len(fr)])
        report[f"{budget}_front_position"] = pos
        print(f"    position of the recommendation on its front (index, front size) per seed: {pos}")
        report[f"{budget}_stable_within_tol"] = bool(np.all(spread <= args.tol))
        print(f"(a) {budget}, seeds {seeds_b}: recommended {objs} per seed:\n{M}\n    spread (max-min)/median = "
              f"{spread} (tolerance {args.tol}): {'stable' if np.all(spread <= args.tol) else 'NOT stable'}")
    # (a) against the front pooled over every run: for each recommendation, the best primary objective any run
    # verified at the same or better values of the other objectives (its shortfall is how far the run's own front
    # falls short where its rule picked; a spread in the other objectives with no shortfall is the rule reading a
    # steep front at different points, not the runs disagreeing)
    pooled = []
    for (budget, sd), (_, _, _, d_) in rec.items():
        V = d_["verify"]
        fr = [int(i) for i in np.asarray(V["front"]).reshape(-1)]
        pooled += [[float(V[o][i]) for o in objs] for i in fr]
    P = np.asarray(pooled) * sense                                  # minimised
    j = objs.index(s.objectives.primary)
    others = [k for k in range(len(objs)) if k != j]
    shortfall = {}
    for (budget, sd), (_, f, _, _) in sorted(rec.items()):
        fs = f * sense
        ok = np.all(P[:, others] <= fs[others] + 1e-12 * np.abs(fs[others]), axis=1)
        best = float(np.min(P[ok, j])) * sense[j]
        shortfall[f"{budget}_{sd}"] = float(abs(best - f[j]) / abs(best))
        print(f"(a) {budget} seed {sd}: {s.objectives.primary} {f[j]:.5g}; best any run verified at >= its other objectives "
              f"{best:.5g} (shortfall {100 * shortfall[f'{budget}_{sd}']:.2f} %)")
    report["shortfall_vs_pooled_front"] = shortfall
    for budget, key in (("large", "larger_budget"), ("continued", "continued")):
        both = [sd for sd in large_seeds if ("default", sd) in rec and (budget, sd) in rec]
        if not both:
            continue
        lost = [sd for sd in both if dominates(rec[("default", sd)][1], rec[(budget, sd)][1], sense)]
        report[f"{key}_seeds"] = both
        report[f"{key}_dominated_by_smaller"] = lost
        relation, hv_pair = {}, {}
        for sd in both:   # per seed: how the larger run's recommendation stands against the smaller run's
            a, b = rec[("default", sd)][1], rec[(budget, sd)][1]
            relation[sd] = ("equal" if np.array_equal(a, b) else "dominated by the default run's"
                            if dominates(a, b, sense) else "dominates the default run's" if dominates(b, a, sense)
                            else "trade-off (neither dominates)")
            hv_pair[sd] = [float(rec[(k, sd)][3]["verify"]["attrs"]["hypervolume"]) for k in ("default", budget)]
            print(f"(b) {budget} seed {sd}: default {dict(zip(objs, a.round(5)))} -> {budget} "
                  f"{dict(zip(objs, b.round(5)))}: {relation[sd]}; verified front hypervolume {hv_pair[sd][0]:.5g} "
                  f"-> {hv_pair[sd][1]:.5g}")
        report[f"{key}_relation"] = {str(k): v for k, v in relation.items()}
        report[f"{key}_hypervolume"] = {str(k): v for k, v in hv_pair.items()}
        print(f"(b) {budget}, seeds {both}: those where the larger budget's recommendation is dominated by the "
              f"smaller run's: {lost or 'none'}")
    if args.no_scan:
        j = objs.index(s.objectives.primary)
        per_seed = []
        for (budget, seed), p_ in sorted(runs.items()):
            V = load(p_)["verify"]
            okj = np.asarray(V["feasible"]).astype(bool)
            fine_best = float(np.max(-sense[j] * np.asarray(V[s.objectives.primary])[okj])) * -sense[j]
            per_seed.append({"budget": budget, "seed": seed, "job_fine_best_primary": fine_best,
                             "hv_job_fine": float(V["attrs"]["hypervolume"]),
                             "front_size": int(np.asarray(V["front"]).size)})
            print(f"(c, fine grids, no scan) {budget} seed {seed}: best {s.objectives.primary} {fine_best:.4g}, hypervolume "
                  f"{per_seed[-1]['hv_job_fine']:.4g}, verified front {per_seed[-1]['front_size']} points", flush=True)
        report.update(per_seed=per_seed, runs_wall_s=t_runs, runs_cpu_s=c_runs, load_after=os.getloadavg())
        (out / "bench_designer.json").write_text(json.dumps(report, indent=1, default=float))
        print(f"wrote {out / 'bench_designer.json'}")
        return
    scale = sense / np.abs(np.asarray([float(base[o]) for o in objs]))
    Ff = objective_matrix(Mf, objs, scale) if len(Xf) else np.zeros((0, len(objs)))
    fin = np.all(np.isfinite(Ff), axis=1)
    Ff = Ff[fin]
    X_scan_nd = Xf[fin][non_dominated(Ff)] if len(Ff) else np.zeros((0, space.dim))
    hv_scan = hypervolume(Ff[non_dominated(Ff)], np.zeros(len(objs))) if len(Ff) else 0.0
    j = objs.index(s.objectives.primary)
    best_scan = float(np.max(-sense[j] * prim[feas])) * -sense[j] if feas.any() else float("nan")
    # like with like: the scan's coarse non-dominated set and its best designs on the primary, verified on the
    # job's fine grids (continuous regular workspace), normalised by the fine-grid baseline as the job's front is
    cached_f = out / f"scan_{args.scan_log2}_fine.npz"
    if cached_f.exists():
        zf = np.load(cached_f)
        mvs = {k[3:]: zf[k] for k in zf.files if k.startswith("mv_")}
        c_fine = float(zf["c_fine"])
    else:
        from deltajax.optimize import workflow as W

        jf = np.flatnonzero(feas)
        top = jf[np.argsort(sense[j] * prim[jf], kind="stable")[:args.fine_top]]
        Xv = np.concatenate([space.baseline_genes()[None], X_scan_nd, X[top]])
        space_v = dataclasses.replace(space, n_R=s.verify.n_R) if space.reconfigurable else space
        c2 = _cpu()
        mvs = W.verify(W.designer_problem(s, fine=True), space_v, Xv)
        c_fine = _cpu() - c2
        np.savez(cached_f, c_fine=c_fine, **{f"mv_{k}": v for k, v in mvs.items()})
    bvf = np.asarray([float(mvs[o][0]) for o in objs])
    Fsv = objective_matrix(mvs, objs, sense / np.abs(bvf))
    okv = mvs["feasible"].astype(bool) & np.all(np.isfinite(Fsv), axis=1)
    hv_scan_fine = hypervolume(Fsv[okv][non_dominated(Fsv[okv])], np.zeros(len(objs))) if okv.any() else 0.0
    best_scan_fine = float(np.max(-sense[j] * mvs[s.objectives.primary][okv])) * -sense[j] if okv.any() else float("nan")
    print(f"scan verified on the fine grids: {len(Fsv)} designs ({int(okv.sum())} feasible), {c_fine:.0f} CPU-s; "
          f"best {s.objectives.primary} {best_scan_fine:.4g}, hypervolume {hv_scan_fine:.4g}", flush=True)
    report.update(scan_fine_designs=int(len(Fsv)), scan_fine_feasible=int(okv.sum()), scan_fine_cpu_s=c_fine,
                  scan_fine_best_primary=best_scan_fine, scan_fine_hypervolume=hv_scan_fine)
    # the rule's own question on the fine grids (recommend: floor): the scan's best primary objective among its
    # verified feasible designs that meet the floor, to compare with each run's recommendation
    from deltajax.optimize.workflow import floor_limits

    lim = floor_limits(len(objs), j, s.recommend_floor, sense)
    at_floor = okv & np.all(Fsv <= lim[None, :], axis=1)
    best_scan_floor = (float(np.max(-sense[j] * mvs[s.objectives.primary][at_floor])) * -sense[j] if at_floor.any()
                       else float("nan"))
    if s.recommend == "floor":
        print(f"scan, fine grids, the floor rule's question: best {s.objectives.primary} among its {int(at_floor.sum())} verified "
              f"designs at the floor ({s.recommend_floor} x the baseline): {best_scan_floor:.5g}", flush=True)
    report.update(scan_fine_best_primary_at_floor=best_scan_floor)
    per_seed = []
    for budget, seeds in (("default", args.seeds), ("large", large_seeds), ("continued", large_seeds)):
        for seed in seeds:
            if (budget, seed) not in runs:
                continue
            d = load(runs[(budget, seed)])
            Vr = d["verify"]
            ir = int(Vr["attrs"]["recommended"])
            rec_fine = np.asarray([float(Vr[o][ir]) for o in objs])
            dom_fine = int(sum(dominates(np.asarray([float(mvs[o][i]) for o in objs]), rec_fine, sense)
                               for i in np.flatnonzero(okv)))
            if s.recommend == "floor":
                print(f"(c, fine grids, the rule's question) {budget} seed {seed}: recommended {s.objectives.primary} "
                      f"{rec_fine[j]:.5g} vs the scan's best at the floor {best_scan_floor:.5g} "
                      f"({'>=' if -sense[j] * rec_fine[j] >= -sense[j] * best_scan_floor else '<'}); verified scan "
                      f"designs dominating the recommendation: {dom_fine}", flush=True)
            mg = ev(np.asarray(d["ga"]["best_genes"])[None, :])
            G = np.asarray(d["verify"]["genes"])
            mj = ev(G)                                          # every design the job verified, on the coarse grids
            Fj = objective_matrix(mj, objs, scale)
            ok = mj["feasible"].astype(bool) & np.all(np.isfinite(Fj), axis=1)
            hv_job = hypervolume(Fj[ok][non_dominated(Fj[ok])], np.zeros(len(objs))) if ok.any() else 0.0
            best_job = float(np.max(-sense[j] * mj[s.objectives.primary][ok])) * -sense[j] if ok.any() else float("nan")
            ga_best = float(mg[s.objectives.primary][0]) if bool(mg["feasible"][0]) else float("nan")
            fr = Fj[int(d["verify"]["attrs"]["recommended"])]
            dom = int(np.sum([dominates(f, fr, np.ones(len(objs))) for f in Ff]))
            V = d["verify"]
            okj = np.asarray(V["feasible"]).astype(bool)
            fine_best = float(np.max(-sense[j] * np.asarray(V[s.objectives.primary])[okj])) * -sense[j]
            hv_fine = float(V["attrs"]["hypervolume"])
            print(f"(c, fine grids) {budget} seed {seed}: best {s.objectives.primary} {fine_best:.4g} vs scan {best_scan_fine:.4g}"
                  f" ({'>=' if fine_best >= best_scan_fine else '<'}); hypervolume {hv_fine:.4g} vs scan "
                  f"{hv_scan_fine:.4g} ({'>=' if hv_fine >= hv_scan_fine else '<'})", flush=True)
            per_seed.append({"budget": budget, "seed": seed, "ga_best_primary": ga_best, "job_best_primary": best_job,
                             "job_fine_best_primary": fine_best, "hv_job_fine": hv_fine,
                             "hv_job": hv_job, "scan_designs_dominating_recommended": dom,
                             "recommended_fine": rec_fine.tolist(), "scan_fine_designs_dominating_recommended": dom_fine,
                             "refined_accepted": int(np.sum(d.get("refine", {}).get("accepted", [])))})
            print(f"(c) {budget} seed {seed}: {s.objectives.primary} GA best {ga_best:.4g}, best of the job's designs "
                  f"{best_job:.4g} vs best of the scan {best_scan:.4g} ({'>=' if best_job >= best_scan else '<'}); "
                  f"hypervolume job {hv_job:.4g} vs scan {hv_scan:.4g}; scan designs dominating the "
                  f"recommendation (coarse grids): {dom}", flush=True)
    report.update(scan_designs=len(X), scan_feasible=int(feas.sum()), scan_best_primary=best_scan,
                  scan_hypervolume=hv_scan, per_seed=per_seed, scan_wall_s=t_scan, scan_cpu_s=c_scan,
                  scan_cheap_pass_cpu_s=c_cheap, runs_wall_s=t_runs, runs_cpu_s=c_runs, load_after=os.getloadavg(),
                  scan_designs_per_cpu_s=len(X) / max(c_scan, 1e-9))
    print(f"scan: {len(X)} Sobol designs, {int(feas.sum())} feasible, {t_scan:.0f} s wall / {c_scan:.0f} CPU-s "
          f"(cheap pass {c_cheap:.0f} CPU-s; {len(X) / max(c_scan, 1e-9):.0f} designs per CPU-s overall); runs "
          f"{t_runs:.0f} s wall / {c_runs:.0f} CPU-s; load {load0} -> {os.getloadavg()}")
    (out / "bench_designer.json").write_text(json.dumps(report, indent=1, default=float))
    print(f"wrote {out / 'bench_designer.json'}")


if __name__ == "__main__":
    main()
