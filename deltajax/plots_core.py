"""Figures of the kinematic core (index-vs-R curves, benchmark bars). matplotlib, host side only."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["plot_index_curves"]


def plot_index_curves(R, points, values: dict, feasible, argmax: dict):
    """Index-vs-R curves at each point (Franco-López 2026 Figs 3-6): velocity indices left, force right.

    Args:
        R: (n,) base radii (m).
        points: (m, 3) the points (m).
        values: index name -> (m, n) values.
        feasible: (m, n) IK feasibility.
        argmax: index name -> (m,) maximising R.
    """
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
