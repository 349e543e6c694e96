"""Figures of the reconfig_motion job: the index landscape with the four R(t), the R-drive profiles and the arm
torques (per method: fixed, pointwise, path_dp, path_refined)."""

from __future__ import annotations

import math

import numpy as np

from .core import pyplot

__all__ = ["motion_landscape", "motion_profiles", "motion_torques"]


def motion_landscape(name, t, Rg, table, paths, crit):
    """reconfig_motion: the index ``crit`` over (t, R) (``table``, NaN unreachable) and the methods' R(t) ``paths``."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 5))
    im = ax.pcolormesh(t, Rg, table.T, shading="nearest", cmap="viridis")
    fig.colorbar(im, ax=ax, label=f"{crit} (NaN: unreachable)")
    styles = {"fixed": dict(color="w", ls="--", lw=1.5), "pointwise": dict(color="r", ls="none", marker=".", ms=4),
              "path_dp": dict(color="orange", lw=2.0), "path_refined": dict(color="k", lw=1.2)}
    for m, R in paths.items():
        ax.plot(t, R, label=m, **styles[m])
    ax.set_xlabel("t (s)")
    ax.set_ylabel("R (m)")
    ax.set_title(f"{name}: {crit} over (t, R) and the four R(t)")
    ax.legend(loc="upper right", fontsize=8, framealpha=0.8, facecolor="0.6")  # grey: the white "fixed" line shows
    return fig


def motion_profiles(name, t, data, criterion, drive_speed, drive_force):
    """reconfig_motion: index, R(t), Rdot, R force and screw torque per method (``data``: method -> arrays), with
    the R drive's speed and force limits dotted."""
    plt = pyplot()
    keys = (("value", criterion, None), ("R", "R (m)", None), ("R_dot", "Rdot (m/s)", float(drive_speed)),
            ("force_R", "F_R (N)", float(drive_force)), ("screw_torque", "screw motor torque (N m)", None))
    fig, axes = plt.subplots(len(keys), 1, figsize=(9, 12), sharex=True)
    colors = {"fixed": "C0", "pointwise": "C3", "path_dp": "C1", "path_refined": "k"}
    for ax, (key, label, lim) in zip(axes, keys):
        lo, hi = np.inf, -np.inf
        for m, d in data.items():
            y = np.asarray(d[key])
            kw = dict(marker=".", ms=3, lw=0.6) if m == "pointwise" else dict(lw=1.4)
            ax.plot(t, y, color=colors[m], label=m, **kw)
            if m != "pointwise":
                lo, hi = min(lo, np.nanmin(y)), max(hi, np.nanmax(y))
        if lim is not None and math.isfinite(lim):
            ax.axhline(lim, color="grey", ls=":", lw=1)
            ax.axhline(-lim, color="grey", ls=":", lw=1)
            lo, hi = min(lo, -lim), max(hi, lim)
        if key in ("R_dot", "force_R", "screw_torque"):
            pad = 0.15 * (hi - lo + 1e-12)
            ax.set_ylim(lo - pad, hi + pad)   # pointwise jumps run off this scale; their peaks are in the summary
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(ncol=4, fontsize=8)
    axes[0].set_title(f"{name}: index, R(t), Rdot, R force and screw torque (dotted: drive limits; pointwise "
                      "off-scale where it jumps)", fontsize=9)
    axes[-1].set_xlabel("t (s)")
    return fig


def motion_torques(name, t, data):
    """reconfig_motion: the three arm torques per method at the nominal duration."""
    plt = pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    # colours as in the profiles; wide solid under dashed/dotted, so methods that agree stay distinguishable
    styles = {"fixed": dict(color="C0", ls="-", lw=2.8, alpha=0.6), "pointwise": dict(color="C3", ls=":", lw=1.2),
              "path_dp": dict(color="C1", ls="--", lw=1.6), "path_refined": dict(color="k", ls="-.", lw=1.0)}
    for i, ax in enumerate(axes):
        for m, d in data.items():
            ax.plot(t, np.asarray(d["tau"])[:, i], label=m, **styles[m])
        ax.set_ylabel(f"tau_{i + 1} (N m)")
        ax.grid(alpha=0.3)
    axes[0].legend(ncol=4, fontsize=8)
    axes[0].set_title(f"{name}: arm torques at the nominal duration")
    axes[-1].set_xlabel("t (s)")
    return fig
