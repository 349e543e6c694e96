"""Numba drivers of the host jobs (grid fields, redundancy resolution, reconfigurable reach) and their threads.

Why Numba and not JAX here: a per-point loop can *skip* work per (point, R) pair -- the full kernel runs only
where the IK succeeds -- and the branch-free kernel compiles to one vectorised loop body. The maths is the
Numba mirror of the JAX core in :mod:`.numba_kernel` (loop closure -> loop vectors -> Jacobian blocks ->
singular values -> indices, name for name, each tested against its JAX twin); the screen of the fast
redundancy mode is in :mod:`.numba_screen`. This module only loops over points and samples.

Index order in the output rows: :data:`deltajax.INDEX_NAMES` (inv_cond, sigma_min_v, sigma_min_f, omega_v,
omega_f, k_tilde, manipulability, imi).
"""

from __future__ import annotations

import math
import os

import numba as nb
import numpy as np

from .numba_kernel import (CA0, CA1, CA2, CRITERION, CUBIC, FAST, INLINE, JACOBI, N_IDX, OPTS, SA0, SA1, SA2,
                         SV_METHODS, as_tuple4, ik_ok, ik_ok_all, kt_tuple, limits_tuple, point_kernel, point_value)
from .numba_screen import resolve_screened, screen_audit, screen_window, tcubic, tcubic2

__all__ = ["N_IDX", "CRITERION", "SV_METHODS", "JACOBI", "FAST", "limits_tuple", "kt_tuple", "fixed_fields",
           "fixed_fields_dense", "fields_at", "rows", "fixed_mask", "resolve", "resolve_screened", "screen_window", "screen_audit", "any_reach",
           "reach_k_range", "parallel", "plane_stats"]

# names the tests and benchmarks have used since the first round
_ik_ok = ik_ok
_tcubic = tcubic
_tcubic2 = tcubic2


@nb.njit(**INLINE)
def store_masked(out, j, f, i0, i1, i2, i3, i4, i5, i6, i7):
    """Write the 8 indices of point ``j`` into the rows ``out`` (:func:`rows`), NaN where not ``f``."""
    nan = math.nan
    o0, o1, o2, o3, o4, o5, o6, o7 = out
    o0[j] = i0 if f else nan
    o1[j] = i1 if f else nan
    o2[j] = i2 if f else nan
    o3[j] = i3 if f else nan
    o4[j] = i4 if f else nan
    o5[j] = i5 if f else nan
    o6[j] = i6 if f else nan
    o7[j] = i7 if f else nan


@nb.njit(**OPTS)
def fixed_fields(x, y, z, R, r, L1, L2, lim, kt, out, ok, method=JACOBI):
    """Indices and ``ok`` (n,) of a fixed robot at the points (x, y, z) (each (n,), contiguous;
    mirror-canonical: y -> |y|), NaN where not feasible; ``method`` as in :data:`SV_METHODS`. ``out`` is a
    tuple of 8 contiguous (n,) arrays, one per index (:func:`rows`).

    Structure of arrays and one branch-free loop body: LLVM vectorises it (interleaved (n, 3) / (n, 8)
    layouts, or a strided 2-D block, do not vectorise: measured 4x slower).
    """
    lim, kt = as_tuple4(lim), as_tuple4(kt)
    # the whole kernel only where every loop closes within limits (a grid is mostly unreachable: 80 % of the
    # 2 mm Table-6 grid): a vectorised IK pass, the reachable points gathered into contiguous arrays, the
    # kernel over those, the results scattered back. The same inlined kernel on the same floats: the values
    # are those of the kernel run on every point (tested).
    n = x.shape[0]
    xs, ys, zs, idx = np.empty(n), np.empty(n), np.empty(n), np.empty(n, np.int64)
    for j in range(n):
        ok[j] = ik_ok_all(x[j], abs(y[j]), z[j], R, r, L1, L2, lim)
    m = 0
    for j in range(n):
        if ok[j]:
            xs[m] = x[j]
            ys[m] = abs(y[j])
            zs[m] = z[j]
            idx[m] = j
            m += 1
    nan = math.nan
    for o in out:
        o[:] = nan
    cols = (np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m))
    fm = np.empty(m, np.bool_)
    # one loop per solver, the method a constant in each (LLVM does not unswitch a loop body this large)
    if method == JACOBI:
        _fields_loop(xs[:m], ys[:m], zs[:m], R, r, L1, L2, lim, kt, cols, fm, JACOBI)
    else:
        _fields_loop(xs[:m], ys[:m], zs[:m], R, r, L1, L2, lim, kt, cols, fm, FAST)
    o0, o1, o2, o3, o4, o5, o6, o7 = out
    c0, c1, c2, c3, c4, c5, c6, c7 = cols
    for t in range(m):
        j = idx[t]
        ok[j] = fm[t]
        o0[j] = c0[t]
        o1[j] = c1[t]
        o2[j] = c2[t]
        o3[j] = c3[t]
        o4[j] = c4[t]
        o5[j] = c5[t]
        o6[j] = c6[t]
        o7[j] = c7[t]


@nb.njit(**OPTS)
def fixed_fields_dense(x, y, z, R, r, L1, L2, lim, kt, out, ok, method=JACOBI):
    """:func:`fixed_fields` with the kernel run on every point (no IK pass, no gather): the reference the
    compacted version is tested against, and the benchmark of the branch-free loop."""
    lim, kt = as_tuple4(lim), as_tuple4(kt)
    if method == JACOBI:
        _fields_loop(x, y, z, R, r, L1, L2, lim, kt, out, ok, JACOBI)
    else:
        _fields_loop(x, y, z, R, r, L1, L2, lim, kt, out, ok, FAST)


@nb.njit(**INLINE)
def _fields_loop(x, y, z, R, r, L1, L2, lim, kt, out, ok, method):
    for j in range(x.shape[0]):
        f, i0, i1, i2, i3, i4, i5, i6, i7 = point_kernel(x[j], abs(y[j]), z[j], R, r, L1, L2, lim, kt, method)
        store_masked(out, j, f, i0, i1, i2, i3, i4, i5, i6, i7)
        ok[j] = f


@nb.njit(**OPTS)
def fields_at(x, y, z, ks, R_min, R_step, r, L1, L2, lim, kt, out):
    """Indices at sample ks[j] per point (NaN where ks < 0 or not feasible); exact (Jacobi); ``out`` as in
    :func:`fixed_fields`."""
    lim, kt = as_tuple4(lim), as_tuple4(kt)
    for j in range(x.shape[0]):
        k = ks[j]
        f, i0, i1, i2, i3, i4, i5, i6, i7 = point_kernel(x[j], abs(y[j]), z[j], R_min + max(k, 0) * R_step, r, L1,
                                                          L2, lim, kt, JACOBI)
        store_masked(out, j, f & (k >= 0), i0, i1, i2, i3, i4, i5, i6, i7)


def rows(out: np.ndarray, a: int = 0, b: int | None = None) -> tuple:
    """The 8 rows of an (8, n) array restricted to columns a:b, as the contiguous (n,) arrays the field loops
    take (each row of a C-ordered block is contiguous even when the block is a column slice)."""
    return tuple(out[i, a:b] for i in range(out.shape[0]))


@nb.njit(**OPTS)
def fixed_mask(x, y, z, R, r, L1, L2, lim, ok):
    """Reachable (IK within limits on every chain) at the points (x, y, z) (each (n,))."""
    lim = as_tuple4(lim)
    for j in range(x.shape[0]):
        ok[j] = ik_ok(x[j], abs(y[j]), z[j], R, r, L1, L2, lim)


@nb.njit(**OPTS)
def resolve(pts, k_start, k_stop, R_min, R_step, r, L1, L2, lim, kt, crit, best_k, best_v, n_full):
    """Per point: the sample k in [k_start, k_stop) maximising index ``crit`` (ties -> smallest k).

    The cheap IK test runs first for every sample; the exact kernel only where it passes. ``n_full``
    counts exact-kernel evaluations per point.
    """
    lim, kt = as_tuple4(lim), as_tuple4(kt)
    n = pts.shape[0]
    for j in range(n):
        x = pts[j, 0]
        y = abs(pts[j, 1])
        z = pts[j, 2]
        bk = -1
        bv = -math.inf
        cnt = 0
        for k in range(k_start[j], k_stop[j]):
            R = R_min + k * R_step
            if not ik_ok(x, y, z, R, r, L1, L2, lim):
                continue
            cnt += 1
            f, v = point_value(x, y, z, R, r, L1, L2, lim, kt, crit, JACOBI)
            if f and v > bv:  # NaN never wins; strict: ties keep the smaller R
                bv = v
                bk = k
        best_k[j] = bk
        best_v[j] = bv
        n_full[j] = cnt


@nb.njit(**OPTS)
def any_reach(pts, k_start, k_stop, R_min, R_step, r, L1, L2, lim, ok):
    """Some sample k in [k_start, k_stop) reaches the point (first feasible sample ends the search)."""
    lim = as_tuple4(lim)
    n = pts.shape[0]
    for j in range(n):
        x = pts[j, 0]
        y = abs(pts[j, 1])
        z = pts[j, 2]
        hit = False
        for k in range(k_start[j], k_stop[j]):
            if ik_ok(x, y, z, R_min + k * R_step, r, L1, L2, lim):
                hit = True
                break
        ok[j] = hit


@nb.njit(**OPTS)
def reach_k_range(pts, R_min, R_step, n_R, r, L1, L2, k_lo, k_hi):
    """Closed-form sample range (see redundancy.reach_interval), widened by one sample each side."""
    n = pts.shape[0]
    for j in range(n):
        x = pts[j, 0]
        y = abs(pts[j, 1])
        z = pts[j, 2]
        lo = -math.inf
        hi = math.inf
        for ca, sa in ((CA0, SA0), (CA1, SA1), (CA2, SA2)):
            px = ca * x + sa * y
            py = -sa * x + ca * y
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


# -- chunk helpers of the host driver (write into preallocated buffers: no fresh pages per chunk) ---------------
@nb.njit(**OPTS)
def grid_points(gx, gy, gz, j0, nyh, start, x, y, z):
    """Points start, start + 1, ... (len(x) of them) of the grid gx x gy[j0:j0 + nyh] x gz in x-major
    (i, j, k) order, written into x, y, z (the first item's indices by division, the others by counting)."""
    nz = gz.shape[0]
    i = start // (nyh * nz)
    rem = start - i * (nyh * nz)
    j = rem // nz
    k = rem - j * nz
    for t in range(x.shape[0]):
        x[t] = gx[i]
        y[t] = gy[j0 + j]
        z[t] = gz[k]
        k += 1
        if k == nz:
            k = 0
            j += 1
            if j == nyh:
                j = 0
                i += 1


@nb.njit(**OPTS)
def partial_stats(vals, start, nz, nyh, w_row0, w_other, out):
    """Weighted partial statistics of each row of ``vals`` (m, n) over its finite entries: out (m, 4) =
    [min, max, sum of w v, sum of w] (float64). Entry t is item start + t of an (nx, nyh, nz) layout; its
    weight is ``w_row0`` on the layout's first y-row and ``w_other`` elsewhere (2 / 1 for a mirror half whose
    first row lies on the mirror plane, so that the statistics are those of the full grid)."""
    m, n = vals.shape
    for a in range(m):
        lo = math.inf
        hi = -math.inf
        s = 0.0
        c = 0.0
        for t in range(n):
            v = np.float64(vals[a, t])
            if math.isfinite(v):
                j = ((start + t) // nz) % nyh
                w = w_row0 if j == 0 else w_other
                lo = min(lo, v)
                hi = max(hi, v)
                s += w * v
                c += w
        out[a, 0] = lo
        out[a, 1] = hi
        out[a, 2] = s
        out[a, 3] = c


@nb.njit(**OPTS)
def plane_stats(ok, values, count, n, s, lo, hi):
    """Per-x-plane count, finite count, sum, min, max of ``values`` (k, m, c) over ``ok`` (k, m) in one pass
    (:func:`deltajax.workspace.chunks.plane_statistics` allocates the outputs; NumPy's sums bit for bit)."""
    k, m, c = values.shape
    for p in range(k):
        for j in range(c):
            n[p, j] = 0
            lo[p, j] = math.inf
            hi[p, j] = -math.inf
        cnt = 0
        for t in range(m):
            o = ok[p, t]
            cnt += o
            for j in range(c):
                v = values[p, t, j]
                f = o and math.isfinite(v)
                w = v if f else 0.0  # NumPy's np.where(finite, values, 0.0); float32: the f64 sum of two
                if t == 0:           # f32 rounded to f32 is the f32 sum (53 >= 2 * 24 + 2 bits)
                    s[p, j] = w      # NumPy's reduction starts from the first element
                else:
                    s[p, j] += w
                if f:
                    n[p, j] += 1
                    if v < lo[p, j]:
                        lo[p, j] = v
                    if v > hi[p, j]:
                        hi[p, j] = v
        count[p] = cnt
