"""Jacobian-based performance indices, the singularity-sensitive index k~, singularity classification.

The paper's tabulated numbers (Franco-López 2026, Tables 2-8) are computed from the homogenised 3x3
theta-block M = J^[:, 1:4] of the Jacobian with R frozen (SPEC §1), not from the 3x4 matrix its prose
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

import functools
import math
from typing import NamedTuple, Optional

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .geometry import Delta
from .jacobian import _resolve_length, homogenise, jq_diagonal, jq_theta, jx_det, jx_row
from .kinematics import (_branch_sign, _from_chain_frames, chain_local, design_ok, forearm_units, limit_terms,
                         loop_closure, loop_vectors, passive_angles)

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
    "SV_METHODS",
]

MATRICES = ("theta3x3", "full3x4")
#: Names of the scalar indices returned by :func:`indices`, usable as a redundancy-resolution criterion.
INDEX_NAMES = ("inv_cond", "sigma_min_v", "sigma_min_f", "omega_v", "omega_f", "k_tilde", "manipulability",
               "imi")


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
    left = 1.0 - ((s - a) / a) ** 2
    right = 1.0 - ((s - a) / (b - a)) ** 2
    val = jnp.where(inside, jnp.where(s <= a, left, right), 0.0)
    return jnp.where(jnp.isnan(sigma), jnp.nan, val)


def k_tilde(sigma_min_v, sigma_min_f, *, b_v=2.0, b_f=4.2, beta=0.5):
    """Singularity-sensitive index k~ = s~_v(sigma_min_v) * s~_f(sigma_min_f), a_v = beta b_v, a_f = (1-beta) b_f."""
    return sigma_tilde(sigma_min_v, beta * b_v, b_v) * sigma_tilde(sigma_min_f, (1.0 - beta) * b_f, b_f)


# -- eigenvalues of a symmetric 3x3 (flat scalars) -----------------------------------------------------------

#: t = u P(u), u = sqrt(c), approximates the root t in [0, 1] of t^2 (t + 3) = c (c in [0, 4]) to 3.2e-6
#: relative (least-squares Chebyshev fit); one Halley step then gives ~3e-16 relative (measured over 4e5 c).
_T_POLY = (0.5773484152710456, -0.055513434266994274, 0.013131880611233873, -0.0035774990190131535,
           0.0007894847448390405, -8.944924427049106e-05)


def _cubic_root01(c):
    """The root t in [0, 1] of t^2 (t + 3) = c for c in [0, 4]: polynomial start in sqrt(c), one Halley step."""
    u = jnp.sqrt(c)
    poly = _T_POLY[-1]
    for a in _T_POLY[-2::-1]:
        poly = poly * u + a
    t = u * poly
    g = t * t * (t + 3.0) - c
    g1 = 3.0 * t * (t + 2.0)
    g2 = 6.0 * (t + 1.0)
    den = 2.0 * g1 * g1 - g * g2
    return t - jnp.where(den > 0.0, 2.0 * g * g1 / jnp.where(den > 0.0, den, 1.0), 0.0)


def _eig_top2_fast(x00, x11, x22, x01, x02, x12, c2, det):
    """Two largest eigenvalues of a symmetric PSD 3x3 by the closed-form cubic, without inverse trig.

    With q = tr/3, p^2 = ||X - q I||_F^2 / 6 and r = det((X - q I)/p) / 2 in [-1, 1], the eigenvalues are
    q + p x with x^3 - 3x = 2r. The largest x = 1 + t, t^2 (t + 3) = 2 (1 + r) (polynomial start and one
    Halley step, :func:`_cubic_root01`): lambda_1 = q + p (1 + t), all terms positive, relative accuracy ~eps.
    lambda_2 does not come from the cubic's middle root (it cancels to ~sqrt(eps) lambda_1 when lambda_2,
    lambda_3 << lambda_1) but from the invariants the caller knows accurately: the sum of principal 2x2 minors
    ``c2`` and ``det``: lambda_2 lambda_3 = det / lambda_1 = pi, lambda_2 + lambda_3 = (c2 - pi) / lambda_1 =
    sigma, lambda_2 = sigma / 2 + sqrt(sigma^2 / 4 - pi) (no cancellation). A split below the cubic's
    ~sqrt(eps) noise (a repeated eigenvalue, e.g. on the robot's axis) is reported as the pair's mean.
    """
    q = (x00 + x11 + x22) * (1.0 / 3.0)
    b00, b11, b22 = x00 - q, x11 - q, x22 - q
    p2 = (b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (x01 * x01 + x02 * x02 + x12 * x12)) * (1.0 / 6.0)
    pos = p2 > 0.0
    p = jnp.where(pos, jnp.sqrt(jnp.where(pos, p2, 1.0)), 0.0)
    det_b = b00 * (b11 * b22 - x12 * x12) - x01 * (x01 * b22 - x12 * x02) + x02 * (x01 * x12 - b11 * x02)
    r = jnp.clip(0.5 * det_b / jnp.where(pos, p2 * p, 1.0), -1.0, 1.0)
    t = _cubic_root01(2.0 * (1.0 + r))
    t2 = _cubic_root01(2.0 * (1.0 - r))
    l1, l2c = q + p * (1.0 + t), q + p * (t2 - t)
    eps = jnp.finfo(jnp.result_type(x00)).eps
    # r carries an absolute error ~eps (1 + |q| / p) (cancellation in X - q I); t moves by its square root
    tie12 = (l1 - l2c) ** 2 <= 64.0 * eps * p * (p + jnp.abs(q))
    l1 = jnp.where(tie12, 0.5 * (l1 + l2c), l1)
    l1_pos = l1 > 0.0
    inv1 = 1.0 / jnp.where(l1_pos, l1, 1.0)
    prod23 = det * inv1
    sum23 = (c2 - prod23) * inv1
    disc = 0.25 * sum23 * sum23 - prod23
    root = jnp.where(disc > 64.0 * eps * sum23 * sum23, jnp.sqrt(jnp.where(disc > 0.0, disc, 1.0)), 0.0)
    l2 = jnp.where(tie12, l1, jnp.where(l1_pos, 0.5 * sum23 + root, 0.0))
    return l1, l2


def _jacobi_rotate(A, p: int, q: int):
    """One Jacobi rotation zeroing A[p, q] of a symmetric 3x3 matrix given as a dict of its 6 entries."""
    r = 3 - p - q
    app, aqq, apq = A[(p, p)], A[(q, q)], A[(p, q)]
    arp, arq = A[(r, p)], A[(r, q)]
    zero = apq == 0.0
    apq_safe = jnp.where(zero, 1.0, apq)
    tau = (aqq - app) / (2.0 * apq_safe)
    t = jnp.where(zero, 0.0, jnp.sign(tau + (tau == 0.0)) / (jnp.abs(tau) + jnp.sqrt(1.0 + tau * tau)))
    c = 1.0 / jnp.sqrt(1.0 + t * t)
    s = t * c
    out = dict(A)
    out[(p, p)] = app - t * apq
    out[(q, q)] = aqq + t * apq
    out[(p, q)] = out[(q, p)] = jnp.zeros_like(apq)
    out[(r, p)] = out[(p, r)] = c * arp - s * arq
    out[(r, q)] = out[(q, r)] = s * arp + c * arq
    return out


def _eig_top2_jacobi(x00, x11, x22, x01, x02, x12, sweeps: int = 4):
    """Two largest eigenvalues of a symmetric 3x3 by cyclic Jacobi (exact to ~eps ||X||, repeated ones too).

    Convergence is quadratic; 4 sweeps reach machine precision for 3x3. sqrt only, no inverse trig.
    """
    A = {(0, 0): x00, (1, 1): x11, (2, 2): x22, (0, 1): x01, (1, 0): x01, (0, 2): x02, (2, 0): x02,
         (1, 2): x12, (2, 1): x12}
    for _ in range(sweeps):
        for p, q in ((0, 1), (0, 2), (1, 2)):
            A = _jacobi_rotate(A, p, q)
    e0, e1, e2 = A[(0, 0)], A[(1, 1)], A[(2, 2)]
    hi = jnp.maximum(jnp.maximum(e0, e1), e2)
    lo = jnp.minimum(jnp.minimum(e0, e1), e2)
    return hi, e0 + e1 + e2 - hi - lo


SV_METHODS = ("fast", "jacobi", "svd")


@functools.partial(jax.custom_jvp, nondiff_argnums=(8,))
def sym3_top2(x00, x11, x22, x01, x02, x12, c2, det, method: str = "fast"):
    """(lambda_1, lambda_2), the two largest eigenvalues of the symmetric PSD 3x3 [[x00, x01, x02],
    [., x11, x12], [., ., x22]]; scalars. ``c2`` (sum of the principal 2x2 minors) and ``det`` are the
    matrix's invariants, passed in because the caller knows them without cancellation (``"fast"`` uses them
    for lambda_2; ``"jacobi"`` ignores them). ``method``: ``"fast"`` (closed-form cubic) or ``"jacobi"``.

    Custom JVP (finite everywhere): d lambda = tr(adj(X - lambda I) dX) / tr(adj(X - lambda I)) (the
    eigen-projector) for an eigenvalue separated from the others by more than eps^0.4 max|lambda|; a pair
    closer than that gets the derivative of its mean (tr(dX) minus the isolated one's, halved), a triple
    tr(dX) / 3. The projector eigenvalues come from Jacobi in both methods; c2 and det must be consistent
    with X (their tangents are not used).
    """
    if method == "fast":
        return _eig_top2_fast(x00, x11, x22, x01, x02, x12, c2, det)
    if method == "jacobi":
        return _eig_top2_jacobi(x00, x11, x22, x01, x02, x12)
    raise ValueError(f"method must be 'fast' or 'jacobi', got {method!r}")


@sym3_top2.defjvp
def _sym3_top2_jvp(method, primals, tangents):
    x00, x11, x22, x01, x02, x12 = primals[:6]
    d00, d11, d22, d01, d02, d12 = tangents[:6]
    lam1, lam2 = sym3_top2(*primals, method)
    l1, l2 = (lam1, lam2) if method == "jacobi" else _eig_top2_jacobi(*primals[:6])
    l3 = x00 + x11 + x22 - l1 - l2
    dtr = d00 + d11 + d22

    def proj(lam):
        a00, a11, a22 = x00 - lam, x11 - lam, x22 - lam
        c00 = a11 * a22 - x12 * x12
        c11 = a00 * a22 - x02 * x02
        c22 = a00 * a11 - x01 * x01
        c01 = x02 * x12 - x01 * a22
        c02 = x01 * x12 - x02 * a11
        c12 = x01 * x02 - a00 * x12
        num = c00 * d00 + c11 * d11 + c22 * d22 + 2.0 * (c01 * d01 + c02 * d02 + c12 * d12)
        return num, c00 + c11 + c22

    eps = jnp.finfo(jnp.result_type(x00)).eps
    tol = eps ** 0.4 * jnp.maximum(jnp.maximum(jnp.abs(l1), jnp.abs(l3)), jnp.finfo(jnp.result_type(x00)).tiny)
    sep12 = (l1 - l2) > tol
    sep23 = (l2 - l3) > tol
    n1, den1 = proj(l1)
    n3, den3 = proj(l3)
    g1 = n1 / jnp.where(sep12, den1, 1.0)
    g3 = n3 / jnp.where(sep23, den3, 1.0)
    dl1 = jnp.where(sep12, g1, jnp.where(sep23, 0.5 * (dtr - g3), dtr / 3.0))
    dl2 = jnp.where(sep12, jnp.where(sep23, dtr - g1 - g3, 0.5 * (dtr - g1)), dl1)
    return (lam1, lam2), (dl1, dl2)


def _sqrt0(x):
    """sqrt(max(x, 0)) with a finite (zero) derivative at and below 0."""
    pos = x > 0.0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def singular_values(jx, d=None, *, method: str = "fast"):
    """Singular values s1 >= s2 >= s3 of M = Jx^-1 diag(d), flat (no inverse, no SVD); or, legacy, of a matrix.

    ``singular_values(M)`` (one argument, a 3 x n matrix) is the reference ``jnp.linalg.svd`` and returns an
    array. The kernel form takes ``jx`` = the 9 entries of Jx row-major (row i = unit forearm vector u_i,
    base frame) and ``d`` = the 3 homogenised Jq diagonal entries (:func:`deltajax.jacobian.jq_theta`) as
    scalars and returns the tuple (s1, s2, s3) of scalars. Two exact reformulations, chosen per point by
    which factor is closer to singular (G = Jx Jx^T, D = diag(d)):

    * Jq side (|det Jx| >= |prod d|): M^T M = D adj(G) D / det G, so s1, s2 = sqrt(eig(D adj(G) D)) / |det Jx|;
    * Jx side (otherwise): M^-1 M^-T = adj(D) G adj(D) / prod(d)^2, so s3, s2 = |prod d| / sqrt(eig(...)).

    The remaining singular value comes from the exact determinant s1 s2 s3 = |prod d| / |det Jx|, so it keeps
    full relative accuracy near either kind of singularity. The two largest eigenvalues come from
    :func:`sym3_top2` (``method="fast"`` closed-form cubic, default; ``"jacobi"`` exact sweeps); both have
    finite derivatives everywhere, repeated singular values (the robot's axis) included.

    Accuracy of ``"fast"`` against ``jnp.linalg.svd`` (float64, tests/test_kernel.py): <= 1e-9 relative
    on every singular value for 1/k > 1e-3 off the axis; on the axis (s1 = s2 or s2 = s3) the split of the
    repeated pair is ~sqrt(eps) relative (<= 1e-7 measured), s3 on the Jq side stays ~1e-12.
    """
    if d is None:
        return jnp.linalg.svd(jx, compute_uv=False)
    if method not in ("fast", "jacobi"):
        raise ValueError(f"method must be 'fast' or 'jacobi', got {method!r}")
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
    e1, e2 = sym3_top2(*X, c2, det_x, method)
    r1, r2 = _sqrt0(e1), _sqrt0(e2)
    # Jq side (det_jx >= prod_d); det_jx = 0 there means both factors singular: s1 = inf
    det_pos = det_jx > 0.0
    det_safe = jnp.where(det_pos, det_jx, 1.0)
    a1 = jnp.where(det_pos, r1 / det_safe, jnp.inf)
    a2 = jnp.where(det_pos, r2 / det_safe, jnp.inf)
    a12 = a1 * a2
    a12_pos = det_pos & (a12 > 0)
    a3 = jnp.where(a12_pos, prod_d / (det_safe * jnp.where(a12_pos, a12, 1.0)), 0.0)
    # Jx side (prod_d > det_jx >= 0, so prod_d > 0)
    b3 = prod_d / jnp.where(r1 > 0, r1, 1.0)
    b2 = prod_d / jnp.where(r2 > 0, r2, 1.0)
    b23 = b2 * b3
    db = det_jx * b23
    b1 = jnp.where(db > 0, prod_d / jnp.where(db > 0, db, 1.0), jnp.inf)
    return jnp.where(jx_side, b1, a1), jnp.where(jx_side, b2, a2), jnp.where(jx_side, b3, a3)


def singular_values_closed_form(Jx: Float[Array, "3 3"], dhat: Float[Array, "3"], *,
                                method: str = "jacobi") -> Float[Array, "3"]:
    """Stacked form of :func:`singular_values` for a (3, 3) Jx and (3,) diagonal (kept for callers)."""
    s = singular_values(tuple(Jx[i, k] for i in range(3) for k in range(3)), (dhat[0], dhat[1], dhat[2]),
                        method=method)
    return jnp.stack(s)


def indices_from_sv(s1, s2, s3, *, b_v=2.0, b_f=4.2, beta=0.5, raw_scale=1.0) -> Indices:
    """All indices from the singular values s1 >= s2 >= s3 (scalars) of the homogenised matrix.

    ``raw_scale`` converts the homogenised manipulability to the raw one (length**3 for theta3x3). No masking:
    NaN in gives NaN out; s3 = 0 gives inv_cond = sigma_min_v = 0, omega_f = imi = inf.
    """
    omega_v = s1 * s2 * s3
    manip = omega_v * raw_scale
    sigma_min_f = 1.0 / s1
    return Indices(
        inv_cond=s3 / s1,
        sigma_min_v=s3,
        sigma_min_f=sigma_min_f,
        omega_v=omega_v,
        omega_f=1.0 / omega_v,
        k_tilde=k_tilde(s3, sigma_min_f, b_v=b_v, b_f=b_f, beta=beta),
        manipulability=manip,
        imi=1.0 / manip,
        singular_values=jnp.stack([s1, s2, s3]),
    )


def indices_from_singular_values(s: Float[Array, "3"], *, b_v=2.0, b_f=4.2, beta=0.5,
                                 raw_scale: Float[Array, ""] | float = 1.0) -> Indices:
    """All indices from the stacked singular values ``s`` (descending); see :func:`indices_from_sv`."""
    return indices_from_sv(s[0], s[1], s[2], b_v=b_v, b_f=b_f, beta=beta, raw_scale=raw_scale)


def _nan_where_not(ok, ind: Indices) -> Indices:
    nan = jnp.asarray(jnp.nan, ind.sigma_min_v.dtype)
    return Indices(*(jnp.where(ok if v.ndim == jnp.ndim(ok) else ok[..., None], v, nan) for v in ind))


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
    valid = design_ok(robot)
    one = jnp.asarray(1.0, dtype)
    L1 = jnp.where(valid, robot.upper_arm, one)
    L2 = jnp.where(valid, robot.forearm, 2.0 * one)
    L = L1 if length is None else jnp.where(valid, jnp.asarray(length, dtype), one)
    lim = limit_terms(robot.theta_min, robot.theta_max)
    chains, rows, d = [], [], []
    for i in range(3):
        x, y, z = chain_local(p[0], p[1], p[2], i)
        lc = loop_closure(x + robot.platform_radius - robot.base_radius, y, z, L1, L2, lim, sign)  # (x + r) - R
        ux, uy, uz = loop_vectors(lc.dx, lc.py, lc.pz, lc.cos, lc.sin, L1, L2)
        rows.extend(jx_row(ux, uy, uz, i))
        di = jq_theta(ux, uz, lc.cos, lc.sin)
        d.append(di if length is None else di * (L1 / L))
        chains.append(lc)
    ok = valid & chains[0].ok & chains[1].ok & chains[2].ok
    s1, s2, s3 = singular_values(tuple(rows), tuple(d), method=sv_method)
    ind = indices_from_sv(s1, s2, s3, b_v=b_v, b_f=b_f, beta=beta, raw_scale=L ** 3)
    return PointKernel(ok=ok, chains=tuple(chains), det_jx=jx_det(*rows), indices=_nan_where_not(ok, ind))


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
    theta = jnp.asarray(theta)
    p = jnp.asarray(p)
    dtype = jnp.result_type(p.dtype, theta.dtype, robot.upper_arm.dtype)
    ok = design_ok(robot) & jnp.all(jnp.isfinite(p)) & jnp.all(jnp.isfinite(theta))
    # double where: invalid inputs are replaced by a harmless configuration before any algebra
    theta = jnp.where(ok, theta, jnp.asarray([0.3, 0.5, 0.7], dtype)).astype(dtype)
    p = jnp.where(ok, p, jnp.asarray([0.01, 0.02, 0.3], dtype)).astype(dtype)
    robot = _harmless_design(robot, ok)
    L = _resolve_length(robot, length)
    u_local = forearm_units(robot, p, theta)
    Jx = _from_chain_frames(u_local)
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
        return _nan_where_not(ok, ind)
    Jq = jnp.concatenate([u_local[:, :1], jnp.diag(dhat * L)], axis=1)
    J = jnp.linalg.solve(Jx, Jq)
    s = singular_values(homogenise(J, L))
    ind = indices_from_singular_values(s, b_v=b_v, b_f=b_f, beta=beta)
    manip = jnp.sqrt(jnp.abs(jnp.linalg.det(J @ J.T)))
    return _nan_where_not(ok, ind._replace(manipulability=manip, imi=1.0 / manip))


def _harmless_design(robot: Delta, ok) -> Delta:
    """``robot`` where ``ok``, else a valid stand-in design (double where for traced invalid designs)."""
    f = lambda v, good: jnp.where(ok, v, jnp.asarray(good, v.dtype))  # noqa: E731
    return eqx.tree_at(lambda r: (r.base_radius, r.platform_radius, r.upper_arm, r.forearm, r.theta_min,
                                  r.theta_max), robot,
                       (f(robot.base_radius, 0.2), f(robot.platform_radius, 0.05), f(robot.upper_arm, 0.2),
                        f(robot.forearm, 0.4), f(robot.theta_min, -1.0), f(robot.theta_max, 2.0)))


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
    from .kinematics import ik_cos_sin

    sign = _branch_sign(branch)
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
    theta = jnp.asarray(theta)
    p = jnp.asarray(p)
    dtype = jnp.result_type(p.dtype, theta.dtype, robot.upper_arm.dtype)
    finite = design_ok(robot) & jnp.all(jnp.isfinite(p)) & jnp.all(jnp.isfinite(theta))
    theta = jnp.where(finite, theta, jnp.asarray([0.3, 0.5, 0.7], dtype)).astype(dtype)
    p = jnp.where(finite, p, jnp.asarray([0.01, 0.02, 0.3], dtype)).astype(dtype)
    robot = _harmless_design(robot, finite)
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

    Jx = _from_chain_frames(u_local)
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
