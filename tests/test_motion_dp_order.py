"""The path DP's order is exactly the documented one for every variant it supports, on many random tables:
aggregate "min" is lexicographic (best minimum first, then the largest integral among the paths with that
minimum), aggregate "integral" is (integral, then minimum); static bands, traced speed/acceleration limits,
the force limit and the three boundary conditions, against brute force over every sample path."""

import math

import jax.numpy as jnp
import numpy as np
import pytest
from _motion_helpers import brute_force, random_tables

from deltajax import motion as mo

#: seeds 21 and 28 made the one-pass DP return a path with the optimal minimum but a smaller integral
SEEDS = range(40)
DT = 0.05
#: (w, a, force limit): tight bands with a binding force limit, then no limit at all
LIMITS = [(1, 1, 4.0), (2, 1, 3.0), (3, 6, math.inf)]


def _check_path(tab, res, bf, w, a, fmax, aggregate):
    assert res.ok == np.isfinite(bf[0])
    if res.ok:   # the returned path achieves the score and meets the bands and the force limit
        assert mo.path_score(tab, res.k, aggregate) == bf
        assert np.all(np.abs(np.diff(res.k)) <= w) and np.all(np.abs(np.diff(res.k, 2)) <= a)
        assert np.all(np.abs(res.force_R) <= fmax)


@pytest.mark.slow   # 18 DP programs (static bands x boundaries x aggregates) to compile or load
@pytest.mark.parametrize("aggregate", ["min", "integral"])
def test_dp_order_equals_brute_force_over_many_seeds(aggregate):
    """resolve_tables (static bands, the host filter of closed starts, the returned path) = brute force."""
    for seed in SEEDS:
        tab = random_tables(seed)
        for w, a, fmax in LIMITS:
            for boundary in mo.BOUNDARIES:
                res = mo.resolve_tables(tab, DT, w, a, fmax, aggregate=aggregate, boundary=boundary)
                bf = brute_force(tab, DT, w, a, fmax, aggregate, boundary)
                assert res.score == bf, (seed, w, a, fmax, boundary)
                _check_path(tab, res, bf, w, a, fmax, aggregate)


@pytest.mark.slow
def test_min_order_with_traced_speed_and_accel_limits():
    """path_optimum's form (wide static bands, the limits traced per design; three programs): the lexicographic
    (min, integral) optimum of brute force with the bands those limits give, and a path that achieves it
    (closed: every start tried, the best by the same order)."""
    n = 4
    dR = 0.01
    for seed in SEEDS:
        tab = random_tables(seed, n=n)
        args = (tab.value, tab.feasible, tab.force_coef, tab.weights, dR, DT, 3.0)
        for speed, accel in ((0.2, 4.0), (0.4, 4.0), (math.inf, 8.0)):
            w = n - 1 if math.isinf(speed) else int(math.floor(speed * DT / dR * (1 + 1e-9)))
            a = min(2 * w, int(math.floor(accel * DT * DT / dR * (1 + 1e-9))))
            for boundary in mo.BOUNDARIES:
                bf = brute_force(tab, DT, w, a, 3.0, "min", boundary)
                starts = range(n) if boundary == "closed" else [0]
                got = [mo.path_dp_jit(*args, k0, w=n - 1, a=2 * (n - 1), primary_min=True, boundary=boundary,
                                  backtrack=True, speed=speed, accel=accel) for k0 in starts]
                P, S, path = max(((float(P), float(S), np.asarray(k)) for P, S, k in got), key=lambda r: r[:2])
                assert P == bf[0], (seed, speed, accel, boundary)
                if np.isfinite(bf[0]):   # the DP's own running sum, not path_score's: equal to rounding
                    assert S == pytest.approx(bf[1], rel=1e-12, abs=0), (seed, speed, accel, boundary)
                    assert mo.path_score(tab, path, "min") == bf
                    assert np.all(np.abs(np.diff(path)) <= w) and np.all(np.abs(np.diff(path, 2)) <= a)
                else:
                    assert S == -math.inf
