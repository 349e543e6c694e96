"""The main job's ``tolerance`` stage and its robust recommendation (``experiment.tolerance``, ``experiment.robust``).

The stage runs after ``verify`` on the verification problem and reads only what ``verify`` stored (so a resumed run
computes the same): the Monte Carlo of :func:`deltajax.tolerance.analyse` for the baseline and the recommendation,
stored in the results group ``tolerance``.

**Robust recommendation** (``experiment.robust.enabled``): the recommendation rule
(:func:`deltajax.optimize.workflow.recommend`) is applied among the verified candidates that hold every constraint
in at least ``robust.probability`` of the Monte Carlo samples. It is found lazily: the rule picks from the verified
front of the feasible candidates not yet found wanting; that design gets the Monte Carlo (``tolerance.seed``); below
the probability it is set aside and the rule picks again. Whatever it picks then holds at the probability and is
the rule's answer among the candidates that do (for ``floor`` and ``primary`` exactly: a candidate never checked is
dominated by, or ranks after, the one chosen). The chosen design is then confirmed by a *fresh* Monte Carlo with
``robust.confirm_seed`` (independent of the samples that selected it); if that falls below the probability it is
set aside too. At most ``robust.max_candidates`` designs are checked. The nominal recommendation stays stored next
to the robust one (``verify`` attribute ``recommended_nominal``, group ``tolerance/robust``): what robustness costs.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Optional, Sequence

import numpy as np

__all__ = ["tolerances_of", "robust_choice", "RobustChoice", "store_tolerance", "store_robust", "store_frozen",
           "headline_lines",
           "cost_lines", "summary_attrs"]


def tolerances_of(s):
    """The :class:`deltajax.tolerance.Tolerances` of the validated settings' ``tolerance`` block."""
    from ..tolerance import tolerances_from_mapping

    return tolerances_from_mapping(s.tolerance, prefix="experiment.tolerance")


@dataclasses.dataclass(frozen=True)
class RobustChoice:
    """What the robust selection checked and chose.

    Attributes:
        chosen: verify row of the robust recommendation (-1: none found within the cap).
        checked: verify rows checked, in order.
        p_selection: their Monte Carlo probability that every constraint holds (``tolerance.seed``).
        p_confirm: the fresh Monte Carlo's probability (``robust.confirm_seed``) for the designs that passed the
            selection (NaN for the others).
        results: the :func:`deltajax.tolerance.analyse` results, per checked row (selection) and the confirmation.
        exhausted: True when every feasible candidate was checked (no robust design exists among them).
    """

    chosen: int
    checked: tuple
    p_selection: tuple
    p_confirm: tuple
    results: dict
    confirm: Optional[dict]
    exhausted: bool


def robust_choice(analyse_rows: Callable[[Sequence[int], int], dict], F: np.ndarray, feasible: np.ndarray,
                  rule: Callable[[np.ndarray], int], probability: float, seed: int, confirm_seed: int,
                  max_candidates: int, known: Optional[dict] = None,
                  log: Callable[[str], Any] = lambda _m: None) -> RobustChoice:
    """The robust recommendation (module docstring).

    Args:
        analyse_rows: ``(rows, seed) -> analyse result`` of the verified designs ``rows``.
        F: (n, k) verified minimised objectives; feasible: (n,) nominal feasibility on the fine grids.
        rule: ``front rows -> chosen row`` (the job's recommendation rule; -1 for an empty front).
        probability: required probability that every constraint holds.
        known: ``{row: result of analyse_rows([row], seed)}`` already computed (reused, same seed).
    """
    from .pareto import non_dominated

    ok = np.asarray(feasible, bool) & np.all(np.isfinite(F), axis=1)
    out_rows, p_sel, p_conf, results = [], [], [], dict(known or {})
    wanting: set = set()
    confirm = None
    while True:
        rest = np.asarray([i for i in np.flatnonzero(ok) if i not in wanting], int)
        if len(rest) == 0:
            return RobustChoice(-1, tuple(out_rows), tuple(p_sel), tuple(p_conf), results, None, True)
        nd = rest[non_dominated(F[rest])]
        nd = nd[np.lexsort(F[nd].T[::-1])]
        r = int(rule(nd))
        if len(out_rows) >= max_candidates:
            log(f"robust: {max_candidates} candidates checked (experiment.robust.max_candidates), none holds every "
                f"constraint in >= {probability:g} of the samples")
            return RobustChoice(-1, tuple(out_rows), tuple(p_sel), tuple(p_conf), results, None, False)
        if r not in results:
            results[r] = analyse_rows([r], seed)
        p = float(results[r]["p_all"][0])
        out_rows.append(r)
        p_sel.append(p)
        if p < probability:
            p_conf.append(float("nan"))
            wanting.add(r)
            continue
        confirm = analyse_rows([r], confirm_seed)
        pc = float(confirm["p_all"][0])
        p_conf.append(pc)
        if pc < probability:
            log(f"robust: row {r} held in {p:.4f} of the selection samples but {pc:.4f} of the fresh ones; set aside")
            wanting.add(r)
            continue
        return RobustChoice(r, tuple(out_rows), tuple(p_sel), tuple(p_conf), results, confirm, False)


def _put_design_block(res, group: str, names, rows, a: dict, tol_text: str, roles=None) -> None:
    """One :func:`deltajax.tolerance.analyse` result (designs ``names`` at verify ``rows``) into ``group``."""
    from ..tolerance import CONSTRAINT_METRICS, PARAMETERS, PERCENTILES
    from .designer import DESIGN_UNITS

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
            attrs={"meaning": f"fraction of the samples (seed {s.tolerance['seed']}) in which every constraint holds"})
    res.put(g, "p_confirm", np.asarray(rc.p_confirm, float), units="1", dims=("checked",),
            attrs={"meaning": f"the fresh Monte Carlo's fraction (seed {s.robust['confirm_seed']}); NaN: not "
                              "confirmed (below the probability in the selection)"})
    if rc.confirm is not None:
        _put_design_block(res, f"{g}/confirm", [design_names[rc.chosen]], [rc.chosen], rc.confirm, tol_text)
    cost = {}
    for who, i in (("nominal", nominal), ("robust", rc.chosen)):
        for m in ("picks_per_min", "regular_volume"):
            cost[f"{who}_{m}"] = float(mv[m][i]) if i >= 0 else float("nan")
    res.set_attrs(g, probability=float(s.robust["probability"]), confirm_seed=int(s.robust["confirm_seed"]),
                  selection_seed=int(s.tolerance["seed"]), max_candidates=int(s.robust["max_candidates"]),
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
