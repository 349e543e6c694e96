"""Redundancy resolution of the reconfigurable Delta: the best base radius R per point (SPEC §1).

For each point the candidates are the R samples ``R_min + k R_step`` (k = 0..n_R-1). A sample is *feasible*
when the IK succeeds for all chains within the joint limits and Jx is not exactly singular (det Jx != 0) and
the criterion is not NaN. The selected sample maximises the criterion (any name in
:data:`deltajax.INDEX_NAMES`, k~ by default); ties go to the smallest R. Points with no feasible sample
get ``ok=False``, ``k=-1`` and NaN values.

Two implementations return the identical selection (tested):

* **exact** -- every sample is evaluated, like the paper. :func:`resolve_redundancy` (pure, jit/vmap-able:
  a ``lax.scan`` over the samples keeps memory O(N)) and the host driver ``resolve_redundancy_host(...,
  mode="exact")``.
* **fast** -- ``resolve_redundancy_host(..., mode="fast")``. The savings, none of which changes the answer:

  1. *Closed-form reach interval.* For chain i with P in its local frame, d_x = p_x,i + r - R and
     L2' = sqrt(L2^2 - p_y,i^2), the loop closes iff rho = sqrt(d_x^2 + p_z^2) lies in [|L2' - L1|, L2' + L1]
     (the loop-closure condition (d_x^2 + p_z^2 + p_y^2 + L1^2 - L2^2)^2 <= 4 L1^2 (d_x^2 + p_z^2) is
     a quadratic in d_x^2 whose roots are exactly these). Hence R must lie in
     [p_x,i + r - sqrt((L2'+L1)^2 - p_z^2), p_x,i + r + sqrt((L2'+L1)^2 - p_z^2)] for every chain; the
     intersection (widened by one sample for rounding) bounds the sample range of each point.
  2. *Feasibility pass.* A cheap IK-only sweep over that range gives the first and last feasible sample
     k_first..k_last (joint limits included); the full kernel (Jacobians + singular values) runs only on
     that window. Windows are sorted by length and evaluated in buckets of equal width, so almost no
     padded work is done.
  3. *Mirror symmetry.* The kernel evaluates every point at (x, |y|, z) (see :mod:`.grid`), so a point and
     its mirror image have bit-identical answers; the host driver solves each mirror pair once.
     The three-fold rotation maps the Cartesian grid onto itself only for a few points (120 deg rotations
     of grid points are not grid points), so it is not used.

Exact-singular Jx is detected by det Jx == 0 exactly (rank tolerance zero), as SPEC §1 asks.
"""

from __future__ import annotations

from functools import partial
from typing import Callable, NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ..geometry import ReconfigurableDelta
from ..indices import INDEX_NAMES, Indices, indices_from_singular_values, singular_values_closed_form
from ..kinematics import _from_chain_frames, ik_cos_sin, to_chain_frames
from .grid import _canonical

__all__ = [
    "Redundancy",
    "resolve_redundancy",
    "resolve_redundancy_host",
    "reconfigurable_reachable",
    "reach_interval",
    "feasible_window",
    "sample_value",
]


class Redundancy(NamedTuple):
    """Result of redundancy resolution for N points.

    Attributes:
        k: index of the selected R sample (-1 where none is feasible).
        R: selected base radius R* = R_min + k R_step (m; NaN where none).
        value: criterion value at R* (NaN where none).
        ok: some R sample is feasible.
        indices: every index at R* (:class:`deltajax.Indices`, each field of shape (N,), singular values (N, 3)).
    """

    k: Int[Array, "n"]
    R: Float[Array, "n"]
    value: Float[Array, "n"]
    ok: Bool[Array, "n"]
    indices: Indices


def _check_criterion(criterion: str) -> None:
    if criterion not in INDEX_NAMES:
        raise ValueError(f"criterion must be one of {INDEX_NAMES}, got {criterion!r}")


def _sample_R(recon: ReconfigurableDelta, k):
    return recon.R_min + jnp.asarray(k, recon.R_min.dtype) * recon.R_step


def _kernel(recon: ReconfigurableDelta, p, k, b_v, b_f, beta):
    """(feasible, indices) of canonical point ``p`` at sample ``k``: the algebraic kernel (see .grid)."""
    robot = recon.at(_sample_R(recon, k))
    cs = ik_cos_sin(robot, p)
    ok = jnp.all(cs.ok)
    c = jnp.where(ok, cs.cos, 1.0)
    s = jnp.where(ok, cs.sin, 0.0)
    loc = to_chain_frames(p)
    L1, L2 = robot.upper_arm, robot.forearm
    u = jnp.stack([loc[:, 0] + robot.platform_radius - robot.base_radius - L1 * c, loc[:, 1],
                   loc[:, 2] - L1 * s], axis=-1) / L2
    Jx = _from_chain_frames(u)
    det_jx = (Jx[0, 0] * (Jx[1, 1] * Jx[2, 2] - Jx[1, 2] * Jx[2, 1])
              - Jx[0, 1] * (Jx[1, 0] * Jx[2, 2] - Jx[1, 2] * Jx[2, 0])
              + Jx[0, 2] * (Jx[1, 0] * Jx[2, 1] - Jx[1, 1] * Jx[2, 0]))
    dhat = u[:, 2] * c - u[:, 0] * s
    sv = singular_values_closed_form(Jx, dhat)
    ind = indices_from_singular_values(sv, b_v=b_v, b_f=b_f, beta=beta, raw_scale=L1 ** 3)
    return ok & (det_jx != 0.0), ind


def sample_value(recon: ReconfigurableDelta, p: Float[Array, "3"], k: Int[Array, ""], *,
                 criterion: str = "k_tilde", b_v: float = 2.0, b_f: float = 4.2, beta: float = 0.5
                 ) -> tuple[Bool[Array, ""], Float[Array, ""]]:
    """(feasible, criterion value) of one point at R sample ``k``; the value is -inf where not feasible."""
    _check_criterion(criterion)
    feas, ind = _kernel(recon, _canonical(jnp.asarray(p)), k, b_v, b_f, beta)
    v = getattr(ind, criterion)
    feas = feas & ~jnp.isnan(v)
    return feas, jnp.where(feas, v, -jnp.inf)


def _nan_indices(ind: Indices, ok) -> Indices:
    return Indices(*(jnp.where(ok if v.ndim == ok.ndim else ok[..., None], v, jnp.nan) for v in ind))


def _finish(recon, pts, best_k, best_v, b_v, b_f, beta) -> Redundancy:
    ok = best_k >= 0
    k_safe = jnp.where(ok, best_k, 0)
    _, ind = jax.vmap(lambda q, kk: _kernel(recon, _canonical(q), kk, b_v, b_f, beta))(pts, k_safe)
    R = jnp.where(ok, _sample_R(recon, k_safe), jnp.nan)
    return Redundancy(k=best_k, R=R, value=jnp.where(ok, best_v, jnp.nan), ok=ok, indices=_nan_indices(ind, ok))


def resolve_redundancy(recon: ReconfigurableDelta, points: Float[Array, "n 3"], criterion: str = "k_tilde", *,
                       b_v: float = 2.0, b_f: float = 4.2, beta: float = 0.5) -> Redundancy:
    """Exact redundancy resolution: sweep every R sample (pure; jit/vmap-able, memory O(N)).

    Args:
        recon: the reconfigurable robot (``n_R`` static).
        points: (N, 3) platform positions (m, base frame).
        criterion: index to maximise, a name in :data:`deltajax.INDEX_NAMES` (default ``"k_tilde"``).
        b_v, b_f, beta: parameters of k~ (may be traced).

    Returns:
        :class:`Redundancy` (ties -> smallest R; ``ok=False`` where no sample is feasible).
    """
    _check_criterion(criterion)
    pts = jnp.asarray(points)
    dtype = jnp.result_type(pts.dtype, recon.R_min.dtype)
    pts = pts.astype(dtype)
    n = pts.shape[0]
    value = jax.vmap(lambda q, kk: sample_value(recon, q, kk, criterion=criterion, b_v=b_v, b_f=b_f, beta=beta),
                     in_axes=(0, None))

    def step(carry, k):
        best_k, best_v = carry
        feas, v = value(pts, k)
        better = feas & (v > best_v)  # strictly greater: ties keep the smaller R
        return (jnp.where(better, k, best_k), jnp.where(better, v, best_v)), None

    init = (jnp.full((n,), -1, jnp.int32), jnp.full((n,), -jnp.inf, dtype))
    (best_k, best_v), _ = jax.lax.scan(step, init, jnp.arange(recon.n_R, dtype=jnp.int32))
    return _finish(recon, pts, best_k, best_v, b_v, b_f, beta)


def reconfigurable_reachable(recon: ReconfigurableDelta, points: Float[Array, "n 3"]) -> Bool[Array, "n"]:
    """Whether some R sample reaches each point (IK within limits for all chains); pure, memory O(N).

    Vmap over designs: ``jax.vmap(reconfigurable_reachable, in_axes=(0, None))``.
    """
    pts = jnp.asarray(points)
    canon = jax.vmap(_canonical)(pts)

    def step(acc, k):
        robot = recon.at(_sample_R(recon, k))
        ok = jax.vmap(lambda q: jnp.all(ik_cos_sin(robot, q).ok))(canon)
        return acc | ok, None

    acc, _ = jax.lax.scan(step, jnp.zeros(pts.shape[:1], bool), jnp.arange(recon.n_R, dtype=jnp.int32))
    return acc


# -- fast mode -----------------------------------------------------------------------------------------------

def reach_interval(recon: ReconfigurableDelta, p: Float[Array, "3"]) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """Closed-form interval [R_lo, R_hi] (m) outside which some chain cannot close its loop (any R).

    Necessary condition only (joint limits and the inner hole |d_x| >= sqrt((L2' - L1)^2 - p_z^2) are not
    used); empty (R_lo > R_hi) when no R reaches the point.
    """
    robot = recon.robot
    loc = to_chain_frames(_canonical(jnp.asarray(p)))
    L1, L2, r = robot.upper_arm, robot.forearm, robot.platform_radius
    py2 = loc[:, 1] ** 2
    l2p2 = L2 * L2 - py2
    l2p = jnp.sqrt(jnp.where(l2p2 >= 0, l2p2, 0.0))
    hi2 = (l2p + L1) ** 2 - loc[:, 2] ** 2
    reach = (l2p2 >= 0) & (hi2 >= 0)
    half = jnp.sqrt(jnp.where(reach, hi2, 0.0))
    c = loc[:, 0] + r
    lo = jnp.max(jnp.where(reach, c - half, jnp.inf))
    hi = jnp.min(jnp.where(reach, c + half, -jnp.inf))
    return lo, hi


def _reach_k_range(recon, p):
    lo, hi = reach_interval(recon, p)
    # one extra sample on each side absorbs rounding of the closed form against the IK's own test
    k_lo = jnp.ceil((lo - recon.R_min) / recon.R_step) - 1.0
    k_hi = jnp.floor((hi - recon.R_min) / recon.R_step) + 1.0
    k_lo = jnp.clip(jnp.where(jnp.isfinite(k_lo), k_lo, recon.n_R), 0, recon.n_R)
    k_hi = jnp.clip(jnp.where(jnp.isfinite(k_hi), k_hi, -1), -1, recon.n_R - 1)
    return k_lo.astype(jnp.int32), k_hi.astype(jnp.int32)


def feasible_window(recon: ReconfigurableDelta, p: Float[Array, "3"], *, width: int
                    ) -> tuple[Int[Array, ""], Int[Array, ""]]:
    """First and last IK-feasible sample (k_first, k_last) of one point; (n_R, -1) when none.

    Only samples k_lo .. k_lo + width - 1 of the closed-form range (:func:`reach_interval`) are tested,
    so ``width`` must cover it (the host driver picks it per bucket).
    """
    q = _canonical(jnp.asarray(p))
    k_lo, k_hi = _reach_k_range(recon, q)
    ks = k_lo + jnp.arange(width, dtype=jnp.int32)
    ok = jax.vmap(lambda R: jnp.all(ik_cos_sin(recon.at(R), q).ok))(_sample_R(recon, ks)) & (ks <= k_hi)
    first = jnp.min(jnp.where(ok, ks, recon.n_R))
    last = jnp.max(jnp.where(ok, ks, -1))
    return first, last


@jax.jit
def _reach_batch(recon, pts):
    return jax.vmap(lambda q: _reach_k_range(recon, q))(pts)


def _pair_points(seg_pts, seg, k, n_R):
    return seg_pts[seg], k, (k >= 0) & (k < n_R)


@jax.jit
def _pairs_feasible(recon, seg_pts, seg, k):
    """First/last IK-feasible sample per segment over flat (segment, sample) pairs."""
    p, k, valid = _pair_points(seg_pts, seg, k, recon.n_R)
    ok = jax.vmap(lambda q, kk: jnp.all(ik_cos_sin(recon.at(_sample_R(recon, kk)), _canonical(q)).ok))(p, k)
    ok = ok & valid
    n_seg = seg_pts.shape[0]
    first = jax.ops.segment_min(jnp.where(ok, k, recon.n_R), seg, num_segments=n_seg, indices_are_sorted=True)
    last = jax.ops.segment_max(jnp.where(ok, k, -1), seg, num_segments=n_seg, indices_are_sorted=True)
    return first, last


@partial(jax.jit, static_argnames=("criterion",))
def _pairs_best(recon, seg_pts, seg, k, b_v, b_f, beta, criterion: str):
    """Best sample per segment (max criterion, ties -> smallest k) over flat (segment, sample) pairs."""
    p, k, valid = _pair_points(seg_pts, seg, k, recon.n_R)
    feas, v = jax.vmap(lambda q, kk: sample_value(recon, q, kk, criterion=criterion, b_v=b_v, b_f=b_f,
                                                   beta=beta))(p, jnp.where(valid, k, 0))
    feas = feas & valid
    v = jnp.where(feas, v, -jnp.inf)
    n_seg = seg_pts.shape[0]
    vmax = jax.ops.segment_max(v, seg, num_segments=n_seg, indices_are_sorted=True)
    is_max = feas & (v == vmax[seg])
    kbest = jax.ops.segment_min(jnp.where(is_max, k, recon.n_R), seg, num_segments=n_seg, indices_are_sorted=True)
    found = kbest < recon.n_R
    return jnp.where(found, kbest, -1), jnp.where(found, vmax, -jnp.inf)


@jax.jit
def _kernel_batch(recon, pts, k, b_v, b_f, beta):
    return jax.vmap(lambda q, kk: _kernel(recon, _canonical(q), kk, b_v, b_f, beta))(pts, k)


def _flat_chunks(starts: np.ndarray, widths: np.ndarray, chunk_pairs: int, max_segments: int):
    """Split points (with sample windows start..start+width-1) into chunks of whole windows.

    Yields (point indices, segment id per pair, sample k per pair), pairs padded to ``chunk_pairs`` with
    k = -1 (invalid) in the last segment slot.
    """
    todo = np.nonzero(widths > 0)[0]
    w = widths[todo]
    csum = np.cumsum(w)
    pos = 0
    n = len(todo)
    done = 0
    while pos < n:
        stop = int(np.searchsorted(csum, done + chunk_pairs, side="right"))
        stop = min(max(stop, pos + 1), pos + max_segments, n)
        idx = todo[pos:stop]
        ww = widths[idx]
        total = int(ww.sum())
        seg = np.repeat(np.arange(len(idx), dtype=np.int32), ww)
        offs = np.arange(total, dtype=np.int64) - np.repeat(np.cumsum(ww) - ww, ww)
        k = (np.repeat(starts[idx], ww) + offs).astype(np.int32)
        pad = chunk_pairs - total
        if pad > 0:
            seg = np.concatenate([seg, np.full(pad, max_segments - 1, np.int32)])
            k = np.concatenate([k, np.full(pad, -1, np.int32)])
        yield idx, seg, k
        done = int(csum[stop - 1])
        pos = stop


def _run_pairs(fn, pts, starts, widths, chunk_pairs, max_segments, progress=None):
    n = pts.shape[0]
    out_a = np.empty(n, np.float64)
    out_b = np.empty(n, np.float64)
    seg_pts = np.zeros((max_segments, 3))
    for idx, seg, k in _flat_chunks(starts, widths, chunk_pairs, max_segments):
        seg_pts[:] = 0.0
        seg_pts[:len(idx)] = pts[idx]
        a, b = fn(jnp.asarray(seg_pts), jnp.asarray(seg), jnp.asarray(k))
        out_a[idx] = np.asarray(a)[:len(idx)]
        out_b[idx] = np.asarray(b)[:len(idx)]
        if progress is not None:
            progress(len(idx))
    return out_a, out_b


def resolve_redundancy_host(recon: ReconfigurableDelta, points: np.ndarray, criterion: str = "k_tilde", *,
                            mode: str = "fast", b_v: float = 2.0, b_f: float = 4.2, beta: float = 0.5,
                            chunk_pairs: int = 1 << 20, mirror: bool = True, return_indices: bool = True,
                            progress: Optional[Callable[[int], None]] = None) -> Redundancy:
    """Redundancy resolution on the host, in memory-bounded chunks, as NumPy arrays.

    Work is laid out as flat (point, R sample) pairs: each point contributes its window of samples, whole
    windows are packed into chunks of ``chunk_pairs`` pairs and reduced per point (segment max, then the
    smallest k attaining it). One compiled program serves every chunk and both modes, so the two modes
    evaluate every (point, sample) pair they share with the same machine code.

    Args:
        recon: the reconfigurable robot.
        points: (N, 3) positions (m).
        criterion, b_v, b_f, beta: as in :func:`resolve_redundancy`.
        mode: ``"fast"`` (reach interval + feasibility window + mirror pairs) or ``"exact"`` (every sample of
            every point, the paper's sweep). Both return the identical selection.
        chunk_pairs: (point, sample) pairs per compiled call (bounds memory).
        mirror: solve each mirror pair (x, +-y, z) once (fast mode only).
        return_indices: also evaluate every index at R* (one more kernel call per point).
        progress: called with the number of points finished after each chunk.

    Returns:
        :class:`Redundancy` of NumPy arrays.
    """
    _check_criterion(criterion)
    if mode not in ("fast", "exact"):
        raise ValueError(f"mode must be 'fast' or 'exact', got {mode!r}")
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n_all = pts.shape[0]
    n_R = recon.n_R
    chunk_pairs = max(int(chunk_pairs), n_R)
    max_segments = chunk_pairs // 4 if mode == "fast" else chunk_pairs // n_R + 1
    if mode == "fast" and mirror and n_all:
        keyed = np.stack([pts[:, 0], np.abs(pts[:, 1]), pts[:, 2]], axis=-1)
        uniq, inverse = np.unique(keyed, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
    else:
        uniq, inverse = pts, None
    n = uniq.shape[0]
    if mode == "exact":
        starts = np.zeros(n, np.int64)
        widths = np.full(n, n_R, np.int64)
    else:
        k_lo, k_hi = (np.asarray(a).astype(np.int64) for a in _reach_batch(recon, jnp.asarray(uniq)))
        span = np.where(k_hi >= k_lo, k_hi - k_lo + 1, 0)
        first, last = _run_pairs(lambda a, b, c: _pairs_feasible(recon, a, b, c), uniq, k_lo, span,
                                 chunk_pairs * 2, max_segments)
        first, last = first.astype(np.int64), last.astype(np.int64)
        has = (span > 0) & (last >= first)
        widths = np.where(has, last - first + 1, 0)
        starts = np.where(has, first, 0)
    best_k, best_v = _run_pairs(
        lambda a, b, c: _pairs_best(recon, a, b, c, b_v, b_f, beta, criterion=criterion), uniq, starts, widths,
        chunk_pairs, max_segments, progress)
    best_k = np.where(widths > 0, best_k, -1).astype(np.int32)
    best_v = np.where(widths > 0, best_v, -np.inf)
    if inverse is not None:
        best_k, best_v = best_k[inverse], best_v[inverse]
    ok = best_k >= 0
    if return_indices:
        ind = _indices_at(recon, pts, best_k, b_v=b_v, b_f=b_f, beta=beta)
    else:
        ind = Indices(*([np.full(n_all, np.nan)] * 8 + [np.full((n_all, 3), np.nan)]))
    R = np.where(ok, np.asarray(_sample_R(recon, np.maximum(best_k, 0))), np.nan)
    return Redundancy(k=best_k, R=R, value=np.where(ok, best_v, np.nan), ok=ok, indices=ind)


def _indices_at(recon, pts, best_k, *, b_v, b_f, beta, size: int = 1 << 16) -> Indices:
    n = pts.shape[0]
    out = [np.full(n, np.nan) for _ in range(8)] + [np.full((n, 3), np.nan)]
    for s in range(0, n, size):
        sl = slice(s, min(n, s + size))
        m_n = sl.stop - sl.start
        kk = np.maximum(best_k[sl], 0)
        m = best_k[sl] >= 0
        q = pts[sl]
        if m_n < size:  # one compiled size
            q = np.concatenate([q, np.zeros((size - m_n, 3))])
            kk = np.concatenate([kk, np.zeros(size - m_n, kk.dtype)])
        _, ind = _kernel_batch(recon, jnp.asarray(q), jnp.asarray(kk, jnp.int32), b_v, b_f, beta)
        for j, v in enumerate(ind):
            v = np.asarray(v)[:m_n]
            out[j][sl] = np.where(m if v.ndim == 1 else m[:, None], v, np.nan)
    return Indices(*out)
