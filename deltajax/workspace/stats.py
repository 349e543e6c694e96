"""Statistics of index fields over a workspace (Franco-López 2026 Tables 6-8: :data:`deltajax.papers.FRANCO2026_INDEX_STATS`).

The paper's tables give min / max / mean of each index "throughout the entire (ODR) workspace": over the
grid points reachable by the fixed robot (R = 0.200 m), evaluated for the fixed robot (ODR) and, at the same
points, for the reconfigurable robot at its k~-optimal R* (RDR).
"""

from __future__ import annotations

import numpy as np

from ..indices import INDEX_NAMES

__all__ = ["index_stats", "stats_from_partials"]


def index_stats(fields: dict, mask: np.ndarray, names=INDEX_NAMES, chunk: int = 1 << 22) -> dict:
    """min / max / mean (float64 accumulation, NaN ignored) of each field over ``mask``.

    Args:
        fields: name -> array of the mask's shape.
        mask: bool array selecting the points.
        names: which fields.
        chunk: elements per reduction step (bounded memory for 2 mm grids).

    Returns:
        {name: {"min", "max", "mean", "count"}}; NaN statistics when no finite value is selected.
    """
    m = np.asarray(mask, bool).reshape(-1)
    out = {}
    for n in names:
        f = np.asarray(fields[n]).reshape(-1)
        lo, hi, s, c = np.inf, -np.inf, 0.0, 0
        for a in range(0, m.size, chunk):
            v = f[a:a + chunk][m[a:a + chunk]].astype(np.float64)
            v = v[np.isfinite(v)]
            if v.size:
                lo, hi = min(lo, float(v.min())), max(hi, float(v.max()))
                s += float(v.sum())
                c += int(v.size)
        out[n] = {"min": lo if c else np.nan, "max": hi if c else np.nan, "mean": s / c if c else np.nan,
                  "count": c}
    return out


def stats_from_partials(partials: np.ndarray, names=INDEX_NAMES) -> dict:
    """min / max / mean of each field from per-chunk partial statistics, in the format of :func:`index_stats`.

    Args:
        partials: (n_chunks, len(names), 4) rows [min, max, weighted sum, weighted count] over the finite
            values of each chunk (the grid drivers' ``stats=True``; mirror-half items weighted 2).
        names: the fields, in the order of the partials' second axis.
    """
    p = np.asarray(partials, dtype=np.float64)
    out = {}
    for a, n in enumerate(names):
        c = float(p[:, a, 3].sum())
        out[n] = {"min": float(p[:, a, 0].min()) if c else np.nan, "max": float(p[:, a, 1].max()) if c else np.nan,
                  "mean": float(p[:, a, 2].sum()) / c if c else np.nan, "count": int(c)}
    return out
