"""Workspace boundary search along rays from a centre (the boundary-search paper), vmapped over all rays.

A boundary point is searched on every ray ``p(rho) = C + rho d(phi, theta)`` from a centre ``C``, with
``d = (sin phi cos theta, sin phi sin theta, cos phi)`` in the base frame of docs/CONVENTIONS.md (z down, into the
workspace): ``phi`` is the polar angle from +z (the paper's phi in [0, 180] deg), ``theta`` the azimuth
from +x (the paper's theta in [0, 360] deg). The reachability test ("Test-Pose") of a point is the core IK,
``dj.ik_cos_sin(robot, p).ok.all()``, restricted to one side of the base plate (``z > 0``) when
``half_space`` is true (the paper: "depending on which side of the base plate the workspace is placed").

Two searches, both returning a *bracket* per ray: ``radius_in`` (the last radius tested reachable) and
``radius_out`` (the first radius tested unreachable), with ``radius_out - radius_in <= eps``:

* :func:`bisect_rays` -- Conti et al.'s bisection, all rays at once: the interval ``[0, rho_max]`` is halved
  ``n = ceil(log2(rho_max / eps))`` times; every ray costs exactly ``n`` Test-Pose calls. (The paper's form,
  "start at rho0, add/subtract rho0/2, rho0/4, ... until the increment is <= eps/2", is the same search with
  ``rho_max = 2 rho0``.)
* :func:`continuation_rays` -- the paper's faster variant: along each azimuth the first ray (phi = 0) is
  bisected; every next ray starts from a prediction made from the previous radius and steps by +-eps until
  the test flips. Predictors: ``"tangent"`` (the paper's: the hypotenuse ``rho_prev / cos(dphi)``),
  ``"previous"`` (``rho_prev``) and ``"linear"`` (``2 rho_prev - rho_prev2``). All azimuths run in parallel
  (``vmap``), the polar angles in sequence (``lax.scan``), the eps-steps in a batched ``while_loop``; the
  per-ray call count is exactly that of the sequential algorithm.

Both searches assume each ray leaves the workspace once (a star-shaped workspace seen from ``C``). The
workspace of the paper's robot is not star-shaped from every centre; :func:`ray_profiles` samples every ray
densely and reports rays that leave and re-enter, the exact ray-integrated volume and the volume the search
puts in doubt. :func:`sector_volume` turns radii into a volume (pyramid sectors / spherical sectors) and
:func:`grid_volume` counts a Cartesian grid as an independent check.
"""

from __future__ import annotations

import math
from functools import partial
from typing import NamedTuple, Optional, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ..geometry import Delta
from ..kinematics import ik_cos_sin
from .grid import make_grid

__all__ = [
    "BoundaryResult",
    "RayProfiles",
    "angle_grid",
    "ray_directions",
    "test_pose",
    "reach_bound",
    "bisection_calls",
    "bisect_rays",
    "continuation_rays",
    "boundary_search",
    "sector_volume",
    "vertex_weights",
    "ray_profiles",
    "grid_volume",
    "GridVolume",
    "METHODS",
    "PREDICTORS",
    "VOLUME_RULES",
]

METHODS = ("conti", "continuation")
PREDICTORS = ("tangent", "previous", "linear")
VOLUME_RULES = ("pyramid", "spherical", "riemann_naive")


class BoundaryResult(NamedTuple):
    """Boundary of the workspace seen from ``centre``, one bracket per ray.

    Attributes:
        centre: the search centre C (m, base frame).
        polar: polar angles phi from +z (rad), shape (n_polar,).
        azimuth: azimuths theta from +x (rad), shape (n_azimuth,).
        radius_in: last radius tested reachable (m), shape (n_azimuth, n_polar); NaN where not ``ok``.
        radius_out: first radius tested unreachable (m); ``radius_out - radius_in <= eps``.
        calls: Test-Pose calls spent on each ray (int32).
        ok: the bracket is valid: C is reachable and the search did not run into ``rho_max``.
    """

    centre: Float[Array, "3"]
    polar: Float[Array, "np"]
    azimuth: Float[Array, "na"]
    radius_in: Float[Array, "na np"]
    radius_out: Float[Array, "na np"]
    calls: Int[Array, "na np"]
    ok: Bool[Array, "na np"]

    @property
    def radius(self) -> Float[Array, "na np"]:
        """Bracket midpoint (m): within eps/2 of the boundary crossing."""
        return 0.5 * (self.radius_in + self.radius_out)


# ------------------------------------------------------------------------------------------------------------
# Angles, directions, the reachability test
# ------------------------------------------------------------------------------------------------------------
def angle_grid(step_deg: float, polar_range_deg: Sequence[float] = (0.0, 180.0),
               azimuth_range_deg: Sequence[float] = (0.0, 360.0)) -> tuple[np.ndarray, np.ndarray]:
    """Inclusive angle samples ``lo + k * step`` (the paper's loops), in radians.

    Args:
        step_deg: angular step (deg), the same for both angles (the paper: 1 or 2 deg).
        polar_range_deg: (lo, hi) of the polar angle phi (deg), within [0, 180].
        azimuth_range_deg: (lo, hi) of the azimuth theta (deg), width at most 360.

    Returns:
        (polar, azimuth) in rad as float64 NumPy arrays. With the defaults and 2 deg: 91 x 181 rays (the
        azimuth 360 deg repeats 0 deg, as in the paper's loops; :func:`vertex_weights` gives it no double weight).

    Raises:
        ValueError: step not positive, a range that the step does not divide, or ranges out of bounds.
    """
    step = float(step_deg)
    if not (math.isfinite(step) and step > 0):
        raise ValueError(f"angular step must be a positive number of degrees, got {step_deg!r}")
    out = []
    for name, (lo, hi), lim in (("polar", polar_range_deg, (0.0, 180.0)),
                                ("azimuth", azimuth_range_deg, (-360.0, 360.0))):
        lo, hi = float(lo), float(hi)
        if not (lim[0] <= lo < hi <= lim[1]) or (name == "azimuth" and hi - lo > 360.0 + 1e-9):
            raise ValueError(f"{name} range must satisfy {lim[0]} <= lo < hi <= {lim[1]} deg"
                             f"{' and hi - lo <= 360' if name == 'azimuth' else ''}, got ({lo}, {hi})")
        n = (hi - lo) / step
        if abs(n - round(n)) > 1e-9 * max(1.0, n):
            raise ValueError(f"angular step {step} deg does not divide the {name} range ({lo}, {hi}) deg")
        k = np.arange(int(round(n)) + 1, dtype=np.float64)
        out.append(np.deg2rad(lo + step * k))
    return out[0], out[1]


def ray_directions(polar: Float[Array, "np"], azimuth: Float[Array, "na"]) -> Float[Array, "na np 3"]:
    """Unit ray directions ``d[j, i] = (sin phi_i cos theta_j, sin phi_i sin theta_j, cos phi_i)``."""
    polar, azimuth = jnp.asarray(polar), jnp.asarray(azimuth)
    sp, cp = jnp.sin(polar)[None, :], jnp.cos(polar)[None, :]
    st, ct = jnp.sin(azimuth)[:, None], jnp.cos(azimuth)[:, None]
    shape = (azimuth.shape[0], polar.shape[0])
    return jnp.stack([sp * ct, sp * st, jnp.broadcast_to(cp, shape)], axis=-1)


def test_pose(robot: Delta, p: Float[Array, "3"], half_space: bool = True) -> Bool[Array, ""]:
    """The paper's Test-Pose: is P reachable (IK solvable for all chains, within joint limits)?

    Args:
        robot: the robot.
        p: platform centre P (m, base frame, z down).
        half_space: also require ``p_z > 0`` (the workspace on the far side of the base plate).
    """
    ok = jnp.all(ik_cos_sin(robot, p).ok)
    return ok & (p[2] > 0.0) if half_space else ok


test_pose.__test__ = False  # not a pytest test despite the name


def reach_bound(robot: Delta, centre: Sequence[float]) -> float:
    """A radius from ``centre`` beyond which nothing is reachable (m): ``max_i |C - A_i| + L1 + L2 + r``.

    Every reachable P is within L1 + L2 of the point A_i - r u_i of each chain; a safe ``rho_max`` default.
    """
    c = np.asarray(centre, dtype=np.float64)
    R, r = float(robot.base_radius), float(robot.platform_radius)
    ang = np.array([0.0, 2 * np.pi / 3, 4 * np.pi / 3])
    a = np.stack([R * np.cos(ang), R * np.sin(ang), np.zeros(3)], -1)
    return float(np.max(np.linalg.norm(a - c[None, :], axis=-1)) + robot.upper_arm + robot.forearm + abs(r))


def bisection_calls(rho_max: float, eps: float) -> int:
    """Test-Pose calls per ray of the bisection: ``ceil(log2(rho_max / eps))`` (bracket width <= eps)."""
    if not (eps > 0 and rho_max > eps):
        raise ValueError(f"need 0 < eps < rho_max, got eps={eps!r}, rho_max={rho_max!r}")
    n = math.ceil(math.log2(rho_max / eps) - 1e-12)
    return max(n, 1)


def _check_search_args(eps: float, rho_max: float) -> None:
    if not (isinstance(eps, (int, float)) and math.isfinite(eps) and eps > 0):
        raise ValueError(f"eps must be a positive number (m), got {eps!r}")
    if not (isinstance(rho_max, (int, float)) and math.isfinite(rho_max) and rho_max > eps):
        raise ValueError(f"rho_max must be a number > eps (m), got {rho_max!r}")


# ------------------------------------------------------------------------------------------------------------
# Conti et al.: bisection on every ray at once
# ------------------------------------------------------------------------------------------------------------
def _bisect(robot, centre, dirs, rho_max, n_iter: int, half_space: bool):
    """Bisection of [0, rho_max] on rays ``dirs`` (..., 3); returns (lo, hi) after n_iter tests."""
    test = jax.vmap(lambda p: test_pose(robot, p, half_space))
    flat = dirs.reshape(-1, 3)
    lo = jnp.zeros(flat.shape[0], flat.dtype)
    hi = jnp.full(flat.shape[0], rho_max, flat.dtype)

    def body(_, lohi):
        lo, hi = lohi
        mid = 0.5 * (lo + hi)
        inside = test(centre[None, :] + mid[:, None] * flat)
        return jnp.where(inside, mid, lo), jnp.where(inside, hi, mid)

    lo, hi = jax.lax.fori_loop(0, n_iter, body, (lo, hi))
    return lo.reshape(dirs.shape[:-1]), hi.reshape(dirs.shape[:-1])


@partial(jax.jit, static_argnames=("n_iter", "half_space"))
def _bisect_jit(robot, centre, polar, azimuth, rho_max, n_iter, half_space):
    dirs = ray_directions(polar, azimuth)
    lo, hi = _bisect(robot, centre, dirs, rho_max, n_iter, half_space)
    centre_ok = test_pose(robot, centre, half_space)
    ok = centre_ok & (hi < rho_max)  # hi == rho_max: every test was true, the search saturated
    calls = jnp.full(lo.shape, n_iter, jnp.int32)
    nan = jnp.asarray(jnp.nan, lo.dtype)
    return BoundaryResult(centre, polar, azimuth, jnp.where(ok, lo, nan), jnp.where(ok, hi, nan), calls, ok)


def _prep(robot, centre, polar, azimuth):
    dtype = jnp.result_type(robot.upper_arm.dtype, float)
    return (jnp.asarray(centre, dtype).reshape(3), jnp.asarray(polar, dtype), jnp.asarray(azimuth, dtype))


def bisect_rays(robot: Delta, centre: Sequence[float], polar, azimuth, *, eps: float, rho_max: float,
                half_space: bool = True) -> BoundaryResult:
    """Conti et al.'s bisection on all rays (azimuth x polar) at once.

    Args:
        robot: the robot.
        centre: search centre C (m, base frame); must be reachable.
        polar: polar angles (rad), e.g. from :func:`angle_grid`.
        azimuth: azimuths (rad).
        eps: tolerance (m): the bracket ``[radius_in, radius_out]`` is at most eps wide.
        rho_max: outer end of the search interval (m), assumed unreachable (not tested, as in the paper);
            rays where every test was true come back ``ok=False``.
        half_space: Test-Pose also requires ``z > 0``.

    Returns:
        :class:`BoundaryResult`; ``calls`` is :func:`bisection_calls` on every ray.
    """
    _check_search_args(eps, rho_max)
    c, ph, az = _prep(robot, centre, polar, azimuth)
    return _bisect_jit(robot, c, ph, az, jnp.asarray(rho_max, c.dtype), bisection_calls(rho_max, eps),
                       bool(half_space))


# ------------------------------------------------------------------------------------------------------------
# The paper's continuation variant
# ------------------------------------------------------------------------------------------------------------
def _step_search(test_at, rho0, eps, rho_max, max_steps):
    """Step from rho0 by +-eps until Test-Pose flips (one ray; vmap it).

    Returns (radius_in, radius_out, calls, ok). Radii are ``rho0 + k eps`` (no accumulated sums); stepping
    down stops at the centre (rho = 0, reachable by assumption), stepping up at rho_max (ok = False).
    The first loop iteration (k = 0) is the test at rho0 itself, so Test-Pose has a single call site
    (one copy of the IK in the compiled loop: compiles faster).
    """
    rho0 = jnp.clip(rho0, 0.0, rho_max)

    def radius(k, t0):
        return jnp.clip(rho0 + jnp.where(t0, 1.0, -1.0) * k * eps, 0.0, rho_max)

    def cond(state):
        k, t0, flipped = state
        r = radius(k, t0)
        at_end = jnp.where(t0, r >= rho_max, r <= 0.0)
        return (k < 0) | (~flipped & ~at_end & (k < max_steps))

    def body(state):
        k, t0, _ = state
        k = k + 1
        t = test_at(radius(k, t0))
        first = k == 0
        return k, jnp.where(first, t, t0), ~first & (t != t0)

    k, t0, flipped = jax.lax.while_loop(cond, body, (jnp.full((), -1, jnp.int32), jnp.asarray(True),
                                                     jnp.asarray(False)))
    r_k, r_prev = radius(k, t0), radius(k - 1, t0)
    # Up (t0 true): r_prev reachable, r_k not. Down (t0 false): r_k reachable, r_prev not.
    # Ran into rho = 0 without a flip: the centre itself (reachable) is the inner end.
    r_in = jnp.where(t0, r_prev, jnp.where(flipped, r_k, 0.0))
    r_out = jnp.where(t0, r_k, r_prev)
    ok = flipped | ~t0
    return r_in, r_out, k + 1, ok


@partial(jax.jit, static_argnames=("max_steps", "predictor", "half_space"))
def _continuation_jit(robot, centre, polar, azimuth, first, eps, rho_max, max_steps, predictor, half_space):
    dirs = ray_directions(polar, azimuth)  # (na, np, 3)
    # First ray of every azimuth: the bisection result ``first`` (computed by its own jitted function).
    lo, hi, calls0 = first.radius_in[:, 0], first.radius_out[:, 0], first.calls[:, 0]
    ok0 = first.ok[:, 0]
    lo = jnp.where(ok0, lo, 0.0)

    def one_ray(d, rho0):
        return _step_search(lambda rho: test_pose(robot, centre + rho * d, half_space), rho0, eps, rho_max,
                            max_steps)

    rays = jax.vmap(one_ray)

    def step(carry, xs):
        prev, prev2 = carry  # radius_in of the previous two rays on each azimuth
        d, dphi = xs
        if predictor == "tangent":
            rho0 = prev / jnp.cos(dphi)
        elif predictor == "linear":
            rho0 = 2.0 * prev - prev2
        else:
            rho0 = prev
        r_in, r_out, calls, ok = rays(d, rho0)
        return (r_in, prev), (r_in, r_out, calls, ok)

    dphi = jnp.diff(polar)
    xs = (jnp.moveaxis(dirs[:, 1:, :], 1, 0), dphi)
    _, (r_in, r_out, calls, ok) = jax.lax.scan(step, (lo, lo), xs)
    r_in = jnp.concatenate([lo[:, None], r_in.T], axis=1)
    r_out = jnp.concatenate([hi[:, None], r_out.T], axis=1)
    calls = jnp.concatenate([calls0[:, None], calls.T], axis=1)
    # Stepping down to rho = 0 takes the centre as the inner end: valid only if the centre is reachable.
    ok = jnp.concatenate([ok0[:, None], ok.T], axis=1) & test_pose(robot, centre, half_space)
    nan = jnp.asarray(jnp.nan, r_in.dtype)
    return BoundaryResult(centre, polar, azimuth, jnp.where(ok, r_in, nan), jnp.where(ok, r_out, nan), calls, ok)


def continuation_rays(robot: Delta, centre: Sequence[float], polar, azimuth, *, eps: float, rho_max: float,
                      predictor: str = "tangent", half_space: bool = True) -> BoundaryResult:
    """The paper's continuation search: bisect phi = polar[0], then step +-eps from a prediction.

    Args:
        robot, centre, polar, azimuth, eps, rho_max, half_space: as in :func:`bisect_rays`.
        predictor: initial radius of each next ray from the previous one(s) on the same azimuth:
            ``"tangent"`` (paper, ``rho_prev / cos(dphi)``), ``"previous"`` or ``"linear"``.

    Returns:
        :class:`BoundaryResult`; ``calls`` counts every Test-Pose evaluation of the sequential algorithm
        (bisection calls on the first ray, then 1 + number of eps-steps on each next ray).
    """
    _check_search_args(eps, rho_max)
    if predictor not in PREDICTORS:
        raise ValueError(f"predictor must be one of {PREDICTORS}, got {predictor!r}")
    c, ph, az = _prep(robot, centre, polar, azimuth)
    if ph.shape[0] < 2:
        raise ValueError("continuation needs at least two polar angles")
    max_steps = int(math.ceil(rho_max / eps)) + 2
    rmax = jnp.asarray(rho_max, c.dtype)
    first = _bisect_jit(robot, c, ph[:1], az, rmax, bisection_calls(rho_max, eps), bool(half_space))
    return _continuation_jit(robot, c, ph, az, first, jnp.asarray(eps, c.dtype), rmax, max_steps, predictor,
                             bool(half_space))


def boundary_search(robot: Delta, centre: Sequence[float], *, step_deg: float = 1.0, eps: float = 0.01,
                    rho_max: Optional[float] = None, method: str = "continuation", predictor: str = "tangent",
                    half_space: bool = True, polar_range_deg: Sequence[float] = (0.0, 180.0),
                    azimuth_range_deg: Sequence[float] = (0.0, 360.0)) -> BoundaryResult:
    """Boundary of the workspace seen from ``centre`` on the paper's inclusive angle grid.

    Args:
        robot: the robot.
        centre: search centre C (m, base frame).
        step_deg: angular step of both angles (deg).
        eps: tolerance (m).
        rho_max: search radius (m); default :func:`reach_bound`.
        method: ``"conti"`` (bisection on every ray) or ``"continuation"`` (the paper's variant).
        predictor: continuation predictor (see :func:`continuation_rays`).
        half_space: Test-Pose also requires ``z > 0``.
        polar_range_deg, azimuth_range_deg: angle ranges (deg).
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    polar, azimuth = angle_grid(step_deg, polar_range_deg, azimuth_range_deg)
    if rho_max is None:
        rho_max = reach_bound(robot, centre)
    if method == "conti":
        return bisect_rays(robot, centre, polar, azimuth, eps=eps, rho_max=rho_max, half_space=half_space)
    return continuation_rays(robot, centre, polar, azimuth, eps=eps, rho_max=rho_max, predictor=predictor,
                             half_space=half_space)


# ------------------------------------------------------------------------------------------------------------
# Volumes
# ------------------------------------------------------------------------------------------------------------
def _azimuth_is_full_circle(azimuth: np.ndarray) -> bool:
    return abs((azimuth[-1] - azimuth[0]) - 2 * np.pi) < 1e-9


def vertex_weights(polar, azimuth) -> np.ndarray:
    """Solid angle (sr) attached to each ray (azimuth x polar) for vertex quadrature.

    Each ray owns the half cells around it: ``(cos phi_{i-1/2} - cos phi_{i+1/2}) * dtheta_j``, with the
    polar half cells clipped to the range ends and the azimuth half cells likewise (so the repeated
    azimuth 360 deg and 0 deg each own half a cell). The weights sum to the solid angle of the angle range
    (4 pi for the full sphere).
    """
    ph, az = np.asarray(polar, np.float64), np.asarray(azimuth, np.float64)
    pe = np.concatenate([[ph[0]], 0.5 * (ph[1:] + ph[:-1]), [ph[-1]]])
    ae = np.concatenate([[az[0]], 0.5 * (az[1:] + az[:-1]), [az[-1]]])
    wp = np.cos(pe[:-1]) - np.cos(pe[1:])
    wa = np.diff(ae)
    return wa[:, None] * wp[None, :]


def sector_volume(radius, polar, azimuth, rule: str = "pyramid") -> float:
    """Volume enclosed by a radius function on an (azimuth x polar) grid, seen from its centre (m^3).

    Args:
        radius: boundary radius per ray (m), shape (n_azimuth, n_polar); NaN rays make the result NaN.
        polar, azimuth: the angle samples (rad), inclusive ends as from :func:`angle_grid`.
        rule: ``"pyramid"``: each grid cell is a pyramid sector with apex at the centre and the four boundary
            points as base, split into two tetrahedra (exact volume of the star polyhedron; a sphere comes out
            slightly small, as for any inscribed polyhedron); ``"spherical"``: vertex quadrature
            ``sum w_ij rho_ij^3 / 3`` with the exact solid angles of :func:`vertex_weights` (exact for a
            sphere); ``"riemann_naive"``: ``sum rho^3/3 sin(phi) dphi dtheta`` over every sample, the repeated
            azimuth included (what a direct loop over the paper's inclusive angle ranges gives).

    Returns:
        The volume (m^3) as a Python float.
    """
    rho = np.asarray(radius, np.float64)
    ph, az = np.asarray(polar, np.float64), np.asarray(azimuth, np.float64)
    if rho.shape != (az.size, ph.size):
        raise ValueError(f"radius has shape {rho.shape}, expected (n_azimuth, n_polar) = {(az.size, ph.size)}")
    if rule == "spherical":
        return float(np.sum(vertex_weights(ph, az) * rho ** 3) / 3.0)
    if rule == "riemann_naive":
        dphi = np.diff(ph).mean() if ph.size > 1 else 0.0
        dth = np.diff(az).mean() if az.size > 1 else 0.0
        return float(np.sum(rho ** 3 * np.sin(ph)[None, :]) * dphi * dth / 3.0)
    if rule != "pyramid":
        raise ValueError(f"volume rule must be one of {VOLUME_RULES}, got {rule!r}")
    d = np.asarray(ray_directions(ph, az), np.float64)
    q = rho[..., None] * d  # boundary points relative to the centre
    a, b, c, e = q[:-1, :-1], q[1:, :-1], q[1:, 1:], q[:-1, 1:]

    def tet(u, v, w):
        return np.abs(np.einsum("...i,...i->...", u, np.cross(v, w))) / 6.0

    return float(np.sum(tet(a, b, c)) + np.sum(tet(a, c, e)))


class RayProfiles(NamedTuple):
    """Dense samples along every ray (see :func:`ray_profiles`); arrays are (n_azimuth, n_polar).

    Attributes:
        n_exits: number of inside -> outside transitions along the ray (1 for a star-shaped ray).
        first_exit: radius of the first exit (m), midpoint between the two samples around it.
        last_exit: radius of the last exit (m): the outermost boundary on the ray.
        reentry_beyond: some sample beyond ``radius_out`` (the searched boundary) is reachable.
        hole_before: some sample before ``radius_in`` is unreachable.
        vol_integrand: ``int 1[reachable] rho^2 drho`` along the ray (m^3/sr): its solid-angle sum is the
            exact workspace volume, star-shaped or not.
        vol_missed: ``int_{rho > radius_out} 1[reachable] rho^2 drho``: reachable but outside the sector.
        vol_false: ``int_{rho < radius_in} 1[unreachable] rho^2 drho``: inside the sector but unreachable.
    """

    n_exits: Int[Array, "na np"]
    first_exit: Float[Array, "na np"]
    last_exit: Float[Array, "na np"]
    reentry_beyond: Bool[Array, "na np"]
    hole_before: Bool[Array, "na np"]
    vol_integrand: Float[Array, "na np"]
    vol_missed: Float[Array, "na np"]
    vol_false: Float[Array, "na np"]


@partial(jax.jit, static_argnames=("n_samples", "chunk", "half_space"))
def _profiles_jit(robot, centre, dirs, r_in, r_out, rho_max, n_samples, chunk, half_space):
    dr = rho_max / n_samples
    rho = (jnp.arange(n_samples, dtype=dirs.dtype) + 0.5) * dr  # midpoint rule
    test = jax.vmap(jax.vmap(lambda p: test_pose(robot, p, half_space)))

    def one_chunk(args):
        d, lo, hi = args  # (chunk, 3), (chunk,), (chunk,)
        pts = centre[None, None, :] + rho[None, :, None] * d[:, None, :]
        inside = test(pts)  # (chunk, n)
        nxt = jnp.concatenate([inside[:, 1:], jnp.zeros_like(inside[:, :1])], axis=1)
        exits = inside & ~nxt
        n_exits = jnp.sum(exits, axis=1).astype(jnp.int32)
        idx = jnp.arange(n_samples)[None, :]
        first = jnp.min(jnp.where(exits, idx, n_samples), axis=1)
        last = jnp.max(jnp.where(exits, idx, -1), axis=1)
        w = rho[None, :] ** 2 * dr
        beyond = rho[None, :] > hi[:, None]
        before = rho[None, :] < lo[:, None]
        return (n_exits, (first + 1.0) * dr, (last + 1.0) * dr,
                jnp.any(inside & beyond, axis=1), jnp.any(~inside & before, axis=1),
                jnp.sum(jnp.where(inside, w, 0.0), axis=1), jnp.sum(jnp.where(inside & beyond, w, 0.0), axis=1),
                jnp.sum(jnp.where(~inside & before, w, 0.0), axis=1))

    n = dirs.shape[0]
    pad = (-n) % chunk
    def padded(x):
        return jnp.concatenate([x, jnp.repeat(x[-1:], pad, axis=0)], axis=0) if pad else x
    d, lo, hi = padded(dirs), padded(r_in), padded(r_out)
    m = d.shape[0] // chunk
    outs = jax.lax.map(one_chunk, (d.reshape(m, chunk, 3), lo.reshape(m, chunk), hi.reshape(m, chunk)))
    return tuple(o.reshape(-1)[:n] for o in outs)


def ray_profiles(robot: Delta, result: BoundaryResult, *, rho_max: float, n_samples: int = 1024,
                 half_space: bool = True, chunk: int = 512) -> RayProfiles:
    """Sample every ray of ``result`` densely (vmapped, chunked) to find rays that leave and re-enter.

    Args:
        robot: the robot searched.
        result: a boundary search result (its bracket is compared with the samples).
        rho_max: sample the rays on (0, rho_max] (m).
        n_samples: samples per ray (midpoints of n_samples equal cells); features thinner than
            ``rho_max / n_samples`` can be missed.
        half_space: Test-Pose also requires ``z > 0`` (use the same as for the search).
        chunk: rays per chunk (memory ~ chunk * n_samples).

    Returns:
        :class:`RayProfiles`, arrays shaped like ``result.radius_in``.
    """
    if not (isinstance(n_samples, int) and n_samples >= 2):
        raise ValueError(f"n_samples must be an integer >= 2, got {n_samples!r}")
    if not (isinstance(rho_max, (int, float)) and math.isfinite(rho_max) and rho_max > 0):
        raise ValueError(f"rho_max must be a positive number (m), got {rho_max!r}")
    dirs = ray_directions(result.polar, result.azimuth)
    shape = dirs.shape[:-1]
    big = jnp.asarray(rho_max, dirs.dtype) * 2
    r_in = jnp.where(result.ok, result.radius_in, 0.0).reshape(-1)
    r_out = jnp.where(result.ok, result.radius_out, big).reshape(-1)
    outs = _profiles_jit(robot, jnp.asarray(result.centre), dirs.reshape(-1, 3), r_in, r_out,
                         jnp.asarray(rho_max, dirs.dtype), int(n_samples), int(min(chunk, dirs[..., 0].size)),
                         bool(half_space))
    return RayProfiles(*(o.reshape(shape) for o in outs))


# ------------------------------------------------------------------------------------------------------------
# Independent check: Cartesian grid volume (the workspace engine's grid and reachable mask)
# ------------------------------------------------------------------------------------------------------------
class GridVolume(NamedTuple):
    """Reachable volume counted on a cell-centred Cartesian grid.

    Attributes:
        volume: ``count * h^3`` (m^3).
        count: reachable cells.
        centroid: mean of the reachable cell centres (m, base frame).
        h: grid step (m).
        shape: grid shape (nx, ny, nz).
    """

    volume: float
    count: int
    centroid: np.ndarray
    h: float
    shape: tuple


@partial(jax.jit, static_argnames=("half_space",))
def _count_chunk(robot, pts, valid, half_space):
    m = jax.vmap(lambda p: test_pose(robot, p, half_space))(pts) & valid
    w = m.astype(pts.dtype)
    return jnp.sum(m.astype(jnp.int64 if jax.config.jax_enable_x64 else jnp.int32)), w @ pts


def grid_volume(robot: Delta, h: float, bounds: Sequence[Sequence[float]], *, half_space: bool = True,
                chunk: int = 1 << 21, progress=None) -> GridVolume:
    """Volume of the reachable set counted on a cell-centred grid, ``count * h^3``, and its centroid.

    The cells tile the box ``bounds = ((x0, x1), (y0, y1), (z0, z1))`` (m; each side a whole number of h);
    their centres ``lo + h/2 + k h`` come from :func:`deltajax.workspace.make_grid`, so no sample lies on the
    plane z = 0 when z0 = 0. The box must contain the workspace. Reachability is :func:`test_pose` (the
    workspace engine's reachable mask plus the ``z > 0`` side when ``half_space``).

    Args:
        robot: the robot.
        h: grid step (m).
        bounds: the box (m).
        half_space: count only z > 0.
        chunk: points per evaluation (memory bound).
        progress: optional wrapper ``progress(iterable, total=)`` (e.g. ``ctx.progress``).
    """
    if not (isinstance(h, (int, float)) and math.isfinite(h) and h > 0):
        raise ValueError(f"grid step h must be a positive number (m), got {h!r}")
    for name, (lo, hi) in zip("xyz", bounds):
        n = (hi - lo) / h
        if not (n >= 1 and abs(n - round(n)) <= 1e-6 * n):
            raise ValueError(f"grid box side {name} = ({lo}, {hi}) m must be a whole number (>= 1) of h = {h} m")
    half = 0.5 * float(h)
    grid = make_grid(*((lo + half, hi - half) for lo, hi in bounds), h=float(h))
    dtype = jnp.result_type(robot.upper_arm.dtype, float)
    n = grid.n_points
    starts = range(0, n, chunk)
    if progress is not None:
        starts = progress(starts, total=len(starts))
    count, moment = 0, np.zeros(3)
    for s in starts:
        pts = grid.points(s, s + chunk)
        k = pts.shape[0]
        valid = np.arange(chunk) < k
        if k < chunk:
            pts = np.concatenate([pts, np.zeros((chunk - k, 3))], axis=0)
        c, mom = _count_chunk(robot, jnp.asarray(pts, dtype), jnp.asarray(valid), bool(half_space))
        count += int(c)
        moment += np.asarray(mom, np.float64)
    centroid = moment / max(count, 1)
    return GridVolume(volume=count * float(h) ** 3, count=count, centroid=centroid, h=float(h), shape=grid.shape)
