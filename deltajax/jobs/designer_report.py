"""The main job's report: the baseline-vs-recommended summary (stored and printed) and the plots, drawn from the
stored results only (so a resumed run reports the same)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np

if TYPE_CHECKING:
    from ..optimize.robust import RobustChoice

__all__ = ["SUMMARY_METRICS", "FIXED_R_METRIC", "summary", "change_text", "print_summary", "plots", "tolerances_of",
           "store_tolerance", "store_robust", "store_frozen", "headline_lines", "cost_lines", "summary_attrs",
           "store_certify", "certify_lines", "store_ga", "store_pareto", "store_refine", "store_floor", "store_verify",
           "rule_text", "robust_text", "floor_line", "margins_text"]

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


def summary(ctx, res, data, space, objs, s) -> None:
    """Stage baseline vs recommended design, per metric with units and direction, and the parameters of each
    design (``data``: the results file as loaded after the verify stage)."""
    from ..optimize.certify import MARGIN_UNITS, overlay
    from ..optimize.designer import DESIGN_SENSE, DESIGN_UNITS

    V = overlay(data)          # the certified figures where the certify stage ran
    rec = int(V["attrs"]["recommended"])
    if rec < 0:
        ctx.log("no feasible design was found on the fine grids: no recommendation (loosen the constraints)")
        res.set_attrs("summary", recommended="none")
        return
    names = list(V["design_name"])
    params = V["params"]
    path_mode = s.reconfig.get("mode") == "path"  # rtmode
    metrics = SUMMARY_METRICS + (PATH_SUMMARY_METRICS if path_mode else ())
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
                                                       if path_mode else ")")})
        res.put("summary", f"{col}_fixed_R", np.asarray([_fixed_value(V, m, i) for m in metrics]), units="mixed",
                dims=("metric",), attrs={"design": names[i], "units_see": "metric_units",
                                         "variant": "fixed R = the operating R chosen for the task"})
    Cg = data.get("certify") or {}
    mn = [k for k in MARGIN_UNITS if f"margin_{k}" in Cg]
    if mn:    # every constraint's margin in units, for both designs (group certify holds every verified design's)
        res.put_axis("summary", "margin", np.arange(len(mn)), units="1")
        res.put("summary", "margin_name", np.asarray(mn, dtype=object), units="1", dims=("margin",))
        res.put("summary", "margin_units", np.asarray([MARGIN_UNITS[k] for k in mn], dtype=object), units="1",
                dims=("margin",))
        for col, i in (("baseline", 0), ("recommended", rec)):
            res.put("summary", f"{col}_margins", np.asarray([float(np.asarray(Cg[f"margin_{k}"]).reshape(-1)[i])
                                                             for k in mn]), units="mixed", dims=("margin",),
                    attrs={"meaning": ">= 0: the constraint holds by that much", "units_see": "margin_units",
                           "certified": int(np.asarray(Cg["certified"]).reshape(-1)[i])})
    res.put_axis("summary", "parameter", np.arange(space.dim), units="1")
    res.put("summary", "parameter_name", np.asarray(space.names, dtype=object), units="1", dims=("parameter",))
    res.put("summary", "parameter_units", np.asarray([space.units(n) for n in space.names], dtype=object),
            units="1", dims=("parameter",))
    res.put("summary", "baseline_params", params[0], units="mixed", dims=("parameter",))
    res.put("summary", "recommended_params", params[rec], units="mixed", dims=("parameter",))
    robust = V["attrs"].get("recommended_by")       # the tolerance stage's robust recommendation, when it found one
    res.set_attrs("summary", recommended=names[rec], rule=s.recommend,
                  rule_text=rule_text(s) + (f"; {robust}" if robust else ""), objectives=",".join(objs),
                  fixed_R_variant="R frozen at the operating R chosen for the task (same constraints); its picks/min "
                                  "and margins equal the reconfigurable design's at that R (mode per_task; with "
                                  "mode=path the reconfigurable design runs the cycle with R(t)), its regular "
                                  "workspace is the good set at that R alone (base plate as the reconfigurable "
                                  "design's)", operating_mode=s.reconfig.get("mode", "per_task"),
                  evaluation=("certified: worst cases searched, the density doubled to check them (group certify); "
                              "the other designs on the fine verification grids (group verify)") if mn else
                  "fine verification grids (group verify)")
    res.set_attrs("summary", required_margins=margins_text(s))
    if "tolerance" in data:   # the tolerance stage's headline figures (group tolerance holds the rest)
        res.set_attrs("summary", **summary_attrs(data["tolerance"]))


def margins_text(s) -> str:
    """``experiment.robust.margins`` in words ("none": the constraints as stated)."""
    from ..optimize.workflow import required_margins

    m = required_margins(s)
    parts = [f"index threshold +{m['index']:g}" if m["index"] else "",
             f"passive joints' limit -{m['joint_deg']:g} deg" if m["joint_deg"] else "",
             f"links' clearance +{m['clearance_mm']:g} mm" if m["clearance_mm"] else "",
             f"motor peak and rated torque -{m['motor_percent']:g} %" if m["motor_percent"] else ""]
    parts = [p for p in parts if p]
    return ", ".join(parts) if parts else "none"


def change_text(baseline: float, recommended: float, sense: int) -> str:
    """The table's change column: the relative change of a metric from the baseline to the recommended design
    and whether that is better or worse (``sense``: -1 higher is better, 1 lower is better, 0 describes the
    design: no verdict), e.g. ``"+21.7 % better"``; the verdict alone where a relative change means nothing (a
    value not positive, e.g. a negative margin), ``"-"`` where a value is not finite."""
    x, y = float(baseline), float(recommended)
    if not (np.isfinite(x) and np.isfinite(y)):
        return "-"
    verdict = {-1: "better" if y > x else "worse", 1: "better" if y < x else "worse"}.get(int(sense), "")
    if not (x > 0 and y > 0):
        return verdict if verdict and y != x else ("same" if sense else "-")
    pct = 100 * (y - x) / x
    if round(pct, 1) == 0:
        return "0.0 % same" if sense else "0.0 %"
    return f"{pct:+.1f} % {verdict}".rstrip()


def print_summary(ctx, data) -> None:
    from ..optimize.designer import DESIGN_SENSE, FEASIBILITY_TOL
    from ..optimize.workflow import STORED_METRIC

    S = data.get("summary")
    if not S or "metric_name" not in S:
        return
    names = list(S["metric_name"])
    units = list(S["metric_units"])
    dirs = list(S["direction"])
    b, r = S["baseline"], S["recommended"]
    bf, rf = S["baseline_fixed_R"], S["recommended_fixed_R"]
    rec = S["attrs"]["recommended"]
    where = "certified" if "margin_name" in S else "fine verification grids"
    ctx.log(f"baseline (franco2026 + motor) vs recommended design ({rec}; rule {S['attrs'].get('rule_text', '')}), "
            f"{where}; reconfigurable (R per point) | fixed R (R frozen at the operating R):")
    ctx.log(f"  {'metric':20s} {'units':6s} {'baseline':>9s} {'recommended':>11s} {'change':>15s} | "
            f"{'base fixR':>9s} {'rec fixR':>9s}  direction")
    for n, u, d, x, y, xf, yf in zip(names, units, dirs, b, r, bf, rf):
        ch = change_text(x, y, DESIGN_SENSE.get(n, 0))
        ctx.log(f"  {n:20s} {u:6s} {x:9.4g} {y:11.4g} {ch:>15s} | {xf:9.4g} {yf:9.4g}  {d}")
    from ..optimize.certify import overlay

    V = overlay(data)
    if V is not None and "feasible" in V:   # on the same fine grids as the table (the search grids may differ)
        names_v = list(V["design_name"])
        for who, name in (("baseline", names_v[0]), ("recommended", rec)):
            i = names_v.index(name)
            g = np.asarray(V[STORED_METRIC["g"]], float)[i]
            bad = [str(c) for c, v in zip(V["constraint_names"], g) if not v <= FEASIBILITY_TOL]  # NaN: violated
            on = "certified" if "margin_name" in S else "on the fine grids"
            ctx.log(f"  {who} {on}: " + ("feasible (every constraint met)" if bool(V["feasible"][i])
                                         else "infeasible" + (f", violates {', '.join(bad)} on the fine grids"
                                                              if bad else "")))
    req = S["attrs"].get("required_margins", "none")
    if req != "none":
        ctx.log(f"  every constraint required with a margin (experiment.robust.margins): {req}; the feasibility and "
                "the margins below are against the tightened constraints, the tolerance analysis against the "
                "stated ones")
    if "margin_name" in S:
        ctx.log("  margins (>= 0: the constraint holds by that much; certified):")
        ctx.log(f"  {'margin':26s} {'units':7s} {'baseline':>10s} {'recommended':>11s}")
        for n, u, x, y in zip(S["margin_name"], S["margin_units"], S["baseline_margins"], S["recommended_margins"]):
            ctx.log(f"  {n:26s} {u:7s} {x:10.4g} {y:11.4g}")
        for line in certify_lines(data.get("certify") or {}):
            ctx.log(line)
    T = data.get("tolerance")
    if T is not None and "role" in T:
        ctx.log(f"  tolerance analysis (group tolerance; {T['attrs'].get('tolerances', '')}):")
        for line in headline_lines(T, ("baseline", "recommended", "nominal_recommended")) + cost_lines(T):
            ctx.log(line)
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


def plots(ctx, data, objs, s) -> None:
    """Plots drawn from the staged results only (so a resumed run draws the same figures)."""
    from .. import plots as P
    from ..optimize.designer import DESIGN_UNITS

    G = data.get("ga", {})
    # the GA minimises -picks/min / |baseline picks/min| when picks/min is its only objective
    scale = (abs(float(G["attrs"]["baseline_primary"]))
             if s.objectives.mode != "weighted" and s.objectives.primary == "picks_per_min" and "baseline_primary" in G.get("attrs", {})
             else None)
    seeds = ["the baseline"]
    if s.screen.enabled and not s.objectives.primary.startswith("regular"):
        seeds.append("the screen's best designs")
    if s.continue_from is not None:
        seeds.append("the earlier run's front")
    fig = P.ga_convergence(G, picks_per_fitness=scale, seeds=", ".join(seeds) + ", random members")
    if fig is not None:
        ctx.savefig(fig, "ga_convergence")
    from ..optimize.certify import overlay

    V = overlay(data)          # the certified figures, front and margins where the certify stage ran
    fig = P.ga_pareto(V, objs, s, DESIGN_UNITS, floor=floor_line(V, objs, s) if V is not None else None)
    if fig is not None:
        ctx.savefig(fig, "ga_pareto")


def floor_line(V, objs, s):
    """``(objective, value)``: the floor rule's threshold on the plotted objective that is not the primary, in
    its own units (the verified baseline's value times ``recommend_floor`` if maximised, divided if minimised: the
    rule's :func:`deltajax.optimize.workflow.floor_limits` in the objective's units); None for another rule or when
    the primary is not one of the two plotted objectives."""
    from ..optimize.designer import DESIGN_SENSE
    from ..optimize.workflow import floor_limits

    if s.recommend != "floor" or s.objectives.primary not in objs[:2] or len(objs) < 2:
        return None
    o = objs[1] if s.objectives.primary == objs[0] else objs[0]
    lim = floor_limits(len(objs), list(objs).index(s.objectives.primary), s.recommend_floor, [DESIGN_SENSE[k] for k in objs])
    return o, abs(float(lim[list(objs).index(o)])) * abs(float(np.asarray(V[o], float)[0]))


def rule_text(s) -> str:
    """The recommendation rule in words (stored and printed with the recommendation)."""
    if s.recommend == "floor":
        others = [o for o in s.objectives.names if o != s.objectives.primary]
        return (f"floor: the best {s.objectives.primary} among verified front points with {', '.join(others)} at least "
                f"{s.recommend_floor:g} x the verified baseline's (if none has: the point closest to that floor)"
                + ("; the floor step's designs included" if s.floor_solve.enabled else ""))
    if s.recommend == "band":
        return (f"band: among verified front points whose {s.objectives.primary} is within {100 * s.recommend_band:g} % of "
                f"the front's best, the best on {', '.join(o for o in s.objectives.names if o != s.objectives.primary)}")
    if s.recommend == "knee":
        return "knee of the verified front (objectives normalised over the front)"
    return f"best {s.objectives.primary} on the verified front"


def robust_text(s) -> str:
    """The robust recommendation's requirement in words (``experiment.robust``)."""
    return (f"robust: the rule applied among verified candidates holding every constraint in >= "
            f"{100 * s.robust.probability:g} % of {s.tolerance.samples} Monte Carlo samples "
            f"(seed {s.tolerance.seed}), confirmed by a fresh Monte Carlo (seed {s.robust.confirm_seed})")


def store_ga(res, gres, space, ga_cfg, ga_what: str, base_genes, seeds, baseline_primary: float, best_params,
             fingerprint: str) -> None:
    """Group ``ga``: the GA's per-generation history, its best design (genes and parameters), the gene bounds and
    the run's settings (:func:`deltajax.optimize.run_ga`'s result ``gres``; ``fingerprint``: the run's, which its
    checkpoint carried)."""
    from ..optimize.designer import DESIGN_UNITS

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
    res.put("ga", "best_genes", gres.best_genes, units="1", dims=("gene",))
    res.put("ga", "best_params", best_params, units="mixed", dims=("gene",), attrs=gene_units)
    res.put("ga", "baseline_genes", base_genes, units="1", dims=("gene",))
    res.set_attrs("ga", algorithm=ga_cfg.algorithm, population_size=ga_cfg.population_size,
                  generations=ga_cfg.generations, sigma=ga_cfg.sigma, seed=ga_cfg.seed,
                  fitness_best=gres.best_fitness, objective=ga_what, resumed_from=gres.resumed_from,
                  fingerprint=fingerprint, seeded_with=len(seeds), baseline_primary=baseline_primary,
                  constraint_handling="feasibility_first (1e3 + violation)")


def store_pareto(res, front, extra_X, objs, s) -> None:
    """Group ``pareto``: NSGA-II's feasible front on the search grids (genes, normalised objectives), the
    feasible final-population designs off it, and the hypervolume history."""
    res.put_axis("pareto", "point", np.arange(len(front.X)), units="1")
    res.put_axis("pareto", "gene", np.arange(extra_X.shape[1]), units="1")
    res.put_axis("pareto", "objective", np.arange(len(objs)), units="1")
    res.put("pareto", "population_feasible_genes", extra_X, units="1", dims=("population_point", "gene"),
            attrs={"meaning": "feasible final-population designs off the search front (verified too)"})
    res.put("pareto", "genes", front.X, units="1", dims=("point", "gene"))
    res.put("pareto", "F_search", front.F, units="1", dims=("point", "objective"),
            attrs={"meaning": "minimised objectives on the search grids: sense x metric / |baseline metric|"})
    res.put("pareto", "objective_names", np.asarray(objs, dtype=object), units="1", dims=("objective",))
    res.put("pareto", "hypervolume_history", front.history_hv, units="1", dims=("generation",))
    res.set_attrs("pareto", n_evals=front.n_evals, algorithm="pymoo NSGA-II",
                  population_size=s.pareto.population_size, generations=s.pareto.generations)


def store_refine(res, ro, refined, space, objs, s) -> None:
    """Group ``refine``: each winner before and after the optax refinement, and which were accepted."""
    res.put_axis("refine", "winner", np.arange(len(ro.accepted)), units="1")
    res.put_axis("refine", "gene", np.arange(space.dim), units="1")
    res.put_axis("refine", "objective", np.arange(len(objs)), units="1")
    res.put_axis("refine", "accepted_design", np.arange(len(refined)), units="1")
    for k in ("genes_before", "genes_after", "F_before", "F_after"):
        res.put("refine", k, getattr(ro, k), units="1", dims=("winner", "gene" if "genes" in k else "objective"))
    res.put("refine", "accepted", ro.accepted.astype(np.uint8), units="1", dims=("winner",))
    res.put("refine", "accepted_genes", refined, units="1", dims=("accepted_design", "gene"))
    res.set_attrs("refine", rule="accepted iff feasible on the search grids, no objective worse, primary better",
                  steps=s.refine.steps, learning_rate=s.refine.learning_rate, penalty=s.refine.penalty)


def store_floor(res, fo, names, first: int, objs, s) -> None:
    """Group ``floor``: what the floor step (:func:`deltajax.optimize.floor.solve_floor`) verified: each design's
    row in ``verify`` (``first`` onward), the verified design it descended from, its iterate and the predicted
    objectives."""
    res.put_axis("floor", "design", np.arange(len(fo.genes)), units="1")
    res.put_axis("floor", "objective", np.arange(len(objs)), units="1")
    res.put("floor", "verify_row", np.arange(first, first + len(fo.genes)), units="1", dims=("design",),
            attrs={"meaning": "row of each floor-step design on verify's design axis"})
    res.put("floor", "start", np.asarray([names[i] for i in fo.start], dtype=object), units="1", dims=("design",),
            attrs={"meaning": "the verified front point its descent started from"})
    res.put("floor", "step", fo.step, units="1", dims=("design",),
            attrs={"meaning": f"descent iterate (steps of experiment.refine.steps={s.refine.steps} per round)"})
    res.put("floor", "F_predicted", fo.predicted, units="1", dims=("design", "objective"),
            attrs={"meaning": "predicted fine-grid objectives (search-grid values x the start's fine/search "
                              "ratio), normalised like verify/F"})
    res.set_attrs("floor", starts=",".join(names[i] for i in fo.starts), predicted_to_meet_floor=fo.n_predicted,
                  rounds=s.floor_solve.rounds, candidates=s.floor_solve.candidates,
                  method="epsilon-constraint: projected Adam on the primary objective + constraint penalty from each "
                         "verified front point that meets the floor; iterates predicted to meet it verified")


def store_verify(res, space, cand, names, mv, Fv, nd, rec, hv, hv_base, ref, objs, s) -> None:
    """Group ``verify``: every candidate's fine-grid metrics, constraint values, parameters, the front, the
    recommendation and the hypervolume with its reference."""
    import jax
    import jax.numpy as jnp

    from ..optimize.designer import CONSTRAINT_NAMES, DESIGN_UNITS
    from ..optimize.workflow import STORED_METRIC

    res.put_axis("verify", "design", np.arange(len(cand)), units="1")
    res.put_axis("verify", "gene", np.arange(space.dim), units="1")
    res.put_axis("verify", "constraint", np.arange(len(CONSTRAINT_NAMES)), units="1")
    res.put_axis("verify", "objective", np.arange(len(objs)), units="1")
    res.put("verify", "design_name", np.asarray(names, dtype=object), units="1", dims=("design",))
    res.put("verify", "constraint_names", np.asarray(CONSTRAINT_NAMES, dtype=object), units="1", dims=("constraint",))
    res.put("verify", "genes", cand, units="1", dims=("design", "gene"))
    params = np.asarray(jax.vmap(space.to_params)(jnp.asarray(cand)))
    res.put("verify", "params", params, units="mixed", dims=("design", "gene"),
            attrs={"gene_names": ",".join(space.names),
                   "units_per_gene": ",".join(space.units(n) for n in space.names)})
    for k, v in mv.items():
        if k == "g":
            res.put("verify", STORED_METRIC[k], v, units="1", dims=("design", "constraint"),
                    attrs={"meaning": "normalised constraint values, <= 0 satisfied (see deltajax.optimize.designer)"})
        else:
            res.put("verify", k, v.astype(float) if v.dtype != bool else v.astype(np.uint8),
                    units=DESIGN_UNITS.get(k, "1"), dims=("design",))
    res.put("verify", "front", np.asarray(nd, int), units="1", dims=("front_point",),
            attrs={"meaning": "indices (design axis) of the verified Pareto front, sorted by the first objective"})
    res.put("verify", "F", Fv, units="1", dims=("design", "objective"),
            attrs={"meaning": "minimised objectives: sense x metric / |verified baseline metric|"})
    v = s.verify
    res.set_attrs("verify", recommended=int(rec), recommend_rule=s.recommend, recommend_rule_text=rule_text(s),
                  recommend_band=s.recommend_band, recommend_floor=s.recommend_floor,
                  search_regular_measure=(f"refine_cylinder, {s.search_refine[0]} steps, samples {s.search_refine[1]}"
                                          if s.search_refine else "polar grid"),
                  hypervolume=hv, hypervolume_baseline_only=hv_base,
                  hypervolume_reference="objectives normalised by the baseline verified on the fine grids "
                                        "(sense x metric / |baseline|); reference point 0 for maximised objectives "
                                        f"(zero picks/min, zero volume), {s.pareto.ref_min_factor} x baseline for "
                                        "minimised ones",
                  reference_point=np.asarray(ref), objectives=",".join(objs),
                  grids=f"task {v.task_n_r}x{v.task_n_phi}x{v.task_n_z}, cycle {v.cycle_samples} samples, "
                        f"regular grid {v.rw_n_z}x{v.rw_n_r}x{v.rw_n_phi}, n_R {v.n_R}, operating-R "
                        f"candidates {v.n_R_operating}")


# -- the certify stage's group (deltajax.optimize.certify computes, this stores and prints) -----------------------

def store_certify(res, names, cert: dict, feas, marg: dict, front, Fv, rec: int, rec0: int, floor, s) -> None:
    """Group ``certify``: per verified design (``design``, verify's axis) its margins in units and whether it was
    certified; per certified design (``certified_design``; ``row`` on verify's axis) every certified figure, the
    first density's figure, the change doubling made and whether every change is within its tolerance; the front
    and the normalised objectives with the certified figures in place; attributes: the tolerances, the method, the
    certified recommendation."""
    from ..optimize.certify import CERTIFIED_METRICS, MARGIN_UNITS, RAY_PASSES, TOLERANCES
    from ..optimize.designer import DESIGN_UNITS

    g = "certify"
    n = len(names)
    rows = sorted(cert)
    res.put_axis(g, "design", np.arange(n), units="1")
    res.put_axis(g, "certified_design", np.arange(len(rows)), units="1")
    res.put(g, "certified", np.asarray([i in cert for i in range(n)], np.uint8), units="1", dims=("design",),
            attrs={"meaning": "1: the design's figures are certified (worst cases searched, doubling checked)"})
    for k, v in marg.items():
        res.put(g, f"margin_{k}", np.asarray(v, float), units=MARGIN_UNITS[k], dims=("design",),
                attrs={"meaning": "margin to the constraint (>= 0: met by that much); the certified figures where "
                                  "certified, else the fine verification's"})
    res.put(g, "row", np.asarray(rows, int), units="1", dims=("certified_design",),
            attrs={"meaning": "row on verify's design axis"})
    res.put(g, "design_name", np.asarray([names[i] for i in rows], dtype=object), units="1",
            dims=("certified_design",))
    for k in CERTIFIED_METRICS:
        res.put(g, k, np.asarray([cert[i][k] for i in rows], float), units=DESIGN_UNITS.get(k, "1"),
                dims=("certified_design",))
    for k in TOLERANCES:
        u = DESIGN_UNITS.get(k, "1")
        res.put(g, f"{k}_first", np.asarray([cert[i][f"{k}_first"] for i in rows], float), units=u,
                dims=("certified_design",), attrs={"meaning": "the figure at the verification's density"})
        res.put(g, f"{k}_change", np.asarray([cert[i][f"{k}_change"] for i in rows], float),
                units="1" if k == "regular_volume" else u, dims=("certified_design",),
                attrs={"meaning": "change of the figure when the density is doubled"
                                  + (" (relative)" if k == "regular_volume" else "")})
    res.put(g, "converged", np.asarray([cert[i]["converged"] for i in rows], np.uint8), units="1",
            dims=("certified_design",), attrs={"meaning": "1: every change of the last doubling within its tolerance"})
    res.put(g, "doublings", np.asarray([cert[i]["doublings"] for i in rows], int), units="1",
            dims=("certified_design",),
            attrs={"meaning": "times the first density was doubled (1: the first doubling settled every figure; "
                              "more while a figure moved more than its tolerance, at most 1 + max_extra_doublings)"})
    res.put(g, "cycle_samples", np.asarray([cert[i]["cycle_samples"] for i in rows], int), units="1",
            dims=("certified_design",), attrs={"meaning": "cycle samples of the density reached (the figures')"})
    res.put(g, "feasible", np.asarray(feas, np.uint8)[rows], units="1", dims=("certified_design",))
    res.put(g, "front", np.asarray(front, int), units="1", dims=("front_point",),
            attrs={"meaning": "the verified front with the certified figures in place (rows of verify's design axis)"})
    if Fv is not None:
        res.put_axis(g, "objective", np.arange(Fv.shape[1]), units="1")
        res.put(g, "F", np.asarray(Fv, float), units="1", dims=("design", "objective"),
                attrs={"meaning": "minimised objectives with the certified figures in place: sense x metric / "
                                  "|certified baseline metric|"})
    v, t = s.verify, s.task
    res.set_attrs(g, recommended=int(rec), recommended_name=names[rec] if rec >= 0 else "none",
                  verified_recommended=names[rec0] if rec0 >= 0 else "none",
                  **{f"tolerance_{k}": float(x) for k, x in TOLERANCES.items()},
                  tolerance_units="regular_volume relative; joint_margin_deg deg; interference_margin m; "
                                  "utilisations and index 1",
                  volume_floor=float("nan") if floor is None else float(floor),
                  max_extra_doublings=int(v.certify_doublings),
                  method=f"regular workspace by rays ({v.rw_n_z} levels x {v.rw_n_phi} rays per pass, "
                         f"{v.rw_n_r} samples along a ray, passes {','.join(RAY_PASSES)}); task cylinder "
                         f"{int(t.n_r) + 1} x {2 * int(t.n_phi) - 1} x {int(t.n_z) + 2} samples + golden-"
                         f"section search from the worst; cycle {8 * (int(v.cycle_samples) - 1) + 1} samples + "
                         "golden-section search in t from the worst joint margin, clearance and peak torque utilisation (the RMS "
                         "from the samples); then every density doubled, and doubled again (at most "
                         f"{int(v.certify_doublings)} more times) while a figure moved more than its tolerance")


def certify_lines(Cg) -> list:
    """Printed lines of the ``certify`` group (as loaded): per certified design the regular volume and the change
    doubling the density made, and whether every figure is within its tolerance."""
    if not Cg or "row" not in Cg:
        return []
    out = []
    tol = float(Cg["attrs"].get("tolerance_regular_volume", float("nan")))
    for j, name in enumerate(np.asarray(Cg["design_name"]).reshape(-1)):
        ch = {k[:-7]: float(np.asarray(Cg[k]).reshape(-1)[j]) for k in Cg if k.endswith("_change")}
        worst = [k for k, x in ch.items() if not x <= float(Cg["attrs"].get(f"tolerance_{k}", np.inf))]
        vol = 1e3 * float(np.asarray(Cg["regular_volume"]).reshape(-1)[j])
        moved = 100 * ch.get("regular_volume", float("nan"))
        nd = int(np.asarray(Cg["doublings"]).reshape(-1)[j]) if "doublings" in Cg else 1
        again = f", after {nd} doublings" if nd > 1 else ""
        out.append(f"  certified {name}: regular volume {vol:.4g} L (doubling the density moved it {moved:.2f} %"
                   f"{again}, tolerance {100 * tol:g} %)" + ("; every figure within its tolerance" if not worst else
                                                             f"; NOT within tolerance: {', '.join(worst)}"))
    return out


# -- the tolerance stage's groups and summary lines (deltajax.optimize.robust chooses, this stores and prints) ----

def tolerances_of(s):
    """The :class:`deltajax.tolerance.Tolerances` of the validated settings' ``tolerance`` block."""
    from ..config.ga_reconfig import tolerances_of as of

    return of(s.tolerance)


def _put_design_block(res, group: str, names, rows, a: dict, tol_text: str, roles=None) -> None:
    """One :func:`deltajax.tolerance.analyse` result (designs ``names`` at verify ``rows``) into ``group``."""
    from ..tolerance import CONSTRAINT_METRICS, PARAMETERS, PERCENTILES
    from ..optimize.designer import DESIGN_UNITS

    cn = list(a["constraint_names"])
    res.put_axis(group, "design", np.arange(len(names)), units="1")
    res.put_axis(group, "constraint", np.arange(len(cn)), units="1")
    res.put_axis(group, "percentile", np.asarray(PERCENTILES, float), units="%")
    res.put_axis(group, "parameter", np.arange(len(PARAMETERS)), units="1")
    res.put(group, "design_name", np.asarray(names, dtype=object), units="1", dims=("design",))
    res.put(group, "verify_row", np.asarray(rows, int), units="1", dims=("design",),
            attrs={"meaning": "row of each design on verify's design axis"})
    if roles is not None:
        res.put(group, "role", np.asarray(roles, dtype=object), units="1", dims=("design",),
                attrs={"meaning": "baseline | recommended (the run's recommendation) | nominal_recommended (robust "
                                  "mode: the recommendation without the robustness requirement)"})
    res.put(group, "constraint_names", np.asarray(cn, dtype=object), units="1", dims=("constraint",))
    res.put(group, "constraint_enabled", np.asarray(a["enabled"], np.uint8), units="1", dims=("constraint",))
    res.put(group, "p_all", a["p_all"], units="1", dims=("design",),
            attrs={"meaning": "fraction of the Monte Carlo samples in which every constraint holds (a NaN margin "
                              "counts as violated)"})
    res.put(group, "p_all_lower95", a["p_all_lower95"], units="1", dims=("design",),
            attrs={"meaning": "one-sided 95 % Clopper-Pearson lower bound of p_all"})
    res.put(group, "p_holds", a["p_holds"], units="1", dims=("design", "constraint"),
            attrs={"meaning": "fraction of the samples in which each constraint holds"})
    res.put(group, "nominal_feasible", np.asarray(a["nominal_feasible"], np.uint8), units="1", dims=("design",),
            attrs={"meaning": "the unperturbed design, through the same program"})
    res.put(group, "nominal_picks_per_min", a["nominal_picks_per_min"], units="1/min", dims=("design",))
    res.put(group, "picks_mean", a["picks_mean"], units="1/min", dims=("design",),
            attrs={"meaning": "mean picks/min over the samples whose cycle is reachable"})
    res.put(group, "picks_min", a["picks_min"], units="1/min", dims=("design",),
            attrs={"meaning": "smallest picks/min of the samples (NaN if any sample's cycle is unreachable)"})
    res.put(group, "picks_nan", a["picks_nan"], units="1", dims=("design",),
            attrs={"meaning": "samples whose cycle is unreachable (picks/min NaN)"})
    res.put(group, "picks_percentiles", a["picks_percentiles"], units="1/min", dims=("design", "percentile"),
            attrs={"meaning": "picks/min percentiles over the samples (NaN ranked lowest)"})
    res.put(group, "p_reaches_nominal_picks", a["p_reaches_nominal_picks"], units="1", dims=("design",),
            attrs={"meaning": "fraction of the samples whose picks/min reaches the nominal design's"})
    res.put(group, "g_percentiles", a["g_percentiles"], units="1", dims=("design", "constraint", "percentile"),
            attrs={"meaning": "percentiles of the normalised constraint values (<= 0 holds; NaN margins count 1)"})
    res.put(group, "metric_percentiles", a["metric_percentiles"], units="mixed",
            dims=("design", "constraint", "percentile"),
            attrs={"meaning": "percentiles of the metric behind each constraint (NaN ranked worst)",
                   "metric_per_constraint": ",".join(CONSTRAINT_METRICS[c][0] for c in cn),
                   "units_per_constraint": ",".join(DESIGN_UNITS[CONSTRAINT_METRICS[c][0]] for c in cn)})
    res.put(group, "parameter_name", np.asarray([p[0] for p in PARAMETERS], dtype=object), units="1",
            dims=("parameter",))
    res.put(group, "parameter_units", np.asarray([p[2] for p in PARAMETERS], dtype=object), units="1",
            dims=("parameter",), attrs={"meaning": "units of the deviations: m, deg, or 1 (relative)"})
    res.put(group, "deviations", a["deviations"], units="mixed", dims=("sample", "parameter"),
            attrs={"meaning": "the Monte Carlo samples' deviations (units: parameter_units)"})
    t = a["tolerances"]
    res.set_attrs(group, samples=int(a["samples"]), seed=int(a["seed"]), tolerances=tol_text,
                  distribution=t["distribution"], length_m=t["length"], joint_offset_deg=t["joint_offset_deg"],
                  mass_relative=t["mass"], motor_relative=t["motor"],
                  grids="the verification problem (fine grids, group verify), regular workspace not evaluated")


def store_tolerance(res, roles, names, rows, a: dict, tol_text: str) -> None:
    """Group ``tolerance``: the Monte Carlo of the baseline and the recommendation (robust mode: and the nominal
    recommendation), one entry per ``roles`` (a design may appear under two roles)."""
    _put_design_block(res, "tolerance", names, rows, a, tol_text, roles=roles)


def store_robust(res, rc: RobustChoice, design_names: Sequence[str], nominal: int, mv, s, tol_text: str) -> None:
    """Group ``tolerance/robust``: the designs checked, their probabilities, the confirmation, the cost."""
    g = "tolerance/robust"
    res.put_axis(g, "checked", np.arange(len(rc.checked)), units="1")
    res.put(g, "checked_name", np.asarray([design_names[i] for i in rc.checked], dtype=object), units="1",
            dims=("checked",))
    res.put(g, "checked_row", np.asarray(rc.checked, int), units="1", dims=("checked",),
            attrs={"meaning": "verify rows checked, in the order the rule picked them"})
    res.put(g, "p_selection", np.asarray(rc.p_selection, float), units="1", dims=("checked",),
            attrs={"meaning": f"fraction of the samples (seed {s.tolerance.seed}) in which every constraint holds"})
    res.put(g, "p_confirm", np.asarray(rc.p_confirm, float), units="1", dims=("checked",),
            attrs={"meaning": f"the fresh Monte Carlo's fraction (seed {s.robust.confirm_seed}); NaN: not "
                              "confirmed (below the probability in the selection)"})
    if rc.confirm is not None:
        _put_design_block(res, f"{g}/confirm", [design_names[rc.chosen]], [rc.chosen], rc.confirm, tol_text)
    cost = {}
    for who, i in (("nominal", nominal), ("robust", rc.chosen)):
        for m in ("picks_per_min", "regular_volume"):
            cost[f"{who}_{m}"] = float(mv[m][i]) if i >= 0 else float("nan")
    res.set_attrs(g, probability=float(s.robust.probability), confirm_seed=int(s.robust.confirm_seed),
                  selection_seed=int(s.tolerance.seed), max_candidates=int(s.robust.max_candidates),
                  nominal_recommended=design_names[nominal] if nominal >= 0 else "none",
                  robust_recommended=design_names[rc.chosen] if rc.chosen >= 0 else "none",
                  exhausted=bool(rc.exhausted),
                  p_nominal=float(rc.p_selection[0]) if rc.checked and rc.checked[0] == nominal else float("nan"),
                  p_robust_selection=float(rc.p_selection[list(rc.checked).index(rc.chosen)]) if rc.chosen >= 0
                  else float("nan"),
                  p_robust_confirm=float(rc.confirm["p_all"][0]) if rc.confirm is not None else float("nan"),
                  rule="the recommendation rule among verified candidates holding every constraint in >= probability "
                       "of the Monte Carlo samples (checked lazily, the chosen one confirmed by a fresh Monte Carlo)",
                  **cost)


def store_frozen(res, roles, names, rows, a: dict, tol_text: str) -> None:
    """Group ``tolerance/frozen_R``: the same samples with each design held at its nominal operating R."""
    _put_design_block(res, "tolerance/frozen_R", names, rows, a, tol_text, roles=roles)
    res.set_attrs("tolerance/frozen_R", operating_R="each sample run at its design's nominal operating R (moved by "
                  "the R actuator's deviation, that of R_min); group tolerance: the R re-chosen per sample")


def headline_lines(T, roles: Sequence[str]) -> list:
    """Printed lines of the ``tolerance`` group (as loaded): for each of ``roles`` the probability that every
    constraint holds and the picks/min percentiles."""
    from ..tolerance import PERCENTILES

    q = list(PERCENTILES)
    tr = [str(x) for x in T["role"]]
    out = []
    for who in roles:
        if who not in tr:
            continue
        i = tr.index(who)
        pp = np.asarray(T["picks_percentiles"], float)[i]
        held = np.asarray(T["p_holds"], float)[i]
        cn = list(T["constraint_names"])
        weak = [f"{c} {100 * h:.1f} %" for c, h in zip(cn, held) if h < 1.0]
        out.append(f"  {who} ({T['design_name'][i]}): every constraint holds in {100 * float(T['p_all'][i]):.1f} % of {T['attrs']['samples']} "
                   f"samples (95 % lower bound {100 * float(T['p_all_lower95'][i]):.1f} %); picks/min p5 {pp[q.index(5.0)]:.4g}"
                   f" / p50 {pp[q.index(50.0)]:.4g} / p95 {pp[q.index(95.0)]:.4g} (nominal "
                   f"{float(T['nominal_picks_per_min'][i]):.4g})" + (f"; holds: {', '.join(weak)}" if weak else ""))
        Fz = T.get("frozen_R")
        if Fz is not None:
            held = np.asarray(Fz["p_holds"], float)[i]
            weak = [f"{c} {100 * h:.1f} %" for c, h in zip(cn, held) if h < 1.0]
            out.append(f"    at its nominal operating R (not re-chosen per built robot): every constraint holds in "
                       f"{100 * float(Fz['p_all'][i]):.1f} %" + (f"; holds: {', '.join(weak)}" if weak else ""))
    return out


def summary_attrs(T) -> dict:
    """The ``summary`` group's attributes of the ``tolerance`` group (as loaded): per role the probability that
    every constraint holds and the picks/min p5 / p50 / p95."""
    from ..tolerance import PERCENTILES

    q = list(PERCENTILES)
    out = {}
    for i, who in enumerate(str(x) for x in T["role"]):
        pp = np.asarray(T["picks_percentiles"], float)[i]
        out[f"{who}_p_all_constraints_hold"] = float(T["p_all"][i])
        if "frozen_R" in T:
            out[f"{who}_p_all_constraints_hold_at_nominal_R"] = float(T["frozen_R"]["p_all"][i])
        for p in (5.0, 50.0, 95.0):
            out[f"{who}_picks_p{p:g}"] = float(pp[q.index(p)])
    out["tolerance_samples"] = int(T["attrs"]["samples"])
    return out


def cost_lines(T) -> list:
    """Printed lines of ``tolerance/robust`` (as loaded): what the robust recommendation costs."""
    Rb = T.get("robust")
    if Rb is None:
        return []
    a = Rb["attrs"]
    if a["robust_recommended"] == "none":
        return [f"  robust: no verified candidate holds every constraint in >= {100 * float(a['probability']):g} % of "
                f"the samples ({len(np.atleast_1d(Rb['checked_row']))} checked); the recommendation is the nominal one"]
    return [f"  robustness costs: nominal {a['nominal_recommended']} {float(a['nominal_picks_per_min']):.4g} picks/min, "
            f"{1e3 * float(a['nominal_regular_volume']):.4g} L regular, holds in {100 * float(a['p_nominal']):.1f} % -> "
            f"robust {a['robust_recommended']} {float(a['robust_picks_per_min']):.4g} picks/min, "
            f"{1e3 * float(a['robust_regular_volume']):.4g} L, holds in {100 * float(a['p_robust_selection']):.1f} % "
            f"(fresh Monte Carlo, seed {int(a['confirm_seed'])}: {100 * float(a['p_robust_confirm']):.1f} %)"]
