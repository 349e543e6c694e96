"""Brute force over every sample path of a small :class:`deltajax.motion.PathTables`, and random tables with
ties, shared by the DP's exactness tests (tests/test_motion.py, tests/test_motion_dp_order.py)."""

import functools
import itertools
import math

import jax.numpy as jnp
import numpy as np

from deltajax import motion as mo


@functools.lru_cache(maxsize=8)
def _all_paths(K: int, n: int) -> np.ndarray:
    return np.array(list(itertools.product(range(n), repeat=K)), dtype=np.int64).reshape(-1, K)


def brute_force(tab, dt, w, a, fmax, aggregate, boundary):
    """The best (primary, secondary) score of :func:`deltajax.motion.path_score` over every sample path k (K,) that
    meets the bands (w, a), the boundary condition and the force limit (``(-inf, -inf)`` when none does).

    Vectorised over the n^K paths; the winner's score is :func:`path_score` itself on the few paths within
    rounding of the best, so the comparison with the DP is exact (``==``)."""
    K, n = tab.value.shape
    dR = float(tab.R_step)
    ks = _all_paths(K, n)
    d1, d2 = np.diff(ks, axis=1), np.diff(ks, 2, axis=1)
    keep = np.all(np.abs(d1) <= w, axis=1) & np.all(np.abs(d2) <= a, axis=1)
    if boundary in ("rest", "closed"):
        keep &= (d1[:, 0] == 0) & (d1[:, -1] == 0)
    if boundary == "closed":
        keep &= ks[:, 0] == ks[:, -1]
    j = np.arange(K)
    keep &= np.all(np.asarray(tab.feasible)[j, ks], axis=1)
    ks = ks[keep]
    if ks.shape[0] == 0:
        return (-math.inf, -math.inf)
    # the rates of motion._int_rates, row by row
    v = np.empty(ks.shape, float)
    acc = np.empty(ks.shape, float)
    v[:, 1:-1] = (ks[:, 2:] - ks[:, :-2]) * dR / (2 * dt)
    v[:, 0] = (ks[:, 1] - ks[:, 0]) * dR / dt
    v[:, -1] = (ks[:, -1] - ks[:, -2]) * dR / dt
    acc[:, 1:-1] = (ks[:, 2:] - 2 * ks[:, 1:-1] + ks[:, :-2]) * dR / (dt * dt)
    acc[:, 0], acc[:, -1] = acc[:, 1], acc[:, -2]
    c = np.asarray(tab.force_coef)[j, ks]
    F = c[..., 0] + v * (c[..., 1] + v * c[..., 2]) + acc * c[..., 3]
    ks = ks[np.all(np.abs(F) <= fmax, axis=1)]
    if ks.shape[0] == 0:
        return (-math.inf, -math.inf)
    vv = np.asarray(tab.value)[j, ks]
    integral = np.sum(np.asarray(tab.weights) * vv, axis=1)
    mn = np.min(vv, axis=1)
    tol = 1e-9 * (1.0 + np.max(np.abs(integral)))
    if aggregate == "min":
        near = (mn == np.max(mn)) & (integral >= np.max(integral[mn == np.max(mn)]) - tol)
    else:
        near = integral >= np.max(integral) - tol
    return max(mo.path_score(tab, k, aggregate) for k in ks[near])


def random_tables(seed, K=5, n=4):
    """Random (K, n) tables: values rounded to 0.01 (ties happen and must be handled), ~15 % infeasible cells,
    random force coefficients."""
    rng = np.random.default_rng(seed)
    value = rng.uniform(0.0, 1.0, (K, n)).round(2)
    feasible = rng.uniform(size=(K, n)) > 0.15
    coef = rng.normal(0.0, 1.0, (K, n, 4)) * np.array([3.0, 1.0, 0.5, 0.3])
    return mo.PathTables(t=jnp.linspace(0, 1, K), R=jnp.arange(n) * 0.01 + 0.1,
                         value=jnp.asarray(np.where(feasible, value, np.nan)), feasible=jnp.asarray(feasible),
                         force_coef=jnp.asarray(np.where(feasible[..., None], coef, np.nan)),
                         weights=jnp.asarray(np.r_[0.5, np.ones(K - 2), 0.5] * 0.25), R_step=jnp.asarray(0.01))
