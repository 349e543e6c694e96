"""The backends beyond their kernel functions: the Numba drivers (``deltajax.workspace.numba_fields``) against the
JAX core and the NumPy reference on a mixed batch (reachable, unreachable, joint-limit, on-axis, huge and
non-finite points), the fast eigenvalue method against the exact one on a workspace, the benchmark loops, and
the Jacobi rotation's underflow guard.

Function by function, every backend against the JAX definition: the conformance table
(``deltajax.backends.KERNELS``, ``tests/test_backend_conformance.py``).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import deltajax as dj
from deltajax import reference as ref
from deltajax.indices import point_kernel
from deltajax.workspace import numba_fields, numba_kernel as nbk

ROBOT = dj.presets.franco2026(fixed_R=0.2)
R, r, L1, L2 = 0.2, 0.065, 0.2, 0.4
TH_MIN, TH_MAX = float(ROBOT.theta_min), float(ROBOT.theta_max)
LIM_NB = tuple(float(v) for v in nbk.limits_tuple(TH_MIN, TH_MAX))
KT = (0.5 * 2.0, 2.0, 0.5 * 4.2, 4.2)
METHODS = (("jacobi", nbk.JACOBI), ("fast", nbk.FAST))
RNG = np.random.default_rng(20261201)


def _points(n, rng=RNG):
    """Random points over the franco2026 box plus special ones: the z axis, joint-limit and reach edges,
    far away, huge and non-finite."""
    p = np.stack([rng.uniform(-0.45, 0.45, n), rng.uniform(-0.45, 0.45, n), rng.uniform(-0.05, 0.65, n)], -1)
    special = [[0.0, 0.0, z] for z in np.linspace(0.1, 0.55, 10)]
    special += [[1e-9, -1e-9, 0.3], [0.3, 0.2, 0.1], [2.0, 0.0, 0.3], [1e200, 0.0, 0.3], [0.0, 0.0, -0.3],
                [np.nan, 0.0, 0.3], [np.inf, 0.1, 0.2], [0.1, 0.1, 0.0]]
    return np.concatenate([p, np.array(special)])


def _nb_fields(pts, method):
    x, y, z = (np.ascontiguousarray(pts[:, i]) for i in range(3))
    out = np.empty((numba_fields.N_IDX, len(pts)))
    ok = np.empty(len(pts), np.bool_)
    # the drivers pass mirror-canonical points (|y|); y >= 0 here so nothing is changed
    numba_fields.fixed_fields(x, y, z, R, r, L1, L2, np.array(nbk.limits_tuple(TH_MIN, TH_MAX)), np.array(KT), numba_fields.rows(out),
                     ok, method)
    return ok, out


# -- the drivers on one batch, all three backends ----------------------------------------------------------------
@pytest.mark.parametrize("method,code", METHODS)
@pytest.mark.slow
def test_fixed_fields_driver_agrees_with_jax_and_reference(method, code):
    pts = _points(3000)
    pts[:, 1] = np.abs(pts[:, 1])  # the Numba drivers evaluate mirror-canonical points (see workspace.grid)
    ok_nb, out = _nb_fields(pts, code)
    pk = jax.jit(jax.vmap(lambda p: point_kernel(ROBOT, p, sv_method=method)))(jnp.asarray(pts))
    ok_jax = np.asarray(pk.ok) & (np.asarray(pk.det_jx) != 0.0)
    r_ = ref.point_indices(R, r, L1, L2, TH_MIN, TH_MAX, pts)
    np.testing.assert_array_equal(ok_nb, ok_jax)
    np.testing.assert_array_equal(ok_nb, r_["ok"])
    assert 300 < ok_nb.sum() < len(pts) - 300
    assert np.all(np.isnan(out[:, ~ok_nb]))  # failure is NaN, never a number
    on_axis = np.hypot(pts[:, 0], pts[:, 1]) < 1e-4
    for i, n in enumerate(dj.INDEX_NAMES):
        np.testing.assert_allclose(out[i, ok_nb], np.asarray(getattr(pk.indices, n))[ok_nb], rtol=1e-11)
        tol = 1e-9 if method == "jacobi" else 1e-7
        sel = ok_nb & ~on_axis
        np.testing.assert_allclose(out[i, sel], r_[n][sel], rtol=tol)
        np.testing.assert_allclose(out[i, ok_nb & on_axis], r_[n][ok_nb & on_axis], rtol=1e-6)


def test_workspace_fields_fast_method_matches_exact():
    g = dj.workspace.franco2026_grid(0.05)
    a = dj.workspace.fixed_workspace(ROBOT, g)
    b = dj.workspace.fixed_workspace(ROBOT, g, sv_method="fast")
    np.testing.assert_array_equal(a.ok, b.ok)
    for n in dj.INDEX_NAMES:
        np.testing.assert_allclose(b.fields[n], a.fields[n], rtol=1e-7)
    with pytest.raises(ValueError, match="sv_method"):
        dj.workspace.fixed_workspace(ROBOT, g, sv_method="cardano")


def test_benchmark_hook_and_minimal_loop():
    from deltajax.benchmarks.numba_loops import bench_kernel_rates, bench_numba, minimal_loop, minimal_loop_newton

    pts = _points(3000)
    pts[:, 1] = np.abs(pts[:, 1])
    ok, out = _nb_fields(pts, nbk.FAST)
    x, y, z = (np.ascontiguousarray(pts[ok, i]) for i in range(3))
    o2, k2 = np.empty((8, len(x))), np.empty(len(x), np.bool_)
    minimal_loop(x, y, z, R, r, L1, L2, np.array(LIM_NB), np.array(KT), o2, k2)
    assert k2.all()  # the ceiling computes the same thing (to the cubic's accuracy)
    np.testing.assert_allclose(o2, out[:, ok], rtol=1e-6)
    o3, k3 = np.empty_like(o2), np.empty_like(k2)  # the same loop with FMA-only divides / square roots
    minimal_loop_newton(x, y, z, R, r, L1, L2, np.array(LIM_NB), np.array(KT), o3, k3)
    np.testing.assert_array_equal(k3, k2)
    np.testing.assert_allclose(o3, o2, rtol=1e-6)  # ~1 ulp per operation, amplified near the cubic's ties
    rates = bench_kernel_rates(pts, [R, r, L1, L2, TH_MIN, TH_MAX], 1)
    assert {"exact (jacobi)", "fast (cubic)", "exact on reachable", "minimal loop ceiling (reachable)",
            "minimal loop, FMA-only divide/sqrt (reachable)"} <= set(rates)
    assert rates["exact on reachable"][0] == ok.sum() and all(v[2] >= 0 for v in rates.values())
    assert bench_numba(pts[:100], ROBOT)["fast (cubic)"]["n"] == 100


def test_jacobi_rotation_survives_underflowing_off_diagonals():
    # a repeated eigenvalue: the sweeps drive a_pq to ~1e-156 with a_qq == a_pp exactly, where the squares
    # of the one-division rotation underflow (they gave inf/NaN before the guard)
    A = (1.524432339144239, 0.3983987489261778, 0.6310453646442962, 0.26725819731717965, 0.5894091119446706,
         0.1327923499557009)
    M = np.array([[A[0], A[3], A[4]], [A[3], A[1], A[5]], [A[4], A[5], A[2]]])
    got = nbk.sym3_top2(*A, 0.0, 0.0, nbk.JACOBI)
    np.testing.assert_allclose(got, np.linalg.eigvalsh(M)[::-1][:2], rtol=1e-13)
    app, aqq, arp, arq = nbk._jacobi_rotate(0.3, 0.3, 1e-160, 1e-170, 2e-170)
    assert all(math.isfinite(v) for v in (app, aqq, arp, arq)) and abs(app - 0.3) < 1e-159
