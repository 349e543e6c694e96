"""Numba side of the Table-6 job: the faster host paths give bitwise the results of the plain ones.

* ``numba_fields.fixed_fields`` (IK pass, reachable points gathered, kernel, scatter) equals ``numba_fields.fixed_fields_dense``
  (the kernel on every point) bitwise, both singular-value methods;
* the vectorised window trimming of the screen (``numba_screen.trim_window``) equals the scalar first/last
  feasible sample search;
* the fast (screened) redundancy resolution equals the exact sweep on random points, edges included;
* end to end: ``reconfig_indices`` at toy size in fast mode and in exact mode store the same selection and
  fields, as judged by ``experiments/check_reconfig_indices.py`` (which also detects a one-ulp change).
"""

import shutil
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

import deltajax as dj
from deltajax import workspace as ws
from deltajax.workspace import numba_fields, numba_screen
from deltajax.workspace.redundancy import nb_params

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
from check_reconfig_indices import compare  # noqa: E402

REC = dj.presets.franco2026()
Q = nb_params(REC)
KT = numba_fields.kt_tuple(2.0, 4.2, 0.5)


@pytest.mark.parametrize("method", [numba_fields.JACOBI, numba_fields.FAST])
def test_compacted_fields_equal_dense(method):
    g = ws.franco2026_grid(0.02)
    p = g.points().reshape(-1, 3)
    x, y, z = (np.ascontiguousarray(p[:, i]) for i in range(3))
    n = len(x)
    out_c, out_d = np.empty((8, n)), np.empty((8, n))
    ok_c, ok_d = np.empty(n, bool), np.empty(n, bool)
    args = (float(REC.robot.base_radius), Q["r"], Q["L1"], Q["L2"], Q["lim"], KT)
    numba_fields.fixed_fields(x, y, z, *args, numba_fields.rows(out_c), ok_c, method)
    numba_fields.fixed_fields_dense(x, y, z, *args, numba_fields.rows(out_d), ok_d, method)
    assert 0 < ok_c.sum() < n
    np.testing.assert_array_equal(ok_c, ok_d)
    np.testing.assert_array_equal(out_c, out_d)  # NaN where NaN, every bit of the rest


def test_trim_window_equals_scalar_search():
    rng = np.random.default_rng(3)
    pts = np.stack([rng.uniform(-0.45, 0.45, 3000), np.abs(rng.uniform(-0.45, 0.45, 3000)),
                    rng.uniform(0.0, 0.62, 3000)], -1)
    k_lo, k_stop = ws.reach_k_range_host(REC, pts)
    tb = np.empty(numba_screen.TRIM_BLOCK, np.uint8)
    a = (Q["R_min"], Q["R_step"], Q["r"], Q["L1"], Q["L2"], Q["lim"])
    hit = 0
    for j in range(len(pts)):
        x, y, z = pts[j]
        k0, k1 = int(k_lo[j]), int(k_stop[j])
        while k0 < k1 and not numba_fields.ik_ok(x, y, z, a[0] + k0 * a[1], *a[2:]):
            k0 += 1
        while k1 > k0 and not numba_fields.ik_ok(x, y, z, a[0] + (k1 - 1) * a[1], *a[2:]):
            k1 -= 1
        got = numba_screen.trim_window.py_func(x, y, z, int(k_lo[j]), int(k_stop[j]), *a, tb)
        assert got == (k0, k1), j
        hit += k1 > k0
    assert 300 < hit < 3000  # reachable and unreachable points both covered


def test_screened_equals_exact_on_random_points():
    rng = np.random.default_rng(4)
    pts = np.stack([rng.uniform(-0.4, 0.4, 4000), rng.uniform(-0.4, 0.4, 4000), rng.uniform(0.0, 0.6, 4000)], -1)
    fast, wf = ws.resolve_redundancy_host(REC, pts, "k_tilde", mode="fast")
    exact, _ = ws.resolve_redundancy_host(REC, pts, "k_tilde", mode="exact")
    np.testing.assert_array_equal(fast.k, exact.k)
    np.testing.assert_array_equal(fast.value, exact.value)
    np.testing.assert_array_equal(fast.indices, exact.indices)
    assert fast.ok.sum() > 500 and wf["fallback"] == 0


@pytest.mark.slow
def test_toy_job_fast_equals_exact_and_checker_detects_changes(toy_run, tmp_path):
    from deltajax.run import run_experiment
    from toy_jobs import overrides

    fast = toy_run("reconfig_indices")
    exact = run_experiment("reconfig_indices", overrides("reconfig_indices") + ["experiment.mode=exact"],
                           run_dir=tmp_path / "exact")
    assert compare(fast, fast) == []
    assert compare(fast, exact, ignore_attrs=("mode",)) == []
    assert any("mode" in d for d in compare(fast, exact))
    changed = tmp_path / "changed.h5"
    shutil.copy(fast, changed)
    with h5py.File(changed, "r+") as f:
        d = f["workspace/k_tilde_odr"]
        v = d[()]
        i = np.flatnonzero(np.isfinite(v.ravel()))[0]
        v.ravel()[i] = np.nextafter(v.ravel()[i], np.float32(np.inf))
        d[...] = v
    diffs = compare(fast, changed)
    assert len(diffs) == 1 and "k_tilde_odr: values differ at 1 of" in diffs[0]
    assert compare(fast, changed, rtol=1e-6) == []
