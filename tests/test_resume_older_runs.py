"""A run directory staged by an older deltajax (its finished screen stage has no screen/front_genes, which now seeds
NSGA-II) is refused with one line on resume, never resumed with a made-up seeding or crashed with a KeyError."""

import json
import shutil

import h5py
import pytest

from deltajax.rundir import MANIFEST, CheckpointError
from deltajax.run import run_experiment

from toy_jobs import overrides

TOY = overrides("ga_reconfig")


@pytest.mark.slow
def test_resume_without_screen_front_is_refused(toy_run, tmp_path):
    done = toy_run("ga_reconfig")
    old = tmp_path / "old"
    shutil.copytree(done.parent, old)
    with h5py.File(old / "results.h5", "r+") as f:
        f.attrs["ga_reconfig_stages"] = "screen"  # killed after the screen stage ...
        del f["screen/front_genes"]  # ... by a version that did not store the NSGA-II seeds
        for g in [k for k in f if k not in ("screen",) and isinstance(f[k], h5py.Group)
                  and k in ("ga", "pareto", "refine", "verify", "summary")]:
            del f[g]
    m = json.loads((old / MANIFEST).read_text())
    m["status"] = "running"  # the run was killed, not finished
    (old / MANIFEST).write_text(json.dumps(m))
    with pytest.raises(CheckpointError, match="screen/front_genes"):
        run_experiment("ga_reconfig", TOY, run_dir=old)
