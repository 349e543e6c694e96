"""Constraints a Delta designer checks, as pure functions of one design and one configuration (vmap to batch).

Every function here is built on the public core (:func:`deltajax.ik`, :func:`deltajax.elbows`,
:func:`deltajax.kinematics.forearm_units`, :func:`deltajax.point_indices`, :func:`deltajax.cycle_profile`) and returns
*margins*: a signed number that is >= 0 when the constraint holds, in the units of the quantity (rad, m, or
a utilisation ratio). A margin can be used as a constraint (``margin >= 0``) or as an objective (maximise it).
Unreachable configurations give NaN margins (failure as data; a NaN margin never counts as satisfied).

Models (explicit, documented; all frames: base frame, z down, chain i at angle 2 pi i / 3, docs/CONVENTIONS.md):

* **Passive joints** (:class:`JointModel`). ``kind="ball"``: a spherical joint at each end of every forearm
  (the parallelogram as one rod) whose socket allows a *cone* of half-angle ``limit`` around a neutral axis
  fixed in the body that carries it. Elbow: the neutral axis lies in the chain's vertical plane at angle
  ``elbow_neutral`` from the upper arm's direction (rotating with the arm), so the elbow cone angle is
  ``acos(u . n_e)`` with ``n_e = (cos(th1 + phi_e), 0, sin(th1 + phi_e))`` in the chain frame.
  Platform: the neutral axis (from C_i toward B_i) lies in the chain's plane, tilted ``platform_neutral`` from
  the upward vertical toward the base joint (the platform translates, so the axis is fixed), and the cone
  angle is ``acos(-u . n_p)``. ``kind="universal"``: a universal joint at each end with its first axis
  parallel to the motor axis (the chain frame's y) and the second perpendicular to it and to the rod; each
  rotation is limited to +-``limit`` around its neutral: about the first axis the in-plane angle of the rod
  relative to the neutral direction above, about the second the out-of-plane tilt ``theta_i3 - pi/2``.
* **Link interference** (:class:`LinkModel`): forearms (the parallelogram's envelope) and upper arms are
  capsules (segments B_i C_i and A_i B_i with radii ``forearm_radius`` / ``upper_arm_radius``); the base plate
  is the disc ``z = 0, |xy| <= plate_radius``. Clearances (surface-to-surface, m, exact: no sampling):
  forearm-forearm (3 pairs), forearm i - upper arm j (j != i, 6 pairs), base plate - forearms
  (:func:`segment_disc_distance`) and platform centre. Margin = min clearance - ``clearance``.
* **Motors, gearing and the cycle rate** (:class:`Motor`, :func:`cycle_rate`, :func:`picks_per_minute`, ...):
  :mod:`deltajax.drive`, re-exported here (the designer checks them with the rest).
* **Regular workspace**: the largest cylinder centred on the z axis with height/diameter ratio
  ``hd_ratio`` inside the *good* workspace (:func:`good_point`: reachable, index >= threshold, passive
  joints within limits, no interference), on a polar sample grid (:func:`regular_workspace`, in
  :mod:`deltajax.regular`, re-exported here), optionally refined to a *continuous* measure
  (:func:`refine_cylinder`: golden-section search of the centre height around the grid's answer, bisection on the diameter with the good test on a fixed set of samples scaled with the cylinder), so
  that the value moves continuously with the design instead of stepping between the grid's levels and rings.
"""

from __future__ import annotations

import math
import warnings
from typing import NamedTuple, Optional

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from .fields import ConstraintError, check_range, float_leaf
from .geometry import CHAIN_ANGLES, Delta
from .indices import point_kernel
from .kinematics import (elbows_from_cos_sin, elbows_unguarded, forearm_units_from_cos_sin, forearm_units_unguarded,
                         guarded_configuration)
from .drive import (CycleRate, DriveLoads, Motor, cycle_rate, cycle_rate_refined, drive_loads,  # noqa: F401
                    drive_ok, min_cycle_time, motor_side, picks_per_minute, with_drive)  # re-exported: the designer's
from .plate import PLATE_NEWTON_STEPS, PLATE_SAMPLES, segment_disc_distance  # noqa: F401  (re-exported)
from .tracing import traced_once
from .regular import (REFINE_BISECT, REFINE_GOLDEN, REFINE_SAMPLES, RegularWorkspace, cylinder_samples,  # noqa: F401
                      largest_cylinder, polar_grid, refine_cylinder, regular_workspace)  # the designer's constraints

__all__ = ["JointModel", "LinkModel", "GoodSpec", "JointAngles", "Interference", "PointCheck", "ConstraintError",
           "joint_angles", "joint_margin", "segment_distance", "segment_disc_distance", "interference", "good_point",
           "good_point_possible", "good_point_decided", "good_point_settle", "GoodState", "plate_blocks",
           "JOINT_BAND", "largest_cylinder", "regular_workspace", "RegularWorkspace", "polar_grid", "cylinder_samples",
           "refine_cylinder",
           # deltajax.drive's, re-exported
           "Motor", "DriveLoads", "CycleRate", "with_drive", "motor_side", "drive_ok", "drive_loads", "cycle_rate",
           "cycle_rate_refined", "min_cycle_time", "picks_per_minute"]


# -- passive joints --------------------------------------------------------------------------------------------

class JointModel(eqx.Module):
    """Passive joints at both ends of each forearm (see the module docstring).

    Attributes:
        kind: ``"ball"`` (cone limit) or ``"universal"`` (limit about each of its two axes); static.
        limit: cone half-angle (ball) or the +- range about each axis (universal), rad.
        elbow_neutral: neutral axis at the elbow, angle from the upper arm's direction in the chain plane, rad.
        platform_neutral: neutral axis at the platform (C_i toward B_i), tilt from the upward vertical toward
            the base joint in the chain plane, rad.
    """

    limit: jax.Array = eqx.field(converter=float_leaf)
    elbow_neutral: jax.Array = eqx.field(converter=float_leaf, default=math.pi / 2)
    platform_neutral: jax.Array = eqx.field(converter=float_leaf, default=0.0)
    kind: str = eqx.field(static=True, default="ball")

    def __check_init__(self):
        if self.kind not in ("ball", "universal"):
            raise ConstraintError(f"JointModel.kind must be 'ball' or 'universal', got {self.kind!r}")
        check_range("JointModel", "limit", self.limit, lo=0.0, strict=True, hi=math.pi, error=ConstraintError)
        for n in ("elbow_neutral", "platform_neutral"):
            check_range("JointModel", n, getattr(self, n), lo=-math.pi, strict=False, hi=math.pi,
                        error=ConstraintError)


class JointAngles(NamedTuple):
    """Deflection of each passive joint from its neutral axis (rad), chain i in row i.

    ``elbow``/``platform``: the cone angle (ball) or the larger of the two axis rotations (universal).
    """

    elbow: Float[Array, "3"]
    platform: Float[Array, "3"]


def _dot3(u, v):
    """u . v of 3-vectors (last axis) in components: elementwise, so XLA fuses it with its neighbours (``jnp.dot`` of
    3-vectors under vmap is a dot_general, which XLA:CPU ran as a library call per dot: 36 of 116 kernels)."""
    return u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1] + u[..., 2] * v[..., 2]


def _angle_between(a, b):
    """Angle between unit vectors (rows), robust near 0 and pi (atan2 of |a x b| and a . b)."""
    c = jnp.sum(a * b, axis=-1)
    s = jnp.linalg.norm(jnp.cross(a, b), axis=-1)
    return jnp.arctan2(s, c)


def joint_angles(robot: Delta, p: Float[Array, "3"], theta: Float[Array, "3"], joints: JointModel) -> JointAngles:
    """Passive-joint deflections at the elbows and the platform for one configuration.

    Args:
        robot: the robot (R frozen).
        p: platform centre (m, base frame).
        theta: actuated angles (rad), e.g. ``dj.ik(robot, p).theta``.
        joints: the joint model.

    Returns:
        :class:`JointAngles`, NaN where the (traced) design is invalid or p or theta is not finite
        (:func:`deltajax.kinematics.guarded_configuration`).
    """
    robot, p, theta, ok = guarded_configuration(robot, p, theta)
    nan = jnp.asarray(jnp.nan, theta.dtype)
    return JointAngles(*(jnp.where(ok, v, nan) for v in _joint_angles(robot, p, theta, joints)))


def _joint_angles(robot: Delta, p, theta, joints: JointModel) -> JointAngles:
    """:func:`joint_angles` of a configuration already guarded (:func:`guarded_configuration`'s stand-ins)."""
    u = forearm_units_unguarded(robot, p, theta)                      # (3, 3) chain frames, B -> C
    th = jnp.asarray(theta)
    z = jnp.zeros_like(th)
    n_e = jnp.stack([jnp.cos(th + joints.elbow_neutral), z, jnp.sin(th + joints.elbow_neutral)], axis=-1)
    sp, cp = jnp.sin(joints.platform_neutral), jnp.cos(joints.platform_neutral)
    n_p = jnp.stack([sp + z, z, -cp + z], axis=-1)           # from C toward B at neutral
    if joints.kind == "ball":
        return JointAngles(elbow=_angle_between(u, n_e), platform=_angle_between(-u, n_p))
    # universal: in-plane angle of the rod about the first axis (chain y), out-of-plane tilt about the second
    tilt = jnp.abs(jnp.arccos(jnp.clip(u[:, 1], -1.0, 1.0)) - jnp.pi / 2)
    in_plane_e = jnp.arctan2(u[:, 2], u[:, 0]) - (th + joints.elbow_neutral)
    in_plane_p = jnp.arctan2(-u[:, 2], -u[:, 0]) - jnp.arctan2(n_p[:, 2], n_p[:, 0])
    wrap = lambda a: jnp.abs(jnp.mod(a + jnp.pi, 2 * jnp.pi) - jnp.pi)  # noqa: E731
    return JointAngles(elbow=jnp.maximum(wrap(in_plane_e), tilt), platform=jnp.maximum(wrap(in_plane_p), tilt))


def joint_margin(robot: Delta, p, theta, joints: JointModel) -> Float[Array, ""]:
    """limit - largest deflection over the six joints (rad); >= 0 when every joint is within its limit; NaN as
    :func:`joint_angles` (by ``where``: ``jnp.max`` does not carry NaN at every batch size)."""
    robot, p, theta, ok = guarded_configuration(robot, p, theta)
    return _joint_margin(robot, p, theta, ok, joints)


def _joint_margin(robot: Delta, p, theta, ok, joints: JointModel):
    a = _joint_angles(robot, p, theta, joints)
    return jnp.where(ok, joints.limit - jnp.maximum(jnp.max(a.elbow), jnp.max(a.platform)), jnp.nan)


#: Half-width of the band around a ball joint's limit where :func:`_ball_joints_decided` leaves the decision to
#: :func:`_joint_margin` (in sin(angle - limit): ~1e-9 rad, far above both computations' rounding).
JOINT_BAND = 1e-9


def _ball_joints_decided(robot: Delta, p, cos, sin, joints: JointModel):
    """(within, decided) for ball joints without inverse trigonometry: a cone angle phi = atan2(|a x b|, a . b) is
    at most the limit L exactly when sin(phi - L) = |a x b| cos L - (a . b) sin L <= 0 (phi, L in [0, pi]); the
    forearm units and the elbows' neutral axes from the actuated angles' cos and sin (angle addition, no
    transcendental per pair). Decided where every joint is inside the limit by more than :data:`JOINT_BAND` or
    one is outside by more: there :func:`_joint_margin` >= 0 gives the same answer."""
    u = forearm_units_from_cos_sin(robot, p, cos, sin)
    ce, se = jnp.cos(joints.elbow_neutral), jnp.sin(joints.elbow_neutral)
    z = jnp.zeros_like(cos)
    n_e = jnp.stack([cos * ce - sin * se, z, sin * ce + cos * se], axis=-1)     # cos, sin of theta + neutral
    sp, cp = jnp.sin(joints.platform_neutral), jnp.cos(joints.platform_neutral)
    n_p = jnp.stack([sp + z, z, -cp + z], axis=-1)
    cL, sL = jnp.cos(joints.limit), jnp.sin(joints.limit)

    def side(a, b):   # |a x b| cos L - (a . b) sin L per row, in components (fused by XLA, see _dot3)
        c = (a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1], a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
             a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0])
        return jnp.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]) * cL - _dot3(a, b) * sL

    d = jnp.concatenate([side(u, n_e), side(-u, n_p)])
    within = jnp.all(d < -JOINT_BAND)
    return within, within | jnp.any(d > JOINT_BAND)


# -- link interference -----------------------------------------------------------------------------------------

class LinkModel(eqx.Module):
    """Link envelopes for interference checks (m).

    Attributes:
        forearm_radius: capsule radius around the forearm axis B_i C_i (half the parallelogram's width plus
            the rod radius).
        upper_arm_radius: capsule radius around the upper arm A_i B_i.
        clearance: required surface-to-surface clearance.
        plate_overhang: base plate radius = base radius R + this (may be < 0); for a reconfigurable design
            pass ``plate_radius`` explicitly (it must hold the motors at R_max).
    """

    forearm_radius: jax.Array = eqx.field(converter=float_leaf, default=0.02)
    upper_arm_radius: jax.Array = eqx.field(converter=float_leaf, default=0.02)
    clearance: jax.Array = eqx.field(converter=float_leaf, default=0.005)
    plate_overhang: jax.Array = eqx.field(converter=float_leaf, default=0.0)

    def __check_init__(self):
        for n in ("forearm_radius", "upper_arm_radius", "clearance"):
            check_range("LinkModel", n, getattr(self, n), lo=0.0, strict=False, hi=10.0, error=ConstraintError)
        check_range("LinkModel", "plate_overhang", self.plate_overhang, lo=-10.0, strict=False, hi=10.0,
                    error=ConstraintError)


def segment_distance(p0, p1, q0, q1) -> Float[Array, ""]:
    """Minimum distance between segments [p0, p1] and [q0, q1] (3-vectors), exact (Ericson's clamped
    closest points, branch-free; degenerate segments handled)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e, f, c, b = _dot3(d1, d1), _dot3(d2, d2), _dot3(d2, r), _dot3(d1, r), _dot3(d1, d2)
    tiny = 1e-30
    denom = a * e - b * b
    s = jnp.where(denom > tiny * jnp.maximum(a * e, tiny), jnp.clip((b * f - c * e) / jnp.where(denom > 0, denom, 1.0),
                                                                   0.0, 1.0), 0.0)
    s = jnp.where(a > tiny, s, 0.0)
    t = jnp.where(e > tiny, (b * s + f) / jnp.where(e > tiny, e, 1.0), 0.0)
    # t outside [0, 1]: clamp it and recompute s for the clamped t
    t_c = jnp.clip(t, 0.0, 1.0)
    s = jnp.where((t != t_c) & (a > tiny), jnp.clip((t_c * b - c) / jnp.where(a > tiny, a, 1.0), 0.0, 1.0), s)
    d = (p0 + s * d1) - (q0 + t_c * d2)
    return jnp.sqrt(_dot3(d, d))


class Interference(NamedTuple):
    """Surface clearances of one configuration (m) and the margin (min clearance - required clearance)."""

    forearm_forearm: Float[Array, ""]
    forearm_upper_arm: Float[Array, ""]
    base_plate: Float[Array, ""]
    margin: Float[Array, ""]


def interference(robot: Delta, p: Float[Array, "3"], theta: Float[Array, "3"], links: LinkModel, *,
                 plate_radius: Optional[Float[Array, ""]] = None, n_plate: Optional[int] = None) -> Interference:
    """Link clearances of one configuration (see :class:`LinkModel`), all exact: segment-segment distances
    between the link axes (:func:`segment_distance`) and the segment-disc clearance of each forearm axis to
    the base plate (:func:`segment_disc_distance`); the base-plate clearance is also at most the platform
    centre's height p_z.

    Every field is NaN where the (traced) design is invalid, p or theta is not finite (e.g. a failed IK) or
    the plate radius is negative or not finite (:func:`deltajax.kinematics.guarded_configuration`).
    ``n_plate`` (the old sample count) is accepted for old callers with a DeprecationWarning: the plate
    clearance is no longer sampled.
    """
    if n_plate is not None:
        warnings.warn("interference: n_plate is ignored, the base-plate clearance is exact (no samples)",
                      DeprecationWarning, stacklevel=2)
    robot, p, theta, ok = guarded_configuration(robot, p, theta)
    return _interference(robot, p, theta, ok, links, plate_radius)


def _chain_axes(dtype):
    """The chains' x axes in the base frame, (3, 3)."""
    return jnp.asarray([[math.cos(a), math.sin(a), 0.0] for a in CHAIN_ANGLES], dtype)


def _forearm_ends(robot: Delta, p):
    """The forearms' ends C_i at the platform (base frame), (3, 3)."""
    return p[None, :] + robot.platform_radius * _chain_axes(p.dtype)


def _link_clearances(robot: Delta, p, theta, links: LinkModel):
    """Elbows B, forearm ends C (base frame) and the forearm-forearm and forearm-upper arm clearances (m) of a
    configuration already guarded (:func:`guarded_configuration`)."""
    B = elbows_unguarded(robot, theta)                                         # (3, 3) base frame
    dirs = _chain_axes(B.dtype)
    C = _forearm_ends(robot, p)
    A = robot.base_radius * dirs
    pairs = ((0, 1), (1, 2), (2, 0))
    ff = jnp.min(jnp.stack([segment_distance(B[i], C[i], B[j], C[j]) for i, j in pairs])) - 2 * links.forearm_radius
    fu = jnp.min(jnp.stack([segment_distance(B[i], C[i], A[j], B[j]) for i in range(3) for j in range(3) if j != i]))
    return B, C, ff, fu - links.forearm_radius - links.upper_arm_radius


def _plate_radius(robot: Delta, links: LinkModel, plate_radius, ok, dtype):
    """The plate radius (``plate_radius`` or R + overhang) and ``ok`` with its guard (finite, >= 0)."""
    Rp = robot.base_radius + links.plate_overhang if plate_radius is None else jnp.asarray(plate_radius, dtype)
    ok = ok & jnp.isfinite(Rp) & (Rp >= 0.0)
    return jnp.where(ok, Rp, robot.base_radius), ok


def _interference(robot: Delta, p, theta, ok, links: LinkModel, plate_radius) -> Interference:
    """:func:`interference` of a configuration already guarded (:func:`guarded_configuration`'s stand-ins and its
    ``ok``): each consumer of one configuration guards it once (:func:`good_point`)."""
    B, C, ff, fu = _link_clearances(robot, p, theta, links)
    Rp, ok = _plate_radius(robot, links, plate_radius, ok, B.dtype)
    return _interference_of(p, B, C, ff, fu, Rp, ok, links)


def _interference_of(p, B, C, ff, fu, Rp, ok, links: LinkModel) -> Interference:
    """:func:`_interference` from the link clearances (:func:`_link_clearances`) and the guarded plate radius."""
    plate = jnp.stack([segment_disc_distance(B[i], C[i], Rp) for i in range(3)])
    bp = jnp.minimum(jnp.min(plate) - links.forearm_radius, p[2])
    margin = jnp.minimum(jnp.minimum(ff, fu), bp) - links.clearance
    nan = jnp.asarray(jnp.nan, B.dtype)
    # NaN by where: jnp.minimum does not carry NaN through XLA:CPU's vectorised loops at every batch size
    return Interference(*(jnp.where(ok, v, nan) for v in (ff, fu, bp, margin)))


# -- good and regular workspace --------------------------------------------------------------------------------

class GoodSpec(eqx.Module):
    """What makes a point of the workspace *good*: reachable, ``index >= threshold``, passive joints within
    limits, links clear. ``index`` is a field of :class:`deltajax.indices.Indices` (static)."""

    joints: JointModel
    links: LinkModel
    threshold: jax.Array = eqx.field(converter=float_leaf, default=0.3)
    index: str = eqx.field(static=True, default="k_tilde")
    beta: jax.Array = eqx.field(converter=float_leaf, default=0.5)


class PointCheck(NamedTuple):
    good: Bool[Array, ""]
    reachable: Bool[Array, ""]
    index: Float[Array, ""]
    joint_margin: Float[Array, ""]
    interference_margin: Float[Array, ""]


def _segment_meets_plate_region(q0, q1, radius, z_top, z_bottom=None):
    """Does the segment [q0, q1] (base frame, z down) have a point with |xy| <= ``radius`` and ``z_bottom`` <= z
    <= ``z_top`` (None: no lower bound)? Closed form: the t-interval where |xy(t)|^2 <= radius^2 (a quadratic)
    meets the one where z(t) is in range (z is linear) inside [0, 1]; False where ``radius`` is not positive."""
    d = q1 - q0
    a = d[0] * d[0] + d[1] * d[1]
    b = 2.0 * (q0[0] * d[0] + q0[1] * d[1])
    c = q0[0] * q0[0] + q0[1] * q0[1] - radius * radius
    moves = a > jnp.finfo(a.dtype).tiny * jnp.maximum(jnp.abs(c), 1.0)      # not a vertical segment
    disc = b * b - 4.0 * a * c
    real = moves & (disc >= 0.0)
    root = jnp.sqrt(jnp.where(real, disc, 0.0))
    a_s = jnp.where(moves, a, 1.0)
    t1 = jnp.where(moves, (-b - root) / (2.0 * a_s), 0.0)
    t2 = jnp.where(moves, (-b + root) / (2.0 * a_s), 1.0)
    over = jnp.where(moves, real, c <= 0.0)            # some t (of the line) lies over the disc of ``radius``
    dz = d[2]
    tz = (z_top - q0[2]) / jnp.where(dz != 0.0, dz, 1.0)
    z_lo = jnp.where(dz < 0.0, tz, jnp.where((dz == 0.0) & (q0[2] > z_top), jnp.inf, -jnp.inf))
    z_hi = jnp.where(dz > 0.0, tz, jnp.where((dz == 0.0) & (q0[2] > z_top), -jnp.inf, jnp.inf))
    if z_bottom is not None:     # z(t) >= z_bottom as well
        tb = (z_bottom - q0[2]) / jnp.where(dz != 0.0, dz, 1.0)
        z_lo = jnp.maximum(z_lo, jnp.where(dz > 0.0, tb, jnp.where((dz == 0.0) & (q0[2] < z_bottom), jnp.inf,
                                                                    -jnp.inf)))
        z_hi = jnp.minimum(z_hi, jnp.where(dz < 0.0, tb, jnp.where((dz == 0.0) & (q0[2] < z_bottom), -jnp.inf,
                                                                    jnp.inf)))
    lo = jnp.maximum(jnp.maximum(t1, z_lo), 0.0)
    hi = jnp.minimum(jnp.minimum(t2, z_hi), 1.0)
    return over & (lo <= hi) & (radius > 0.0)


def _plate_margin(dt):
    """Margin of the closed-form plate tests (m): covers the rounding of the exact clearance and of the tests."""
    return jnp.maximum(jnp.asarray(1e-9, dt), 1e3 * jnp.finfo(dt).eps)


def _plate_clear(B, C, Rp, links: LinkModel) -> Bool[Array, ""]:
    """A sufficient condition for every forearm's plate clearance to meet :func:`interference`'s requirement
    (``segment_disc_distance - forearm_radius >= clearance``), in closed form: no forearm axis enters the set of
    points within c = forearm_radius + clearance (plus a margin) of the disc, bounded by {|xy| <= Rp, z <= c}
    (over the disc: its height; through the base) and {|xy| <= Rp + c, |z| <= c} (beside it: the distance to
    the rim is at least both |xy| - Rp and |z|)."""
    e = _plate_margin(B.dtype)
    c = links.forearm_radius + links.clearance + e
    hit = [_segment_meets_plate_region(B[i], C[i], Rp + e, c) | _segment_meets_plate_region(B[i], C[i], Rp + c, c, -c)
           for i in range(3)]
    return ~jnp.any(jnp.stack(hit))


def plate_blocks(robot: Delta, p, cos, sin, links: LinkModel, plate_radius) -> Bool[Array, ""]:
    """A sufficient condition for a forearm's base-plate clearance to fail :func:`interference`'s requirement
    (``segment_disc_distance - forearm_radius < clearance``), in closed form: some point of a forearm axis lies
    over the disc shrunk by a margin and less than ``forearm_radius + clearance`` (less the margin) below the
    plate's plane (above it: through the base). The exact clearance of such a segment is at most that point's
    height (a point over the disc is its height from it), so it fails by more than the margin, which covers the
    rounding of both computations (1e-9 m in float64). ``cos``, ``sin``: the actuated angles' (the kernel's)."""
    Rp, _ = _plate_radius(robot, links, plate_radius, jnp.asarray(True), p.dtype)
    return _plate_blocked(elbows_from_cos_sin(robot, cos, sin), _forearm_ends(robot, p), Rp, links)


def _plate_blocked(B, C, Rp, links: LinkModel) -> Bool[Array, ""]:
    """:func:`plate_blocks` of the forearm axes B_i C_i (base frame) and the plate radius ``Rp``."""
    e = _plate_margin(B.dtype)
    z_top = links.forearm_radius + links.clearance - e
    return jnp.any(jnp.stack([_segment_meets_plate_region(B[i], C[i], Rp - e, z_top) for i in range(3)]))


def good_point_possible(robot: Delta, p: Float[Array, "3"], spec: GoodSpec, *, plate_radius=None) -> Bool[Array, ""]:
    """A necessary condition of :func:`good_point` (same ``plate_radius``) at a few % of its cost: reachable, the
    index at least the threshold (the same kernel call that :func:`good_point` makes) and no forearm through or
    just under the base plate by a closed-form test (:func:`plate_blocks`); the passive joints and the exact link
    clearances, most of the full test's cost, are left out. False means ``good_point(robot, p, spec,
    plate_radius=plate_radius).good`` is False, so a caller may skip the full test there (the search evaluator's
    regular-workspace grid, the ray searches of :mod:`deltajax.optimize.rays`). The threshold is relaxed by 1e-9 so
    that a last-bit difference between the two compiled copies of the kernel can only let a point through (to the
    full test), never drop a good one."""
    k = point_kernel(robot, p, beta=spec.beta)
    v = getattr(k.indices, spec.index)
    cos, sin = jnp.stack([c.cos for c in k.chains]), jnp.stack([c.sin for c in k.chains])
    return k.ok & (v >= spec.threshold - 1e-9) & ~plate_blocks(robot, p, cos, sin, spec.links, plate_radius)


def _solved(robot: Delta, p, spec: GoodSpec):
    """The IK solved once for every consumer: the index kernel's loop closures give the configuration (its ok and
    cos/sin are ik_cos_sin's, theta is ik's atan2 of them), guarded once (where the IK is ok it is unchanged).
    Returns (ok, index value, cos, sin, guarded robot, p, theta, ok)."""
    k = point_kernel(robot, p, beta=spec.beta)
    ok = k.ok
    cos, sin = jnp.stack([c.cos for c in k.chains]), jnp.stack([c.sin for c in k.chains])
    theta = jnp.arctan2(sin, cos)
    theta = jnp.where(theta <= -jnp.pi, theta + 2.0 * jnp.pi, theta)  # (-pi, pi], as ik
    theta = jnp.where(ok, theta, 0.5)               # a harmless configuration where IK failed
    return (ok, getattr(k.indices, spec.index), cos, sin) + tuple(guarded_configuration(robot, p, theta))


@traced_once
def good_point(robot: Delta, p: Float[Array, "3"], spec: GoodSpec, *, plate_radius=None) -> PointCheck:
    """Is ``p`` (m, base frame) in the good workspace of ``robot`` (R frozen)? Margins NaN if unreachable."""
    st = _good_state(robot, p, spec, plate_radius)[2]
    jm, im = _margins(st, spec)
    nan = jnp.asarray(jnp.nan, jm.dtype)
    v, jm, im = (jnp.where(st.ok, x, nan) for x in (st.index, jm, im))
    return PointCheck(good=_good_flag(st, jm, im, spec), reachable=st.ok, index=v, joint_margin=jm,
                      interference_margin=im)


class GoodState(NamedTuple):
    """The configuration at one point solved once for every term of the good test (:func:`good_point`; with
    ``state=True`` :func:`good_point_decided` returns it for :func:`good_point_settle`): the IK's ok and the index
    value, the guarded configuration (:func:`deltajax.kinematics.guarded_configuration`: robot, p, theta, ok), the
    elbows B and forearm ends C (base frame), the link clearances (m) and the guarded plate radius and its ok."""

    ok: Bool[Array, ""]
    index: Float[Array, ""]
    robot: Delta
    p: Float[Array, "3"]
    theta: Float[Array, "3"]
    ok_g: Bool[Array, ""]
    B: Float[Array, "3 3"]
    C: Float[Array, "3 3"]
    ff: Float[Array, ""]
    fu: Float[Array, ""]
    Rp: Float[Array, ""]
    ok_p: Bool[Array, ""]


def _good_state(robot: Delta, p, spec: GoodSpec, plate_radius):
    """(cos, sin, :class:`GoodState`): the actuated angles' cos and sin (the kernel's) and the state at ``p``."""
    ok, v, cos, sin, robot_g, p_g, theta_g, ok_g = _solved(robot, p, spec)
    B, C, ff, fu = _link_clearances(robot_g, p_g, theta_g, spec.links)
    Rp, ok_p = _plate_radius(robot_g, spec.links, plate_radius, ok_g, B.dtype)
    return cos, sin, GoodState(ok, v, robot_g, p_g, theta_g, ok_g, B, C, ff, fu, Rp, ok_p)


def _margins(st: GoodState, spec: GoodSpec):
    """The joint margin (rad) and the interference margin (m) of the state (NaN where its guard is not ok)."""
    jm = _joint_margin(st.robot, st.p, st.theta, st.ok_g, spec.joints)
    return jm, _interference_of(st.p, st.B, st.C, st.ff, st.fu, st.Rp, st.ok_p, spec.links).margin


def _good_flag(st: GoodState, jm, im, spec: GoodSpec) -> Bool[Array, ""]:
    """The good test's flag from the state and its margins (a NaN compares False)."""
    return st.ok & (st.index >= spec.threshold) & (jm >= 0) & (im >= 0)


def good_point_settle(st: GoodState, spec: GoodSpec) -> Bool[Array, ""]:
    """:func:`good_point`'s ``good`` from the configuration :func:`good_point_decided` solved (``state=True``): the
    terms it did not compute (the joint margins, the forearms' exact plate clearances), by the same functions on the
    same state as :func:`good_point`, so the IK, the index and the link distances are not solved a second time
    where the decided test leaves a point undecided (:func:`deltajax.optimize.rays.settle_good`)."""
    return _good_flag(st, *_margins(st, spec), spec)


def good_point_decided(robot: Delta, p: Float[Array, "3"], spec: GoodSpec, *, plate_radius=None, state: bool = False
                       ) -> tuple[Bool[Array, ""], ...]:
    """(good, decided): :func:`good_point`'s ``good`` (same ``plate_radius``) wherever ``decided``, at about half its
    cost: the forearms' exact plate clearances (a Newton search each) are replaced by closed-form tests
    (:func:`plate_blocks` and its converse) that settle them except where a forearm passes within a margin of the
    rim at the required clearance, and ball joints' cone angles by a sign test without inverse trigonometry
    (:func:`_ball_joints_decided`; undecided within ~1e-9 rad of the limit). Undecided: 2 % of the pairs that
    pass :func:`good_point_possible` on a polar grid of the main job's regular-workspace range, 12 % of those of
    the ray searches (they sample densely where the good set ends). Where ``decided`` is False the caller runs
    :func:`good_point` (:func:`deltajax.optimize.rays.settle_good`). Every other term is computed by the same
    functions on the same configuration as in :func:`good_point`, ``margin >= 0`` splits exactly into its terms,
    and the closed-form tests decide only outside a margin wider than both computations' rounding, so the flag is
    the exact one. ``state=True``: also the :class:`GoodState` that :func:`good_point_settle` finishes from."""
    cos, sin, st = _good_state(robot, p, spec, plate_radius)
    if spec.joints.kind == "ball":
        j_in, j_dec = _ball_joints_decided(st.robot, st.p, cos, sin, spec.joints)
    else:
        j_in, j_dec = _joint_margin(st.robot, st.p, st.theta, st.ok_g, spec.joints) >= 0, jnp.asarray(True)
    cl = spec.links.clearance
    rest = st.ok & st.ok_p & (st.index >= spec.threshold) & (st.ff >= cl) & (st.fu >= cl) & (st.p[2] >= cl)
    clear = _plate_clear(st.B, st.C, st.Rp, spec.links)
    blocked = _plate_blocked(st.B, st.C, st.Rp, spec.links)
    # decided: a term certainly fails, or every term certainly holds
    out = rest & j_in & clear, ~rest | (j_dec & ~j_in) | blocked | (j_in & clear)
    return out + (st,) if state else out
