"""Figures of the main job (ga_reconfig), drawn from its staged results only (a resumed run draws the same)."""

from __future__ import annotations

import numpy as np

from .core import pyplot

__all__ = ["convergence_series", "ga_convergence", "ga_pareto"]

#: feasibility first (:func:`deltajax.optimize.workflow.ga_fitness`): an infeasible design's fitness is 1e3 + violation
_INFEASIBLE_FITNESS = 1e3


def convergence_series(G, picks_per_fitness=None):
    """The GA convergence in the designer's units, from the staged ``ga`` group ``G`` (picks/min, 1/min).

    The GA minimises a normalised fitness; its state's best so far also holds the initial population (generation
    0: the seeds and random members), which no generation record holds. So the best so far at generation g is
    the generation's best that set it (fitness equal to the state's best), or the initial population's best when
    no generation up to g reached it (``from_initial``).

    Args:
        G: the ``ga`` group as loaded (``best_fitness``, ``gen_best_fitness``, ``gen_best_picks_per_min``,
            ``gen_best_feasible``, ``gen_feasible_fraction`` per generation).
        picks_per_fitness: picks/min per unit of -fitness when the GA's fitness is -picks/min / |baseline picks/min|
            (objective picks_per_min alone: the baseline's picks/min on the search grids); None for another
            objective (the initial population's best then has no picks/min: NaN).

    Returns:
        None without a GA history, else a dict of (n,) arrays over ``generation`` 1..n: ``gen_best`` (picks/min of
        each generation's best design by the GA's fitness, NaN if infeasible), ``best_so_far`` (picks/min of the best
        design so far by the GA's fitness, NaN while none is feasible or it is unknown), ``from_initial`` (the best
        so far is still the initial population's), ``feasible_fraction``; and ``initial_best`` (picks/min of the
        initial population's best if it beat generation 1, else NaN) and ``baseline`` (the baseline's picks/min on
        the search grids, NaN unless ``picks_per_fitness``) as floats.
    """
    if "best_fitness" not in G:
        return None
    best = np.asarray(G["best_fitness"], float)
    gbf = np.asarray(G["gen_best_fitness"], float)
    n = len(best)
    feas = (np.asarray(G["gen_best_feasible"]).astype(bool) if "gen_best_feasible" in G
            else gbf < _INFEASIBLE_FITNESS)
    if "gen_best_picks_per_min" in G:
        picks = np.asarray(G["gen_best_picks_per_min"], float)
    else:
        picks = -gbf * (np.nan if picks_per_fitness is None else picks_per_fitness)
    gen_best = np.where(feas, picks, np.nan)
    # the state's best is the minimum over the initial population and generations 1..g (evosax keeps the first
    # of equal values, and a generation record is that minimum's exact copy)
    from_initial = best < np.minimum.accumulate(gbf)
    src = np.zeros(n, int)
    for g in range(n):
        hit = np.flatnonzero(gbf[:g + 1] == best[g])
        src[g] = hit[-1] if len(hit) else -1
    init_fit = best[0] if from_initial[0] else np.nan
    scale = np.nan if picks_per_fitness is None else float(picks_per_fitness)
    initial_best = -init_fit * scale if init_fit < _INFEASIBLE_FITNESS else np.nan
    best_so_far = np.where(from_initial, initial_best, gen_best[np.maximum(src, 0)])
    best_so_far = np.where(best < _INFEASIBLE_FITNESS, best_so_far, np.nan)
    return {"generation": np.arange(1, n + 1), "gen_best": gen_best, "best_so_far": best_so_far,
            "from_initial": from_initial, "feasible_fraction": np.asarray(G["gen_feasible_fraction"], float),
            "initial_best": float(initial_best), "baseline": scale}


def ga_convergence(G, picks_per_fitness=None, seeds="the seeds"):
    """The main job's GA convergence in picks/min (:func:`convergence_series`) and the feasible fraction per
    generation (``G``: the staged ``ga`` group; ``seeds``: what seeded the initial population, in words); None
    without a GA history."""
    from matplotlib.ticker import MaxNLocator

    c = convergence_series(G, picks_per_fitness)
    if c is None:
        return None
    plt = pyplot()
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.6), gridspec_kw={"width_ratios": [1.6, 1]})
    gens = c["generation"]
    objective = str(G.get("attrs", {}).get("objective", ""))
    if np.isfinite(c["baseline"]):
        ax[0].axhline(c["baseline"], color="k", ls=":", lw=1, label="baseline franco2026 (search grids)")
    has0 = np.isfinite(c["initial_best"])
    x0 = np.concatenate([[0], gens]) if has0 else gens
    y0 = np.concatenate([[c["initial_best"]], c["best_so_far"]]) if has0 else c["best_so_far"]
    ax[0].step(x0, y0, ".-", where="post", color="C0", lw=1.5, label="best so far (feasible)")
    ax[0].plot(gens, c["gen_best"], "o", color="C1", ms=5, label="best of each generation (feasible)")
    if has0:
        ax[0].plot([0], [c["initial_best"]], "s", color="C0", ms=7, mfc="none", mew=1.5,
                   label=f"generation 0: initial population ({seeds})")
    title = f"GA on the {objective}, search grids" if objective else "GA, search grids"
    if picks_per_fitness is None:   # the GA ranks by another objective: these are its best designs' picks/min
        title += "\npicks/min of the designs the GA ranks best by its objective"
    if np.any(c["from_initial"]):
        last = int(gens[c["from_initial"]][-1])
        title += (f"\nbest so far through generation {last}: the initial population's best (generation 0)"
                  + ("" if has0 else ", whose picks/min are not stored for this objective"))
    ax[0].set_title(title, fontsize=9)
    ax[0].set_xlabel("generation")
    ax[0].set_ylabel("picks per minute [1/min]  (higher is better)")
    ax[0].grid(alpha=0.3)
    ax[1].plot(gens, c["feasible_fraction"], "o-", ms=4)
    ax[1].set_ylim(0, 1.02)
    ax[1].set_xlabel("generation")
    ax[1].set_ylabel("feasible fraction of the population")
    ax[1].grid(alpha=0.3)
    for a in ax:  # generations are whole numbers (short toy runs drew 1.5, 2.5, ...)
        a.xaxis.set_major_locator(MaxNLocator(integer=True))
    fig.tight_layout()
    # below the axes, so no point hides behind it (after the layout: it must not widen the left panel)
    ax[0].legend(fontsize=7, loc="upper left", bbox_to_anchor=(0.0, -0.16), ncol=2, borderaxespad=0)
    return fig


def ga_pareto(V, objs, s, units, floor=None):
    """The main job's designs verified on the fine grids in the plane of the first two objectives: front,
    baseline, GA best, refined, floor-step, carried (a continued run's) and recommended designs (``V``: the staged
    ``verify`` group; ``s``: the job's settings; ``units``: each objective's unit, e.g. ``{"picks_per_min":
    "1/min", "regular_volume": "m^3"}``;
    ``floor``: ``(objective, value)`` of the recommendation rule's floor in that objective's units, drawn as a line
    (:func:`deltajax.jobs.designer_report.floor_line`), or None); None without them."""
    plt = pyplot()
    if V is None or len(objs) < 2:
        return None
    o0, o1 = objs[0], objs[1]
    x, y = np.asarray(V[o0], float), np.asarray(V[o1], float)
    feas = np.asarray(V["feasible"]).astype(bool)
    front = np.asarray(V["front"], int).reshape(-1)
    rec = int(V["attrs"]["recommended"])
    sx = 1e3 if units[o0] == "m^3" else 1.0
    sy = 1e3 if units[o1] == "m^3" else 1.0
    ux = "dm^3 (L)" if sx == 1e3 else units[o0]
    uy = "dm^3 (L)" if sy == 1e3 else units[o1]
    fig, ax = plt.subplots(figsize=(11, 4.8))
    names = [str(n) for n in V["design_name"]]
    # the GA's best by name: in a continued run (experiment.continue_from) it can be a design of the earlier run
    g = V["attrs"].get("ga_best_design", "ga_best")
    gi = names.index(g) if g in names else -1
    others = np.setdiff1d(np.arange(1, len(x)), np.concatenate([front, [gi]]))
    dom, bad = others[feas[others]], others[~feas[others]]
    if len(dom):
        ax.plot(x[dom] * sx, y[dom] * sy, "o", mfc="none", color="0.55", ms=5, label="candidates, feasible, dominated")
    if len(bad):
        ax.plot(x[bad] * sx, y[bad] * sy, "x", color="0.55", ms=5,
                label="candidates feasible on the search grids, infeasible on the fine grids")
    if len(front):
        o = front[np.argsort(x[front])]
        ax.step(x[o] * sx, y[o] * sy, "-", where="pre", color="C0", lw=1, alpha=0.6)
        ax.plot(x[o] * sx, y[o] * sy, "o", color="C0", ms=6, label="Pareto front (verified, all feasible)")
    ax.plot(x[0] * sx, y[0] * sy, "k*", ms=14, label="baseline franco2026" + ("" if feas[0] else " (infeasible)"))
    if gi >= 0 and feas[gi]:
        ax.plot(x[gi] * sx, y[gi] * sy, "s", color="C2", ms=8, mfc="none", mew=2, label=f"GA best on {s.objectives.primary}")
    ea_i = [i for i, n in enumerate(names) if n.startswith("earlier_")]
    if ea_i:
        ax.plot(x[ea_i] * sx, y[ea_i] * sy, "o", color="C7", ms=9, mfc="none", mew=1.2,
                label="the earlier run's front (experiment.continue_from; its verified values)")
    ref_i = [i for i, n in enumerate(names) if n.startswith("refined_")]
    if ref_i:
        ax.plot(x[ref_i] * sx, y[ref_i] * sy, "^", color="C1", ms=7, mfc="none", mew=1.5,
                label="refined by optax (accepted: feasible, no objective worse)")
    fl_i = [i for i, n in enumerate(names) if n.startswith("floor_")]
    if fl_i:
        ax.plot(x[fl_i] * sx, y[fl_i] * sy, "+", color="C4", ms=9, mew=1.5,
                label="floor step (descents at the floor, verified)")
    if floor is not None and floor[0] in (o0, o1):
        on_y = floor[0] == o1
        (ax.axhline if on_y else ax.axvline)(floor[1] * (sy if on_y else sx), color="C3", ls="--", lw=1, alpha=0.7,
                                             label=f"floor: {s.recommend_floor:g} x the baseline's {floor[0]}")
    if rec >= 0:
        what = (f"band: {s.objectives.primary} within {100 * s.recommend_band:g} % of the best, then the most {o1}"
                if s.recommend == "band" else s.recommend)
        ax.plot(x[rec] * sx, y[rec] * sy, "D", color="C3", ms=10, label=f"recommended ({what})")
        M = V.get("margins") if isinstance(V, dict) else None      # certified margins (group certify)
        if M:
            txt = "\n".join(["margins (>= 0: met by)"] + [f"{k}: {float(v[rec]):.3g} {u}" for k, (v, u) in M.items()
                                                          if np.isfinite(v[rec])])
            ax.annotate(txt, (x[rec] * sx, y[rec] * sy), xytext=(10, -10), textcoords="offset points", fontsize=6,
                        va="top", bbox=dict(boxstyle="round", fc="white", ec="C3", alpha=0.85))
        if "regular_volume_fixed" == o1 or o1 == "regular_volume":
            yf = float(V["regular_volume_fixed"][rec]) * sy if o1 == "regular_volume" else None
            if yf is not None:
                ax.plot(x[rec] * sx, yf, "v", color="C3", ms=9, mfc="none", mew=1.5,
                        label="recommended, fixed R (operating R)")
    ax.set_xlabel(f"{o0} [{ux}]  (higher is better)" if o0 in ("picks_per_min", "regular_volume") else
                  f"{o0} [{ux}]")
    ax.set_ylabel(f"{o1} [{uy}]  (higher is better)" if o1 in ("picks_per_min", "regular_volume") else
                  f"{o1} [{uy}]")
    ax.grid(alpha=0.3)
    # beside the axes, so no marker hides behind it
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0)
    fig.tight_layout()
    hv = V["attrs"].get("hypervolume", float("nan"))
    ax.set_title(f"All designs verified on the fine grids. Hypervolume of the front {hv:.3g}\n"
                 f"(objectives / baseline, reference at 0: the baseline alone spans 1)", fontsize=9)
    return fig
