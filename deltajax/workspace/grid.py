"""Workspace grids and the per-point kernels evaluated on them (pure, jit/vmap-able).

Grid rule (docs/CONVENTIONS.md): inclusive end points, coordinates built from integer indices, never by accumulating a
float ``arange``. The franco2026 grid is x, y = -0.4 + 0.002 i (i = 0..400), z = 0.002 k (k = 0..299);
we compute each coordinate as ``h * (i + i0)`` with the integer offset ``i0 = lo / h`` whenever ``lo`` is a
whole number of steps, so that a grid symmetric about 0 is *bit-for-bit* symmetric (y -> -y maps grid
points onto grid points exactly; redundancy resolution relies on it, see :mod:`.redundancy`).

Public functions (single robot; vmap over a population of designs with ``in_axes=(0, None)``)::

    grid = make_grid(x=(-0.4, 0.4), y=(-0.4, 0.4), z=(0.0, 0.598), h=0.002)   # Grid (host object)
    pts  = grid.points(start, stop)                 # float64[n, 3], flat C order (x slowest, z fastest)
    reachable_mask(robot, points)      -> bool[N]   # IK ok for all chains, theta within limits
    reachable_fraction(robot, points)  -> float[]   # mean of the mask
    mirrored_point_indices(robot, p)   -> (ok, Indices)    # one point at (x, |y|, z): the core point_kernel
    index_fields(robot, points, ...)   -> (ok[N], {name: float[N]})  # NaN outside the workspace

The kernel (:func:`mirrored_point_indices`) is the core :func:`deltajax.indices.point_kernel`, the algebraic
form: cos/sin of the actuated angles straight from
:func:`deltajax.ik_cos_sin` (no inverse trig), the homogenised theta-block M = Jx^-1 diag(sin th2 sin th3)
and its singular values by :func:`deltajax.indices.singular_values` (no SVD). It agrees with
``dj.indices(robot, p, dj.ik(robot, p).theta)`` to rounding (tested), and it evaluates every point at its
mirror image (x, |y|, z): the robot is symmetric under y -> -y (chain 0 on the x axis, chains 1 and 2 swap),
so this is exact in real arithmetic and makes every field bit-for-bit mirror-symmetric.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Optional, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ..geometry import Delta
from ..indices import INDEX_NAMES, Indices, map_points, point_indices, point_kernel
from ..kinematics import chain_local, design_ok, ik_cos_sin, limit_terms, loop_closure, safe_point

__all__ = [
    "Grid",
    "make_grid",
    "franco2026_grid",
    "reachable_mask",
    "canonical_point",
    "reachable_fraction",
    "point_indices",
    "mirrored_point_indices",
    "index_fields",
    "reach_candidate",
    "box_fields",
    "FIELD_NAMES",
    "CANDIDATE_SLACK",
    "CANDIDATE_SLACK_F32",
]

#: Scalar index fields produced by :func:`index_fields` (the core's :data:`deltajax.INDEX_NAMES`).
FIELD_NAMES = tuple(INDEX_NAMES)


def _axis(lo: float, hi: float, h: float, name: str) -> np.ndarray:
    """Inclusive axis lo, lo + h, ..., hi built from integer indices (m)."""
    lo, hi, h = float(lo), float(hi), float(h)
    for k, v in ((f"{name}[0]", lo), (f"{name}[1]", hi), ("h", h)):
        if not math.isfinite(v):
            raise ValueError(f"grid {k} must be finite, got {v!r}")
    if not h > 0:
        raise ValueError(f"grid spacing h must be > 0 m, got {h!r}")
    if not hi >= lo:
        raise ValueError(f"grid {name} range is empty: ({lo!r}, {hi!r})")
    n_float = (hi - lo) / h
    n = round(n_float)
    if abs(n_float - n) > 1e-6 * max(1.0, n_float):
        raise ValueError(f"grid {name} range ({lo!r}, {hi!r}) m is not a whole number of h={h!r} m steps "
                         f"({n_float:.6f}); inclusive end points need (hi - lo) / h integer")
    i = np.arange(n + 1, dtype=np.int64)
    off = lo / h
    if abs(off - round(off)) <= 1e-9 * max(1.0, abs(off)):
        return h * (i + round(off)).astype(np.float64)  # symmetric ranges stay exactly symmetric
    return lo + h * i.astype(np.float64)


@dataclasses.dataclass(frozen=True, eq=False)
class Grid:
    """A rectangular grid of platform positions (host object; shapes are static).

    Attributes:
        x, y, z: the axes (m, base frame, z down), inclusive end points.
        h: spacing (m), the same on all axes.
        bounds: the enclosing box ((x0, x1), (y0, y1), (z0, z1)) (m) used for the paper's volume
            count / N * V_box; by default the grid's own end points.
    """

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    h: float
    bounds: tuple

    @property
    def shape(self) -> tuple[int, int, int]:
        return (len(self.x), len(self.y), len(self.z))

    @property
    def n_points(self) -> int:
        return int(np.prod(self.shape))

    @property
    def box_volume(self) -> float:
        """V_box of the enclosing box (m^3)."""
        (a, b), (c, d), (e, f) = self.bounds
        return float((b - a) * (d - c) * (f - e))

    @property
    def mirror_symmetric(self) -> bool:
        """Whether y -> -y maps the grid onto itself bit-for-bit."""
        return bool(np.array_equal(self.y, -self.y[::-1]))

    def points(self, start: int = 0, stop: Optional[int] = None) -> np.ndarray:
        """Points ``start:stop`` of the flattened grid (C order: x slowest, z fastest), float64[n, 3] (m)."""
        stop = self.n_points if stop is None else min(int(stop), self.n_points)
        idx = np.arange(int(start), stop, dtype=np.int64)
        return self.points_at(idx)

    def points_at(self, flat_index: np.ndarray) -> np.ndarray:
        """Points at the given flat indices, float64[n, 3] (m)."""
        nx, ny, nz = self.shape
        flat_index = np.asarray(flat_index, dtype=np.int64)
        i, rem = np.divmod(flat_index, ny * nz)
        j, k = np.divmod(rem, nz)
        return np.stack([self.x[i], self.y[j], self.z[k]], axis=-1)

    def mirror_index(self, flat_index: np.ndarray) -> np.ndarray:
        """Flat index of the mirror image (x, -y, z) of each point (requires :attr:`mirror_symmetric`)."""
        nx, ny, nz = self.shape
        i, rem = np.divmod(np.asarray(flat_index, dtype=np.int64), ny * nz)
        j, k = np.divmod(rem, nz)
        return (i * ny + (ny - 1 - j)) * nz + k

    def volume_count(self, count: int) -> float:
        """Volume as count * h^3 (m^3)."""
        return float(count) * self.h ** 3

    def volume_box(self, count: int) -> float:
        """Volume as the paper's count / N * V_box (m^3)."""
        return float(count) / self.n_points * self.box_volume


def make_grid(x: Sequence[float], y: Sequence[float], z: Sequence[float], h: float,
              bounds: Optional[Sequence[Sequence[float]]] = None) -> Grid:
    """Build a grid with inclusive end points.

    Args:
        x, y, z: (lo, hi) of each axis (m); (hi - lo) must be a whole number of steps.
        h: spacing (m).
        bounds: enclosing box for :meth:`Grid.volume_box` (default: the end points).

    Raises:
        ValueError: naming the axis and values when a range is empty, not finite or not a multiple of h.
    """
    ax = _axis(x[0], x[1], h, "x"), _axis(y[0], y[1], h, "y"), _axis(z[0], z[1], h, "z")
    if bounds is None:
        bounds = ((float(x[0]), float(x[1])), (float(y[0]), float(y[1])), (float(z[0]), float(z[1])))
    bounds = tuple((float(a), float(b)) for a, b in bounds)
    return Grid(x=ax[0], y=ax[1], z=ax[2], h=float(h), bounds=bounds)


def franco2026_grid(h: float = 0.002, *, paper_box: bool = True) -> Grid:
    """The grid of Franco-López 2026 §6.1: x, y in [-0.4, 0.4], z = 0, h, ..., 0.6 - h (m).

    At h = 0.002 this is the paper's 401 x 401 x 300 grid. The paper's box is x, y in [-0.4, 0.4],
    z in [0, 0.6] (V_box = 0.384 m^3) while its z samples stop at 0.598; ``paper_box=False`` uses the
    grid's own end points instead.
    """
    nz = round(0.6 / h)
    z_hi = (nz - 1) * h
    bounds = ((-0.4, 0.4), (-0.4, 0.4), (0.0, 0.6)) if paper_box else None
    return make_grid((-0.4, 0.4), (-0.4, 0.4), (0.0, z_hi), h, bounds=bounds)


# -- kernels (pure) ------------------------------------------------------------------------------------------

def canonical_point(p: Float[Array, "3"]) -> Float[Array, "3"]:
    """The mirror image (x, |y|, z): exact for the y -> -y symmetric robot, see the module docstring."""
    return jnp.stack([p[0], jnp.abs(p[1]), p[2]])


def reachable_point(robot: Delta, p: Float[Array, "3"]) -> Bool[Array, ""]:
    """IK solvable for all chains with every theta inside the joint limits (one point)."""
    return jnp.all(ik_cos_sin(robot, canonical_point(jnp.asarray(p))).ok)


def reachable_mask(robot: Delta, points: Float[Array, "n 3"]) -> Bool[Array, "n"]:
    """Reachable mask of ``points`` (m, base frame) for one robot; pure, jit/vmap-able.

    Vmap over designs: ``jax.vmap(reachable_mask, in_axes=(0, None))(robots, points)``.
    """
    return jax.vmap(reachable_point, in_axes=(None, 0))(robot, jnp.asarray(points))


def reachable_fraction(robot: Delta, points: Float[Array, "n 3"]) -> Float[Array, ""]:
    """Fraction of ``points`` that are reachable (multiply by the box volume for a volume)."""
    m = reachable_mask(robot, points)
    return jnp.mean(m.astype(jnp.result_type(float)))


def mirrored_point_indices(robot: Delta, p: Float[Array, "3"], *, b_v: float = 2.0, b_f: float = 4.2,
                           beta: float = 0.5, sv_method: str = "fast") -> tuple[Bool[Array, ""], Indices]:
    """Reachability and all indices (theta3x3, homogenised by L1) at one point, evaluated at its mirror
    image (x, |y|, z) so that fields are bit-for-bit mirror-symmetric; the core
    :func:`deltajax.indices.point_kernel`.

    (Until 2026-12-01 this was ``deltajax.workspace.point_indices``; that name is now the core
    :func:`deltajax.point_indices` itself, one meaning per name.)

    Args:
        robot: the robot (R = ``robot.base_radius``).
        p: platform centre (m, base frame).
        b_v, b_f, beta: parameters of k~.
        sv_method: ``"fast"`` (closed-form cubic, default for fields) or ``"jacobi"`` (exact).

    Returns:
        (ok, indices): ``ok`` is reachability within joint limits; the indices are NaN where not ok.
    """
    out = point_kernel(robot, canonical_point(jnp.asarray(p)), sv_method=sv_method, b_v=b_v, b_f=b_f, beta=beta)
    return out.ok, out.indices


def index_fields(robot: Delta, points: Float[Array, "n 3"], *, b_v: float = 2.0, b_f: float = 4.2,
                 beta: float = 0.5, sv_method: str = "fast") -> tuple[Bool[Array, "n"], dict]:
    """Reachable mask and every scalar index at ``points`` (NaN outside the workspace); pure.

    ``sv_method="fast"`` (default: the closed-form cubic, <= 1e-9 relative to the exact form away from the
    robot's axis, see :func:`deltajax.indices.singular_values`) or ``"jacobi"``.

    Returns:
        (ok[n], {name: float[n]} for name in :data:`FIELD_NAMES`).
    """
    ok, ind = map_points(lambda q: mirrored_point_indices(robot, q, b_v=b_v, b_f=b_f, beta=beta,
                                                          sv_method=sv_method), points)
    return ok, {name: getattr(ind, name) for name in FIELD_NAMES}


# -- compacted evaluation (the workspace_grid JAX path) --------------------------------------------------------

#: slacks of :func:`reach_candidate` in float64: (discriminant, relative to (L1 + L2)^2; joint-limit margin;
#: distance from the motor axis, relative to L1 + L2, below which the margin is not tested). See its docstring.
CANDIDATE_SLACK = (1e-12, 1e-3, 1e-2)
#: the same in float32 (``precision=float32``): roundings ~1e-7 (L1 + L2)^2 in disc need the disc slack 1e4 x
#: eps32 ~ 1.2e-3; its square root, 0.035 (L1 + L2), can move the margin by more than its whole range [-2, 2]
#: near the motor axis, so in float32 the margin is not tested (4 > 2): a reach-only pre-test.
CANDIDATE_SLACK_F32 = (1.2e-3, 4.0, 1e-2)


def reach_candidate(robot: Delta, p: Float[Array, "3"]) -> Bool[Array, ""]:
    """Conservative pre-test of :func:`mirrored_point_indices`' ``ok`` at one point: False only where ``ok`` is
    False, also when the two are compiled into different XLA programs (so that skipping the points where it is
    False cannot change a result).

    The same pieces as the kernel (:func:`deltajax.kinematics.safe_point`, ``design_ok``, ``chain_local``,
    ``loop_closure`` of each chain at the mirror image (x, |y|, z)), with slack instead of the kernel's exact
    tests ``disc >= 0`` and ``margin >= 0``: a chain passes when disc >= -1e-12 (L1 + L2)^2 and the joint-limit
    margin is >= -1e-3 (or the point is within 0.01 (L1 + L2) of the chain's motor axis, where the margin is
    sensitive to the discriminant). Why these suffice: two compilations of the same formulas differ by a few
    ulps, ~1e-16 (L1 + L2)^2 in disc (10^4 below the slack); a disc changed by d changes sqrt(disc) by at most
    sqrt(|d|) <= 1e-6 (L1 + L2) and cos/sin theta, hence the margin, by at most 2 sqrt(|d|) / rho <= 2e-4 for
    rho >= 0.01 (L1 + L2). Points in the slack layer run the full kernel, whose ``ok`` decides. In float32
    the roundings are ~1e-7 (L1 + L2)^2, and the slacks are :data:`CANDIDATE_SLACK_F32` (reach only).
    """
    p = canonical_point(jnp.asarray(p))
    # the kernel computes in the promoted dtype of the point and the design: float32 slacks when that is float32
    f32 = jnp.result_type(p, robot.upper_arm, robot.forearm, robot.base_radius) == jnp.float32
    tol_d, tol_m, tol_r = CANDIDATE_SLACK_F32 if f32 else CANDIDATE_SLACK
    p, usable = safe_point(robot, p)
    L1, L2 = robot.upper_arm, robot.forearm
    scale = (L1 + L2) * (L1 + L2)
    lim = limit_terms(robot.theta_min, robot.theta_max)
    cand = usable & design_ok(robot)
    for i in range(3):
        x, y, z = chain_local(p[0], p[1], p[2], i)
        dx = x + robot.platform_radius - robot.base_radius  # as every kernel evaluates it
        lc = loop_closure(dx, y, z, L1, L2, lim)
        near_axis = dx * dx + z * z < (tol_r * tol_r) * scale
        cand = cand & (lc.disc >= -tol_d * scale) & ((lc.margin >= -tol_m) | near_axis)
    return cand


def box_fields(robot: Delta, xs: Float[Array, "nx"], ys: Float[Array, "ny"], zs: Float[Array, "nz"], *,
               block: int = 4096, b_v: float = 2.0, b_f: float = 4.2, beta: float = 0.5, sv_method: str = "fast"
               ) -> tuple[Bool[Array, "nx ny nz"], Float[Array, "nx ny nz n_index"]]:
    """Reachable mask and every index on the box grid xs x ys x zs, with the kernel run only where it can
    succeed; pure, jit-able, static shapes (unchanged on a GPU). Equal bit for bit to :func:`index_fields` of
    its points run in whole vector-width batches (XLA:CPU compiles a batch's remainder as scalar code, which
    rounds differently by ~1e-14 relative; ok and NaN patterns are identical either way).

    A cheap pass of :func:`reach_candidate` over the box; the candidates' flat indices compacted
    (``jnp.nonzero`` with a static size); the kernel (:func:`mirrored_point_indices`) over them in blocks of
    ``block`` points in a ``lax.fori_loop`` whose trip count is the number of candidate blocks (the last block
    padded with out-of-range indices, whose results are dropped); its results scattered into arrays that are
    ``ok=False`` and NaN everywhere else -- exactly the kernel's output at a point that is not ``ok``.

    Args:
        robot: the robot (concrete or traced).
        xs, ys, zs: the box's axes (m, base frame).
        block: points per kernel block (static).
        b_v, b_f, beta, sv_method: as in :func:`index_fields`.

    Returns:
        (ok[nx, ny, nz], values[nx, ny, nz, len(FIELD_NAMES)]) in :data:`FIELD_NAMES` order.
    """
    xs, ys, zs = jnp.asarray(xs), jnp.asarray(ys), jnp.asarray(zs)
    shape = (xs.shape[0], ys.shape[0], zs.shape[0])
    n = shape[0] * shape[1] * shape[2]
    n_pad = -(-n // block) * block
    X = jnp.broadcast_to(xs[:, None, None], shape).reshape(-1)
    Y = jnp.broadcast_to(ys[None, :, None], shape).reshape(-1)
    Z = jnp.broadcast_to(zs[None, None, :], shape).reshape(-1)
    cand = jax.vmap(reach_candidate, in_axes=(None, 0))(robot, jnp.stack([X, Y, Z], axis=-1))
    count = jnp.sum(cand, dtype=jnp.int32)
    (idx,) = jnp.nonzero(cand, size=n_pad, fill_value=n)  # sorted candidates, then n (out of range: dropped)
    dtype = jnp.result_type(xs.dtype, robot.upper_arm.dtype)
    nyz = shape[1] * shape[2]

    def body(b, carry):
        ok, vals = carry
        ids = jax.lax.dynamic_slice(idx, (b * block,), (block,))
        i, rem = jnp.divmod(ids, nyz)
        j, k = jnp.divmod(rem, shape[2])
        pts = jnp.stack([xs.at[i].get(mode="clip"), ys.at[j].get(mode="clip"), zs.at[k].get(mode="clip")], axis=-1)
        ok_b, ind = jax.vmap(lambda q: mirrored_point_indices(robot, q, b_v=b_v, b_f=b_f, beta=beta,
                                                              sv_method=sv_method))(pts)
        vals_b = jnp.stack([getattr(ind, name) for name in FIELD_NAMES], axis=-1)
        return ok.at[ids].set(ok_b, mode="drop"), vals.at[ids].set(vals_b, mode="drop")

    init = (jnp.zeros(n, bool), jnp.full((n, len(FIELD_NAMES)), jnp.nan, dtype))
    ok, vals = jax.lax.fori_loop(0, (count + block - 1) // block, body, init)
    return ok.reshape(shape), vals.reshape(shape + (len(FIELD_NAMES),))
