"""Motors, gearing and the cycle rate of a Delta, as pure functions of one design (vmap to batch).

* **Motors and gearing** (:class:`Motor`): per actuator a servo motor (motor side: peak torque, rated
  (continuous) torque, maximum speed, the speed where the peak torque starts to fall linearly to zero at the
  maximum speed, rotor inertia) behind a gearbox of ratio n (motor speed = n x arm speed) and efficiency
  eta. The arm-side torques come from :func:`deltajax.cycle_profile` on the robot whose mass model carries
  ``gear_ratio = n`` and ``rotor_inertia`` (the reflected rotor inertia n^2 J_rotor is part of the arm
  inertia there); motor torque = arm torque / (n eta). Utilisations: peak (max over the cycle of
  |tau_m| / envelope(omega_m)), thermal (RMS of tau_m over the cycle, dwell included, / rated), speed
  (max |omega_m| / max speed).
* **Cycle rate**: picks per minute on the standard 25/305/25 mm go-and-back cycle (one pick per cycle)
  with a given payload, = 60 / (T_min + 2 dwell) where T_min is the shortest motion time (bisection on the
  time scaling, efforts a / T^2 + g) for which every sample is inside the torque-speed envelope and the RMS
  torque (with the dwells at pick and place, holding the static load) is within the rated torque.

The designer's other constraints (passive joints, link interference, the good and regular workspace) are
:mod:`deltajax.constraints`, which re-exports these names. Unreachable configurations give NaN (failure as data).
"""

from __future__ import annotations

import functools
from typing import Callable, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.custom_derivatives import SymbolicZero
from jaxtyping import Array, Bool, Float

from .cycle import cycle_profile, log_bisect
from .fields import ConstraintError, check_range, float_leaf
from .geometry import Delta
from .mass import check_field
from .trajectory import Cycle

__all__ = ["Motor", "DriveLoads", "CycleRate", "with_drive", "motor_side", "drive_ok", "drive_loads",
           "cycle_rate", "cycle_rate_refined", "min_cycle_time", "picks_per_minute"]


# -- motors and gearing ----------------------------------------------------------------------------------------

class Motor(eqx.Module):
    """A servo motor + gearbox per actuator (motor-side values; see the module docstring).

    Attributes:
        peak_torque: N m, available up to ``corner_speed``.
        rated_torque: N m, continuous (thermal) torque.
        max_speed: rad/s.
        corner_speed: rad/s where the peak torque starts to fall linearly to 0 at ``max_speed``.
        rotor_inertia: kg m^2 (rotor + gearbox input).
        efficiency: gearbox efficiency eta in (0, 1].
    """

    peak_torque: jax.Array = eqx.field(converter=float_leaf)
    rated_torque: jax.Array = eqx.field(converter=float_leaf)
    max_speed: jax.Array = eqx.field(converter=float_leaf)
    corner_speed: jax.Array = eqx.field(converter=float_leaf)
    rotor_inertia: jax.Array = eqx.field(converter=float_leaf, default=0.0)
    efficiency: jax.Array = eqx.field(converter=float_leaf, default=1.0)

    def __check_init__(self):
        for n in ("peak_torque", "rated_torque", "max_speed", "corner_speed"):
            check_range("Motor", n, getattr(self, n), lo=0.0, strict=True, hi=1e9, error=ConstraintError)
        check_range("Motor", "rotor_inertia", self.rotor_inertia, lo=0.0, strict=False, hi=1e3,
                    error=ConstraintError)
        check_range("Motor", "efficiency", self.efficiency, lo=0.0, strict=True, hi=1.0, error=ConstraintError)
        conc = [v for v in (self.peak_torque, self.rated_torque, self.max_speed, self.corner_speed)
                if not isinstance(v, jax.core.Tracer)]
        if len(conc) == 4:
            if float(self.rated_torque) > float(self.peak_torque):
                raise ConstraintError(f"Motor.rated_torque={float(self.rated_torque)!r} N m must be <= "
                                      f"peak_torque={float(self.peak_torque)!r} N m")
            if float(self.corner_speed) > float(self.max_speed):
                raise ConstraintError(f"Motor.corner_speed={float(self.corner_speed)!r} rad/s must be <= "
                                      f"max_speed={float(self.max_speed)!r} rad/s")

    def envelope(self, omega: Array) -> Array:
        """Available motor torque at motor speed |omega| (N m); 0 at and beyond max_speed."""
        w = jnp.abs(omega)
        span = jnp.maximum(self.max_speed - self.corner_speed, 1e-12 * self.max_speed)
        frac = jnp.clip((self.max_speed - w) / span, 0.0, 1.0)
        return self.peak_torque * jnp.where(w >= self.max_speed, 0.0, frac)


def _check_gear_ratio(gear_ratio):
    """Concrete scalar gear ratio: one clean error before anything compiles (traced: :func:`_guarded_drive`)."""
    msg = check_field("gear_ratio", "pos", gear_ratio)
    if msg is not None:
        raise ConstraintError(msg + " (motor speed / arm speed)")


def drive_ok(motor: Motor, gear_ratio) -> Bool[Array, ""]:
    """Whether a (possibly traced) motor and gear ratio are valid: every torque and speed finite and > 0,
    rated <= peak torque, corner <= max speed, rotor inertia finite and >= 0, efficiency in (0, 1], gear ratio
    finite and > 0. The traced twin of :meth:`Motor.__check_init__` (which raises for concrete input) and of
    the gear-ratio check: inside a vmapped population an invalid drive gives NaN / ``ok=False``."""
    pos = lambda v: jnp.isfinite(v) & (v > 0)  # noqa: E731  (NaN compares False)
    m = motor
    return (pos(jnp.asarray(gear_ratio)) & pos(m.peak_torque) & pos(m.rated_torque) & pos(m.max_speed)
            & pos(m.corner_speed) & (m.rated_torque <= m.peak_torque) & (m.corner_speed <= m.max_speed)
            & jnp.isfinite(m.rotor_inertia) & (m.rotor_inertia >= 0) & pos(m.efficiency) & (m.efficiency <= 1))


def _guarded_drive(motor: Motor, gear_ratio):
    """(motor, gear ratio, ok): concrete bad input raises (:func:`_check_gear_ratio`); where a traced one is not
    :func:`drive_ok` both are replaced by a harmless stand-in before any algebra (double where), and the
    callers put NaN / ``ok=False`` there."""
    _check_gear_ratio(gear_ratio)
    ok = drive_ok(motor, gear_ratio)
    f = lambda v, good: jnp.where(ok, v, jnp.asarray(good, jnp.result_type(v)))  # noqa: E731
    m = eqx.tree_at(lambda q: (q.peak_torque, q.rated_torque, q.max_speed, q.corner_speed, q.rotor_inertia,
                               q.efficiency), motor,
                    (f(motor.peak_torque, 1.0), f(motor.rated_torque, 0.5), f(motor.max_speed, 100.0),
                     f(motor.corner_speed, 50.0), f(motor.rotor_inertia, 0.0), f(motor.efficiency, 1.0)))
    return m, f(jnp.asarray(gear_ratio, jnp.result_type(float)), 1.0), ok


def with_drive(robot: Delta, motor: Motor, gear_ratio, payload_mass=None) -> Delta:
    """The robot whose mass model carries this gearbox (ratio n) and the motor's rotor inertia (reflected as
    n^2 J_rotor by :class:`deltajax.MassModel`), optionally with a payload (kg)."""
    m = robot.mass
    if m is None:
        raise ConstraintError("with_drive: the robot has no mass model (robot.mass); dynamics need one")
    _check_gear_ratio(gear_ratio)
    m = eqx.tree_at(lambda q: (q.gear_ratio, q.rotor_inertia), m, (float_leaf(gear_ratio) + 0 * m.gear_ratio,
                                                                   motor.rotor_inertia + 0 * m.rotor_inertia))
    if payload_mass is not None:
        m = m.with_payload(payload_mass)
    return eqx.tree_at(lambda d: d.mass, robot, m)


class DriveLoads(NamedTuple):
    """Motor loads of one design on one cycle at one duration (motor side).

    Attributes:
        peak_torque: max_t |tau_m| per actuator (N m).
        rms_torque: RMS of tau_m over the period (motion + dwells) per actuator (N m).
        max_speed: max_t |omega_m| per actuator (rad/s).
        peak_utilisation: max over actuators and time of |tau_m| / envelope(omega_m) (inf past max speed).
        rms_utilisation: max over actuators of rms_torque / rated_torque.
        speed_utilisation: max over actuators of max_speed / motor max speed.
        ok: every cycle sample reachable.
    """

    peak_torque: Float[Array, "3"]
    rms_torque: Float[Array, "3"]
    max_speed: Float[Array, "3"]
    peak_utilisation: Float[Array, ""]
    rms_utilisation: Float[Array, ""]
    speed_utilisation: Float[Array, ""]
    ok: Bool[Array, ""]


def _trap_weights(K, dtype, n_valid=None):
    """Trapezoidal weights of K uniform samples over [0, 1]; ``n_valid`` (traced): the first n_valid of them (the
    rest padding, weight 0)."""
    if n_valid is None:
        return jnp.ones((K,), dtype).at[0].set(0.5).at[-1].set(0.5) / (K - 1)
    k = jnp.arange(K)
    w = jnp.where((k == 0) | (k == n_valid - 1), 0.5, jnp.where(k < n_valid, 1.0, 0.0)).astype(dtype)
    return w / jnp.asarray(n_valid - 1, dtype)


def motor_side(tau_arm, theta_dot, motor: Motor, gear_ratio):
    """(motor torque tau_arm / (n eta) in N m, motor speed n theta_dot in rad/s) of arm-side efforts and speeds
    (any matching shapes) through the gearbox of ratio n = ``gear_ratio``; compare with ``motor.envelope``."""
    return tau_arm * (1.0 / (gear_ratio * motor.efficiency)), theta_dot * gear_ratio


def _peak_ratio(a, g, thd_unit, T, motor: Motor, n):
    """(motor torque, motor speed, |torque| / envelope(speed)) per sample and actuator at duration T from the
    T = 1 profile split (inf past the envelope's speed); the peak utilisation is its maximum."""
    tau_m, om = motor_side(a / (T * T) + g, thd_unit / T, motor, n)   # (K, 3)
    env = motor.envelope(om)
    ratio = jnp.abs(tau_m) / jnp.where(env > 0, env, 1.0)
    return tau_m, om, jnp.where(env > 0, ratio, jnp.where(jnp.abs(tau_m) > 0, jnp.inf, 0.0))


def _loads_from_unit(a, g, thd_unit, T, dwell, motor: Motor, n, ok, n_valid=None):
    """Motor loads at duration T from the T = 1 profile split (a / T^2 + g arm torque, thd_unit / T speed);
    ``n_valid`` (traced): the profile's first n_valid samples are the cycle's, the rest copies of its last."""
    scale = 1.0 / (n * motor.efficiency)
    tau_m, om, ratio = _peak_ratio(a, g, thd_unit, T, motor, n)
    K = a.shape[0]
    move = jnp.tensordot(_trap_weights(K, a.dtype, n_valid), tau_m * tau_m, axes=1) * T  # int tau^2 dt (motion)
    mid = K // 2 if n_valid is None else n_valid // 2                           # the place point
    hold = (g[0] * scale) ** 2 + (g[mid] * scale) ** 2                          # pick and place dwells
    rms = jnp.sqrt((move + dwell * hold) / (T + 2 * dwell))
    nan = jnp.asarray(jnp.nan, a.dtype)
    f = lambda x: jnp.where(ok, x, nan)  # noqa: E731
    return DriveLoads(peak_torque=f(jnp.max(jnp.abs(tau_m), axis=0)), rms_torque=f(rms),
                      max_speed=f(jnp.max(jnp.abs(om), axis=0)), peak_utilisation=f(jnp.max(ratio)),
                      rms_utilisation=f(jnp.max(rms) / motor.rated_torque),
                      speed_utilisation=f(jnp.max(jnp.abs(om)) / motor.max_speed), ok=ok)


def _unit_profile(robot: Delta, cycle):
    prof = cycle_profile(robot, cycle, 1.0)
    ok = jnp.all(prof.ok)
    z = lambda x: jnp.where(prof.ok[:, None], x, 0.0)  # noqa: E731
    return z(prof.tau_inertial_unit), z(prof.tau_gravity), z(prof.theta_dot), ok


def _drive_profile(robot: Delta, cycle, motor: Motor, gear_ratio, dwell, payload_mass):
    """What :func:`drive_loads`, :func:`cycle_rate` and :func:`cycle_rate_refined` start from: the guarded motor,
    the robot with the drive and payload (:func:`with_drive`), its unit-time profile (a, g, theta') on ``cycle``,
    ``ok`` (reachable and a valid drive), and the gear ratio n and dwell in the profile's dtype."""
    motor, gear_ratio, drive = _guarded_drive(motor, gear_ratio)
    r = with_drive(robot, motor, gear_ratio, payload_mass)
    a, g, thd, ok = _unit_profile(r, cycle)
    return motor, r, a, g, thd, ok & drive, jnp.asarray(gear_ratio, a.dtype), jnp.asarray(dwell, a.dtype)


def drive_loads(robot: Delta, cycle, motor: Motor, gear_ratio, *, duration=None, dwell=0.0,
                payload_mass=None) -> DriveLoads:
    """Motor loads on ``cycle`` at ``duration`` (default: its nominal one) with gearbox ratio ``gear_ratio``.

    Args:
        robot: robot with a mass model (its gear ratio and rotor inertia are replaced, see :func:`with_drive`).
        cycle: a Cartesian go-and-back :class:`deltajax.Cycle` (e.g. :func:`deltajax.adept_cycle`; odd sample
            counts put a sample exactly at the place point, where the place dwell holds the static load).
        motor: the motor.
        gear_ratio: n (motor speed / arm speed).
        duration: motion time T (s).
        dwell: s, stop at pick and at place (each).
        payload_mass: kg, replaces the robot's payload if given.

    Every field is NaN and ``ok`` False where the cycle is unreachable or the motor or gear ratio is invalid
    (:func:`drive_ok`; a concrete invalid gear ratio raises :class:`ConstraintError`).
    """
    motor, _, a, g, thd, ok, n, dw = _drive_profile(robot, cycle, motor, gear_ratio, dwell, payload_mass)
    T = cycle.duration if duration is None else jnp.asarray(duration, a.dtype)
    return _loads_from_unit(a, g, thd, T, dw, motor, n, ok)


def _bisect_time(a, g, thd, motor, n, dwell, T_low, T_high, n_iter, n_valid=None):
    def feasible(T):
        L = _loads_from_unit(a, g, thd, T, dwell, motor, n, jnp.asarray(True), n_valid)
        return (L.peak_utilisation <= 1.0) & (L.rms_utilisation <= 1.0)

    return log_bisect(feasible, T_low, T_high, a.dtype, n_iter)


def _implicit_time(T, a, g, thd, motor, n, dwell, T_low):
    """``T`` (the bisection's value, unchanged) carrying the implicit-function derivative of the active limit.

    Bisection is piecewise constant in the design, so its derivative is zero. At an interior T_min the binding
    limit h(T, design) = max(peak utilisation, RMS utilisation) - 1 is 0, hence dT/d(design) = -h_design / h_T
    (implicit function theorem). A custom JVP: the value is the bisection's exactly and costs nothing where nothing
    is differentiated (the search, the verification, the Monte Carlo); where T is not interior (inf, NaN, at T_low)
    or h_T is not negative the derivative is zero. Checked against central differences of the bisection
    (tests/test_constraints.py).
    """
    return _implicit(float(T_low), T, a, g, thd, motor, n, dwell)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _implicit(T_low, T, a, g, thd, motor, n, dwell):
    return T


def _implicit_jvp(T_low, primals, tangents):
    T, *args = primals

    def h(T_, a_, g_, thd_, motor_, n_, dw_):
        L = _loads_from_unit(a_, g_, thd_, T_, dw_, motor_, n_, jnp.asarray(True))
        return jnp.maximum(L.peak_utilisation, L.rms_utilisation) - 1.0

    interior = jnp.isfinite(T) & (T > T_low * (1.0 + 1e-9))
    Ts = jnp.where(interior, T, 1.0)
    hT = jax.grad(h)(Ts, *args)
    use = interior & jnp.isfinite(hT) & (hT < 0)
    # h differentiated in the inputs that carry a tangent (symbolic zeros stay constants, as a closure would keep
    # them), their tangents masked where not used (a select: no 0 x inf where h's derivative is not finite)
    leaves, tree = jax.tree_util.tree_flatten(tuple(args))
    tl = jax.tree_util.tree_leaves(tuple(tangents[1:]), is_leaf=lambda t: isinstance(t, SymbolicZero))
    live = [i for i, t in enumerate(tl) if not isinstance(t, SymbolicZero)]
    if not live:
        return T, jnp.zeros_like(T)

    def h_live(*xs):
        full = list(leaves)
        for i, x in zip(live, xs):
            full[i] = x
        return h(Ts, *jax.tree_util.tree_unflatten(tree, full))

    _, dh = jax.jvp(h_live, tuple(leaves[i] for i in live), tuple(jnp.where(use, tl[i], 0.0) for i in live))
    return T, jnp.where(use, -(dh / jnp.where(use, hT, -1.0)), 0.0)


_implicit.defjvp(_implicit_jvp, symbolic_zeros=True)


class CycleRate(NamedTuple):
    """Fastest cycle of one design within its motors: ``cycle_time`` T_min (s; inf: no T meets the limits,
    NaN: unreachable), ``picks_per_min`` (1/min; 0 / NaN likewise) and the motor ``loads`` at T_min
    (at the nominal duration when T_min is not finite)."""

    cycle_time: Float[Array, ""]
    picks_per_min: Float[Array, ""]
    loads: DriveLoads


def cycle_rate(robot: Delta, cycle, motor: Motor, gear_ratio, *, dwell=0.0, payload_mass=None,
               T_low: float = 1e-3, T_high: float = 60.0, n_iter: int = 60) -> CycleRate:
    """Shortest motion time of ``cycle`` inside the torque-speed envelope and the thermal (RMS) limit, the
    resulting picks per minute (one pick per go-and-back cycle: 60 / (T_min + 2 dwell)) and the loads there.

    Bisection on T over [T_low, T_high] (in log T) with the profile computed once (efforts scale exactly as
    a / T^2 + g, speeds as 1 / T). Feasibility is checked at the returned T (tested at the edge). NaN time and
    rate (loads NaN, ``ok`` False) where the cycle is unreachable or the motor or gear ratio is invalid
    (:func:`drive_ok`; a concrete invalid gear ratio raises :class:`ConstraintError`).
    """
    motor, _, a, g, thd, ok, n, dw = _drive_profile(robot, cycle, motor, gear_ratio, dwell, payload_mass)
    sg = jax.lax.stop_gradient                      # the derivative comes from _implicit_time, not the loop
    T = jnp.where(ok, _bisect_time(sg(a), sg(g), sg(thd), motor, sg(n), sg(dw), T_low, T_high, n_iter), jnp.nan)
    T = _implicit_time(T, a, g, thd, motor, n, dw, T_low)
    ppm = jnp.where(jnp.isfinite(T), 60.0 / (T + 2.0 * dw), jnp.where(jnp.isnan(T), jnp.nan, 0.0))
    Tl = jnp.where(jnp.isfinite(T), T, cycle.duration)
    return CycleRate(cycle_time=T, picks_per_min=ppm, loads=_loads_from_unit(a, g, thd, Tl, dw, motor, n, ok))


def min_cycle_time(robot: Delta, cycle, motor: Motor, gear_ratio, *, dwell=0.0, payload_mass=None,
                   **kw) -> Float[Array, ""]:
    """T_min of :func:`cycle_rate` (s): inf when even the longest time violates a limit (e.g. the static load
    alone exceeds the rated torque), NaN when the cycle is not reachable."""
    return cycle_rate(robot, cycle, motor, gear_ratio, dwell=dwell, payload_mass=payload_mass, **kw).cycle_time


def picks_per_minute(robot: Delta, cycle, motor: Motor, gear_ratio, *, dwell=0.0, payload_mass=None,
                     **kw) -> Float[Array, ""]:
    """Cycle rate (picks/min) of :func:`cycle_rate`: 0 when no motion time meets the limits, NaN when the
    cycle is unreachable."""
    return cycle_rate(robot, cycle, motor, gear_ratio, dwell=dwell, payload_mass=payload_mass, **kw).picks_per_min


def cycle_rate_refined(robot: Delta, cycle, path: Callable, refine: Callable, motor: Motor, gear_ratio, *,
                       dwell=0.0, payload_mass=None, T_low: float = 1e-3, T_high: float = 60.0,
                       n_iter: int = 60, n_valid=None) -> tuple:
    """:func:`cycle_rate` with the peak utilisation searched between the samples of ``cycle``.

    At the samples' fastest time T0 (exactly :func:`cycle_rate`'s) ``refine(f, u, V) -> t`` finds the worst point
    of f(t) = -(max over actuators of |tau_m| / envelope(omega_m)) from its values ``V`` (K, 1) at the samples
    ``cycle.u`` (e.g. :func:`deltajax.optimize.cycle_worst.worst_along`), on the path ``path(u (k,)) -> (x, x',
    x'')`` (the one ``cycle`` samples). The cycle time is then the smallest T at which the samples (peak and RMS)
    and that point (peak) all hold, never below T0; the loads there carry the peak over both (RMS and speed: the
    samples'; the RMS is an integral, the samples' trapezoidal rule). NaN everywhere where a sample or the point
    is unreachable. ``n_valid`` (traced, optional): only the first n_valid samples of ``cycle`` are its samples,
    the rest copies of the last (one compiled program for several densities; ``refine`` must skip them too).
    Returns (the refined :class:`CycleRate`, the samples' T0, the samples' peak utilisation at T0).
    """
    motor, r, a, g, thd, ok, n, dw = _drive_profile(robot, cycle, motor, gear_ratio, dwell, payload_mass)
    T0 = jnp.where(ok, _bisect_time(a, g, thd, motor, n, dw, T_low, T_high, n_iter, n_valid), jnp.nan)
    T0l = jnp.where(jnp.isfinite(T0), T0, cycle.duration)

    def unit_at(t):
        tt = jnp.reshape(t, (1,))
        xt, dxt, ddxt = path(tt)
        a1, g1, thd1, ok1 = _unit_profile(r, Cycle(u=tt, x=xt, dx=dxt, ddx=ddxt, duration=cycle.duration,
                                                   space="cartesian"))
        return a1, g1, thd1, ok1

    def neg_peak(t):
        a1, g1, thd1, ok1 = unit_at(t)
        return jnp.where(ok1, -jnp.max(_peak_ratio(a1, g1, thd1, T0l, motor, n)[2]), jnp.nan)[None]

    t_p = refine(neg_peak, cycle.u, -jnp.max(_peak_ratio(a, g, thd, T0l, motor, n)[2], axis=1)[:, None])
    a1, g1, thd1, ok1 = unit_at(t_p)
    ok = ok & ok1

    def feasible(T):
        L = _loads_from_unit(a, g, thd, T, dw, motor, n, jnp.asarray(True), n_valid)
        pk = jnp.max(_peak_ratio(a1, g1, thd1, T, motor, n)[2])
        return (L.peak_utilisation <= 1.0) & (L.rms_utilisation <= 1.0) & (pk <= 1.0)

    T = jnp.where(ok, jnp.maximum(T0, log_bisect(feasible, T_low, T_high, a.dtype, n_iter)), jnp.nan)
    ppm = jnp.where(jnp.isfinite(T), 60.0 / (T + 2.0 * dw), jnp.where(jnp.isnan(T), jnp.nan, 0.0))
    Tl = jnp.where(jnp.isfinite(T), T, cycle.duration)
    L = _loads_from_unit(a, g, thd, Tl, dw, motor, n, ok, n_valid)
    tau1, _, ratio1 = _peak_ratio(a1, g1, thd1, Tl, motor, n)
    nan = jnp.asarray(jnp.nan, a.dtype)
    L = L._replace(peak_torque=jnp.where(ok, jnp.maximum(L.peak_torque, jnp.abs(tau1[0])), nan),
                   peak_utilisation=jnp.where(ok, jnp.maximum(L.peak_utilisation, jnp.max(ratio1)), nan))
    peak0 = _loads_from_unit(a, g, thd, T0l, dw, motor, n, ok, n_valid).peak_utilisation
    return CycleRate(cycle_time=T, picks_per_min=ppm, loads=L), T0, peak0


