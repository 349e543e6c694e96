"""Fast mode's screen-and-verify redundancy resolution: identical to the exact sweep, and the screen's error bound.

The screen (``numba_fields.screen_window``) approximates the criterion of every sample of a point's window by the
trigonometric eigenvalue formula (no Jacobi) and returns an interval that must contain the exact kernel's
value; the fast mode evaluates the exact kernel only where an interval reaches the largest lower end.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import deltajax as dj
from deltajax import workspace as ws
from deltajax.workspace import numba_fields
from deltajax.workspace.redundancy import nb_params

REC = dj.presets.franco2026()
Q = nb_params(REC)
G40 = ws.franco2026_grid(0.04)  # 21 x 21 x 15
C = numba_fields.CRITERION  # criterion codes by index name
KT = C["k_tilde"]


def _args():
    return Q["R_min"], Q["R_step"], Q["r"], Q["L1"], Q["L2"], Q["lim"]


def _audit(pts, crit=KT, beta=0.5):
    pts = np.ascontiguousarray(pts, dtype=np.float64)
    k_lo, k_stop = ws.reach_k_range_host(REC, pts)
    out = np.empty((len(pts), 4))
    numba_fields.screen_audit(pts, k_lo, k_stop, *_args(), numba_fields.kt_tuple(2.0, 4.2, beta), crit, out)
    return out


@pytest.fixture(scope="module")
def grid_points():
    fixed = ws.fixed_workspace(dj.presets.franco2026(fixed_R=0.2), G40, fields=False)
    return G40.points()[fixed.ok.reshape(-1)]


# -- identity of the selection ---------------------------------------------------------------------------
@pytest.mark.parametrize("criterion,beta", [("k_tilde", 0.25), ("k_tilde", 0.5), ("k_tilde", 0.75),
                                            ("inv_cond", 0.5), ("sigma_min_f", 0.5), ("omega_f", 0.5)])
def test_screened_fast_equals_exact_bitwise(criterion, beta):
    pts = G40.points()  # whole box: reachable and unreachable points, the z axis (x = y = 0) included
    fast, wf = ws.resolve_redundancy_host(REC, pts, criterion, mode="fast", beta=beta)
    exact, we = ws.resolve_redundancy_host(REC, pts, criterion, mode="exact", beta=beta)
    np.testing.assert_array_equal(fast.k, exact.k)
    np.testing.assert_array_equal(fast.value, exact.value)  # NaN where none, bit-identical elsewhere
    np.testing.assert_array_equal(fast.indices, exact.indices)
    assert 2000 < fast.ok.sum() < len(pts)
    # the screen does the work: about one exact kernel per solved point instead of ~166 per point
    assert wf["screened"] == wf["samples"] > 0 and wf["fallback"] == 0
    assert wf["full"] < 1.5 * wf["points"] and we["full"] > 50 * wf["full"]


def test_screen_off_and_margins_give_the_same_selection(grid_points):
    ref, _ = ws.resolve_redundancy_host(REC, grid_points, mode="fast", screen=False, return_indices=False)
    for m in (0.0, 1e-6, 0.05):
        red, w = ws.resolve_redundancy_host(REC, grid_points, mode="fast", screen_margin=m, return_indices=False)
        np.testing.assert_array_equal(red.k, ref.k)
        np.testing.assert_array_equal(red.value, ref.value)
        if m == 0.05:  # a wide margin only means more exact kernels
            assert w["full"] > 2 * w["points"]
    with pytest.raises(ValueError, match="screen_margin"):
        ws.resolve_redundancy_host(REC, grid_points[:3], screen_margin=-1.0)


def test_failed_bound_falls_back_to_the_exact_sweep(grid_points):
    # a negative margin makes every interval wrong (hi < lo): certification fails at every point with a
    # feasible sample, and the fallback sweep must still return the exact selection
    pts = grid_points[::7]
    k_lo, k_stop = ws.reach_k_range_host(REC, pts)
    n = len(pts)
    bk, bv, nf, fb = (np.empty(n, np.int64), np.empty(n), np.empty(n, np.int64), np.empty(n, np.int64))
    numba_fields.resolve_screened(pts, k_lo, k_stop, *_args(), numba_fields.kt_tuple(2.0, 4.2, 0.5), KT, -1.0, bk, bv, nf, fb)
    exact, _ = ws.resolve_redundancy_host(REC, pts, mode="exact", return_indices=False)
    np.testing.assert_array_equal(bk, exact.k)
    np.testing.assert_array_equal(bv[bk >= 0], exact.value[exact.ok])
    assert fb.sum() == exact.ok.sum() > 100


def test_ties_go_to_smallest_R_through_the_screen():
    # b_v tiny: k~ = 0 at every sample (every sample is a candidate), the first feasible sample wins
    pts = np.array([[0.0, 0.0, 0.3], [0.1, -0.05, 0.45], [-0.12, 0.2, 0.4]])
    red, w = ws.resolve_redundancy_host(REC, pts, mode="fast", b_v=1e-9, return_indices=False)
    ex, _ = ws.resolve_redundancy_host(REC, pts, mode="exact", b_v=1e-9, return_indices=False)
    np.testing.assert_array_equal(red.k, ex.k)
    assert np.all(red.value[red.ok] == 0.0) and red.ok.sum() == 3
    assert w["full"] > 30  # many candidates, all verified


# -- the screen's error bound ----------------------------------------------------------------------------
def test_tcubic_solves_the_cardano_cubic():
    w = np.concatenate([np.linspace(0.0, 4.0, 20001), 4.0 - np.logspace(-18, 0, 200), np.logspace(-20, 0, 200)])
    t = np.array([numba_fields._tcubic(v) for v in w])
    tl = np.sqrt(w.astype(np.longdouble) / 3)
    for _ in range(60):  # extended-precision Newton reference
        tl = tl - (tl * tl * (tl + 3) - w) / np.maximum(3 * tl * (tl + 2), 1e-300)
    assert float(np.max(np.abs(t - tl))) < 2e-15  # _T_NEWTON = 1e-14 is the bound used
    # the paired solver of the screen (one shared division), both roots t(w) and t(4 - w)
    t2 = np.array([numba_fields._tcubic2(v, 4.0 - v) for v in w])
    assert float(np.max(np.abs(t2[:, 0] - tl))) < 2e-15
    tl4 = np.sqrt((4.0 - w).astype(np.longdouble) / 3)
    for _ in range(60):
        tl4 = tl4 - (tl4 * tl4 * (tl4 + 3) - (4.0 - w)) / np.maximum(3 * tl4 * (tl4 + 2), 1e-300)
    assert float(np.max(np.abs(t2[:, 1] - tl4))) < 2e-15
    # c = (1 + t) / 2 is cos(acos(r) / 3), r = w / 2 - 1: the trigonometric Cardano formula
    mid = (w > 1e-6) & (w < 4 - 1e-6)
    np.testing.assert_allclose((1 + t[mid]) / 2, np.cos(np.arccos(w[mid] / 2 - 1) / 3), rtol=0, atol=1e-9)


@pytest.mark.parametrize("crit,beta", [(KT, 0.25), (KT, 0.5), (KT, 0.75), (C["inv_cond"], 0.5), (C["sigma_min_f"], 0.5),
                                       (C["omega_v"], 0.5), (C["omega_f"], 0.5)])
def test_screen_bound_contains_exact_values_on_grid(grid_points, crit, beta):
    out = _audit(grid_points, crit, beta)
    assert out[:, 2].sum() == 0  # same feasibility decisions, every exact value inside its interval
    assert out[:, 3].sum() > 200_000  # feasible samples checked
    assert out[:, 1].max() < 0.1  # the bound is at least 10x larger than the observed error
    if crit == KT:
        assert out[:, 0].max() < 1e-7 < _nb_margin()  # max |k~ error| << the default margin


def _nb_margin():
    from deltajax.workspace.redundancy import SCREEN_MARGIN
    return SCREEN_MARGIN


def test_screen_bound_on_the_axis():
    # x = y = 0: two singular values coincide (3-fold symmetry), the trigonometric formula's worst case
    zs = np.linspace(0.06, 0.58, 40)
    pts = np.concatenate([np.stack([0 * zs, 0 * zs, zs], -1), np.stack([0 * zs + 1e-9, 0 * zs + 1e-9, zs], -1),
                          np.stack([0 * zs + 1e-4, 0 * zs, zs], -1)])
    for crit in (KT, C["inv_cond"], C["sigma_min_f"]):
        out = _audit(pts, crit)
        assert out[:, 2].sum() == 0 and out[:, 3].sum() > 5000
        assert out[:, 1].max() < 0.1
        assert out[:, 0].max() < 5e-7  # observed ~5e-8: sqrt(eps)-type loss, still inside the bound


@settings(max_examples=25, deadline=None)
@given(st.floats(-0.35, 0.35), st.floats(-0.35, 0.35), st.floats(0.02, 0.6), st.sampled_from([0.25, 0.5, 0.75]))
def test_screen_bound_random_points(x, y, z, beta):
    out = _audit(np.array([[x, y, z]]), KT, beta)
    assert out[0, 2] == 0
    assert out[0, 1] < 0.1 and out[0, 0] < 5e-7  # ~1e-7 on the axis (x = y = 0), ~1e-8 elsewhere
    # and the selection through the screen is the exact one
    p = np.array([[x, y, z]])
    a, _ = ws.resolve_redundancy_host(REC, p, mode="fast", beta=beta, return_indices=False)
    b, _ = ws.resolve_redundancy_host(REC, p, mode="exact", beta=beta, return_indices=False)
    assert a.k[0] == b.k[0] and (a.value[0] == b.value[0] or (math.isnan(a.value[0]) and math.isnan(b.value[0])))
