"""Work counters of resumed grid jobs: the whole run's work (every finished chunk, those of the processes before a
resume included), stored in the checkpoint and the same numbers as an uninterrupted run's."""

import h5py
import numpy as np
import pytest

import deltajax as dj
from deltajax import workspace as ws
from deltajax.run import run_experiment

REC = dj.presets.franco2026()
G = ws.franco2026_grid(0.1)  # 9 x 9 x 6, the mirror half (270 points) solved in fast mode: 6 chunks
KW = dict(field_dtype=np.float32, chunk_size=50, keep=["R_star"])


def test_redundancy_work_counters_summed_over_resumes(tmp_path):
    ref: dict = {}
    ws.redundancy_grid(REC, G, **KW, work=ref)
    assert ref["samples"] > 0
    ck = tmp_path / "ck"
    for _ in range(2):  # two processes stopped after two chunks each, then the last one finishes
        part: dict = {}
        job = ws.redundancy_grid(REC, G, **KW, work=part, checkpoint_dir=ck, max_chunks=2)
        assert not job.complete
    assert 0 < part["samples"] < ref["samples"]  # the work of the four chunks finished so far
    done: dict = {}
    job = ws.redundancy_grid(REC, G, **KW, work=done, checkpoint_dir=ck)
    assert job.complete and done == ref


def test_redundancy_counters_missing_from_a_checkpoint_are_refused(tmp_path):
    ck = tmp_path / "ck"
    ws.redundancy_grid(REC, G, **KW, checkpoint_dir=ck, max_chunks=2)
    (ck / "work_partials.npy").unlink()  # as written by a version without counters in the checkpoint
    seen = []
    with pytest.raises(ws.CheckpointMismatch, match="work counters of chunks \\[0, 1\\] are missing"):
        ws.redundancy_grid(REC, G, **KW, work={}, checkpoint_dir=ck, progress=seen.append)
    assert seen == []  # refused at the start of the resume, before any chunk is computed


WG = ["plots=false", "progress=false", "experiment.grid.h=0.1", "experiment.grid.z=[0.0,0.6]",
      "experiment.chunk_points=63", "experiment.checkpoint_s=0"]


@pytest.mark.slow
def test_workspace_grid_points_evaluated_over_resumes(tmp_path):
    run_experiment("workspace_grid", [*WG, "experiment.stop_after=4"], run_dir=tmp_path)
    path = run_experiment("workspace_grid", WG, run_dir=tmp_path)
    with h5py.File(path, "r") as f:
        assert f.attrs["points_evaluated"] == 9 * 9 * 7  # as an uninterrupted run
        assert f.attrs["points_evaluated_this_process"] == 5 * 9 * 7
