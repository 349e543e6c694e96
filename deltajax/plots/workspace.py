"""Workspace figures: 3-D workspaces and index slices (Franco-López 2026 Figs 7-8), index-vs-R curves (Figs
3-6), the workspace_grid job's area/slice figure and the boundary_search job's figures."""

from __future__ import annotations

from typing import Optional, Sequence

import numpy as np

from .core import mask_boundary, inner_ticks, mask_limits, pyplot, robust_limits

__all__ = ["workspace_3d", "index_slices", "plot_index_curves", "workspace_grid", "boundary_slice", "boundary_surface"]


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

    plt = pyplot()
    lims = mask_limits(masks, (x, y, z))
    norm = mcolors.Normalize(vmin=lims[2][0], vmax=lims[2][1])
    fig = plt.figure(figsize=(5.2 * len(masks) + 0.8, 5), layout="constrained")
    rng = np.random.default_rng(seed)
    sc = None
    for i, (title, mask) in enumerate(masks.items()):
        ax = fig.add_subplot(1, len(masks), i + 1, projection="3d")
        b = np.argwhere(mask_boundary(mask))
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
            inner_ticks(axis, lo, hi)  # x's last and y's first label meet at the corner otherwise
        count = int(np.count_nonzero(mask))
        cell = float(np.prod([np.mean(np.diff(np.asarray(a, float))) if len(a) > 1 else np.nan for a in (x, y, z)]))
        vol = f", V = {count * cell:.4g} m$^3$" if np.isfinite(cell) else ""
        ax.set_title(f"{title}\n{count} reachable grid points{vol}")
    if sc is not None:
        fig.colorbar(sc, ax=fig.axes, shrink=0.6, label="depth z [m] (down)")
    return fig


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
    plt = pyplot()
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
        inner_ticks(axis, lo, hi)
    if im is not None:
        extend = {(False, False): "neither", (True, False): "min", (False, True): "max", (True, True): "both"}[
            (bool(finite.size and finite.min() < vmin), bool(finite.size and finite.max() > vmax))]
        u = "" if units in ("1", "") else f" [{units}]"
        robust = (vmin, vmax) == (r_lo, r_hi)
        fig.colorbar(im, ax=axes, label=f"{label}{u}" + (" (colour range: 1st-99th percentile)" if robust else ""),
                     shrink=0.8, extend=extend)
    return fig


def plot_index_curves(R, points, values: dict, feasible, argmax: dict):
    """Index-vs-R curves at each point (Franco-López 2026 Figs 3-6): velocity indices left, force right.

    Args:
        R: (n,) base radii (m).
        points: (m, 3) the points (m).
        values: index name -> (m, n) values.
        feasible: (m, n) IK feasibility.
        argmax: index name -> (m,) maximising R.
    """
    plt = pyplot()
    m = len(points)
    fig, axes = plt.subplots(m, 2, figsize=(12, 3.6 * m), squeeze=False, sharex=True)  # one R axis to compare
    groups = (("omega_v", "sigma_min_v", "k_tilde"), ("omega_f", "sigma_min_f", "inv_cond", "k_tilde"))
    colors = {"omega_v": "tab:green", "sigma_min_v": "tab:orange", "k_tilde": "tab:blue", "omega_f": "tab:red",
              "sigma_min_f": "tab:brown", "inv_cond": "tab:purple"}
    labels = {"omega_v": r"$\omega_v$", "sigma_min_v": r"$\sigma_{min,v}$", "k_tilde": r"$\tilde k$",
              "omega_f": r"$\omega_f$", "sigma_min_f": r"$\sigma_{min,f}$", "inv_cond": r"$1/k$"}
    for i, p in enumerate(points):
        for j, names in enumerate(groups):
            ax = axes[i, j]
            for name in names:
                v = np.where(feasible[i], values[name][i], np.nan)
                ax.plot(R, v, color=colors[name], label=f"{labels[name]} (max at R={argmax[name][i]:.5f})")
            ax.set_yscale("log")
            if i == m - 1:
                ax.set_xlabel("R [m]")
            ax.set_ylabel(("velocity", "force")[j] + " indices [1] (log)")
            ax.set_title(f"p = ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.4f}) m; " + ("velocity", "force")[j] + " indices")
            ax.legend(fontsize=8, loc="best")
            ax.grid(alpha=0.3)
    fig.suptitle("Indices vs base radius R (homogenised 3x3 theta-block; curves end where IK fails)")
    fig.tight_layout()
    return fig

def workspace_grid(grid, reach):
    """The workspace_grid job's figure: reachable area per height z and the reachable slice nearest y = 0.

    Args:
        grid: the job's grid (axes ``x``, ``y``, ``z`` and spacing ``h``, m).
        reach: bool (nx, ny, nz) reachability.
    """
    plt = pyplot()
    area = reach.sum(axis=(0, 1)) * grid.h ** 2
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.6))
    a1.plot(grid.z, area)
    a1.set_xlabel("z (m, down)")
    a1.set_ylabel("reachable area (m$^2$)")
    j = int(np.argmin(np.abs(grid.y)))
    a2.imshow(reach[:, j, :].T, origin="upper", aspect="equal",
              extent=(grid.x[0], grid.x[-1], grid.z[-1], grid.z[0]), cmap="Greys")
    a2.set_xlabel("x (m)")
    a2.set_ylabel("z (m)")
    a2.set_title(f"reachable, y = {grid.y[j]:.3f} m")
    fig.tight_layout()
    return fig


def boundary_slice(X, Z, mask, centre, base_radius, polar, azimuth, conti, cont, step):
    """The boundary_search job's slice y = 0 through the centre: the workspace (``mask`` on the (X, Z) mesh), the
    boundaries found by Conti bisection and by continuation at azimuths 0 and 180 deg, the rays that re-enter.

    Args:
        conti, cont: (result, profile) of the Conti bisection and of the continuation search.
        step: the angular step of those searches (deg).
    """
    plt = pyplot()
    res_c, prof_c = conti
    res_n, _ = cont
    polar, azimuth = np.asarray(polar), np.asarray(azimuth)
    fig, ax = plt.subplots(figsize=(7, 6))
    ax.contourf(X, Z, mask.reshape(X.shape).astype(float), levels=[0.5, 1.5], colors=["#cde3f5"])
    ax.contour(X, Z, mask.reshape(X.shape).astype(float), levels=[0.5], colors=["#5a8fbf"], linewidths=0.8)
    for az_deg, sgn in ((0.0, 1.0), (180.0, -1.0)):
        j = int(np.argmin(np.abs(np.rad2deg(azimuth) - az_deg)))
        for res, style, label in ((res_c, "r-", "Conti bisection"), (res_n, "k--", "continuation")):
            r = np.asarray(res.radius)[j]
            ax.plot(centre[0] + sgn * r * np.sin(polar), centre[2] + r * np.cos(polar), style, lw=1.2,
                    label=label if az_deg == 0.0 else None)
        bad = np.asarray(prof_c.n_exits)[j] > 1
        for i in np.flatnonzero(bad):
            e = np.asarray(prof_c.last_exit)[j, i]
            ax.plot([centre[0], centre[0] + sgn * e * np.sin(polar[i])], [centre[2], centre[2] + e * np.cos(polar[i])],
                    color="orange", lw=0.4, alpha=0.6)
    ax.plot(centre[0], centre[2], "k+", ms=10, label="centre C")
    R = float(base_radius)
    ax.plot([R, -0.5 * R], [0.0, 0.0], "ks", ms=4, label="actuated joints A_i (projected)")
    ax.invert_yaxis()
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m, down)")
    n_re = int((np.asarray(prof_c.n_exits) > 1).sum())
    ax.set_title(f"Slice y = 0: workspace (blue), boundaries at {step:g} deg; orange: rays that re-enter ({n_re})")
    ax.legend(loc="lower right", fontsize=8)
    return fig


def boundary_surface(q, ns):
    """The boundary_search job's boundary points ``q`` (n, m, 3) seen from the centre; ``ns`` marks the rays that
    leave and re-enter."""
    plt = pyplot()
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    sel = ~ns
    sc = ax.scatter(q[sel, 0][::7], q[sel, 1][::7], q[sel, 2][::7], s=0.5, c=q[sel, 2][::7], cmap="viridis")
    fig.colorbar(sc, ax=ax, shrink=0.6, pad=0.1, label="z (m, down)")
    ax.scatter(q[ns, 0], q[ns, 1], q[ns, 2], s=2, c="orange", label=f"rays that leave and re-enter ({int(ns.sum())})")
    ax.invert_zaxis()
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m, down)")
    ax.set_title("Boundary (continuation) seen from C")
    ax.legend(loc="upper left", fontsize=8)
    return fig
