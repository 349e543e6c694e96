"""The one-page datasheet figure (jobs/datasheet.py); ``ds`` is a :class:`deltajax.datasheet.Datasheet`."""

from __future__ import annotations

import math

import numpy as np

from .core import pyplot

__all__ = ["datasheet_page"]


def _fmt(v, digits=3) -> str:
    return "-" if not np.isfinite(v) else f"{v:.{digits}g}"


def datasheet_page(ds, title: str = ""):
    """A4-portrait page: key figures, the working-range sketch (side view, z down), picks/min vs payload and the
    payload table."""
    plt = pyplot()
    fig = plt.figure(figsize=(8.27, 11.69))
    fig.suptitle(title or f"deltajax datasheet: {ds.name}", fontsize=14, fontweight="bold", y=0.985)
    m = ds.motor
    rpm = 60.0 / (2.0 * math.pi)
    facts = [
        ("Working range (D x H)", f"{1000 * ds.working_diameter:.0f} x {1000 * ds.working_height:.0f} mm "
                                  f"(H/D {ds.working_height / ds.working_diameter:.2f}, z {1000 * ds.working_z_top:.0f}"
                                  f"..{1000 * (ds.working_z_top + ds.working_height):.0f} mm below base)"
         if ds.working_diameter > 0 else "none"),
        ("Reachable volume", f"{ds.reachable_volume:.3g} m^3 (grid {1000 * ds.volume_h:.0f} mm"
                             f"{', TRUNCATED' if ds.volume_truncated else ''})"),
        ("Max payload", f"{ds.max_payload:.2f} kg (cycle still within the motor limits, no dwell)"),
        ("Geometry R / r / L1 / L2", f"{1000 * ds.base_radius:.0f} / {1000 * ds.platform_radius:.0f} / "
                                     f"{1000 * ds.upper_arm:.0f} / {1000 * ds.forearm:.0f} mm, theta "
                                     f"{math.degrees(ds.theta_min):.0f}..{math.degrees(ds.theta_max):.0f} deg"),
        ("Masses arm / elbow / forearm / plate", f"{ds.upper_arm_mass:.3g} / {ds.elbow_mass:.3g} / "
                                                 f"{ds.forearm_mass:.3g} / {ds.platform_mass:.3g} kg "
                                                 f"({ds.forearm_model})"),
        ("Motor (motor side)", f"peak {float(m.peak_torque):.3g} N m, rated {float(m.rated_torque):.3g} N m, "
                               f"{float(m.max_speed) * rpm:.0f} r/min, rotor {float(m.rotor_inertia):.3g} kg m^2"),
        ("Gearbox", f"{ds.gear_ratio:.3g}:1, efficiency {float(m.efficiency):.2f}; at the arm "
                    f"{ds.arm_peak_torque:.3g} N m, {ds.arm_max_speed:.3g} rad/s"),
        ("Cycle", f"25/305/25 mm at ({', '.join(f'{1000 * c:.0f}' for c in ds.centre)}) mm (z down); "
                  f"vendor: + 2 x {1000 * ds.dwell:.0f} ms dwell"),
    ]
    ax_t = fig.add_axes([0.06, 0.78, 0.88, 0.17])
    ax_t.axis("off")
    for k, (key, val) in enumerate(facts):
        y = 1.0 - k / len(facts)
        ax_t.text(0.0, y, key, fontsize=9, fontweight="bold", va="top")
        ax_t.text(0.38, y, val, fontsize=9, va="top")

    # side view of the working range (z down, as deltajax)
    ax_w = fig.add_axes([0.08, 0.50, 0.36, 0.24])
    reach = ds.upper_arm + ds.forearm
    ax_w.plot([-ds.base_radius, ds.base_radius], [0, 0], color="k", lw=3)
    if ds.working_diameter > 0:
        D, H, z0 = ds.working_diameter, ds.working_height, ds.working_z_top
        ax_w.add_patch(plt.Rectangle((-D / 2, z0), D, H, fc="tab:blue", alpha=0.3, ec="tab:blue"))
    ax_w.plot([ds.centre[0] - 0.1525, ds.centre[0] + 0.1525], [ds.centre[2]] * 2, color="tab:red", lw=1)
    ax_w.set_xlim(-1.1 * max(reach, D / 2 if ds.working_diameter > 0 else 0), 1.1 * max(reach, 0.1))
    ax_w.set_ylim(1.1 * reach, -0.05 * reach)
    ax_w.set_aspect("equal")
    ax_w.set_xlabel("x (m)")
    ax_w.set_ylabel("z (m, down)")
    ax_w.set_title("working range (blue), cycle (red)", fontsize=9)
    ax_w.grid(alpha=0.3)

    ax_p = fig.add_axes([0.56, 0.50, 0.38, 0.24])
    pl = ds.payload[:-1]             # the table's payloads; the largest payload is a note (it squashes the curve)
    ax_p.plot(pl, ds.picks_per_min[:-1], "o-", label="motion only")
    ax_p.plot(pl, ds.picks_per_min_vendor[:-1], "s--", label=f"+ 2 x {1000 * ds.dwell:.0f} ms dwell")
    ax_p.text(0.02, 0.02, f"max payload {ds.max_payload:.3g} kg: {ds.picks_per_min[-1]:.3g} / "
              f"{ds.picks_per_min_vendor[-1]:.3g} picks/min", transform=ax_p.transAxes, ha="left", va="bottom",
              fontsize=7)
    ax_p.set_xlabel("payload (kg)")
    ax_p.set_ylabel("picks / min")
    ax_p.set_title("cycle rate, 25/305/25 mm", fontsize=9)
    ax_p.grid(alpha=0.3)
    ax_p.legend(fontsize=8)

    ax_tab = fig.add_axes([0.04, 0.04, 0.92, 0.40])
    ax_tab.axis("off")
    head = ["payload\nkg", "picks/min\nmotion", "picks/min\nvendor", "T_min\ns", "peak util.", "RMS util.",
            "speed util.", "peak acc.\ng"]
    rows = [[_fmt(r["payload"]), _fmt(r["picks_per_min"], 4), _fmt(r["picks_per_min_vendor"], 4),
             _fmt(r["cycle_time"]), _fmt(r["peak_utilisation"]), _fmt(r["rms_utilisation"]),
             _fmt(r["speed_utilisation"]), _fmt(r["peak_acceleration_g"])] for r in ds.rows()]
    tab = ax_tab.table(cellText=rows, colLabels=head, loc="upper center", cellLoc="center")
    tab.auto_set_font_size(False)
    tab.set_fontsize(8)
    tab.scale(1.0, 1.8)
    ax_tab.text(0.0, 0.02, "Last row: the largest payload. Utilisations at T_min (one of peak / RMS is 1: the binding "
                "limit). Vendor column: the dwells hold the\nstatic load (RMS) and add to the period; ABB's figures "
                "also include a 90 deg tool rotation, not modelled here.", fontsize=7, va="bottom")
    return fig
