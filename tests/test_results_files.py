"""Every experiment's results file at toy sizes: xarray opens every group, every variable has units and a
long_name, z is marked positive-down, large datasets are compressed, errors list the groups."""

import h5py
import numpy as np
import pytest

from deltajax.io import ResultsFile, ResultsGroupError, groups, load, open_xarray
from deltajax.run import list_experiments, run_experiment

COMMON = ["plots=false", "progress=false", "compilation_cache=null"]
#: toy overrides per experiment (seconds each, not minutes)
TOY = {
    "indices_examples": ["experiment.R_step=1e-3"],
    "reconfig_workspace": ["experiment.h=0.04"],
    "reconfig_indices": ["experiment.h=0.04"],
    "boundary_search": ["experiment.steps_deg=[15.0]", "experiment.grid_h=0.2", "experiment.profile_samples=64",
                        "experiment.centre_sweep_z=[1.62]", "experiment.sweep_step_deg=15.0",
                        "experiment.timing_repeats=1"],
    "workspace_grid": ["experiment.grid.h=0.1", "experiment.grid.z=[0.0,0.6]", "experiment.chunk_points=100"],
    "dynamics_cycle": ["experiment.n_samples=41", "experiment.robots=[franco2026]"],
    "bench_kernel": ["experiment.n_points=4000", "experiment.n_baseline=1000", "experiment.block=1000",
                     "experiment.repeats=1"],
    # issue 14's job (motion branch); listed here so the merged suite covers it, skipped while it is absent
    "reconfig_motion": ["experiment.R_step=0.007", "experiment.cases.adept.n_samples=11",
                        "experiment.cases.task.samples_per_segment=5", "experiment.refine.enabled=false",
                        "experiment.cases.task.points=[[0.0,0.0,0.30],[0.15,0.08,0.42],[-0.12,0.12,0.45]]"],
    "ga_reconfig": [  # the main job's own toy size (tests/test_ga_reconfig.py)
        "experiment.design.n_R=3", "experiment.task.n_r=1", "experiment.task.n_phi=3", "experiment.task.n_z=2",
        "experiment.cycle.n_samples=11", "experiment.cycle.n_R_operating=2", "experiment.regular_workspace.n_r=6",
        "experiment.regular_workspace.n_phi=2", "experiment.regular_workspace.n_z=6",
        "experiment.ga.population_size=8", "experiment.ga.generations=2", "experiment.ga.checkpoint_every=2",
        "experiment.pareto.population_size=8", "experiment.pareto.generations=2", "experiment.verify.n_R=3",
        "experiment.verify.n_R_operating=2", "experiment.verify.task_n_r=1", "experiment.verify.task_n_phi=3",
        "experiment.verify.task_n_z=2", "experiment.verify.cycle_samples=13", "experiment.verify.rw_n_r=7",
        "experiment.verify.rw_n_phi=2", "experiment.verify.rw_n_z=7"],
}


def test_every_experiment_has_a_toy_config():
    missing = sorted(set(list_experiments()) - set(TOY))
    assert not missing, f"add toy overrides for {missing} to TOY"


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(TOY))
def test_xarray_opens_every_group_with_units(name, tmp_path):
    if name not in list_experiments():
        pytest.skip(f"experiment {name} is not in this checkout")
    path = run_experiment(name, [*COMMON, *TOY[name]], run_dir=tmp_path)
    names = groups(path)
    assert names, "no data in the results file"
    for g in names:
        ds = open_xarray(path, g)
        for v in [*ds.data_vars.values(), *ds.coords.values()]:
            assert "units" in v.attrs and "long_name" in v.attrs, f"{g}/{v.name}: {dict(v.attrs)}"
            # one name, one meaning across experiments: peak_speed is the end-effector's (joints: peak_joint_speed)
            if v.name == "peak_speed" or str(v.name).startswith("peak_speed_"):
                assert v.attrs["units"] == "m/s", f"{g}/{v.name}"
            if str(v.name).startswith("R_operating"):
                assert v.attrs["units"] == "m", f"{g}/{v.name}"
        if "z" in ds.coords and ds["z"].attrs["units"] == "m":
            assert ds["z"].attrs["positive"] == "down", g
    assert not (tmp_path / "checkpoint").exists()  # a completed run keeps no resume state
    assert "wrote" in (tmp_path / "run.log").read_text()  # the run's own log, not just JAX's


def test_compression_attributes_and_group_errors(tmp_path):
    path = tmp_path / "r.h5"
    res = ResultsFile(path)
    x = np.linspace(-0.4, 0.4, 41)
    z = np.linspace(0.0, 0.6, 31)
    mask = (x[:, None, None] ** 2 + x[None, :, None] ** 2 + (z[None, None, :] - 0.3) ** 2) < 0.1
    for n, a in (("x", x), ("y", x), ("z", z)):
        res.put_axis("workspace", n, a, units="m")
    res.put("workspace", "reachable", mask, units="1", dims=("x", "y", "z"))
    res.put("workspace", "R_star", np.where(mask, 0.2, np.nan), units="m", dims=("x", "y", "z"))
    res.put("workspace", "volume", 0.1, units="m^3")
    res.put("bench/float32", "rate", 1e6, units="1/s")
    res.flush()
    with h5py.File(path, "r") as f:
        d = f["workspace/reachable"]
        assert d.compression == "gzip" and d.shuffle and d.chunks is not None
        assert d.id.get_storage_size() < d.size / 20  # a mask compresses by far more than 20x
        assert f["workspace/volume"].compression is None  # scalars stay contiguous
    out = load(path)
    np.testing.assert_array_equal(out["workspace"]["reachable"], mask)
    ws = open_xarray(path, "workspace")
    assert ws["z"].attrs["positive"] == "down" and ws["R_star"].attrs["units"] == "m"
    assert ws["R_star"].attrs["long_name"].startswith("base radius")
    assert groups(path) == ["bench/float32", "workspace"]
    with pytest.raises(ResultsGroupError, match=r"no group 'ga'; its groups with data: bench/float32, workspace"):
        open_xarray(path, "ga")
    with pytest.raises(ResultsGroupError, match=r"bench/float32, workspace"):
        load(path, "pareto")
    assert load(path, "bench/float32")["rate"] == 1e6
    with pytest.raises(FileNotFoundError, match="no results file"):
        open_xarray(tmp_path / "missing.h5", "workspace")
