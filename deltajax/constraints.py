"""Constraints a Delta designer checks, as pure functions of one design and one configuration (vmap to batch).

Every function here is built on the public core (:func:`deltajax.ik`, :func:`deltajax.elbows`,
:func:`deltajax.kinematics.forearm_units`, :func:`deltajax.point_indices`, :func:`deltajax.cycle_profile`) and returns
*margins*: a signed number that is >= 0 when the constraint holds, in the units of the quantity (rad, m, or
a utilisation ratio). A margin can be used as a constraint (``margin >= 0``) or as an objective (maximise it).
Unreachable configurations give NaN margins (failure as data; a NaN margin never counts as satisfied).

Models (explicit, documented; all frames: base frame, z down, chain i at angle 2 pi i / 3, SPEC §1):

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
from typing import Callable, NamedTuple, Optional

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .cycle import cycle_profile, log_bisect
from .fastmath import recip, rsqrt
from .fields import float_leaf
from .geometry import CHAIN_ANGLES, Delta
from .indices import point_kernel
from .kinematics import elbows_unguarded, forearm_units_unguarded, guarded_configuration
from .mass import check_field
from .tracing import traced_once
from .regular import (REFINE_BISECT, REFINE_GOLDEN, REFINE_SAMPLES, RegularWorkspace, cylinder_samples,  # noqa: F401
                      largest_cylinder, polar_grid, refine_cylinder, regular_workspace)  # the designer's constraints

__all__ = ["JointModel", "LinkModel", "Motor", "GoodSpec", "JointAngles", "Interference", "DriveLoads",
           "joint_angles", "joint_margin", "segment_distance", "segment_disc_distance", "interference", "with_drive",
           "motor_side", "drive_ok", "drive_loads", "cycle_rate_refined",
           "min_cycle_time", "picks_per_minute", "cycle_rate", "CycleRate", "PointCheck", "good_point", "good_point_possible", "largest_cylinder", "regular_workspace",
           "RegularWorkspace", "polar_grid", "cylinder_samples", "refine_cylinder", "ConstraintError"]


class ConstraintError(ValueError):
    """Invalid constraint model (names the field and the value)."""


def _check(cls: str, name: str, v, lo: float = 0.0, strict: bool = True, hi: float = math.inf):
    if isinstance(v, jax.core.Tracer):
        return
    a = np.asarray(v, dtype=float)
    bad = np.any(~np.isfinite(a)) if hi < math.inf or not math.isinf(lo) else np.any(np.isnan(a))
    if bad or np.any(a < lo) or (strict and np.any(a == lo)) or np.any(a > hi):
        rel = ">" if strict else ">="
        raise ConstraintError(f"{cls}.{name} must be {rel} {lo}{'' if hi == math.inf else f' and <= {hi}'}, "
                              f"got {a!r}")


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
        _check("JointModel", "limit", self.limit, 0.0, True, math.pi)
        for n in ("elbow_neutral", "platform_neutral"):
            _check("JointModel", n, getattr(self, n), -math.pi, False, math.pi)


class JointAngles(NamedTuple):
    """Deflection of each passive joint from its neutral axis (rad), chain i in row i.

    ``elbow``/``platform``: the cone angle (ball) or the larger of the two axis rotations (universal).
    """

    elbow: Float[Array, "3"]
    platform: Float[Array, "3"]


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
            _check("LinkModel", n, getattr(self, n), 0.0, False, 10.0)
        _check("LinkModel", "plate_overhang", self.plate_overhang, -10.0, False, 10.0)


def segment_distance(p0, p1, q0, q1) -> Float[Array, ""]:
    """Minimum distance between segments [p0, p1] and [q0, q1] (3-vectors), exact (Ericson's clamped
    closest points, branch-free; degenerate segments handled)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e, f = jnp.dot(d1, d1), jnp.dot(d2, d2), jnp.dot(d2, r)
    c, b = jnp.dot(d1, r), jnp.dot(d1, d2)
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
    return jnp.sqrt(jnp.dot(d, d))


class Interference(NamedTuple):
    """Surface clearances of one configuration (m) and the margin (min clearance - required clearance)."""

    forearm_forearm: Float[Array, ""]
    forearm_upper_arm: Float[Array, ""]
    base_plate: Float[Array, ""]
    margin: Float[Array, ""]


def _plate_slope(q0, d, t, radius):
    """h'(t) / 2 and h''(t) / 2 of h(t) = ((rho(t) - radius)^+)^2 + z(t)^2 at the point q0 + t d (base frame,
    rho = |xy|); h'' is the one-sided value at the rim crossing (h is C1 there)."""
    x, y, z = q0[0] + t * d[0], q0[1] + t * d[1], q0[2] + t * d[2]
    rho2 = x * x + y * y
    out = rho2 > radius * radius
    # 1 / rho beside the disc, 0 over it (multiply-add rsqrt: XLA:CPU fuses it, see deltajax.fastmath)
    inv = jnp.where(out, rsqrt(jnp.where(out, jnp.maximum(rho2, jnp.finfo(rho2.dtype).tiny), 1.0)), 0.0)
    ex = jnp.where(out, rho2 * inv - radius, 0.0)                        # (rho - radius)^+
    rp = (x * d[0] + y * d[1]) * inv                                     # rho'(t) beside the disc
    rpp = (d[0] * d[0] + d[1] * d[1] - rp * rp) * inv                    # rho''(t) >= 0 (rho convex)
    return ex * rp + z * d[2], rp * rp + ex * rpp + d[2] * d[2]


def _plate_h(q0, d, t, radius):
    """h(t) = ((rho(t) - radius)^+)^2 + z(t)^2 of the point q0 + t d (no derivative: the search's samples)."""
    x, y, z = q0[0] + t * d[0], q0[1] + t * d[1], q0[2] + t * d[2]
    rho2 = x * x + y * y
    out = rho2 > radius * radius
    ex = jnp.where(out, rho2 * rsqrt(jnp.where(out, jnp.maximum(rho2, jnp.finfo(rho2.dtype).tiny), 1.0)) - radius, 0.0)
    return ex * ex + z * z


def _plate_excess(q0, d, t, radius):
    """(rho(t) - radius)^+ and z(t) of the point q0 + t d (base frame) against the disc of ``radius``."""
    x, y, z = q0[0] + t * d[0], q0[1] + t * d[1], q0[2] + t * d[2]
    rho2 = x * x + y * y
    out = rho2 > radius * radius
    rho = jnp.sqrt(jnp.where(out, rho2, 1.0))                 # double where: rho = 0 only inside the disc
    return jnp.where(out, rho - radius, 0.0), z


#: Safeguarded Newton steps of :func:`segment_disc_distance` (measured: 8 reach a 54-step bisection to 1e-14 m on
#: 10^6 random, plate-crossing and rim-grazing segments, 6 did not; tests/test_interference_exact.py checks it
#: against a full bisection).
PLATE_NEWTON_STEPS = 8
#: Even samples of the piece that pick Newton's start and bracket in :func:`segment_disc_distance`.
PLATE_SAMPLES = 8


@traced_once
def segment_disc_distance(q0: Float[Array, "3"], q1: Float[Array, "3"], radius: Float[Array, ""]
                          ) -> Float[Array, ""]:
    """Signed clearance (m) between the segment [q0, q1] (base frame, z down) and the base plate, the disc
    ``z = 0, |xy| <= radius``, exact (no sampling).

    It is the minimum over the segment of the signed point-disc distance: a point over the disc
    (|xy| <= radius) counts its height z, negative above the plate (z < 0: through the base); a point beside
    the disc counts its distance to the rim, sqrt((|xy| - radius)^2 + z^2). Negative exactly when part of the
    segment lies over the disc above the plate; the answer then is the lowest z of that part (the set where
    |xy| <= radius is an interval of t, from a quadratic, and z is linear, so an end of it). Otherwise it is
    the unsigned segment-disc distance sqrt(min_t h(t)), h(t) = ((|xy(t)| - radius)^+)^2 + z(t)^2; h is convex
    in t (the distance to a convex set along a line) and C1, so its minimiser is an end of [0, 1] (decided by
    the sign of h' there: closed form) or the root of the monotone h'(t), found by Newton's method on h'
    safeguarded by the bracket that each step's sign of h' shrinks (a step leaving the bracket bisects it),
    :data:`PLATE_NEWTON_STEPS` steps in a fixed-count loop (no data-dependent loop, so vmap and jit(vmap(grad)) run;
    h is quadratic near an interior minimum, so the distance is exact to rounding once t is to ~1e-8). The
    derivative comes from the value at the minimiser (envelope theorem: the minimiser's own derivative does not
    enter), so the search is not differentiated; sqrt at a touching segment has the double-where guard.
    """
    q0, q1 = jnp.asarray(q0), jnp.asarray(q1)
    dtype = jnp.result_type(q0.dtype, q1.dtype, jnp.asarray(radius).dtype)
    q0, q1, radius = q0.astype(dtype), q1.astype(dtype), jnp.asarray(radius, dtype)
    d = q1 - q0
    sg = jax.lax.stop_gradient

    # -- the part over the disc: |xy(t)|^2 = a t^2 + b t + c <= 0 on [t_lo, t_hi] (clipped to [0, 1])
    a = d[0] * d[0] + d[1] * d[1]
    b = 2.0 * (q0[0] * d[0] + q0[1] * d[1])
    c = q0[0] * q0[0] + q0[1] * q0[1] - radius * radius
    tiny = jnp.finfo(dtype).tiny
    moves = a > tiny * jnp.maximum(jnp.abs(c), 1.0)           # not a vertical segment
    disc = b * b - 4.0 * a * c
    real = moves & (disc >= 0.0)
    root = jnp.sqrt(jnp.where(real, disc, 0.0) + jnp.where(real, 0.0, 1.0)) * jnp.where(real, 1.0, 0.0)
    a_s = jnp.where(moves, a, 1.0)
    t1 = (-b - root) / (2.0 * a_s)
    t2 = (-b + root) / (2.0 * a_s)
    t_lo = jnp.where(moves, jnp.clip(t1, 0.0, 1.0), 0.0)
    t_hi = jnp.where(moves, jnp.clip(t2, 0.0, 1.0), 1.0)
    over = jnp.where(moves, real & (t1 <= 1.0) & (t2 >= 0.0), c <= 0.0)
    z_over = jnp.minimum(q0[2] + t_lo * d[2], q0[2] + t_hi * d[2])
    through = over & (z_over < 0.0)

    # -- unsigned distance. Over the disc h = z^2 (closed form); beside it h is smooth, so its minimiser there is
    # an end of the piece or the root of h', found by Newton's method (h convex: h' is monotone)
    q0s, ds, rs = sg(q0), sg(d), sg(radius)
    zero, one = jnp.zeros((), dtype), jnp.ones((), dtype)
    tl, th = sg(t_lo), sg(t_hi)
    g_lo, _ = _plate_slope(q0s, ds, tl, rs)
    g_hi, _ = _plate_slope(q0s, ds, th, rs)
    before = over & (g_lo >= 0.0)                    # the minimiser lies in [0, t_lo] (beside the disc)
    after = over & ~before & (g_hi <= 0.0)           # in [t_hi, 1]
    inside = over & ~before & ~after                 # in [t_lo, t_hi], where h = z^2: its zero or an end
    dz = ds[2]
    t_in = jnp.clip(-q0s[2] / jnp.where(dz != 0.0, dz, 1.0), tl, th)
    t_in = jnp.where(dz != 0.0, t_in, tl)
    lo = jnp.where(after, th, zero)
    hi = jnp.where(before, tl, one)
    g_a, _ = _plate_slope(q0s, ds, lo, rs)
    g_b, _ = _plate_slope(q0s, ds, hi, rs)
    end_a, end_b = lo, hi
    # start: the best of PLATE_SAMPLES + 1 even samples of the piece; h convex, so the minimiser lies between that
    # sample's neighbours (the bracket). Newton from a far start crawls where h' bends (a segment grazing the rim)
    n = PLATE_SAMPLES
    width = hi - lo

    def sample(j, best):                            # running minimum over the samples (first on ties)
        t_b, h_b = best
        tj = lo + (j / n) * width
        hj = _plate_h(q0s, ds, tj, rs)
        return jnp.where(hj < h_b, tj, t_b), jnp.where(hj < h_b, hj, h_b)

    t, _ = jax.lax.fori_loop(1, n + 1, sample, (lo, _plate_h(q0s, ds, lo, rs)))
    step = width / n
    lo, hi = jnp.maximum(t - step, end_a), jnp.minimum(t + step, end_b)

    def newton(_, state):                           # safeguarded: a step that leaves the bracket bisects it
        lo, hi, t = state
        g, H = _plate_slope(q0s, ds, t, rs)
        lo, hi = jnp.where(g > 0.0, lo, t), jnp.where(g > 0.0, t, hi)
        tn = t - g * recip(jnp.where(H > 0.0, H, 1.0))
        return lo, hi, jnp.where((H > 0.0) & (tn >= lo) & (tn <= hi), tn, 0.5 * (lo + hi))   # converged: stays

    # loops, not unrolled: traced once, and unrolled they made the search evaluator's program 7x slower (XLA:CPU
    # fused the unrolled search into each consumer of the good-point test)
    _, _, t = jax.lax.fori_loop(0, PLATE_NEWTON_STEPS, newton, (lo, hi, t))
    t_side = jnp.where(g_a >= 0.0, end_a, jnp.where(g_b <= 0.0, end_b, t))   # an end of the piece, or the root
    t_min = sg(jnp.where(inside, t_in, t_side))
    ex, z = _plate_excess(q0, d, t_min, radius)
    h = ex * ex + z * z
    touch = h > 0.0
    dist = jnp.where(touch, jnp.sqrt(jnp.where(touch, h, 1.0)), 0.0)
    return jnp.where(through, z_over, dist)


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


def _interference(robot: Delta, p, theta, ok, links: LinkModel, plate_radius) -> Interference:
    """:func:`interference` of a configuration already guarded (:func:`guarded_configuration`'s stand-ins and its
    ``ok``): each consumer of one configuration guards it once (:func:`good_point`)."""
    B = elbows_unguarded(robot, theta)                                         # (3, 3) base frame
    dirs = jnp.asarray([[math.cos(a), math.sin(a), 0.0] for a in CHAIN_ANGLES], B.dtype)  # chain x axes
    C = p[None, :] + robot.platform_radius * dirs                     # forearm ends at the platform
    A = robot.base_radius * dirs
    pairs = ((0, 1), (1, 2), (2, 0))
    ff = jnp.min(jnp.stack([segment_distance(B[i], C[i], B[j], C[j]) for i, j in pairs])) - 2 * links.forearm_radius
    fu = jnp.min(jnp.stack([segment_distance(B[i], C[i], A[j], B[j]) for i in range(3) for j in range(3) if j != i]))
    fu = fu - links.forearm_radius - links.upper_arm_radius
    Rp = robot.base_radius + links.plate_overhang if plate_radius is None else jnp.asarray(plate_radius, B.dtype)
    ok = ok & jnp.isfinite(Rp) & (Rp >= 0.0)
    Rp = jnp.where(ok, Rp, robot.base_radius)
    plate = jnp.stack([segment_disc_distance(B[i], C[i], Rp) for i in range(3)])
    bp = jnp.minimum(jnp.min(plate) - links.forearm_radius, p[2])
    margin = jnp.minimum(jnp.minimum(ff, fu), bp) - links.clearance
    nan = jnp.asarray(jnp.nan, B.dtype)
    # NaN by where: jnp.minimum does not carry NaN through XLA:CPU's vectorised loops at every batch size
    return Interference(*(jnp.where(ok, v, nan) for v in (ff, fu, bp, margin)))


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
            _check("Motor", n, getattr(self, n), 0.0, True, 1e9)
        _check("Motor", "rotor_inertia", self.rotor_inertia, 0.0, False, 1e3)
        _check("Motor", "efficiency", self.efficiency, 0.0, True, 1.0)
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


def _trap_weights(K, dtype):
    return jnp.ones((K,), dtype).at[0].set(0.5).at[-1].set(0.5) / (K - 1)


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


def _loads_from_unit(a, g, thd_unit, T, dwell, motor: Motor, n, ok):
    """Motor loads at duration T from the T = 1 profile split (a / T^2 + g arm torque, thd_unit / T speed)."""
    scale = 1.0 / (n * motor.efficiency)
    tau_m, om, ratio = _peak_ratio(a, g, thd_unit, T, motor, n)
    K = a.shape[0]
    move = jnp.tensordot(_trap_weights(K, a.dtype), tau_m * tau_m, axes=1) * T   # int tau^2 dt over the motion
    hold = (g[0] * scale) ** 2 + (g[K // 2] * scale) ** 2                       # pick and place dwells
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
    motor, gear_ratio, drive = _guarded_drive(motor, gear_ratio)
    r = with_drive(robot, motor, gear_ratio, payload_mass)
    a, g, thd, ok = _unit_profile(r, cycle)
    ok = ok & drive
    T = cycle.duration if duration is None else jnp.asarray(duration, a.dtype)
    return _loads_from_unit(a, g, thd, T, jnp.asarray(dwell, a.dtype), motor, jnp.asarray(gear_ratio, a.dtype), ok)


def _bisect_time(a, g, thd, motor, n, dwell, T_low, T_high, n_iter):
    def feasible(T):
        L = _loads_from_unit(a, g, thd, T, dwell, motor, n, jnp.asarray(True))
        return (L.peak_utilisation <= 1.0) & (L.rms_utilisation <= 1.0)

    return log_bisect(feasible, T_low, T_high, a.dtype, n_iter)


def _implicit_time(T, a, g, thd, motor, n, dwell, T_low):
    """``T`` (the bisection's value, unchanged) carrying the implicit-function derivative of the active limit.

    Bisection is piecewise constant in the design, so its derivative is zero. At an interior T_min the binding
    limit h(T, design) = max(peak utilisation, RMS utilisation) - 1 is 0, hence dT/d(design) = -h_design / h_T
    (implicit function theorem). The value stays the bisection's exactly (the correction term is
    h - stop_gradient(h) = 0); where T is not interior (inf, NaN, at T_low) or h_T is not negative the
    derivative is zero. Checked against central differences of the bisection (tests/test_constraints.py).
    """
    sg = jax.lax.stop_gradient
    T0 = sg(T)

    def h(T_, a_, g_, thd_, n_, dw_):
        L = _loads_from_unit(a_, g_, thd_, T_, dw_, motor, n_, jnp.asarray(True))
        return jnp.maximum(L.peak_utilisation, L.rms_utilisation) - 1.0

    interior = jnp.isfinite(T0) & (T0 > T_low * (1.0 + 1e-9))
    Ts = jnp.where(interior, T0, 1.0)
    args = (a, g, thd, n, dwell)
    hT = jax.grad(h)(Ts, *(sg(x) for x in args))
    use = interior & jnp.isfinite(hT) & (hT < 0)
    # where not used, the design enters only through stop_gradient: no 0 x inf in the backward pass
    hv = h(Ts, *(jnp.where(use, x, sg(x)) for x in args))
    corr = (hv - sg(hv)) / jnp.where(use, hT, -1.0)
    return T0 - jnp.where(use, corr, 0.0)


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
    motor, gear_ratio, drive = _guarded_drive(motor, gear_ratio)
    r = with_drive(robot, motor, gear_ratio, payload_mass)
    a, g, thd, ok = _unit_profile(r, cycle)
    ok = ok & drive
    n = jnp.asarray(gear_ratio, a.dtype)
    dw = jnp.asarray(dwell, a.dtype)
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
                       n_iter: int = 60) -> tuple:
    """:func:`cycle_rate` with the peak utilisation searched between the samples of ``cycle``.

    At the samples' fastest time T0 (exactly :func:`cycle_rate`'s) ``refine(f, u, V) -> t`` finds the worst point
    of f(t) = -(max over actuators of |tau_m| / envelope(omega_m)) from its values ``V`` (K, 1) at the samples
    ``cycle.u`` (e.g. :func:`deltajax.optimize.cycle_worst.worst_along`), on the path ``path(u (k,)) -> (x, x',
    x'')`` (the one ``cycle`` samples). The cycle time is then the smallest T at which the samples (peak and RMS)
    and that point (peak) all hold, never below T0; the loads there carry the peak over both (RMS and speed: the
    samples'; the RMS is an integral, the samples' trapezoidal rule). NaN everywhere where a sample or the point
    is unreachable. Returns (the refined :class:`CycleRate`, the samples' T0, the samples' peak utilisation at T0).
    """
    from .trajectory import Cycle

    motor, gear_ratio, drive = _guarded_drive(motor, gear_ratio)
    r = with_drive(robot, motor, gear_ratio, payload_mass)
    a, g, thd, ok = _unit_profile(r, cycle)
    ok = ok & drive
    n = jnp.asarray(gear_ratio, a.dtype)
    dw = jnp.asarray(dwell, a.dtype)
    T0 = jnp.where(ok, _bisect_time(a, g, thd, motor, n, dw, T_low, T_high, n_iter), jnp.nan)
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
        L = _loads_from_unit(a, g, thd, T, dw, motor, n, jnp.asarray(True))
        pk = jnp.max(_peak_ratio(a1, g1, thd1, T, motor, n)[2])
        return (L.peak_utilisation <= 1.0) & (L.rms_utilisation <= 1.0) & (pk <= 1.0)

    T = jnp.where(ok, jnp.maximum(T0, log_bisect(feasible, T_low, T_high, a.dtype, n_iter)), jnp.nan)
    ppm = jnp.where(jnp.isfinite(T), 60.0 / (T + 2.0 * dw), jnp.where(jnp.isnan(T), jnp.nan, 0.0))
    Tl = jnp.where(jnp.isfinite(T), T, cycle.duration)
    L = _loads_from_unit(a, g, thd, Tl, dw, motor, n, ok)
    tau1, _, ratio1 = _peak_ratio(a1, g1, thd1, Tl, motor, n)
    nan = jnp.asarray(jnp.nan, a.dtype)
    L = L._replace(peak_torque=jnp.where(ok, jnp.maximum(L.peak_torque, jnp.abs(tau1[0])), nan),
                   peak_utilisation=jnp.where(ok, jnp.maximum(L.peak_utilisation, jnp.max(ratio1)), nan))
    peak0 = _loads_from_unit(a, g, thd, T0l, dw, motor, n, ok).peak_utilisation
    return CycleRate(cycle_time=T, picks_per_min=ppm, loads=L), T0, peak0


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


def good_point_possible(robot: Delta, p: Float[Array, "3"], spec: GoodSpec) -> Bool[Array, ""]:
    """A necessary condition of :func:`good_point` at ~3 % of its cost: reachable and the index at least the
    threshold (the same kernel call that :func:`good_point` makes, without the passive joints and the links, which
    are ~95 % of its cost). False means ``good_point(robot, p, spec).good`` is False, so a caller may skip the full
    test there (:func:`deltajax.optimize.designer.evaluate_designer`'s regular-workspace grid). The threshold is
    relaxed by 1e-9 so that a last-bit difference between the two compiled copies of the kernel can only let a
    point through (to the full test), never drop a good one."""
    k = point_kernel(robot, p, beta=spec.beta)
    v = getattr(k.indices, spec.index)
    return k.ok & (v >= spec.threshold - 1e-9)


@traced_once
def good_point(robot: Delta, p: Float[Array, "3"], spec: GoodSpec, *, plate_radius=None) -> PointCheck:
    """Is ``p`` (m, base frame) in the good workspace of ``robot`` (R frozen)? Margins NaN if unreachable."""
    # the IK solved once: the index kernel's loop closures give the configuration (its ok and cos/sin are
    # ik_cos_sin's, theta is ik's atan2 of them) handed to the passive joints and the links
    k = point_kernel(robot, p, beta=spec.beta)
    ok = k.ok
    cos, sin = jnp.stack([c.cos for c in k.chains]), jnp.stack([c.sin for c in k.chains])
    theta = jnp.arctan2(sin, cos)
    theta = jnp.where(theta <= -jnp.pi, theta + 2.0 * jnp.pi, theta)  # (-pi, pi], as ik
    theta = jnp.where(ok, theta, 0.5)               # a harmless configuration where IK failed
    v = getattr(k.indices, spec.index)
    # the configuration guarded once for both consumers (where the IK is ok it is unchanged)
    robot_g, p_g, theta_g, ok_g = guarded_configuration(robot, p, theta)
    jm = _joint_margin(robot_g, p_g, theta_g, ok_g, spec.joints)
    im = _interference(robot_g, p_g, theta_g, ok_g, spec.links, plate_radius).margin
    nan = jnp.asarray(jnp.nan, jm.dtype)
    v, jm, im = (jnp.where(ok, x, nan) for x in (v, jm, im))
    good = ok & (v >= spec.threshold) & (jm >= 0) & (im >= 0)
    return PointCheck(good=good, reachable=ok, index=v, joint_margin=jm, interference_margin=im)
