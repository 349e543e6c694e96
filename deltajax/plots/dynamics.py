"""Dynamics along a cycle (jobs/dynamics_cycle.py); ``prof`` is a :class:`deltajax.cycle.CycleProfile`."""

from __future__ import annotations

import numpy as np

from .core import pyplot, actuator_lines

__all__ = ["cycle_platform", "cycle_torques", "adept_profiles"]


def cycle_platform(prof, title: str):
    """Platform position, velocity and acceleration (x, y, z) along a cycle (like the GA paper's Fig. 5)."""
    plt = pyplot()
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
    plt = pyplot()
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
    plt = pyplot()
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
