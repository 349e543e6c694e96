"""Inverse and forward kinematics of the Delta robot, single point (vmap for batches).

Frame and conventions: docs/CONVENTIONS.md (z down, chain i at alpha_i = 2 pi i / 3, theta positive downward, elbow
B_i = (R + L1 cos theta, 0, L1 sin theta) in chain i's local frame). Failure is data: every result carries an
``ok`` mask and a reason code; nothing here raises on a bad point.

The IK is *algebraic*: cos(theta) and sin(theta) come straight from the loop-closure equation
``dx cos(theta) + pz sin(theta) = K / (2 L1)``; the only inverse trig function is the final ``atan2`` that
reports theta itself. Hot loops (workspace grids) use :func:`ik_cos_sin`, which skips it.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .fastmath import recip, sqrt0
from .geometry import CHAIN_ANGLES, FULL_TURN_MAX, FULL_TURN_MIN, Delta

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
    "IK_INVALID_DESIGN",
    "FK_JOINT_LIMIT",
    "FK_INVALID_DESIGN",
    "LimitTerms",
    "limit_terms",
    "design_ok",
    "guarded_configuration",
    "harmless_design",
    "chain_local",
    "LoopClosure",
    "loop_closure",
    "loop_vectors",
    "safe_point",
    "FK_OK",
    "FK_NO_INTERSECTION",
    "FK_DEGENERATE_CENTRES",
    "FK_NONFINITE",
    "FK_TANGENT",
]

# Reason codes (per chain for IK, per pose for FK). 0 always means fine.
IK_OK, IK_UNREACHABLE, IK_JOINT_LIMIT, IK_NONFINITE, IK_INVALID_DESIGN = 0, 1, 2, 3, 4
FK_OK, FK_NO_INTERSECTION, FK_DEGENERATE_CENTRES, FK_NONFINITE, FK_TANGENT, FK_JOINT_LIMIT, FK_INVALID_DESIGN = (
    0, 1, 2, 3, 4, 5, 6)

COS_A = tuple(math.cos(a) for a in CHAIN_ANGLES)
SIN_A = tuple(math.sin(a) for a in CHAIN_ANGLES)


def _rot_cols(dtype) -> tuple[jax.Array, jax.Array]:
    return jnp.asarray(COS_A, dtype=dtype), jnp.asarray(SIN_A, dtype=dtype)


def to_chain_frames(p: Float[Array, "3"]) -> Float[Array, "3 3"]:
    """Express base-frame point ``p`` in each chain's local frame; row i is chain i (m)."""
    ca, sa = _rot_cols(p.dtype)
    px = ca * p[0] + sa * p[1]
    py = -sa * p[0] + ca * p[1]
    pz = jnp.broadcast_to(p[2], (3,))
    return jnp.stack([px, py, pz], axis=-1)


def from_chain_frames(v_local: Float[Array, "3 3"]) -> Float[Array, "3 3"]:
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


class LimitTerms(NamedTuple):
    """Joint-limit interval [lo, hi] in the form the kernel tests it (robot-level scalars).

    theta is inside [lo, hi] (mod 2 pi) iff cos(theta - mid) >= cos(half), i.e.
    ``c * cos_mid + s * sin_mid - cos_half >= 0`` with c, s = cos, sin theta.

    Attributes:
        cos_mid, sin_mid: cos/sin of the interval centre mid = (lo + hi) / 2 (0 when unlimited).
        cos_half: cos of the half width (hi - lo) / 2 (-2 when unlimited: every theta passes).
    """

    cos_mid: Float[Array, ""]
    sin_mid: Float[Array, ""]
    cos_half: Float[Array, ""]


def limit_terms(theta_min, theta_max) -> LimitTerms:
    """:class:`LimitTerms` of the inclusive joint range [theta_min, theta_max] (rad); an infinite bound or a
    full turn ([-pi, pi]) means no limit (the margin then is c cos 0 + 2 >= 1)."""
    lo, hi = jnp.asarray(theta_min), jnp.asarray(theta_max)
    limited = jnp.isfinite(lo) & jnp.isfinite(hi) & (hi - lo < FULL_TURN_MIN)
    mid = jnp.where(limited, 0.5 * (lo + hi), 0.0)
    half = jnp.where(limited, 0.5 * (hi - lo), 0.0)
    return LimitTerms(cos_mid=jnp.cos(mid), sin_mid=jnp.sin(mid),
                      cos_half=jnp.where(limited, jnp.cos(half), -2.0))


def design_ok(robot: Delta) -> Bool[Array, ""]:
    """Whether the (possibly traced) design is valid: R > 0, r >= 0, L1 > 0, L2 > 0, all finite, joint limits
    not NaN with theta_min < theta_max and a finite range of at most one turn (or an infinite bound: unlimited).

    The traced twin of :meth:`Delta.__check_init__` (which raises for concrete input): inside a vmapped
    population an invalid design gets ``ok=False`` everywhere instead of numbers.
    """
    R, r, L1, L2 = robot.base_radius, robot.platform_radius, robot.upper_arm, robot.forearm
    lo, hi = robot.theta_min, robot.theta_max
    lengths = (R > 0) & (r >= 0) & (L1 > 0) & (L2 > 0) & jnp.isfinite(R + r + L1 + L2)
    finite_range = jnp.isfinite(lo) & jnp.isfinite(hi)
    limits = (lo < hi) & ~(finite_range & (hi - lo > FULL_TURN_MAX))  # NaN compares False; a full turn is fine
    return lengths & limits


def guarded_configuration(robot: Delta, p, theta):
    """(robot, p, theta, ok) with ``ok`` = :func:`design_ok` and finite p and theta; where not ok all three are
    replaced by a harmless configuration before any algebra (double where: finite values and gradients).

    The one guard of every public function of a configuration (indices, Jacobians, passive joints,
    interference): callers compute on the returned stand-ins and put NaN (``ok=False``) where ``ok`` is False
    with ``jnp.where`` -- never through ``jnp.minimum``/``maximum``, which XLA:CPU's vectorised loops do not
    NaN-propagate at every batch size.
    """
    theta, p = jnp.asarray(theta), jnp.asarray(p)
    dtype = jnp.result_type(p.dtype, theta.dtype, robot.upper_arm.dtype)
    ok = design_ok(robot) & jnp.all(jnp.isfinite(p)) & jnp.all(jnp.isfinite(theta))
    theta = jnp.where(ok, theta, jnp.asarray([0.3, 0.5, 0.7], dtype)).astype(dtype)
    p = jnp.where(ok, p, jnp.asarray([0.01, 0.02, 0.3], dtype)).astype(dtype)
    return harmless_design(robot, ok), p, theta, ok


def harmless_design(robot: Delta, ok) -> Delta:
    """``robot`` where ``ok``, else a valid stand-in design (double where for traced invalid designs)."""
    f = lambda v, good: jnp.where(ok, v, jnp.asarray(good, v.dtype))  # noqa: E731
    return eqx.tree_at(lambda r: (r.base_radius, r.platform_radius, r.upper_arm, r.forearm, r.theta_min,
                                  r.theta_max), robot,
                       (f(robot.base_radius, 0.2), f(robot.platform_radius, 0.05), f(robot.upper_arm, 0.2),
                        f(robot.forearm, 0.4), f(robot.theta_min, -1.0), f(robot.theta_max, 2.0)))


def chain_local(px, py, pz, i: int):
    """Base-frame point (px, py, pz) (m) in chain ``i``'s local frame (x along the chain's axis); scalars.

    ``i`` is a static chain number 0, 1, 2 (alpha_i = 2 pi i / 3).
    """
    ca, sa = COS_A[i], SIN_A[i]
    if i == 0:
        return px, py, pz
    return ca * px + sa * py, ca * py - sa * px, pz


class LoopClosure(NamedTuple):
    """One chain's loop closure at one point (scalars; see :func:`loop_closure`).

    Attributes:
        cos, sin: cos/sin of the actuated angle theta_i where ``reach``; finite stand-ins (no meaning)
            elsewhere, so that downstream algebra and its gradients stay finite: mask with ``reach``/``ok``.
        disc: IK discriminant rho^2 - m^2 (m^2); >= 0 iff the loop closes.
        reach: the loop closes (disc >= 0 and rho > 0).
        margin: joint-limit margin cos(theta - mid) - cos(half) (>= 0 inside the limits; >= 1 unlimited);
            meaningful where ``reach``.
        ok: ``reach & (margin >= 0)``.
    """

    cos: Float[Array, ""]
    sin: Float[Array, ""]
    disc: Float[Array, ""]
    reach: Bool[Array, ""]
    margin: Float[Array, ""]
    ok: Bool[Array, ""]


def safe_point(robot: Delta, p: Float[Array, "3"]) -> tuple[Float[Array, "3"], Bool[Array, ""]]:
    """(p or a harmless stand-in, whether p is usable): the one double-where guard of the per-point kernels.

    A point with a non-finite coordinate or one farther than R + r + L1 + L2 along an axis cannot be reached
    by any chain; it is replaced by the origin *before* any algebra, so that huge finite values (>= 1e154
    overflow the squares), inf and NaN never meet a zero cotangent (0 * inf = NaN gradients). Callers AND
    the flag into ``ok``.
    """
    bound = jnp.abs(robot.base_radius) + jnp.abs(robot.platform_radius) + jnp.abs(robot.upper_arm) + jnp.abs(
        robot.forearm)
    # three compares, not jnp.all: a reduce is a separate XLA loop; NaN compares False
    good = (jnp.abs(p[..., 0]) <= bound) & (jnp.abs(p[..., 1]) <= bound) & (jnp.abs(p[..., 2]) <= bound)
    return jnp.where(good[..., None], p, jnp.zeros_like(p)), good


def loop_closure(dx, py, pz, L1, L2, lim: LimitTerms, sign: float = 1.0) -> LoopClosure:
    """Algebraic IK of one chain: the loop-closure equation solved for cos/sin theta, no inverse trig.

    With the point in chain i's local frame and dx = p_x,i + r - R: |C - B|^2 = L2^2 reads
    ``dx cos(theta) + pz sin(theta) = m``, m = (rho^2 + py^2 + L1^2 - L2^2) / (2 L1), rho^2 = dx^2 + pz^2.
    It closes iff disc = rho^2 - m^2 >= 0; then with w = sqrt(disc),
    cos theta = (dx m + sign pz w) / rho^2, sin theta = (pz m - sign dx w) / rho^2
    (sign = +1: outer elbow, theta = atan2(pz, dx) - acos(m / rho); -1: the inner branch).

    Gradient guards: w = sqrt(disc if disc > 0 else 0) (exactly on the reach boundary w = 0 and the chain
    rule sends a zero, not 0 * inf, to disc) and 1/rho^2 guarded; the inputs must be finite and bounded
    (:func:`safe_point` at the point level). Written for XLA:CPU: multiplies by 1/(2 L1) (a design scalar,
    divided once) and :mod:`deltajax.fastmath`'s cheap-op sqrt and reciprocal per point, so that the whole
    kernel fuses into one loop (a per-point divide or sqrt would be stored to memory between loops).

    Args:
        dx, py, pz: chain-local loop inputs (m), scalars (vmap for batches), finite.
        L1, L2: upper arm and forearm (m), > 0.
        lim: :func:`limit_terms` of the joint range.
        sign: +1.0 outer elbow (default), -1.0 inner.

    Returns:
        :class:`LoopClosure`.
    """
    rho2 = dx * dx + pz * pz
    m = (rho2 + py * py + L1 * L1 - L2 * L2) * (1.0 / (2.0 * L1))  # = K / (2 L1): the loop-closure equation
    disc = rho2 - m * m  # rho^2 sin^2(acos(m / rho))
    reach = (disc >= 0.0) & (rho2 > 0.0)
    w = sqrt0(disc)
    inv_rho2 = recip(jnp.where(reach, rho2, 1.0))
    c = (dx * m + sign * pz * w) * inv_rho2
    s = (pz * m - sign * dx * w) * inv_rho2
    margin = c * lim.cos_mid + s * lim.sin_mid - lim.cos_half
    return LoopClosure(cos=c, sin=s, disc=disc, reach=reach, margin=margin, ok=reach & (margin >= 0.0))


def loop_vectors(dx, py, pz, c, s, L1, L2):
    """Unit forearm vector u = (C - B) / L2 of one chain in its local frame, (ux, uy, uz) scalars.

    C - B = (dx - L1 cos theta, py, pz - L1 sin theta) with dx, py, pz the inputs of :func:`loop_closure`
    and c, s its cos/sin theta. In the paper's angles u = (sin th3 cos(th1 + th2),
    cos th3, sin th3 sin(th1 + th2)).
    """
    inv_L2 = 1.0 / L2  # a design scalar: one divide, then multiplies per point (one fused loop)
    return (dx - L1 * c) * inv_L2, py * inv_L2, (pz - L1 * s) * inv_L2


def branch_sign(branch: str) -> float:
    if branch not in ("outer", "inner"):
        raise ValueError(f"branch must be 'outer' or 'inner', got {branch!r}")
    return 1.0 if branch == "outer" else -1.0


def ik_cos_sin(robot: Delta, p: Float[Array, "3"], *, branch: str = "outer") -> IKCosSin:
    """Algebraic inverse kinematics: cos and sin of the actuated angles, no inverse trig.

    Built from :func:`loop_closure` per chain.

    Args:
        robot: the robot (its ``base_radius`` is the R used).
        p: platform centre P in the base frame (m, z down).
        branch: ``"outer"`` (default, theta = atan2(pz, dx) - acos(K / (2 L1 rho)), elbow out) or
            ``"inner"`` (the other root).

    Returns:
        :class:`IKCosSin` with per-chain cos, sin (NaN where the loop does not close), ok and reason. An
        invalid (traced) design gives ok=False, reason IK_INVALID_DESIGN on every chain.
    """
    sign = branch_sign(branch)
    p = jnp.asarray(p)
    dtype = jnp.result_type(p.dtype, robot.upper_arm.dtype)
    p = p.astype(dtype)
    finite_p = jnp.all(jnp.isfinite(p))
    p, usable = safe_point(robot, p)
    valid = design_ok(robot)
    lim = limit_terms(robot.theta_min, robot.theta_max)
    out = []
    for i in range(3):
        x, y, z = chain_local(p[0], p[1], p[2], i)
        dx = x + robot.platform_radius - robot.base_radius  # (x + r) - R, as every kernel evaluates it
        out.append(loop_closure(dx, y, z, robot.upper_arm, robot.forearm, lim, sign))
    reach = jnp.stack([o.reach for o in out]) & valid & usable
    inside = jnp.stack([o.margin >= 0.0 for o in out])
    ok = reach & inside
    reason = jnp.where(
        ~valid, IK_INVALID_DESIGN,
        jnp.where(~finite_p, IK_NONFINITE,
                  jnp.where(~reach, IK_UNREACHABLE, jnp.where(~inside, IK_JOINT_LIMIT, IK_OK)))).astype(jnp.int32)
    nan = jnp.asarray(jnp.nan, dtype)
    return IKCosSin(cos=jnp.where(reach, jnp.stack([o.cos for o in out]), nan),
                    sin=jnp.where(reach, jnp.stack([o.sin for o in out]), nan), ok=ok, reason=reason)


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
    """Elbow points B_i in the base frame (m); row i is chain i. NaN where the (traced) design is invalid or
    theta is not finite (:func:`guarded_configuration`)."""
    theta = jnp.asarray(theta)
    robot, _, theta_g, ok = guarded_configuration(robot, jnp.zeros((3,), theta.dtype), theta)
    return jnp.where(ok, elbows_unguarded(robot, theta_g), jnp.nan)


def elbows_unguarded(robot: Delta, theta):
    """:func:`elbows` for a configuration already checked (:func:`guarded_configuration`): no guard, no NaN."""
    return elbows_from_cos_sin(robot, jnp.cos(theta), jnp.sin(theta))


def elbows_from_cos_sin(robot: Delta, c, s):
    """:func:`elbows_unguarded` from the actuated angles' cos ``c`` and sin ``s`` (e.g. the IK's: no trigonometry)."""
    L1 = robot.upper_arm
    return from_chain_frames(jnp.stack([robot.base_radius + L1 * c, jnp.zeros_like(c), L1 * s], axis=-1))


class FKResult(NamedTuple):
    """Forward kinematics of one configuration.

    Attributes:
        p: platform centre in the base frame (m); NaN when not ok.
        ok: the three forearm spheres intersect (non-degenerate), every theta_i is within the joint limits
            and the design is valid (README: out-of-limit gives ``ok=False``).
        reason: FK_* code (0 ok, 1 no intersection, 2 degenerate/collinear centres, 3 non-finite input,
            4 tangent spheres: the pose exists but sits on a singularity; ``ok`` stays True, 5 some theta_i
            outside the joint limits, 6 invalid design). For reason 5 ``p`` still holds the assembled pose
            (where the platform would be), only ``ok`` is False; for every other failure ``p`` is NaN.
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
    c = from_chain_frames(local)
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
    valid = design_ok(robot)
    assembled = finite & nondegenerate & meet & valid
    lim = limit_terms(robot.theta_min, robot.theta_max)
    within = jnp.all(jnp.cos(theta_safe) * lim.cos_mid + jnp.sin(theta_safe) * lim.sin_mid - lim.cos_half >= 0.0)
    ok = assembled & within
    tangent = ok & (jnp.abs(h2) <= tangent_tol * L2 * L2)
    reason = jnp.where(~valid, FK_INVALID_DESIGN, jnp.where(~finite, FK_NONFINITE,
                       jnp.where(~nondegenerate, FK_DEGENERATE_CENTRES,
                                 jnp.where(~meet, FK_NO_INTERSECTION, jnp.where(
                                     ~within, FK_JOINT_LIMIT, jnp.where(tangent, FK_TANGENT, FK_OK))))))
    return FKResult(p=jnp.where(assembled, p, jnp.nan), ok=ok, reason=reason.astype(jnp.int32))


def forearm_units(robot: Delta, p: Float[Array, "3"], theta: Float[Array, "3"]) -> Float[Array, "3 3"]:
    """Unit forearm vectors u_i = (C_i - B_i) / L2 in each chain's *local* frame; row i is chain i.

    In the local frame u = (sin th3 cos(th1 + th2), cos th3, sin th3 sin(th1 + th2)) (paper §2.1); built
    from :func:`loop_vectors` with cos/sin of the given theta. NaN where the (traced) design is invalid or p or
    theta is not finite (:func:`guarded_configuration`).
    """
    robot, p, theta, ok = guarded_configuration(robot, p, theta)
    return jnp.where(ok, forearm_units_unguarded(robot, p, theta), jnp.nan)


def forearm_units_unguarded(robot: Delta, p, theta):
    """:func:`forearm_units` for a configuration already checked (:func:`guarded_configuration`): no guard."""
    return forearm_units_from_cos_sin(robot, p, jnp.cos(theta), jnp.sin(theta))


def forearm_units_from_cos_sin(robot: Delta, p, c, s):
    """:func:`forearm_units_unguarded` from the actuated angles' cos ``c`` and sin ``s`` (no trigonometry)."""
    rows = []
    for i in range(3):
        x, y, z = chain_local(p[0], p[1], p[2], i)
        dx = x + robot.platform_radius - robot.base_radius
        rows.append(jnp.stack(loop_vectors(dx, y, z, c[i], s[i], robot.upper_arm, robot.forearm)))
    return jnp.stack(rows)


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
        (theta2, theta3), each of shape (3,); NaN where the (traced) design is invalid or p or theta is not
        finite (:func:`guarded_configuration`; by ``where``, as ``clip`` does not carry NaN at every batch size).
    """
    robot, p, theta, ok = guarded_configuration(robot, p, theta)
    t2, t3 = _passive_angles(robot, p, theta)
    return jnp.where(ok, t2, jnp.nan), jnp.where(ok, t3, jnp.nan)


def _passive_angles(robot: Delta, p, theta):
    u = forearm_units_unguarded(robot, p, theta)
    uy = jnp.clip(u[:, 1], -1.0, 1.0)
    theta3 = jnp.arccos(uy)
    theta12 = jnp.arctan2(u[:, 2], u[:, 0])
    theta2 = theta12 - jnp.asarray(theta)
    theta2 = jnp.mod(theta2 + jnp.pi, 2.0 * jnp.pi) - jnp.pi
    theta2 = jnp.where(theta2 <= -jnp.pi, theta2 + 2.0 * jnp.pi, theta2)
    return theta2, theta3
