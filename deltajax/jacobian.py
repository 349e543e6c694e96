"""Jacobians of the (reconfigurable) Delta robot, single point.

``Jx xdot = Jq qdot`` with q = (R, theta_1, theta_2, theta_3) (paper §2.1):

* Jx row i is the unit forearm vector u_i in the base frame;
* Jq = [u_x,i in chain i's local frame | diag(L1 sin th_i2 sin th_i3)] (the first column is d/dR);
* J = Jx^-1 Jq maps (Rdot, thetadot) to the platform velocity (3 x 4); J[:, 1:] is the classic Jacobian.

Derivation of the rows: differentiate |C_i - B_i|^2 = L2^2 in chain i's frame, where C_i - B_i =
(p_x + r - R - L1 cos th, p_y, p_z - L1 sin th): u . pdot = u_x Rdot + L1 (u_z cos th - u_x sin th) thdot, and
u_z cos th - u_x sin th = sin th3 sin(th1 + th2 - th1) = sin th2 sin th3.
"""

from __future__ import annotations

from typing import NamedTuple, Optional

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from .geometry import Delta
from .kinematics import (COS_A, SIN_A, LimitTerms, LoopClosure, chain_local, from_chain_frames, forearm_units,
                         guarded_configuration, loop_closure, loop_vectors)

__all__ = ["Jacobians", "jacobians", "jacobian", "homogenise", "jq_diagonal", "jx_row", "jq_theta", "jx_det", "Chain",
           "chain", "JacobianBlocks", "jacobian_blocks"]


def jx_row(ux, uy, uz, i: int):
    """Row i of Jx: chain i's unit forearm vector rotated from its local frame to the base frame (scalars).

    ``i`` is the static chain number (alpha_i = 2 pi i / 3).
    """
    if i == 0:
        return ux, uy, uz
    ca, sa = COS_A[i], SIN_A[i]
    return ca * ux - sa * uy, sa * ux + ca * uy, uz


def jq_theta(ux, uz, c, s):
    """Homogenised theta-diagonal of Jq for one chain: sin th2 sin th3 = uz cos th - ux sin th (dimensionless).

    ``L1 * jq_theta`` is the Jq diagonal entry (m/rad); divide by a homogenising length L instead of L1 for
    ``length != L1`` (times L1 / L). u in the chain's local frame (:func:`deltajax.kinematics.loop_vectors`).
    The R column of Jq is ``ux`` itself.
    """
    return uz * c - ux * s


def jx_det(j00, j01, j02, j10, j11, j12, j20, j21, j22):
    """Signed determinant of Jx given row-major as 9 scalars (explicit cofactor expansion, no LU).

    ``det Jx == 0`` exactly is the rule redundancy resolution uses to skip a sample (docs/CONVENTIONS.md).
    """
    return (j00 * (j11 * j22 - j12 * j21)
            - j01 * (j10 * j22 - j12 * j20)
            + j02 * (j10 * j21 - j11 * j20))


class Chain(NamedTuple):
    """One chain of the per-point kernel (scalars; see :func:`chain`).

    Attributes:
        loop: the chain's :class:`~deltajax.kinematics.LoopClosure` (``loop.ok``: closes within the joint limits).
        jx: row i of Jx (3 scalars, base frame, dimensionless); meaningful where ``loop.reach``.
        d: homogenised Jq entry sin th2 sin th3 (:func:`jq_theta`, dimensionless); meaningful where ``loop.reach``.
    """

    loop: LoopClosure
    jx: tuple
    d: Float[Array, ""]


def chain(x, y, z, R, r, L1, L2, lim: LimitTerms, i: int, sign: float = 1.0) -> Chain:
    """Chain ``i`` of the per-point kernel at the base-frame point (x, y, z) (m): chain_local -> loop_closure
    (dx = (x_i + r) - R) -> loop_vectors -> jx_row, jq_theta.

    The step :func:`deltajax.indices.point_kernel` runs per chain, named so that the Numba mirror's ``chain``
    has a definition to agree with. Inputs finite and bounded (the caller guards the point with
    :func:`deltajax.kinematics.safe_point`; a NaN point gives ``ok=False`` and NaN rows).
    """
    px, py, pz = chain_local(x, y, z, i)
    dx = px + r - R  # (x + r) - R, as every kernel evaluates it
    lc = loop_closure(dx, py, pz, L1, L2, lim, sign)
    ux, uy, uz = loop_vectors(dx, py, pz, lc.cos, lc.sin, L1, L2)
    return Chain(loop=lc, jx=jx_row(ux, uy, uz, i), d=jq_theta(ux, uz, lc.cos, lc.sin))


class JacobianBlocks(NamedTuple):
    """The kernel's Jacobian blocks at one point (scalars; see :func:`jacobian_blocks`).

    Attributes:
        ok: all three loops close within the joint limits.
        det_jx: signed det Jx (:func:`jx_det`; 0 exactly: redundancy resolution skips the sample).
        jx: the 9 entries of Jx, row-major (row i = unit forearm vector of chain i, base frame).
        d: the 3 homogenised Jq entries (:func:`jq_theta`).
        chains: the three :class:`~deltajax.kinematics.LoopClosure`.
    """

    ok: Bool[Array, ""]
    det_jx: Float[Array, ""]
    jx: tuple
    d: tuple
    chains: tuple


def jacobian_blocks(x, y, z, R, r, L1, L2, lim: LimitTerms, sign: float = 1.0) -> JacobianBlocks:
    """Jx, the homogenised Jq diagonal and det Jx at the base-frame point (x, y, z) (m) from the three
    :func:`chain` s, unguarded (values meaningful where ``ok``): the point-to-blocks half of
    :func:`deltajax.indices.point_kernel`, which guards the point first and masks the blocks before the
    singular values."""
    chains = [chain(x, y, z, R, r, L1, L2, lim, i, sign) for i in range(3)]
    jx = chains[0].jx + chains[1].jx + chains[2].jx
    return JacobianBlocks(ok=chains[0].loop.ok & chains[1].loop.ok & chains[2].loop.ok, det_jx=jx_det(*jx), jx=jx,
                          d=tuple(c.d for c in chains), chains=tuple(c.loop for c in chains))


class Jacobians(NamedTuple):
    """The two Jacobians of ``Jx xdot = Jq qdot``.

    Attributes:
        Jx: (3, 3), row i = unit forearm vector u_i (base frame), dimensionless.
        Jq: (3, 4), column 0 = d/dR (dimensionless), columns 1..3 = diag(L1 sin th_i2 sin th_i3) (m/rad).
    """

    Jx: Float[Array, "3 3"]
    Jq: Float[Array, "3 4"]


def jq_diagonal(robot: Delta, u_local: Float[Array, "3 3"], theta: Float[Array, "3"]) -> Float[Array, "3"]:
    """Diagonal of the theta-block of Jq, L1 sin th_i2 sin th_i3 = L1 (u_z cos th - u_x sin th) (m/rad)."""
    return robot.upper_arm * jq_theta(u_local[:, 0], u_local[:, 2], jnp.cos(theta), jnp.sin(theta))


def jacobians(robot: Delta, p: Float[Array, "3"], theta: Float[Array, "3"]) -> Jacobians:
    """Jx and Jq at platform position ``p`` (m, base frame) and actuated angles ``theta`` (rad); NaN where the
    (traced) design is invalid or p or theta is not finite (:func:`deltajax.kinematics.guarded_configuration`)."""
    robot, p, theta, ok = guarded_configuration(robot, p, theta)
    u_local = forearm_units(robot, p, theta)
    Jx = from_chain_frames(u_local)
    diag = jq_diagonal(robot, u_local, theta)
    Jq = jnp.concatenate([u_local[:, :1], jnp.diag(diag)], axis=1)
    return Jacobians(Jx=jnp.where(ok, Jx, jnp.nan), Jq=jnp.where(ok, Jq, jnp.nan))


def jacobian(robot: Delta, p: Float[Array, "3"], theta: Float[Array, "3"]) -> Float[Array, "3 4"]:
    """The full Jacobian J = Jx^-1 Jq mapping (Rdot [m/s], thetadot [rad/s]) to pdot [m/s] (base frame).

    ``J[:, 0]`` is dP/dR (dimensionless) and ``J[:, 1:]`` the classic fixed-R Jacobian (m/rad). NaN where the
    (traced) design is invalid or p or theta is not finite; LAPACK only ever sees the finite stand-in.
    """
    robot, p, theta, ok = guarded_configuration(robot, p, theta)
    jac = jacobians(robot, p, theta)
    return jnp.where(ok, jnp.linalg.solve(jac.Jx, jac.Jq), jnp.nan)


def homogenise(J: Float[Array, "3 4"], length: Float[Array, ""] | float) -> Float[Array, "3 4"]:
    """Homogenised Jacobian: the theta-columns (units of length) divided by ``length`` (paper §3, L1)."""
    scale = jnp.concatenate([jnp.ones((1,), J.dtype), jnp.full((J.shape[1] - 1,), 1.0, J.dtype) / length])
    return J * scale[None, :]


def resolve_length(robot: Delta, length: Optional[float]):
    return robot.upper_arm if length is None else jnp.asarray(length, robot.upper_arm.dtype)
