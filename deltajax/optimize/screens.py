"""Population-level screens of the GA fitness (issue 9): the R sweeps of the volume and of the task coverage for
a whole population at once, with the per-design sweeps' flags bit for bit and a fraction of their work.

:func:`task_cover` decides each (design, task point) from exact values only (one IK pass, one exact sample per
point, the exact sweep of the undecided points in ``lax.while_loop`` chunks); :func:`reach_cover` adds one
certified closed-form exclusion (:data:`REACH_INFLATE`). :mod:`deltajax.optimize.objectives` (``screen=True``)
calls them; tests/test_ga_fitness.py checks them against the sweeps.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Int

from ..geometry import ReconfigurableDelta
from ..indices import point_kernel
from ..workspace import reach_interval, sample_value
from ..workspace.grid import canonical_point, reachable_point

__all__ = ["task_cover", "TaskCover", "TASK_CHUNK", "reach_cover", "ReachCover", "REACH_INFLATE"]


def _chunked_any(flags, chunk: int, fn, init):
    """``init`` updated by ``fn(i, j, valid)`` for the positions j of the True entries of the flat bool array
    ``flags``, ``chunk`` positions at a time in a ``lax.while_loop`` (ceil(n / chunk) iterations for n True
    entries). Positions come from a binary search in the running count (no full-size ``nonzero``)."""
    count = jnp.cumsum(flags, dtype=jnp.int32)
    n = count[-1]
    lane = jnp.arange(chunk, dtype=jnp.int32)

    def body(c):
        i, acc = c
        rank = i * chunk + lane  # the rank-th True entry (0-based)
        j = jnp.minimum(jnp.searchsorted(count, rank + 1, side="left"), flags.shape[0] - 1).astype(jnp.int32)
        return i + 1, fn(acc, j, rank < n)

    _, out = jax.lax.while_loop(lambda c: c[0] * chunk < n, body, (jnp.zeros((), jnp.int32), init))
    return out, n


#: Samples per exact-evaluation chunk of :func:`task_cover` (the while loop runs ceil(n / TASK_CHUNK) chunks).
TASK_CHUNK = 256


class TaskCover(NamedTuple):
    """Coverage of the task points for a population (:func:`task_cover`).

    Attributes:
        covered: (D, N) bool, point n of design d has a feasible R sample with index >= ``k_min``.
        n_first: exact kernel evaluations of the first pass (one per design and point with an IK-feasible
            sample).
        n_rest: exact kernel evaluations of the second pass (the remaining IK-feasible samples of the points the
            first pass did not cover).
        n_sweep: exact evaluations of the full sweep (D N n_R), for the ratio.
    """

    covered: Bool[Array, "d n"]
    n_first: Int[Array, ""]
    n_rest: Int[Array, ""]
    n_sweep: int


def task_cover(pb, designs: ReconfigurableDelta, points=None, *, chunk: int = TASK_CHUNK) -> TaskCover:
    """Which task points each design of a population covers, with the exact sweep's answer and a fraction of
    its exact kernel evaluations.

    The exact answer (:func:`evaluate_design`, via :func:`deltajax.workspace.resolve_redundancy`) is: point p
    is covered iff its best feasible R sample has ``index - k_min >= 0``, i.e. iff *some* feasible sample k has
    ``v_k - k_min >= 0`` (rounding is monotone), where feasible and v_k are those of
    :func:`deltajax.workspace.sample_value` (the exact, Jacobi kernel). That is a threshold, so it needs no
    maximum and no error bound; this function evaluates exactly that predicate on fewer samples:

    1. the IK pass: the core kernel's ``ok`` (loop closure within joint limits; the Jacobian and singular
       values are dead code here) for every sample; a sample that is not IK-feasible is not feasible;
    2. the first pass: the exact :func:`~deltajax.workspace.sample_value` at one IK-feasible sample per
       (design, point) -- the middle one of its IK-feasible range, where the index is usually largest;
    3. the second pass: the exact value at every other IK-feasible sample of the points the first pass left
       uncovered, compacted over the whole population and evaluated in chunks of ``chunk`` samples by a
       ``lax.while_loop`` (work proportional to their number, not to the population).

    Every decision is made by an exact value or by the exact kernel's own infeasibility, so ``covered`` is
    identical to the sweep's (tested on random and near-singular designs); the samples skipped are exactly
    those that cannot change it. Not vmappable over populations in a useful way (it is one already).

    Args:
        pb: the :class:`~deltajax.optimize.objectives.Problem` (``index``, ``k_min``, ``b_v``, ``b_f``, ``beta``;
            points default ``pb.task_points``).
        designs: a batch of reconfigurable designs (leading axis D, e.g. ``jax.vmap(space.decode)(genes)``).
        points: (N, 3) task points (m); default the problem's.
        chunk: samples per chunk of the second pass (static).
    """
    dt = designs.R_min.dtype
    pts = jnp.asarray(pb.task_points if points is None else points, dt)
    D, N, K = designs.R_min.shape[0], pts.shape[0], designs.n_R
    canon = jax.vmap(canonical_point)(pts)
    kw = dict(criterion=pb.index, b_v=pb.b_v, b_f=pb.b_f, beta=pb.beta)

    def ik_ok(d):  # (N, K): the exact kernel's ok at every sample (sample_value's R, canonical point)
        Rs = d.R_samples()
        return jax.vmap(lambda q: jax.vmap(lambda R: point_kernel(d.at(R), q, sv_method="jacobi").ok)(Rs))(canon)

    ikok = jax.vmap(ik_ok)(designs)  # (D, N, K)
    ks = jnp.arange(K, dtype=jnp.int32)[None, None, :]
    lo = jnp.min(jnp.where(ikok, ks, K), axis=-1)
    hi = jnp.max(jnp.where(ikok, ks, -1), axis=-1)
    any_ok = hi >= 0
    first = jnp.where(any_ok, (lo + hi) // 2, 0)  # (D, N)
    first = jnp.where(jnp.take_along_axis(ikok, first[..., None], -1)[..., 0], first, lo)  # an IK-feasible one
    first = jnp.where(any_ok, first, 0)

    def hit(d, q, k):
        feas, v = sample_value(d, q, k, **kw)
        return feas & (v - pb.k_min >= 0.0)

    cov1 = jax.vmap(lambda d, f: jax.vmap(lambda q, k: hit(d, q, k))(pts, f))(designs, first) & any_ok
    rest = ikok & ~cov1[..., None] & (ks != first[..., None])

    def update(covered, j, valid):
        di, pi, ki = j // (N * K), (j // K) % N, j % K
        dd = jax.tree_util.tree_map(lambda a: a[di], designs)
        return covered.at[di, pi].max(jax.vmap(hit)(dd, pts[pi], ki) & valid)

    covered, n = _chunked_any(rest.reshape(-1), chunk, update, cov1)
    return TaskCover(covered=covered, n_first=jnp.sum(any_ok, dtype=jnp.int32), n_rest=n, n_sweep=D * N * K)


#: Relative inflation of L1 and L2 before the closed-form reach test of :func:`reach_cover` (its certificate).
REACH_INFLATE = 1e-6


class ReachCover(NamedTuple):
    """Reachability of the workspace points for a population (:func:`reach_cover`).

    Attributes:
        reachable: (D, N) bool, some R sample reaches point n of design d (IK within the joint limits).
        n_excluded: (design, point) pairs excluded by the closed-form reach test (no IK run).
        n_rest: pairs swept over every R sample in the second pass.
        n_sweep: IK evaluations of the full sweep (D N n_R), for the ratio (the first pass costs D N).
    """

    reachable: Bool[Array, "d n"]
    n_excluded: Int[Array, ""]
    n_rest: Int[Array, ""]
    n_sweep: int


def reach_cover(designs: ReconfigurableDelta, points, *, chunk: int = TASK_CHUNK) -> ReachCover:
    """:func:`deltajax.workspace.reconfigurable_reachable` for a population of designs, with the same flags
    and a fraction of its IK evaluations.

    1. Exclusion (the certificate): :func:`deltajax.workspace.reach_interval` of the design with L1 and L2
       inflated by :data:`REACH_INFLATE` = 1e-6 (relative). When that interval is empty, at every R some chain
       has rho = |(d_x, p_z)| > L1' + L2'' (L1' = (1 + 1e-6) L1, L2'' = sqrt((1 + 1e-6)^2 L2^2 - p_y^2)),
       beyond the true outer reach L1 + L2' (L2' = sqrt(L2^2 - p_y^2)) by delta >= 1e-6 L1 + (L2'' - L2'), with
       L2'' - L2' >= 1e-6 L2^2 / (2 L2''). The IK's discriminant rho^2 - m^2 is then <= -(rho + m)(delta L2' / L1
       + delta^2 / (2 L1)) <= about -2e-6 L2^2 (and -1e-12 L1^2 in the worst corner), many orders beyond its
       rounding (~1e-15 (L1 + L2)^2): the exact IK fails at every sample, so no sample is skipped wrongly.
    2. First pass: the exact IK (:func:`deltajax.workspace.grid.reachable_point`, the sweep's own test) at one
       sample per remaining pair, the middle of the interval's sample range: reachable if it passes.
    3. Second pass: every sample of the pairs the first pass left undecided, compacted over the population and
       evaluated in chunks of ``chunk`` pairs by a ``lax.while_loop``.

    Only step 1 skips samples without running the IK on them, and only where no sample can pass.
    """
    dt = designs.R_min.dtype
    pts = jnp.asarray(points, dt)
    D, N, K = designs.R_min.shape[0], pts.shape[0], designs.n_R

    def window(d):  # (none (N,), mid (N,)): certified unreachable, and the first sample to try
        infl = eqx.tree_at(lambda r: (r.robot.upper_arm, r.robot.forearm), d,
                           (d.robot.upper_arm * (1.0 + REACH_INFLATE), d.robot.forearm * (1.0 + REACH_INFLATE)))
        lo, hi = jax.vmap(lambda q: reach_interval(infl, q))(pts)
        none = lo > hi  # False for NaN: then the pair is swept
        step_ok = d.R_step > 0.0
        k_lo = jnp.ceil((lo - d.R_min) / jnp.where(step_ok, d.R_step, 1.0))
        k_hi = jnp.floor((hi - d.R_min) / jnp.where(step_ok, d.R_step, 1.0))
        k_lo = jnp.where(step_ok & jnp.isfinite(k_lo), jnp.clip(k_lo, 0, K - 1), 0)
        k_hi = jnp.where(step_ok & jnp.isfinite(k_hi), jnp.clip(k_hi, 0, K - 1), K - 1)
        mid = jnp.clip(jnp.floor(0.5 * (k_lo + k_hi)), 0, K - 1).astype(jnp.int32)
        return none, mid

    none, mid = jax.vmap(window)(designs)

    def ok_at(d, q, k):
        return reachable_point(d.at(d.R_min + k.astype(dt) * d.R_step), q)

    ok1 = jax.vmap(lambda d, m: jax.vmap(lambda q, k: ok_at(d, q, k))(pts, m))(designs, mid) & ~none
    ks = jnp.arange(K, dtype=jnp.int32)

    def update(reach, j, valid):
        di, pi = j // N, j % N
        dd = jax.tree_util.tree_map(lambda a: a[di], designs)
        h = jax.vmap(lambda d, q: jnp.any(jax.vmap(lambda k: ok_at(d, q, k))(ks)))(dd, pts[pi])
        return reach.at[di, pi].max(h & valid)

    reach, n = _chunked_any((~none & ~ok1).reshape(-1), chunk, update, ok1)
    return ReachCover(reachable=reach, n_excluded=jnp.sum(none, dtype=jnp.int32), n_rest=n, n_sweep=D * N * K)
