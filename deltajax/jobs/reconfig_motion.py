"""Experiment ``reconfig_motion``: the reconfigurable robot's R(t) along trajectories (issue 14).

For each case (the standard pick-and-place cycle and a multi-point task, on the config robot, franco2026 by
default) four ways to run the reconfiguration joint are compared:

* ``fixed`` -- the best fixed R on the path (every sample feasible, static R force within the limit);
* ``pointwise`` -- R*(t) = argmax of the criterion at every sample independently (what the workspace maps do);
  its jumps are counted and its discrete rates reported as they are (the drive cannot follow them);
* ``path_dp`` -- the exact path-optimal R(t) on the R samples (:func:`deltajax.resolve_path`) under the R drive's
  speed, acceleration and force limits;
* ``path_refined`` -- the smooth spline refinement (:func:`deltajax.refine_path`), kept only if it beats the DP
  with every constraint met (else it repeats the DP and ``accepted = 0``).

For each: the criterion along the path, R, Rdot, Rddot, the R actuator force F_R and arm torques (inverse
dynamics with moving R, :func:`deltajax.cycle_profile`), the screw angle and motor-side torque of the
reconfiguration drive (:mod:`deltajax.mechanism`), and the minimum cycle time when the arms *and* the R drive must
keep up: the path is time-scaled (u fixed, T free) and T_min is the smallest T meeting the arm torque/speed
limits, |F_R| and |Rdot| (:func:`deltajax.cycle_metrics`) and |Rddot| (R'' / T^2 <= limit, closed form).

Writes group ``reconfig_motion/<case>``: axes ``t`` (s), ``R_grid`` (m), ``method``; ``p`` (t, xyz); the index
landscape ``value_table`` (t, R_grid); per method ``<method>/R``, ``R_dot``, ``R_ddot``, ``value``, ``force_R``,
``tau``, ``screw_angle``, ``screw_torque``; and ``summary`` datasets over ``method``. Plots
``<case>_landscape.png`` (index over (t, R) with the four R(t)), ``<case>_profiles.png``, ``<case>_torques.png``.
"""

from __future__ import annotations

import math
import time

import jax
import numpy as np

from .. import motion as mo
from .. import plots
from ..config import reconfig_motion_spec
from ..cycle import Limits
from ..motion_refine import path_report, refine_path

__all__ = ["run", "METHODS", "SUMMARY"]

METHODS = ("fixed", "pointwise", "path_dp", "path_refined")
SUMMARY = (("mean_value", "1"), ("min_value", "1"), ("max_abs_R_dot", "m/s"), ("max_abs_R_ddot", "m/s^2"),
           ("max_abs_force_R", "N"), ("max_abs_screw_torque", "N m"), ("max_screw_speed", "rad/s"),
           ("peak_arm_torque", "N m"), ("n_jumps", "1"), ("max_jump", "m"), ("cycle_time_arms", "s"),
           ("cycle_time_with_drive", "s"), ("within_drive_limits", "1"))


def run(ctx) -> None:
    s = reconfig_motion_spec(ctx.cfg.experiment, ctx.cfg, ctx.robot, ctx.recon, dtype=ctx.dtype)
    recon = s["recon"]
    robot = recon.robot
    res = ctx.results
    mech = s["mech"]
    kw = dict(b_v=s["b_v"], b_f=s["b_f"], beta=s["beta"])
    tables_jit = jax.jit(mo.path_tables, static_argnames=("criterion",))
    lim = s["drive"]
    arms = Limits(torque=s["torque_limit"], speed=s["speed_limit"])
    # one bar over every stage of every case (tables, DP, refinement if on, per-method reports, write and plots)
    stages = 4 + bool(s["refine"]["enabled"])
    bar = ctx.progress(total=stages * len(s["cases"]), desc="reconfig_motion")

    def done(case: str, following: str) -> None:
        bar.update(1)
        bar.set_postfix_str(f"{case}: {following}")

    for name, (cyc, boundary) in s["cases"].items():
        t0 = time.perf_counter()
        c0 = time.process_time()
        bar.set_postfix_str(f"{name}: index tables")
        tab = jax.block_until_ready(tables_jit(recon, cyc, s["criterion"], **kw))
        done(name, "path DP")
        dt = float(cyc.duration) / (cyc.n_samples - 1)
        fixed = mo.fixed_path(tab, lim, s["aggregate"], dt)
        pw = mo.pointwise_path(tab, s["aggregate"], dt)
        dp = mo.resolve_path(recon, cyc, s["criterion"], limits=lim, aggregate=s["aggregate"], boundary=boundary,
                             tables=tab, **kw)
        t_dp = time.perf_counter() - t0
        done(name, "spline refinement" if s["refine"]["enabled"] else "reports")
        if not dp.ok:
            raise RuntimeError(f"case {name!r}: no R(t) meets the drive limits {lim} on this path (bands {dp.bands})")
        if s["refine"]["enabled"]:
            rf = refine_path(recon, cyc, dp, s["criterion"], limits=lim, aggregate=s["aggregate"],
                                boundary=boundary, n_ctrl=s["refine"]["n_ctrl"], steps=s["refine"]["steps"],
                                learning_rate=s["refine"]["learning_rate"], **kw)
            done(name, "reports")
        else:
            rf = None
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        # a "jump": a step the drive cannot make in one sample (the DP's own steps sit exactly at the limit)
        jump = (float(lim.speed) * dt if math.isfinite(float(lim.speed)) else float(recon.R_step)) * (1 + 1e-6)
        profiles = {"fixed": fixed, "pointwise": pw, "path_dp": dp}
        data, rows = {}, {}
        for m in METHODS:
            if m == "path_refined":
                src = rf if rf is not None else dp
                R, Rd, Rdd, val = src.R, src.R_dot, src.R_ddot, src.value
            else:
                r = profiles[m]
                if not r.ok:
                    ctx.log(f"{name}: {m} has no feasible R on this path; skipped")
                    continue
                R, Rd, Rdd, val = r.R, r.R_dot, r.R_ddot, r.value
            prof, drv, row = path_report(robot, cyc, mech, R, Rd, Rdd, np.asarray(val), arms, lim, jump)
            data[m] = dict(R=np.asarray(R), R_dot=np.asarray(Rd), R_ddot=np.asarray(Rdd), value=np.asarray(val),
                           force_R=np.asarray(prof.force_R), tau=np.asarray(prof.tau), screw_angle=np.asarray(drv.q),
                           screw_torque=np.asarray(drv.effort), drive_ok=np.asarray(drv.ok))
            rows[m] = row
        done(name, "write and plots")
        g = f"reconfig_motion/{name}"
        t = np.asarray(cyc.time())
        res.put_axis(g, "t", t, units="s")
        res.put_axis(g, "R_grid", np.asarray(tab.R), units="m")
        res.put(g, "p", np.asarray(cyc.x), units="m", dims=("t", "xyz"),
                attrs={"long_name": "platform centre, base frame (z down)"})
        res.put(g, "value_table", np.asarray(tab.value), units="1", dims=("t", "R_grid"),
                attrs={"long_name": f"{s['criterion']} at (sample, R sample); NaN infeasible"})
        units = dict(R="m", R_dot="m/s", R_ddot="m/s^2", value="1", force_R="N", tau="N m", screw_angle="rad",
                     screw_torque=mech.effort_unit, drive_ok="1")
        for m, d in data.items():
            for key, arr in d.items():
                res.put(f"{g}/{m}", key, arr, units=units[key], dims=("t", "chain") if arr.ndim == 2 else ("t",))
        present = [m for m in METHODS if m in rows]
        res.put_axis(f"{g}/summary", "method", np.asarray(present, dtype="S"), units="1")
        for key, unit in SUMMARY:
            res.put(f"{g}/summary", key, np.asarray([rows[m][key] for m in present], float), units=unit,
                    dims=("method",))
        attrs = dict(boundary=boundary, criterion=s["criterion"], aggregate=s["aggregate"],
                     duration=float(cyc.duration), n_samples=int(cyc.n_samples), R_step=float(recon.R_step),
                     band_speed=dp.bands[0], band_acceleration=dp.bands[1], dp_score=list(dp.score), wall_s=wall,
                     cpu_s=cpu, dp_wall_s=t_dp,
                     drive_speed=float(lim.speed), drive_acceleration=float(lim.acceleration),
                     drive_force=float(lim.force), jump_threshold_m=jump)
        if rf is not None:
            attrs.update(refine_accepted=int(rf.accepted), refine_reason=rf.reason, refine_score=list(rf.spline_score))
        res.set_attrs(g, **attrs)
        res.flush()
        for m in present:
            r = rows[m]
            ctx.log(f"{name:6s} {m:12s} mean {s['criterion']} {r['mean_value']:.4f} min {r['min_value']:.4f} | "
                    f"max|Rdot| {r['max_abs_R_dot']:.3f} m/s max|Rddot| {r['max_abs_R_ddot']:.2f} m/s^2 "
                    f"max|F_R| {r['max_abs_force_R']:.1f} N screw {r['max_abs_screw_torque']:.3f} N m | "
                    f"jumps {r['n_jumps']} (max {1000 * r['max_jump']:.1f} mm) | "
                    f"arm torque {r['peak_arm_torque']:.2f} N m | T_min arms {r['cycle_time_arms']:.3f} s, "
                    f"with R drive {r['cycle_time_with_drive']:.3f} s")
        note = "" if rf is None else f"; refinement {'accepted' if rf.accepted else 'rejected'}: {rf.reason}"
        ctx.log(f"{name}: bands w={dp.bands[0]}, a={dp.bands[1]} samples; DP {t_dp:.1f} s wall; "
                f"case {wall:.1f} s wall, {cpu:.1f} CPU-s{note}")
        # a rejected refinement repeats the DP: draw it only when it differs
        shown = {m: d for m, d in data.items() if m != "path_refined" or (rf is not None and rf.accepted)}
        paths = {m: d["R"] for m, d in shown.items()}
        ctx.savefig(plots.motion_landscape(name, t, np.asarray(tab.R), np.asarray(tab.value), paths, s["criterion"]),
                    f"{name}_landscape")
        ctx.savefig(plots.motion_profiles(name, t, shown, s["criterion"], s["drive"].speed, s["drive"].force),
                    f"{name}_profiles")
        ctx.savefig(plots.motion_torques(name, t, shown), f"{name}_torques")
        bar.update(1)
    bar.close()
    if "mech_info" in s:
        res.set_attrs("reconfig_motion", mechanism="screw_linkage",
                      **{f"mechanism_{k}": float(np.asarray(getattr(mech, k))) for k in
                         ("R_f", "R_r", "d1", "d2", "d3", "pitch", "efficiency", "back_efficiency", "gear_ratio")},
                      **{f"mechanism_{k}": v for k, v in s["mech_info"].items()})
    else:
        res.set_attrs("reconfig_motion", mechanism="direct")
