"""Every backend agrees: the JAX core, its Numba mirror (``deltajax.workspace.numba_kernel``) and the independent
NumPy reference (``deltajax.reference``), function by function on random inputs, then the whole kernel on a
mixed batch (reachable, unreachable, joint-limit, on-axis, huge and non-finite points).

The Numba functions are the inlined building blocks of the workspace drivers; here they are called one
input at a time from Python (each is also an ordinary compiled function).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import deltajax as dj
from deltajax import reference as ref
from deltajax.indices import indices_from_sv, point_kernel, singular_values, sym3_top2
from deltajax.jacobian import jq_theta, jx_det, jx_row
from deltajax.kinematics import chain_local, limit_terms, loop_closure, loop_vectors
from deltajax.workspace import numba_fields, numba_kernel as nbk

ROBOT = dj.presets.franco2026(fixed_R=0.2)
R, r, L1, L2 = 0.2, 0.065, 0.2, 0.4
TH_MIN, TH_MAX = float(ROBOT.theta_min), float(ROBOT.theta_max)
LIM_NB = tuple(float(v) for v in nbk.limits_tuple(TH_MIN, TH_MAX))
LIM_JAX = limit_terms(TH_MIN, TH_MAX)
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


# -- function by function --------------------------------------------------------------------------------------
@pytest.mark.parametrize("i", [0, 1, 2])
def test_chain_local_and_jx_row(i):
    a = RNG.normal(size=(50, 3))
    cl = np.asarray(jax.jit(jax.vmap(lambda p: jnp.stack(chain_local(*p, i))))(a))  # the JAX twins, one call each
    jr = np.asarray(jax.jit(jax.vmap(lambda p: jnp.stack(jx_row(*p, i))))(a))
    for (px, py, pz), cl_k, jr_k in zip(a, cl, jr):
        np.testing.assert_allclose(nbk.chain_local(px, py, pz, i), cl_k, rtol=1e-15, atol=1e-16)
        np.testing.assert_allclose(nbk.jx_row(px, py, pz, i), jr_k, rtol=1e-15, atol=1e-16)
    # the reference's rotation (independent: a (n, 3) form)
    x, y, z = ref.chain_local(a)
    for k, (px, py, pz) in enumerate(a):
        np.testing.assert_allclose(nbk.chain_local(px, py, pz, i), (x[k, i], y[k, i], z[k, i]), rtol=1e-14,
                                   atol=1e-15)


def test_loop_closure_and_loop_vectors():
    n = 400
    dx = RNG.uniform(-0.8, 0.8, n)
    py = RNG.uniform(-0.5, 0.5, n)
    pz = RNG.uniform(-0.1, 0.8, n)
    dx[:3], py[:3], pz[:3] = (np.inf, np.nan, 1e300), (0.0, 0.0, 0.0), (0.3, 0.3, 0.3)  # guarded inputs
    jl = jax.jit(jax.vmap(lambda a, b, c: loop_closure(a, b, c, L1, L2, LIM_JAX)))(dx, py, pz)
    rc, rs, _, rreach, rok = ref.loop_closure(dx, py, pz, L1, L2, TH_MIN, TH_MAX)
    for k in range(n):
        c, s, disc, reach, margin, ok, sdx, spy, spz = nbk.loop_closure(dx[k], py[k], pz[k], L1, L2, LIM_NB)
        if k < 3:
            # non-finite / huge inputs: the Numba loop boxes them itself and fails the chain; the JAX core takes
            # only finite, bounded inputs (safe_point guards the point before loop_closure, tested in test_kernel)
            assert not reach and not ok
            continue
        assert reach == bool(jl.reach[k]) == bool(rreach[k])
        assert ok == bool(jl.ok[k]) == bool(rok[k])
        if not reach:  # cos/sin/margin of an unreachable chain are finite placeholders (masked), not values
            continue
        np.testing.assert_allclose([c, s, margin], [float(jl.cos[k]), float(jl.sin[k]), float(jl.margin[k])],
                                   rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(disc, float(jl.disc[k]), rtol=1e-13, atol=1e-14)
        if reach:
            np.testing.assert_allclose([c, s], [rc[k], rs[k]], rtol=1e-12, atol=1e-13)
        u = nbk.loop_vectors(sdx, spy, spz, c, s, L1, L2)
        np.testing.assert_allclose(u, [float(v) for v in loop_vectors(sdx, spy, spz, c, s, L1, L2)], rtol=1e-15,
                                   atol=1e-16)
        if reach:
            np.testing.assert_allclose(u, [float(v) for v in ref.loop_vectors(dx[k], py[k], pz[k], c, s, L1, L2)],
                                       rtol=1e-14, atol=1e-15)
            assert abs(math.fsum(v * v for v in u) - 1.0) < 1e-13  # unit forearm vector


def test_jq_theta_and_jx_det():
    rows = RNG.normal(size=(100, 13))
    jq = np.asarray(jax.jit(jax.vmap(lambda a: jq_theta(*a)))(rows[:, :4]))  # the JAX twins, one call each
    det = np.asarray(jax.jit(jax.vmap(lambda a: jx_det(*a)))(rows[:, 4:]))
    for row, jq_k, det_k in zip(rows, jq, det):
        ux, uz, c, s = row[:4]
        assert nbk.jq_theta(ux, uz, c, s) == pytest.approx(float(jq_k), rel=1e-15, abs=1e-16)
        j = row[4:]
        assert nbk.jx_det(*j) == pytest.approx(float(det_k), rel=1e-13, abs=1e-15)
        assert nbk.jx_det(*j) == pytest.approx(np.linalg.det(j.reshape(3, 3)), rel=1e-12, abs=1e-14)


@pytest.mark.parametrize("method,code", METHODS)
@pytest.mark.slow
def test_sym3_top2(method, code):
    # random positive semi-definite matrices (what the kernel feeds it), some with a repeated eigenvalue
    mats = []
    for k in range(120):
        Q, _ = np.linalg.qr(RNG.normal(size=(3, 3)))
        lam = RNG.uniform(0.01, 3.0, 3)
        if k % 4 == 0:
            lam[1] = lam[0]
        mats.append(Q @ np.diag(lam) @ Q.T)
    args = np.array([(A[0, 0], A[1, 1], A[2, 2], A[0, 1], A[0, 2], A[1, 2],
                      A[1, 1] * A[2, 2] - A[1, 2] ** 2 + A[0, 0] * A[2, 2] - A[0, 2] ** 2 + A[0, 0] * A[1, 1]
                      - A[0, 1] ** 2, float(np.linalg.det(A))) for A in mats])
    # the JAX twin over all matrices in one compiled call (120 eager calls cost ~40 s of op-by-op dispatch)
    jax_top2 = np.asarray(jax.jit(jax.vmap(lambda a: jnp.stack(sym3_top2(*a, method))))(args))
    for A, a, want in zip(mats, args, jax_top2):
        got = nbk.sym3_top2(*a, code)
        np.testing.assert_allclose(got, want, rtol=1e-12)
        ev = np.linalg.eigvalsh(A)[::-1]
        tol = 1e-12 if method == "jacobi" else 1e-7  # the cubic splits a repeated pair by ~sqrt(eps)
        np.testing.assert_allclose(got, ev[:2], rtol=tol)


def _jx_d(pts):
    """Jx rows (9) and d (3) of reachable points, from the reference's blocks."""
    x, y, z = ref.chain_local(pts)
    dx = x + r - R
    c, s, _, _, ok = ref.loop_closure(dx, y, z, L1, L2, TH_MIN, TH_MAX)
    ok = ok.all(axis=1)
    ux, uy, uz = ref.loop_vectors(dx, y, z, c, s, L1, L2)
    Jx, d = ref.jacobian_blocks(ux, uy, uz, c, s)
    return Jx[ok], d[ok]


@pytest.mark.parametrize("method,code", METHODS)
@pytest.mark.slow
def test_singular_values(method, code):
    Jx, d = _jx_d(_points(2000))
    sv_ref = ref.singular_values(Jx, d)
    fn = jax.jit(jax.vmap(lambda j, dd: jnp.stack(singular_values(tuple(j), tuple(dd), method=method))))
    sv_jax = np.asarray(fn(Jx.reshape(-1, 9), d))
    assert len(d) > 150
    for k in range(len(d)):
        got = nbk.singular_values(*Jx[k].reshape(-1), *d[k], code)
        np.testing.assert_allclose(got, sv_jax[k], rtol=1e-11)
        np.testing.assert_allclose(got, sv_ref[k], rtol=1e-9 if method == "jacobi" else 1e-7)


def test_indices_from_sv():
    for s in np.sort(RNG.uniform(0.05, 5.0, (100, 3)), axis=1)[:, ::-1]:
        got = nbk.indices_from_sv(s[0], s[1], s[2], L1 ** 3, KT)
        want = indices_from_sv(s[0], s[1], s[2], b_v=2.0, b_f=4.2, beta=0.5, raw_scale=L1 ** 3)
        np.testing.assert_allclose(got, [float(getattr(want, n)) for n in dj.INDEX_NAMES], rtol=1e-14)
        kt_ref = ref.k_tilde(s[2], 1.0 / s[0], 2.0, 4.2, 0.5)
        assert got[5] == pytest.approx(float(kt_ref), rel=1e-14, abs=1e-15)
    nan = nbk.indices_from_sv(math.nan, math.nan, math.nan, 1.0, KT)
    assert all(math.isnan(v) for v in nan)  # NaN in, NaN out (never a number)


# -- the whole kernel on one batch, all three backends ---------------------------------------------------------
@pytest.mark.parametrize("method,code", METHODS)
@pytest.mark.slow
def test_every_backend_agrees_on_point_kernel(method, code):
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
