"""Workspace engine: grids, volumes, index fields, redundancy resolution (exact == fast), checkpoint/resume."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import deltajax as dj
from deltajax import workspace as ws
from deltajax.workspace import numba_fields

REC = dj.presets.franco2026()
FIXED = dj.presets.franco2026(fixed_R=0.2)
G20 = ws.franco2026_grid(0.02)  # 41 x 41 x 30


@pytest.fixture(scope="module")
def fixed20():
    return ws.fixed_workspace(FIXED, G20, chunk_size=7000)


# -- grid ----------------------------------------------------------------------------------------------------
def test_paper_grid_shape_and_axes():
    g = ws.franco2026_grid(0.002)
    assert g.shape == (401, 401, 300) and g.n_points == 48_240_300
    assert g.x[0] == -0.4 and g.x[-1] == 0.4 and g.z[0] == 0.0 and g.z[-1] == pytest.approx(0.598, abs=1e-15)
    assert np.all(g.x[1:] > g.x[:-1])
    assert g.mirror_symmetric  # built from integer indices: bit-exact y -> -y
    assert g.box_volume == pytest.approx(0.384)
    i = np.arange(401)
    np.testing.assert_allclose(g.x, -0.4 + 0.002 * i, rtol=0, atol=1e-15)


def test_grid_points_order_and_mirror_index():
    g = ws.make_grid((-0.1, 0.1), (-0.1, 0.1), (0.2, 0.3), 0.05)
    assert g.shape == (5, 5, 3)
    p = g.points()
    assert np.array_equal(p[7], [g.x[0], g.y[2], g.z[1]])
    m = g.mirror_index(np.arange(g.n_points))
    np.testing.assert_array_equal(p[m], p * np.array([1.0, -1.0, 1.0]))


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 5 * 3 * 4 - 1), st.integers(1, 60))
def test_chunk_points_are_the_grid_points_in_order(start, length):
    # the chunk engine's coordinates (numba_fields.grid_points: indices counted, not divided) against the grid's
    # own points, on the whole grid and on its mirror half (y >= 0), across row and plane boundaries
    g = ws.make_grid((-0.1, 0.1), (-0.1, 0.1), (0.2, 0.35), 0.05)  # 5 x 5 x 4
    full = g.points().reshape(g.shape + (3,))
    for j0 in (0, 2):
        half = full[:, j0:, :].reshape(-1, 3)
        n = min(length, half.shape[0] - start) if start < half.shape[0] else 0
        x, y, z = (np.full(n, np.nan) for _ in range(3))
        numba_fields.grid_points(g.x, g.y, g.z, j0, 5 - j0, start, x, y, z)
        np.testing.assert_array_equal(np.stack([x, y, z], -1), half[start:start + n])


def test_grid_rejects_bad_ranges():
    with pytest.raises(ValueError, match="whole number"):
        ws.make_grid((0, 0.105), (0, 0.1), (0, 0.1), 0.01)
    with pytest.raises(ValueError, match="h must be > 0"):
        ws.make_grid((0, 0.1), (0, 0.1), (0, 0.1), 0.0)
    with pytest.raises(ValueError, match="empty"):
        ws.make_grid((0.1, 0.0), (0, 0.1), (0, 0.1), 0.01)


# -- volumes -------------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_fixed_and_reconfigurable_volume_match_jax(fixed20):
    pts = G20.points()
    m_jax = np.asarray(ws.reachable_mask(FIXED, pts)).reshape(G20.shape)
    np.testing.assert_array_equal(fixed20.ok, m_jax)
    rec = ws.reconfigurable_workspace(REC, G20, chunk_size=9000)
    r_jax = np.asarray(ws.reconfigurable_reachable(REC, pts)).reshape(G20.shape)
    np.testing.assert_array_equal(rec.ok, r_jax)
    assert not np.any(fixed20.ok & ~rec.ok)  # R = 0.200 is one of the samples
    c_f, c_r = int(fixed20.ok.sum()), int(rec.ok.sum())
    assert G20.volume_box(c_f) == pytest.approx(c_f / G20.n_points * 0.384)
    assert G20.volume_count(c_f) == pytest.approx(c_f * 0.02 ** 3)
    # paper: 0.075 and 0.137 m^3 (+82 %) at 2 mm; a 20 mm grid is within 1 %
    paper = dj.papers.FRANCO2026_VOLUMES
    assert G20.volume_box(c_f) == pytest.approx(paper["volume_fixed"], rel=0.01)
    assert G20.volume_box(c_r) == pytest.approx(paper["volume_reconfigurable"], rel=0.01)
    frac = float(ws.reachable_fraction(FIXED, pts))
    assert frac == pytest.approx(c_f / G20.n_points)


def test_fields_nan_outside_and_mirror_symmetric(fixed20):
    for n in ws.FIELD_NAMES:
        f = fixed20.fields[n]
        assert np.all(np.isnan(f[~fixed20.ok]))
        assert np.all(np.isfinite(f[fixed20.ok]) | (n in ("omega_f", "imi")))
        np.testing.assert_array_equal(f, f[:, ::-1, :])  # bit-for-bit mirror image


@pytest.mark.slow
def test_numba_and_jax_kernels_agree_with_core_indices(fixed20):
    idx = np.flatnonzero(fixed20.ok.reshape(-1))[::40]
    pts = G20.points_at(idx)
    theta = jax.vmap(lambda p: dj.ik(FIXED, p).theta)(pts)
    ref = jax.vmap(lambda p, t: dj.indices(FIXED, p, t))(pts, theta)
    ok, fields = ws.index_fields(FIXED, pts)
    assert np.all(np.asarray(ok))
    for n in ws.FIELD_NAMES:
        r = np.asarray(getattr(ref, n))
        np.testing.assert_allclose(fixed20.fields[n].reshape(-1)[idx], r, rtol=1e-10)
        np.testing.assert_allclose(np.asarray(fields[n]), r, rtol=1e-10)


# -- redundancy resolution -----------------------------------------------------------------------------------
@pytest.mark.parametrize("criterion,beta", [("k_tilde", 0.5), ("k_tilde", 0.25), ("omega_v", 0.5)])
def test_fast_equals_exact_on_coarse_grid(criterion, beta):
    g = ws.franco2026_grid(0.04)
    pts = g.points()
    fast, wf = ws.resolve_redundancy_host(REC, pts, criterion, mode="fast", beta=beta)
    exact, we = ws.resolve_redundancy_host(REC, pts, criterion, mode="exact", beta=beta)
    np.testing.assert_array_equal(fast.k, exact.k)
    np.testing.assert_array_equal(fast.value, exact.value)
    np.testing.assert_array_equal(fast.indices, exact.indices)
    assert fast.ok.sum() > 1000 and wf["samples"] < we["samples"] / 2  # the fast mode does less work
    col = dj.INDEX_NAMES.index(criterion)
    np.testing.assert_array_equal(fast.indices[fast.ok, col], fast.value[fast.ok])


@pytest.mark.slow
def test_grid_jobs_fast_equal_exact(fixed20):
    a = ws.redundancy_grid(REC, G20, mask=fixed20.ok, mode="fast", chunk_size=5000)
    b = ws.redundancy_grid(REC, G20, mask=fixed20.ok, mode="exact", chunk_size=9000)
    for n in a.fields:
        np.testing.assert_array_equal(a.fields[n], b.fields[n])
    np.testing.assert_array_equal(a.ok, fixed20.ok)  # R = 0.200 reaches every ODR point
    st = ws.index_stats(a.fields, fixed20.ok)
    # Table 6 means (beta 0.5) are reproduced to ~1e-3 even on this 20 mm grid
    table6 = dj.papers.FRANCO2026_INDEX_STATS[0.5]["RDR"]
    assert st["inv_cond"]["mean"] == pytest.approx(table6["inv_cond"][2], abs=3e-3)
    assert st["omega_v"]["mean"] == pytest.approx(table6["omega_v"][2], abs=5e-3)
    assert st["sigma_min_v"]["mean"] == pytest.approx(table6["sigma_min_v"][2], abs=3e-3)


@pytest.mark.slow
def test_jax_exact_equals_host_and_is_jittable():
    rng = np.random.default_rng(1)
    pts = np.stack([rng.uniform(-0.35, 0.35, 300), rng.uniform(-0.35, 0.35, 300), rng.uniform(0.05, 0.58, 300)], -1)
    host, _ = ws.resolve_redundancy_host(REC, pts, mode="fast")
    fn = jax.jit(lambda r, p: ws.resolve_redundancy(r, p, "k_tilde"))
    red = fn(REC, pts)
    np.testing.assert_array_equal(np.asarray(red.k), host.k)
    assert host.ok.sum() > 50 and (~host.ok).sum() > 10
    np.testing.assert_allclose(np.asarray(red.value), host.value, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(red.R), host.R, rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.asarray(red.indices.omega_v), host.indices[:, 3], rtol=1e-10)
    assert np.all(np.isnan(np.asarray(red.indices.k_tilde)[~host.ok]))
    # R* is a feasible sample and its criterion value is the best over all samples (brute force)
    k = int(np.flatnonzero(host.ok)[0])
    # every sample in one compiled call (an eager loop over every 7th sample cost ~40 CPU-s)
    vals = np.asarray(jax.jit(jax.vmap(lambda j: ws.sample_value(REC, pts[k], j)[1]))(jnp.arange(REC.n_R)))
    assert host.value[k] >= vals.max() - 1e-15
    assert vals[host.k[k]] == pytest.approx(host.value[k], rel=1e-12)  # ... and R* attains it


def test_ties_go_to_smallest_R():
    # b_v tiny: sigma~_v = 0 for every sample, so k~ = 0 everywhere and the first feasible sample wins
    pts = np.array([[0.0, 0.0, 0.3], [0.1, -0.05, 0.45], [0.0, 0.0, 0.05]])
    red, _ = ws.resolve_redundancy_host(REC, pts, mode="fast", b_v=1e-9)
    lim = numba_fields.limits_tuple(float(REC.robot.theta_min), float(REC.robot.theta_max))
    for i, p in enumerate(pts):
        first = next((k for k in range(REC.n_R)
                      if numba_fields._ik_ok(p[0], abs(p[1]), p[2], 0.138 + 0.001 * k, 0.065, 0.2, 0.4, lim)), -1)
        assert red.k[i] == first
        if first >= 0:
            assert red.value[i] == 0.0


@settings(max_examples=20)
@given(st.floats(-0.45, 0.45), st.floats(-0.45, 0.45), st.floats(0.0, 0.62))
def test_reach_range_contains_every_feasible_sample(x, y, z):
    lo, stop = ws.reach_k_range_host(REC, np.array([[x, y, z]]))
    lim = numba_fields.limits_tuple(-math.inf, math.inf)  # unlimited joints: the widest feasible set
    feas = [k for k in range(REC.n_R) if numba_fields._ik_ok(x, abs(y), z, 0.138 + 0.001 * k, 0.065, 0.2, 0.4, lim)]
    assert all(lo[0] <= k < stop[0] for k in feas)


# -- checkpoint / resume -------------------------------------------------------------------------------------
def test_killed_run_resumes_bit_for_bit(tmp_path, fixed20):
    ref = ws.redundancy_grid(REC, G20, mask=fixed20.ok, chunk_size=2000)
    part = ws.redundancy_grid(REC, G20, mask=fixed20.ok, chunk_size=2000, checkpoint_dir=tmp_path / "ck", max_chunks=3)
    assert not part.complete
    assert np.isnan(part.fields["R_star"]).sum() > np.isnan(ref.fields["R_star"]).sum()
    seen = []
    done = ws.redundancy_grid(REC, G20, mask=fixed20.ok, chunk_size=2000, checkpoint_dir=tmp_path / "ck",
                              progress=seen.append)
    assert done.complete and seen[0] == 3 * 2000  # resumed after the 3 finished chunks
    for n in ref.fields:
        np.testing.assert_array_equal(done.fields[n], ref.fields[n])
    with pytest.raises(ws.CheckpointMismatch):
        ws.redundancy_grid(REC, G20, mask=fixed20.ok, chunk_size=2000, beta=0.25, checkpoint_dir=tmp_path / "ck")
    f1 = ws.fixed_workspace(FIXED, G20, chunk_size=4000, checkpoint_dir=tmp_path / "f", max_chunks=1)
    f2 = ws.fixed_workspace(FIXED, G20, chunk_size=4000, checkpoint_dir=tmp_path / "f")
    assert not f1.complete and f2.complete
    np.testing.assert_array_equal(f2.ok, fixed20.ok)
    np.testing.assert_array_equal(f2.fields["k_tilde"], fixed20.fields["k_tilde"])


# -- statistics ----------------------------------------------------------------------------------------------
def test_index_stats():
    f = {"a": np.array([1.0, 2.0, np.nan, 4.0, 10.0])}
    m = np.array([True, True, True, True, False])
    s = ws.index_stats(f, m, names=["a"], chunk=2)
    assert s["a"] == {"min": 1.0, "max": 4.0, "mean": 7.0 / 3.0, "count": 3}
