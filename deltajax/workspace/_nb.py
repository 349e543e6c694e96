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
