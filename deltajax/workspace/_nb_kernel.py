"""Numba mirror of the JAX point kernel: loop closure -> loop vectors -> Jacobian blocks -> singular values -> indices.

One small scalar function per step of the core's decomposition (:mod:`deltajax.kinematics`,
:mod:`deltajax.jacobian`, :mod:`deltajax.indices`), name for name, each tested against its JAX twin on random
inputs (``tests/test_backends.py``). Every function takes and returns plain floats (no arrays, no allocation),
is ``inline="always"`` and branch-free (selects, no early exit), so that a loop over points or R samples that
calls them compiles to one straight-line body LLVM can vectorise. The drivers (:mod:`._nb`) and the screen
(:mod:`._nb_screen`) are built from these functions only: the loop-closure algebra exists once in Numba.

Conventions (SPEC §1): point P = (x, y, z) in the base frame (z down); chain i lies at angle alpha_i about z
(its frame rotation is passed as ``ca, sa`` = cos, sin alpha_i); the joint range is passed as
``lim = (cos mid, sin mid, cos half, has_limits)`` (:func:`limits_tuple`); k~ as ``kt = (a_v, b_v, a_f, b_f)``
(:func:`kt_tuple`). The Jacobian blocks are homogenised by L1: Jx row i = unit forearm vector u_i (base
frame), Jq = diag(d_i) with d_i = u_z,i cos theta_i - u_x,i sin theta_i (chain frame), i.e. sin theta_i2
sin theta_i3. The paper's matrix M = Jx^-1 Jq; its singular values come from the two-sided formulation of
:func:`deltajax.indices.singular_values_closed_form`.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..geometry import CHAIN_ANGLES
from ..indices import INDEX_NAMES

# error_model="numpy": x / 0 gives inf/nan like NumPy and JAX instead of raising (Python semantics)
OPTS = dict(cache=True, fastmath=False, nogil=True, error_model="numpy")
_inline = dict(inline="always", **OPTS)

#: cos, sin of the chain angles (compile-time constants inside the kernels)
CA0, CA1, CA2 = (math.cos(a) for a in CHAIN_ANGLES)
SA0, SA1, SA2 = (math.sin(a) for a in CHAIN_ANGLES)

#: column of each index in the kernels' outputs and its criterion code: :data:`deltajax.INDEX_NAMES` order
N_IDX = len(INDEX_NAMES)
CRITERION = {name: i for i, name in enumerate(INDEX_NAMES)}
INV_COND, SIGMA_MIN_V, SIGMA_MIN_F, OMEGA_V, OMEGA_F, K_TILDE, MANIPULABILITY, IMI = (CRITERION[n] for n in (
    "inv_cond", "sigma_min_v", "sigma_min_f", "omega_v", "omega_f", "k_tilde", "manipulability", "imi"))

#: eigenvalue solvers of :func:`singular_values`
JACOBI = 0  # exact: 4 cyclic Jacobi sweeps (~eps ||A||, repeated eigenvalues included)
CUBIC = 1  # fast: trigonometric Cardano without inverse trig (polynomial start + one Halley step)
SV_METHODS = {"jacobi": JACOBI, "cubic": CUBIC}


def limits_tuple(theta_min: float, theta_max: float) -> np.ndarray:
    """(cos mid, sin mid, cos half, has_limits) of the joint range [theta_min, theta_max] (rad)."""
    if math.isfinite(theta_min) and math.isfinite(theta_max):
        mid = 0.5 * (theta_min + theta_max)
        half = 0.5 * (theta_max - theta_min)
        return np.array([math.cos(mid), math.sin(mid), math.cos(half), 1.0])
    return np.array([1.0, 0.0, -1.0, 0.0])


def kt_tuple(b_v: float, b_f: float, beta: float) -> np.ndarray:
    """(a_v, b_v, a_f, b_f) of k~ (a_v = beta b_v, a_f = (1 - beta) b_f)."""
    return np.array([beta * b_v, b_v, (1.0 - beta) * b_f, b_f], dtype=np.float64)


# -- kinematics ------------------------------------------------------------------------------------------------
@nb.njit(**_inline)
def as_tuple4(a):
    """(a[0], a[1], a[2], a[3]) of a parameter array: loop-invariant scalars (an array read inside a loop that
    also stores to arrays blocks LLVM's vectoriser, which cannot prove the two do not alias)."""
    return a[0], a[1], a[2], a[3]


@nb.njit(**_inline)
def to_chain_frame(x, y, ca, sa):
    """(p_x,i, p_y,i) of P in the frame of the chain at angle alpha (ca, sa = cos, sin alpha); z is unchanged."""
    return ca * x + sa * y, -sa * x + ca * y


@nb.njit(**_inline)
def loop_closure(dx, py, z, L1, L2):
    """Algebraic IK of one chain (outer branch): (reach, cos theta, sin theta).

    ``dx = p_x,i + r - R``, ``py = p_y,i``, ``z = p_z`` (chain frame). With rho^2 = dx^2 + z^2 and
    m = K / (2 L1) = (rho^2 + py^2 + L1^2 - L2^2) / (2 L1), the loop closes iff disc = rho^2 - m^2 >= 0;
    cos/sin are meaningless (not NaN-guarded: cheap) where ``reach`` is False.
    """
    rho2 = dx * dx + z * z
    m = (rho2 + py * py + L1 * L1 - L2 * L2) / (2.0 * L1)
    disc = rho2 - m * m
    reach = (disc >= 0.0) & (rho2 > 0.0)
    w = math.sqrt(disc if disc >= 0.0 else 0.0)
    inv = 1.0 / rho2
    c = (dx * m + z * w) * inv
    s = (z * m - dx * w) * inv
    return reach, c, s


@nb.njit(**_inline)
def within_limits(c, s, lim):
    """theta (given by cos, sin) inside the joint range: cos(theta - mid) >= cos(half), or no limits."""
    return (c * lim[0] + s * lim[1] >= lim[2]) | (not (lim[3] > 0.0))


@nb.njit(**_inline)
def loop_vectors(dx, py, z, c, s, L1, L2):
    """Unit forearm vector u_i = (C_i - B_i) / L2 of one chain, in the chain's frame."""
    return (dx - L1 * c) / L2, py / L2, (z - L1 * s) / L2


@nb.njit(**_inline)
def chain(x, y, z, R, r, L1, L2, lim, ca, sa):
    """One chain of the kernel: (ok, Jx row in the base frame (3 floats), Jq diagonal entry d_i / L1).

    ``ok``: the loop closes and theta_i is within the joint limits. The Jx row is the unit forearm vector
    rotated back to the base frame; d_i = u_z c - u_x s (chain frame) is the homogenised Jq diagonal.
    """
    px, py = to_chain_frame(x, y, ca, sa)
    dx = px + r - R
    reach, c, s = loop_closure(dx, py, z, L1, L2)
    ok = reach & within_limits(c, s, lim)
    u0, u1, u2 = loop_vectors(dx, py, z, c, s, L1, L2)
    return ok, ca * u0 - sa * u1, sa * u0 + ca * u1, u2, u2 * c - u0 * s


@nb.njit(**_inline)
def chain_ok(x, y, z, R, r, L1, L2, lim, ca, sa):
    """``ok`` of :func:`chain` alone (the same expressions, hence the same decision)."""
    px, py = to_chain_frame(x, y, ca, sa)
    dx = px + r - R
    reach, c, s = loop_closure(dx, py, z, L1, L2)
    return reach & within_limits(c, s, lim)


@nb.njit(**OPTS)
def ik_ok(x, y, z, R, r, L1, L2, lim):
    """All three chains close within limits at canonical P (y = |y|); early exit at the first failing chain."""
    if not chain_ok(x, y, z, R, r, L1, L2, lim, CA0, SA0):
        return False
    if not chain_ok(x, y, z, R, r, L1, L2, lim, CA1, SA1):
        return False
    return chain_ok(x, y, z, R, r, L1, L2, lim, CA2, SA2)


# -- Jacobian blocks -------------------------------------------------------------------------------------------
@nb.njit(**_inline)
def det3(a00, a01, a02, a10, a11, a12, a20, a21, a22):
    """Determinant of a 3 x 3 matrix by cofactor expansion along the first row (det Jx, signed)."""
    return (a00 * (a11 * a22 - a12 * a21)
            - a01 * (a10 * a22 - a12 * a20)
            + a02 * (a10 * a21 - a11 * a20))


@nb.njit(**_inline)
def sv_matrix(j00, j01, j02, j10, j11, j12, j20, j21, j22, d0, d1, d2):
    """The symmetric matrix whose eigenvalues give the singular values of M = Jx^-1 diag(d) (two-sided).

    Returns (jx_side, prod_d = |d0 d1 d2|, det_jx = |det Jx|, a00, a11, a22, a01, a02, a12): on the Jx side
    (|det Jx| < |prod d|) A = adj(D) G adj(D), else A = D adj(G) D, with G = Jx Jx^T (see
    :func:`deltajax.indices.singular_values_closed_form`).
    """
    det_jx = abs(det3(j00, j01, j02, j10, j11, j12, j20, j21, j22))
    g00 = j00 * j00 + j01 * j01 + j02 * j02
    g11 = j10 * j10 + j11 * j11 + j12 * j12
    g22 = j20 * j20 + j21 * j21 + j22 * j22
    g01 = j00 * j10 + j01 * j11 + j02 * j12
    g02 = j00 * j20 + j01 * j21 + j02 * j22
    g12 = j10 * j20 + j11 * j21 + j12 * j22
    prod_d = abs(d0 * d1 * d2)
    jx_side = det_jx < prod_d
    # Jx side: adj(D) G adj(D)
    e0 = d1 * d2
    e1 = d0 * d2
    e2 = d0 * d1
    # Jq side: D adj(G) D
    c00 = g11 * g22 - g12 * g12
    c11 = g00 * g22 - g02 * g02
    c22 = g00 * g11 - g01 * g01
    c01 = g02 * g12 - g01 * g22
    c02 = g01 * g12 - g02 * g11
    c12 = g01 * g02 - g00 * g12
    x0 = e0 if jx_side else d0
    x1 = e1 if jx_side else d1
    x2 = e2 if jx_side else d2
    return (jx_side, prod_d, det_jx,
            x0 * (g00 if jx_side else c00) * x0,
            x1 * (g11 if jx_side else c11) * x1,
            x2 * (g22 if jx_side else c22) * x2,
            x0 * (g01 if jx_side else c01) * x1,
            x0 * (g02 if jx_side else c02) * x2,
            x1 * (g12 if jx_side else c12) * x2)


# -- eigenvalues of the 3 x 3 symmetric matrix -----------------------------------------------------------------
@nb.njit(**_inline)
def _jacobi_rotate(app, aqq, apq, arp, arq):
    """One Jacobi rotation zeroing a_pq: (a_pp, a_qq, a_rp, a_rq) after it (r the third index)."""
    nz = apq != 0.0
    tau = (aqq - app) / (2.0 * (apq if nz else 1.0))
    sg = 1.0 if (tau + (1.0 if tau == 0.0 else 0.0)) > 0 else -1.0
    t = sg / (abs(tau) + math.sqrt(1.0 + tau * tau))
    t = t if nz else 0.0
    c = 1.0 / math.sqrt(1.0 + t * t)
    s = t * c
    return app - t * apq, aqq + t * apq, c * arp - s * arq, s * arp + c * arq


@nb.njit(**_inline)
def _jacobi_sweep(a00, a11, a22, a01, a02, a12):
    a00, a11, a02, a12 = _jacobi_rotate(a00, a11, a01, a02, a12)  # (0, 1)
    a01 = 0.0
    a00, a22, a01, a12 = _jacobi_rotate(a00, a22, a02, a01, a12)  # (0, 2)
    a02 = 0.0
    a11, a22, a01, a02 = _jacobi_rotate(a11, a22, a12, a01, a02)  # (1, 2)
    a12 = 0.0
    return a00, a11, a22, a01, a02, a12


@nb.njit(**_inline)
def eig_jacobi(a00, a11, a22, a01, a02, a12):
    """The two largest eigenvalues (hi, mid) by 4 cyclic Jacobi sweeps (unrolled; sqrt only)."""
    a00, a11, a22, a01, a02, a12 = _jacobi_sweep(a00, a11, a22, a01, a02, a12)
    a00, a11, a22, a01, a02, a12 = _jacobi_sweep(a00, a11, a22, a01, a02, a12)
    a00, a11, a22, a01, a02, a12 = _jacobi_sweep(a00, a11, a22, a01, a02, a12)
    a00, a11, a22, a01, a02, a12 = _jacobi_sweep(a00, a11, a22, a01, a02, a12)
    hi = max(max(a00, a11), a22)
    lo = min(min(a00, a11), a22)
    return hi, a00 + a11 + a22 - hi - lo


#: least-squares fit of t / s, s = sqrt(w / 3), on [0, 2 / sqrt 3] (max error of the guess 1.1e-5)
_TC4, _TC3, _TC2, _TC1, _TC0 = (0.004862740934509117, -0.02386905831264214, 0.06417057523483471,
                                -0.16573685947992756, 0.9999539697770844)


@nb.njit(**_inline)
def _guess(w):
    s = math.sqrt(w * (1.0 / 3.0))
    return s * ((((_TC4 * s + _TC3) * s + _TC2) * s + _TC1) * s + _TC0)


@nb.njit(**_inline)
def tcubic(w):
    """Root t in [0, 1] of t^2 (t + 3) = w, w in [0, 4]; branch-free, one sqrt and one division.

    With c = (1 + t) / 2 this is the largest root of the Chebyshev equation 4 c^3 - 3 c = w / 2 - 1, i.e.
    cos(acos(r) / 3) of the trigonometric Cardano formula, without inverse trigonometry (vectorisable).
    A polynomial guess in s = sqrt(w / 3) (t = s (1 - s / 6 + ...)) and one Halley step (cubic convergence).
    """
    t = _guess(w)
    f = t * t * (t + 3.0) - w
    fp = 3.0 * t * (t + 2.0)
    den = 2.0 * fp * fp - f * (6.0 * t + 6.0)
    return t - 2.0 * f * fp / max(den, 1e-300)


@nb.njit(**_inline)
def tcubic2(wp, wm):
    """:func:`tcubic` of two arguments with one shared division (x / a, y / b = x b / (a b), y a / (a b))."""
    tp = _guess(wp)
    tm = _guess(wm)
    fp_ = tp * tp * (tp + 3.0) - wp
    dp_ = 3.0 * tp * (tp + 2.0)
    np_ = 2.0 * fp_ * dp_
    ep_ = max(2.0 * dp_ * dp_ - fp_ * (6.0 * tp + 6.0), 1e-150)
    fm_ = tm * tm * (tm + 3.0) - wm
    dm_ = 3.0 * tm * (tm + 2.0)
    nm_ = 2.0 * fm_ * dm_
    em_ = max(2.0 * dm_ * dm_ - fm_ * (6.0 * tm + 6.0), 1e-150)
    inv = 1.0 / (ep_ * em_)
    return tp - np_ * em_ * inv, tm - nm_ * ep_ * inv


@nb.njit(**_inline)
def eig_cubic_parts(a00, a11, a22, a01, a02, a12):
    """Trigonometric Cardano form of the eigenvalues: (q, p, tp, tm, ip) with lambda_max = q + p (1 + tp),
    lambda_mid = q + p (tm - tp), lambda_min = q - p (1 + tm); ip = 1 / p (0 where p = 0).

    q = tr A / 3, p^2 = ||A - q I||_F^2 / 6, r = det((A - q I) / p) / 2 in [-1, 1], tp, tm the roots of
    t^2 (t + 3) = 2 (1 +- r) (:func:`tcubic2`).
    """
    q = (a00 + a11 + a22) * (1.0 / 3.0)
    b00 = a00 - q
    b11 = a11 - q
    b22 = a22 - q
    p2 = (b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)) * (1.0 / 6.0)
    p = math.sqrt(p2)
    ip = 1.0 / p if p > 0.0 else 0.0
    n00 = b00 * ip
    n11 = b11 * ip
    n22 = b22 * ip
    n01 = a01 * ip
    n02 = a02 * ip
    n12 = a12 * ip
    rr = 0.5 * (n00 * (n11 * n22 - n12 * n12) - n01 * (n01 * n22 - n12 * n02) + n02 * (n01 * n12 - n11 * n02))
    rr = min(max(rr, -1.0), 1.0)
    tp, tm = tcubic2(2.0 * (1.0 + rr), 2.0 * (1.0 - rr))
    return q, p, tp, tm, ip


@nb.njit(**_inline)
def eig_cubic(a00, a11, a22, a01, a02, a12):
    """The two largest eigenvalues (hi, mid) by the closed-form cubic (:func:`eig_cubic_parts`)."""
    q, p, tp, tm, ip = eig_cubic_parts(a00, a11, a22, a01, a02, a12)
    return q + p * (1.0 + tp), q + p * (tm - tp)


# -- singular values and indices -------------------------------------------------------------------------------
@nb.njit(**_inline)
def singular_values_from_eig(hi, mid, jx_side, prod_d, det_jx):
    """(s1, s2, s3) of M from the two largest eigenvalues of :func:`sv_matrix`'s matrix; the third singular
    value from the exact determinant s1 s2 s3 = |prod d| / |det Jx| (keeps its relative accuracy near
    either kind of singularity). Jx side: s3, s2 = |prod d| / sqrt(hi, mid); Jq side: s1, s2 = sqrt(hi,
    mid) / |det Jx|. Three divisions, shared by both sides."""
    r1 = math.sqrt(max(hi, 0.0))
    r2 = math.sqrt(max(mid, 0.0))
    x1 = (prod_d if jx_side else r1) / ((r1 if r1 > 0.0 else 1.0) if jx_side else det_jx)  # s3 | s1
    x2 = (prod_d if jx_side else r2) / ((r2 if r2 > 0.0 else 1.0) if jx_side else det_jx)  # s2
    den = det_jx * (x1 * x2)
    x3 = prod_d / (den if den > 0.0 else 1.0)
    x3 = x3 if den > 0.0 else (math.inf if jx_side else 0.0)  # s1 | s3
    return (x3 if jx_side else x1), x2, (x1 if jx_side else x3)


@nb.njit(**_inline)
def singular_values(j00, j01, j02, j10, j11, j12, j20, j21, j22, d0, d1, d2, method):
    """Singular values (s1 >= s2 >= s3) of M = Jx^-1 diag(d) (twin of the core's closed-form singular values);
    ``method``: :data:`JACOBI` (exact) or :data:`CUBIC` (fast closed form)."""
    jx_side, prod_d, det_jx, a00, a11, a22, a01, a02, a12 = sv_matrix(j00, j01, j02, j10, j11, j12, j20, j21, j22,
                                                                       d0, d1, d2)
    if method == JACOBI:
        hi, mid = eig_jacobi(a00, a11, a22, a01, a02, a12)
    else:
        hi, mid = eig_cubic(a00, a11, a22, a01, a02, a12)
    return singular_values_from_eig(hi, mid, jx_side, prod_d, det_jx)


@nb.njit(**_inline)
def sigma_tilde(sig, a, b):
    """The paper's piecewise quadratic: 1 - ((sig - a) / a)^2 up to a, 1 - ((sig - a) / (b - a))^2 up to b,
    0 above; NaN stays NaN."""
    t = (sig - a) / (a if sig <= a else b - a)
    v = 1.0 - t * t
    return 0.0 if sig > b else v


@nb.njit(**_inline)
def indices(s1, s2, s3, L1, kt):
    """All indices from the singular values, in :data:`deltajax.INDEX_NAMES` order (8 floats)."""
    ov = s1 * s2 * s3
    man = ov * (L1 * L1 * L1)
    return (s3 / s1, s3, 1.0 / s1, ov, 1.0 / ov,
            sigma_tilde(s3, kt[0], kt[1]) * sigma_tilde(1.0 / s1, kt[2], kt[3]), man, 1.0 / man)


@nb.njit(**_inline)
def jacobian_blocks(x, y, z, R, r, L1, L2, lim):
    """The three chains at P (canonical, y = |y|): (ok, det Jx signed, Jx (9 floats, rows), d (3 floats))."""
    ok0, j00, j01, j02, d0 = chain(x, y, z, R, r, L1, L2, lim, CA0, SA0)
    ok1, j10, j11, j12, d1 = chain(x, y, z, R, r, L1, L2, lim, CA1, SA1)
    ok2, j20, j21, j22, d2 = chain(x, y, z, R, r, L1, L2, lim, CA2, SA2)
    det_s = det3(j00, j01, j02, j10, j11, j12, j20, j21, j22)
    return ok0 & ok1 & ok2, det_s, j00, j01, j02, j10, j11, j12, j20, j21, j22, d0, d1, d2


@nb.njit(**_inline)
def point_indices(x, y, z, R, r, L1, L2, lim, kt, method):
    """The whole kernel at one canonical point: (feasible, 8 indices); feasible = IK within limits on every
    chain and det Jx != 0 exactly. Branch-free: the indices are meaningless where not feasible."""
    ok, det_s, j00, j01, j02, j10, j11, j12, j20, j21, j22, d0, d1, d2 = jacobian_blocks(x, y, z, R, r, L1, L2, lim)
    s1, s2, s3 = singular_values(j00, j01, j02, j10, j11, j12, j20, j21, j22, d0, d1, d2, method)
    i0, i1, i2, i3, i4, i5, i6, i7 = indices(s1, s2, s3, L1, kt)
    return ok & (det_s != 0.0), i0, i1, i2, i3, i4, i5, i6, i7


@nb.njit(**_inline)
def criterion_of(crit, i0, i1, i2, i3, i4, i5, i6, i7):
    """The index with criterion code ``crit`` (:data:`CRITERION`) among the 8."""
    v = i0
    v = i1 if crit == SIGMA_MIN_V else v
    v = i2 if crit == SIGMA_MIN_F else v
    v = i3 if crit == OMEGA_V else v
    v = i4 if crit == OMEGA_F else v
    v = i5 if crit == K_TILDE else v
    v = i6 if crit == MANIPULABILITY else v
    return i7 if crit == IMI else v


@nb.njit(**OPTS)
def point_value(x, y, z, R, r, L1, L2, lim, kt, crit, method):
    """(feasible, criterion value) of the exact kernel at one canonical point (redundancy resolution)."""
    f, i0, i1, i2, i3, i4, i5, i6, i7 = point_indices(x, y, z, R, r, L1, L2, lim, kt, method)
    return f, criterion_of(crit, i0, i1, i2, i3, i4, i5, i6, i7)
