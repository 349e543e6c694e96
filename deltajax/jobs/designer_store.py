"""The main job's results groups, written from what its stages computed: ``ga``, ``pareto``, ``refine``,
``floor``, ``verify``, ``certify``, ``tolerance`` / ``robust`` / ``frozen`` (the engines compute, this stores;
the summary, its printout and the plots are :mod:`deltajax.jobs.designer_report`'s). Application wing."""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np
import jax
import jax.numpy as jnp

from .designer_report import rule_text
from ..optimize.designer import CONSTRAINT_NAMES, DESIGN_UNITS
from ..optimize.workflow import STORED_METRIC
from ..optimize.certify import CERTIFIED_METRICS, MARGIN_UNITS, RAY_PASSES, TOLERANCES
from ..tolerance import CONSTRAINT_METRICS, PARAMETERS, PERCENTILES

if TYPE_CHECKING:
    from ..optimize.robust import RobustChoice

__all__ = ["store_ga", "store_pareto", "store_refine", "store_floor", "store_verify", "store_certify",
           "store_tolerance", "store_robust", "store_frozen"]


def store_ga(res, gres, space, ga_cfg, ga_what: str, base_genes, seeds, baseline_primary: float, best_params,
             fingerprint: str) -> None:
    """Group ``ga``: the GA's per-generation history, its best design (genes and parameters), the gene bounds and
    the run's settings (:func:`deltajax.optimize.run_ga`'s result ``gres``; ``fingerprint``: the run's, which its
    checkpoint carried)."""
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


def store_certify(res, names, cert: dict, feas, marg: dict, front, Fv, rec: int, rec0: int, floor, s) -> None:
    """Group ``certify``: per verified design (``design``, verify's axis) its margins in units and whether it was
    certified; per certified design (``certified_design``; ``row`` on verify's axis) every certified figure, the
    first density's figure, the change doubling made and whether every change is within its tolerance; the front
    and the normalised objectives with the certified figures in place; attributes: the tolerances, the method, the
    certified recommendation."""
    g = "certify"
    n = len(names)
    rows = sorted(cert)
    res.put_axis(g, "design", np.arange(n), units="1")
    res.put_axis(g, "certified_design", np.arange(len(rows)), units="1")
    res.put(g, "certified", np.asarray([i in cert for i in range(n)], np.uint8), units="1", dims=("design",),
            attrs={"meaning": "1: the design's figures are certified (worst cases searched, doubling checked; "
                              "the regular workspace's too where certified_design's regular_certified is 1)"})
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
    res.put(g, "regular_certified", np.asarray([cert[i]["regular_certified"] for i in rows], np.uint8), units="1",
            dims=("certified_design",),
            attrs={"meaning": "1: the regular-workspace figures certified too (rays at doubled density); 0: the "
                              "verification's (the rule moved on once this design's task and cycle figures were "
                              "certified), their change NaN"})
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


def _put_design_block(res, group: str, names, rows, a: dict, tol_text: str, roles=None) -> None:
    """One :func:`deltajax.tolerance.analyse` result (designs ``names`` at verify ``rows``) into ``group``."""
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
