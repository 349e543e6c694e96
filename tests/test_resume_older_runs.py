"""A run directory staged by an older deltajax (its finished screen stage has no screen/front_genes, which now seeds
NSGA-II) is refused with one line on resume, never resumed with a made-up seeding or crashed with a KeyError."""

import json
import shutil

import pytest

from deltajax.io import ResultsFile, read
from deltajax.rundir import MANIFEST, CheckpointError
from deltajax.run import run_experiment

from toy_jobs import overrides

TOY = overrides("ga_reconfig")


@pytest.mark.slow
def test_resume_without_screen_front_is_refused(toy_run, tmp_path):
    done = toy_run("ga_reconfig")
    old = tmp_path / "old"
    shutil.copytree(done.parent, old)
    # killed after the screen stage by a version that did not store the NSGA-II seeds (screen/front_genes); written
    # through ResultsFile, as a run writes it (an edited file is refused before the job reads it)
    stored = read(done, verify=True)
    res = ResultsFile(old / "results.h5")
    res.attrs.update({k: v for k, v in stored.attrs.items() if k != "start_time"}, ga_reconfig_stages="screen")
    for group, variables in stored.variables.items():
        if group.split("/")[0] not in ("", "ga", "pareto", "refine", "verify", "summary"):
            res.set_attrs(group, **stored.group_attrs[group])
            res.put_variables(group, {k: v for k, v in variables.items()
                                      if k not in ("front_genes", "front_design")})
    res.flush()
    m = json.loads((old / MANIFEST).read_text())
    m["status"] = "running"  # the run was killed, not finished
    (old / MANIFEST).write_text(json.dumps(m))
    with pytest.raises(CheckpointError, match="screen/front_genes"):
        run_experiment("ga_reconfig", TOY, run_dir=old)
