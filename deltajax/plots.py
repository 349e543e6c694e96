"""Matplotlib figures of workspace results (Franco-López 2026 Figs 7-8). Host side; Agg backend.

Functions take plain NumPy arrays (as saved in results.h5) and return a ``matplotlib.figure.Figure``.
"""

from __future__ import annotations

from typing import Optional, Sequence

import numpy as np

__all__ = ["workspace_3d", "index_slices", "robust_limits", "bench_rates", "bench_rates_from_results", "actuator_lines",
           "cycle_platform", "cycle_torques", "adept_profiles"]


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _boundary(mask: np.ndarray) -> np.ndarray:
    """Points of ``mask`` with at least one unreachable 6-neighbour (the workspace surface)."""
    m = np.asarray(mask, bool)
    p = np.pad(m, 1, constant_values=False)
    inner = m.copy()
    for ax in range(3):
        for s in (-1, 1):
            inner &= np.roll(p, s, axis=ax)[1:-1, 1:-1, 1:-1]
    return m & ~inner


def _limits(masks: dict, axes) -> list:
    """Common (lo, hi) of every axis over the points reachable in any of the masks (one cell of margin)."""
    any_mask = np.zeros_like(np.asarray(next(iter(masks.values())), bool))
    for m in masks.values():
        any_mask |= np.asarray(m, bool)
    out = []
    for d, ax in enumerate(axes):
        other = tuple(k for k in range(3) if k != d)
        hit = np.flatnonzero(any_mask.any(axis=other))
        ax = np.asarray(ax, float)
        step = float(ax[1] - ax[0]) if len(ax) > 1 else 0.0
        out.append((ax[hit[0]] - step, ax[hit[-1]] + step) if hit.size else (ax[0], ax[-1]))
    return out


def _inner_ticks(axis, lo: float, hi: float, n: int = 5) -> None:
    """About ``n`` round ticks strictly inside (lo, hi), none within 6 % of an end: labels of neighbouring
    panels (or of two axes meeting at a corner) cannot run into each other."""
    from matplotlib.ticker import MaxNLocator

    margin = 0.06 * (hi - lo)
    axis.set_ticks([t for t in MaxNLocator(n).tick_values(lo, hi) if lo + margin < t < hi - margin])


def workspace_3d(x, y, z, masks: dict, max_points: int = 40000, seed: int = 0):
    """3-D view of one or more workspaces (Fig 7): their surface points, one panel per mask.

    The panels share their axis limits (those of the largest workspace), aspect ratio and colour scale (depth
    z), so they compare at a glance.

    Args:
        x, y, z: grid axes (m, z down: plotted with z increasing downward).
        masks: title -> bool (nx, ny, nz).
        max_points: surface points drawn per panel (random subsample).
    """
    import matplotlib.colors as mcolors

    plt = _plt()
    lims = _limits(masks, (x, y, z))
    norm = mcolors.Normalize(vmin=lims[2][0], vmax=lims[2][1])
    fig = plt.figure(figsize=(5.2 * len(masks) + 0.8, 5), layout="constrained")
    rng = np.random.default_rng(seed)
    sc = None
    for i, (title, mask) in enumerate(masks.items()):
        ax = fig.add_subplot(1, len(masks), i + 1, projection="3d")
        b = np.argwhere(_boundary(mask))
        if len(b) > max_points:
            b = b[rng.choice(len(b), max_points, replace=False)]
        px, py, pz = x[b[:, 0]], y[b[:, 1]], z[b[:, 2]]
        sc = ax.scatter(px, py, pz, c=pz, s=1, cmap="viridis", norm=norm)
        ax.set_xlim(*lims[0])
        ax.set_ylim(*lims[1])
        ax.set_zlim(*lims[2])
        ax.set_box_aspect([hi - lo for lo, hi in lims])  # true proportions, the same in every panel
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_zlabel("z [m] (down)")
        ax.invert_zaxis()
        for axis, (lo, hi) in zip((ax.xaxis, ax.yaxis), lims[:2]):
            _inner_ticks(axis, lo, hi)  # x's last and y's first label meet at the corner otherwise
        count = int(np.count_nonzero(mask))
        cell = float(np.prod([np.mean(np.diff(np.asarray(a, float))) if len(a) > 1 else np.nan for a in (x, y, z)]))
        vol = f", V = {count * cell:.4g} m$^3$" if np.isfinite(cell) else ""
        ax.set_title(f"{title}\n{count} reachable grid points{vol}")
    if sc is not None:
        fig.colorbar(sc, ax=fig.axes, shrink=0.6, label="depth z [m] (down)")
    return fig


def robust_limits(values, lo_pct: float = 1.0, hi_pct: float = 99.0) -> tuple[float, float]:
    """Colour limits (lo_pct, hi_pct percentiles of the finite values): a few near-singular points must not
    squash the whole map into one colour."""
    v = np.asarray(values, float).ravel()
    v = v[np.isfinite(v)]
    if not v.size:
        return 0.0, 1.0
    lo, hi = (float(t) for t in np.percentile(v, [lo_pct, hi_pct]))
    return (lo, hi) if hi > lo else (float(v.min()), float(v.max()) if v.max() > v.min() else float(v.min()) + 1)


def index_slices(x, y, z_values: Sequence[float], columns: dict, label: str = "index",
                 vmin: Optional[float] = None, vmax: Optional[float] = None, units: str = "1"):
    """Heat maps of an index on x-y planes (Fig 8): rows = heights, columns = robots.

    Every panel shares the axes and one colour scale. The default colour range is the 1st-99th percentile of
    all panels' values (:func:`robust_limits`); values beyond it show in the end colours, marked by the colour
    bar's arrows, so that the few near-singular points do not wash out the rest.

    Args:
        x, y: axes (m).
        z_values: heights of the rows (m).
        columns: title -> array (len(z_values), nx, ny), NaN outside the workspace.
        label: colour-bar label (the index name).
        vmin, vmax: colour range (default: robust common range of all panels).
        units: the index's units ("1": dimensionless).
    """
    plt = _plt()
    vals = np.concatenate([np.asarray(v, float).ravel() for v in columns.values()])
    finite = vals[np.isfinite(vals)]
    r_lo, r_hi = robust_limits(finite)
    vmin = r_lo if vmin is None else vmin
    vmax = r_hi if vmax is None else vmax
    nr, nc = len(z_values), len(columns)
    fig, axes = plt.subplots(nr, nc, figsize=(3.6 * nc + 1.2, 3.4 * nr), squeeze=False, sharex=True, sharey=True,
                             layout="constrained")
    im = None
    cmap = plt.get_cmap("viridis").with_extremes(bad="white")
    for c, (title, data) in enumerate(columns.items()):
        for r, zv in enumerate(z_values):
            ax = axes[r, c]
            im = ax.pcolormesh(x, y, np.asarray(data[r]).T, vmin=vmin, vmax=vmax, cmap=cmap, shading="nearest")
            ax.set_aspect("equal")
            if r == 0:
                ax.set_title(title, fontsize=10)
            if c == 0:
                ax.set_ylabel(f"z = {zv:.3f} m\ny [m]")
            if r == nr - 1:
                ax.set_xlabel("x [m]")
    # ticks strictly inside the panels (shared by every panel): neighbours' end labels ("0.4-0.4") cannot clash
    for axis, (lo, hi) in ((axes[0, 0].xaxis, axes[0, 0].get_xlim()), (axes[0, 0].yaxis, axes[0, 0].get_ylim())):
        _inner_ticks(axis, lo, hi)
    if im is not None:
        extend = {(False, False): "neither", (True, False): "min", (False, True): "max", (True, True): "both"}[
            (bool(finite.size and finite.min() < vmin), bool(finite.size and finite.max() > vmax))]
        u = "" if units in ("1", "") else f" [{units}]"
        robust = (vmin, vmax) == (r_lo, r_hi)
        fig.colorbar(im, ax=axes, label=f"{label}{u}" + (" (colour range: 1st-99th percentile)" if robust else ""),
                     shrink=0.8, extend=extend)
    return fig


def bench_rates(rates: dict, baseline: str, title: str = "kernel throughput"):
    """Horizontal bars of throughputs (evaluations/s, log scale), each labelled with its ratio to ``baseline``.

    Args:
        rates: label -> evaluations per second.
        baseline: the label the ratios are taken against (e.g. the NumPy reference).
        title: figure title (say what was measured and where).
    """
    plt = _plt()
    names = list(rates)
    v = np.asarray([rates[n] for n in names], float)
    fig, ax = plt.subplots(figsize=(7.5, 0.55 * len(names) + 1.4), layout="constrained")
    colors = ["0.55" if n == baseline else "tab:blue" for n in names]
    ax.barh(range(len(names)), v, color=colors)
    ax.set_yticks(range(len(names)), names)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel(f"evaluations per second (warm; higher is better); x = ratio to {baseline}")
    ax.set_xlim(v[v > 0].min() / 3 if np.any(v > 0) else 1, v.max() * 12 if v.size else 10)
    base = rates[baseline]
    for i, val in enumerate(v):
        ax.text(val * 1.08, i, f"{val / 1e6:.3g} M/s, x{val / base:.2g}", va="center", fontsize=8)
    ax.set_title(title, fontsize=10)
    ax.grid(axis="x", alpha=0.3, which="both")
    return fig


#: line styles of actuators 1, 2, 3 (and the R actuator): distinguishable in colour, dash and width, so that
#: equal curves (e.g. actuators 1 and 3 of a motion symmetric in them) stay visible as a striped line
ACTUATOR_STYLES = ({"color": "tab:blue", "ls": "-", "lw": 2.6, "alpha": 0.75},
                   {"color": "tab:orange", "ls": "--", "lw": 1.8},
                   {"color": "tab:green", "ls": (0, (1, 1.5)), "lw": 2.2},
                   {"color": "k", "ls": "-.", "lw": 1.4})


def actuator_lines(ax, t, values, label: str = "actuator {i}", names: Optional[Sequence[str]] = None,
                   legend: bool = True, **legend_kw):
    """Plot one line per actuator (columns of ``values``, shape (n, k)) with :data:`ACTUATOR_STYLES` and a
    legend; overlapping actuators remain distinguishable (wide solid under dashed/dotted).

    Args:
        label: legend label, ``{i}`` = actuator number from 1 (ignored where ``names`` are given).
        names: one label per column instead (e.g. ``"xyz"`` for the platform's coordinates).
        legend: draw the legend on this axis (False: the caller draws one legend for several axes);
            ``legend_kw`` go to ``ax.legend`` (default ``fontsize=8``).
    """
    values = np.asarray(values)
    for j in range(values.shape[1]):
        lab = names[j] if names is not None else label.format(i=j + 1)
        ax.plot(t, values[:, j], label=lab, **ACTUATOR_STYLES[j % len(ACTUATOR_STYLES)])
    if legend:
        ax.legend(**{"fontsize": 8, **legend_kw})
    return ax


def bench_rates_from_results(results, title: str = "kernel throughput"):
    """:func:`bench_rates` of every scalar rate (units ``1/s``) staged under the ``bench`` group of a
    :class:`deltajax.io.ResultsFile`, labelled ``<subgroup> <name>``; the baseline is the NumPy rate."""
    rates = {}
    for g, name, data, units in results.staged("bench"):
        if units == "1/s" and np.ndim(data) == 0:
            words = " ".join([*g.split("/")[1:], name]).replace("_", " ").split()
            words = [{"cpu": "(CPU time)", "wall": "(wall)"}.get(w, w) for w in words if w != "rate"]
            if words in (["float32"], ["float64"]):
                words.append("jax fast")
            rates[" ".join(words)] = float(data)
    if not rates:
        raise ValueError("no rates (datasets in 1/s) staged under 'bench'")
    baseline = next((k for k in rates if "numpy" in k), next(iter(rates)))
    return bench_rates(rates, baseline, title)


# ---- dynamics along a cycle (jobs/dynamics_cycle.py); ``prof`` is a :class:`deltajax.cycle.CycleProfile` ----
def cycle_platform(prof, title: str):
    """Platform position, velocity and acceleration (x, y, z) along a cycle (like the GA paper's Fig. 5)."""
    plt = _plt()
    fig, axes = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
    t = np.asarray(prof.t)
    for ax, key, unit in zip(axes, ("p", "p_dot", "p_ddot"), ("m", "m/s", "m/s$^2$")):
        actuator_lines(ax, t, np.asarray(getattr(prof, key)), names="xyz", legend=False)
        ax.set_ylabel(f"{key} ({unit})")
        ax.grid(alpha=0.3)
    axes[0].legend(ncol=3)
    axes[0].set_title(title)
    axes[-1].set_xlabel("t (s)")
    return fig


def cycle_torques(prof, title: str):
    """Actuator torques along a cycle (the GA paper's Fig. 6), and the R actuator's force when R moves."""
    plt = _plt()
    has_R = np.any(np.abs(np.asarray(prof.R_dot)) > 0)
    fig, axes = plt.subplots(2 if has_R else 1, 1, figsize=(7, 6 if has_R else 3.6), sharex=True, squeeze=False)
    t = np.asarray(prof.t)
    actuator_lines(axes[0, 0], t, np.asarray(prof.tau)[:, :3])  # distinguishable styles: equal torques stay visible
    axes[0, 0].set_ylabel("torque (N m)")
    axes[0, 0].grid(alpha=0.3)
    axes[0, 0].set_title(title)
    if has_R:
        axes[1, 0].plot(t, np.asarray(prof.force_R), color="k")
        axes[1, 0].set_ylabel("R actuator force (N)")
        axes[1, 0].grid(alpha=0.3)
    axes[-1, 0].set_xlabel("t (s)")
    return fig


def adept_profiles(name: str, prof_nom, prof_min, T_min: float):
    """Torque, joint speed and acceleration of the standard cycle at its nominal duration (left) and at the
    minimum cycle time ``T_min`` (s, right), one y scale per row."""
    plt = _plt()
    fig, axes = plt.subplots(3, 2, figsize=(11, 8), sharex="col", sharey="row")  # columns compared row by row
    cases = ((prof_nom, "nominal duration"), (prof_min, f"minimum cycle time {T_min:.3f} s"))
    for col, (prof, label) in enumerate(cases):
        t = np.asarray(prof.t)
        for row, (key, unit) in enumerate((("tau", "N m"), ("theta_dot", "rad/s"), ("theta_ddot", "rad/s$^2$"))):
            actuator_lines(axes[row, col], t, np.asarray(getattr(prof, key))[:, :3], label="{i}", legend=False)
            axes[row, col].set_ylabel(f"{key} ({unit})")
            axes[row, col].grid(alpha=0.3)
        axes[0, col].set_title(f"{name}, standard cycle, {label}")
        axes[-1, col].set_xlabel("t (s)")
    fig.legend(*axes[0, 0].get_legend_handles_labels(), title="actuator", ncol=3, loc="lower center",
               bbox_to_anchor=(0.5, 0.92))
    return fig
