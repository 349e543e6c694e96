"""The job table, and every CLI job end to end at its toy size (tests/toy_jobs.py): the run completes, its
results file has data, its figures are real PNGs. Each run is the session's shared one (conftest ``toy_run``):
the other test files check their numbers on the same files, so no job runs twice."""

import json
from pathlib import Path

import numpy as np
import pytest

from deltajax.io import groups, load
from deltajax.jobs import JOBS, load as load_job
from deltajax.run import CONFIG_DIR, list_experiments

from toy_jobs import GA_STAGES_OFF, HAS_REFINE, TOY

#: figures each job writes (at least these)
PLOTS = {
    "indices_examples": ["index_curves.png"],
    "reconfig_workspace": ["fig7_workspace.png"],
    "reconfig_indices": ["fig8_omega_v_slices.png"],
    "boundary_search": ["boundary_slice.png", "boundary_surface.png"],
    "workspace_grid": ["workspace_grid.png"],
    "dynamics_cycle": ["industrial_adept_profiles.png", "franco2026_adept_profiles.png"],
    "bench_kernel": [],
    "reconfig_motion": ["adept_landscape.png", "task_profiles.png"],
    "ga_reconfig": ["ga_pareto.png", "ga_convergence.png"],
    "datasheet": ["datasheet_industrial.png"],
}


def test_jobs_table_matches_configs_and_modules():
    configs = sorted(p.stem for p in (Path(CONFIG_DIR) / "experiment").glob("*.yaml"))
    assert sorted(JOBS) == configs
    assert list(list_experiments())[0] == "ga_reconfig"  # the main job first in --help
    for name in JOBS:
        assert callable(load_job(name).run), name
    assert sorted(TOY) == sorted(JOBS) == sorted(PLOTS)  # every job has a toy size and is run below


def _assert_complete(path, name):
    run_dir = path.parent
    manifest = json.loads((run_dir / "deltajax_run.json").read_text())
    assert manifest["experiment"] == name and manifest["status"] == "complete", manifest
    assert groups(path), "no data in the results file"
    assert "end_time" in load(path)["attrs"]
    assert not list(run_dir.glob("*.tmp")) and not list(run_dir.glob(".*.tmp"))


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(TOY))
def test_every_job_end_to_end_at_toy_size(name, toy_run):
    path = toy_run(name)
    _assert_complete(path, name)
    for png in PLOTS[name]:
        data = (path.parent / png).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000, png


def _stages(path):
    return load(path)["attrs"]["ga_reconfig_stages"].split(",")


@pytest.mark.slow
def test_ga_reconfig_with_optional_stages_on(toy_run):
    path = toy_run("ga_reconfig")
    stages = _stages(path)
    assert stages[-4:] == ["results", "plots", "export", "report"], stages
    assert (path.parent / "report.html").stat().st_size > 1_000_000     # plotly.js inline
    assert stages.index("ga") < stages.index("pareto") < stages.index("verify"), stages
    assert "pareto" in groups(path) and "verify" in stages
    if HAS_REFINE:
        assert "refine" in stages, stages


@pytest.mark.slow
def test_stage_log_lines_carry_time_and_memory(toy_run):
    """The stage engine logs each computed stage's wall time, CPU-seconds, the process's peak memory so far and what
    it holds once the stage's freed memory went back to the system (never more than the peak)."""
    import re

    path = toy_run("ga_reconfig")
    log = (path.parent / "run.log").read_text()
    lines = {m[0]: m[1:] for m in re.findall(r"\[(\w+): ([\d.]+) s, ([\d.]+) CPU-s, peak ([\d.]+) GiB, "
                                              r"([\d.]+) GiB in use\]", log)}
    assert {"ga", "verify", "certify", "results"} <= set(lines), log[-2000:]
    for name, (wall, cpu, peak, in_use) in lines.items():
        assert 0 < float(in_use) <= float(peak) < 64, (name, peak, in_use)


@pytest.mark.slow
def test_ga_reconfig_with_optional_stages_off(toy_run):
    path = toy_run("ga_reconfig", *GA_STAGES_OFF)
    _assert_complete(path, "ga_reconfig")
    stages = _stages(path)
    assert "pareto" not in stages and "refine" not in stages and stages[-1] == "report", stages
    assert "pareto" not in groups(path)
    assert (path.parent / "ga_convergence.png").read_bytes()[:4] == b"\x89PNG"


@pytest.mark.slow
def test_ga_reconfig_exports_its_baseline_and_recommendation(toy_run):
    """The export stage: both designs' datasheets (with units, figures on disk) and the recommendation's MJCF,
    URDF and loop-closure sidecar, which load and describe the design the summary recommends."""
    import json

    import mujoco

    from deltajax.export import SIDECAR_FORMAT

    path = toy_run("ga_reconfig")
    data = load(path)
    run_dir = path.parent
    for name in ("baseline", "recommended"):
        sheet = data["datasheet"][name]
        assert np.all(np.diff(sheet["picks_per_min"][:-1]) < 0)           # the rate falls with payload
        assert sheet["picks_per_min_vendor"][0] < sheet["picks_per_min"][0]
        assert (run_dir / f"datasheet_{name}.png").read_bytes()[:4] == b"\x89PNG"
    model = mujoco.MjModel.from_xml_path(str(run_dir / "recommended.xml"))
    assert model.nu >= 3 and model.neq >= 3                               # three motors, three loop closures
    loops = json.loads((run_dir / "recommended.loops.json").read_text())
    assert loops["format"] == SIDECAR_FORMAT and loops["urdf"] == "recommended.urdf"
    assert len(loops["loop_closures"]) == 3
    from deltajax.config import source_run
    from deltajax.jobs.datasheet import run_designs

    S = data["summary"]
    space, motor = source_run(str(run_dir))
    designs = {n: r for n, r, *_ in run_designs(space, S, motor)}
    R_op = list(S["metric_name"]).index("R_operating")
    for name in ("baseline", "recommended"):   # each datasheet at the R the run operates the design at
        assert float(data["datasheet"][name]["base_radius"]) == pytest.approx(float(S[name][R_op]))
    rec = getattr(designs["recommended"], "robot", designs["recommended"])
    assert loops["loop_closures"][0]["point1"][2] == pytest.approx(-float(rec.forearm))
    assert "<robot name=\"deltajax_recommended\">" in (run_dir / "recommended.urdf").read_text()
