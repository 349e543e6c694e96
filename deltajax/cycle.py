"""Along a cycle: joint/effort profiles, actuator limits, designer metrics and the minimum cycle time.

Built on the single-configuration dynamics of :mod:`deltajax.dynamics` (one sample = one call of its
flat hot path or of :func:`~deltajax.dynamics.inverse_dynamics_motion`); the cycles themselves come from
:mod:`deltajax.trajectory`. Efforts at duration T are ``inertial_unit / T^2 + gravity`` exactly, so the
minimum cycle time under :class:`Limits` is closed-form per sample (:func:`cycle_metrics`);
:func:`min_cycle_time_bisection` is the slow cross-check.
"""

from __future__ import annotations

from typing import Any, NamedTuple, Optional

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .dynamics import (Motion, flat_efforts, flat_motion, inverse_dynamics_motion, joint_motion, platform_motion,
                       require_mass, virtual_work_split)
from .fields import check_range, float_leaf
from .geometry import Delta
from .mass import FOREARM_MODELS
from .trajectory import trapezoid_weights

__all__ = [
    "Limits",
    "CycleProfile",
    "CycleMetrics",
    "cycle_profile",
    "cycle_metrics",
    "within_limits",
    "min_cycle_time_bisection", "log_bisect",
    "metrics_by_forearm_model",
]



class Limits(eqx.Module):
    """Actuator limits at the arm side (gearbox output): |tau_i| <= torque, |thetadot_i| <= speed.

    Attributes:
        torque: N m (scalar or per actuator (3,)); ``inf`` for none.
        speed: rad/s (scalar or (3,)); ``inf`` for none. Motor-side values: divide by the gear ratio.
        force_R: N, limit on |force_R| of the reconfiguration actuator (``inf``: none).
        speed_R: m/s, limit on |Rdot| (``inf``: none).
    """

    torque: jax.Array = eqx.field(converter=float_leaf)
    speed: jax.Array = eqx.field(converter=float_leaf, default=float("inf"))
    force_R: jax.Array = eqx.field(converter=float_leaf, default=float("inf"))
    speed_R: jax.Array = eqx.field(converter=float_leaf, default=float("inf"))

    def __check_init__(self):
        for name, unit in (("torque", "N m"), ("speed", "rad/s"), ("force_R", "N"), ("speed_R", "m/s")):
            v = getattr(self, name)
            shape = np.shape(v)
            if not isinstance(v, jax.core.Tracer) and shape not in ((), (3,)):
                raise ValueError(f"Limits.{name} must be a scalar or 3 values (one per actuator), got shape {shape}")
            check_range("Limits", name, v, unit=unit, allow_inf=True)


class CycleProfile(NamedTuple):
    """Joint and effort profiles along a cycle at one duration (K samples; rows = samples).

    ``tau = tau_inertial_unit / T^2 + tau_gravity`` exactly (likewise ``force_R``), where the unit terms are
    the inertial efforts at T = 1 s: all velocity-product and acceleration terms scale as 1/T^2.
    """

    t: Float[Array, "K"]
    p: Float[Array, "K 3"]
    p_dot: Float[Array, "K 3"]
    p_ddot: Float[Array, "K 3"]
    theta: Float[Array, "K 3"]
    theta_dot: Float[Array, "K 3"]
    theta_ddot: Float[Array, "K 3"]
    R: Float[Array, "K"]
    R_dot: Float[Array, "K"]
    tau: Float[Array, "K 3"]
    force_R: Float[Array, "K"]
    tau_gravity: Float[Array, "K 3"]
    force_R_gravity: Float[Array, "K"]
    tau_inertial_unit: Float[Array, "K 3"]
    force_R_inertial_unit: Float[Array, "K"]
    ok: Bool[Array, "K"]


class CycleMetrics(NamedTuple):
    """What a designer asks of a cycle (one design, one cycle).

    Attributes:
        peak_torque: max_t |tau_i| at the cycle's nominal duration (N m), per actuator.
        rms_torque: sqrt(mean_t tau_i^2) at the nominal duration (N m), trapezoidal rule in time.
        peak_speed: max_t |thetadot_i| at the nominal duration (rad/s).
        cycle_time: minimum duration of the cycle meeting all limits (s); ``inf`` if the static (gravity)
            efforts alone exceed a limit.
        ok: every sample reachable and non-singular, and a finite cycle time exists.
        peak_acceleration: max_t |thetaddot_i| at the nominal duration (rad/s^2).
        peak_force_R: max_t |force_R| at the nominal duration (N).
        cycles_per_minute: 60 / cycle_time.
        reachable: every sample reachable, within joint limits and non-singular.
        n_bad: number of samples that are not.
    Every field is NaN when ``reachable`` is False (no silent numbers).
    """

    peak_torque: Float[Array, "3"]
    rms_torque: Float[Array, "3"]
    peak_speed: Float[Array, "3"]
    cycle_time: Float[Array, ""]
    ok: Bool[Array, ""]
    peak_acceleration: Float[Array, "3"]
    peak_force_R: Float[Array, ""]
    cycles_per_minute: Float[Array, ""]
    reachable: Bool[Array, ""]
    n_bad: jax.Array


class _Columns(NamedTuple):
    """A cycle at T = 1 as per-chain columns (tuples of 3 arrays of shape (K,)), the layout both
    :func:`cycle_profile` and :func:`cycle_metrics` consume: under a vmap over designs every column is one
    flat (P, K) array (no (P, K, 3) arrays, whose transposes XLA:CPU would materialise)."""

    p: tuple
    p_dot: tuple
    p_ddot: tuple
    theta: tuple
    theta_dot: tuple
    theta_ddot: tuple
    tau_in: tuple
    tau_g: tuple
    fR_in: jax.Array
    fR_g: jax.Array
    R: jax.Array
    R_dot: jax.Array
    ok: jax.Array


def _sample(robot: Delta, cycle, k_x, k_dx, k_ddx, k_R, k_dR, k_ddR, method) -> _Columns:
    """One sample of a cycle at T = 1: joint motion and (inertial, gravity) efforts, as per-chain scalars."""
    rob = robot if k_R is None else robot.with_base_radius(k_R)
    dR = jnp.zeros((), k_x.dtype) if k_dR is None else k_dR
    ddR = jnp.zeros((), k_x.dtype) if k_ddR is None else k_ddR
    nan = jnp.asarray(jnp.nan, k_x.dtype)
    R = rob.base_radius * jnp.ones((), k_x.dtype)
    split = lambda v: tuple(v[k] for k in range(3))  # noqa: E731
    if cycle.space == "cartesian" and method == "virtual_work":
        # the hot path (GA fitness, motor sizing): flat scalars from IK to efforts
        cols = tuple(split(v) for v in (k_x, k_dx, k_ddx))
        chains, ok, rows, det = flat_motion(rob, *cols, dR, ddR)
        tau_in, tau_g, fR_in, fR_g = flat_efforts(rob, chains, rows, det, cols[2], ddR)
        mask = lambda xs: tuple(jnp.where(ok, x, nan) for x in xs)  # noqa: E731
        return _Columns(p=cols[0], p_dot=cols[1], p_ddot=cols[2],
                        theta=mask([jnp.arctan2(ch.s, ch.c) for ch in chains]),
                        theta_dot=mask([ch.thd for ch in chains]), theta_ddot=mask([ch.thdd for ch in chains]),
                        tau_in=mask(tau_in), tau_g=mask(tau_g), fR_in=jnp.where(ok, fR_in, nan),
                        fR_g=jnp.where(ok, fR_g, nan), R=R, R_dot=dR, ok=ok)
    if cycle.space == "cartesian":
        motion = joint_motion(rob, k_x, k_dx, k_ddx, dR, ddR)
    else:
        motion = platform_motion(rob, k_x, k_dx, k_ddx, dR, ddR)
    if method == "virtual_work":
        tau_in, tau_g, fR_in, fR_g = virtual_work_split(rob, motion)
    else:
        full = inverse_dynamics_motion(rob, motion, method=method)
        zero3 = jnp.zeros_like(motion.theta)
        static = Motion(p=motion.p, p_dot=zero3, p_ddot=zero3, theta=motion.theta, theta_dot=zero3,
                        theta_ddot=zero3, R_dot=jnp.zeros_like(dR), R_ddot=jnp.zeros_like(dR), ok=motion.ok)
        grav = inverse_dynamics_motion(rob, static, method=method)
        tau_in, tau_g = full.tau - grav.tau, grav.tau
        fR_in, fR_g = full.force_R - grav.force_R, grav.force_R
    ok = motion.ok
    tau_in, tau_g, fR_in, fR_g = (jnp.where(ok, e, nan) for e in (tau_in, tau_g, fR_in, fR_g))
    return _Columns(p=split(motion.p), p_dot=split(motion.p_dot), p_ddot=split(motion.p_ddot),
                    theta=split(motion.theta), theta_dot=split(motion.theta_dot),
                    theta_ddot=split(motion.theta_ddot), tau_in=split(tau_in), tau_g=split(tau_g), fR_in=fR_in,
                    fR_g=fR_g, R=R, R_dot=dR, ok=ok)


def _columns(robot: Delta, cycle, method: str) -> _Columns:
    require_mass(robot)
    if method not in ("virtual_work", "lagrange"):
        raise ValueError(f"method must be 'virtual_work' or 'lagrange', got {method!r}")
    has_R = cycle.R is not None
    args = (cycle.x, cycle.dx, cycle.ddx) + ((cycle.R, cycle.dR, cycle.ddR) if has_R else ())

    def one(*a):
        x, dx, ddx = a[:3]
        R, dR, ddR = a[3:] if has_R else (None, None, None)
        return _sample(robot, cycle, x, dx, ddx, R, dR, ddR, method)

    return jax.vmap(one)(*args)


def cycle_profile(robot: Delta, cycle, duration: Any = None, *, method: str = "virtual_work") -> CycleProfile:
    """Joint motion and actuator efforts along ``cycle`` at ``duration`` (default: its nominal one).

    Args:
        robot: robot with a mass model; its base radius is used unless the cycle carries an R profile.
        cycle: :class:`deltajax.trajectory.Cycle`.
        duration: cycle time T (s).
        method: inverse-dynamics formulation (``"virtual_work"`` or ``"lagrange"``).
    """
    col = _columns(robot, cycle, method)
    T = cycle.duration if duration is None else jnp.asarray(duration, cycle.duration.dtype)
    inv_T2 = 1.0 / (T * T)

    def st(cols, scale=None):
        # Arithmetic on the flat columns, the stack last: XLA:CPU emits a root concatenation as one
        # vectorised loop per column, but an elementwise op *on* concatenations element by element (2.3x
        # slower profile, measured).
        return jnp.stack(cols if scale is None else [c * scale for c in cols], axis=-1)

    return CycleProfile(
        t=cycle.u * T, p=st(col.p), p_dot=st(col.p_dot, 1.0 / T), p_ddot=st(col.p_ddot, inv_T2),
        theta=st(col.theta), theta_dot=st(col.theta_dot, 1.0 / T), theta_ddot=st(col.theta_ddot, inv_T2), R=col.R,
        R_dot=col.R_dot / T, tau=st([a * inv_T2 + g for a, g in zip(col.tau_in, col.tau_g)]),
        force_R=col.fR_in * inv_T2 + col.fR_g, tau_gravity=st(col.tau_g), force_R_gravity=col.fR_g,
        tau_inertial_unit=st(col.tau_in), force_R_inertial_unit=col.fR_in, ok=col.ok)


def _T2_bound(a, g, limit):
    """Per sample, the smallest T^2 with |a / T^2 + g| <= limit (0: no bound; limit infinite: 0).

    With x = 1 / T^2 >= 0 the feasible set of a sample is [0, (limit - sign(a) g) / |a|]; a sample with
    |g| > limit is infeasible for every T (the caller checks max |g| <= limit).
    """
    denom = limit - jnp.sign(a) * g
    ratio = jnp.where(jnp.abs(a) > 0, jnp.abs(a) / jnp.where(denom > 0, denom, 1.0), 0.0)
    return jnp.where(jnp.isinf(limit), 0.0, ratio)


@jax.custom_jvp
def _max_sum_reduce(maxed: tuple, summed: tuple) -> tuple:
    """(max over axis 0 of each of ``maxed`` (all >= 0), sum over axis 0 of each of ``summed``) in ONE
    variadic reduction: one loop over the samples evaluates every operand's producers once."""
    n_max = len(maxed)

    def combine(u, v):
        return tuple(jnp.maximum(x, y) if k < n_max else x + y for k, (x, y) in enumerate(zip(u, v)))

    ops = maxed + summed
    zeros = tuple(jnp.zeros((), x.dtype) for x in ops)
    return tuple(jax.lax.reduce(ops, zeros, combine, (0,)))


@_max_sum_reduce.defjvp
def _max_sum_reduce_jvp(primals, tangents):
    # Written out because JAX's generic reduce JVP fails on symbolic-zero tangents (e.g. a constant R'):
    # a max moves with its (first) maximising sample, a sum with the sum of the tangents.
    maxed, summed = primals
    t_max, t_sum = tangents
    out = _max_sum_reduce(maxed, summed)
    t_out = tuple(jnp.take(t, jnp.argmax(x, axis=0), axis=0) for x, t in zip(maxed, t_max))
    return out, t_out + tuple(jnp.sum(t, axis=0) for t in t_sum)


def cycle_metrics(robot: Delta, cycle, limits: Limits, *, method: str = "virtual_work") -> CycleMetrics:
    """Peak/RMS torque, peak speed and minimum cycle time of one design on one cycle (pure, vmappable).

    The minimum cycle time is exact for the sampled profile: efforts scale as ``a / T^2 + g`` and speeds as
    ``theta' / T``, so each sample and actuator bounds T from below in closed form (the 1-D time-scaling
    problem that a bisection on T would solve; :func:`min_cycle_time_bisection` is that cross-check). Peaks
    between samples are missed: use enough samples (a few hundred per cycle).

    Args:
        robot: robot with a mass model (vmap over a batch of designs).
        cycle: :class:`deltajax.trajectory.Cycle` (vmap over a batch of trajectories).
        limits: :class:`Limits`.
        method: inverse-dynamics formulation.

    Returns:
        :class:`CycleMetrics`.
    """
    col = _columns(robot, cycle, method)
    ok = col.ok
    T = cycle.duration
    inv_T2 = 1.0 / (T * T)
    safe = lambda x: jnp.where(ok, x, 0.0)  # noqa: E731
    w = trapezoid_weights(ok.shape[0], 1.0 / (ok.shape[0] - 1), col.fR_in.dtype)
    tq = jnp.broadcast_to(limits.torque, (3,))
    a = [safe(x) for x in col.tau_in] + [safe(col.fR_in)]
    g = [safe(x) for x in col.tau_g] + [safe(col.fR_g)]
    lim = [tq[0], tq[1], tq[2], limits.force_R]
    effort = [ai * inv_T2 + gi for ai, gi in zip(a, g)]
    ratio = [_T2_bound(ai, gi, li) for ai, gi, li in zip(a, g, lim)]
    # Every per-sample quantity goes through ONE variadic reduction over the samples, so the per-sample kernel
    # is evaluated once per sample; separate reductions make XLA:CPU fuse a copy of the kernel into each
    # (measured 2x slower). All max-type quantities are >= 0, so 0 is their identity.
    maxed = ([jnp.abs(x) for x in effort] + ratio + [jnp.abs(x) for x in g]
             + [jnp.abs(safe(x)) for x in col.theta_dot] + [jnp.abs(safe(x)) for x in col.theta_ddot]
             + [jnp.abs(safe(col.R_dot))])
    summed = [w * x * x for x in effort[:3]] + [jnp.where(ok, 0.0, 1.0)]
    red = _max_sum_reduce(tuple(maxed), tuple(summed))
    peak_effort, T2_effort, g_max = red[0:4], red[4:8], red[8:12]
    thd_unit, thdd_unit, R_speed = jnp.stack(red[12:15]), jnp.stack(red[15:18]), red[18]
    sq_sum, n_bad_f = red[19:22], red[22]
    n_bad = n_bad_f.astype(jnp.int32)
    reachable = n_bad == 0
    sp = jnp.broadcast_to(limits.speed, (3,))
    feasible = jnp.all(jnp.stack(g_max) <= jnp.stack(lim))
    T2 = jnp.concatenate([jnp.stack(T2_effort), jnp.where(jnp.isinf(sp), 0.0, (thd_unit / sp) ** 2),
                          jnp.where(jnp.isinf(limits.speed_R), 0.0, (R_speed / limits.speed_R) ** 2)[None]])
    cycle_time = jnp.where(feasible, jnp.sqrt(jnp.max(T2)), jnp.inf)
    # traced limits are not checked by Limits (concrete ones are): a NaN or non-positive limit has no cycle time
    limits_valid = jnp.all(jnp.stack([jnp.all(x > 0) for x in (tq, sp, limits.force_R, limits.speed_R)]))
    cycle_time = jnp.where(limits_valid, cycle_time, jnp.nan)
    nan = jnp.asarray(jnp.nan, w.dtype)
    nan_if = lambda x: jnp.where(reachable, x, nan)  # noqa: E731
    cycle_time = nan_if(cycle_time)
    return CycleMetrics(
        peak_torque=nan_if(jnp.stack(peak_effort[:3])), rms_torque=nan_if(jnp.sqrt(jnp.stack(sq_sum))),
        peak_speed=nan_if(thd_unit / T), cycle_time=cycle_time, ok=reachable & jnp.isfinite(cycle_time),
        peak_acceleration=nan_if(thdd_unit * inv_T2), peak_force_R=nan_if(peak_effort[3]),
        cycles_per_minute=60.0 / cycle_time, reachable=reachable, n_bad=n_bad)


def within_limits(profile: CycleProfile, limits: Limits, rtol: float = 0.0) -> jax.Array:
    """Do all efforts and speeds of a profile respect ``limits`` (with relative slack ``rtol``)?"""
    tq = jnp.broadcast_to(limits.torque, profile.tau.shape) * (1 + rtol)
    sp = jnp.broadcast_to(limits.speed, profile.theta_dot.shape) * (1 + rtol)
    return (jnp.all(jnp.abs(profile.tau) <= tq) & jnp.all(jnp.abs(profile.theta_dot) <= sp)
            & jnp.all(jnp.abs(profile.force_R) <= limits.force_R * (1 + rtol))
            & jnp.all(jnp.abs(profile.R_dot) <= limits.speed_R * (1 + rtol)))


def log_bisect(feasible, T_low, T_high, dtype, n_iter: int = 60) -> jax.Array:
    """Smallest T in [T_low, T_high] with ``feasible(T)`` by bisection on log T (feasibility monotone in T:
    infeasible below, feasible above); ``T_low`` when that is feasible, ``inf`` when ``T_high`` is not."""
    lo, hi = jnp.log(jnp.asarray(T_low, dtype)), jnp.log(jnp.asarray(T_high, dtype))

    def body(_, lh):
        a, b = lh
        m = 0.5 * (a + b)
        f = feasible(jnp.exp(m))
        return jnp.where(f, a, m), jnp.where(f, m, b)

    _, h = jax.lax.fori_loop(0, n_iter, body, (lo, hi))
    T = jnp.where(feasible(jnp.exp(lo)), jnp.exp(lo), jnp.exp(h))
    return jnp.where(feasible(jnp.exp(hi)), T, jnp.inf)


def min_cycle_time_bisection(robot: Delta, cycle, limits: Limits, *, T_low: float = 1e-3, T_high: float = 100.0,
                             n_iter: int = 60, method: str = "virtual_work") -> jax.Array:
    """Minimum cycle time by bisection on T, re-evaluating the full profile at every step (slow; a check).

    Feasibility is monotone in T (efforts a / T^2 + g move toward the static g as T grows, speeds fall), so
    bisection on [T_low, T_high] converges; returns ``inf`` if T_high is infeasible.
    """
    def feasible(T):
        return within_limits(cycle_profile(robot, cycle, T, method=method), limits)

    return log_bisect(feasible, T_low, T_high, cycle.duration.dtype, n_iter)


def metrics_by_forearm_model(robot: Delta, cycle, limits: Limits, *, method: str = "virtual_work", metrics=None,
                             own: Optional[CycleMetrics] = None) -> dict:
    """{forearm model: :class:`CycleMetrics`} of one design on one cycle under every model of
    :data:`deltajax.mass.FOREARM_MODELS` (the robot's own model included; ``own``: its metrics if already
    computed). ``metrics``: the (e.g. jitted) :func:`cycle_metrics` to call."""
    metrics = cycle_metrics if metrics is None else metrics
    mass = require_mass(robot)
    out = {mass.forearm_model: metrics(robot, cycle, limits, method=method) if own is None else own}
    for fm in FOREARM_MODELS:
        if fm not in out:
            out[fm] = metrics(eqx.tree_at(lambda d: d.mass, robot, mass.with_forearm_model(fm)), cycle, limits,
                              method=method)
    return out
