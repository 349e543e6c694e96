"""Experiment ``ga_reconfig`` (the main job): optimise the reconfigurable Delta around franco2026.

    python -m deltajax.run experiment=ga_reconfig
    python -m deltajax.run experiment=ga_reconfig experiment.ga.population_size=256 experiment.ga.generations=200
    python -m deltajax.run experiment=ga_reconfig hydra.run.dir=<dir of a killed run>      # resume

Steps: (1) baseline metrics of the franco2026 design (the robot config's R range, r, L1, L2, limits, masses);
(2) single-objective evosax GA on the weighted, baseline-normalised fitness (volume with R per point, peak
torque on the pick-and-place cycle, end-effector speed; constraints: task cylinder in the good workspace,
cycle reachable), checkpointed into ``results.h5`` (group ``ga/checkpoint``) every ``checkpoint_every``
generations and resumed bit-identically after a kill; (3) NSGA-II Pareto front (pymoo) of the chosen
objectives, exported in decision and objective space with its hypervolume; (4) optax refinement of the GA
winner and some Pareto points on the smooth relaxation, verified on the true objectives; (5) baseline vs
winner on a finer quadrature and cycle (``verify``), beside the GA paper's +15 % workspace, -12 % torque,
+8 % speed.

Groups: ``ga`` (history, best design, comparison), ``pareto``, ``refine`` (SPEC §5). Plots:
``ga_convergence.png``, ``ga_pareto.png``.
"""

from __future__ import annotations

import dataclasses
import math
import re
from typing import Any, Mapping

import numpy as np

from ..config import ConfigError

__all__ = ["run", "build", "PAPER_CLAIMS"]

#: Hasanlu 2025 (abstract, conclusions): improvements of the optimised design over the baseline (%).
PAPER_CLAIMS = {"volume": 15.0, "peak_torque": -12.0, "peak_speed": 8.0}


def _plain(x: Any) -> Any:
    from omegaconf import DictConfig, ListConfig, OmegaConf

    if isinstance(x, (DictConfig, ListConfig)):
        return OmegaConf.to_container(x, resolve=True)
    return x


def build(ectx: Mapping[str, Any], robot, recon):
    """(design space, problem without baseline, GA config) from the experiment config (validated)."""
    from ..optimize import DesignSpace, DesignSpaceError, GAConfig, GAError, ObjectiveError, Problem

    e = _plain(ectx)
    d = e.get("design") or {}
    baseline = recon if recon is not None else robot
    try:
        space = DesignSpace.from_bounds(baseline, d.get("bounds") or {}, n_R=d.get("n_R"),
                                        prefix="experiment.design.bounds")
    except DesignSpaceError as err:
        raise ConfigError(str(err)) from None
    ws = dict(e.get("workspace") or {})

    def hi(name):
        lo_hi = space._range(name)
        return lo_hi[1]

    R_hi = hi("R_max") if space.reconfigurable else hi("base_radius")
    r_lo = space._range("platform_radius")[0]
    auto_r = R_hi - r_lo + hi("upper_arm") + hi("forearm")
    auto_z = hi("upper_arm") + hi("forearm")
    r_max = ws.pop("r_max", None) or auto_r
    z_max = ws.pop("z_max", None) or auto_z
    cfg = dict(e)
    cfg["workspace"] = ws
    try:
        pb = Problem.from_config(cfg, r_max=float(r_max), z_max=float(z_max))
        ga = GAConfig.from_mapping(e.get("ga") or {}, seed=0)
    except (ObjectiveError, GAError) as err:
        raise ConfigError(str(err)) from None
    return space, pb, ga


def _history_name(k: str) -> str:
    return k.replace("/", "__")


def _load_checkpoint(path) -> Any:
    """The GA checkpoint stored in a results.h5, or None."""
    from ..io import load

    if not path.exists():
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


def run(ctx) -> None:
    import jax
    import jax.numpy as jnp

    from ..optimize import (METRIC_UNITS, SENSE, evaluate_design, fitness_from_metrics, hypervolume, make_fitness,
                            nsga2, refine, run_ga)
    from ..optimize.pareto import padded_batch

    import time

    e = ctx.cfg.experiment
    t_start = time.perf_counter()
    timings = {}

    def lap(name):
        nonlocal t_start
        now = time.perf_counter()
        timings[name] = now - t_start
        t_start = now
        ctx.log(f"[{name}: {timings[name]:.1f} s]")

    space, pb, ga_cfg = build(e, ctx.robot, ctx.recon)
    ga_cfg = dataclasses.replace(ga_cfg, seed=int(ctx.cfg.seed))
    resume = str(e.get("resume", "auto"))
    if resume not in ("auto", "never", "must"):
        raise ConfigError(f"experiment.resume must be auto, never or must, got {resume!r}")
    stop_after = e.get("stop_after", None)
    if stop_after is not None and (not isinstance(stop_after, int) or stop_after < 1):
        raise ConfigError(f"experiment.stop_after must be null or an integer >= 1, got {stop_after!r}")
    res = ctx.results
    ctx.log(f"design space: {dict(zip(space.names, zip(space.lower, space.upper)))} ({space.dim} genes, "
            f"{'reconfigurable' if space.reconfigurable else 'fixed'}, n_R={space.n_R}); "
            f"{len(pb.ws_points)} workspace samples, {len(pb.task_points)} task samples")

    # (1) baseline ------------------------------------------------------------------------------------------
    P_eval = max(int(e.pareto.population_size) if e.pareto.enabled else 1, 2)
    eval_all = jax.jit(jax.vmap(lambda g: evaluate_design(pb, space.decode(g))))
    batch_eval = padded_batch(eval_all, P_eval)
    base_genes = space.baseline_genes()
    if not space.baseline_inside():
        ctx.log("note: the baseline lies outside the bounds; its clipped genes are used as the GA seed")
    # the baseline as the GA sees it: decoded from its genes (equal to the config robot up to rounding)
    base_true = {k: float(v[0]) for k, v in batch_eval(base_genes[None, :]).items()}
    for k in pb.weights:
        if not (math.isfinite(base_true[k]) and base_true[k] != 0):
            raise ConfigError(f"experiment.objectives.weights.{k}: the baseline's {k} is {base_true[k]!r}, "
                              "which cannot normalise it")
    pb = pb.with_baseline(base_true)
    ctx.log("baseline: " + ", ".join(f"{k}={v:.4g}" for k, v in base_true.items()))
    if not base_true["feasible"]:
        ctx.log("warning: the baseline violates the designer constraints "
                f"(violation {base_true['violation']:.3g}); loosen constraints.* or move the task")

    lap("baseline")

    # (2) GA with checkpoints ---------------------------------------------------------------------------------
    path = ctx.run_dir / "results.h5"
    ck = None
    if resume != "never":
        ck = _load_checkpoint(path)
        if ck is None and resume == "must":
            raise ConfigError(f"experiment.resume=must but {path} holds no GA checkpoint")
    fit = make_fitness(pb, space)
    extra = {"space": [space.names, space.lower, space.upper, space.n_R, space.reconfigurable],
             "problem": {"weights": dict(pb.weights), "settings": {k: str(v) for k, v in pb.settings.items()},
                         "n_ws": len(pb.ws_points), "n_task": len(pb.task_points), "k_min": pb.k_min,
                         "coverage_min": pb.coverage_min, "handling": pb.handling, "penalty": pb.penalty,
                         "n_op": pb.n_R_operating, "baseline": {k: repr(v) for k, v in sorted(base_true.items())}}}
    if ck is not None:
        ctx.log(f"resuming the GA from generation {ck['generations_done']} of {path}")
    else:
        ctx.log("starting the GA from generation 0")

    def save(c):
        _put_checkpoint(res, c)
        res.flush()

    bar = ctx.progress(total=ga_cfg.generations, desc=f"GA {ga_cfg.algorithm}")
    if ck is not None:
        bar.update(int(ck["generations_done"]))
    try:
        gres = run_ga(fit, space.dim, ga_cfg, init_genes=base_genes, checkpoint=ck, save_checkpoint=save,
                      stop_after=stop_after, fingerprint_extra=extra, progress=bar.update)
    except Exception as err:  # noqa: BLE001 - a stale checkpoint is a config problem, name it
        from ..optimize import GAError

        if isinstance(err, GAError):
            raise ConfigError(f"{err} ({path})") from None
        raise
    finally:
        bar.close()
    if gres.generations_done < ga_cfg.generations:
        ctx.log(f"stopped after {gres.generations_done} generations (experiment.stop_after); rerun with "
                f"hydra.run.dir={ctx.run_dir} to resume")
        res.set_attrs("ga", stopped_after=gres.generations_done)
        return

    lap("ga")
    h = gres.history
    res.put_axis("ga", "generation", np.arange(1, gres.generations_done + 1), units="1")
    for k, v in h.items():
        if k == "gen_best_genes":
            res.put("ga", k, v, units="1", dims=("generation", "gene"))
        elif k.startswith("aux/"):
            name = k[4:]
            res.put("ga", f"gen_best_{name}", v.astype(float), units=METRIC_UNITS.get(name, "1"),
                    dims=("generation",))
        else:
            res.put("ga", k, v, units="1", dims=("generation",))
    best = gres.best_genes
    res.put_axis("ga", "gene", np.arange(space.dim), units="1")
    res.put("ga", "gene_names", np.asarray(space.names, dtype=object), units="1", dims=("gene",))
    res.put("ga", "lower", np.asarray(space.lower), units="mixed", dims=("gene",),
            attrs={"units_per_gene": ",".join(space.units(n) for n in space.names)})
    res.put("ga", "upper", np.asarray(space.upper), units="mixed", dims=("gene",))
    res.put("ga", "best_genes", best, units="1", dims=("gene",))
    res.put("ga", "best_params", np.asarray(space.to_params(jnp.asarray(best))), units="mixed", dims=("gene",))
    res.put("ga", "baseline_genes", base_genes, units="1", dims=("gene",))
    fit_base = float(fitness_from_metrics(pb, {k: jnp.asarray(v) for k, v in base_true.items()}))
    res.set_attrs("ga", algorithm=ga_cfg.algorithm, population_size=ga_cfg.population_size,
                  generations=ga_cfg.generations, sigma=ga_cfg.sigma, seed=ga_cfg.seed, fitness_best=gres.best_fitness,
                  fitness_baseline=fit_base,
                  resumed_from=gres.resumed_from, fingerprint=gres.fingerprint,
                  constraint_handling=pb.handling, weights=str(dict(pb.weights)))
    ctx.log(f"GA best fitness {gres.best_fitness:.5g} (baseline {fit_base:.5g}): "
            f"{space.describe(best)}")

    # (3) Pareto front ------------------------------------------------------------------------------------
    front = None
    if e.pareto.enabled:
        objs = [str(o) for o in e.pareto.objectives]
        for o in objs:
            if o not in SENSE:
                raise ConfigError(f"experiment.pareto.objectives: unknown metric {o!r}; known: {list(SENSE)}")
        scale = np.asarray([SENSE[o] / abs(base_true[o]) for o in objs])
        ref = np.asarray([(-float(e.pareto.ref_max_factor)) if SENSE[o] < 0 else float(e.pareto.ref_min_factor)
                          for o in objs])

        def pareto_eval(X):
            m = batch_eval(np.asarray(X))
            F = np.stack([m[o] for o in objs], axis=1) * scale
            return F, m["violation"][:, None]

        pbar = ctx.progress(total=int(e.pareto.generations), desc="NSGA-II")
        front = nsga2(pareto_eval, space.dim, len(objs), n_constr=1, pop_size=int(e.pareto.population_size),
                      n_gen=int(e.pareto.generations), seed=int(ctx.cfg.seed),
                      initial=np.stack([base_genes, best]), ref=ref, progress=pbar.update)
        pbar.close()
        hv = hypervolume(front.F, ref)
        hv_base = hypervolume((np.asarray([base_true[o] for o in objs]) * scale)[None, :], ref)
        res.put_axis("pareto", "point", np.arange(len(front.X)), units="1")
        res.put_axis("pareto", "gene", np.arange(space.dim), units="1")
        res.put_axis("pareto", "objective", np.arange(len(objs)), units="1")
        res.put("pareto", "objective_names", np.asarray(objs, dtype=object), units="1", dims=("objective",))
        res.put("pareto", "genes", front.X, units="1", dims=("point", "gene"))
        params = np.asarray(jax.vmap(space.to_params)(jnp.asarray(front.X))) if len(front.X) else np.zeros(
            (0, space.dim))
        res.put("pareto", "params", params, units="mixed", dims=("point", "gene"),
                attrs={"gene_names": ",".join(space.names)})
        res.put("pareto", "F", front.F, units="1", dims=("point", "objective"),
                attrs={"meaning": "minimised objectives: sense * metric / |baseline metric|"})
        for j, o in enumerate(objs):
            res.put("pareto", o, front.F[:, j] / scale[j], units=METRIC_UNITS[o], dims=("point",))
        res.put("pareto", "reference_point", ref, units="1", dims=("objective",))
        res.put("pareto", "hypervolume_history", front.history_hv, units="1")
        res.set_attrs("pareto", hypervolume=hv, hypervolume_baseline_only=hv_base, n_points=len(front.X),
                      n_evals=front.n_evals, algorithm="pymoo NSGA-II",
                      reference="F_ref: 0.5 x baseline for maximised, 2 x baseline for minimised metrics "
                                "(ref_max_factor / ref_min_factor)")
        ctx.log(f"Pareto front: {len(front.X)} points, hypervolume {hv:.4g} (baseline alone {hv_base:.4g}) "
                f"w.r.t. reference {ref.tolist()} in normalised objective space")

    lap("pareto")

    # (4) refinement -----------------------------------------------------------------------------------------
    if e.refine.enabled:
        starts = [best]
        kinds = ["ga_best"]
        if front is not None and len(front.X) and int(e.refine.pareto_points) > 0:
            idx = np.unique(np.linspace(0, len(front.X) - 1, int(e.refine.pareto_points)).round().astype(int))
            starts += [front.X[i] for i in idx]
            kinds += [f"pareto_{i}" for i in idx]
        G0 = np.stack(starts)

        def true_fn(G):
            return batch_eval(np.asarray(G))

        dirs = [dict(pb.weights)] + [{o: 1.0 for o in objs}] * (len(G0) - 1)
        rr = refine(pb, space, G0, steps=int(e.refine.steps), learning_rate=float(e.refine.learning_rate),
                    tau=float(e.refine.tau), directions=dirs, true_fn=true_fn)
        res.put_axis("refine", "design", np.arange(len(G0)), units="1")
        res.put_axis("refine", "gene", np.arange(space.dim), units="1")
        res.put("refine", "kind", np.asarray(kinds, dtype=object), units="1", dims=("design",))
        res.put("refine", "genes_before", rr.genes_before, units="1", dims=("design", "gene"))
        res.put("refine", "genes_after", rr.genes_after, units="1", dims=("design", "gene"))
        for k in ("true_before", "true_after", "surrogate_before", "surrogate_after"):
            res.put("refine", k, getattr(rr, k), units="1", dims=("design",))
        res.put("refine", "accepted", rr.accepted.astype(np.uint8), units="1", dims=("design",))
        res.put("refine", "loss_history", rr.loss_history, units="1", dims=("design", "step"))
        for k in rr.metrics_before:
            res.put("refine", f"{k}_before", rr.metrics_before[k].astype(float), units=METRIC_UNITS.get(k, "1"),
                    dims=("design",))
            res.put("refine", f"{k}_after", rr.metrics_after[k].astype(float), units=METRIC_UNITS.get(k, "1"),
                    dims=("design",))
        res.set_attrs("refine", steps=int(e.refine.steps), learning_rate=float(e.refine.learning_rate),
                      tau=float(e.refine.tau), optimizer="optax.adam + projection_box",
                      objective="ga_best: the GA fitness; pareto_i: sum of the front's normalised objectives")
        for i, kd in enumerate(kinds):
            ctx.log(f"refine {kd}: true objective {rr.true_before[i]:.5g} -> {rr.true_after[i]:.5g} "
                    f"(surrogate {rr.surrogate_before[i]:.5g} -> {rr.surrogate_after[i]:.5g}), "
                    f"{'accepted' if rr.accepted[i] else 'rejected'}")
        if rr.accepted[0]:
            best = rr.genes_after[0]
            res.put("ga", "best_genes_refined", best, units="1", dims=("gene",))

    lap("refine")

    # (5) verification on a finer quadrature: baseline vs winner ---------------------------------------------
    v = _plain(e.verify) or {}
    vcfg = dict(_plain(e))
    vcfg["workspace"] = {**{k: x for k, x in (vcfg.get("workspace") or {}).items() if k not in ("r_max", "z_max")},
                         **{k: v[k] for k in ("n_r", "n_phi", "n_z") if k in v}}
    vcfg["cycle"] = {**(vcfg.get("cycle") or {}), "n_samples": int(v.get("cycle_samples", 201))}
    from ..optimize import Problem

    pv = Problem.from_config(vcfg, r_max=pb.settings["r_max"], z_max=pb.settings["z_max"])
    ev = jax.jit(jax.vmap(lambda g: evaluate_design(pv, space.decode(g))))
    cands = [base_genes, best]
    pick = None
    if front is not None and len(front.X):
        # the Pareto point that improves the baseline most in its worst objective (max-min), if any dominates it
        fb = np.asarray([base_true[o] for o in objs]) * scale
        gain = (fb[None, :] - front.F) / np.abs(fb[None, :])
        dom = np.all(gain >= 0, axis=1) & np.any(gain > 0, axis=1)
        if np.any(dom):
            pick = int(np.argmax(np.where(dom, gain.min(axis=1), -np.inf)))
            cands.append(front.X[pick])
    mv = {k: np.asarray(x) for k, x in ev(jnp.asarray(np.stack(cands))).items()}
    rows = []
    for k in ("volume", "volume_fixed", "good_volume", "task_index_mean", "task_index_min", "peak_torque",
              "cycle_time", "peak_speed"):
        b, w = float(mv[k][0]), float(mv[k][1])
        change = 100.0 * (w - b) / abs(b) if b != 0 else math.nan
        rows.append((k, b, w, change, PAPER_CLAIMS.get(k, math.nan)))
        if pick is not None:
            pv_k = float(mv[k][2])
            res.put("ga/comparison", f"{k}_pareto_pick", pv_k, units=METRIC_UNITS[k])
            res.put("ga/comparison", f"{k}_pareto_pick_change_percent", 100.0 * (pv_k - b) / abs(b) if b else math.nan,
                    units="%")
        res.put("ga/comparison", f"{k}_baseline", b, units=METRIC_UNITS[k])
        res.put("ga/comparison", f"{k}_best", w, units=METRIC_UNITS[k])
        res.put("ga/comparison", f"{k}_change_percent", change, units="%")
        if k in PAPER_CLAIMS:
            res.put("ga/comparison", f"{k}_paper_change_percent", PAPER_CLAIMS[k], units="%")
    res.set_attrs("ga/comparison", feasible_baseline=bool(mv["feasible"][0]), feasible_best=bool(mv["feasible"][1]),
                  quadrature=f"wedge n_r={v.get('n_r')} n_phi={v.get('n_phi')} n_z={v.get('n_z')}, "
                             f"cycle samples {v.get('cycle_samples')}",
                  best_params=str(space.describe(best)),
                  pareto_pick=-1 if pick is None else pick,
                  pareto_pick_params="" if pick is None else str(space.describe(front.X[pick])),
                  pareto_pick_feasible=bool(mv["feasible"][2]) if pick is not None else False,
                  baseline_params=str(space.describe(base_genes)))
    lap("verify")
    res.set_attrs("ga", **{f"time_{k}_s": v for k, v in timings.items()})
    ctx.log("baseline vs optimised (verification quadrature):")
    ctx.log(f"  {'metric':16s} {'baseline':>10s} {'GA best':>10s} {'change %':>9s} {'Pareto*':>10s} "
            f"{'change %':>9s} {'paper %':>8s}")
    for i, (k, b, w, c, p) in enumerate(rows):
        if pick is not None:
            pv_k = float(mv[k][2])
            extra = f"{pv_k:10.4g} {100.0 * (pv_k - b) / abs(b) if b else math.nan:9.1f}"
        else:
            extra = f"{'-':>10s} {'-':>9s}"
        ctx.log(f"  {k:16s} {b:10.4g} {w:10.4g} {c:9.1f} {extra} {'' if math.isnan(p) else f'{p:+.0f}':>8s}")
    if pick is not None:
        ctx.log(f"  Pareto* = the front's point that dominates the baseline with the largest worst-case gain: "
                f"{space.describe(front.X[pick])}")
    else:
        ctx.log("  no Pareto point dominates the baseline in all objectives")

    # plots ------------------------------------------------------------------------------------------------
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
    gens = np.arange(1, gres.generations_done + 1)
    feas = h["gen_best_fitness"] < 1e3
    ax[0].plot(gens, np.where(h["best_fitness"] < 1e3, h["best_fitness"], np.nan), label="best so far")
    ax[0].plot(gens[feas], h["gen_best_fitness"][feas], ".", label="best of generation")
    ax[0].axhline(fit_base, color="k", ls="--", lw=0.8, label="baseline")
    ax[0].set_xlabel("generation")
    ax[0].set_ylabel("fitness (minimised)")
    ax[0].legend()
    ax[0].set_title(f"{ga_cfg.algorithm}, population {ga_cfg.population_size}")
    ax[1].plot(gens, h["gen_feasible_fraction"])
    ax[1].set_xlabel("generation")
    ax[1].set_ylabel("feasible fraction of the population")
    ctx.savefig(fig, "ga_convergence")
    if front is not None and len(front.F):
        fig, ax = plt.subplots(figsize=(6, 4.5))
        o0, o1 = objs[0], objs[1]
        x, y = front.F[:, 0] / scale[0], front.F[:, 1] / scale[1]
        c = front.F[:, 2] / scale[2] if len(objs) > 2 else None
        sc = ax.scatter(x, y, c=c, cmap="viridis", label="Pareto front (NSGA-II)")
        if c is not None:
            fig.colorbar(sc, ax=ax, label=f"{objs[2]} [{METRIC_UNITS[objs[2]]}]")
        ax.plot(base_true[o0], base_true[o1], "k*", ms=12, label="baseline (franco2026)")
        ax.plot(float(mv[o0][1]) if o0 in mv else np.nan, float(mv[o1][1]) if o1 in mv else np.nan, "r^", ms=9,
                label="GA winner (verification)")
        ax.set_xlabel(f"{o0} [{METRIC_UNITS[o0]}]")
        ax.set_ylabel(f"{o1} [{METRIC_UNITS[o1]}]")
        ax.legend(fontsize=8)
        ctx.savefig(fig, "ga_pareto")
