"""Memory options of the grid drivers: only the kept fields are stored, statistics accumulate
chunk by chunk (full-grid weights on the mirror half) and survive a kill + resume through the checkpoint."""

import numpy as np
import pytest

import deltajax as dj
from deltajax import workspace as ws

REC = dj.presets.franco2026()
FIXED = dj.presets.franco2026(fixed_R=0.2)
G = ws.franco2026_grid(0.04)  # 21 x 21 x 15: odd ny, the mirror plane y = 0 is a grid row


def _assert_stats_equal(a, b):
    for n in dj.INDEX_NAMES:
        assert a[n]["count"] == b[n]["count"]
        for k in ("min", "max", "mean"):
            assert a[n][k] == pytest.approx(b[n][k], rel=1e-13), (n, k)


@pytest.fixture(scope="module")
def full_fixed():
    return ws.fixed_workspace(FIXED, G, field_dtype=np.float32)


def test_fixed_keep_and_streamed_stats(full_fixed):
    job = ws.fixed_workspace(FIXED, G, field_dtype=np.float32, keep=["k_tilde"], stats=True, chunk_size=1000)
    assert set(job.fields) == {"k_tilde"}
    np.testing.assert_array_equal(job.fields["k_tilde"], full_fixed.fields["k_tilde"])
    np.testing.assert_array_equal(job.ok, full_fixed.ok)
    _assert_stats_equal(job.stats, ws.index_stats(full_fixed.fields, full_fixed.ok))
    assert full_fixed.stats is None  # only when asked for
    with pytest.raises(ValueError, match="keep"):
        ws.fixed_workspace(FIXED, G, keep=["volume"])


def test_redundancy_keep_stats_and_resume(tmp_path, full_fixed):
    kw = dict(mask=full_fixed.ok, field_dtype=np.float32, chunk_size=700)
    ref = ws.redundancy_grid(REC, G, **kw)
    ck = tmp_path / "ck"
    part = ws.redundancy_grid(REC, G, **kw, keep=["R_star", "k_tilde"], stats=True, R_dtype=np.float32,
                              checkpoint_dir=ck, max_chunks=2)
    assert not part.complete and part.stats is None
    done = ws.redundancy_grid(REC, G, **kw, keep=["R_star", "k_tilde"], stats=True, R_dtype=np.float32,
                              checkpoint_dir=ck)
    assert done.complete and set(done.fields) == {"R_star", "k_tilde"}
    assert done.fields["R_star"].dtype == np.float32
    np.testing.assert_array_equal(done.fields["R_star"], ref.fields["R_star"].astype(np.float32))
    np.testing.assert_array_equal(done.fields["k_tilde"], ref.fields["k_tilde"])
    _assert_stats_equal(done.stats, ws.index_stats(ref.fields, full_fixed.ok))
    # a checkpoint whose statistics of finished chunks are lost is refused, not silently averaged over less
    parts = np.load(ck / "stats_partials.npy", mmap_mode="r+")
    parts[0] = np.nan
    parts.flush()
    del parts
    with pytest.raises(ws.CheckpointMismatch, match="statistics"):
        ws.redundancy_grid(REC, G, **kw, keep=["R_star", "k_tilde"], stats=True, R_dtype=np.float32,
                           checkpoint_dir=ck)
