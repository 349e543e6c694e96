"""Statistics of index fields over a workspace (Franco-López 2026 Tables 6-8).

The paper's tables give min / max / mean of each index "throughout the entire (ODR) workspace": over the
grid points reachable by the fixed robot (R = 0.200 m), evaluated for the fixed robot (ODR) and, at the same
points, for the reconfigurable robot at its k~-optimal R* (RDR).
"""

from __future__ import annotations

import numpy as np

from ..indices import INDEX_NAMES

__all__ = ["index_stats", "TABLE_INDICES", "PAPER_TABLES"]

#: Rows of the paper's Tables 6-8 (paper symbol -> our index name).
TABLE_INDICES = {"1/k": "inv_cond", "omega_v": "omega_v", "omega_f": "omega_f", "sigma_v": "sigma_min_v",
                 "sigma_f": "sigma_min_f"}

#: The paper's Tables 6 (beta 0.5), 7 (0.75), 8 (0.25): {beta: {robot: {index: (min, max, mean)}}}.
_ODR = {"inv_cond": (8.93e-4, 0.9994, 0.4778), "omega_v": (5.71e-4, 1.1375, 0.7036),
        "omega_f": (0.8790, 1748.7, 1.8231), "sigma_min_v": (9.87e-4, 0.8493, 0.6008),
        "sigma_min_f": (0.4060, 9.4800, 0.7924)}
PAPER_TABLES = {
    0.5: {"RDR": {"inv_cond": (0.1505, 0.9999, 0.4988), "omega_v": (0.0635, 1.1538, 0.6380),
                  "omega_f": (0.8666, 15.7337, 1.7976), "sigma_min_v": (0.2100, 0.9963, 0.5981),
                  "sigma_min_f": (0.3672, 1.9724, 0.8231)}, "ODR": _ODR},
    0.75: {"RDR": {"inv_cond": (0.1511, 0.9999, 0.4916), "omega_v": (0.0881, 1.3151, 0.7197),
                   "omega_f": (0.7603, 11.3387, 1.5480), "sigma_min_v": (0.2409, 0.9997, 0.6204),
                   "sigma_min_f": (0.3534, 1.2721, 0.7769)}, "ODR": _ODR},
    0.25: {"RDR": {"inv_cond": (0.1443, 0.9999, 0.4598), "omega_v": (0.0291, 0.9751, 0.5374),
                   "omega_f": (1.0254, 34.3475, 2.1525), "sigma_min_v": (0.1740, 0.9435, 0.5329),
                   "sigma_min_f": (0.4060, 2.8499, 0.8597)}, "ODR": _ODR},
}


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
