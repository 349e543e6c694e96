"""The main job's report: the baseline-vs-recommended summary (stored and printed) and the plots, drawn from the
stored results only (so a resumed run reports the same)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..optimize.certify import MARGIN_UNITS, overlay
from ..optimize.designer import DESIGN_SENSE, DESIGN_UNITS, FEASIBILITY_TOL
from ..optimize.workflow import floor_limits, required_margins, STORED_METRIC
from .. import plots as P
from ..config.ga_reconfig import tolerances_of as of
from ..tolerance import PERCENTILES

__all__ = ["SUMMARY_METRICS", "FIXED_R_METRIC", "summary", "change_text", "print_summary", "plots", "tolerances_of",
           "headline_lines", "cost_lines", "summary_attrs", "certify_lines", "rule_text", "robust_text", "floor_line",
           "margins_text"]

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
    """Plots drawn from the staged results only (so a resumed run draws the same figures); none with
    ``plots=false``."""
    if not ctx.plots:
        return

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

    V = overlay(data)          # the certified figures, front and margins where the certify stage ran
    fig = P.ga_pareto(V, objs, s, DESIGN_UNITS, floor=floor_line(V, objs, s) if V is not None else None)
    if fig is not None:
        ctx.savefig(fig, "ga_pareto")


def floor_line(V, objs, s):
    """``(objective, value)``: the floor rule's threshold on the plotted objective that is not the primary, in
    its own units (the verified baseline's value times ``recommend_floor`` if maximised, divided if minimised: the
    rule's :func:`deltajax.optimize.workflow.floor_limits` in the objective's units); None for another rule or when
    the primary is not one of the two plotted objectives."""
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


# -- the certify stage's lines (deltajax.optimize.certify computes, deltajax.jobs.designer_store stores) ----------


def certify_lines(Cg) -> list:
    """Printed lines of the ``certify`` group (as loaded): per certified design the regular volume and the change
    doubling the density made, and whether every figure is within its tolerance."""
    if not Cg or "row" not in Cg:
        return []
    out = []
    tol = float(Cg["attrs"].get("tolerance_regular_volume", float("nan")))
    for j, name in enumerate(np.asarray(Cg["design_name"]).reshape(-1)):
        ch = {k[:-7]: float(np.asarray(Cg[k]).reshape(-1)[j]) for k in Cg if k.endswith("_change")}
        reg = bool(np.asarray(Cg["regular_certified"]).reshape(-1)[j]) if "regular_certified" in Cg else True
        worst = [k for k, x in ch.items() if not x <= float(Cg["attrs"].get(f"tolerance_{k}", np.inf))
                 and (reg or k != "regular_volume")]
        vol = 1e3 * float(np.asarray(Cg["regular_volume"]).reshape(-1)[j])
        tail = "; every figure within its tolerance" if not worst else f"; NOT within tolerance: {', '.join(worst)}"
        if not reg:
            out.append(f"  certified {name}: task and cycle figures (regular volume {vol:.4g} L: the verification's; "
                       f"the rule moved on before its rays were doubled)" + tail)
            continue
        moved = 100 * ch.get("regular_volume", float("nan"))
        nd = int(np.asarray(Cg["doublings"]).reshape(-1)[j]) if "doublings" in Cg else 1
        again = f", after {nd} doublings" if nd > 1 else ""
        out.append(f"  certified {name}: regular volume {vol:.4g} L (doubling the density moved it {moved:.2f} %"
                   f"{again}, tolerance {100 * tol:g} %)" + tail)
    return out


# -- the tolerance stage's summary lines (deltajax.optimize.robust chooses, deltajax.jobs.designer_store stores) -

def tolerances_of(s):
    """The :class:`deltajax.tolerance.Tolerances` of the validated settings' ``tolerance`` block."""
    return of(s.tolerance)


def headline_lines(T, roles: Sequence[str]) -> list:
    """Printed lines of the ``tolerance`` group (as loaded): for each of ``roles`` the probability that every
    constraint holds and the picks/min percentiles."""
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
