"""Dynamics along the standard pick-and-place cycle and the GA paper's test motion.

For the config robot and the presets listed in ``experiment.robots``: joint positions, speeds, accelerations
and actuator torques along the standard 25/305/25 mm cycle (at its nominal duration and at the minimum cycle
time under the actuator limits) and along the GA paper's motion; peak/RMS torque, peak speed, minimum cycle
time and cycles per minute; a Lagrange-vs-virtual-work cross-check on every profile. For a reconfigurable
config robot, the GA motion again with R moving, with the R actuator's force.

Every robot and case is evaluated with both forearm models (:data:`deltajax.mass.FOREARM_MODELS`: the robot's
own model drives the profiles, the other is the comparison); peak and RMS torque and minimum cycle
time of each, and the relative difference, in ``dynamics/<robot>/<case>_forearm_models`` and
``dynamics/forearm_models`` (one row per robot/case).

Writes group ``dynamics/<robot>/<case>`` (time axis ``t``; datasets p, p_dot, p_ddot, theta, theta_dot,
theta_ddot, tau, force_R, R) plus ``dynamics/<robot>/adept_metrics`` and ``dynamics/summary``; plots
``<robot>_ga_motion_platform.png`` (like the paper's Fig. 5), ``<robot>_ga_motion_torques.png`` (Fig. 6),
``<robot>_adept_profiles.png``.
"""

from __future__ import annotations

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plots, presets
from .. import trajectory as tr
from ..config import ConfigError
from ..cycle import Limits, cycle_metrics, cycle_profile, metrics_by_forearm_model
from ..mass import FOREARM_MODELS
from .stages import Runner, Stage, State

__all__ = ["run", "preset_robot", "CASE_FIELDS"]

CASE_FIELDS = (("p", "m"), ("p_dot", "m/s"), ("p_ddot", "m/s^2"), ("theta", "rad"), ("theta_dot", "rad/s"),
               ("theta_ddot", "rad/s^2"), ("tau", "N m"), ("force_R", "N"), ("R", "m"), ("R_dot", "m/s"))


def preset_robot(name):
    if name == "franco2026":
        return presets.franco2026(fixed_R=0.200, with_mass=True)
    rob = presets.get(name)
    return rob if getattr(rob, "mass", None) is not None else None


def _save_case(res, group, prof, attrs):
    t = np.asarray(prof.t)
    res.put_axis(group, "t", t, units="s")
    for name, unit in CASE_FIELDS:
        arr = np.asarray(getattr(prof, name))
        dims = ("t",) if arr.ndim == 1 else ("t", "xyz" if name.startswith("p") else "chain")
        res.put(group, name, arr, units=unit, dims=dims)
    res.put(group, "ok", np.asarray(prof.ok), units="1", dims=("t",))
    res.set_attrs(group, **attrs)


def _rel(new, old):
    """Relative change (new - old) / |old| (NaN where old is 0 or not finite)."""
    new, old = np.asarray(new, float), np.asarray(old, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(np.isfinite(old) & (old != 0), (new - old) / np.abs(old), np.nan)


def _save_forearm_models(res, group, by_model):
    """Metrics of one robot/case under each forearm model, and rigid_rod relative to point_split."""
    models = list(FOREARM_MODELS)
    res.put(group, "forearm_model", np.asarray(models, dtype="S"), units="1", dims=("forearm_model",))
    for key, unit in (("peak_torque", "N m"), ("rms_torque", "N m")):
        res.put(group, key, np.stack([np.asarray(getattr(by_model[fm], key)) for fm in models]), units=unit,
                dims=("forearm_model", "chain"))
    for key, unit in (("cycle_time", "s"), ("cycles_per_minute", "1/min")):
        res.put(group, key, np.asarray([float(getattr(by_model[fm], key)) for fm in models]), units=unit,
                dims=("forearm_model",))
    rod, split = by_model["rigid_rod"], by_model["point_split"]
    res.put(group, "rel_change_peak_torque", _rel(np.max(rod.peak_torque), np.max(split.peak_torque)), units="1",
            attrs={"long_name": "(rigid_rod - point_split) / point_split of the largest peak torque"})
    res.put(group, "rel_change_rms_torque", _rel(np.max(rod.rms_torque), np.max(split.rms_torque)), units="1")
    res.put(group, "rel_change_cycle_time", _rel(rod.cycle_time, split.cycle_time), units="1")


def _save_forearm_summary(res, comparison):
    g = "dynamics/forearm_models"
    res.put(g, "case", np.asarray([c for c, _ in comparison], dtype="S"), units="1", dims=("case",))
    res.put(g, "forearm_model", np.asarray(list(FOREARM_MODELS), dtype="S"), units="1", dims=("forearm_model",))
    for key, unit, red in (("peak_torque", "N m", np.max), ("rms_torque", "N m", np.max),
                           ("cycle_time", "s", float)):
        arr = np.asarray([[red(np.asarray(getattr(bm[fm], key))) for fm in FOREARM_MODELS] for _, bm in comparison])
        res.put(g, key, arr, units=unit, dims=("case", "forearm_model"),
                attrs={"long_name": f"{key} (largest over the actuators) per forearm model"})
    res.set_attrs(g, note="rigid_rod: rods with translation + rotation energy; point_split: end point masses "
                          "(deltajax/mass.py); static torques identical")


def _forearm_line(name, case, by_model):
    rod, split = by_model["rigid_rod"], by_model["point_split"]
    pk = (float(np.max(rod.peak_torque)), float(np.max(split.peak_torque)))
    rms = (float(np.max(rod.rms_torque)), float(np.max(split.rms_torque)))
    ct = (float(rod.cycle_time), float(split.cycle_time))
    return (f"{name:12s} {case:10s} forearm rigid_rod vs point_split: peak torque {pk[0]:.4f} vs {pk[1]:.4f} N m "
            f"({100 * float(_rel(*pk)):+.2f} %), RMS {rms[0]:.4f} vs {rms[1]:.4f} N m "
            f"({100 * float(_rel(*rms)):+.2f} %), "
            f"min cycle time {ct[0]:.4f} vs {ct[1]:.4f} s ({100 * float(_rel(*ct)):+.2f} %)")


def run(ctx) -> None:
    """The dynamics job: settings and robots read once, then one stage per robot (both cases, stored and drawn),
    the GA motion with R moving (a reconfigurable robot with ``experiment.recon_R_amplitude`` != 0) and the
    summaries, on the stage engine."""
    spec = ctx.settings                                # checked before the run (config.dynamics_cycle_spec)
    method, robots = spec.method, _robots(ctx, spec)
    st = State(ctx=ctx, res=ctx.results, spec=spec, dtype=ctx.dtype, robots=robots, method=method,
               other="lagrange" if method == "virtual_work" else "virtual_work",
               profile_jit=jax.jit(cycle_profile, static_argnames=("method",)),
               metrics_jit=jax.jit(cycle_metrics, static_argnames=("method",)),
               ga=tr.ga_paper_motion(amplitude=spec.ga_amplitude, duration=spec.ga_duration,
                                     n_samples=spec.n_samples, dtype=ctx.dtype),
               summary=[], comparison=[], max_formulation_gap=0.0,  # comparison: (robot/case, {model: metrics})
               bar=ctx.progress(total=len(robots), desc="robots"))
    stages = [Stage(name, functools.partial(_robot, name=name, last=i == len(robots) - 1))
              for i, name in enumerate(robots)]
    Runner(ctx, "dynamics_cycle", resumable=False).run(
        (*stages, Stage("moving_R", _moving_R, when=lambda st: st.ctx.recon is not None
                        and st.spec.recon_R_amplitude != 0.0), Stage("summary", _store_summary)), st)


def _robots(ctx, spec) -> dict:
    """The robots evaluated: the config robot (under ``spec.cfg_name``), then the presets of
    ``experiment.robots`` (ConfigError for one without a mass model)."""
    robots = {spec.cfg_name: ctx.robot}
    for name in spec.robots:
        if name not in robots:
            rob = preset_robot(name)
            if rob is None:
                raise ConfigError(f"experiment.robots: preset {name!r} has no mass model")
            robots[name] = rob
    return robots


def _in_dtype(robot, dtype):
    """The robot with its inexact arrays in the run's precision."""
    return jax.tree.map(lambda x: jnp.asarray(x, dtype) if eqx.is_inexact_array(x) else x, robot)


def _robot(st: State, name: str, last: bool) -> None:
    """One robot along the standard cycle (its own centre, heading, duration and limits) and the GA paper's motion:
    each case computed, stored (flushed once both are) and drawn (:func:`_case`)."""
    spec, s = st.spec, st.spec.setup(name)
    robot = _in_dtype(st.robots[name], st.dtype)
    limits = Limits(torque=s.torque_limit, speed=s.speed_limit)
    cycle = tr.adept_cycle(s.centre, heading=math.radians(s.heading_deg), duration=s.duration,
                           law=spec.law, blend=spec.blend, n_samples=spec.n_samples, dtype=st.dtype)
    for case, cyc in {"adept": cycle, "ga_motion": st.ga}.items():
        _case(st, name, robot, s, limits, case, cyc)
    st.res.flush()
    st.bar.update(1)
    if last:
        st.bar.close()


def _case(st: State, name: str, robot, s: dict, limits, case: str, cyc) -> None:
    """One robot and case: metrics under the limits, the profile with the job's method and the cross-check with
    the other (the gap), both forearm models; groups ``dynamics/<robot>/<case>`` (``_metrics``,
    ``_forearm_models``), the adept cycle again at its minimum cycle time, the figures and the log lines."""
    ctx, res, method, other, profile_jit = st.ctx, st.res, st.method, st.other, st.profile_jit
    m = st.metrics_jit(robot, cyc, limits, method=method)
    prof = profile_jit(robot, cyc, method=method)
    check = profile_jit(robot, cyc, method=other)
    gap = float(np.nanmax(np.abs(np.asarray(prof.tau) - np.asarray(check.tau)))) if bool(m.reachable) else 0.0
    st.max_formulation_gap = max(st.max_formulation_gap, gap)
    g = f"dynamics/{name}/{case}"
    _save_case(res, g, prof, dict(duration=float(cyc.duration), method=method, limits_torque=s.torque_limit,
                                  limits_speed=s.speed_limit, formulation_gap_Nm=gap,
                                  forearm_model=robot.mass.forearm_model))
    mg = f"dynamics/{name}/{case}_metrics"
    # stored as peak_joint_*: actuator (joint) rates, unlike the GA's end-effector peak_speed (m/s)
    for key, stored, unit in (("peak_torque", "peak_torque", "N m"), ("rms_torque", "rms_torque", "N m"),
                              ("peak_speed", "peak_joint_speed", "rad/s"),
                              ("peak_acceleration", "peak_joint_acceleration", "rad/s^2")):
        res.put(mg, stored, np.asarray(getattr(m, key)), units=unit, dims=("chain",))
    for key, unit in (("cycle_time", "s"), ("cycles_per_minute", "1/min"), ("peak_force_R", "N"),
                      ("ok", "1"), ("reachable", "1"), ("n_bad", "1")):
        res.put(mg, key, np.asarray(getattr(m, key)), units=unit)
    st.summary.append((name, case, m, gap))
    by_model = metrics_by_forearm_model(robot, cyc, limits, method=method, metrics=st.metrics_jit, own=m)
    _save_forearm_models(res, f"dynamics/{name}/{case}_forearm_models", by_model)
    st.comparison.append((f"{name}/{case}", by_model))
    ctx.log(_forearm_line(name, case, by_model))
    ctx.log(f"{name:12s} {case:10s} reachable={bool(m.reachable)} "
            f"peak torque {np.array2string(np.asarray(m.peak_torque), precision=3)} N m, "
            f"RMS {np.array2string(np.asarray(m.rms_torque), precision=3)} N m, "
            f"peak speed {np.array2string(np.asarray(m.peak_speed), precision=3)} rad/s at T = "
            f"{float(cyc.duration):.3f} s; min cycle time {float(m.cycle_time):.4f} s "
            f"({float(m.cycles_per_minute):.1f} cycles/min) under {s.torque_limit} N m, "
            f"{s.speed_limit} rad/s; |tau_{method} - tau_{other}| <= {gap:.2e} N m")
    if case == "adept" and bool(m.ok):
        prof_min = profile_jit(robot, cyc, m.cycle_time, method=method)
        _save_case(res, f"dynamics/{name}/adept_at_min_cycle_time", prof_min,
                   dict(duration=float(m.cycle_time), method=method))
        if ctx.plots:
            ctx.savefig(plots.adept_profiles(name, prof, prof_min, float(m.cycle_time)), f"{name}_adept_profiles")
    if case == "ga_motion" and bool(m.reachable) and ctx.plots:
        ctx.savefig(plots.cycle_platform(prof, f"{name}: GA paper motion, platform (cf. its Fig. 5)"),
                    f"{name}_ga_motion_platform")
        ctx.savefig(plots.cycle_torques(prof, f"{name}: GA paper motion, actuator torques (cf. its Fig. 6)"),
                    f"{name}_ga_motion_torques")


def _moving_R(st: State) -> None:
    """The config robot along the GA motion with R = R0 + A sin(2 pi t/T): group
    ``dynamics/<robot>/ga_motion_moving_R`` with the R actuator's force (its gap to the other method)."""
    ctx, res, spec, method, cfg_name = st.ctx, st.res, st.spec, st.method, st.spec.cfg_name
    recon = ctx.recon
    robot = _in_dtype(recon.robot, st.dtype)
    R0, A = float(recon.robot.base_radius), spec.recon_R_amplitude
    cyc = tr.with_R_profile(st.ga, R0, amplitude=A)
    s = spec.setup(cfg_name)
    limits = Limits(torque=s.torque_limit, speed=s.speed_limit)
    m = st.metrics_jit(robot, cyc, limits, method=method)
    prof = st.profile_jit(robot, cyc, method=method)
    check = st.profile_jit(robot, cyc, method=st.other)
    gap_R = float(np.nanmax(np.abs(np.asarray(prof.force_R) - np.asarray(check.force_R))))
    g = f"dynamics/{cfg_name}/ga_motion_moving_R"
    _save_case(res, g, prof, dict(duration=float(cyc.duration), method=method, R0=R0, R_amplitude=A,
                                  formulation_gap_N=gap_R))
    res.put(g, "peak_force_R", float(m.peak_force_R), units="N")
    st.summary.append((cfg_name, "ga_motion_moving_R", m, gap_R))
    ctx.log(f"{cfg_name} GA motion with R = {R0} + {A} sin(2 pi t/T): peak R force {float(m.peak_force_R):.3f} N, "
            f"peak torque {np.array2string(np.asarray(m.peak_torque), precision=3)} N m")
    if bool(m.reachable) and ctx.plots:
        ctx.savefig(plots.cycle_torques(prof, f"{cfg_name}: GA motion with moving R"), f"{cfg_name}_ga_motion_moving_R")


def _store_summary(st: State) -> None:
    """``dynamics/summary`` (one row per robot/case), ``dynamics/forearm_models`` and the job's attributes."""
    res, spec, summary = st.res, st.spec, st.summary
    names = [f"{n}/{c}" for n, c, _, _ in summary]
    res.put("dynamics/summary", "case", np.asarray(names, dtype="S"), units="1", dims=("case",))
    for key, stored, unit, dims in (("cycle_time", "cycle_time", "s", ("case",)),
                                    ("cycles_per_minute", "cycles_per_minute", "1/min", ("case",)),
                                    ("peak_torque", "peak_torque", "N m", ("case", "chain")),
                                    ("rms_torque", "rms_torque", "N m", ("case", "chain")),
                                    ("peak_speed", "peak_joint_speed", "rad/s", ("case", "chain"))):
        as_is = float if dims == ("case",) else np.asarray
        res.put("dynamics/summary", stored, np.asarray([as_is(getattr(m, key)) for _, _, m, _ in summary]),
                units=unit, dims=dims)
    _save_forearm_summary(res, st.comparison)
    res.set_attrs("dynamics", method=st.method, law=spec.law, blend=spec.blend, n_samples=spec.n_samples,
                  max_formulation_gap=st.max_formulation_gap)
    st.ctx.log(f"largest |virtual work - Lagrange| over all profiles: {st.max_formulation_gap:.2e}")
