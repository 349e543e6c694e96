"""Matplotlib figures of workspace results (Franco-López 2026 Figs 7-8). Host side; Agg backend.

Functions take plain NumPy arrays (as saved in results.h5) and return a ``matplotlib.figure.Figure``.
"""

from __future__ import annotations

from typing import Optional, Sequence

import numpy as np

__all__ = ["workspace_3d", "index_slices"]


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


def workspace_3d(x, y, z, masks: dict, max_points: int = 40000, seed: int = 0):
    """3-D view of one or more workspaces (Fig 7): their surface points, one panel per mask.

    Args:
        x, y, z: grid axes (m, z down: plotted with z increasing downward).
        masks: title -> bool (nx, ny, nz).
        max_points: surface points drawn per panel (random subsample).
    """
    plt = _plt()
    fig = plt.figure(figsize=(5.5 * len(masks), 5))
    rng = np.random.default_rng(seed)
    for i, (title, mask) in enumerate(masks.items()):
        ax = fig.add_subplot(1, len(masks), i + 1, projection="3d")
        b = np.argwhere(_boundary(mask))
        if len(b) > max_points:
            b = b[rng.choice(len(b), max_points, replace=False)]
        px, py, pz = x[b[:, 0]], y[b[:, 1]], z[b[:, 2]]
        ax.scatter(px, py, pz, c=pz, s=1, cmap="viridis")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_zlabel("z [m] (down)")
        ax.invert_zaxis()
        ax.set_title(title)
    fig.tight_layout()
    return fig


def index_slices(x, y, z_values: Sequence[float], columns: dict, label: str = "index",
                 vmin: Optional[float] = None, vmax: Optional[float] = None):
    """Heat maps of an index on x-y planes (Fig 8): rows = heights, columns = robots.

    Args:
        x, y: axes (m).
        z_values: heights of the rows (m).
        columns: title -> array (len(z_values), nx, ny), NaN outside the workspace.
        label: colour-bar label.
        vmin, vmax: colour range (default: common range of all panels).
    """
    plt = _plt()
    vals = np.concatenate([np.asarray(v, float).ravel() for v in columns.values()])
    vals = vals[np.isfinite(vals)]
    if vmin is None:
        vmin = float(vals.min()) if vals.size else 0.0
    if vmax is None:
        vmax = float(vals.max()) if vals.size else 1.0
    nr, nc = len(z_values), len(columns)
    fig, axes = plt.subplots(nr, nc, figsize=(4.2 * nc, 3.8 * nr), squeeze=False)
    im = None
    for c, (title, data) in enumerate(columns.items()):
        for r, zv in enumerate(z_values):
            ax = axes[r, c]
            im = ax.pcolormesh(x, y, np.asarray(data[r]).T, vmin=vmin, vmax=vmax, cmap="jet", shading="nearest")
            ax.set_aspect("equal")
            ax.set_title(f"{title}, z = {zv:.3f} m")
            ax.set_xlabel("x [m]")
            ax.set_ylabel("y [m]")
    if im is not None:
        fig.colorbar(im, ax=axes, label=label, shrink=0.8)
    return fig
