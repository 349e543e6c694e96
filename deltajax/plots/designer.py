"""Figures of the main job (ga_reconfig), drawn from its staged results only (a resumed run draws the same)."""

from __future__ import annotations

import numpy as np

from .core import _plt

__all__ = ["ga_convergence", "ga_pareto"]


def ga_convergence(G):
    """The main job's GA convergence: best fitness and feasible fraction per generation (``G``: the staged
    ``ga`` group); None without a GA history."""
    from matplotlib.ticker import MaxNLocator

    if "best_fitness" not in G:
        return None
    plt = _plt()
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    bf = np.asarray(G["best_fitness"])
    gens = np.arange(1, len(bf) + 1)
    ax[0].plot(gens, np.where(bf < 1e3, bf, np.nan), label="best so far (feasible)")
    gb = np.asarray(G["gen_best_fitness"])
    ax[0].plot(gens, np.where(gb < 1e3, gb, np.nan), ".", label="best of generation")
    ax[0].set_xlabel("generation")
    ax[0].set_ylabel("fitness (minimised; baseline = -1 per objective)")
    ax[0].legend(fontsize=8)
    ax[0].set_title(str(G["attrs"].get("objective", "")), fontsize=9)
    ax[1].plot(gens, np.asarray(G["gen_feasible_fraction"]))
    ax[1].set_ylim(0, 1.02)
    ax[1].set_xlabel("generation")
    ax[1].set_ylabel("feasible fraction of the population")
    for a in ax:  # generations are whole numbers (short toy runs drew 1.5, 2.5, ...)
        a.xaxis.set_major_locator(MaxNLocator(integer=True))
    return fig


def ga_pareto(V, objs, s, units, floor=None):
    """The main job's designs verified on the fine grids in the plane of the first two objectives: front,
    baseline, GA best, refined, floor-step, carried (a continued run's) and recommended designs (``V``: the staged
    ``verify`` group; ``s``: the job's settings; ``units``: each objective's unit, e.g. ``{"picks_per_min":
    "1/min", "regular_volume": "m^3"}``;
    ``floor``: ``(objective, value)`` of the recommendation rule's floor in that objective's units, drawn as a line
    (:func:`deltajax.optimize.report.floor_line`), or None); None without them."""
    plt = _plt()
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
        ax.plot(x[gi] * sx, y[gi] * sy, "s", color="C2", ms=8, mfc="none", mew=2, label=f"GA best on {s.primary}")
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
        what = (f"band: {s.primary} within {100 * s.recommend_band:g} % of the best, then the most {o1}"
                if s.recommend == "band" else s.recommend)
        ax.plot(x[rec] * sx, y[rec] * sy, "D", color="C3", ms=10, label=f"recommended ({what})")
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
