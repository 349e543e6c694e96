"""Refusals leave nothing behind: no directory for a refused run, a finished run's ``.hydra/`` untouched by a
rerun, no summary written into a run that is not a sweep, a sweep with one bad value refused in one line before
Hydra creates its folder."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from deltajax.run import CONFIG_DIR, execute

REPO = Path(__file__).resolve().parent.parent
ENV = {**os.environ, "PYTHONPATH": str(REPO)}


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "deltajax.run", *args], cwd=cwd, env=ENV, capture_output=True,
                          text=True, timeout=300)


@pytest.mark.slow
def test_rerun_of_a_finished_run_does_not_rewrite_its_hydra_files(toy_run):
    from hydra import compose, initialize_config_dir
    from toy_jobs import overrides

    path = toy_run("workspace_grid")
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(config_name="config", overrides=["experiment=workspace_grid", *overrides("workspace_grid")])
    calls = []  # the CLI writes .hydra/ in on_claimed
    assert execute(cfg, path.parent, on_claimed=lambda: calls.append(1)) == path
    assert calls == []


def test_merge_refuses_a_run_directory_and_writes_nothing(toy_run, tmp_path, capsys):
    from deltajax.merge import main

    run = toy_run("workspace_grid").parent
    before = sorted(p.name for p in run.iterdir())
    assert main([str(run)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "is a run directory" in err and "\n" not in err
    assert sorted(p.name for p in run.iterdir()) == before  # no summary.csv / summary.json
    assert main([str(tmp_path)]) == 2  # no runs at all
    assert "holds no runs of a sweep" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_sweep_jobs_expands_every_value():
    from deltajax.overrides import sweep_jobs

    jobs = sweep_jobs(["-m", "experiment=workspace_grid", "experiment.grid.h=0.1,0", "seed=1,2",
                       "hydra/launcher=joblib"])
    assert jobs == [["experiment=workspace_grid", f"experiment.grid.h={h}", f"seed={s}"]
                    for h in ("0.1", "0") for s in ("1", "2")]
    assert sweep_jobs(["experiment=workspace_grid", "seed=1"]) is None  # a single run


@pytest.mark.slow
def test_refused_run_leaves_no_directory(tmp_path):
    (tmp_path / "kept").mkdir()  # a folder that existed before the run stays
    out = _cli("experiment=workspace_grid", "experiment.grid.h=0", "hydra.run.dir=kept/new/run", cwd=tmp_path)
    assert out.returncode == 2
    assert out.stderr.strip().splitlines()[-1].endswith("experiment.grid.h must be > 0 m, got 0.0 m")
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*")) == ["kept"]


@pytest.mark.slow
def test_sweep_with_one_bad_value_is_refused_before_it_starts(tmp_path):
    out = _cli("-m", "experiment=workspace_grid", "experiment.grid.h=0.1,0", "experiment.grid.z=[0.0,0.6]",
               "plots=false", "hydra.sweep.dir=sweep", cwd=tmp_path)
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert lines == ["ERROR: sweep job 1 (experiment=workspace_grid experiment.grid.h=0 experiment.grid.z=[0.0,0.6] "
                     "plots=false): experiment.grid.h must be > 0 m, got 0.0 m"]
    assert list(tmp_path.iterdir()) == []  # no sweep folder, no empty summary.csv
