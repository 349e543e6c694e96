"""Vendor-style datasheets: ``python -m deltajax.run experiment=datasheet source=<preset | run dir>``.

``source`` is a :data:`deltajax.presets.PRESETS` name (``franco2026``: its fixed variant at R = 0.200 m with the GA
paper's masses, as in dynamics_cycle; the drive from ``experiment.motor`` / ``experiment.gear_ratio``) or a
ga_reconfig run directory: then its baseline and recommended designs (``summary`` group), each at its operating R
and with the run's own
motor and the design's gear ratio (the run's settings rebuild its design space; ``experiment.motor`` and
``experiment.gear_ratio`` are not used, and the log says so).

Writes, per design, group ``datasheet/<design>``: the payload table (axis ``payload``, kg; columns of
:data:`deltajax.datasheet.ROW_FIELDS` with units) and every scalar of :class:`deltajax.datasheet.Datasheet` as a
scalar dataset with its unit; the figure ``datasheet_<design>.png`` (one page).
"""

from __future__ import annotations

import os

import numpy as np

from .. import io, plots
from ..config import ConfigError
from ..drive import Motor
from ..datasheet import MOTOR_FIELDS, ROW_FIELDS, UNITS, datasheet
from .dynamics_cycle import preset_robot

__all__ = ["run", "run_designs", "write", "save"]


def _designs_from_run(spec, ctx):
    """[(name, robot, motor, gear ratio, R)] of a ga_reconfig run's baseline and recommended designs."""
    S = io.load_groups(os.path.join(spec.source, "results.h5"), ("summary",)).get("summary") or {}
    if "recommended_params" not in S:
        raise ConfigError(f"source={spec.source!r}: the run has no recommendation (group summary; unfinished run or "
                          "no feasible design)")
    ctx.log("source is a ga_reconfig run: its motor and each design's gear ratio are used "
            "(experiment.motor / experiment.gear_ratio ignored)")
    return run_designs(spec.source_space, S, spec.source_motor)


def run_designs(space, summary, motor_settings) -> list:
    """[(name, robot, motor, gear ratio, R)] of a ga_reconfig run's baseline and (where the run recommends one)
    recommended design: its ``summary`` group's parameters decoded by the run's design space ``space``, with the
    run's motor ``motor_settings`` (the settings' ``motor`` mapping), each design's own gear ratio and, for a
    reconfigurable design, the operating R the run chose for its task (``R_operating``; None: a fixed-R design)."""
    motor = Motor(**{k: v for k, v in motor_settings.items() if k != "gear_ratio"})
    metrics = [str(m) for m in summary["metric_name"]]
    out = []
    for col, label in (("baseline_params", "baseline"), ("recommended_params", "recommended")):
        if col not in summary:
            continue
        rob = space.decode(space.from_params(np.asarray(summary[col], float)))
        base = rob.robot if hasattr(rob, "robot") else rob
        R = float(np.asarray(summary[label])[metrics.index("R_operating")]) if hasattr(rob, "robot") else None
        out.append((label, rob, motor, float(base.mass.gear_ratio), R))
    return out


def write(ctx, designs, **kwargs) -> None:
    """The datasheet of each of ``designs`` ([(name, robot, motor, gear ratio, R)]) into group ``datasheet/<name>``,
    its log lines and its figure ``datasheet_<name>.png`` (rendered; the results file is written once all are
    computed, before any figure: :meth:`deltajax.run.RunContext.savefig`); ``kwargs`` go to
    :func:`deltajax.datasheet`."""
    for name, robot, motor, n, R in ctx.progress(designs, total=len(designs), desc="datasheets"):
        ds = datasheet(robot, motor, n, name=name, R=R, **kwargs)
        save(ctx.results, f"datasheet/{name}", ds)
        ctx.log(f"{name}: working range {1000 * ds.working_diameter:.0f} x {1000 * ds.working_height:.0f} mm, "
                f"reachable volume {ds.reachable_volume:.4g} m^3, max payload {ds.max_payload:.3g} kg")
        ctx.log(f"  {'payload kg':>10s} {'picks/min':>10s} {'vendor':>8s} {'T_min s':>8s} {'peak':>6s} {'RMS':>6s} "
                f"{'acc g':>6s}")
        for r in ds.rows():
            ctx.log(f"  {r['payload']:10.3g} {r['picks_per_min']:10.1f} {r['picks_per_min_vendor']:8.1f} "
                    f"{r['cycle_time']:8.4f} {r['peak_utilisation']:6.3f} {r['rms_utilisation']:6.3f} "
                    f"{r['peak_acceleration_g']:6.2f}")
        if ctx.plots:   # the A4 page is drawn only to be saved
            ctx.savefig(plots.datasheet_page(ds, f"deltajax datasheet: {name}"), f"datasheet_{name}", crop=False)
    ctx.results.flush()


def _designs_from_preset(name: str, spec):
    robot = preset_robot(name)
    if robot is None:
        raise ConfigError(f"source={name!r}: the preset has no mass model, a datasheet needs one")
    return [(name, robot, Motor(**spec.motor.kwargs()), spec.gear_ratio, spec.R)]


def save(res, group: str, ds) -> None:
    """One datasheet into ``group`` of the results file (units on every dataset)."""
    res.put_axis(group, "payload", ds.payload, units="kg", long_name="payload carried by the platform")
    for name, unit, long_name in ROW_FIELDS[1:]:
        res.put(group, name, getattr(ds, name), units=unit, dims=("payload",), long_name=long_name)
    for name, value in ds.scalars().items():
        if name.startswith("motor_"):
            res.put(group, name, float(value), units=MOTOR_FIELDS[name[len("motor_"):]], long_name="motor side")
        elif name == "centre":
            res.put(group, name, np.asarray(value), units="m", dims=("xyz",), attrs={"positive": "down"},
                    long_name="centre of the 25/305/25 mm cycle (base frame, z down)")
        elif isinstance(value, str):
            continue
        elif name in UNITS:
            res.put(group, name, float(value), units=UNITS[name])
    res.set_attrs(group, name=ds.name, forearm_model=ds.forearm_model, volume_truncated=bool(ds.volume_truncated),
                  cycle="25/305/25 mm go-and-back (deltajax.adept_cycle), one pick per cycle",
                  vendor_column=f"60 / (T_min + 2 x {ds.dwell} s); no tool rotation modelled")


def run(ctx) -> None:
    spec = ctx.settings                                # checked before the run (config.datasheet_settings)
    if spec.kind == "preset":
        designs = _designs_from_preset(spec.source, spec)
    else:
        designs = _designs_from_run(spec, ctx)
    write(ctx, designs, payloads=spec.payloads, vendor_dwell=spec.vendor_dwell, centre=spec.centre,
          hd_ratio=spec.hd_ratio, volume_h=spec.volume_h, n_samples=spec.n_samples,
          cylinder_grid=spec.cylinder_grid)
    ctx.results.set_attrs("datasheet", source=spec.source, source_kind=spec.kind,
                          designs=",".join(d[0] for d in designs))
