"""Experiment ``reconfig_motion``: the reconfigurable robot's R(t) along trajectories.

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

import functools
import math
import time

import jax
import numpy as np

from .. import motion as mo
from .. import plots
from ..cycle import Limits
from ..motion_refine import path_report, refine_path
from .stages import Runner, Stage, State

__all__ = ["run", "METHODS", "SUMMARY", "CASE_STAGES"]

METHODS = ("fixed", "pointwise", "path_dp", "path_refined")
SUMMARY = (("mean_value", "1"), ("min_value", "1"), ("max_abs_R_dot", "m/s"), ("max_abs_R_ddot", "m/s^2"),
           ("max_abs_force_R", "N"), ("max_abs_screw_torque", "N m"), ("max_screw_speed", "rad/s"),
           ("peak_arm_torque", "N m"), ("n_jumps", "1"), ("max_jump", "m"), ("cycle_time_arms", "s"),
           ("cycle_time_with_drive", "s"), ("within_drive_limits", "1"))


def run(ctx) -> None:
    """The motion job: its settings read once, then per case (:data:`CASE_STAGES`: R(t) by each method, their
    reports, the case's results, its figures) and the mechanism's attributes, on the stage engine."""
    s = ctx.settings                                   # checked before the run (config.reconfig_motion_spec)
    # one bar over every step of every case (tables, DP, refinement if on, per-method reports, write and plots)
    st = State(ctx=ctx, res=ctx.results, s=s, kw=dict(b_v=s.b_v, b_f=s.b_f, beta=s.beta),
               tables_jit=jax.jit(mo.path_tables, static_argnames=("criterion",)),
               arms=Limits(torque=s.torque_limit, speed=s.speed_limit), cases={},
               bar=ctx.progress(total=(4 + bool(s.refine.enabled)) * len(s.cycles), desc="reconfig_motion"))
    stages = [Stage(f"{case}/{step}", functools.partial(fn, case=case)) for case in s.cycles
              for step, fn in CASE_STAGES]
    Runner(ctx, "reconfig_motion", resumable=False).run((*stages, Stage("mechanism", _store_mechanism)), st)


def _done(st: State, case: str, following: str) -> None:
    """One step of the bar done; ``following`` is the step it shows next."""
    st.bar.update(1)
    st.bar.set_postfix_str(f"{case}: {following}")


def _paths(st: State, case: str) -> None:
    """R(t) of one case by every method: the index tables on the R samples, the best fixed R, the pointwise
    argmax, the path DP under the drive limits and (if on) its spline refinement; wall and CPU seconds timed."""
    s, recon, lim = st.s, st.s.recon, st.s.drive
    cyc, boundary = s.cycles[case]
    c = st.cases[case] = State(cyc=cyc, boundary=boundary)
    t0 = time.perf_counter()
    c0 = time.process_time()
    st.bar.set_postfix_str(f"{case}: index tables")
    c.tab = tab = jax.block_until_ready(st.tables_jit(recon, cyc, s.criterion, **st.kw))
    _done(st, case, "path DP")
    c.dt = dt = float(cyc.duration) / (cyc.n_samples - 1)
    c.fixed = mo.fixed_path(tab, lim, s.aggregate, dt)
    c.pw = mo.pointwise_path(tab, s.aggregate, dt)
    c.dp = dp = mo.resolve_path(recon, cyc, s.criterion, limits=lim, aggregate=s.aggregate, boundary=boundary,
                                tables=tab, **st.kw)
    c.t_dp = time.perf_counter() - t0
    _done(st, case, "spline refinement" if s.refine.enabled else "reports")
    if not dp.ok:
        raise RuntimeError(f"case {case!r}: no R(t) meets the drive limits {lim} on this path (bands {dp.bands})")
    if s.refine.enabled:
        c.rf = refine_path(recon, cyc, dp, s.criterion, limits=lim, aggregate=s.aggregate,
                           boundary=boundary, n_ctrl=s.refine.n_ctrl, steps=s.refine.steps,
                           learning_rate=s.refine.learning_rate, **st.kw)
        _done(st, case, "reports")
    else:
        c.rf = None
    c.wall, c.cpu = time.perf_counter() - t0, time.process_time() - c0


def _reports(st: State, case: str) -> None:
    """Each method's profiles along the case's path (:func:`deltajax.motion_refine.path_report`: R actuator
    force, arm torques, screw drive) and its summary row; a method with no feasible R is skipped (logged)."""
    s, c, lim = st.s, st.cases[case], st.s.drive
    # a "jump": a step the drive cannot make in one sample (the DP's own steps sit exactly at the limit)
    c.jump = jump = (float(lim.speed) * c.dt if math.isfinite(float(lim.speed))
                     else float(s.recon.R_step)) * (1 + 1e-6)
    profiles = {"fixed": c.fixed, "pointwise": c.pw, "path_dp": c.dp}
    c.data, c.rows = {}, {}
    for m in METHODS:
        if m == "path_refined":
            src = c.rf if c.rf is not None else c.dp
            R, Rd, Rdd, val = src.R, src.R_dot, src.R_ddot, src.value
        else:
            r = profiles[m]
            if not r.ok:
                st.ctx.log(f"{case}: {m} has no feasible R on this path; skipped")
                continue
            R, Rd, Rdd, val = r.R, r.R_dot, r.R_ddot, r.value
        prof, drv, row = path_report(s.recon.robot, c.cyc, s.mech, R, Rd, Rdd, np.asarray(val), st.arms, lim,
                                     jump)
        c.data[m] = dict(R=np.asarray(R), R_dot=np.asarray(Rd), R_ddot=np.asarray(Rdd), value=np.asarray(val),
                         force_R=np.asarray(prof.force_R), tau=np.asarray(prof.tau), screw_angle=np.asarray(drv.q),
                         screw_torque=np.asarray(drv.effort), drive_ok=np.asarray(drv.ok))
        c.rows[m] = row
    _done(st, case, "write and plots")


def _store_case(st: State, case: str) -> None:
    """The case's group ``reconfig_motion/<case>`` (flushed) and its log lines."""
    s, c, res, lim, dp, rf = st.s, st.cases[case], st.res, st.s.drive, st.cases[case].dp, st.cases[case].rf
    g = f"reconfig_motion/{case}"
    c.t = np.asarray(c.cyc.time())
    res.put_axis(g, "t", c.t, units="s")
    res.put_axis(g, "R_grid", np.asarray(c.tab.R), units="m")
    res.put(g, "p", np.asarray(c.cyc.x), units="m", dims=("t", "xyz"),
            attrs={"long_name": "platform centre, base frame (z down)"})
    res.put(g, "value_table", np.asarray(c.tab.value), units="1", dims=("t", "R_grid"),
            attrs={"long_name": f"{s.criterion} at (sample, R sample); NaN infeasible"})
    units = dict(R="m", R_dot="m/s", R_ddot="m/s^2", value="1", force_R="N", tau="N m", screw_angle="rad",
                 screw_torque=s.mech.effort_unit, drive_ok="1")
    for m, d in c.data.items():
        for key, arr in d.items():
            res.put(f"{g}/{m}", key, arr, units=units[key], dims=("t", "chain") if arr.ndim == 2 else ("t",))
    present = [m for m in METHODS if m in c.rows]
    res.put_axis(f"{g}/summary", "method", np.asarray(present, dtype="S"), units="1")
    for key, unit in SUMMARY:
        res.put(f"{g}/summary", key, np.asarray([c.rows[m][key] for m in present], float), units=unit,
                dims=("method",))
    attrs = dict(boundary=c.boundary, criterion=s.criterion, aggregate=s.aggregate,
                 duration=float(c.cyc.duration), n_samples=int(c.cyc.n_samples), R_step=float(s.recon.R_step),
                 band_speed=dp.bands[0], band_acceleration=dp.bands[1], dp_score=list(dp.score), wall_s=c.wall,
                 cpu_s=c.cpu, dp_wall_s=c.t_dp,
                 drive_speed=float(lim.speed), drive_acceleration=float(lim.acceleration),
                 drive_force=float(lim.force), jump_threshold_m=c.jump)
    if rf is not None:
        attrs.update(refine_accepted=int(rf.accepted), refine_reason=rf.reason, refine_score=list(rf.spline_score))
    res.set_attrs(g, **attrs)
    res.flush()
    for m in present:
        r = c.rows[m]
        st.ctx.log(f"{case:6s} {m:12s} mean {s.criterion} {r['mean_value']:.4f} min {r['min_value']:.4f} | "
                   f"max|Rdot| {r['max_abs_R_dot']:.3f} m/s max|Rddot| {r['max_abs_R_ddot']:.2f} m/s^2 "
                   f"max|F_R| {r['max_abs_force_R']:.1f} N screw {r['max_abs_screw_torque']:.3f} N m | "
                   f"jumps {r['n_jumps']} (max {1000 * r['max_jump']:.1f} mm) | "
                   f"arm torque {r['peak_arm_torque']:.2f} N m | T_min arms {r['cycle_time_arms']:.3f} s, "
                   f"with R drive {r['cycle_time_with_drive']:.3f} s")
    note = "" if rf is None else f"; refinement {'accepted' if rf.accepted else 'rejected'}: {rf.reason}"
    st.ctx.log(f"{case}: bands w={dp.bands[0]}, a={dp.bands[1]} samples; DP {c.t_dp:.1f} s wall; "
               f"case {c.wall:.1f} s wall, {c.cpu:.1f} CPU-s{note}")


def _plot_case(st: State, case: str) -> None:
    """The case's figures: the index landscape over (t, R) with each R(t), the profiles and the arm torques (none
    with ``plots=false``)."""
    s, c, ctx = st.s, st.cases[case], st.ctx
    if not ctx.plots:
        st.bar.update(1)
        return
    # a rejected refinement repeats the DP: draw it only when it differs
    shown = {m: d for m, d in c.data.items() if m != "path_refined" or (c.rf is not None and c.rf.accepted)}
    paths = {m: d["R"] for m, d in shown.items()}
    ctx.savefig(plots.motion_landscape(case, c.t, np.asarray(c.tab.R), np.asarray(c.tab.value), paths,
                                       s.criterion), f"{case}_landscape")
    ctx.savefig(plots.motion_profiles(case, c.t, shown, s.criterion, s.drive.speed, s.drive.force),
                f"{case}_profiles")
    ctx.savefig(plots.motion_torques(case, c.t, shown), f"{case}_torques")
    st.bar.update(1)


def _store_mechanism(st: State) -> None:
    """The reconfiguration drive's attributes on group ``reconfig_motion`` (the bar closes: every case is done)."""
    s, mech = st.s, st.s.mech
    st.bar.close()
    if s.mech_info is not None:
        st.res.set_attrs("reconfig_motion", mechanism="screw_linkage",
                         **{f"mechanism_{k}": float(np.asarray(getattr(mech, k))) for k in
                            ("R_f", "R_r", "d1", "d2", "d3", "pitch", "efficiency", "back_efficiency", "gear_ratio")},
                         **{f"mechanism_{k}": v for k, v in s.mech_info.items()})
    else:
        st.res.set_attrs("reconfig_motion", mechanism="direct")


#: the stages of each case, in order (named ``<case>/<step>``)
CASE_STAGES = (("paths", _paths), ("reports", _reports), ("store", _store_case), ("plots", _plot_case))
