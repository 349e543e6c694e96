"""Inverse and forward kinematics of the Delta robot, single point (vmap for batches).

Frame and conventions: SPEC §1 (z down, chain i at alpha_i = 2 pi i / 3, theta positive downward, elbow
B_i = (R + L1 cos theta, 0, L1 sin theta) in chain i's local frame). Failure is data: every result carries an
``ok`` mask and a reason code; nothing here raises on a bad point.

The IK is *algebraic*: cos(theta) and sin(theta) come straight from the loop-closure equation
``dx cos(theta) + pz sin(theta) = K / (2 L1)``; the only inverse trig function is the final ``atan2`` that
reports theta itself. Hot loops (workspace grids) use :func:`ik_cos_sin`, which skips it.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .geometry import CHAIN_ANGLES, Delta

__all__ = [
    "IKResult",
    "FKResult",
    "IKCosSin",
    "ik",
    "ik_cos_sin",
    "fk",
    "passive_angles",
    "elbows",
    "forearm_units",
    "to_chain_frames",
    "IK_OK",
    "IK_UNREACHABLE",
    "IK_JOINT_LIMIT",
    "IK_NONFINITE",
    "FK_OK",
    "FK_NO_INTERSECTION",
    "FK_DEGENERATE_CENTRES",
    "FK_NONFINITE",
    "FK_TANGENT",
]

# Reason codes (per chain for IK, per pose for FK). 0 always means fine.
IK_OK, IK_UNREACHABLE, IK_JOINT_LIMIT, IK_NONFINITE = 0, 1, 2, 3
FK_OK, FK_NO_INTERSECTION, FK_DEGENERATE_CENTRES, FK_NONFINITE, FK_TANGENT = 0, 1, 2, 3, 4

_COS_A = tuple(math.cos(a) for a in CHAIN_ANGLES)
_SIN_A = tuple(math.sin(a) for a in CHAIN_ANGLES)


def _rot_cols(dtype) -> tuple[jax.Array, jax.Array]:
    return jnp.asarray(_COS_A, dtype=dtype), jnp.asarray(_SIN_A, dtype=dtype)


def to_chain_frames(p: Float[Array, "3"]) -> Float[Array, "3 3"]:
    """Express base-frame point ``p`` in each chain's local frame; row i is chain i (m)."""
    ca, sa = _rot_cols(p.dtype)
    px = ca * p[0] + sa * p[1]
    py = -sa * p[0] + ca * p[1]
    pz = jnp.broadcast_to(p[2], (3,))
    return jnp.stack([px, py, pz], axis=-1)


def _from_chain_frames(v_local: Float[Array, "3 3"]) -> Float[Array, "3 3"]:
    """Rotate row i (a vector in chain i's local frame) back to the base frame."""
    ca, sa = _rot_cols(v_local.dtype)
    x = ca * v_local[:, 0] - sa * v_local[:, 1]
    y = sa * v_local[:, 0] + ca * v_local[:, 1]
    return jnp.stack([x, y, v_local[:, 2]], axis=-1)


class IKCosSin(NamedTuple):
    """Algebraic IK output (no inverse trig). All arrays have one entry per chain.

    Attributes:
        cos: cos(theta_i).
        sin: sin(theta_i).
        ok: the chain can close the loop and theta_i is within the joint limits.
        reason: IK_* code per chain.
    """

    cos: Float[Array, "3"]
    sin: Float[Array, "3"]
    ok: Bool[Array, "3"]
    reason: Int[Array, "3"]


class IKResult(NamedTuple):
    """Inverse kinematics of one point.

    Attributes:
        theta: actuated angles (rad), wrapped to (-pi, pi]; NaN where the chain failed.
        ok: all three chains solved within limits.
        reason: IK_* code per chain (0 ok, 1 unreachable, 2 joint limit, 3 non-finite input).
    """

    theta: Float[Array, "3"]
    ok: Bool[Array, ""]
    reason: Int[Array, "3"]


def _within_limits(c, s, lo, hi):
    """Is theta (given by cos, sin) inside the inclusive interval [lo, hi] (mod 2 pi)?

    theta is in [lo, hi] iff cos(theta - mid) >= cos(half) with mid, half the interval's centre and half
    width (< pi by validation). Unlimited joints (infinite bounds) always pass.
    """
    finite = jnp.isfinite(lo) & jnp.isfinite(hi)
    mid = jnp.where(finite, 0.5 * (lo + hi), 0.0)
    half = jnp.where(finite, 0.5 * (hi - lo), 0.0)
    inside = c * jnp.cos(mid) + s * jnp.sin(mid) >= jnp.cos(half)
    return inside | ~finite


def ik_cos_sin(robot: Delta, p: Float[Array, "3"], *, branch: str = "outer") -> IKCosSin:
    """Algebraic inverse kinematics: cos and sin of the actuated angles, no inverse trig.

    Args:
        robot: the robot (its ``base_radius`` is the R used).
        p: platform centre P in the base frame (m, z down).
        branch: ``"outer"`` (default, theta = atan2(pz, dx) - acos(K / (2 L1 rho)), elbow out) or
            ``"inner"`` (the other root).

    Returns:
        :class:`IKCosSin` with per-chain cos, sin, ok and reason.
    """
    if branch not in ("outer", "inner"):
        raise ValueError(f"branch must be 'outer' or 'inner', got {branch!r}")
    p = jnp.asarray(p)
    dtype = jnp.result_type(p.dtype, robot.upper_arm.dtype)
    p = p.astype(dtype)
    finite_p = jnp.all(jnp.isfinite(p))
    p_safe = jnp.where(finite_p, p, jnp.zeros_like(p))
    loc = to_chain_frames(p_safe)
    L1, L2 = robot.upper_arm, robot.forearm
    dx = loc[:, 0] + robot.platform_radius - robot.base_radius
    py, pz = loc[:, 1], loc[:, 2]
    rho2 = dx * dx + pz * pz
    m = (rho2 + py * py + L1 * L1 - L2 * L2) / (2.0 * L1)  # = K / (2 L1)
    disc = rho2 - m * m  # rho^2 sin^2(acos(m / rho)) >= 0 when reachable
    reach = (disc >= 0.0) & (rho2 > 0.0)
    w = jnp.sqrt(jnp.where(reach, disc, 1.0))
    sign = 1.0 if branch == "outer" else -1.0
    inv_rho2 = 1.0 / jnp.where(reach, rho2, 1.0)
    # theta = phi -/+ psi with cos(phi) = dx/rho, sin(phi) = pz/rho, cos(psi) = m/rho, sin(psi) = w/rho.
    c = (dx * m + sign * pz * w) * inv_rho2
    s = (pz * m - sign * dx * w) * inv_rho2
    limits = _within_limits(c, s, robot.theta_min, robot.theta_max)
    ok = reach & limits & finite_p
    reason = jnp.where(
        ~finite_p, IK_NONFINITE, jnp.where(~reach, IK_UNREACHABLE, jnp.where(~limits, IK_JOINT_LIMIT, IK_OK))
    ).astype(jnp.int32)
    nan = jnp.asarray(jnp.nan, dtype)
    return IKCosSin(cos=jnp.where(reach & finite_p, c, nan), sin=jnp.where(reach & finite_p, s, nan),
                    ok=ok, reason=reason)


def ik(robot: Delta, p: Float[Array, "3"], *, branch: str = "outer") -> IKResult:
    """Inverse kinematics of one point.

    Args:
        robot: the robot (a reconfigurable one is frozen first: ``ik(recon.at(R), p)``).
        p: platform centre P in the base frame (m, z down).
        branch: ``"outer"`` (default) or ``"inner"`` elbow branch, see :func:`ik_cos_sin`.

    Returns:
        :class:`IKResult`; ``theta`` is NaN for chains that failed.
    """
    cs = ik_cos_sin(robot, p, branch=branch)
    theta = jnp.arctan2(cs.sin, cs.cos)
    theta = jnp.where(theta <= -jnp.pi, theta + 2.0 * jnp.pi, theta)  # wrap to (-pi, pi]
    theta = jnp.where(cs.ok, theta, jnp.nan)
    return IKResult(theta=theta, ok=jnp.all(cs.ok), reason=cs.reason)


def elbows(robot: Delta, theta: Float[Array, "3"]) -> Float[Array, "3 3"]:
    """Elbow points B_i in the base frame (m); row i is chain i."""
    theta = jnp.asarray(theta)
    L1 = robot.upper_arm
    local = jnp.stack([robot.base_radius + L1 * jnp.cos(theta), jnp.zeros_like(theta), L1 * jnp.sin(theta)],
                      axis=-1)
    return _from_chain_frames(local)


class FKResult(NamedTuple):
    """Forward kinematics of one configuration.

    Attributes:
        p: platform centre in the base frame (m); NaN when not ok.
        ok: the three forearm spheres intersect (non-degenerate).
        reason: FK_* code (0 ok, 1 no intersection, 2 degenerate/collinear centres, 3 non-finite input,
            4 tangent spheres: the pose exists but sits on a singularity; ``ok`` stays True).
    """

    p: Float[Array, "3"]
    ok: Bool[Array, ""]
    reason: Int[Array, ""]


def fk(robot: Delta, theta: Float[Array, "3"], *, mode: str = "lower", tangent_tol: float = 1e-10) -> FKResult:
    """Forward kinematics by intersecting the three forearm spheres.

    Sphere i has centre B_i - r e_i (the elbow shifted by the platform radius along the chain's axis) and
    radius L2. Of the two intersections, ``mode="lower"`` (default) returns the one with the larger z (the
    platform below the elbows, z down), ``mode="upper"`` the other.

    Args:
        robot: the robot.
        theta: actuated angles (rad).
        mode: assembly mode, ``"lower"`` or ``"upper"``.
        tangent_tol: relative tolerance (of L2^2) on the squared half-chord h^2: |h^2| below it is reported
            as tangent (a Jx singularity; the pose is returned, ``ok`` True), h^2 below -tol as no intersection.

    Returns:
        :class:`FKResult`.
    """
    if mode not in ("lower", "upper"):
        raise ValueError(f"mode must be 'lower' or 'upper', got {mode!r}")
    theta = jnp.asarray(theta)
    dtype = jnp.result_type(theta.dtype, robot.upper_arm.dtype)
    theta = theta.astype(dtype)
    finite = jnp.all(jnp.isfinite(theta))
    theta_safe = jnp.where(finite, theta, jnp.zeros_like(theta))
    L1, L2 = robot.upper_arm, robot.forearm
    local = jnp.stack([robot.R_minus_r + L1 * jnp.cos(theta_safe), jnp.zeros_like(theta_safe),
                       L1 * jnp.sin(theta_safe)], axis=-1)
    c = _from_chain_frames(local)
    # Trilateration in the frame (ex, ey, ez) spanned by the centres.
    d21 = c[1] - c[0]
    d31 = c[2] - c[0]
    d = jnp.linalg.norm(d21)
    ok_d = d > 1e-12 * L2
    ex = d21 / jnp.where(ok_d, d, 1.0)
    i_ = jnp.dot(ex, d31)
    ey_raw = d31 - i_ * ex
    j_ = jnp.linalg.norm(ey_raw)
    ok_j = j_ > 1e-12 * L2
    ey = ey_raw / jnp.where(ok_j, j_, 1.0)
    ez = jnp.cross(ex, ey)
    x = 0.5 * d  # equal radii
    y = (i_ * i_ + j_ * j_ - 2.0 * i_ * x) / (2.0 * jnp.where(ok_j, j_, 1.0))
    h2 = L2 * L2 - x * x - y * y
    nondegenerate = ok_d & ok_j
    meet = h2 >= -tangent_tol * L2 * L2  # rounding can push an exactly tangent pose slightly negative
    h = jnp.sqrt(jnp.where(h2 > 0.0, h2, 0.0))
    base = c[0] + x * ex + y * ey
    sol_a = base + h * ez
    sol_b = base - h * ez
    a_lower = sol_a[2] >= sol_b[2]
    lower = jnp.where(a_lower, sol_a, sol_b)
    upper = jnp.where(a_lower, sol_b, sol_a)
    p = lower if mode == "lower" else upper
    ok = finite & nondegenerate & meet
    tangent = ok & (jnp.abs(h2) <= tangent_tol * L2 * L2)
    reason = jnp.where(~finite, FK_NONFINITE,
                       jnp.where(~nondegenerate, FK_DEGENERATE_CENTRES,
                                 jnp.where(~meet, FK_NO_INTERSECTION, jnp.where(tangent, FK_TANGENT, FK_OK))))
    return FKResult(p=jnp.where(ok, p, jnp.nan), ok=ok, reason=reason.astype(jnp.int32))


def forearm_units(robot: Delta, p: Float[Array, "3"], theta: Float[Array, "3"]) -> Float[Array, "3 3"]:
    """Unit forearm vectors u_i = (C_i - B_i) / L2 in each chain's *local* frame; row i is chain i.

    In the local frame u = (sin th3 cos(th1 + th2), cos th3, sin th3 sin(th1 + th2)) (paper §2.1).
    """
    p = jnp.asarray(p)
    loc = to_chain_frames(p)
    theta = jnp.asarray(theta)
    L1 = robot.upper_arm
    bx = robot.base_radius + L1 * jnp.cos(theta)
    bz = L1 * jnp.sin(theta)
    v = jnp.stack([loc[:, 0] + robot.platform_radius - bx, loc[:, 1], loc[:, 2] - bz], axis=-1)
    return v / robot.forearm


def passive_angles(robot: Delta, p: Float[Array, "3"], theta: Float[Array, "3"]
                   ) -> tuple[Float[Array, "3"], Float[Array, "3"]]:
    """Passive joint angles (theta_i2, theta_i3) of the paper (rad).

    theta_i2 = 0: upper arm and forearm stretched in line; pi: folded. theta_i3 = pi/2: forearm in the
    chain's vertical plane. theta_i2 is wrapped to (-pi, pi].

    Args:
        robot: the robot.
        p: platform centre (m, base frame).
        theta: actuated angles (rad), e.g. from :func:`ik`.

    Returns:
        (theta2, theta3), each of shape (3,).
    """
    u = forearm_units(robot, p, theta)
    uy = jnp.clip(u[:, 1], -1.0, 1.0)
    theta3 = jnp.arccos(uy)
    theta12 = jnp.arctan2(u[:, 2], u[:, 0])
    theta2 = theta12 - jnp.asarray(theta)
    theta2 = jnp.mod(theta2 + jnp.pi, 2.0 * jnp.pi) - jnp.pi
    theta2 = jnp.where(theta2 <= -jnp.pi, theta2 + 2.0 * jnp.pi, theta2)
    return theta2, theta3
