"""The regular workspace found by rays, and the worst point of a field over a cylinder: pure geometry over a
good-point predicate (what "good" means is :func:`deltajax.constraints.good_point`), used by the designer's
verification (:mod:`deltajax.optimize.designer`) and by :mod:`deltajax.optimize.certify`.

* :func:`ray_cylinders` / :func:`ray_cylinder`: the largest axis-centred cylinder with a given H/D inside a good
  set, from *rays*: a ray (phi, z) of the 60 deg wedge (the Delta's three-fold + mirror symmetry) gives the first
  bad radius rho*(phi, z) (dense samples along the ray, then the first bad interval searched again, ``n_levels``
  times in all: a bad island between the old grid's rings, e.g. where a forearm passes through the base plate, is
  found, not skipped; :meth:`RayDensity.doubled` halves every spacing, the final resolution's too). The profile
  rho(z) = min over phi of rho* is refined in the passes of :data:`RAY_PASSES`, each
  placed where the previous one left the answer uncertain (coarse; levels zoomed onto the cylinder found so far;
  phi rays zoomed onto each level's smallest radius; a final check of the winning cylinder that can only shrink
  it). All passes run in one loop with one call of the good test: one traced copy per compiled program (two when
  the first samples along a ray and the nested searches differ in size, as at a doubled density).
* :func:`worst_in_cylinder`: the minimum of a scalar field over a task cylinder: dense samples, then a
  coordinate-wise golden section in (rho, phi, z) from the worst samples.

Pure JAX, float64, vmappable.
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple, Optional, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ..regular import RegularWorkspace

__all__ = ["RAY_DENSITY", "RAY_PASSES", "RAY_BATCH", "POSSIBLE_CHUNKS", "RayDensity", "ray_cylinders", "ray_cylinder",
           "worst_in_cylinder", "padded_linspace", "golden_min", "good_where_possible", "any_good_where_possible",
           "UNDECIDED_CHUNKS", "settle_good", "Decided", "first_open"]

_GOLD = (math.sqrt(5.0) - 1.0) / 2.0

#: The passes of :func:`ray_cylinders`, in order (module docstring).
RAY_PASSES = ("coarse", "zoom_z", "zoom_z", "zoom_z") + ("zoom_phi",) * 6 + ("check",)


class RayDensity(NamedTuple):
    """Density of :func:`ray_cylinders`: per pass ``n_z`` levels x ``n_phi`` rays (over the 60 deg wedge, both
    ends), ``n_along`` samples along a ray, then ``n_levels - 1`` nested searches of the first bad interval with
    ``n_refine`` samples each (0: ``n_along``): resolution r_max / ((n_along - 1) (n_refine - 1)^(n_levels - 1))."""

    n_phi: int = 7
    n_z: int = 16
    n_along: int = 9
    n_levels: int = 4
    n_refine: int = 0

    @property
    def refine(self) -> int:
        """Samples of each nested search."""
        return self.n_refine or self.n_along

    def doubled(self) -> "RayDensity":
        """Twice the density: half the spacing of the rays in phi and z, of the samples along a ray (same end points:
        2 n - 1 samples) and of the final resolution (the nested searches as they were)."""
        return self._replace(n_phi=2 * self.n_phi - 1, n_z=2 * self.n_z - 1, n_along=2 * self.n_along - 1,
                             n_refine=self.refine)


#: The verification's density (the fine evaluator, :func:`deltajax.optimize.designer.evaluate_designer`).
RAY_DENSITY = RayDensity()


def padded_linspace(a, b, n, size: int):
    """``jnp.linspace(a, b, n)`` at a traced count ``n`` (2 <= n <= ``size``), padded to ``size`` samples with
    copies of ``b``: the same values as the static linspace in its first n entries (one compiled program serves
    every count up to ``size``; the callers keep the padding out of their searches)."""
    s = jnp.minimum(jnp.arange(size), n - 1) / jnp.asarray(n - 1, jnp.result_type(float))
    return a * (1 - s) + b * s


def golden_min(f, a, b, n):
    """Golden-section search for a minimum of f on [a, b] (n steps); returns (x, f(x)) of the best point seen
    (the two interior points; the ends are not evaluated). One f per step (single traced copy)."""
    dt = jnp.result_type(a)
    c, d = b - _GOLD * (b - a), a + _GOLD * (b - a)
    inf = jnp.asarray(jnp.inf, dt)

    def step(i, st):
        a, b, c, d, fc, fd, xb, fb = st
        left = fc <= fd                                   # the minimum lies in [a, d]
        a2, b2 = jnp.where(left, a, c), jnp.where(left, d, b)
        xg = jnp.where(left, b2 - _GOLD * (b2 - a2), a2 + _GOLD * (b2 - a2))
        x = jnp.where(i == 0, c, jnp.where(i == 1, d, xg))
        fx = f(x)
        fx_ = jnp.where(jnp.isnan(fx), -inf, fx)          # NaN (unreachable) is the worst
        better = fx_ < fb
        xb, fb = jnp.where(better, x, xb), jnp.where(better, fx_, fb)
        gs = i >= 2
        return (jnp.where(gs, a2, a), jnp.where(gs, b2, b),
                jnp.where(gs, jnp.where(left, x, d), c), jnp.where(gs, jnp.where(left, c, x), d),
                jnp.where(gs, jnp.where(left, fx_, fd), jnp.where(i == 0, fx_, fc)),
                jnp.where(gs, jnp.where(left, fc, fx_), jnp.where(i == 1, fx_, fd)), xb, fb)

    st = jax.lax.fori_loop(0, 2 + n, step, (a, b, c, d, inf, inf, a, inf))
    return st[6], st[7]


# -- the regular workspace by rays ------------------------------------------------------------------------------

#: (R, point) pairs per evaluation of the good test in a ray pass: a pass with more evaluates them in batches of
#: this many (``jax.lax.map``), so its memory is bounded. The certify stage's second further doubling reaches
#: ~8e5 pairs per pass (the design's 16 R samples x 25 x 61 rays x 33 first samples along each), whose unbatched
#: intermediates (~3.5 kB a pair) took the main job from 1.9 to 4.45 GiB.
RAY_BATCH = 1 << 16


#: Pairs per full good test call of :func:`good_where_possible` in :func:`ray_cylinders`, as a fraction of all the
#: pairs of a search level (1/POSSIBLE_CHUNKS each; at most :data:`RAY_BATCH`).
POSSIBLE_CHUNKS = 16


def _possible(possible_R: Callable, Rf, Pf):
    """``possible_R`` at every pair, in batches of :data:`RAY_BATCH` pairs beyond that many (bounded memory at the
    certification's densities, like the full test's batches)."""
    if Rf.shape[0] <= RAY_BATCH:
        return jax.vmap(possible_R)(Rf, Pf)
    return jax.lax.map(lambda a: possible_R(*a), (Rf, Pf), batch_size=RAY_BATCH)


#: The full tests that a chunk's undecided pairs get per step of :func:`settle_good`: 1/UNDECIDED_CHUNKS of the chunk.
UNDECIDED_CHUNKS = 32


def _packed(mask, size: int):
    """Indices of the True entries of ``mask`` (M,) packed to the front in their order, padded to a multiple of
    ``size`` with the first of them (0 when there is none: a padding lane repeats a packed pair), and their
    count."""
    M = mask.shape[0]
    m = mask.astype(jnp.int32)
    pos = jnp.cumsum(m) - 1
    n = jnp.sum(m)
    order = jnp.zeros((M,), jnp.int32).at[jnp.where(mask, pos, M)].set(jnp.arange(M, dtype=jnp.int32), mode="drop")
    order = jnp.concatenate([order, jnp.zeros((size * -(-M // size) - M,), jnp.int32)])
    return jnp.where(jnp.arange(order.shape[0]) < n, order, order[0]), n


def first_open(mask, size: int):
    """(pick, live): the indices of the first ``size`` True entries of ``mask`` (M,) in their order, (size,) int32
    (0 beyond the last: a dead lane), and which lanes hold one -- the next round of a loop that tests the open
    pairs ``size`` at a time (:func:`any_good_where_possible`, the designer's all-any test)."""
    M = mask.shape[0]
    m = mask.astype(jnp.int32)
    pos = jnp.cumsum(m) - 1
    pick = jnp.zeros((size,), jnp.int32).at[jnp.where(mask & (pos < size), pos, size)].set(
        jnp.arange(M, dtype=jnp.int32), mode="drop")
    return pick, jnp.arange(size) < jnp.sum(m)


class Decided(NamedTuple):
    """A decided test that hands its work on: ``decide(R, p) -> (good, decided, state)`` and ``settle(state) ->
    good``, the full test's answer from that state (e.g. :func:`deltajax.constraints.good_point_decided` with
    ``state=True`` and :func:`deltajax.constraints.good_point_settle`: the IK is solved once per pair)."""

    decide: Callable
    settle: Callable


def settle_good(good_R: Callable, decided_R: Optional[Callable | Decided], R, P, live):
    """``good_R`` at the pairs (R, P) of one chunk: without ``decided_R`` the full test at every pair; with it
    (``(R, p) -> (good, decided)``, e.g. :func:`deltajax.constraints.good_point_decided`, or a :class:`Decided`)
    its answer where it decides, and the full test, packed, only at the live pairs it leaves undecided (a loop of
    chunks of 1/:data:`UNDECIDED_CHUNKS` of the chunk that does not run at all when none is): ``good_R`` there, or
    a :class:`Decided`'s ``settle`` of the state its ``decide`` left at those pairs."""
    if decided_R is None:
        return jax.vmap(good_R)(R, P)
    if isinstance(decided_R, Decided):
        g, dec, state = jax.vmap(decided_R.decide)(R, P)
        full = lambda idx: jax.vmap(decided_R.settle)(jax.tree_util.tree_map(lambda x: x[idx], state))  # noqa: E731
    else:
        g, dec = jax.vmap(decided_R)(R, P)
        full = lambda idx: jax.vmap(good_R)(R[idx], P[idx])  # noqa: E731
    K = R.shape[0]
    k2 = max(K // UNDECIDED_CHUNKS, 1)
    order, n = _packed(live & ~dec, k2)

    def body(st):
        c, g = st
        idx = jax.lax.dynamic_slice(order, (c * k2,), (k2,))
        gf = full(idx)
        return c + 1, g.at[jnp.where(c * k2 + jnp.arange(k2) < n, idx, K)].set(gf, mode="drop")

    return jax.lax.while_loop(lambda st: st[0] * k2 < n, body, (jnp.int32(0), g))[1]


def good_where_possible(good_R: Callable, possible_R: Callable, Rf, Pf, chunk: int,
                        decided_R: Optional[Callable] = None):
    """``good_R(Rf[i], Pf[i])`` for every pair i, (M,) bools, with the full test run only where the cheap necessary
    condition ``possible_R(R, p)`` holds (False elsewhere, which is the full test's answer there: ``possible_R``
    False must imply ``good_R`` False, e.g. :func:`deltajax.constraints.good_point_possible`).

    The pairs that may be good are packed to the front (in their order) and tested ``chunk`` at a time by a while
    loop that stops after the last one: the same test at the same pairs, so the same answers, at the cost of the
    possible pairs instead of all (working memory: ``chunk`` pairs). Vmapped over designs the loop runs until the
    batch's design with the most possible pairs is done. ``decided_R``: see :func:`settle_good`."""
    M = Rf.shape[0]
    maybe = _possible(possible_R, Rf, Pf)
    K = max(min(int(chunk), M), 1)
    order, count = _packed(maybe, K)

    def body(st):
        c, out = st
        idx = jax.lax.dynamic_slice(order, (c * K,), (K,))
        live = c * K + jnp.arange(K) < count
        g = settle_good(good_R, decided_R, Rf[idx], Pf[idx], live)
        return c + 1, out.at[jnp.where(live, idx, M)].set(g, mode="drop")

    _, out = jax.lax.while_loop(lambda st: st[0] * K < count, body, (jnp.int32(0), jnp.zeros((M,), bool)))
    return out


def any_good_where_possible(good_R: Callable, possible_R: Callable, Rf, Pf, sets: Sequence[tuple], chunk: int,
                            skip=None, decided_R: Optional[Callable] = None):
    """For every point of every set, whether ``good_R`` holds at any of its R: ``sets`` = ((n_points, n_R), ...)
    and the pairs (``Rf`` (M,), ``Pf`` (M, 3)) laid out set after set, each R-major (its first R at every point,
    then its second R at every point, ...); returns (sum of n_points,) bools, the sets' points in order.
    ``skip`` (sum of n_points,) bools: points whose answer the caller does not need (none of their pairs is tested;
    True is returned for them).

    The full test runs only at pairs where ``possible_R`` holds (a necessary condition of ``good_R``) and whose
    point has no good R yet: rounds of ``chunk`` pairs taken in layout order from the pairs still open, until none
    is. The answer does not depend on which pairs are tested or in what order (the test is pure), so it is the full
    any's, at the cost of fewer full tests. No array of M indices is built beyond the loop's own state (a constant
    of that size bloated the certification's programs). ``decided_R``: see :func:`settle_good` (a round's pairs get
    the cheaper test, and the full test only where it does not decide)."""
    M = Rf.shape[0]
    maybe = _possible(possible_R, Rf, Pf)
    K = max(min(int(chunk), M), 1)
    starts = np.cumsum([0] + [n * r for n, r in sets])[:-1]
    offs = np.cumsum([0] + [n for n, _ in sets])[:-1]
    n_all = int(sum(n for n, _ in sets))

    def open_points(sat):      # per pair: its point has no good R yet
        return jnp.concatenate([jnp.tile(~sat[o:o + n], r) for (n, r), o in zip(sets, offs)])

    def point_of(m):           # the point (index into sat) of pair m
        out = jnp.zeros_like(m)
        for (n, _), st, o in zip(sets, starts, offs):
            out = jnp.where(m >= st, o + (m - st) % n, out)
        return out

    def remaining(tested, sat):
        return maybe & ~tested & open_points(sat)

    def body(st):
        c, tested, sat = st
        pick, live = first_open(remaining(tested, sat), K)
        g = settle_good(good_R, decided_R, Rf[pick], Pf[pick], live) & live
        tested = tested.at[jnp.where(live, pick, M)].set(True, mode="drop")
        sat = sat.at[jnp.where(g, point_of(pick), n_all)].set(True, mode="drop")
        return c + 1, tested, sat

    _, _, sat = jax.lax.while_loop(lambda st: jnp.any(remaining(st[1], st[2])), body,
                                   (jnp.int32(0), jnp.zeros((M,), bool),
                                    jnp.zeros((n_all,), bool) if skip is None else skip))
    return sat


def _first_bad(good_R: Callable, R_sets, phi, z, r_hi, n_along: int, n_levels: int, possible_R, n_refine: int,
               decided_R: Optional[Callable] = None):
    """First bad radius along each ray, for each good set j (a point is good for set j when ``good_R(R, p)`` holds
    at any R of ``R_sets[j]``): ``phi[j]``, ``z[j]``, ``r_hi[j]`` (N,) per set; returns a list of (N,). ``n_along``
    samples in [0, r_hi], then the first bad interval searched again with ``n_refine`` samples
    (:attr:`RayDensity.refine`), ``n_levels`` times in all (every level a dense search, so an island inside the
    interval is found too; a first level of its own size is a second traced copy of the search). The value is the
    last good sample before the first bad one (never over-stated by the search), ``r_hi`` when every sample is good
    and 0 when the axis point is bad. Every (R, point) pair of every set goes through one vmapped call of ``good_R``
    (in batches of :data:`RAY_BATCH` pairs); with ``possible_R`` (a necessary condition of ``good_R``) only the
    pairs where it holds and whose point has no good R yet do (:func:`any_good_where_possible`: the same
    answers), and after the first level neither end of a ray's interval (its last good and first bad sample) nor
    a finished ray's samples are tested again."""
    dt = jnp.result_type(z[0])
    cs = [(jnp.cos(ph), jnp.sin(ph)) for ph in phi]
    init = [(jnp.zeros_like(zj), jnp.asarray(rh, dt) * jnp.ones_like(zj), jnp.zeros(zj.shape, bool),
             jnp.zeros(zj.shape, bool)) for zj, rh in zip(z, r_hi)]

    def level(n):
        return _level(good_R, R_sets, phi, z, cs, n, dt, possible_R, decided_R)

    if n_refine == n_along:
        st = jax.lax.fori_loop(0, n_levels, level(n_along), init)
    else:
        st = level(n_along)(0, init)
        st = jax.lax.fori_loop(1, n_levels, level(n_refine), st)
    return [jnp.where(axis_bad, 0.0, lo) for lo, _, _, axis_bad in st]


def _level(good_R, R_sets, phi, z, cs, n_along: int, dt, possible_R, decided_R=None):
    """One level of :func:`_first_bad`'s search with ``n_along`` samples per interval: ``(i, state) -> state``."""
    u = jnp.linspace(0.0, 1.0, n_along, dtype=dt)
    ends = (jnp.arange(n_along) == 0) | (jnp.arange(n_along) == n_along - 1)
    known = jnp.arange(n_along) < n_along - 1           # a known sample's answer: only the last one is bad
    sizes = [ph.shape[0] * n_along * Rj.shape[0] for ph, Rj in zip(phi, R_sets)]

    def level(i, st):
        rows = []
        for j, (lo, hi, _, _) in enumerate(st):
            s = lo[:, None] + u[None, :] * (hi - lo)[:, None]                          # (N, n_along)
            p = jnp.stack([s * cs[j][0][:, None], s * cs[j][1][:, None], jnp.broadcast_to(z[j][:, None], s.shape)],
                          axis=-1)
            nR = R_sets[j].shape[0]
            if possible_R is not None:   # R-major (any_good_where_possible's layout)
                rows.append((jnp.broadcast_to(R_sets[j][:, None], (nR, s.size)).reshape(-1),
                             jnp.broadcast_to(p.reshape(1, -1, 3), (nR, s.size, 3)).reshape(-1, 3)))
            else:                        # point-major, R inner
                rows.append((jnp.broadcast_to(R_sets[j], s.shape + (nR,)).reshape(-1),
                             jnp.broadcast_to(p[:, :, None, :], s.shape + (nR, 3)).reshape(-1, 3)))
        Rf = jnp.concatenate([r for r, _ in rows])
        Pf = jnp.concatenate([p for _, p in rows])
        M = Rf.shape[0]
        # after the first level a sample's answer is known or not needed: a ray's first sample is its last good
        # one, its last the first bad one, and a finished ray (every sample good, or its axis point bad) keeps its
        # answer whatever the samples say
        later = i > 0
        skips = [later & ((done | axis_bad)[:, None] | ends[None, :]) for _, _, done, axis_bad in st]
        if possible_R is not None:    # the one call, where the pair may be good and its point has no good R yet
            anyg = any_good_where_possible(good_R, possible_R, Rf, Pf,
                                           [(ph.shape[0] * n_along, Rj.shape[0]) for ph, Rj in zip(phi, R_sets)],
                                           min(-(-M // POSSIBLE_CHUNKS), RAY_BATCH),
                                           skip=jnp.concatenate([sk.reshape(-1) for sk in skips]),
                                           decided_R=decided_R)
        else:
            gf = (jax.vmap(good_R)(Rf, Pf) if M <= RAY_BATCH else                       # the one call,
                  jax.lax.map(lambda a: good_R(*a), (Rf, Pf), batch_size=RAY_BATCH))    # in batches
        out, k, kp = [], 0, 0
        for j, (lo, hi, done, axis_bad) in enumerate(st):
            npts = lo.shape[0] * n_along
            if possible_R is not None:
                g = anyg[kp:kp + npts].reshape(lo.shape[0], n_along)                   # (N, n_along)
            else:
                g = jnp.any(gf[k:k + sizes[j]].reshape(lo.shape[0], n_along, -1), axis=2)
            g = jnp.where(skips[j], known, g)
            k += sizes[j]
            kp += npts
            s = lo[:, None] + u[None, :] * (hi - lo)[:, None]
            jb = jnp.argmin(g, axis=1)
            all_good = jnp.all(g, axis=1)
            axis_bad = axis_bad | ((i == 0) & ~g[:, 0])
            take = lambda idx: jnp.take_along_axis(s, idx[:, None], axis=1)[:, 0]  # noqa: E731
            new_lo = jnp.where(all_good, hi, take(jnp.maximum(jb - 1, 0)))
            new_hi = jnp.where(all_good, hi, take(jb))
            out.append((jnp.where(done, lo, new_lo), jnp.where(done, hi, new_hi), done | all_good, axis_bad))
        return out

    return level


def _window_min(pz, pr, lo, hi):
    """The smallest radius of the profile over [lo, hi]: the samples inside and the profile linearly interpolated
    at both ends (samples ``pz``, ``pr``; empty slots have ``pr`` = inf); -1 when [lo, hi] leaves the sampled
    range. Between two samples the profile is taken as linear: where the smallest radius changes rays (a kink of
    a minimum over phi) that is below the true profile."""
    fin = jnp.isfinite(pr)
    inside = (pz >= lo) & (pz <= hi) & fin
    m = jnp.min(jnp.where(inside, pr, jnp.inf))

    def at(e):
        below, above = fin & (pz <= e), fin & (pz >= e)
        zb = jnp.max(jnp.where(below, pz, -jnp.inf))
        za = jnp.min(jnp.where(above, pz, jnp.inf))
        rb = jnp.min(jnp.where(below & (pz == zb), pr, jnp.inf))
        ra = jnp.min(jnp.where(above & (pz == za), pr, jnp.inf))
        w = jnp.where(za > zb, (e - zb) / jnp.where(za > zb, za - zb, 1.0), 0.0)
        return jnp.where(za > zb, rb + w * (ra - rb), jnp.minimum(ra, rb))

    ok = (lo >= jnp.min(jnp.where(fin, pz, jnp.inf))) & (hi <= jnp.max(jnp.where(fin, pz, -jnp.inf)))
    return jnp.where(ok, jnp.minimum(m, jnp.minimum(at(lo), at(hi))), -1.0)


def _diameter_at(pz, pr, c, hd_ratio, d_max, n_iter: int = 48):
    """Largest D with D <= 2 x :func:`_window_min` over [c - hd D / 2, c + hd D / 2] (the span shrinks with D, so
    the test is monotone: bisection)."""
    def body(_, lh):
        lo, hi = lh
        mid = 0.5 * (lo + hi)
        ok = 2.0 * _window_min(pz, pr, c - hd_ratio * mid / 2.0, c + hd_ratio * mid / 2.0) >= mid
        return jnp.where(ok, mid, lo), jnp.where(ok, hi, mid)

    lo, _ = jax.lax.fori_loop(0, n_iter, body, (jnp.zeros_like(c), jnp.asarray(d_max, c.dtype)))
    return lo


def _profile_cylinder(pz, pr, z_min, z_max, hd_ratio, d_max, n_c: int, n_golden: int = 24):
    """(centre, D) of the largest cylinder over the profile samples (pz, pr): ``n_c`` centres over [z_min, z_max],
    then a golden section around the best (no good test: cheap)."""
    dt = pz.dtype
    cs = jnp.linspace(z_min, z_max, n_c, dtype=dt)
    Ds = jax.vmap(lambda c: _diameter_at(pz, pr, c, hd_ratio, d_max))(cs)
    j = jnp.argmax(Ds)
    dcs = cs[1] - cs[0]
    c_g, negD = golden_min(lambda c: -_diameter_at(pz, pr, c, hd_ratio, d_max), cs[j] - dcs, cs[j] + dcs, n_golden)
    better = -negD > Ds[j]
    return jnp.where(better, c_g, cs[j]), jnp.where(better, -negD, Ds[j])


def ray_cylinders(good_R: Callable, R_sets: Sequence, r_max: float, z_min: float, z_max: float, hd_ratio: float,
                  density: RayDensity = RAY_DENSITY, dtype=None, *, possible_R: Optional[Callable] = None,
                  decided_R: Optional[Callable] = None) -> list:
    """The regular workspace from rays (module docstring) of each good set: a point is good for set j when
    ``good_R(R, p)`` (R scalar, p (3,) m, z down) holds at any R of ``R_sets[j]`` (an (n_j,) array: e.g. the
    design's R samples, R chosen per point; or the operating R alone). The largest cylinder on the z axis with
    height = ``hd_ratio`` x diameter inside [z_min, z_max] and radius <= ``r_max``. Pure, vmappable; returns one
    :class:`deltajax.constraints.RegularWorkspace` per set (zeros when nothing fits). The passes of
    :data:`RAY_PASSES` run in one loop, and every pass's rays of every set go through one call of ``good_R``.

    Each profile sample is a *level*: its z, the smallest first-bad radius of its rays, the phi of that ray and the
    phi span around it still unsearched. After the coarse pass, rays search [0, min(r_max, 0.65 D)] only (D: the
    cylinder so far; a radius beyond that cannot bind), so the same samples give a finer radius.

    ``possible_R(R, p) -> bool``: a cheap necessary condition of ``good_R`` (False only where ``good_R`` is False,
    e.g. :func:`deltajax.constraints.good_point_possible`); the full test then runs only where it holds
    (:func:`any_good_where_possible`), with the same answer. ``decided_R(R, p) -> (good, decided)`` (with
    ``possible_R``): a cheaper test whose answer is taken where it decides (:func:`settle_good`), e.g.
    :func:`deltajax.constraints.good_point_decided`, or a :class:`Decided` that hands its state to the full test."""
    dt = jnp.result_type(float) if dtype is None else dtype
    n = density
    nz, nphi = n.n_z, n.n_phi
    m = len(R_sets)
    R_sets = [jnp.asarray(Rj, dt).reshape(-1) for Rj in R_sets]
    nzoom = RAY_PASSES.count("zoom_z")
    kinds, sub, seen = [], [], {}
    for k in RAY_PASSES:
        kinds.append(("coarse", "zoom_z", "zoom_phi", "check").index(k))
        base = "zoom_z" if k == "zoom_phi" else k
        sub.append(seen.get(base + k, 0) % max(nzoom, 1))
        seen[base + k] = seen.get(base + k, 0) + 1
    T = nz * (1 + nzoom)                       # the coarse levels, then each zoom_z pass's
    wedge = math.pi / 3.0
    d_max = 2.0 * r_max
    phi0 = jnp.linspace(0.0, wedge, nphi, dtype=dt)
    phi_mid = (jnp.arange(nphi, dtype=dt) + 0.5) / nphi * wedge       # the check's rays: between the grid's
    dphi0 = wedge / (nphi - 1)
    zg = jnp.linspace(z_min, z_max, nz, dtype=dt)
    dz0 = (z_max - z_min) / (nz - 1)
    ui = jnp.linspace(-1.0, 1.0, nphi, dtype=dt)
    jz = jnp.arange(nz)
    n_c = 4 * nz
    inf = jnp.asarray(jnp.inf, dt)
    kind_of, sub_of = jnp.asarray(kinds), jnp.asarray(sub)

    def layout(i, st):
        """Pass i's rays of one set: z (nz, nphi), phi (nz, nphi), r_hi (), the level slots it writes (nz,), the
        phi half-width of its rays (nz,) and the zoomed range (lo, hi)."""
        c, D = st["c"], st["D"]
        top, bot = c - hd_ratio * D / 2.0, c + hd_ratio * D / 2.0
        kind, k = kind_of[i], sub_of[i]
        # zoom_z: the range is fixed by the first zoom_z pass (over the cylinder so far and 1.5 coarse spacings
        # beyond each end); pass k takes every nzoom-th of nzoom x nz uniform levels from offset k
        first = (kind == 1) & (k == 0)
        lo = jnp.where(first, jnp.maximum(top - 1.5 * dz0, z_min), st["lo"])
        hi = jnp.where(first, jnp.minimum(bot + 1.5 * dz0, z_max), st["hi"])
        zz = lo + (nzoom * jz + k) * (hi - lo) / (nzoom * nz - 1)
        slots = jnp.where(kind == 0, jz, (1 + k) * nz + jz)
        z_ck = jnp.linspace(top, bot, nz)                                # check: top disc to bottom disc
        zs = jnp.select([kind == 0, kind == 1, kind == 2], [zg, zz, st["z"][slots]], z_ck)
        width = jnp.where(kind == 2, st["span"][slots], 0.0)
        ps = jnp.select([kind <= 1, kind == 3], [jnp.broadcast_to(phi0, (nz, nphi)),
                                                  jnp.broadcast_to(phi_mid, (nz, nphi))],
                        jnp.clip(st["phi"][slots][:, None] + width[:, None] * ui[None, :], 0.0, wedge))
        r_hi = jnp.where(kind == 3, D / 2.0, jnp.where((kind == 0) | (D <= 0), r_max, jnp.minimum(r_max, 0.65 * D)))
        return jnp.broadcast_to(zs[:, None], (nz, nphi)), ps, r_hi, slots, width, lo, hi

    def update(i, st, zs, ps, slots, width, lo, hi, rho):
        """One set's state after pass i gave the radii ``rho`` (nz, nphi) of its rays."""
        kind = kind_of[i]
        row_r = jnp.min(rho, axis=1)
        row_phi = ps[jz, jnp.argmin(rho, axis=1)]
        add, zoom, chk = kind <= 1, kind == 2, kind == 3
        old_r = st["r"][slots]
        better = row_r < old_r
        z = st["z"].at[slots].set(jnp.where(add, zs[:, 0], st["z"][slots]))
        r = st["r"].at[slots].set(jnp.where(add, row_r, jnp.where(zoom, jnp.minimum(row_r, old_r), old_r)))
        phi = st["phi"].at[slots].set(jnp.where(add | (zoom & better), row_phi, st["phi"][slots]))
        span = st["span"].at[slots].set(jnp.where(add, dphi0, jnp.where(zoom, 2.0 * width / (nphi - 1),
                                                                        st["span"][slots])))
        c_new, D_new = _profile_cylinder(z, r, z_min, z_max, hd_ratio, d_max, n_c)
        return dict(z=z, r=r, phi=phi, span=span, c=jnp.where(chk, st["c"], c_new), D=jnp.where(chk, st["D"], D_new),
                    check=jnp.where(chk, jnp.min(row_r), st["check"]), lo=lo, hi=hi)

    def one_pass(i, sts):
        lay = [layout(i, st) for st in sts]
        radii = _first_bad(good_R, R_sets, [a[1].reshape(-1) for a in lay], [a[0].reshape(-1) for a in lay],
                           [jnp.broadcast_to(a[2], (nz * nphi,)) for a in lay], n.n_along, n.n_levels, possible_R,
                           n.refine, decided_R)
        return [update(i, st, *a[:2], *a[3:], r.reshape(nz, nphi)) for st, a, r in zip(sts, lay, radii)]

    st0 = dict(z=jnp.full((T,), inf), r=jnp.full((T,), inf), phi=jnp.zeros((T,), dt), span=jnp.full((T,), dphi0, dt),
               c=jnp.asarray(0.5 * (z_min + z_max), dt), D=jnp.zeros((), dt), check=inf,
               lo=jnp.asarray(z_min, dt), hi=jnp.asarray(z_max, dt))
    sts = jax.lax.fori_loop(0, len(RAY_PASSES), one_pass, [dict(st0) for _ in range(m)])
    out = []
    for st in sts:
        D = jnp.maximum(jnp.minimum(st["D"], 2.0 * st["check"]), 0.0)
        H = hd_ratio * D
        out.append(RegularWorkspace(volume=math.pi / 4.0 * D * D * H, diameter=D, height=H, z_top=st["c"] - H / 2.0))
    return out


def ray_cylinder(good_fn: Callable, r_max: float, z_min: float, z_max: float, hd_ratio: float,
                 density: RayDensity = RAY_DENSITY, dtype=None) -> RegularWorkspace:
    """:func:`ray_cylinders` of one good set given as ``good_fn(p) -> bool`` (p (3,), m, z down)."""
    dt = jnp.result_type(float) if dtype is None else dtype
    return ray_cylinders(lambda R, p: good_fn(p), [jnp.zeros((1,), dt)], r_max, z_min, z_max, hd_ratio, density,
                         dt)[0]


# -- worst points of a task cylinder ------------------------------------------------------------------------------

def worst_in_cylinder(f: Callable, diameter: float, height: float, z_top: float, n_r: int, n_phi: int, n_z: int,
                      *, n_golden: int = 10, n_start: int = 2, sweeps: int = 2, counts=None):
    """Minimum of the field ``f(p)`` (a scalar or an (m,) vector of fields, each minimised on its own; NaN:
    unreachable, the worst) over the cylinder of ``diameter`` and ``height`` on the z axis from ``z_top`` (z down),
    using the 60 deg wedge (the Delta's symmetry): samples rho in [0, D/2] (``n_r``) x phi in [0, 60 deg]
    (``n_phi``) x z (``n_z``), then from the ``n_start`` worst samples of each field a coordinate-wise golden
    section (``sweeps`` sweeps over rho, phi, z, each in +-1 sample spacing, clipped to the cylinder). Returns
    (minimum, point (3,)), each with a leading (m,) axis for a vector field. Two call sites of ``f`` (the samples
    and the search), so it is traced twice.

    ``counts``: (3,) traced sample counts (rings, angles, levels), each >= 2 and at most ``n_r``, ``n_phi``, ``n_z``
    (the array shapes): the same samples and search as with those counts as ``n_*``, in one compiled program for
    every count up to the shapes (the samples beyond a count repeat its last one and are never chosen)."""
    if counts is None:
        m = (n_r, n_phi, n_z)
    else:
        m = tuple(jnp.asarray(counts)[i] for i in range(3))

    def grid(a, b, n, size):
        return jnp.linspace(a, b, n) if isinstance(n, int) else padded_linspace(a, b, n, size)

    rr = grid(0.0, diameter / 2.0, m[0], n_r)
    pp = grid(0.0, math.pi / 3.0, m[1], n_phi)
    zz = grid(z_top, z_top + height, m[2], n_z)
    Z, Rr, P = jnp.meshgrid(zz, rr, pp, indexing="ij")
    q = jnp.stack([Rr.reshape(-1), P.reshape(-1), Z.reshape(-1)], axis=1)     # (rho, phi, z)
    if counts is None:
        pad = None
    else:
        iz, ir, ip = jnp.meshgrid(jnp.arange(n_z), jnp.arange(n_r), jnp.arange(n_phi), indexing="ij")
        pad = ((ir >= m[0]) | (ip >= m[1]) | (iz >= m[2])).reshape(-1)

    def at(x):
        return jnp.stack([x[0] * jnp.cos(x[1]), x[0] * jnp.sin(x[1]), x[2]])

    def fv(p):
        return jnp.atleast_1d(f(p))

    V = jax.vmap(lambda x: fv(at(x)))(q)                                      # (n, m)
    V = jnp.where(jnp.isnan(V), -jnp.inf, V)
    if pad is not None:
        V = jnp.where(pad[:, None], jnp.inf, V)
    lo = jnp.asarray([0.0, 0.0, z_top])
    hi = jnp.asarray([diameter / 2.0, math.pi / 3.0, z_top + height])
    if counts is None:
        step = jnp.asarray([diameter / 2.0 / max(n_r - 1, 1), math.pi / 3.0 / max(n_phi - 1, 1),
                            height / max(n_z - 1, 1)])
    else:
        step = jnp.stack([diameter / 2.0 / jnp.maximum(m[0] - 1, 1), math.pi / 3.0 / jnp.maximum(m[1] - 1, 1),
                          height / jnp.maximum(m[2] - 1, 1)]).astype(q.dtype)
    ns = min(n_start, q.shape[0])

    def field(v, c):
        _, idx = jax.lax.top_k(-v, ns)

        def search(x0, f0):
            def coord(i, st):
                x, fx = st
                d = i % 3
                a = jnp.clip(x[d] - step[d], lo[d], hi[d])
                b = jnp.clip(x[d] + step[d], lo[d], hi[d])
                t, ft = golden_min(lambda t: fv(at(x.at[d].set(t)))[c], a, b, n_golden)
                better = ft < fx
                return jnp.where(better, x.at[d].set(t), x), jnp.where(better, ft, fx)

            return jax.lax.fori_loop(0, 3 * sweeps, coord, (x0, f0))

        xs, fs = jax.vmap(search)(q[idx], v[idx])
        j = jnp.argmin(fs)
        best = jnp.minimum(fs[j], jnp.min(v))
        return jnp.where(jnp.isinf(best) & (best < 0), jnp.nan, best), at(xs[j])

    best, pts = jax.vmap(field, in_axes=(1, 0))(V, jnp.arange(V.shape[1]))
    scalar = jnp.ndim(jax.eval_shape(f, jnp.zeros(3, q.dtype))) == 0
    return (best[0], pts[0]) if scalar else (best, pts)


# -- one design, certified ------------------------------------------------------------------------------------------
