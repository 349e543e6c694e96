"""Inverse dynamics of the (reconfigurable) Delta robot, single configuration (vmap for batches).

Model: :mod:`deltajax.mass` (z down, gravity +z). Forearms: ``rigid_rod`` (default) or ``point_split``. The
formulations below are written for the point split (masses s m_f at the elbows, (1 - s) m_f at the platform,
inside the lumped I, s, M); the rigid rod has the same potential energy and the kinetic energy
``T_split - J/2 sum_i |w_i'|^2`` (w_i = C_i - B_i, J = ``mass.forearm_rotation_deficit()``), which adds
``-J w_i'' . dw_i/dq`` to every generalised force (platform rows -J sum_i w_i'', arm rows
J L1 (cos th w_z'' - sin th w_x''), R row J sum_i w_x''). The autodiff formulation instead uses the rods'
``m/2 |v_c|^2 + I_c/2 |u x u'|^2`` literally, and tests/test_dynamics.py checks all three against Newton-Euler
on free-body diagrams.
Generalised coordinates q = (R, theta_1, theta_2, theta_3): R is the reconfiguration joint that moves the
three A_i radially together (the robot's ``base_radius`` is R at the current instant), theta the actuated
arm angles. Generalised forces: ``tau`` (N m, about the motor axes, positive in the +theta = downward sense,
at the gearbox output) and ``force_R`` (N, total radial force of the R actuator, positive outward).

Three independent formulations (tested to agree to 1e-9 in float64):

* ``method="lagrange"`` (GA paper §2.6, derived here since its formulas are garbled): the Lagrangian in the
  redundant coordinates (p, R, theta) with the three loop constraints
  Gamma_i = |C_i - B_i|^2 - L2^2 = 0 and multipliers lambda. Per chain, with I = arm inertia about the motor
  axis (reflected rotor included), s = first moment m_a c + m_e L1, m_R = radial mass, M = platform mass:

      T = sum_i [ m_R Rdot^2 / 2 - s sin(th_i) Rdot thdot_i + I thdot_i^2 / 2 ] + M |pdot|^2 / 2
      V = - g sum_i s sin(th_i) - M g p_z                         (z down)

  giving  M (pddot - g e_z) = sum_i lambda_i dGamma_i/dp   (3 equations -> lambda), then
  tau_i   = I thddot_i - s sin(th_i) Rddot - g s cos(th_i) - lambda_i dGamma_i/dth_i,
  force_R = 3 m_R Rddot - s sum_i (sin th_i thddot_i + cos th_i thdot_i^2) - sum_i lambda_i dGamma_i/dR.
* ``method="virtual_work"`` (d'Alembert + Jacobian transpose): inertial-minus-gravity forces of every lumped
  body from its point acceleration, mapped by the partial velocities of the arms, plus the platform's
  ``J^T F = Jq^T Jx^-T M (pddot - g e_z)`` with ``Jx, Jq`` from :func:`deltajax.jacobians`.
* ``method="autodiff"``: Euler-Lagrange equations of the *reduced* Lagrangian L(q, qdot) with the platform
  position from the forward kinematics, differentiated by JAX (no IK, no Jacobians, no hand algebra).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from .geometry import Delta
from .jacobian import jq_theta, jx_det, jx_row
from .kinematics import (COS_A, SIN_A, branch_sign, from_chain_frames, chain_local, design_ok, fk, limit_terms,
                         loop_closure, loop_vectors, safe_point, to_chain_frames)

__all__ = [
    "Motion",
    "Torques",
    "joint_motion",
    "platform_motion",
    "inverse_dynamics",
    "inverse_dynamics_motion",
    "gravity_torques",
    "energy",
    "energy_from_joints",
    "METHODS",
    "require_mass",
    "flat_motion",
    "flat_efforts",
    "virtual_work_split",
]

METHODS = ("virtual_work", "lagrange", "autodiff")


class Motion(NamedTuple):
    """Kinematic state of the whole robot at one instant (base frame, SI units).

    Attributes:
        p, p_dot, p_ddot: platform centre position (m), velocity (m/s), acceleration (m/s^2).
        theta, theta_dot, theta_ddot: actuated angles (rad), rates (rad/s), accelerations (rad/s^2).
        R_dot, R_ddot: reconfiguration joint rate (m/s) and acceleration (m/s^2); R itself is the robot's
            ``base_radius``.
        ok: kinematics solved, within joint limits and away from singularities (Jx and Jq invertible).
    """

    p: Float[Array, "3"]
    p_dot: Float[Array, "3"]
    p_ddot: Float[Array, "3"]
    theta: Float[Array, "3"]
    theta_dot: Float[Array, "3"]
    theta_ddot: Float[Array, "3"]
    R_dot: Float[Array, ""]
    R_ddot: Float[Array, ""]
    ok: Bool[Array, ""]


class Torques(NamedTuple):
    """Actuator efforts.

    Attributes:
        tau: arm torques (N m), positive in the +theta (downward) sense, at the gearbox output.
        force_R: total force of the R actuator along +R (outward), N.
        ok: the motion was valid (see :class:`Motion`); efforts are NaN otherwise.
    """

    tau: Float[Array, "3"]
    force_R: Float[Array, ""]
    ok: Bool[Array, ""]


def require_mass(robot: Delta):
    """The robot's mass model; a clear error when it has none."""
    if robot.mass is None:
        raise ValueError("robot.mass is None: dynamics needs a mass model (e.g. presets.franco2026(with_mass=True)"
                         " or a `mass:` block in the robot config)")
    return robot.mass


def _chain_terms(robot: Delta, p, theta, c=None, s=None):
    """Loop vectors w_i = C_i - B_i (chain frames), unit u (local) and Jq diagonal d_i = L1 sin th2 sin th3.

    (3,)-array form for the per-point API; built from the core's :func:`~deltajax.kinematics.loop_vectors`
    and :func:`~deltajax.jacobian.jq_theta`.
    """
    L1, L2 = robot.upper_arm, robot.forearm
    c = jnp.cos(theta) if c is None else c
    s = jnp.sin(theta) if s is None else s
    shift = robot.platform_radius - robot.base_radius
    u, d = [], []
    for i in range(3):
        x, y, z = chain_local(p[0], p[1], p[2], i)
        ui = loop_vectors(x + shift, y, z, c[i], s[i], L1, L2)
        u.append(jnp.stack(ui))
        d.append(L1 * jq_theta(ui[0], ui[2], c[i], s[i]))
    u = jnp.stack(u)
    return u * L2, u, jnp.stack(d)


def _adjugate_rows(A):
    """(det A, C) with C[i] = A[j] x A[k] ((i, j, k) cyclic), so that A^-1 = C^T / det and A^-T = C / det.

    Closed form for 3x3 systems: XLA:CPU's batched LU for tiny matrices costs more than the rest of the
    inverse dynamics together. The determinant is the core's :func:`~deltajax.jacobian.jx_det`.
    """
    C = jnp.stack([jnp.cross(A[1], A[2]), jnp.cross(A[2], A[0]), jnp.cross(A[0], A[1])])
    return jx_det(*(A[i, j] for i in range(3) for j in range(3))), C


def _solve3(A, b, *, transpose: bool = False):
    """Solve A x = b (or A^T x = b) for a 3x3 A by the adjugate (caller masks singular A)."""
    det, C = _adjugate_rows(A)
    det = jnp.where(det != 0, det, 1.0)
    return (C @ b if transpose else C.T @ b) / det


def _validity(robot: Delta, u_local, d, tol):
    """Away from type-1 (Jq) and type-2 (Jx) singularities, relative tolerance ``tol``."""
    det_jx, _ = _adjugate_rows(from_chain_frames(u_local))
    return (jnp.abs(det_jx) > tol) & jnp.all(jnp.abs(d) > tol * robot.upper_arm)


# ---------------------------------------------------------------------------------------------------------
# Flat (scalar per chain) form: what cycle_profile / cycle_metrics run. Under vmap over samples and designs
# every quantity here is one flat (P, K) array; nothing is a per-point (3,) vector or (3, 3) matrix
# (XLA:CPU does not vectorise those: docs/BENCHMARKS.md).
# ---------------------------------------------------------------------------------------------------------
class _Chain(NamedTuple):
    """One chain at one instant (scalars): cos/sin theta, unit forearm u (chain frame), Jq entry d = L1 sin th2
    sin th3, joint rate and acceleration, loop closed within limits."""

    c: jax.Array
    s: jax.Array
    ux: jax.Array
    uy: jax.Array
    uz: jax.Array
    d: jax.Array
    thd: jax.Array
    thdd: jax.Array
    ok: jax.Array


def _chain_motion(robot: Delta, i: int, p, v, a, R_dot, R_ddot, lim, sign) -> _Chain:
    """Chain i's joint motion for a platform motion (p, v, a: base-frame 3-tuples of scalars); see joint_motion."""
    L1, L2 = robot.upper_arm, robot.forearm
    x, y, z = chain_local(*p, i)
    vx, vy, vz = chain_local(*v, i)
    ax, ay, az = chain_local(*a, i)
    dx = x + (robot.platform_radius - robot.base_radius)
    lc = loop_closure(dx, y, z, L1, L2, lim, sign)
    c, s = lc.cos, lc.sin
    ux, uy, uz = loop_vectors(dx, y, z, c, s, L1, L2)
    d = L1 * jq_theta(ux, uz, c, s)
    d_safe = jnp.where(jnp.abs(d) > 0, d, 1.0)
    thd = (ux * vx + uy * vy + uz * vz - ux * R_dot) / d_safe
    wx, wz = vx - R_dot + L1 * s * thd, vz - L1 * c * thd          # w' = C' - B'
    thdd = ((ux * ax + uy * ay + uz * az) + (wx * wx + vy * vy + wz * wz) / L2 - ux * R_ddot
            + L1 * thd * thd * (ux * c + uz * s)) / d_safe
    return _Chain(c=c, s=s, ux=ux, uy=uy, uz=uz, d=d, thd=thd, thdd=thdd, ok=lc.ok)


def _chain_state(robot: Delta, i: int, p, theta, thd, thdd) -> _Chain:
    """Chain i for a given joint state (theta known, e.g. from FK): cos/sin of theta, u and d from the core."""
    L1 = robot.upper_arm
    c, s = jnp.cos(theta), jnp.sin(theta)
    x, y, z = chain_local(*p, i)
    ux, uy, uz = loop_vectors(x + (robot.platform_radius - robot.base_radius), y, z, c, s, L1, robot.forearm)
    return _Chain(c=c, s=s, ux=ux, uy=uy, uz=uz, d=L1 * jq_theta(ux, uz, c, s), thd=thd, thdd=thdd,
                  ok=jnp.isfinite(theta))


def _jx_rows(chains):
    return tuple(jx_row(ch.ux, ch.uy, ch.uz, i) for i, ch in enumerate(chains))


def _flat_validity(robot: Delta, chains, rows, tol):
    det = jx_det(*rows[0], *rows[1], *rows[2])
    ok = jnp.abs(det) > tol
    for ch in chains:
        ok = ok & ch.ok & (jnp.abs(ch.d) > tol * robot.upper_arm)
    return ok, det


def _cross(a, b):
    return a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]


def flat_efforts(robot: Delta, chains, rows, det, p_ddot, R_ddot):
    """Virtual-work efforts, split (tau_inertial, tau_gravity, force_R_inertial, force_R_gravity); scalars.

    Arms: I thdd - S sin th Rdd (inertial) and -g S cos th (gravity), with I, S the lumped inertia and first
    moment; R: m_R Rdd - S (cos th thd^2 + sin th thdd) per chain; platform: J^T F = Jq^T Jx^-T F,
    Jx^-T F = C F / det (C[i] = row_j x row_k). Rigid-rod forearms add -J w_i'' . dw_i/dq (module docstring).
    """
    mm = require_mass(robot)
    L1, g = robot.upper_arm, mm.gravity
    I_arm, S, M, m_R = mm.arm_inertia(L1), mm.arm_first_moment(L1), mm.moving_mass(), mm.radial_mass()
    tau_in = [I_arm * ch.thdd - S * ch.s * R_ddot for ch in chains]
    tau_g = [-g * S * ch.c for ch in chains]
    fR_in = sum(m_R * R_ddot - S * (ch.c * ch.thd * ch.thd + ch.s * ch.thdd) for ch in chains)
    F = [M * a for a in p_ddot]
    if mm.forearm_model == "rigid_rod":
        J = mm.forearm_rotation_deficit()
        for i, ch in enumerate(chains):
            bx = R_ddot - L1 * (ch.c * ch.thd * ch.thd + ch.s * ch.thdd)      # elbow acceleration B''
            bz = L1 * (ch.c * ch.thdd - ch.s * ch.thd * ch.thd)
            ax, _, az = chain_local(*p_ddot, i)
            wx, wz = ax - bx, az - bz                                        # w'' = C'' - B'' (x, z)
            tau_in[i] = tau_in[i] + J * L1 * (ch.c * wz - ch.s * wx)
            fR_in = fR_in + J * wx
            # -J sum_i w_i'' in the base frame = -3 J p'' + J sum_i B_i'' (B'' has no y component)
            F[0] = F[0] - J * (p_ddot[0] - COS_A[i] * bx)
            F[1] = F[1] - J * (p_ddot[1] - SIN_A[i] * bx)
            F[2] = F[2] - J * (p_ddot[2] - bz)
    C = (_cross(rows[1], rows[2]), _cross(rows[2], rows[0]), _cross(rows[0], rows[1]))
    inv_det = 1.0 / jnp.where(det != 0, det, 1.0)
    fR_g = jnp.zeros_like(fR_in)
    for i, ch in enumerate(chains):
        y = (C[i][0] * F[0] + C[i][1] * F[1] + C[i][2] * F[2]) * inv_det      # (Jx^-T F)_i
        y_g = -M * g * C[i][2] * inv_det                                     # (Jx^-T (-M g e_z))_i
        tau_in[i] = tau_in[i] + ch.d * y
        tau_g[i] = tau_g[i] + ch.d * y_g
        fR_in = fR_in + ch.ux * y
        fR_g = fR_g + ch.ux * y_g
    return tau_in, tau_g, fR_in, fR_g


def _elbow_rates(robot: Delta, theta, theta_dot, theta_ddot, R_dot, R_ddot, c=None, s=None):
    """Elbow velocity and acceleration in the chain frames (rows = chains)."""
    L1 = robot.upper_arm
    c = jnp.cos(theta) if c is None else c
    s = jnp.sin(theta) if s is None else s
    zero = jnp.zeros_like(theta)
    b_dot = jnp.stack([R_dot - L1 * s * theta_dot, zero, L1 * c * theta_dot], axis=-1)
    b_ddot = jnp.stack([R_ddot - L1 * c * theta_dot ** 2 - L1 * s * theta_ddot, zero,
                        -L1 * s * theta_dot ** 2 + L1 * c * theta_ddot], axis=-1)
    return b_dot, b_ddot


def _loop_acceleration(robot: Delta, m: Motion, c, s):
    """Loop-vector accelerations w_i'' = C_i'' - B_i'' in the chain frames (rows = chains), m/s^2."""
    _, b_ddot = _elbow_rates(robot, m.theta, m.theta_dot, m.theta_ddot, m.R_dot, m.R_ddot, c, s)
    return to_chain_frames(m.p_ddot) - b_ddot


def joint_motion(robot: Delta, p: Float[Array, "3"], p_dot: Float[Array, "3"], p_ddot: Float[Array, "3"],
                 R_dot=0.0, R_ddot=0.0, *, branch: str = "outer", singular_tol: float = 1e-9) -> Motion:
    """Joint positions, rates and accelerations for a platform motion (IK + closed-form loop derivatives).

    Differentiating |C_i - B_i|^2 = L2^2 once and twice (w = C_i - B_i in chain i's frame, u = w / L2):
    ``u.pdot = u_x Rdot + d_i thdot_i`` and
    ``u.pddot + |wdot|^2 / L2 = u_x Rddot - L1 thdot^2 (u_x cos th + u_z sin th) + d_i thddot_i``,
    with d_i = L1 (u_z cos th - u_x sin th) = L1 sin th2 sin th3 (the Jq diagonal).

    Args:
        robot: the robot at the current base radius R.
        p, p_dot, p_ddot: platform position, velocity, acceleration (base frame, SI).
        R_dot, R_ddot: reconfiguration rate and acceleration (m/s, m/s^2).
        branch: IK branch.
        singular_tol: relative threshold on |det Jx| and |d_i| / L1 below which the sample is flagged.

    Returns:
        :class:`Motion`; ``ok`` False (and NaN joint values) where unreachable, outside limits or singular.
    """
    p, p_dot, p_ddot = (jnp.asarray(a) for a in (p, p_dot, p_ddot))
    dtype = jnp.result_type(p.dtype, robot.upper_arm.dtype)
    p, p_dot, p_ddot = (a.astype(dtype) for a in (p, p_dot, p_ddot))
    R_dot = jnp.asarray(R_dot, dtype)
    R_ddot = jnp.asarray(R_ddot, dtype)
    chains, ok, _, _ = flat_motion(robot, tuple(p), tuple(p_dot), tuple(p_ddot), R_dot, R_ddot,
                                    branch=branch, singular_tol=singular_tol)
    theta = jnp.stack([jnp.arctan2(ch.s, ch.c) for ch in chains])   # only reported; the dynamics use (c, s)
    nan = jnp.asarray(jnp.nan, dtype)
    return Motion(p=p, p_dot=p_dot, p_ddot=p_ddot, theta=jnp.where(ok, theta, nan),
                  theta_dot=jnp.where(ok, jnp.stack([ch.thd for ch in chains]), nan),
                  theta_ddot=jnp.where(ok, jnp.stack([ch.thdd for ch in chains]), nan),
                  R_dot=R_dot, R_ddot=R_ddot, ok=ok)


def flat_motion(robot: Delta, p, v, a, R_dot, R_ddot, *, branch: str = "outer", singular_tol: float = 1e-9):
    """The three chains' joint motion (scalars), validity, Jx rows and det Jx for one platform motion."""
    lim = limit_terms(robot.theta_min, robot.theta_max)
    sign = branch_sign(branch)
    _, usable = safe_point(robot, jnp.stack(p))  # non-finite or huge p: a stand-in before any algebra
    p = tuple(jnp.where(usable, pk, jnp.zeros_like(pk)) for pk in p)
    chains = tuple(_chain_motion(robot, i, p, v, a, R_dot, R_ddot, lim, sign) for i in range(3))
    rows = _jx_rows(chains)
    ok, det = _flat_validity(robot, chains, rows, singular_tol)
    return chains, ok & usable & design_ok(robot), rows, det


def platform_motion(robot: Delta, theta: Float[Array, "3"], theta_dot: Float[Array, "3"],
                    theta_ddot: Float[Array, "3"], R_dot=0.0, R_ddot=0.0, *, mode: str = "lower",
                    singular_tol: float = 1e-9) -> Motion:
    """Platform position, velocity and acceleration for a joint motion (FK + the same loop derivatives).

    ``Jx pdot = b1``, ``Jx pddot = b2`` with b1_i = u_i.Bdot_i and b2_i = u_i.Bddot_i - |wdot_i|^2 / L2
    (u_i, Bdot_i in chain i's frame).
    """
    theta, theta_dot, theta_ddot = (jnp.asarray(a) for a in (theta, theta_dot, theta_ddot))
    dtype = jnp.result_type(theta.dtype, robot.upper_arm.dtype)
    R_dot = jnp.asarray(R_dot, dtype)
    R_ddot = jnp.asarray(R_ddot, dtype)
    fwd = fk(robot, theta, mode=mode)
    p = jnp.where(fwd.ok, fwd.p, jnp.asarray([0.0, 0.0, 1.0], dtype) * robot.forearm)
    w, u, d = _chain_terms(robot, p, theta)
    ok = fwd.ok & _validity(robot, u, d, singular_tol)
    Jx = from_chain_frames(u)
    Jx_safe = jnp.where(ok, Jx, jnp.eye(3, dtype=dtype))
    b_dot, b_ddot = _elbow_rates(robot, theta, theta_dot, theta_ddot, R_dot, R_ddot)
    p_dot = _solve3(Jx_safe, jnp.sum(u * b_dot, axis=-1))
    w_dot = to_chain_frames(p_dot) - b_dot
    rhs2 = jnp.sum(u * b_ddot, axis=-1) - jnp.sum(w_dot * w_dot, axis=-1) / robot.forearm
    p_ddot = _solve3(Jx_safe, rhs2)
    nan = jnp.asarray(jnp.nan, dtype)
    return Motion(p=jnp.where(ok, p, nan), p_dot=jnp.where(ok, p_dot, nan), p_ddot=jnp.where(ok, p_ddot, nan),
                  theta=theta, theta_dot=theta_dot, theta_ddot=theta_ddot, R_dot=R_dot, R_ddot=R_ddot, ok=ok)


# ---------------------------------------------------------------------------------------------------------
# Formulation 1: Lagrange equations in (p, R, theta) with multipliers
# ---------------------------------------------------------------------------------------------------------
def _lagrange(robot: Delta, m: Motion):
    mm = require_mass(robot)
    L1, g = robot.upper_arm, mm.gravity
    th, thd, thdd = m.theta, m.theta_dot, m.theta_ddot
    c, s = jnp.cos(th), jnp.sin(th)
    I_arm = mm.arm_inertia(L1)
    s_arm = mm.arm_first_moment(L1)
    M = mm.moving_mass()
    ez = jnp.asarray([0.0, 0.0, 1.0], th.dtype)
    lhs_theta = I_arm * thdd - s_arm * s * m.R_ddot - g * s_arm * c
    lhs_R = 3.0 * mm.radial_mass() * m.R_ddot - s_arm * jnp.sum(s * thdd + c * thd ** 2)
    lhs_p = M * (m.p_ddot - g * ez)
    # Constraint gradients of Gamma_i = |w_i|^2 - L2^2, w_i = rot_i(p) + (r - R - L1 cos th, 0, -L1 sin th).
    w, _, _ = _chain_terms(robot, m.p, th, c, s)               # loop vectors from the core (chain frames)
    dG_dp = 2.0 * from_chain_frames(w)                       # (3 constraints, 3 coords), base frame
    dG_dR = -2.0 * w[:, 0]                                    # (3,)
    dG_dth = 2.0 * L1 * (w[:, 0] * s - w[:, 2] * c)           # (3,) diagonal
    if mm.forearm_model == "rigid_rod":
        # T_rod = T_split - J/2 sum_i |w_i'|^2 (mass.py): d/dt dT/dqdot - dT/dq of it adds -J w_i'' . dw_i/dq.
        J = mm.forearm_rotation_deficit()
        w_dd = _loop_acceleration(robot, m, c, s)
        lhs_p = lhs_p - J * jnp.sum(from_chain_frames(w_dd), axis=0)
        lhs_theta = lhs_theta + J * L1 * (c * w_dd[:, 2] - s * w_dd[:, 0])
        lhs_R = lhs_R + J * jnp.sum(w_dd[:, 0])
    lam = _solve3(dG_dp, lhs_p, transpose=True)
    tau = lhs_theta - lam * dG_dth
    force_R = lhs_R - jnp.sum(lam * dG_dR)
    return tau, force_R


# ---------------------------------------------------------------------------------------------------------
# Formulation 2: virtual work (d'Alembert) with the Jacobian transpose
# ---------------------------------------------------------------------------------------------------------
def virtual_work_split(robot: Delta, m: Motion):
    """Virtual-work efforts split into (tau_inertial, tau_gravity, force_R_inertial, force_R_gravity).

    The inertial part holds every acceleration and velocity-product term, the gravity part the static
    efforts at the same configuration; one pass shares the Jacobians between them (used for time scaling).
    Per-point front end of the flat form (:func:`flat_efforts`).
    """
    p = tuple(m.p[k] for k in range(3))
    chains = tuple(_chain_state(robot, i, p, m.theta[i], m.theta_dot[i], m.theta_ddot[i]) for i in range(3))
    rows = _jx_rows(chains)
    det = jx_det(*rows[0], *rows[1], *rows[2])
    tau_in, tau_g, fR_in, fR_g = flat_efforts(robot, chains, rows, det, tuple(m.p_ddot[k] for k in range(3)),
                                               m.R_ddot)
    return jnp.stack(tau_in), jnp.stack(tau_g), fR_in, fR_g


def _virtual_work(robot: Delta, m: Motion):
    tau_in, tau_g, fR_in, fR_g = virtual_work_split(robot, m)
    return tau_in + tau_g, fR_in + fR_g


def inverse_dynamics_motion(robot: Delta, motion: Motion, *, method: str = "virtual_work") -> Torques:
    """Actuator efforts for a full kinematic state (see :func:`joint_motion`, :func:`platform_motion`).

    Args:
        robot: robot with a mass model, at the current base radius R.
        motion: the kinematic state.
        method: ``"virtual_work"`` (default, fastest) or ``"lagrange"``.

    Returns:
        :class:`Torques` (NaN where ``motion.ok`` is False).
    """
    if method == "virtual_work":
        tau, fR = _virtual_work(robot, motion)
    elif method == "lagrange":
        tau, fR = _lagrange(robot, motion)
    else:
        raise ValueError(f"method must be 'virtual_work' or 'lagrange' for a Motion, got {method!r}")
    nan = jnp.asarray(jnp.nan, tau.dtype)
    return Torques(tau=jnp.where(motion.ok, tau, nan), force_R=jnp.where(motion.ok, fR, nan), ok=motion.ok)


# ---------------------------------------------------------------------------------------------------------
# Formulation 3: autodiff of the reduced Lagrangian (FK-based, no hand algebra)
# ---------------------------------------------------------------------------------------------------------
def _points(robot: Delta, q):
    """Positions (base frame) as functions of q = (R, theta): arm com, elbow B_i, carriage A_i, P, forearm end C_i."""
    R, theta = q[0], q[1:]
    mm = robot.mass
    L1 = robot.upper_arm
    rob = robot.with_base_radius(R)
    c_arm = mm.upper_arm_com_fraction * L1
    zero = jnp.zeros_like(theta)
    com = from_chain_frames(jnp.stack([R + c_arm * jnp.cos(theta), zero, c_arm * jnp.sin(theta)], axis=-1))
    elbow = from_chain_frames(jnp.stack([R + L1 * jnp.cos(theta), zero, L1 * jnp.sin(theta)], axis=-1))
    carriage = from_chain_frames(jnp.stack([R + zero, zero, zero], axis=-1))
    p = fk(rob, theta).p
    ends = p[None, :] + from_chain_frames(jnp.stack([robot.platform_radius + zero, zero, zero], axis=-1))
    return com, elbow, carriage, p, ends


def _energies(robot: Delta, q, qd):
    """(T, V) of the model from body positions (FK) and their velocities (forward-mode autodiff).

    ``point_split``: point masses at the elbows and the platform. ``rigid_rod``: the elbow hardware at B_i,
    each forearm's mass at its centre of mass x_c = s B_i + (1 - s) C_i, plus I_c/2 |u x u'|^2 with
    u = (C_i - B_i) / L2 (the rods' rotation; the module docstring of :mod:`deltajax.mass`).
    """
    mm = require_mass(robot)
    L1 = robot.upper_arm
    (com, elbow, carriage, p, ends), (v_com, v_elbow, v_carr, v_p, v_ends) = jax.jvp(
        lambda qq: _points(robot, qq), (q,), (qd,))
    T = 0.5 * (mm.upper_arm_inertia_factor * mm.upper_arm_mass * L1 * L1
               + mm.gear_ratio ** 2 * mm.rotor_inertia) * jnp.sum(qd[1:] ** 2)
    if mm.forearm_model == "point_split":
        bodies = ((mm.upper_arm_mass, com, v_com), (mm.elbow_point_mass(), elbow, v_elbow),
                  (mm.carriage_mass, carriage, v_carr), (mm.moving_mass(), p, v_p))
    else:
        s = mm.forearm_elbow_fraction
        rod = s * elbow + (1.0 - s) * ends
        v_rod = s * v_elbow + (1.0 - s) * v_ends
        bodies = ((mm.upper_arm_mass, com, v_com), (mm.elbow_mass, elbow, v_elbow),
                  (mm.carriage_mass, carriage, v_carr), (mm.platform_mass + mm.payload_mass, p, v_p),
                  (mm.forearm_mass, rod, v_rod))
        u = (ends - elbow) / robot.forearm
        u_dot = (v_ends - v_elbow) / robot.forearm
        omega = jnp.cross(u, u_dot)
        T = T + 0.5 * mm.forearm_inertia(robot.forearm) * jnp.sum(omega * omega)
    V = jnp.zeros((), q.dtype)
    for mass, x, v in bodies:
        T = T + 0.5 * mass * jnp.sum(v * v)
        V = V - mass * mm.gravity * jnp.sum(x[..., 2])
    return T, V


def _autodiff(robot: Delta, theta, theta_dot, theta_ddot, R_dot, R_ddot):
    dtype = theta.dtype
    q = jnp.concatenate([jnp.reshape(robot.base_radius, (1,)).astype(dtype), theta])
    qd = jnp.concatenate([jnp.reshape(R_dot, (1,)).astype(dtype), theta_dot])
    qdd = jnp.concatenate([jnp.reshape(R_ddot, (1,)).astype(dtype), theta_ddot])

    def lagrangian(q_, qd_):
        T, V = _energies(robot, q_, qd_)
        return T - V

    dL_dqd = jax.grad(lagrangian, argnums=1)
    # d/dt dL/dqd = (d2L/dqd2) qdd + (d2L/dqd dq) qd
    _, ddt = jax.jvp(lambda a, b: dL_dqd(a, b), (q, qd), (qd, qdd))
    Q = ddt - jax.grad(lagrangian, argnums=0)(q, qd)
    return Q[1:], Q[0]


def inverse_dynamics(robot: Delta, theta: Float[Array, "3"], theta_dot: Float[Array, "3"],
                     theta_ddot: Float[Array, "3"], R_dot=0.0, R_ddot=0.0, *, method: str = "virtual_work",
                     mode: str = "lower") -> Torques:
    """Inverse dynamics tau(theta, thetadot, thetaddot) (+ the R force when R moves), one configuration.

    Args:
        robot: robot with a mass model (``robot.mass``), at the current base radius R (``recon.at(R)``).
        theta, theta_dot, theta_ddot: actuated angles (rad), rates (rad/s), accelerations (rad/s^2).
        R_dot, R_ddot: reconfiguration rate (m/s) and acceleration (m/s^2); 0 for a fixed Delta.
        method: ``"virtual_work"``, ``"lagrange"`` or ``"autodiff"`` (see the module docstring).
        mode: FK assembly mode for the platform position.

    Returns:
        :class:`Torques`.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    motion = platform_motion(robot, theta, theta_dot, theta_ddot, R_dot, R_ddot, mode=mode)
    if method != "autodiff":
        return inverse_dynamics_motion(robot, motion, method=method)
    require_mass(robot)
    th = motion.theta
    tau, fR = _autodiff(robot, th, motion.theta_dot, motion.theta_ddot, motion.R_dot, motion.R_ddot)
    nan = jnp.asarray(jnp.nan, tau.dtype)
    return Torques(tau=jnp.where(motion.ok, tau, nan), force_R=jnp.where(motion.ok, fR, nan), ok=motion.ok)


def gravity_torques(robot: Delta, p: Float[Array, "3"], theta: Float[Array, "3"]) -> Torques:
    """Static holding efforts at rest (platform at ``p``, arms at ``theta``)."""
    z3 = jnp.zeros_like(jnp.asarray(theta))
    zp = jnp.zeros_like(jnp.asarray(p))
    w, u, d = _chain_terms(robot, p, theta)
    ok = jnp.all(jnp.isfinite(theta)) & _validity(robot, u, d, 1e-9)
    zero = jnp.zeros((), z3.dtype)
    motion = Motion(p=p, p_dot=zp, p_ddot=zp, theta=theta, theta_dot=z3, theta_ddot=z3, R_dot=zero,
                    R_ddot=zero, ok=ok)
    return inverse_dynamics_motion(robot, motion)


def energy(robot: Delta, motion: Motion) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """(kinetic, potential) energy (J) of the lumped model for a kinematic state (closed form).

    Potential energy is -sum m g z (z down) with the base plane z = 0 as reference.
    """
    mm = require_mass(robot)
    L1 = robot.upper_arm
    s, thd = jnp.sin(motion.theta), motion.theta_dot
    s_arm = mm.arm_first_moment(L1)
    M = mm.moving_mass()
    T = (jnp.sum(0.5 * mm.radial_mass() * motion.R_dot ** 2 - s_arm * s * motion.R_dot * thd
                 + 0.5 * mm.arm_inertia(L1) * thd ** 2) + 0.5 * M * jnp.sum(motion.p_dot ** 2))
    if mm.forearm_model == "rigid_rod":
        zero = jnp.zeros_like(motion.R_dot)
        b_dot, _ = _elbow_rates(robot, motion.theta, thd, jnp.zeros_like(thd), motion.R_dot, zero)
        w_dot = to_chain_frames(motion.p_dot) - b_dot
        T = T - 0.5 * mm.forearm_rotation_deficit() * jnp.sum(w_dot * w_dot)
    V = -mm.gravity * (s_arm * jnp.sum(s) + M * motion.p[2])
    return T, V


def energy_from_joints(robot: Delta, theta, theta_dot, R_dot=0.0) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """(kinetic, potential) energy (J) from joint values only, via FK and autodiff of the body positions."""
    theta = jnp.asarray(theta)
    dtype = jnp.result_type(theta.dtype, robot.upper_arm.dtype)
    q = jnp.concatenate([jnp.reshape(robot.base_radius, (1,)).astype(dtype), theta.astype(dtype)])
    qd = jnp.concatenate([jnp.reshape(jnp.asarray(R_dot, dtype), (1,)), jnp.asarray(theta_dot, dtype)])
    return _energies(robot, q, qd)
