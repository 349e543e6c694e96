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
from jaxtyping import Array, Float

from .geometry import Delta
from .kinematics import _from_chain_frames, forearm_units

__all__ = ["Jacobians", "jacobians", "jacobian", "homogenise", "jq_diagonal"]


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
    return robot.upper_arm * (u_local[:, 2] * jnp.cos(theta) - u_local[:, 0] * jnp.sin(theta))


def jacobians(robot: Delta, p: Float[Array, "3"], theta: Float[Array, "3"]) -> Jacobians:
    """Jx and Jq at platform position ``p`` (m, base frame) and actuated angles ``theta`` (rad)."""
    u_local = forearm_units(robot, p, theta)
    Jx = _from_chain_frames(u_local)
    diag = jq_diagonal(robot, u_local, theta)
    Jq = jnp.concatenate([u_local[:, :1], jnp.diag(diag)], axis=1)
    return Jacobians(Jx=Jx, Jq=Jq)


def jacobian(robot: Delta, p: Float[Array, "3"], theta: Float[Array, "3"]) -> Float[Array, "3 4"]:
    """The full Jacobian J = Jx^-1 Jq mapping (Rdot [m/s], thetadot [rad/s]) to pdot [m/s] (base frame).

    ``J[:, 0]`` is dP/dR (dimensionless) and ``J[:, 1:]`` the classic fixed-R Jacobian (m/rad).
    """
    jac = jacobians(robot, p, theta)
    return jnp.linalg.solve(jac.Jx, jac.Jq)


def homogenise(J: Float[Array, "3 4"], length: Float[Array, ""] | float) -> Float[Array, "3 4"]:
    """Homogenised Jacobian: the theta-columns (units of length) divided by ``length`` (paper §3, L1)."""
    scale = jnp.concatenate([jnp.ones((1,), J.dtype), jnp.full((J.shape[1] - 1,), 1.0, J.dtype) / length])
    return J * scale[None, :]


def _resolve_length(robot: Delta, length: Optional[float]):
    return robot.upper_arm if length is None else jnp.asarray(length, robot.upper_arm.dtype)
