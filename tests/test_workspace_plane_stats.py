"""workspace_grid's per-plane statistics: the one-pass kernel equals the NumPy form it
replaced, bit for bit (sums in the same order), for float64 and float32, with NaN, +-inf and empty planes."""

import numpy as np
import pytest

from deltajax.workspace.chunks import plane_statistics


def numpy_form(ok, values):
    """The NumPy formulation used until stop 20 (the reference)."""
    finite = ok[..., None] & np.isfinite(values)
    return {
        "plane_count": ok.sum(axis=1, dtype=np.int64),
        "plane_n": finite.sum(axis=1, dtype=np.int64),
        "plane_sum": np.where(finite, values, 0.0).sum(axis=1),
        "plane_min": np.where(finite, values, np.inf).min(axis=1),
        "plane_max": np.where(finite, values, -np.inf).max(axis=1),
    }


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_plane_statistics_equal_the_numpy_form_bit_for_bit(dtype):
    rng = np.random.default_rng(1)
    k, m, c = 5, 3001, 8
    vals = (rng.lognormal(0.0, 4.0, (k, m, c)) * rng.choice([-1.0, 1.0], (k, m, c))).astype(dtype)
    ok = rng.random((k, m)) < 0.3
    ok[3] = False  # a plane with no reachable point: count 0, min +inf, max -inf, sum 0
    vals[~ok] = np.nan  # NaN outside the workspace, as the kernels write it
    vals[rng.random((k, m, c)) < 0.01] = np.inf
    vals[rng.random((k, m, c)) < 0.01] = -np.inf
    vals[rng.random((k, m, c)) < 0.01] = np.nan  # non-finite where ok too: left out of n, sum, min, max
    got, ref = plane_statistics(ok, vals), numpy_form(ok, vals)
    assert set(got) == set(ref)
    for key in ref:
        assert got[key].dtype == ref[key].dtype and got[key].shape == ref[key].shape, key
        assert np.array_equal(got[key].view(np.uint8), ref[key].view(np.uint8)), key
    assert got["plane_count"][3] == 0 and np.all(got["plane_min"][3] == np.inf)


def test_plane_statistics_refuses_mismatched_shapes():
    with pytest.raises(ValueError, match="ok has shape"):
        plane_statistics(np.ones((2, 3), bool), np.zeros((2, 4, 8)))
