"""Jacobian-based performance indices, the singularity-sensitive index k~, singularity classification.

The paper's tabulated numbers (Franco-López 2026, Tables 2-8) are computed from the homogenised 3x3
theta-block M = J^[:, 1:4] of the Jacobian with R frozen (docs/CONVENTIONS.md), not from the 3x4 matrix its prose
describes; ``matrix="theta3x3"`` (default) does that, ``matrix="full3x4"`` uses the homogenised 3x4 J.

Closed-form singular values (hot path). With D = diag(sin th2 sin th3) (the homogenised theta-block of Jq)
and G = Jx Jx^T (Gram matrix of the unit forearm vectors), M^T M = D G^-1 D = D adj(G) D / det(G). The
two largest eigenvalues of the symmetric S = D adj(G) D give sigma_1,2 = sqrt(lambda_1,2(S)) / |det Jx|, and
sigma_3 = |det M| / (sigma_1 sigma_2) with the exact
determinant det M = prod(D) / det Jx (see :func:`singular_values_closed_form`; the eigenvalues come from
cyclic Jacobi sweeps, not Cardano, to stay exact on the robot's axis). ``sv_method="svd"`` uses
``jnp.linalg.svd`` instead.
"""

from __future__ import annotations

from typing import NamedTuple, Optional

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .eigen3 import sym3_top2
from .fastmath import fuse_outputs, recip, sqrt0
from .geometry import Delta
from .jacobian import chain, resolve_length, homogenise, jq_diagonal, jq_theta, jx_det, jx_row
from .kinematics import (branch_sign, from_chain_frames, design_ok, forearm_units, guarded_configuration, limit_terms,
                         passive_angles, safe_point)
from .kinematics import ik_cos_sin

__all__ = [
    "Indices",
    "indices",
    "indices_from_singular_values",
    "singular_values",
    "k_tilde",
    "sigma_tilde",
    "Singularity",
    "classify_singularity",
    "MATRICES",
    "INDEX_NAMES",
    "point_indices",
    "point_kernel",
    "PointKernel",
    "sym3_top2",
    "indices_from_sv",
    "singular_values_closed_form",
    "SvMatrix",
    "sv_matrix",
    "singular_values_from_eig",
    "criterion_of",
    "point_value",
    "SV_METHODS",
    "POINT_BLOCK",
    "map_points",
]

MATRICES = ("theta3x3", "full3x4")
#: Names of the scalar indices returned by :func:`indices`, usable as a redundancy-resolution criterion.
INDEX_NAMES = ("inv_cond", "sigma_min_v", "sigma_min_f", "omega_v", "omega_f", "k_tilde", "manipulability",
               "imi")
#: The range of values of each index, (lo, hi), hi None: unbounded (thresholds on an index must lie in it).
INDEX_RANGES = {name: (0.0, 1.0 if name in ("inv_cond", "k_tilde") else None) for name in INDEX_NAMES}


class Indices(NamedTuple):
    """Performance indices at one configuration (NaN where the configuration is invalid).

    Attributes:
        inv_cond: 1/k = s3 / s1 (0 singular, 1 isotropic).
        sigma_min_v: s3, velocity minimum singular value.
        sigma_min_f: 1 / s1, force minimum singular value.
        omega_v: s1 s2 s3, velocity manipulability (of the homogenised matrix).
        omega_f: 1 / omega_v, force manipulability.
        k_tilde: singularity-sensitive index in [0, 1] (paper Eq. 15-17).
        manipulability: Yoshikawa's sqrt(det(J J^T)) of the *non-homogenised* matrix (m^3/rad^3 for theta3x3).
        imi: inverse manipulability index 1 / sqrt(det(J J^T)) (GA paper), non-homogenised.
        singular_values: (s1, s2, s3), descending, of the homogenised matrix.
    """

    inv_cond: Float[Array, ""]
    sigma_min_v: Float[Array, ""]
    sigma_min_f: Float[Array, ""]
    omega_v: Float[Array, ""]
    omega_f: Float[Array, ""]
    k_tilde: Float[Array, ""]
    manipulability: Float[Array, ""]
    imi: Float[Array, ""]
    singular_values: Float[Array, "3"]


def sigma_tilde(sigma, a, b):
    """Piecewise-quadratic normalisation of a minimum singular value (paper Eq. 16-17).

    1 - ((s - a)/a)^2 on [0, a], 1 - ((s - a)/(b - a))^2 on (a, b], 0 beyond b; NaN stays NaN.
    """
    inside = sigma <= b  # False for NaN and +inf
    s = jnp.where(inside, sigma, a)  # double where: inf/NaN never reach the squares (finite gradients)
    # multiply by the breakpoints' reciprocals (design scalars): a per-point divide would be its own XLA loop
    u = s * (1.0 / a)
    left = u * (2.0 - u)                   # = 1 - (u - 1)^2, exactly 0 at s = 0 (a singular point scores 0)
    right = 1.0 - ((s - a) * (1.0 / (b - a))) ** 2
    val = jnp.where(inside, jnp.where(s <= a, left, right), 0.0)
    return jnp.where(jnp.isnan(sigma), jnp.nan, val)


def k_tilde(sigma_min_v, sigma_min_f, *, b_v=2.0, b_f=4.2, beta=0.5):
    """Singularity-sensitive index k~ = s~_v(sigma_min_v) * s~_f(sigma_min_f), a_v = beta b_v, a_f = (1-beta) b_f."""
    return sigma_tilde(sigma_min_v, beta * b_v, b_v) * sigma_tilde(sigma_min_f, (1.0 - beta) * b_f, b_f)


SV_METHODS = ("fast", "jacobi", "svd")


_sqrt0 = sqrt0  # sqrt(max(x, 0)), finite (zero) derivative at and below 0: deltajax.fastmath.sqrt0


def singular_values(jx, d=None, *, method: str = "fast", with_inverses: bool = False):
    """Singular values s1 >= s2 >= s3 of M = Jx^-1 diag(d), flat (no inverse, no SVD); or, legacy, of a matrix.

    ``singular_values(M)`` (one argument, a 3 x n matrix) is the reference ``jnp.linalg.svd`` and returns an
    array (NaN for a matrix with a non-finite entry, which never reaches LAPACK). The kernel form takes ``jx`` = the 9 entries of Jx row-major (row i = unit forearm vector u_i,
    base frame) and ``d`` = the 3 homogenised Jq diagonal entries (:func:`deltajax.jacobian.jq_theta`) as
    scalars and returns the tuple (s1, s2, s3) of scalars. Two exact reformulations, chosen per point by
    which factor is closer to singular (G = Jx Jx^T, D = diag(d)):

    * Jq side (|det Jx| >= |prod d|): M^T M = D adj(G) D / det G, so s1, s2 = sqrt(eig(D adj(G) D)) / |det Jx|;
    * Jx side (otherwise): M^-1 M^-T = adj(D) G adj(D) / prod(d)^2, so s3, s2 = |prod d| / sqrt(eig(...)).

    The remaining singular value comes from the exact determinant s1 s2 s3 = |prod d| / |det Jx|, so it keeps
    full relative accuracy near either kind of singularity. The two largest eigenvalues come from
    :func:`sym3_top2` (``method="fast"`` closed-form cubic, default; ``"jacobi"`` exact sweeps); both have
    finite derivatives everywhere, repeated singular values (the robot's axis) included.

    Accuracy against LAPACK (solve + SVD of M; franco2026 at R = 0.14..0.46, 50 000 random points each,
    1/k > 1e-3; tests/test_kernel.py): float64 ``"fast"`` <= 6e-13 relative on every singular value off the
    axis and <= 1.1e-13 exactly on the z axis (two equal singular values: the tie rule of
    :func:`_eig_top2_fast`), <= 1e-7 within 1e-5 m of the axis (the cubic's sqrt(eps) split of a nearly
    repeated pair); ``"jacobi"`` <= 6e-13 everywhere. float32: fast <= 2.7e-3, jacobi <= 3e-4.
    """
    if d is None:
        # LAPACK never sees a non-finite entry: it prints "** On entry to DLASCL parameter number 4 had an
        # illegal value" on stdout for inf (a solve through a singular Jx); such a matrix gives NaN here
        fin = jnp.all(jnp.isfinite(jx), axis=(-2, -1))
        s = jnp.linalg.svd(jnp.where(fin[..., None, None], jx, 0.0), compute_uv=False)
        return jnp.where(fin[..., None], s, jnp.nan)
    if method not in ("fast", "jacobi"):
        raise ValueError(f"method must be 'fast' or 'jacobi', got {method!r}")
    m = sv_matrix(jx, d)
    e1, e2 = sym3_top2(m.x00, m.x11, m.x22, m.x01, m.x02, m.x12, m.c2, m.det_x, method)
    return singular_values_from_eig(e1, e2, m.jx_side, m.prod_d, m.det_jx, with_inverses=with_inverses)


class SvMatrix(NamedTuple):
    """The symmetric 3x3 X whose two largest eigenvalues give the singular values of M = Jx^-1 diag(d)
    (:func:`sv_matrix`); scalars.

    Attributes:
        jx_side: X is the Jx side adj(D) G adj(D) (|det Jx| < |prod d|), else the Jq side D adj(G) D.
        prod_d: |d0 d1 d2|.
        det_jx: |det Jx|.
        c2: sum of X's principal 2x2 minors (from the factors, no cancellation).
        det_x: det X (from the factors).
        x00, x11, x22, x01, x02, x12: the entries of X.
    """

    jx_side: Bool[Array, ""]
    prod_d: Float[Array, ""]
    det_jx: Float[Array, ""]
    c2: Float[Array, ""]
    det_x: Float[Array, ""]
    x00: Float[Array, ""]
    x11: Float[Array, ""]
    x22: Float[Array, ""]
    x01: Float[Array, ""]
    x02: Float[Array, ""]
    x12: Float[Array, ""]


def sv_matrix(jx, d) -> SvMatrix:
    """The first half of :func:`singular_values`: X and its invariants from ``jx`` (the 9 entries of Jx,
    row-major) and ``d`` (the 3 homogenised Jq entries), scalars; which side is chosen per point by which factor
    is closer to singular (G = Jx Jx^T, D = diag(d), see :func:`singular_values`)."""
    J = [[jx[3 * i + k] for k in range(3)] for i in range(3)]
    G = {(i, j): J[i][0] * J[j][0] + J[i][1] * J[j][1] + J[i][2] * J[j][2] for i in range(3) for j in range(i, 3)}
    det_jx = jnp.abs(jx_det(*jx))
    prod_d = jnp.abs(d[0] * d[1] * d[2])
    jx_side = det_jx < prod_d
    adj_d = (d[1] * d[2], d[0] * d[2], d[0] * d[1])
    g00, g11, g22, g01, g02, g12 = G[(0, 0)], G[(1, 1)], G[(2, 2)], G[(0, 1)], G[(0, 2)], G[(1, 2)]
    adj_g = {(0, 0): g11 * g22 - g12 * g12, (1, 1): g00 * g22 - g02 * g02, (2, 2): g00 * g11 - g01 * g01,
             (0, 1): g02 * g12 - g01 * g22, (0, 2): g01 * g12 - g02 * g11, (1, 2): g01 * g02 - g00 * g12}
    X = [jnp.where(jx_side, adj_d[i] * G[(i, j)] * adj_d[j], d[i] * adj_g[(i, j)] * d[j])
         for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))]
    # invariants of X without cancellation (principal 2x2 minors of adj(G) are det(G) G_kk):
    # S = D adj(G) D: c2 = det G sum_k G_kk adj_d_k^2, det = prod^2 det(G)^2;
    # T = adj(D) G adj(D): c2 = prod^2 sum_k d_k^2 adjG_kk, det = prod^4 det(G)
    det_g = det_jx * det_jx
    p2d = prod_d * prod_d
    c2 = jnp.where(jx_side,
                   p2d * (d[0] * d[0] * adj_g[(0, 0)] + d[1] * d[1] * adj_g[(1, 1)] + d[2] * d[2] * adj_g[(2, 2)]),
                   det_g * (g00 * adj_d[0] * adj_d[0] + g11 * adj_d[1] * adj_d[1] + g22 * adj_d[2] * adj_d[2]))
    det_x = jnp.where(jx_side, p2d * p2d * det_g, p2d * det_g * det_g)
    return SvMatrix(jx_side, prod_d, det_jx, c2, det_x, *X)


def singular_values_from_eig(e1, e2, jx_side, prod_d, det_jx, *, with_inverses: bool = False):
    """The second half of :func:`singular_values`: (s1, s2, s3) from the two largest eigenvalues e1 >= e2 of
    :func:`sv_matrix`'s X (the third from the exact determinant s1 s2 s3 = |prod d| / |det Jx|); with
    ``with_inverses`` also 1/s1, s1 s2 s3 and its inverse (:class:`_SvTail`)."""
    t = _sv_tail(_sqrt0(e1), _sqrt0(e2), prod_d, det_jx, jx_side)
    return (t.s1, t.s2, t.s3) if not with_inverses else t


class _SvTail(NamedTuple):
    s1: Float[Array, ""]
    s2: Float[Array, ""]
    s3: Float[Array, ""]
    inv_s1: Float[Array, ""]
    omega: Float[Array, ""]
    inv_omega: Float[Array, ""]


def _sv_tail(a, b, prod_d, det_jx, jx_side) -> _SvTail:
    """Singular values, 1/s1, omega = s1 s2 s3 = prod/det and 1/omega from A = sqrt(e1), B = sqrt(e2) with three
    reciprocals (1/det, 1/prod, 1/(A B)) and products: every output is a cheap function of a few values, so
    XLA:CPU computes each from the three reciprocals instead of re-deriving a divide chain per output.

    Jq side (det >= prod): s1 = A / det, s2 = B / det, s3 = prod det / (A B);
    Jx side (prod > det): s1 = A B / (prod det), s2 = prod / B, s3 = prod / A. det = 0 exactly (Jx singular)
    gives s1 = omega = inf (and s2 = inf on the Jq side); prod = 0 gives 1/omega = inf (a value below the smallest
    normal number counts as 0). The reciprocals are deltajax.fastmath's cheap-op ones (one fused loop).
    """
    ab = a * b
    tiny = jnp.finfo(jnp.result_type(ab)).tiny  # recip (deltajax.fastmath) needs a normal argument
    det_pos, prod_pos = det_jx >= tiny, prod_d >= tiny
    z_det = recip(jnp.where(det_pos, det_jx, 1.0))  # double where: finite values and gradients at det = 0
    z_prod = recip(jnp.where(prod_pos, prod_d, 1.0))
    z_ab = recip(jnp.where(ab >= tiny, ab, 1.0))
    s1 = jnp.where(det_pos, jnp.where(jx_side, ab * z_det * z_prod, a * z_det), jnp.inf)
    s2 = jnp.where(jx_side, prod_d * a * z_ab, jnp.where(det_pos, b * z_det, jnp.inf))
    s3 = jnp.where(jx_side, prod_d, prod_d * det_jx) * jnp.where(jx_side, b, 1.0) * z_ab
    inv_s1 = jnp.where(jx_side, prod_d, b) * det_jx * z_ab
    omega = jnp.where(det_pos, prod_d * z_det, jnp.inf)
    inv_omega = jnp.where(prod_pos, det_jx * z_prod, jnp.inf)
    return _SvTail(s1, s2, s3, inv_s1, omega, inv_omega)


def singular_values_closed_form(Jx: Float[Array, "3 3"], dhat: Float[Array, "3"], *,
                                method: str = "jacobi") -> Float[Array, "3"]:
    """Stacked form of :func:`singular_values` for a (3, 3) Jx and (3,) diagonal (kept for callers)."""
    s = singular_values(tuple(Jx[i, k] for i in range(3) for k in range(3)), (dhat[0], dhat[1], dhat[2]),
                        method=method)
    return jnp.stack(fuse_outputs(s))  # stacked after the one fused loop (see _fused_masked)


def indices_from_sv(s1, s2, s3, *, b_v=2.0, b_f=4.2, beta=0.5, raw_scale=1.0, inv_s1=None, omega=None,
                    inv_omega=None) -> Indices:
    """All indices from the singular values s1 >= s2 >= s3 (scalars) of the homogenised matrix.

    ``raw_scale`` converts the homogenised manipulability to the raw one (length**3 for theta3x3). No masking:
    NaN in gives NaN out; s3 = 0 gives inv_cond = sigma_min_v = 0, omega_f = imi = inf. ``inv_s1``, ``omega``
    and ``inv_omega`` (1/s1, s1 s2 s3, its inverse), when the caller has them without a divide
    (:func:`singular_values` ``with_inverses=True``), replace the divides here.
    """
    omega_v = s1 * s2 * s3 if omega is None else omega
    sigma_min_f = 1.0 / s1 if inv_s1 is None else inv_s1
    omega_f = 1.0 / omega_v if inv_omega is None else inv_omega
    return Indices(
        inv_cond=s3 * sigma_min_f,
        sigma_min_v=s3,
        sigma_min_f=sigma_min_f,
        omega_v=omega_v,
        omega_f=omega_f,
        k_tilde=k_tilde(s3, sigma_min_f, b_v=b_v, b_f=b_f, beta=beta),
        manipulability=omega_v * raw_scale,
        imi=omega_f * (1.0 / raw_scale),
        singular_values=jnp.stack([s1, s2, s3]),
    )


def indices_from_singular_values(s: Float[Array, "3"], *, b_v=2.0, b_f=4.2, beta=0.5,
                                 raw_scale: Float[Array, ""] | float = 1.0) -> Indices:
    """All indices from the stacked singular values ``s`` (descending); see :func:`indices_from_sv`."""
    return indices_from_sv(s[0], s[1], s[2], b_v=b_v, b_f=b_f, beta=beta, raw_scale=raw_scale)


def _fused_masked(ok, ind: Indices, sv) -> Indices:
    """``_nan_where_not(ok, ind)`` computed in one XLA:CPU loop (:func:`deltajax.fastmath.fuse_outputs`) from the
    scalar indices and singular values ``sv`` = (s1, s2, s3); the stack comes after the loop (a stack inside it
    makes XLA re-emit the shared algebra per element)."""
    nan = jnp.asarray(jnp.nan, jnp.result_type(sv[0]))
    scal = {k: jnp.where(ok, v, nan) for k, v in ind._asdict().items() if k != "singular_values"}
    scal, sv = fuse_outputs((scal, tuple(jnp.where(ok, v, nan) for v in sv)))
    return Indices(**scal, singular_values=jnp.stack(sv))


def _nan_where_not(ok, ind: Indices) -> Indices:
    nan = jnp.asarray(jnp.nan, ind.sigma_min_v.dtype)
    return Indices(*(jnp.where(ok if v.ndim == jnp.ndim(ok) else ok[..., None], v, nan) for v in ind))


#: Default points per block of :func:`map_points` (0: one plain vmap). The kernel is one XLA:CPU loop
#: (:mod:`deltajax.fastmath`) with no intermediates in memory, so blocks only add loop overhead (measured
#: 1.1-1.6x slower at 4096); it was 4096 while the kernel was ~90 loops with stored intermediates.
POINT_BLOCK = 0


def map_points(fn, points, *, block: Optional[int] = None):
    """``jax.vmap(fn)(points)`` over the leading axis, evaluated in blocks of ``block`` points (``jax.lax.map``
    over blocks): the same values, with block-sized intermediates (for a function whose intermediates would not
    fit in cache).

    ``block=None``: :data:`POINT_BLOCK` on the CPU backend, one block (plain vmap) on accelerators, whose
    throughput needs every point in flight; 0 means one block.
    """
    points = jnp.asarray(points)
    if block is None:
        block = POINT_BLOCK if jax.default_backend() == "cpu" else 0
    n = points.shape[0]
    if block <= 0 or n <= block:
        return jax.vmap(fn)(points)
    nb = -(-n // block)
    # pad with copies of the last point to whole blocks (one compiled block, no separate remainder program);
    # block j holds the points j, j + nb, j + 2 nb, ...: the point axis stays the outer one, so a batch
    # sharded over devices along its points keeps each device on its own points in every block
    pad = jnp.broadcast_to(points[-1:], (nb * block - n,) + points.shape[1:])
    blocks = jnp.swapaxes(jnp.concatenate([points, pad]).reshape((block, nb) + points.shape[1:]), 0, 1)
    out = jax.lax.map(jax.vmap(fn), blocks)
    return jax.tree_util.tree_map(lambda a: jnp.swapaxes(a, 0, 1).reshape((nb * block,) + a.shape[2:])[:n], out)


class PointKernel(NamedTuple):
    """Everything the per-point kernel computes (scalars per point; vmap for batches).

    Attributes:
        ok: valid design, finite point, all three loops close within the joint limits.
        chains: the three :class:`~deltajax.kinematics.LoopClosure` (chain 0, 1, 2).
        det_jx: signed det Jx (0 exactly: skip this sample in redundancy resolution); computed on the
            guarded loop, meaningful where ``ok``.
        indices: every index (theta3x3, homogenised by ``length``), NaN where not ``ok``.
    """

    ok: Bool[Array, ""]
    chains: tuple
    det_jx: Float[Array, ""]
    indices: Indices


def point_kernel(robot: Delta, p: Float[Array, "3"], *, sign: float = 1.0, sv_method: str = "fast",
                 length: Optional[float] = None, b_v: float = 2.0, b_f: float = 4.2, beta: float = 0.5
                 ) -> PointKernel:
    """The one per-point kernel: loop closure -> loop vectors -> Jacobian blocks -> singular values -> indices.

    Flat scalars throughout (under vmap every intermediate is an (N,) array), cos/sin passed through (no
    atan2), no small stacked matrices. Failed points (invalid design, unreachable, non-finite, huge) run
    the algebra on finite stand-ins (double where) so values *and gradients* stay finite; their indices are
    NaN.

    Args:
        robot: the robot (R = ``robot.base_radius``), possibly traced/vmapped.
        p: platform centre (m, base frame).
        sign: IK branch, +1.0 outer (default) or -1.0 inner.
        sv_method: ``"fast"`` (closed-form cubic, default) or ``"jacobi"`` (exact).
        length: homogenising length (default L1).
        b_v, b_f, beta: parameters of k~.
    """
    p = jnp.asarray(p)
    dtype = jnp.result_type(p.dtype, robot.upper_arm.dtype)
    p = p.astype(dtype)
    p, usable = safe_point(robot, p)
    valid = design_ok(robot)
    one = jnp.asarray(1.0, dtype)
    L1 = jnp.where(valid, robot.upper_arm, one)
    L2 = jnp.where(valid, robot.forearm, 2.0 * one)
    L = L1 if length is None else jnp.where(valid, jnp.asarray(length, dtype), one)
    lim = limit_terms(robot.theta_min, robot.theta_max)
    chains, rows, d = [], [], []
    for i in range(3):
        ch = chain(p[0], p[1], p[2], robot.base_radius, robot.platform_radius, L1, L2, lim, i, sign)
        rows.extend(ch.jx)
        d.append(ch.d if length is None else ch.d * (L1 / L))
        chains.append(ch.loop)
    ok = valid & usable & chains[0].ok & chains[1].ok & chains[2].ok
    # double where: a failed point's Jacobian is garbage (finite); the singular values run on a fixed regular
    # stand-in (Jx = I, d = (0.3, 0.5, 0.7): distinct, well separated) so that no inf/NaN meets a zero cotangent
    eye = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    rows = [jnp.where(ok, v, e) for v, e in zip(rows, eye)]
    d = [jnp.where(ok, v, e) for v, e in zip(d, (0.3, 0.5, 0.7))]
    t = singular_values(tuple(rows), tuple(d), method=sv_method, with_inverses=True)
    ind = indices_from_sv(t.s1, t.s2, t.s3, b_v=b_v, b_f=b_f, beta=beta, raw_scale=L ** 3, inv_s1=t.inv_s1,
                          omega=t.omega, inv_omega=t.inv_omega)
    # every output from ONE XLA:CPU loop (deltajax.fastmath.fuse_outputs; outputs a caller drops are removed).
    # Scalars only into the loop: the stacked singular values are stacked after it (a stack inside the fused
    # loop makes XLA re-emit the kernel per element)
    nan = jnp.asarray(jnp.nan, dtype)
    masked = {k: jnp.where(ok, v, nan) for k, v in ind._asdict().items() if k != "singular_values"}
    sv = tuple(jnp.where(ok, v, nan) for v in (t.s1, t.s2, t.s3))
    ok, chains, det_jx, masked, sv = fuse_outputs((ok, tuple(chains), jx_det(*rows), masked, sv))
    return PointKernel(ok=ok, chains=chains, det_jx=det_jx, indices=Indices(**masked, singular_values=jnp.stack(sv)))


def criterion_of(ind: Indices, criterion: str):
    """The index named ``criterion`` (one of :data:`INDEX_NAMES`) of ``ind``: the criterion a redundancy
    resolution maximises (the Numba mirror selects it by its column number)."""
    if criterion not in INDEX_NAMES:
        raise ValueError(f"criterion must be one of {INDEX_NAMES}, got {criterion!r}")
    return getattr(ind, criterion)


def point_value(robot: Delta, p: Float[Array, "3"], criterion: str, *, sv_method: str = "fast", b_v: float = 2.0,
                b_f: float = 4.2, beta: float = 0.5):
    """(feasible, criterion value) of :func:`point_kernel` at one point: feasible = every loop closes within the
    joint limits and det Jx != 0 exactly (redundancy resolution's rule for skipping a sample); the value is NaN
    where the loops do not close (:func:`criterion_of`)."""
    k = point_kernel(robot, p, sv_method=sv_method, b_v=b_v, b_f=b_f, beta=beta)
    return k.ok & (k.det_jx != 0.0), criterion_of(k.indices, criterion)


def _resolve_sv_method(sv_method: str, default: str) -> str:
    aliases = {"closed_form": "jacobi", None: default}
    m = aliases.get(sv_method, sv_method)
    if m not in SV_METHODS:
        raise ValueError(f"sv_method must be one of {SV_METHODS} (or 'closed_form' = 'jacobi'), got {sv_method!r}")
    return m


def indices(robot: Delta, p: Float[Array, "3"], theta: Float[Array, "3"], *, matrix: str = "theta3x3",
            b_v: float = 2.0, b_f: float = 4.2, beta: float = 0.5, length: Optional[float] = None,
            sv_method: str = "jacobi") -> Indices:
    """Performance indices at platform position ``p`` (m, base frame) and actuated angles ``theta`` (rad).

    Args:
        robot: the robot (R frozen at ``robot.base_radius``).
        p: platform centre (m).
        theta: actuated angles (rad). Every index is NaN when theta or p is not finite or the (traced)
            design is invalid (failure as data); p and theta are assumed to be one configuration (use
            :func:`classify_singularity` ``ok`` to check the loop closes).
        matrix: ``"theta3x3"`` (default; the paper's numbers) or ``"full3x4"`` (the homogenised 3x4 J).
        b_v, b_f, beta: parameters of k~ (paper: 2, 4.2, 0.5).
        length: homogenising length (default L1).
        sv_method: ``"jacobi"`` (default, exact closed form of :func:`singular_values`; ``"closed_form"`` is
            its old name), ``"fast"`` (closed-form cubic) or ``"svd"`` (``jnp.linalg.svd``); theta3x3 only
            for the first two.

    Returns:
        :class:`Indices`.
    """
    if matrix not in MATRICES:
        raise ValueError(f"matrix must be one of {MATRICES}, got {matrix!r}")
    method = _resolve_sv_method(sv_method, "jacobi")
    robot, p, theta, ok = guarded_configuration(robot, p, theta)
    L = resolve_length(robot, length)
    u_local = forearm_units(robot, p, theta)
    Jx = from_chain_frames(u_local)
    dhat = jq_diagonal(robot, u_local, theta) / L  # homogenised theta-block diagonal
    if matrix == "theta3x3":
        if method == "svd":
            s = singular_values(jnp.linalg.solve(Jx, jnp.diag(dhat)))
            ind = indices_from_singular_values(s, b_v=b_v, b_f=b_f, beta=beta, raw_scale=L ** 3)
        else:
            c, s_ = jnp.cos(theta), jnp.sin(theta)
            rows, d = [], []
            for i in range(3):
                ux, uy, uz = u_local[i, 0], u_local[i, 1], u_local[i, 2]
                rows.extend(jx_row(ux, uy, uz, i))
                d.append(jq_theta(ux, uz, c[i], s_[i]) * (robot.upper_arm / L))
            sv = singular_values(tuple(rows), tuple(d), method=method)
            ind = indices_from_sv(*sv, b_v=b_v, b_f=b_f, beta=beta, raw_scale=L ** 3)
            return _fused_masked(ok, ind, sv)
        return _nan_where_not(ok, ind)
    Jq = jnp.concatenate([u_local[:, :1], jnp.diag(dhat * L)], axis=1)
    J = jnp.linalg.solve(Jx, Jq)
    s = singular_values(homogenise(J, L))
    ind = indices_from_singular_values(s, b_v=b_v, b_f=b_f, beta=beta)
    manip = jnp.sqrt(jnp.abs(jnp.linalg.det(J @ J.T)))
    return _nan_where_not(ok, ind._replace(manipulability=manip, imi=1.0 / manip))


def point_indices(robot: Delta, p: Float[Array, "3"], *, branch: str = "outer", b_v: float = 2.0,
                  b_f: float = 4.2, beta: float = 0.5, length: Optional[float] = None,
                  sv_method: str = "fast"):
    """IK and all indices of one point (theta3x3): the hot-path kernel :func:`point_kernel`.

    No inverse trig and no SVD. Equals ``indices(robot, p, ik(robot, p).theta)`` to rounding (1e-9 relative
    away from singular poses with the default ``sv_method="fast"``; ``"jacobi"`` for the exact form), with
    NaN indices where the point is not reachable.

    Returns:
        (``IKCosSin``, :class:`Indices`); the ``IKCosSin`` is exactly :func:`deltajax.ik_cos_sin`'s.
    """
    sign = branch_sign(branch)
    method = _resolve_sv_method(sv_method, "fast")
    if method == "svd":
        raise ValueError("point_indices supports sv_method 'fast' or 'jacobi'; use indices(..., sv_method='svd')")
    k = point_kernel(robot, p, sign=sign, sv_method=method, length=length, b_v=b_v, b_f=b_f, beta=beta)
    return ik_cos_sin(robot, p, branch=branch), k.indices


class Singularity(NamedTuple):
    """Singularity classification of one configuration (paper §4 and §5.1).

    Attributes:
        type1: all chains theta3 = pi/2 and theta1 + theta2 = pi (forearms coplanar with the platform).
        type2: all chains theta3 = pi/2 and theta1 + theta2 = pi/2 (forearms vertical).
        type3: number of chains (0..3) with theta2 = 0 and theta1 = pi/2 (vertical, stretched).
        type4: theta2 = 0 for two or more chains that are not of type 3.
        jx_rank: numerical rank of Jx (3 = regular; -1 where not ``ok``).
        jq_rank: numerical rank of the theta-block of Jq (fixed robot; -1 where not ``ok``).
        jq_full_rank: numerical rank of the 3x4 Jq (reconfigurable robot, R column included; -1 where not ``ok``).
        near_singular: any of 1/k, sigma_min_v, sigma_min_f below ``near_tol`` or omega_v, omega_f below
            ``omega_tol`` (paper §5.1: 0.1 and 1e-3).
        singular: any exact (within tolerance) singularity above.
        ok: the input is a valid configuration: design valid, p and theta finite and every loop closes
            (| |C_i - B_i| - L2 | <= 1e-6 L2). Where False every flag is False and the ranks are -1.
        stretched_or_folded: number of chains with sin(theta2) sin(theta3) = 0 within ``rank_tol``
            (theta2 = 0 stretched, pi folded, or the forearm perpendicular to the chain plane):
            exactly the chains whose Jq diagonal entry vanishes.
    """

    type1: Bool[Array, ""]
    type2: Bool[Array, ""]
    type3: Int[Array, ""]
    type4: Bool[Array, ""]
    jx_rank: Int[Array, ""]
    jq_rank: Int[Array, ""]
    jq_full_rank: Int[Array, ""]
    near_singular: Bool[Array, ""]
    singular: Bool[Array, ""]
    ok: Bool[Array, ""]
    stretched_or_folded: Int[Array, ""]


def _angle_close(a, b, tol):
    d = jnp.mod(a - b + jnp.pi, 2.0 * jnp.pi) - jnp.pi
    return jnp.abs(d) <= tol


#: Default relative tolerance of :func:`classify_singularity`'s ranks and stretched/folded test. The IK
#: recovers theta at a stretched/folded chain only to ~sqrt(eps) (its discriminant vanishes there and enters
#: through a square root: ~1e-8 rad in float64), so an exact singularity reached through ``ik`` shows up as
#: |sin th2 sin th3| ~ 1e-8; 1e-6 catches it with margin and is still far below any pose a user would call
#: regular (1/k ~ 1e-6).
SINGULAR_TOL = 1e-6


def classify_singularity(robot: Delta, p: Float[Array, "3"], theta: Float[Array, "3"], *,
                         angle_tol: float = 1e-6, rank_tol: float = SINGULAR_TOL, near_tol: float = 0.1,
                         omega_tol: float = 1e-3) -> Singularity:
    """Classify the singularities of a configuration.

    Args:
        robot, p, theta: the configuration (m, rad), e.g. theta from :func:`deltajax.ik`.
        angle_tol: tolerance on the analytic angle conditions (rad); the stretched test (theta2 = 0) of
            types 3/4 uses ``max(angle_tol, rank_tol)`` (theta2 from IK carries ~1e-8 rad round-off).
        rank_tol: relative tolerance (dimensionless) for the numerical ranks of Jx (singular values of Jx,
            whose rows are unit vectors, below ``rank_tol``) and of Jq (|sin th2 sin th3| below ``rank_tol``);
            default :data:`SINGULAR_TOL` = 1e-6, robust to IK round-off.
        near_tol: threshold on 1/k, sigma_min_v and sigma_min_f for "near singular".
        omega_tol: threshold on omega_v and omega_f for "near singular".
    """
    robot, p, theta, finite = guarded_configuration(robot, p, theta)
    u_local = forearm_units(robot, p, theta)
    closes = jnp.all(jnp.abs(jnp.sqrt(jnp.sum(u_local * u_local, axis=-1)) - 1.0) <= 1e-6)
    ok = finite & closes
    th2, th3 = passive_angles(robot, p, theta)
    half_pi = 0.5 * jnp.pi
    th12 = theta + th2
    t3_plane = _angle_close(th3, half_pi, angle_tol)
    type1 = jnp.all(t3_plane & _angle_close(th12, jnp.pi, angle_tol))
    type2 = jnp.all(t3_plane & _angle_close(th12, half_pi, angle_tol))
    stretched = _angle_close(th2, 0.0, max(angle_tol, rank_tol))
    vertical = stretched & _angle_close(theta, half_pi, max(angle_tol, rank_tol))
    type3 = jnp.sum(vertical).astype(jnp.int32)
    type4 = jnp.sum(stretched & ~vertical) >= 2

    Jx = from_chain_frames(u_local)
    diag = jq_diagonal(robot, u_local, theta)
    Jq = jnp.concatenate([u_local[:, :1], jnp.diag(diag)], axis=1)
    sx = jnp.linalg.svd(Jx, compute_uv=False)
    jx_rank = jnp.sum(sx > rank_tol * jnp.maximum(sx[0], 1e-300)).astype(jnp.int32)
    flat = jnp.abs(diag) <= rank_tol * robot.upper_arm
    jq_rank = jnp.sum(~flat).astype(jnp.int32)
    sq = jnp.linalg.svd(homogenise(Jq, robot.upper_arm), compute_uv=False)
    jq_full_rank = jnp.sum(sq > rank_tol * jnp.maximum(sq[0], 1e-300)).astype(jnp.int32)

    ind = indices(robot, p, theta)
    near = ((ind.inv_cond < near_tol) | (ind.sigma_min_v < near_tol) | (ind.sigma_min_f < near_tol)
            | (ind.omega_v < omega_tol) | (ind.omega_f < omega_tol))
    singular = type1 | type2 | (type3 > 0) | type4 | (jx_rank < 3) | (jq_rank < 3)
    no = jnp.asarray(False)
    m1 = jnp.asarray(-1, jnp.int32)
    return Singularity(type1=type1 & ok, type2=type2 & ok, type3=jnp.where(ok, type3, 0), type4=type4 & ok,
                       jx_rank=jnp.where(ok, jx_rank, m1), jq_rank=jnp.where(ok, jq_rank, m1),
                       jq_full_rank=jnp.where(ok, jq_full_rank, m1), near_singular=(near | singular) & ok,
                       singular=singular & ok, ok=ok | no,
                       stretched_or_folded=jnp.where(ok, jnp.sum(flat), 0).astype(jnp.int32))
