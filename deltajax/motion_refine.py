"""Smooth refinement of a path-optimal R(t): optax on a cubic B-spline (see :mod:`deltajax.motion`), and
:func:`path_report`, what running a given R(t) costs (efforts, drive, cycle times).

R(t) = B c with a uniform cubic B-spline basis (``n_ctrl`` control points), initialised by least squares on the
DP solution (shrunk toward its mean until it meets the rate limits), improved by Adam on a smooth surrogate of
the path criterion with quadratic penalties, and accepted only if the best iterate that meets every constraint
beats the DP's exact criterion (same samples, same weights). Continuous-time rate bounds: the derivative of a
cubic B-spline is a quadratic B-spline with coefficients Delta c / h and the second derivative the linear
B-spline Delta^2 c / h^2, both inside the convex hull of their coefficients, so |Delta c| / h <= Rdot_max and
|Delta^2 c| / h^2 <= Rddot_max bound the speed and acceleration at every instant, not only at the samples.
The R force is checked at every sample with the spline's analytic rates; when no iterate is accepted the DP
solution comes back unchanged (``accepted=False``).
"""

from __future__ import annotations

import math
from typing import NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np

from .cycle import Limits, cycle_metrics, cycle_profile
from .geometry import ReconfigurableDelta
from .mechanism import drive_profile
from .motion import PathResult, RDriveLimits, check_path_args, criterion_at, lex_better, path_forces
from .trajectory import Cycle, trapezoid_weights, with_R

__all__ = ["RefineResult", "refine_path", "spline_basis", "path_cycle_times", "path_report"]


def spline_basis(t: np.ndarray, T: float, n_ctrl: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Uniform cubic B-spline basis on [0, T] with ``n_ctrl`` control points: (B, B', B'') at times t, and h.

    The knot spacing is h = T / (n_ctrl - 3); R(t) = B c, Rdot = B' c, Rddot = B'' c (rows = samples).
    """
    if n_ctrl < 4:
        raise ValueError(f"n_ctrl must be >= 4, got {n_ctrl!r}")
    h = T / (n_ctrl - 3)
    t = np.asarray(t, float)
    seg = np.clip(np.floor(t / h).astype(int), 0, n_ctrl - 4)
    u = t / h - seg
    # uniform cubic B-spline blending functions and their derivatives in u
    b = np.stack([(1 - u) ** 3, 3 * u ** 3 - 6 * u ** 2 + 4, -3 * u ** 3 + 3 * u ** 2 + 3 * u + 1, u ** 3], -1) / 6
    db = np.stack([-3 * (1 - u) ** 2, 9 * u ** 2 - 12 * u, -9 * u ** 2 + 6 * u + 3, 3 * u ** 2], -1) / 6
    ddb = np.stack([6 * (1 - u), 18 * u - 12, -18 * u + 6, 6 * u], -1) / 6
    n = t.shape[0]
    B, B1, B2 = (np.zeros((n, n_ctrl)) for _ in range(3))
    for i in range(4):
        np.add.at(B, (np.arange(n), seg + i), b[:, i])
        np.add.at(B1, (np.arange(n), seg + i), db[:, i] / h)
        np.add.at(B2, (np.arange(n), seg + i), ddb[:, i] / (h * h))
    return B, B1, B2, h


class RefineResult(NamedTuple):
    """Outcome of :func:`refine_path`.

    Attributes:
        accepted: the spline beat the DP's exact criterion with every constraint satisfied.
        R, R_dot, R_ddot, value, force_R: (K,) the returned profile (the spline if accepted, else the DP's).
        score: (primary, secondary) of the returned profile.
        dp_score: the DP's score.
        spline_score: best feasible spline iterate's score (-inf if none was feasible).
        ctrl: (n_ctrl,) control points of the best feasible iterate (NaN if none).
        reason: why it was or was not accepted.
    """

    accepted: bool
    R: np.ndarray
    R_dot: np.ndarray
    R_ddot: np.ndarray
    value: np.ndarray
    force_R: np.ndarray
    score: tuple
    dp_score: tuple
    spline_score: tuple
    ctrl: np.ndarray
    reason: str


def refine_path(recon: ReconfigurableDelta, cycle: Cycle, dp: PathResult, criterion: str = "k_tilde", *,
                limits: Optional[RDriveLimits] = None, aggregate: str = "integral", boundary: str = "free",
                n_ctrl: int = 12, steps: int = 200, learning_rate: float = 2e-4, softmin_scale: float = 0.01,
                penalty: float = 1e4, margin: float = 0.02, b_v: float = 2.0, b_f: float = 4.2,
                beta: float = 0.5) -> RefineResult:
    """Smooth refinement of a DP solution: optax Adam on a cubic B-spline R(t) (see the module docstring).

    Args:
        recon, cycle, criterion, limits, aggregate, b_v, b_f, beta: as in :func:`resolve_path`.
        dp: the DP's :class:`PathResult` (its ``ok`` must be True).
        boundary: ``"rest"``/``"closed"`` add Rdot = 0 at the ends (and R(0) = R(T)) as penalties and checks.
        n_ctrl: control points; steps, learning_rate (m per step scale): Adam settings.
        softmin_scale: temperature of the soft-min surrogate for aggregate "min" (index units).
        penalty: weight of the quadratic constraint penalties (relative violations).
        margin: the penalties aim at limits * (1 - margin) so that iterates end strictly inside.

    Returns:
        :class:`RefineResult`.
    """
    import optax

    limits = RDriveLimits() if limits is None else limits  # built at call time: the caller's precision
    check_path_args(criterion, aggregate, boundary)
    if not dp.ok:
        raise ValueError("refine_path needs a feasible DP solution (dp.ok is False)")
    robot = recon.robot
    x, xd, xdd = cycle.rates()
    dtype = x.dtype
    T = float(cycle.duration)
    t = np.asarray(cycle.time())
    K = t.shape[0]
    B, B1, B2, h = spline_basis(t, T, n_ctrl)
    c0 = np.linalg.lstsq(B, np.asarray(dp.R), rcond=None)[0]
    Bj, B1j, B2j = (jnp.asarray(M, dtype) for M in (B, B1, B2))
    wts = trapezoid_weights(K, T / (K - 1), dtype)
    Rlo, Rhi = float(recon.R_min), float(recon.R_max)
    sp, ac, fm = float(limits.speed), float(limits.acceleration), float(limits.force)
    pm = aggregate == "min"

    def profile(c):
        return Bj @ c, B1j @ c, B2j @ c

    def evaluate(c):
        R, Rd, Rdd = profile(c)
        feas, val = jax.vmap(lambda p, r: criterion_at(robot, p, r, criterion, b_v, b_f, beta))(x, R)
        F, _, okd = path_forces(robot, cycle, x, xd, xdd, R, Rd, Rdd)
        return R, Rd, Rdd, feas & okd, val, F

    def viol(c, scale):
        R, Rd, Rdd, feas, val, F = evaluate(c)
        dc1 = jnp.abs(jnp.diff(c)) / h
        dc2 = jnp.abs(jnp.diff(c, 2)) / (h * h)
        terms = [jnp.sum(jnp.maximum(Rlo - c, 0.0) ** 2 + jnp.maximum(c - Rhi, 0.0) ** 2) / recon.R_step ** 2]
        if math.isfinite(sp):
            terms.append(jnp.sum(jnp.maximum(dc1 - sp * scale, 0.0) ** 2) / sp ** 2)
        if math.isfinite(ac):
            terms.append(jnp.sum(jnp.maximum(dc2 - ac * scale, 0.0) ** 2) / ac ** 2)
        if math.isfinite(fm):
            Fs = jnp.where(feas, F, 0.0)
            terms.append(jnp.sum(jnp.maximum(jnp.abs(Fs) - fm * scale, 0.0) ** 2) / fm ** 2)
        if boundary in ("rest", "closed"):
            terms.append((Rd[0] ** 2 + Rd[-1] ** 2) / max(sp if math.isfinite(sp) else 1.0, 1e-12) ** 2)
        if boundary == "closed":
            terms.append((R[-1] - R[0]) ** 2 / recon.R_step ** 2)
        return sum(terms), (R, Rd, Rdd, feas, val, F)

    def loss(c):
        pen, (R, Rd, Rdd, feas, val, F) = viol(c, 1.0 - margin)
        v = jnp.where(feas, val, -1.0)
        if pm:
            obj = -softmin_scale * jax.nn.logsumexp(-v / softmin_scale)
        else:
            obj = jnp.sum(wts * v) / T
        return -obj + penalty * pen

    def exact(c):
        """(feasible, primary, secondary) with the hard checks: range, bounds on rates, force, boundary."""
        R, Rd, Rdd, feas, val, F = evaluate(c)
        ok = jnp.all(feas) & jnp.all(c >= Rlo) & jnp.all(c <= Rhi)
        ok = ok & jnp.all(jnp.abs(jnp.diff(c)) / h <= sp) & jnp.all(jnp.abs(jnp.diff(c, 2)) / (h * h) <= ac)
        ok = ok & jnp.all(jnp.abs(F) <= fm)
        if boundary in ("rest", "closed"):
            ok = ok & (jnp.abs(Rd[0]) <= 1e-9) & (jnp.abs(Rd[-1]) <= 1e-9)
        if boundary == "closed":
            ok = ok & (jnp.abs(R[-1] - R[0]) <= 1e-12)
        vv = jnp.where(feas, val, 0.0)
        integral, mn = jnp.sum(wts * vv), jnp.min(vv)
        p, s = (mn, integral) if pm else (integral, mn)
        neg = -jnp.inf
        return ok, jnp.where(ok, p, neg), jnp.where(ok, s, neg)

    opt = optax.adam(learning_rate)

    def project(c):
        c = jnp.clip(c, Rlo, Rhi)
        if boundary == "rest":
            # Rdot(0) = (c2 - c0) / 2h for the uniform cubic B-spline: c0 = c2 (and c_{n-1} = c_{n-3}) makes it 0
            c = c.at[0].set(c[2]).at[-1].set(c[-3])
        elif boundary == "closed":
            # and R(T) = R(0): the last three control points mirror the first three
            c = c.at[0].set(c[2])
            c = c.at[-1].set(c[2]).at[-2].set(c[1]).at[-3].set(c[2])
        return c

    @jax.jit
    def run(c):
        st = opt.init(c)
        ok, p, s = exact(c)
        best = (jnp.where(ok, c, jnp.nan * c), p, s)

        def body(carry, _):
            c, st, best = carry
            g = jax.grad(loss)(c)
            g = jnp.where(jnp.isfinite(g), g, 0.0)
            upd, st = opt.update(g, st, c)
            c = project(optax.apply_updates(c, upd))
            ok, p, s = exact(c)
            better = ok & lex_better(p, s, best[1], best[2])
            best = jax.tree.map(lambda new, old: jnp.where(better, new, old), (c, p, s), best)
            return (c, st, best), None

        (_, _, best), _ = jax.lax.scan(body, (c, st, best), None, length=steps)
        return best

    c_init = project(jnp.asarray(c0, dtype))
    # start inside the rate limits: shrink the fit toward its mean (scales every difference, stays in range)
    lam = 1.0
    cc = np.asarray(c_init)
    for lim_v, d in ((sp, np.abs(np.diff(cc)) / h), (ac, np.abs(np.diff(cc, 2)) / (h * h))):
        if math.isfinite(lim_v) and d.size and d.max() > lim_v * (1 - margin):
            lam = min(lam, lim_v * (1 - margin) / d.max())
    c_init = project(jnp.asarray(cc.mean() + lam * (cc - cc.mean()), dtype))
    c_best, p_best, s_best = run(c_init)
    spline_score = (float(p_best), float(s_best))
    dp_score = tuple(float(v) for v in dp.score)
    if np.isfinite(spline_score[0]) and spline_score > dp_score:
        R, Rd, Rdd, feas, val, F = (np.asarray(a) for a in evaluate(c_best))
        return RefineResult(True, R, Rd, Rdd, val, F, spline_score, dp_score, spline_score, np.asarray(c_best),
                            "spline improves the exact criterion and meets every constraint")
    reason = ("no spline iterate met every constraint" if not np.isfinite(spline_score[0])
              else f"spline score {spline_score[0]:.6g} does not beat the DP's {dp_score[0]:.6g}")
    return RefineResult(False, np.asarray(dp.R), np.asarray(dp.R_dot), np.asarray(dp.R_ddot), np.asarray(dp.value),
                        np.asarray(dp.force_R), dp_score, dp_score, spline_score, np.asarray(c_best), reason)


def path_cycle_times(robot, cycle: Cycle, R, R_dot, R_ddot, arms: Limits, drive: RDriveLimits) -> tuple[float, float]:
    """(minimum cycle time for the arms only, minimum cycle time with the R drive too) of ``cycle`` carrying
    R(t) (m, m/s, m/s^2 at the nominal duration), time-scaled with u fixed (:func:`deltajax.cycle_metrics`;
    the drive's acceleration limit in closed form: R'' / T^2 <= limit)."""
    c = with_R(cycle, R, R_dot, R_ddot)
    t_arms = cycle_metrics(robot, c, arms).cycle_time
    full = cycle_metrics(robot, c, Limits(torque=arms.torque, speed=arms.speed, force_R=float(drive.force),
                                          speed_R=float(drive.speed)))
    T = float(cycle.duration)
    Rdd_u = np.max(np.abs(np.asarray(R_ddot))) * T * T        # R'' in normalised time
    acc = float(drive.acceleration)
    T_acc = math.sqrt(Rdd_u / acc) if math.isfinite(acc) else 0.0
    return float(t_arms), max(float(full.cycle_time), T_acc)


def path_report(robot, cycle: Cycle, mech, R, R_dot, R_ddot, value, arms: Limits, drive: RDriveLimits,
                jump: float):
    """What running R(t) along ``cycle`` costs: (CycleProfile, DriveProfile of ``mech``, summary dict).

    The summary holds the trapezoid mean and the min of ``value`` (the criterion per sample), the largest
    |Rdot|, |Rddot|, |F_R|, motor-side drive effort and speed, arm torque, the number of steps larger than
    ``jump`` (m) and the largest step, both cycle times of :func:`path_cycle_times`, and whether the path keeps
    the drive's limits (1/0).
    """
    prof = cycle_profile(robot, with_R(cycle, R, R_dot, R_ddot))
    drv = drive_profile(mech, prof.R, prof.R_dot, prof.force_R)
    T_arms, T_drive = path_cycle_times(robot, cycle, R, R_dot, R_ddot, arms, drive)
    R, Rd, Rdd, value = (np.asarray(x) for x in (R, R_dot, R_ddot, value))
    dR = np.abs(np.diff(R))
    within = (np.all(np.abs(Rd) <= float(drive.speed) * (1 + 1e-9))
              and np.all(np.abs(Rdd) <= float(drive.acceleration) * (1 + 1e-9) + 1e-9)
              and np.all(np.abs(np.asarray(prof.force_R)) <= float(drive.force)))
    w = np.asarray(trapezoid_weights(len(value), 1.0, np.float64))
    row = dict(mean_value=float(np.sum(w * value) / (len(value) - 1)), min_value=float(np.min(value)),
               max_abs_R_dot=float(np.max(np.abs(Rd))), max_abs_R_ddot=float(np.max(np.abs(Rdd))),
               max_abs_force_R=float(np.max(np.abs(prof.force_R))),
               max_abs_screw_torque=float(np.max(np.abs(drv.effort))),
               max_screw_speed=float(np.max(np.abs(drv.motor_speed))),
               peak_arm_torque=float(np.max(np.abs(prof.tau))), n_jumps=int(np.sum(dR > jump)),
               max_jump=float(dR.max()), cycle_time_arms=T_arms, cycle_time_with_drive=T_drive,
               within_drive_limits=int(bool(within)))
    return prof, drv, row
