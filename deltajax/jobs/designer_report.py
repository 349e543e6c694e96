"""The main job's report: the baseline-vs-recommended summary (stored and printed) and the plots, drawn from the
stored results only (so a resumed run reports the same)."""

from __future__ import annotations

import numpy as np

__all__ = ["SUMMARY_METRICS", "FIXED_R_METRIC", "summary", "change_text", "print_summary", "plots"]

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
    from ..optimize.designer import DESIGN_SENSE, DESIGN_UNITS

    V = data["verify"]
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
                  evaluation="fine verification grids (group verify)")
    if "tolerance" in data:   # the tolerance stage's headline figures (group tolerance holds the rest)
        from ..optimize.robust import summary_attrs

        res.set_attrs("summary", **summary_attrs(data["tolerance"]))


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
    ctx.log(f"baseline (franco2026 + motor) vs recommended design ({rec}; rule {S['attrs'].get('rule_text', '')}), "
            "fine verification grids; reconfigurable (R per point) | fixed R (R frozen at the operating R):")
    ctx.log(f"  {'metric':20s} {'units':6s} {'baseline':>9s} {'recommended':>11s} {'change':>15s} | "
            f"{'base fixR':>9s} {'rec fixR':>9s}  direction")
    for n, u, d, x, y, xf, yf in zip(names, units, dirs, b, r, bf, rf):
        ch = change_text(x, y, DESIGN_SENSE.get(n, 0))
        ctx.log(f"  {n:20s} {u:6s} {x:9.4g} {y:11.4g} {ch:>15s} | {xf:9.4g} {yf:9.4g}  {d}")
    V = data.get("verify")
    if V is not None and "feasible" in V:   # on the same fine grids as the table (the search grids may differ)
        names_v = list(V["design_name"])
        for who, name in (("baseline", names_v[0]), ("recommended", rec)):
            i = names_v.index(name)
            g = np.asarray(V[STORED_METRIC["g"]], float)[i]
            bad = [str(c) for c, v in zip(V["constraint_names"], g) if not v <= FEASIBILITY_TOL]  # NaN: violated
            ctx.log(f"  {who} on the fine grids: " + ("feasible (every constraint met)" if bool(V["feasible"][i])
                                                       else "infeasible" + (f", violates {', '.join(bad)}" if bad
                                                                            else "")))
    T = data.get("tolerance")
    if T is not None and "role" in T:
        from ..optimize.robust import cost_lines, headline_lines

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
             if s.mode != "weighted" and s.primary == "picks_per_min" and "baseline_primary" in G.get("attrs", {})
             else None)
    seeds = ["the baseline"]
    if s.screen["enabled"] and not s.primary.startswith("regular"):
        seeds.append("the screen's best designs")
    if s.continue_from is not None:
        seeds.append("the earlier run's front")
    fig = P.ga_convergence(G, picks_per_fitness=scale, seeds=", ".join(seeds) + ", random members")
    if fig is not None:
        ctx.savefig(fig, "ga_convergence")
    V = data.get("verify")
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

    if s.recommend != "floor" or s.primary not in objs[:2] or len(objs) < 2:
        return None
    o = objs[1] if s.primary == objs[0] else objs[0]
    lim = floor_limits(len(objs), list(objs).index(s.primary), s.recommend_floor, [DESIGN_SENSE[k] for k in objs])
    return o, abs(float(lim[list(objs).index(o)])) * abs(float(np.asarray(V[o], float)[0]))


def rule_text(s) -> str:
    """The recommendation rule in words (stored and printed with the recommendation)."""
    if s.recommend == "floor":
        others = [o for o in s.objectives if o != s.primary]
        return (f"floor: the best {s.primary} among verified front points with {', '.join(others)} at least "
                f"{s.recommend_floor:g} x the verified baseline's (if none has: the point closest to that floor)"
                + ("; the floor step's designs included" if s.floor_solve["enabled"] else ""))
    if s.recommend == "band":
        return (f"band: among verified front points whose {s.primary} is within {100 * s.recommend_band:g} % of "
                f"the front's best, the best on {', '.join(o for o in s.objectives if o != s.primary)}")
    if s.recommend == "knee":
        return "knee of the verified front (objectives normalised over the front)"
    return f"best {s.primary} on the verified front"


def robust_text(s) -> str:
    """The robust recommendation's requirement in words (``experiment.robust``)."""
    return (f"robust: the rule applied among verified candidates holding every constraint in >= "
            f"{100 * s.robust['probability']:g} % of {s.tolerance['samples']} Monte Carlo samples "
            f"(seed {s.tolerance['seed']}), confirmed by a fresh Monte Carlo (seed {s.robust['confirm_seed']})")


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
            attrs={"meaning": f"descent iterate (steps of experiment.refine.steps={s.refine['steps']} per round)"})
    res.put("floor", "F_predicted", fo.predicted, units="1", dims=("design", "objective"),
            attrs={"meaning": "predicted fine-grid objectives (search-grid values x the start's fine/search "
                              "ratio), normalised like verify/F"})
    res.set_attrs("floor", starts=",".join(names[i] for i in fo.starts), predicted_to_meet_floor=fo.n_predicted,
                  rounds=s.floor_solve["rounds"], candidates=s.floor_solve["candidates"],
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
                                        f"(zero picks/min, zero volume), {s.pareto['ref_min_factor']} x baseline for "
                                        "minimised ones",
                  reference_point=np.asarray(ref), objectives=",".join(objs),
                  grids=f"task {v['task_n_r']}x{v['task_n_phi']}x{v['task_n_z']}, cycle {v['cycle_samples']} samples, "
                        f"regular grid {v['rw_n_z']}x{v['rw_n_r']}x{v['rw_n_phi']}, n_R {v['n_R']}, operating-R "
                        f"candidates {v['n_R_operating']}")
