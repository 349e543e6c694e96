"""Numba kernels of the host drivers (grid fields, redundancy resolution, reconfigurable reach).

Why Numba and not JAX here: the kernel (algebraic IK + Jacobians + closed-form singular values) compiled by
XLA:CPU runs at ~0.3-2 M evaluations/s (many fusions with intermediate arrays in memory, SPEC §7), while a
per-point loop runs at tens of millions per second and -- more important for redundancy resolution -- can
*skip* work per (point, R) pair: the full kernel runs only where the IK succeeds. The arithmetic is a
line-by-line port of :func:`deltajax.ik_cos_sin` and :func:`deltajax.indices.singular_values_closed_form`
(same formulas, same order), so results agree with the JAX kernel to rounding (tested), and the fast and
exact modes share this one compiled function, so they evaluate every shared (point, R) pair bit-identically.

Index order in the output rows: :data:`deltajax.INDEX_NAMES` (inv_cond, sigma_min_v, sigma_min_f, omega_v,
omega_f, k_tilde, manipulability, imi).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..geometry import CHAIN_ANGLES

_CA = np.array([math.cos(a) for a in CHAIN_ANGLES])
_SA = np.array([math.sin(a) for a in CHAIN_ANGLES])
N_IDX = 8

# error_model="numpy": x / 0 gives inf/nan like NumPy and JAX instead of raising (Python semantics)
_opts = dict(cache=True, fastmath=False, nogil=True, error_model="numpy")


@nb.njit(**_opts)
def _ik_ok(x, y, z, R, r, L1, L2, lim):
    """All three chains reachable (outer branch) within limits; y must already be canonical (|y|)."""
    for i in range(3):
        ca = _CA[i]
        sa = _SA[i]
        px = ca * x + sa * y
        py = -sa * x + ca * y
        dx = px + r - R
        rho2 = dx * dx + z * z
        m = (rho2 + py * py + L1 * L1 - L2 * L2) / (2.0 * L1)
        disc = rho2 - m * m
        if not (disc >= 0.0 and rho2 > 0.0):
            return False
        if lim[3] > 0.0:
            w = math.sqrt(disc)
            inv = 1.0 / rho2
            c = (dx * m + z * w) * inv
            s = (z * m - dx * w) * inv
            if not (c * lim[0] + s * lim[1] >= lim[2]):
                return False
    return True


@nb.njit(**_opts)
def _rot(A, p, q):
    r = 3 - p - q
    app = A[p, p]
    aqq = A[q, q]
    apq = A[p, q]
    arp = A[r, p]
    arq = A[r, q]
    if apq == 0.0:
        t = 0.0
    else:
        tau = (aqq - app) / (2.0 * apq)
        sg = 1.0 if (tau + (1.0 if tau == 0.0 else 0.0)) > 0 else -1.0
        t = sg / (abs(tau) + math.sqrt(1.0 + tau * tau))
    c = 1.0 / math.sqrt(1.0 + t * t)
    s = t * c
    A[p, p] = app - t * apq
    A[q, q] = aqq + t * apq
    A[p, q] = 0.0
    A[q, p] = 0.0
    a = c * arp - s * arq
    b = s * arp + c * arq
    A[r, p] = a
    A[p, r] = a
    A[r, q] = b
    A[q, r] = b


@nb.njit(**_opts)
def _point(x, y, z, R, r, L1, L2, lim, kt, out, S):
    """Indices of one point into ``out`` (8,); returns 0 unreachable, 1 ok, 2 Jx exactly singular.

    ``S`` is a (6, 3, 3) scratch array (allocated once per point by the caller: no allocation per sample).
    """
    cc = S[0, 0]
    ss = S[0, 1]
    d = S[0, 2]
    U = S[1]  # local unit forearm vectors
    for i in range(3):
        ca = _CA[i]
        sa = _SA[i]
        px = ca * x + sa * y
        py = -sa * x + ca * y
        dx = px + r - R
        rho2 = dx * dx + z * z
        m = (rho2 + py * py + L1 * L1 - L2 * L2) / (2.0 * L1)
        disc = rho2 - m * m
        if not (disc >= 0.0 and rho2 > 0.0):
            return 0
        w = math.sqrt(disc)
        inv = 1.0 / rho2
        c = (dx * m + z * w) * inv
        s = (z * m - dx * w) * inv
        if lim[3] > 0.0 and not (c * lim[0] + s * lim[1] >= lim[2]):
            return 0
        cc[i] = c
        ss[i] = s
        U[i, 0] = (px + r - R - L1 * c) / L2
        U[i, 1] = py / L2
        U[i, 2] = (z - L1 * s) / L2
    J = S[2]
    for i in range(3):
        J[i, 0] = _CA[i] * U[i, 0] - _SA[i] * U[i, 1]
        J[i, 1] = _SA[i] * U[i, 0] + _CA[i] * U[i, 1]
        J[i, 2] = U[i, 2]
        d[i] = U[i, 2] * cc[i] - U[i, 0] * ss[i]
    det_s = (J[0, 0] * (J[1, 1] * J[2, 2] - J[1, 2] * J[2, 1])
             - J[0, 1] * (J[1, 0] * J[2, 2] - J[1, 2] * J[2, 0])
             + J[0, 2] * (J[1, 0] * J[2, 1] - J[1, 1] * J[2, 0]))
    if det_s == 0.0:
        return 2
    det_jx = abs(det_s)
    G = S[3]
    for a in range(3):
        for b in range(3):
            G[a, b] = J[a, 0] * J[b, 0] + J[a, 1] * J[b, 1] + J[a, 2] * J[b, 2]
    prod_d = abs(d[0] * d[1] * d[2])
    jx_side = det_jx < prod_d
    A = S[4]
    if jx_side:
        ad0 = d[1] * d[2]
        ad1 = d[0] * d[2]
        ad2 = d[0] * d[1]
        cc[0] = ad0  # cc is no longer needed: reuse it for adj(D)
        cc[1] = ad1
        cc[2] = ad2
        for a in range(3):
            for b in range(3):
                A[a, b] = cc[a] * G[a, b] * cc[b]
    else:
        g00 = G[0, 0]
        g11 = G[1, 1]
        g22 = G[2, 2]
        g01 = G[0, 1]
        g02 = G[0, 2]
        g12 = G[1, 2]
        C = S[5]
        C[0, 0] = g11 * g22 - g12 * g12
        C[1, 1] = g00 * g22 - g02 * g02
        C[2, 2] = g00 * g11 - g01 * g01
        C[0, 1] = C[1, 0] = g02 * g12 - g01 * g22
        C[0, 2] = C[2, 0] = g01 * g12 - g02 * g11
        C[1, 2] = C[2, 1] = g01 * g02 - g00 * g12
        for a in range(3):
            for b in range(3):
                A[a, b] = d[a] * C[a, b] * d[b]
    for _ in range(4):
        _rot(A, 0, 1)
        _rot(A, 0, 2)
        _rot(A, 1, 2)
    e0 = A[0, 0]
    e1 = A[1, 1]
    e2 = A[2, 2]
    hi = max(max(e0, e1), e2)
    lo = min(min(e0, e1), e2)
    mid = e0 + e1 + e2 - hi - lo
    r1 = math.sqrt(max(hi, 0.0))
    r2 = math.sqrt(max(mid, 0.0))
    if jx_side:
        s3 = prod_d / r1 if r1 > 0 else prod_d
        s2 = prod_d / r2 if r2 > 0 else prod_d
        b23 = s2 * s3
        s1 = prod_d / (det_jx * b23) if det_jx * b23 > 0 else math.inf
    else:
        s1 = r1 / det_jx
        s2 = r2 / det_jx
        a12 = s1 * s2
        s3 = prod_d / (det_jx * a12) if a12 > 0 else 0.0
    ov = s1 * s2 * s3
    out[0] = s3 / s1
    out[1] = s3
    out[2] = 1.0 / s1
    out[3] = ov
    out[4] = 1.0 / ov
    out[5] = _st(s3, kt[0], kt[1]) * _st(1.0 / s1, kt[2], kt[3])
    out[6] = ov * L1 * L1 * L1
    out[7] = 1.0 / out[6]
    return 1


@nb.njit(**_opts)
def _st(sig, a, b):
    if math.isnan(sig):
        return math.nan
    if sig <= a:
        t = (sig - a) / a
        return 1.0 - t * t
    if sig <= b:
        t = (sig - a) / (b - a)
        return 1.0 - t * t
    return 0.0


@nb.njit(**_opts)
def fixed_fields(pts, R, r, L1, L2, lim, kt, out, ok):
    """Indices (n, 8) and ok (n,) of a fixed robot at canonical points (n, 3)."""
    n = pts.shape[0]
    scratch = np.empty((1, 6, 3, 3))
    for j in range(n):
        row = out[j]
        S = scratch[0]
        st = _point(pts[j, 0], abs(pts[j, 1]), pts[j, 2], R, r, L1, L2, lim, kt, row, S)
        ok[j] = st == 1
        if st != 1:
            for q in range(N_IDX):
                row[q] = math.nan


@nb.njit(**_opts)
def fields_at(pts, ks, R_min, R_step, r, L1, L2, lim, kt, out):
    """Indices (n, 8) at sample ks[j] per point (NaN where ks < 0 or not feasible)."""
    n = pts.shape[0]
    scratch = np.empty((1, 6, 3, 3))
    for j in range(n):
        row = out[j]
        st = 0
        if ks[j] >= 0:
            S = scratch[0]
            st = _point(pts[j, 0], abs(pts[j, 1]), pts[j, 2], R_min + ks[j] * R_step, r, L1, L2, lim, kt, row, S)
        if st != 1:
            for q in range(N_IDX):
                row[q] = math.nan


@nb.njit(**_opts)
def fixed_mask(pts, R, r, L1, L2, lim, ok):
    n = pts.shape[0]
    for j in range(n):
        ok[j] = _ik_ok(pts[j, 0], abs(pts[j, 1]), pts[j, 2], R, r, L1, L2, lim)


@nb.njit(**_opts)
def resolve(pts, k_start, k_stop, R_min, R_step, r, L1, L2, lim, kt, crit, best_k, best_v, n_full):
    """Per point: the sample k in [k_start, k_stop) maximising index ``crit`` (ties -> smallest k).

    The cheap IK test runs first for every sample; the full kernel only where it passes. ``n_full``
    counts full-kernel evaluations per point.
    """
    n = pts.shape[0]
    scratch = np.empty((1, 6, 3, 3))
    rows = np.empty((1, N_IDX))
    for j in range(n):
        x = pts[j, 0]
        y = abs(pts[j, 1])
        z = pts[j, 2]
        tid = 0
        row = rows[tid]
        S = scratch[tid]
        bk = -1
        bv = -math.inf
        cnt = 0
        for k in range(k_start[j], k_stop[j]):
            R = R_min + k * R_step
            if not _ik_ok(x, y, z, R, r, L1, L2, lim):
                continue
            cnt += 1
            if _point(x, y, z, R, r, L1, L2, lim, kt, row, S) != 1:
                continue
            v = row[crit]
            if v > bv:  # NaN never wins; strict: ties keep the smaller R
                bv = v
                bk = k
        best_k[j] = bk
        best_v[j] = bv
        n_full[j] = cnt


@nb.njit(**_opts)
def any_reach(pts, k_start, k_stop, R_min, R_step, r, L1, L2, lim, ok):
    n = pts.shape[0]
    for j in range(n):
        x = pts[j, 0]
        y = abs(pts[j, 1])
        z = pts[j, 2]
        hit = False
        for k in range(k_start[j], k_stop[j]):
            if _ik_ok(x, y, z, R_min + k * R_step, r, L1, L2, lim):
                hit = True
                break
        ok[j] = hit


@nb.njit(**_opts)
def reach_k_range(pts, R_min, R_step, n_R, r, L1, L2, k_lo, k_hi):
    """Closed-form sample range (see redundancy.reach_interval), widened by one sample each side."""
    n = pts.shape[0]
    for j in range(n):
        x = pts[j, 0]
        y = abs(pts[j, 1])
        z = pts[j, 2]
        lo = -math.inf
        hi = math.inf
        for i in range(3):
            px = _CA[i] * x + _SA[i] * y
            py = -_SA[i] * x + _CA[i] * y
            l2p2 = L2 * L2 - py * py
            if l2p2 < 0:
                lo = math.inf
                break
            h2 = (math.sqrt(l2p2) + L1) ** 2 - z * z
            if h2 < 0:
                lo = math.inf
                break
            half = math.sqrt(h2)
            lo = max(lo, px + r - half)
            hi = min(hi, px + r + half)
        if not (lo <= hi):
            k_lo[j] = 0
            k_hi[j] = 0
            continue
        a = math.ceil((lo - R_min) / R_step) - 1.0
        b = math.floor((hi - R_min) / R_step) + 1.0
        a = min(max(a, 0.0), float(n_R))
        b = min(max(b, -1.0), float(n_R - 1))
        k_lo[j] = int(a)
        k_hi[j] = int(b) + 1 if b >= a else int(a)  # exclusive stop


def parallel(block_fn, n: int, n_threads: int | None = None) -> None:
    """Call ``block_fn(lo, hi)`` over contiguous blocks of ``range(n)`` in threads.

    The kernels release the GIL (``nogil``); each block works on disjoint slices of the per-point arrays,
    so there is no shared mutable state (numba's ``prange`` dropped iterations of these loops in our tests,
    so we parallelise by hand). Results do not depend on the number of threads.
    """
    import os
    from concurrent.futures import ThreadPoolExecutor

    if n_threads is None:
        n_threads = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    blocks = max(1, min(n_threads * 8, n // 64))
    edges = np.linspace(0, n, blocks + 1).astype(np.int64)
    if blocks == 1 or n_threads == 1:
        block_fn(0, n)
        return
    with ThreadPoolExecutor(n_threads) as ex:
        for f in [ex.submit(block_fn, int(edges[i]), int(edges[i + 1])) for i in range(blocks)]:
            f.result()


def limits_tuple(theta_min: float, theta_max: float) -> np.ndarray:
    """(cos mid, sin mid, cos half, has_limits) of the joint range, as ik_cos_sin uses it."""
    if math.isfinite(theta_min) and math.isfinite(theta_max):
        mid = 0.5 * (theta_min + theta_max)
        half = 0.5 * (theta_max - theta_min)
        return np.array([math.cos(mid), math.sin(mid), math.cos(half), 1.0])
    return np.array([1.0, 0.0, -1.0, 0.0])


def kt_tuple(b_v: float, b_f: float, beta: float) -> np.ndarray:
    """(a_v, b_v, a_f, b_f) of k~."""
    return np.array([beta * b_v, b_v, (1.0 - beta) * b_f, b_f], dtype=np.float64)


# -- screen-and-verify redundancy resolution (fast mode) -------------------------------------------------------
#
# The screen evaluates an approximation of the criterion at every sample of a point's window together with a
# bound on its difference from the exact kernel's value; only samples that can still be the exact argmax are
# then evaluated by the exact kernel (:func:`_point`). See :func:`resolve_screened` and the module docstring of
# :mod:`.redundancy` for the argument; the constants below are the bound's ingredients.

_EPS = 2.220446049250313e-16
#: eigenvalue rounding of both solvers (Jacobi: backward stable, ~eps ||A|| per rotation, 12 rotations; the
#: trigonometric formula: q, p and the final sums), in units of eps (|q| + 2 p) >= eps ||A||_2. Measured
#: worst case over 2e6 random workspace samples: ~6 (tests/test_workspace_screen.py); 512 is the bound used.
_C_LAMBDA = 512.0
#: rounding of r = det(B) / 2 with B = (A - q I) / p, in units of eps (1 + |q| / p): the entries of B are
#: <= sqrt 6 (6 products of 3 entries), and the diagonal a_ii - q carries the rounding of q, ~3 eps |q|,
#: which is large relative to p when the eigenvalues are clustered (near the robot's axis |q| / p ~ 1e4).
_C_R = 512.0
#: residual of _tcubic (polynomial guess + one Halley step) over w in [0, 4]: measured 5.6e-16 (tested).
_T_NEWTON = 1e-14
#: least-squares fit of t / s, s = sqrt(w / 3), on [0, 2 / sqrt 3] (max error of the guess 1.1e-5)
_TC4, _TC3, _TC2, _TC1, _TC0 = (0.004862740934509117, -0.02386905831264214, 0.06417057523483471,
                                -0.16573685947992756, 0.9999539697770844)


@nb.njit(inline="always", **_opts)
def _tcubic(w):
    """Root t in [0, 1] of t^2 (t + 3) = w, w in [0, 4]; branch-free, one sqrt and one division.

    With c = (1 + t) / 2 this is the largest root of the Chebyshev equation 4 c^3 - 3 c = w / 2 - 1, i.e.
    cos(acos(r) / 3) of the trigonometric Cardano formula, without inverse trigonometry (vectorisable).
    A polynomial guess in s = sqrt(w / 3) (t = s (1 - s / 6 + ...)) and one Halley step (cubic convergence).
    """
    s = math.sqrt(w * (1.0 / 3.0))
    t = s * ((((_TC4 * s + _TC3) * s + _TC2) * s + _TC1) * s + _TC0)
    f = t * t * (t + 3.0) - w
    fp = 3.0 * t * (t + 2.0)
    den = 2.0 * fp * fp - f * (6.0 * t + 6.0)
    return t - 2.0 * f * fp / max(den, 1e-300)


@nb.njit(inline="always", **_opts)
def _guess(w):
    s = math.sqrt(w * (1.0 / 3.0))
    return s * ((((_TC4 * s + _TC3) * s + _TC2) * s + _TC1) * s + _TC0)


@nb.njit(inline="always", **_opts)
def _tcubic2(wp, wm):
    """:func:`_tcubic` of two arguments with one shared division (x / a, y / b = x b / (a b), y a / (a b))."""
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


@nb.njit(inline="always", **_opts)
def _dt_bound2(tp, tm, a, dw):
    """Bound on |t(w + e) - t(w)| for |e| <= dw (a = sqrt(dw / 3)), for the roots tp and tm (summed): a always
    (t^2 (t + 3) >= 3 t^2 and t increasing), dw / f'(t - a) where the root is away from 0 (t is concave in
    w), 1 (t in [0, 1]); plus the solver residual. One shared division."""
    lp = tp - a
    lm = tm - a
    fp_ = 3.0 * lp * (lp + 2.0) if lp > 0.0 else 1e-150
    fm_ = 3.0 * lm * (lm + 2.0) if lm > 0.0 else 1e-150
    inv = dw / (fp_ * fm_)
    return min(min(a, fm_ * inv), 1.0) + min(min(a, fp_ * inv), 1.0) + 2.0 * _T_NEWTON


@nb.njit(**_opts)
def screen_window(x, y, z, k0, k1, R_min, R_step, r, L1, L2, lim, kt, crit, tol, lo, hi, feas):
    """Approximate criterion at samples k0 <= k < k1 of canonical point (x, y, z), with error bounds.

    Writes, for j = k - k0: ``feas[j]`` = 1 where the exact kernel finds the sample feasible (IK within limits
    and det Jx != 0: the same floating-point expressions as :func:`_point`, so the same decision), and an
    interval [lo[j], hi[j]] that contains the exact kernel's criterion value (-inf, -inf where infeasible;
    -inf, +inf where no bound is available). Straight-line loop body (no inverse trig, no early exit) so
    that LLVM can vectorise it over the samples.

    Eigenvalues: the same matrix as :func:`_point` (S = D adj(G) D or T = adj(D) G adj(D)); instead of Jacobi,
    the trigonometric Cardano formula lambda = q + 2 p cos(phi), written as lambda_max = q + p (1 + t),
    lambda_min = q - p (1 + t'), lambda_mid = q + p (t' - t) with t^2 (t + 3) = 2 (1 + r), t'^2 (t' + 3) =
    2 (1 - r), r = det((A - q I) / p) / 2 (:func:`_tcubic`).
    """
    ca0, ca1, ca2 = _CA[0], _CA[1], _CA[2]
    sa0, sa1, sa2 = _SA[0], _SA[1], _SA[2]
    px0 = ca0 * x + sa0 * y
    py0 = -sa0 * x + ca0 * y
    px1 = ca1 * x + sa1 * y
    py1 = -sa1 * x + ca1 * y
    px2 = ca2 * x + sa2 * y
    py2 = -sa2 * x + ca2 * y
    cx0 = px0 + r
    cx1 = px1 + r
    cx2 = px2 + r
    q0 = py0 * py0
    q1 = py1 * py1
    q2 = py2 * py2
    u01 = py0 / L2
    u11 = py1 / L2
    u21 = py2 / L2
    zz = z * z
    L11 = L1 * L1
    L22 = L2 * L2
    tl1 = 2.0 * L1
    lim0, lim1, lim2 = lim[0], lim[1], lim[2]
    nolim = not (lim[3] > 0.0)
    a_v, b_v, a_f, b_f = kt[0], kt[1], kt[2], kt[3]
    slope_v = 2.0 / min(a_v, b_v - a_v)
    slope_f = 2.0 / min(a_f, b_f - a_f)
    ia_v = 1.0 / a_v
    iba_v = 1.0 / (b_v - a_v)
    ia_f = 1.0 / a_f
    iba_f = 1.0 / (b_f - a_f)
    L13 = L1 * L1 * L1
    for j in range(k1 - k0):
        R = R_min + (k0 + j) * R_step
        # chain 0 (the expressions of _point, in the same order)
        dx = cx0 - R
        rho2 = dx * dx + zz
        m = (rho2 + q0 + L11 - L22) / tl1
        disc = rho2 - m * m
        ok0 = (disc >= 0.0) & (rho2 > 0.0)
        w = math.sqrt(disc if disc >= 0.0 else 0.0)
        inv = 1.0 / rho2
        c0 = (dx * m + z * w) * inv
        s0 = (z * m - dx * w) * inv
        ok0 = ok0 & (nolim | (c0 * lim0 + s0 * lim1 >= lim2))
        u00 = (dx - L1 * c0) / L2
        u02 = (z - L1 * s0) / L2
        # chain 1
        dx = cx1 - R
        rho2 = dx * dx + zz
        m = (rho2 + q1 + L11 - L22) / tl1
        disc = rho2 - m * m
        ok1 = (disc >= 0.0) & (rho2 > 0.0)
        w = math.sqrt(disc if disc >= 0.0 else 0.0)
        inv = 1.0 / rho2
        c1 = (dx * m + z * w) * inv
        s1_ = (z * m - dx * w) * inv
        ok1 = ok1 & (nolim | (c1 * lim0 + s1_ * lim1 >= lim2))
        u10 = (dx - L1 * c1) / L2
        u12 = (z - L1 * s1_) / L2
        # chain 2
        dx = cx2 - R
        rho2 = dx * dx + zz
        m = (rho2 + q2 + L11 - L22) / tl1
        disc = rho2 - m * m
        ok2 = (disc >= 0.0) & (rho2 > 0.0)
        w = math.sqrt(disc if disc >= 0.0 else 0.0)
        inv = 1.0 / rho2
        c2 = (dx * m + z * w) * inv
        s2_ = (z * m - dx * w) * inv
        ok2 = ok2 & (nolim | (c2 * lim0 + s2_ * lim1 >= lim2))
        u20 = (dx - L1 * c2) / L2
        u22 = (z - L1 * s2_) / L2
        # Jx rows (base frame) and D
        j00 = ca0 * u00 - sa0 * u01
        j01 = sa0 * u00 + ca0 * u01
        j02 = u02
        j10 = ca1 * u10 - sa1 * u11
        j11 = sa1 * u10 + ca1 * u11
        j12 = u12
        j20 = ca2 * u20 - sa2 * u21
        j21 = sa2 * u20 + ca2 * u21
        j22 = u22
        d0 = u02 * c0 - u00 * s0
        d1 = u12 * c1 - u10 * s1_
        d2 = u22 * c2 - u20 * s2_
        det_s = (j00 * (j11 * j22 - j12 * j21)
                 - j01 * (j10 * j22 - j12 * j20)
                 + j02 * (j10 * j21 - j11 * j20))
        ok = ok0 & ok1 & ok2 & (det_s != 0.0)
        det_jx = abs(det_s)
        g00 = j00 * j00 + j01 * j01 + j02 * j02
        g11 = j10 * j10 + j11 * j11 + j12 * j12
        g22 = j20 * j20 + j21 * j21 + j22 * j22
        g01 = j00 * j10 + j01 * j11 + j02 * j12
        g02 = j00 * j20 + j01 * j21 + j02 * j22
        g12 = j10 * j20 + j11 * j21 + j12 * j22
        prod_d = abs(d0 * d1 * d2)
        jx_side = det_jx < prod_d
        # T = adj(D) G adj(D) (entries as _point's Jacobi reads them: A[0,1], A[2,0], A[2,1])
        e0 = d1 * d2
        e1 = d0 * d2
        e2 = d0 * d1
        t00 = e0 * g00 * e0
        t11 = e1 * g11 * e1
        t22 = e2 * g22 * e2
        t01 = e0 * g01 * e1
        t02 = e2 * g02 * e0
        t12 = e2 * g12 * e1
        # S = D adj(G) D
        c00 = g11 * g22 - g12 * g12
        c11 = g00 * g22 - g02 * g02
        c22 = g00 * g11 - g01 * g01
        c01 = g02 * g12 - g01 * g22
        c02 = g01 * g12 - g02 * g11
        c12 = g01 * g02 - g00 * g12
        s00 = d0 * c00 * d0
        s11 = d1 * c11 * d1
        s22 = d2 * c22 * d2
        s01 = d0 * c01 * d1
        s02 = d2 * c02 * d0
        s12 = d2 * c12 * d1
        a00 = t00 if jx_side else s00
        a11 = t11 if jx_side else s11
        a22 = t22 if jx_side else s22
        a01 = t01 if jx_side else s01
        a02 = t02 if jx_side else s02
        a12 = t12 if jx_side else s12
        # eigenvalues (trigonometric form, no inverse trig)
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
        wp = 2.0 * (1.0 + rr)
        wm = 2.0 * (1.0 - rr)
        tp, tm = _tcubic2(wp, wm)
        dw = 2.0 * _C_R * _EPS * (1.0 + abs(q) * ip) if p > 0.0 else 0.0  # error of wp, wm
        dt_a = math.sqrt(dw * (1.0 / 3.0))
        lam_hi = q + p * (1.0 + tp)
        lam_mid = q + p * (tm - tp)
        e_lam = _C_LAMBDA * _EPS * (abs(q) + 2.0 * p) + p * _dt_bound2(tp, tm, dt_a, dw)
        # singular values (the formulas of _point, rearranged: two divisions)
        r1 = math.sqrt(max(lam_hi, 0.0))
        r2 = math.sqrt(max(lam_mid, 0.0))
        ir12 = 1.0 / (r1 * r2)
        ir1 = r2 * ir12
        # Jx side: s3 = |prod d| / r1, s2 = |prod d| / r2, 1/s1 = |det Jx| |prod d| / (r1 r2)
        # Jq side: s1 = r1 / |det Jx|, s2 = r2 / |det Jx|, s3 = |prod d| |det Jx| / (r1 r2)
        pdj = prod_d * det_jx * ir12
        sv3 = prod_d * ir1 if jx_side else pdj
        inv1 = pdj if jx_side else det_jx * ir1
        # relative error bounds (first order x 2; each lambda known to e_lam; 8 eps for the rearrangement)
        rho_hi = e_lam * ir1 * ir1
        rho_mid = e_lam * (ir12 * r1) * (ir12 * r1)
        ea = 2.0 * rho_hi + 8.0 * _EPS  # singular value from lambda_max
        eb = 2.0 * rho_mid + 8.0 * _EPS  # from lambda_mid
        ec = 2.0 * (ea + eb) + 8.0 * _EPS  # from the determinant
        er1 = ec if jx_side else ea
        er3 = ea if jx_side else ec
        big = ((max(ea, eb) > 0.05) | (not (lam_hi > 0.0)) | (not (lam_mid > 0.0)) | (not (inv1 > 0.0))
               | (not (sv3 >= 0.0)) | (not (inv1 < math.inf)) | (not (sv3 < math.inf)))
        # criterion value and absolute error bound
        if crit == 5:
            fv = 1.0 - ((sv3 - a_v) * ia_v) ** 2 if sv3 <= a_v else 1.0 - ((sv3 - a_v) * iba_v) ** 2
            fv = fv if sv3 <= b_v else 0.0
            ff = 1.0 - ((inv1 - a_f) * ia_f) ** 2 if inv1 <= a_f else 1.0 - ((inv1 - a_f) * iba_f) ** 2
            ff = ff if inv1 <= b_f else 0.0
            val = fv * ff
            err = slope_v * sv3 * er3 + slope_f * inv1 * er1 + 16.0 * _EPS
        elif crit == 0:
            val = sv3 * inv1
            err = val * 2.0 * (er1 + er3)
        elif crit == 1:
            val = sv3
            err = sv3 * er3
        elif crit == 2:
            val = inv1
            err = inv1 * er1
        else:
            # s1 s2 s3 = |prod d| / |det Jx| whatever the eigenvalues: only rounding differs
            ov = prod_d / det_jx
            if crit == 3:
                val = ov
            elif crit == 4:
                val = 1.0 / ov
            elif crit == 6:
                val = ov * L13
            else:
                val = 1.0 / (ov * L13)
            err = abs(val) * 64.0 * _EPS
            big = big | (not (ov > 0.0)) | (not (ov < math.inf))
        err = err + tol
        unknown = big | (val != val) | (err != err)
        lo_j = -math.inf if unknown else val - err
        hi_j = math.inf if unknown else val + err
        lo[j] = lo_j if ok else -math.inf
        hi[j] = hi_j if ok else -math.inf
        feas[j] = 1 if ok else 0


@nb.njit(**_opts)
def resolve_screened(pts, k_start, k_stop, R_min, R_step, r, L1, L2, lim, kt, crit, tol, best_k, best_v, n_full,
                     n_fallback):
    """Screen-and-verify version of :func:`resolve`: the identical selection, far fewer exact kernels.

    Per point: :func:`screen_window` gives intervals [lo_k, hi_k] around the exact value v_k of every
    feasible sample; with T = max_k lo_k, a sample with hi_k < T has v_k < T <= v_m for the sample m of the
    largest lo, so it cannot be the (first) argmax. The exact kernel then runs on the candidates
    (hi_k >= T) in increasing k with the comparison of :func:`resolve` (strict >: ties to the smallest k).
    Certification: every non-candidate has v_k <= hi_k < T, so if the best exact candidate value is >= T the
    result is the exact sweep's; otherwise (only possible if a bound failed, e.g. a NaN exact value at the
    sample defining T) the point falls back to the full exact sweep of its window (counted in n_fallback).
    """
    n = pts.shape[0]
    scratch = np.empty((1, 6, 3, 3))
    rows = np.empty((1, N_IDX))
    width = 0
    for j in range(n):
        width = max(width, k_stop[j] - k_start[j])
    lo = np.empty(max(width, 1))
    hi = np.empty(max(width, 1))
    feas = np.empty(max(width, 1), np.uint8)
    for j in range(n):
        x = pts[j, 0]
        y = abs(pts[j, 1])
        z = pts[j, 2]
        row = rows[0]
        S = scratch[0]
        k0 = k_start[j]
        k1 = k_stop[j]
        bk = -1
        bv = -math.inf
        cnt = 0
        fb = 0
        # trim the window to its first and last IK-feasible samples (scalar test, early exit)
        while k0 < k1 and not _ik_ok(x, y, z, R_min + k0 * R_step, r, L1, L2, lim):
            k0 += 1
        while k1 > k0 and not _ik_ok(x, y, z, R_min + (k1 - 1) * R_step, r, L1, L2, lim):
            k1 -= 1
        if k1 > k0:
            screen_window(x, y, z, k0, k1, R_min, R_step, r, L1, L2, lim, kt, crit, tol, lo, hi, feas)
            T = -math.inf
            anyf = False
            for i in range(k1 - k0):
                if feas[i] != 0:
                    anyf = True
                    if lo[i] > T:
                        T = lo[i]
            if anyf:
                for i in range(k1 - k0):
                    if feas[i] != 0 and hi[i] >= T:
                        cnt += 1
                        if _point(x, y, z, R_min + (k0 + i) * R_step, r, L1, L2, lim, kt, row, S) != 1:
                            continue
                        v = row[crit]
                        if v > bv:
                            bv = v
                            bk = k0 + i
                if not (bv >= T):  # a bound failed: the exact sweep of the window
                    fb = 1
                    bk = -1
                    bv = -math.inf
                    for i in range(k1 - k0):
                        if feas[i] == 0:
                            continue
                        cnt += 1
                        if _point(x, y, z, R_min + (k0 + i) * R_step, r, L1, L2, lim, kt, row, S) != 1:
                            continue
                        v = row[crit]
                        if v > bv:
                            bv = v
                            bk = k0 + i
        best_k[j] = bk
        best_v[j] = bv
        n_full[j] = cnt
        n_fallback[j] = fb


@nb.njit(**_opts)
def screen_audit(pts, k_start, k_stop, R_min, R_step, r, L1, L2, lim, kt, crit, out):
    """Check the screen against the exact kernel at every sample of every window (tests, benchmark).

    ``out`` (n, 4) per point: [max |approx - exact|, max |approx - exact| / bound (the screen's error bound
    without margin), number of samples outside their interval or with a different feasibility decision,
    number of feasible samples]; approx is the interval's centre. NaN exact values are skipped.
    """
    n = pts.shape[0]
    S = np.empty((6, 3, 3))
    row = np.empty(N_IDX)
    width = 1
    for j in range(n):
        width = max(width, k_stop[j] - k_start[j])
    lo = np.empty(width)
    hi = np.empty(width)
    feas = np.empty(width, np.uint8)
    for j in range(n):
        x = pts[j, 0]
        y = abs(pts[j, 1])
        z = pts[j, 2]
        k0 = k_start[j]
        k1 = k_stop[j]
        e_abs = 0.0
        e_rel = 0.0
        bad = 0
        nf = 0
        if k1 > k0:
            screen_window(x, y, z, k0, k1, R_min, R_step, r, L1, L2, lim, kt, crit, 0.0, lo, hi, feas)
            for i in range(k1 - k0):
                st = _point(x, y, z, R_min + (k0 + i) * R_step, r, L1, L2, lim, kt, row, S)
                if (st == 1) != (feas[i] != 0):
                    bad += 1
                    continue
                if st != 1:
                    continue
                nf += 1
                v = row[crit]
                if math.isnan(v):
                    continue
                if not (lo[i] <= v <= hi[i]):
                    bad += 1
                if math.isinf(lo[i]) or math.isinf(hi[i]):
                    continue
                c = 0.5 * (lo[i] + hi[i])
                hw = 0.5 * (hi[i] - lo[i])
                e = abs(c - v)
                e_abs = max(e_abs, e)
                if hw > 0:
                    e_rel = max(e_rel, e / hw)
                elif e > 0:
                    e_rel = math.inf
        out[j, 0] = e_abs
        out[j, 1] = e_rel
        out[j, 2] = bad
        out[j, 3] = nf
