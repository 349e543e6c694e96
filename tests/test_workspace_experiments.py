"""CLI experiments reconfig_workspace and reconfig_indices on a coarse grid: results layout and numbers."""

import numpy as np
import pytest

from deltajax.config import ConfigError
from deltajax.io import load
from deltajax.run import run_experiment


@pytest.mark.slow
def test_reconfig_workspace(toy_run):
    path = toy_run("reconfig_workspace")  # experiment.h=0.04: the session's shared toy run (tests/toy_jobs.py)
    tmp_path = path.parent
    r = load(path)["workspace"]
    assert r["reachable_fixed"].shape == (21, 21, 15)
    assert r["units"]["volume_box_fixed"] == "m^3" and r["units"]["x"] == "m"
    assert r["count_reconfigurable"] > r["count_fixed"] > 0
    assert r["increase_percent"] == pytest.approx(100 * (r["count_reconfigurable"] / r["count_fixed"] - 1))
    assert (tmp_path / "fig7_workspace.png").stat().st_size > 1000
    import xarray as xr
    ds = xr.open_dataset(path, group="workspace", engine="h5netcdf")
    assert ds["reachable_fixed"].dims == ("x", "y", "z")


@pytest.mark.slow
def test_reconfig_indices_beta_override(toy_run, tmp_path):
    path = toy_run("reconfig_indices")  # h=0.04, beta=0.75, slices_z=[0.4]: the session's shared toy run
    r = load(path)["workspace"]
    assert r["attrs"]["beta"] == 0.75
    assert r["stats"].shape == (2, 8, 3)
    rdr, odr = r["stats"][0], r["stats"][1]
    i_omv = list(r["index"]).index("omega_v")
    assert rdr[i_omv, 0] > odr[i_omv, 0]  # reconfiguration avoids low velocity manipulability
    assert not np.isnan(r["paper_stats"][0, i_omv, 2])
    assert np.all(np.isnan(r["R_star"][r["reachable_fixed"] == 0]))
    assert (path.parent / "fig8_omega_v_slices.png").exists()
    with pytest.raises(ConfigError, match="beta"):
        run_experiment("reconfig_indices", ["experiment.h=0.04", "beta=1.5"], run_dir=tmp_path / "bad")
