"""Shared helpers of the figures: pyplot access, workspace surface/limits, ticks, colour limits and the
actuator line styles. Host side only."""

from __future__ import annotations

from typing import Optional, Sequence

import numpy as np

__all__ = ["robust_limits", "actuator_lines", "ACTUATOR_STYLES"]


def pyplot():
    """pyplot, on whatever backend is selected: the CLI (:mod:`deltajax.run`) selects Agg once before a job runs;
    a library user (a notebook) keeps their own."""
    import matplotlib.pyplot as plt

    return plt


def mask_boundary(mask: np.ndarray) -> np.ndarray:
    """Points of ``mask`` with at least one unreachable 6-neighbour (the workspace surface)."""
    m = np.asarray(mask, bool)
    p = np.pad(m, 1, constant_values=False)
    inner = m.copy()
    for ax in range(3):
        for s in (-1, 1):
            inner &= np.roll(p, s, axis=ax)[1:-1, 1:-1, 1:-1]
    return m & ~inner


def mask_limits(masks: dict, axes) -> list:
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


def inner_ticks(axis, lo: float, hi: float, n: int = 5) -> None:
    """About ``n`` round ticks strictly inside (lo, hi), none within 6 % of an end: labels of neighbouring
    panels (or of two axes meeting at a corner) cannot run into each other."""
    from matplotlib.ticker import MaxNLocator

    margin = 0.06 * (hi - lo)
    axis.set_ticks([t for t in MaxNLocator(n).tick_values(lo, hi) if lo + margin < t < hi - margin])


def robust_limits(values, lo_pct: float = 1.0, hi_pct: float = 99.0) -> tuple[float, float]:
    """Colour limits (lo_pct, hi_pct percentiles of the finite values): a few near-singular points must not
    squash the whole map into one colour."""
    v = np.asarray(values, float).ravel()
    v = v[np.isfinite(v)]
    if not v.size:
        return 0.0, 1.0
    lo, hi = (float(t) for t in np.percentile(v, [lo_pct, hi_pct]))
    return (lo, hi) if hi > lo else (float(v.min()), float(v.max()) if v.max() > v.min() else float(v.min()) + 1)


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

