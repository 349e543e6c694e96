"""Throughput of the Numba kernel for the benchmarks (``experiments/bench_kernel.py``, ``bench_workspace.py``).

:func:`bench_kernel_rates` is the hook the kernel benchmark calls; :func:`bench_numba` the same figures for one
robot as a dict. Labels:

* ``exact (jacobi)`` / ``fast (cubic)``: the production field loop (:func:`deltajax.workspace.numba_fields.fixed_fields`, the mirror's
  :func:`deltajax.workspace.numba_kernel.point_kernel` with either eigenvalue solver) over every point;
* ``exact on reachable`` / ``fast on reachable``: the same on the reachable points only (the issue's figure);
* ``minimal loop ceiling``: :func:`minimal_loop`, the same algebra stripped to the bone (reciprocals instead
  of divisions where the core divides, no input guards, no repeated-eigenvalue fix-up), the ceiling the
  production loop is compared with (docs/BENCHMARKS.md);
* ``minimal loop, FMA-only divide/sqrt``: :func:`minimal_loop_newton`, the same loop with every per-point divide
  and square root as multiplies and adds (bit-trick start + Newton steps): whether the divide/square-root units
  are what bounds the ceiling.

All single-threaded (CPU seconds = one core's), best of ``repeats``.
"""

from __future__ import annotations

import math
import time

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic

from ..workspace.numba_kernel import (FAST, INLINE, JACOBI, N_IDX, OPTS, T_POLY, as_tuple4, chain_local, jx_row, kt_tuple,
                         limits_tuple, sv_matrix)

__all__ = ["bench_kernel_rates", "bench_numba", "minimal_loop", "minimal_loop_newton"]


# -- the arithmetic the ceiling is built from: IEEE divide / square root, or FMA-only Newton iterations ----------
@intrinsic
def _bits(typingctx, x):
    """The IEEE-754 bit pattern of a float64 as an int64 (an LLVM bitcast: free, and it vectorises)."""
    def codegen(context, builder, sig, args):
        return builder.bitcast(args[0], ir.IntType(64))
    return types.int64(types.float64), codegen


@intrinsic
def _from_bits(typingctx, i):
    """The float64 whose bit pattern is the int64 ``i``."""
    def codegen(context, builder, sig, args):
        return builder.bitcast(args[0], ir.DoubleType())
    return types.float64(types.int64), codegen


@nb.njit(**INLINE)
def _ieee_div(a, b):
    return a / b


@nb.njit(**INLINE)
def _ieee_sqrt0(x):
    return math.sqrt(max(x, 0.0))


@nb.njit(**INLINE)
def _newton_div(a, b):
    """a / b as a x 1/b, 1/b from the bit-trick start (~12 % error) and five Newton steps (multiplies and adds
    only; ~1 ulp for positive normal b): the ``recip`` of :mod:`deltajax.fastmath` in Numba."""
    y = _from_bits(np.int64(0x7FDE623822FC16E6) - _bits(b))
    for _ in range(5):
        y = y * (2.0 - b * y)
    return a * y


@nb.njit(**INLINE)
def _newton_sqrt0(x):
    """sqrt(max(x, 0)) as x / sqrt(x) from the bit-trick 1/sqrt start and five Newton steps."""
    xp = x if x > 0.0 else 1.0
    y = _from_bits(np.int64(0x5FE6EB50C7B537A9) - (_bits(xp) >> np.int64(1)))
    h = 0.5 * xp
    for _ in range(5):
        y = y * (1.5 - h * y * y)
    return xp * y if x > 0.0 else 0.0


@nb.njit(**INLINE)
def _min_chain(x, y, z, R, r, L1, h1, iL2, c0, lim, i, div, sqrt0):
    px, py, pz = chain_local(x, y, z, i)
    dx = px + r - R
    rho2 = dx * dx + pz * pz
    m = (rho2 + py * py + c0) * h1
    disc = rho2 - m * m
    w = sqrt0(disc)
    inv = div(1.0, rho2)
    c = (dx * m + pz * w) * inv
    s = (pz * m - dx * w) * inv
    ok = (disc >= 0.0) & (c * lim[0] + s * lim[1] - lim[2] >= 0.0)
    ux = (dx - L1 * c) * iL2
    uy = py * iL2
    uz = (pz - L1 * s) * iL2
    j0, j1, j2 = jx_row(ux, uy, uz, i)
    return ok, j0, j1, j2, uz * c - ux * s


@nb.njit(**INLINE)
def _root01(cc, sqrt0):
    u = sqrt0(cc)
    t = u * (((((T_POLY[5] * u + T_POLY[4]) * u + T_POLY[3]) * u + T_POLY[2]) * u + T_POLY[1]) * u + T_POLY[0])
    g = t * t * (t + 3.0) - cc
    g1 = 3.0 * t * (t + 2.0)
    return t, g, g1, max(2.0 * g1 * g1 - g * 6.0 * (t + 1.0), 1e-150)  # 0 at a double root (t = 0)


@nb.njit(**INLINE)
def _minimal(x, y, z, R, r, L1, L2, lim, kt, out, ok, div, sqrt0):
    """:func:`minimal_loop` with its divides and square roots as the functions ``div`` (a, b) -> a / b and
    ``sqrt0`` (x) -> sqrt(max(x, 0)); compile-time constants after inlining."""
    lim = as_tuple4(lim)
    kt = as_tuple4(kt)
    h1 = 1.0 / (2.0 * L1)
    iL2 = 1.0 / L2
    c0 = L1 * L1 - L2 * L2
    l13 = L1 * L1 * L1
    iav, ibv, iaf, ibf = 1.0 / kt[0], 1.0 / (kt[1] - kt[0]), 1.0 / kt[2], 1.0 / (kt[3] - kt[2])
    for j in range(x.shape[0]):
        xj, yj, zj = x[j], y[j], z[j]
        ok0, j00, j01, j02, d0 = _min_chain(xj, yj, zj, R, r, L1, h1, iL2, c0, lim, 0, div, sqrt0)
        ok1, j10, j11, j12, d1 = _min_chain(xj, yj, zj, R, r, L1, h1, iL2, c0, lim, 1, div, sqrt0)
        ok2, j20, j21, j22, d2 = _min_chain(xj, yj, zj, R, r, L1, h1, iL2, c0, lim, 2, div, sqrt0)
        # the kernel's matrix X (its unused invariants are dead code after inlining)
        jx_side, prod, det, _, _, x00, x11, x22, x01, x02, x12 = sv_matrix(j00, j01, j02, j10, j11, j12, j20, j21,
                                                                            j22, d0, d1, d2)
        q = (x00 + x11 + x22) * (1.0 / 3.0)
        b00, b11, b22 = x00 - q, x11 - q, x22 - q
        p2 = (b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (x01 * x01 + x02 * x02 + x12 * x12)) * (1.0 / 6.0)
        p = sqrt0(p2)
        det_b = b00 * (b11 * b22 - x12 * x12) - x01 * (x01 * b22 - x12 * x02) + x02 * (x01 * x12 - b11 * x02)
        rr = min(max(div(0.5 * det_b, max(p2 * p, 1e-300)), -1.0), 1.0)
        t, g, gp, dn = _root01(2.0 * (1.0 + rr), sqrt0)
        t2, h, hp, en = _root01(2.0 * (1.0 - rr), sqrt0)
        inv = div(1.0, dn * en)
        t = t - 2.0 * g * gp * en * inv
        t2 = t2 - 2.0 * h * hp * dn * inv
        r1 = sqrt0(q + p * (1.0 + t))
        r2 = sqrt0(q + p * (t2 - t))
        ir12 = div(1.0, r1 * r2)
        pdj = prod * det * ir12
        s3 = prod * r2 * ir12 if jx_side else pdj  # Jx side: prod / r1
        is1 = pdj if jx_side else det * r2 * ir12  # 1 / s1: Jx side det prod / (r1 r2); Jq side det / r1
        ov = div(prod, det)
        tv = (s3 - kt[0]) * (iav if s3 <= kt[0] else ibv)
        tf = (is1 - kt[2]) * (iaf if is1 <= kt[2] else ibf)
        f = ok0 & ok1 & ok2 & (det != 0.0)
        nan = math.nan
        out[0, j] = s3 * is1 if f else nan
        out[1, j] = s3 if f else nan
        out[2, j] = is1 if f else nan
        out[3, j] = ov if f else nan
        out[4, j] = div(det, prod) if f else nan
        out[5, j] = ((0.0 if s3 > kt[1] else 1.0 - tv * tv) * (0.0 if is1 > kt[3] else 1.0 - tf * tf)) if f else nan
        out[6, j] = ov * l13 if f else nan
        out[7, j] = div(det, prod * l13) if f else nan
        ok[j] = f


@nb.njit(**OPTS)
def minimal_loop(x, y, z, R, r, L1, L2, lim, kt, out, ok):
    """The kernel's algebra as the tightest branch-free loop (the benchmark ceiling; not used for results):
    algebraic IK, Jx rows = unit forearm vectors, diagonal Jq, two-sided S/T, closed-form cubic with one
    Halley step (both roots share one division), s3 from |det|, every index; ``out`` (8, n)."""
    _minimal(x, y, z, R, r, L1, L2, lim, kt, out, ok, _ieee_div, _ieee_sqrt0)


@nb.njit(**OPTS)
def minimal_loop_newton(x, y, z, R, r, L1, L2, lim, kt, out, ok):
    """:func:`minimal_loop` with every per-point divide and square root replaced by multiplies and adds (bit-trick
    start + Newton steps, as the JAX kernel's :mod:`deltajax.fastmath`): whether the IEEE divide / square-root
    units bound the ceiling on this CPU (they do not: it runs slower, docs/BENCHMARKS.md)."""
    _minimal(x, y, z, R, r, L1, L2, lim, kt, out, ok, _newton_div, _newton_sqrt0)


def _best(fn, repeats: int) -> tuple[float, float]:
    fn()  # compile / warm
    best = (math.inf, math.inf)
    for _ in range(max(1, repeats)):
        w, c = time.perf_counter(), time.process_time()
        fn()
        w, c = time.perf_counter() - w, time.process_time() - c
        if c < best[1]:
            best = (w, c)
    return best


def bench_kernel_rates(points: np.ndarray, geo, repeats: int = 3) -> dict:
    """Numba kernel throughput: {label: (n evaluated, wall s, CPU s)} (see the module docstring).

    Args:
        points: (n, 3) float64 points (m, base frame); evaluated at (x, |y|, z) like the drivers do.
        geo: [R, r, L1, L2, theta_min, theta_max] (m, rad).
        repeats: timed repetitions (best CPU time is reported).
    """
    from ..workspace import numba_fields

    R, r, L1, L2, lo, hi = (float(v) for v in geo)
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    x, y, z = np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(np.abs(pts[:, 1])), np.ascontiguousarray(pts[:, 2])
    lim, kt = limits_tuple(lo, hi), kt_tuple(2.0, 4.2, 0.5)
    n = len(x)
    out, ok = np.empty((N_IDX, n)), np.empty(n, np.bool_)
    res = {}
    for label, m in (("exact (jacobi)", JACOBI), ("fast (cubic)", FAST)):
        w, c = _best(lambda: numba_fields.fixed_fields(x, y, z, R, r, L1, L2, lim, kt, numba_fields.rows(out), ok, m), repeats)
        res[label] = (n, w, c)
    sel = ok.copy()
    xr, yr, zr = (np.ascontiguousarray(a[sel]) for a in (x, y, z))
    nr = len(xr)
    if nr:
        o2, k2 = np.empty((N_IDX, nr)), np.empty(nr, np.bool_)
        for label, m in (("exact on reachable", JACOBI), ("fast on reachable", FAST)):
            w, c = _best(lambda: numba_fields.fixed_fields(xr, yr, zr, R, r, L1, L2, lim, kt, numba_fields.rows(o2), k2, m), repeats)
            res[label] = (nr, w, c)
        w, c = _best(lambda: minimal_loop(xr, yr, zr, R, r, L1, L2, lim, kt, o2, k2), repeats)
        res["minimal loop ceiling (reachable)"] = (nr, w, c)
        w, c = _best(lambda: minimal_loop_newton(xr, yr, zr, R, r, L1, L2, lim, kt, o2, k2), repeats)
        res["minimal loop, FMA-only divide/sqrt (reachable)"] = (nr, w, c)
    return res


def bench_numba(points: np.ndarray, robot) -> dict:
    """:func:`bench_kernel_rates` for a :class:`deltajax.Delta`: {label: {"n", "wall_s", "cpu_s",
    "M_eval_per_cpu_s"}}."""
    geo = [float(np.asarray(getattr(robot, k))) for k in ("base_radius", "platform_radius", "upper_arm", "forearm",
                                                          "theta_min", "theta_max")]
    return {k: {"n": n, "wall_s": w, "cpu_s": c, "M_eval_per_cpu_s": n / max(c, 1e-12) / 1e6}
            for k, (n, w, c) in bench_kernel_rates(points, geo).items()}
