"""Numba mirror of the JAX point kernel: loop closure -> loop vectors -> Jacobian blocks -> singular values -> indices.

One small scalar function per step of the core's decomposition (:mod:`deltajax.kinematics`,
:mod:`deltajax.jacobian`, :mod:`deltajax.indices`), name for name, each registered with its JAX definition in
:data:`deltajax.backends.KERNELS` and checked against it by ``tests/test_backend_conformance.py``. Every function
takes and returns plain floats (no arrays, no allocation), is inlined into its caller by LLVM (:data:`INLINE`)
and branch-free (selects, no early exit), so that a loop over points or R samples that calls them compiles to
one straight-line body LLVM can vectorise. The drivers (:mod:`.numba_fields`) and the screen
(:mod:`.numba_screen`) are built from these functions only: the loop-closure algebra
exists once in Numba.

Conventions (docs/CONVENTIONS.md): point P = (x, y, z) in the base frame (z down); chain i lies at angle alpha_i about z
(its frame rotation is passed as ``ca, sa`` = cos, sin alpha_i); the joint range is passed as
``lim = (cos mid, sin mid, cos half, has_limits)`` (:func:`limits_tuple`); k~ as ``kt = (a_v, b_v, a_f, b_f)``
(:func:`kt_tuple`). The Jacobian blocks are homogenised by L1: Jx row i = unit forearm vector u_i (base
frame), Jq = diag(d_i) with d_i = u_z,i cos theta_i - u_x,i sin theta_i (chain frame), i.e. sin theta_i2
sin theta_i3. The paper's matrix M = Jx^-1 Jq; its singular values come from the two-sided formulation of
:func:`deltajax.indices.singular_values_closed_form`.
"""

from __future__ import annotations

import math
import hashlib
from pathlib import Path

import numba as nb
import numpy as np

from ..geometry import CHAIN_ANGLES, FULL_TURN_MIN
from ..eigen3 import T_POLY
from ..indices import INDEX_NAMES

__all__ = ["OPTS", "INLINE", "N_IDX", "CRITERION", "JACOBI", "FAST", "CUBIC", "SV_METHODS", "limits_tuple", "kt_tuple",
           "as_tuple4", "chain_local", "loop_closure", "loop_vectors", "jx_row", "jq_theta", "jx_det", "chain",
           "chain_ok", "ik_ok_all", "ik_ok", "jacobian_blocks", "sv_matrix", "sym3_top2",
           "singular_values_from_eig", "singular_values", "sigma_tilde", "k_tilde", "indices_from_sv", "point_kernel",
           "criterion_of", "point_value"]

def _drop_stale_cache() -> None:
    """Numba's on-disk cache checks only the file that defines a function, but the drivers (:mod:`.numba_fields`,
    :mod:`.numba_screen`) inline this module's functions: after an edit here their cached machine code would be
    stale. Key the cache on every such source and drop it when they change."""
    here = Path(__file__).parent
    sources = ("numba_kernel.py", "numba_screen.py", "numba_fields.py")
    digest = hashlib.sha256(b"".join((here / f).read_bytes() for f in sources if (here / f).exists())).hexdigest()
    cache = here / "__pycache__"
    stamp = cache / "numba_sources.sha256"
    try:
        if stamp.exists() and stamp.read_text() == digest:
            return
        for f in cache.glob("numba_fields*.nb[ic]"):
            f.unlink()
        cache.mkdir(exist_ok=True)
        stamp.write_text(digest)
    except OSError:  # read-only install: numba then falls back to its own cache locator
        pass


_drop_stale_cache()

# error_model="numpy": x / 0 gives inf/nan like NumPy and JAX instead of raising (Python semantics)
OPTS = dict(cache=True, fastmath=False, nogil=True, error_model="numpy")
#: the small functions every kernel is built from: LLVM ``alwaysinline`` (``forceinline``), so a loop that calls them
#: is one straight-line body LLVM can vectorise. Not Numba's ``inline="always"`` (inlining at the Numba IR level,
#: which re-runs type inference for every call site): the same machine-code speed (bench_workspace --versus), but
#: a cold compile of ``fixed_fields`` + ``fixed_fields_dense`` took 210 CPU-s with it and 15 CPU-s without.
INLINE = dict(forceinline=True, **OPTS)

#: cos, sin of the chain angles (the core's constants; compile-time constants inside the kernels)
COS_A = tuple(math.cos(a) for a in CHAIN_ANGLES)
SIN_A = tuple(math.sin(a) for a in CHAIN_ANGLES)
CA0, CA1, CA2 = COS_A
SA0, SA1, SA2 = SIN_A

#: column of each index in the kernels' outputs and its criterion code: :data:`deltajax.INDEX_NAMES` order
N_IDX = len(INDEX_NAMES)
CRITERION = {name: i for i, name in enumerate(INDEX_NAMES)}
INV_COND, SIGMA_MIN_V, SIGMA_MIN_F, OMEGA_V, OMEGA_F, K_TILDE, MANIPULABILITY, IMI = (CRITERION[n] for n in (
    "inv_cond", "sigma_min_v", "sigma_min_f", "omega_v", "omega_f", "k_tilde", "manipulability", "imi"))

#: eigenvalue solvers of :func:`sym3_top2` / :func:`singular_values` (the core's ``method`` names)
JACOBI = 0  # exact: 4 cyclic Jacobi sweeps (~eps ||A||, repeated eigenvalues included)
FAST = 1  # closed-form cubic without inverse trig (polynomial start + one Halley step)
CUBIC = FAST
SV_METHODS = {"jacobi": JACOBI, "fast": FAST}


def limits_tuple(theta_min: float, theta_max: float) -> np.ndarray:
    """(cos mid, sin mid, cos half, has_limits) of the joint range [theta_min, theta_max] (rad): the core's
    :func:`deltajax.kinematics.limit_terms` (cos half = -2 when a bound is infinite or the range a full turn: every theta passes)."""
    if math.isfinite(theta_min) and math.isfinite(theta_max) and theta_max - theta_min < FULL_TURN_MIN:
        mid = 0.5 * (theta_min + theta_max)
        half = 0.5 * (theta_max - theta_min)
        return np.array([math.cos(mid), math.sin(mid), math.cos(half), 1.0])
    return np.array([1.0, 0.0, -2.0, 0.0])


def kt_tuple(b_v: float, b_f: float, beta: float) -> np.ndarray:
    """(a_v, b_v, a_f, b_f) of k~ (a_v = beta b_v, a_f = (1 - beta) b_f)."""
    return np.array([beta * b_v, b_v, (1.0 - beta) * b_f, b_f], dtype=np.float64)


@nb.njit(**INLINE)
def as_tuple4(a):
    """(a[0], a[1], a[2], a[3]) of a parameter array: loop-invariant scalars (an array read inside a loop that
    also stores to arrays blocks LLVM's vectoriser, which cannot prove that they do not alias)."""
    return a[0], a[1], a[2], a[3]


@nb.njit(**INLINE)
def _rotate_z(a, b, c, i, sign):
    """(a, b, c) rotated about z by -sign alpha_i (sign +1: base -> chain frame, -1: back); chain 0 unchanged."""
    if i == 0:
        return a, b, c
    ca = COS_A[i]
    sa = sign * SIN_A[i]
    return ca * a + sa * b, ca * b - sa * a, c


# -- kinematics (twins of deltajax.kinematics) ------------------------------------------------------------------
@nb.njit(**INLINE)
def chain_local(px, py, pz, i):
    """P in the local frame of chain ``i`` (0, 1, 2; a constant after inlining); chain 0 is the base frame."""
    return _rotate_z(px, py, pz, i, 1.0)


@nb.njit(**INLINE)
def loop_closure(dx, py, pz, L1, L2, lim):
    """Algebraic IK of one chain (outer elbow): twin of :func:`deltajax.kinematics.loop_closure`.

    ``dx = (p_x,i + r) - R``, ``py = p_y,i``, ``pz = p_z`` (chain frame); ``lim`` = (cos mid, sin mid, cos half,
    _) of :func:`limits_tuple`. Returns (cos, sin, disc, reach, margin, ok, dx, py, pz) with the inputs
    sanitised outside the box |dx|, |pz| <= L1 + L2, |py| <= L2 (nothing there closes; catches NaN, inf and
    huge values; disc = -(L1 + L2)^2 there) and cos, sin = 1, 0 where the loop does not close; theta is within
    the joint limits iff margin >= 0.
    """
    box = L1 + L2
    inside = (abs(dx) <= box) & (abs(pz) <= box) & (abs(py) <= L2)
    dx = dx if inside else box
    py = py if inside else 0.0
    pz = pz if inside else 0.0
    rho2 = dx * dx + pz * pz
    m = (rho2 + py * py + L1 * L1 - L2 * L2) * (0.5 / L1)  # a loop-invariant reciprocal: one division less
    disc = rho2 - m * m
    reach = inside & (disc >= 0.0) & (rho2 > 0.0)
    w = math.sqrt(disc) if (reach & (disc > 0.0)) else 0.0
    inv_rho2 = 1.0 / (rho2 if reach else 1.0)
    c = (dx * m + pz * w) * inv_rho2 if reach else 1.0
    s = (pz * m - dx * w) * inv_rho2 if reach else 0.0
    margin = c * lim[0] + s * lim[1] - lim[2]
    return c, s, (disc if inside else -(box * box)), reach, margin, reach & (margin >= 0.0), dx, py, pz


@nb.njit(**INLINE)
def loop_vectors(dx, py, pz, c, s, L1, L2):
    """Unit forearm vector u = (C - B) / L2 of one chain in its local frame (sanitised loop inputs)."""
    inv = 1.0 / L2
    return (dx - L1 * c) * inv, py * inv, (pz - L1 * s) * inv


# -- Jacobian blocks (twins of deltajax.jacobian) ----------------------------------------------------------------
@nb.njit(**INLINE)
def jx_row(ux, uy, uz, i):
    """Row i of Jx in the base frame: the unit forearm vector of chain ``i`` rotated back."""
    return _rotate_z(ux, uy, uz, i, -1.0)


@nb.njit(**INLINE)
def jq_theta(ux, uz, c, s):
    """Homogenised Jq diagonal entry d = uz cos theta - ux sin theta = sin theta2 sin theta3 (chain frame)."""
    return uz * c - ux * s


@nb.njit(**INLINE)
def jx_det(j00, j01, j02, j10, j11, j12, j20, j21, j22):
    """Signed det Jx by cofactor expansion along the first row (0 exactly: the sample is skipped)."""
    return (j00 * (j11 * j22 - j12 * j21)
            - j01 * (j10 * j22 - j12 * j20)
            + j02 * (j10 * j21 - j11 * j20))


@nb.njit(**INLINE)
def chain(x, y, z, R, r, L1, L2, lim, i):
    """One chain of :func:`point_kernel`: (ok, Jx row i (3 floats, base frame), d_i).

    chain_local -> loop_closure (dx = (x + r) - R) -> loop_vectors -> jx_row, jq_theta.
    """
    px, py, pz = chain_local(x, y, z, i)
    c, s, disc, reach, margin, ok, dx, py, pz = loop_closure(px + r - R, py, pz, L1, L2, lim)
    ux, uy, uz = loop_vectors(dx, py, pz, c, s, L1, L2)
    j0, j1, j2 = jx_row(ux, uy, uz, i)
    return ok, j0, j1, j2, jq_theta(ux, uz, c, s)


@nb.njit(**INLINE)
def chain_ok(x, y, z, R, r, L1, L2, lim, i):
    """``ok`` of :func:`chain` alone (the same loop closure, hence the same decision)."""
    px, py, pz = chain_local(x, y, z, i)
    return loop_closure(px + r - R, py, pz, L1, L2, lim)[5]


@nb.njit(**INLINE)
def ik_ok_all(x, y, z, R, r, L1, L2, lim):
    """:func:`ik_ok` without the early exit (all three chains, branch-free: vectorises over samples or points;
    the same loop closures, hence the same decision)."""
    return (chain_ok(x, y, z, R, r, L1, L2, lim, 0) & chain_ok(x, y, z, R, r, L1, L2, lim, 1)
            & chain_ok(x, y, z, R, r, L1, L2, lim, 2))


@nb.njit(**OPTS)
def ik_ok(x, y, z, R, r, L1, L2, lim):
    """All three chains close within limits at canonical P (y = |y|); stops at the first failing chain."""
    if not chain_ok(x, y, z, R, r, L1, L2, lim, 0):
        return False
    if not chain_ok(x, y, z, R, r, L1, L2, lim, 1):
        return False
    return chain_ok(x, y, z, R, r, L1, L2, lim, 2)


@nb.njit(**INLINE)
def jacobian_blocks(x, y, z, R, r, L1, L2, lim):
    """The three chains at P (canonical, y = |y|): (ok, det Jx signed, Jx (9 floats, rows), d (3 floats))."""
    ok0, j00, j01, j02, d0 = chain(x, y, z, R, r, L1, L2, lim, 0)
    ok1, j10, j11, j12, d1 = chain(x, y, z, R, r, L1, L2, lim, 1)
    ok2, j20, j21, j22, d2 = chain(x, y, z, R, r, L1, L2, lim, 2)
    det_s = jx_det(j00, j01, j02, j10, j11, j12, j20, j21, j22)
    return ok0 & ok1 & ok2, det_s, j00, j01, j02, j10, j11, j12, j20, j21, j22, d0, d1, d2


# -- singular values (twins of deltajax.indices) ---------------------------------------------------------------
@nb.njit(**INLINE)
def sv_matrix(j00, j01, j02, j10, j11, j12, j20, j21, j22, d0, d1, d2):
    """The symmetric matrix X whose two largest eigenvalues give the singular values of M = Jx^-1 diag(d).

    Returns (jx_side, prod_d = |d0 d1 d2|, det_jx = |det Jx|, c2, det X, x00, x11, x22, x01, x02, x12): c2 the
    sum of X's principal 2x2 minors and det X from the factors (no cancellation); on the Jx side
    (|det Jx| < |prod d|) X = adj(D) G adj(D), else X = D adj(G) D, G = Jx Jx^T (the first half of
    :func:`deltajax.indices.singular_values`, same expressions).
    """
    det_jx = abs(jx_det(j00, j01, j02, j10, j11, j12, j20, j21, j22))
    g00 = j00 * j00 + j01 * j01 + j02 * j02
    g11 = j10 * j10 + j11 * j11 + j12 * j12
    g22 = j20 * j20 + j21 * j21 + j22 * j22
    g01 = j00 * j10 + j01 * j11 + j02 * j12
    g02 = j00 * j20 + j01 * j21 + j02 * j22
    g12 = j10 * j20 + j11 * j21 + j12 * j22
    prod_d = abs(d0 * d1 * d2)
    jx_side = det_jx < prod_d
    e0 = d1 * d2  # adj(D)
    e1 = d0 * d2
    e2 = d0 * d1
    c00 = g11 * g22 - g12 * g12  # adj(G)
    c11 = g00 * g22 - g02 * g02
    c22 = g00 * g11 - g01 * g01
    c01 = g02 * g12 - g01 * g22
    c02 = g01 * g12 - g02 * g11
    c12 = g01 * g02 - g00 * g12
    x0 = e0 if jx_side else d0
    x1 = e1 if jx_side else d1
    x2 = e2 if jx_side else d2
    # invariants of X without cancellation: sum of the principal 2x2 minors c2 and det X
    det_g = det_jx * det_jx
    p2d = prod_d * prod_d
    c2 = (p2d * (d0 * d0 * c00 + d1 * d1 * c11 + d2 * d2 * c22) if jx_side
          else det_g * (g00 * e0 * e0 + g11 * e1 * e1 + g22 * e2 * e2))
    det_x = p2d * p2d * det_g if jx_side else p2d * det_g * det_g
    return (jx_side, prod_d, det_jx, c2, det_x,
            x0 * (g00 if jx_side else c00) * x0,
            x1 * (g11 if jx_side else c11) * x1,
            x2 * (g22 if jx_side else c22) * x2,
            x0 * (g01 if jx_side else c01) * x1,
            x0 * (g02 if jx_side else c02) * x2,
            x1 * (g12 if jx_side else c12) * x2)


@nb.njit(**INLINE)
def _jacobi_rotate(app, aqq, apq, arp, arq):
    """One Jacobi rotation zeroing a_pq: (a_pp, a_qq, a_rp, a_rq) after it (r the third index).

    t = sign(tau) / (|tau| + sqrt(1 + tau^2)), tau = (a_qq - a_pp) / (2 a_pq), written with |2 a_pq| through
    numerator and denominator (one division instead of two; where a_pq and a_qq - a_pp are so small that
    their squares underflow, |t| = 1 is as good as any: the a_pq being zeroed is below 1e-154)."""
    nz = apq != 0.0
    num = aqq - app
    den = 2.0 * apq
    sg = 1.0 if (num == 0.0) | ((num > 0.0) == (den > 0.0)) else -1.0  # sign of tau, +1 at tau = 0
    q = abs(num) + math.sqrt(num * num + den * den)  # 0 only where both squares underflow: then t = sign
    t = sg * abs(den) / (q if q > 0.0 else 1.0)
    t = (t if q > 0.0 else sg) if nz else 0.0
    c = 1.0 / math.sqrt(1.0 + t * t)
    s = t * c
    return app - t * apq, aqq + t * apq, c * arp - s * arq, s * arp + c * arq


@nb.njit(**INLINE)
def _jacobi_sweep(a00, a11, a22, a01, a02, a12):
    a00, a11, a02, a12 = _jacobi_rotate(a00, a11, a01, a02, a12)  # (0, 1)
    a01 = 0.0
    a00, a22, a01, a12 = _jacobi_rotate(a00, a22, a02, a01, a12)  # (0, 2)
    a02 = 0.0
    a11, a22, a01, a02 = _jacobi_rotate(a11, a22, a12, a01, a02)  # (1, 2)
    a12 = 0.0
    return a00, a11, a22, a01, a02, a12


@nb.njit(**INLINE)
def _eig_top2_jacobi(x00, x11, x22, x01, x02, x12):
    """The two largest eigenvalues by 4 cyclic Jacobi sweeps (unrolled; sqrt only)."""
    x00, x11, x22, x01, x02, x12 = _jacobi_sweep(x00, x11, x22, x01, x02, x12)
    x00, x11, x22, x01, x02, x12 = _jacobi_sweep(x00, x11, x22, x01, x02, x12)
    x00, x11, x22, x01, x02, x12 = _jacobi_sweep(x00, x11, x22, x01, x02, x12)
    x00, x11, x22, x01, x02, x12 = _jacobi_sweep(x00, x11, x22, x01, x02, x12)
    hi = max(max(x00, x11), x22)
    lo = min(min(x00, x11), x22)
    return hi, x00 + x11 + x22 - hi - lo


_EPS = 2.220446049250313e-16


@nb.njit(**INLINE)
def _cubic_root01(c):
    """The root t in [0, 1] of t^2 (t + 3) = c, c in [0, 4]: polynomial start in sqrt(c), one Halley step."""
    u = math.sqrt(c)
    t = u * (((((T_POLY[5] * u + T_POLY[4]) * u + T_POLY[3]) * u + T_POLY[2]) * u + T_POLY[1]) * u
             + T_POLY[0])
    g = t * t * (t + 3.0) - c
    g1 = 3.0 * t * (t + 2.0)
    g2 = 6.0 * (t + 1.0)
    den = 2.0 * g1 * g1 - g * g2
    return t - (2.0 * g * g1 / (den if den > 0.0 else 1.0) if den > 0.0 else 0.0)


@nb.njit(**INLINE)
def _eig_top2_fast(x00, x11, x22, x01, x02, x12, c2, det):
    """The two largest eigenvalues: lambda_1 by the closed-form cubic without inverse trig (q + p x,
    x^3 - 3x = 2r); lambda_2 from the invariants (lambda_2 lambda_3 = det / lambda_1, lambda_2 + lambda_3 =
    (c2 - det / lambda_1) / lambda_1, no cancellation); a split below the cubic's sqrt(eps) noise is the
    pair's mean (the core's expressions)."""
    q = (x00 + x11 + x22) * (1.0 / 3.0)
    b00 = x00 - q
    b11 = x11 - q
    b22 = x22 - q
    p2 = (b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (x01 * x01 + x02 * x02 + x12 * x12)) * (1.0 / 6.0)
    pos = p2 > 0.0
    p = math.sqrt(p2) if pos else 0.0
    det_b = b00 * (b11 * b22 - x12 * x12) - x01 * (x01 * b22 - x12 * x02) + x02 * (x01 * x12 - b11 * x02)
    r = min(max(0.5 * det_b / (p2 * p if pos else 1.0), -1.0), 1.0)
    t = _cubic_root01(2.0 * (1.0 + r))
    t2 = _cubic_root01(2.0 * (1.0 - r))
    l1 = q + p * (1.0 + t)
    l2c = q + p * (t2 - t)
    tie12 = (l1 - l2c) * (l1 - l2c) <= 64.0 * _EPS * p * (p + abs(q))
    l1 = 0.5 * (l1 + l2c) if tie12 else l1
    l1_pos = l1 > 0.0
    inv1 = 1.0 / (l1 if l1_pos else 1.0)
    prod23 = det * inv1
    sum23 = (c2 - prod23) * inv1
    disc = 0.25 * sum23 * sum23 - prod23
    root = math.sqrt(disc if disc > 0.0 else 1.0) if disc > 64.0 * _EPS * sum23 * sum23 else 0.0
    l2 = l1 if tie12 else ((0.5 * sum23 + root) if l1_pos else 0.0)
    return l1, l2


@nb.njit(**INLINE)
def sym3_top2(x00, x11, x22, x01, x02, x12, c2, det, method):
    """(lambda_1, lambda_2), the two largest eigenvalues of a symmetric PSD 3x3 with principal-minor sum ``c2``
    and determinant ``det``; ``method`` :data:`FAST` or :data:`JACOBI` (which ignores c2, det; a constant
    inside the kernels' loops: LLVM unswitches it)."""
    if method == JACOBI:
        return _eig_top2_jacobi(x00, x11, x22, x01, x02, x12)
    return _eig_top2_fast(x00, x11, x22, x01, x02, x12, c2, det)


@nb.njit(**INLINE)
def singular_values_from_eig(e1, e2, jx_side, prod_d, det_jx):
    """(s1, s2, s3) from the two largest eigenvalues of :func:`sv_matrix`'s X (the second half of the core's
    singular_values): the third from the exact determinant s1 s2 s3 = |prod d| / |det Jx|. Three divisions
    shared by both sides."""
    r1 = math.sqrt(e1) if e1 > 0.0 else 0.0
    r2 = math.sqrt(e2) if e2 > 0.0 else 0.0
    det_pos = det_jx > 0.0
    det_safe = det_jx if det_pos else 1.0
    # Jx side: b3 = prod / r1, b2 = prod / r2; Jq side: a1 = r1 / det, a2 = r2 / det
    x1 = (prod_d if jx_side else r1) / ((r1 if r1 > 0.0 else 1.0) if jx_side else det_safe)
    x2 = (prod_d if jx_side else r2) / ((r2 if r2 > 0.0 else 1.0) if jx_side else det_safe)
    x1 = x1 if (jx_side or det_pos) else math.inf
    x2 = x2 if (jx_side or det_pos) else math.inf
    x12 = x1 * x2  # b3 b2 | a1 a2
    den = det_jx * x12 if jx_side else det_safe * x12
    pos = (den > 0.0) if jx_side else (det_pos & (x12 > 0.0))
    x3 = prod_d / (den if pos else 1.0)
    x3 = x3 if pos else (math.inf if jx_side else 0.0)  # b1 | a3
    return (x3 if jx_side else x1), x2, (x1 if jx_side else x3)


@nb.njit(**INLINE)
def singular_values(j00, j01, j02, j10, j11, j12, j20, j21, j22, d0, d1, d2, method):
    """Singular values (s1 >= s2 >= s3) of M = Jx^-1 diag(d): twin of the core's ``singular_values(jx, d)``."""
    jx_side, prod_d, det_jx, c2, det_x, x00, x11, x22, x01, x02, x12 = sv_matrix(j00, j01, j02, j10, j11, j12, j20,
                                                                                 j21, j22, d0, d1, d2)
    e1, e2 = sym3_top2(x00, x11, x22, x01, x02, x12, c2, det_x, method)
    return singular_values_from_eig(e1, e2, jx_side, prod_d, det_jx)


# -- indices (twins of deltajax.indices) -------------------------------------------------------------------------
@nb.njit(**INLINE)
def sigma_tilde(sig, a, b):
    """The paper's piecewise quadratic: 1 - ((sig - a) / a)^2 up to a, 1 - ((sig - a) / (b - a))^2 up to b,
    0 above; NaN stays NaN."""
    if sig <= a:
        u = sig * (1.0 / a)                   # loop-invariant reciprocals
        v = u * (2.0 - u)                     # = 1 - (u - 1)^2, exactly 0 at sig = 0, as the JAX definition
    else:
        t = (sig - a) * (1.0 / (b - a))
        v = 1.0 - t * t
    return 0.0 if sig > b else v


@nb.njit(**INLINE)
def k_tilde(sigma_min_v, sigma_min_f, kt):
    """k~ = s~_v(sigma_min_v) s~_f(sigma_min_f) with ``kt`` = (a_v, b_v, a_f, b_f) (:func:`kt_tuple`)."""
    return sigma_tilde(sigma_min_v, kt[0], kt[1]) * sigma_tilde(sigma_min_f, kt[2], kt[3])


@nb.njit(**INLINE)
def indices_from_sv(s1, s2, s3, raw_scale, kt):
    """All indices from the singular values, in :data:`deltajax.INDEX_NAMES` order (8 floats); ``kt`` =
    (a_v, b_v, a_f, b_f); ``raw_scale`` = L1^3 (homogenised -> raw manipulability)."""
    omega_v = s1 * s2 * s3
    manip = omega_v * raw_scale
    sigma_min_f = 1.0 / s1
    omega_f = 1.0 / omega_v
    return (s3 * sigma_min_f, s3, sigma_min_f, omega_v, omega_f,
            k_tilde(s3, sigma_min_f, kt), manip,
            omega_f * (1.0 / raw_scale))


@nb.njit(**INLINE)
def point_kernel(x, y, z, R, r, L1, L2, lim, kt, method):
    """The whole kernel at one point (twin of :func:`deltajax.indices.point_kernel`, theta3x3 homogenised by
    L1): (feasible, 8 indices). Feasible = every loop closes within the joint limits and det Jx != 0
    exactly (redundancy resolution's rule). Branch-free: the indices are meaningless where not feasible."""
    ok, det_s, j00, j01, j02, j10, j11, j12, j20, j21, j22, d0, d1, d2 = jacobian_blocks(x, y, z, R, r, L1, L2, lim)
    s1, s2, s3 = singular_values(j00, j01, j02, j10, j11, j12, j20, j21, j22, d0, d1, d2, method)
    i0, i1, i2, i3, i4, i5, i6, i7 = indices_from_sv(s1, s2, s3, L1 * L1 * L1, kt)
    return ok & (det_s != 0.0), i0, i1, i2, i3, i4, i5, i6, i7


@nb.njit(**INLINE)
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
    """(feasible, criterion value) of the kernel at one canonical point (redundancy resolution)."""
    f, i0, i1, i2, i3, i4, i5, i6, i7 = point_kernel(x, y, z, R, r, L1, L2, lim, kt, method)
    return f, criterion_of(crit, i0, i1, i2, i3, i4, i5, i6, i7)
