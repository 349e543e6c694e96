"""Every experiment's results file at toy sizes: xarray opens every group, every variable has units and a
long_name, z is marked positive-down, large datasets are compressed, errors list the groups."""

import h5py
import numpy as np
import pytest

from deltajax.io import ResultsFile, ResultsGroupError, groups, load, open_xarray
from deltajax.run import list_experiments

from toy_jobs import TOY  # the toy sizes, shared with every test through conftest's toy_run (one run per job)


def test_every_experiment_has_a_toy_config():
    missing = sorted(set(list_experiments()) - set(TOY))
    assert not missing, f"add toy overrides for {missing} to TOY"


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(TOY))
def test_xarray_opens_every_group_with_units(name, toy_run):
    path = toy_run(name)  # the session's one toy run of this job (also checked by tests/test_jobs.py)
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
    assert not (path.parent / "checkpoint").exists()  # a completed run keeps no resume state
    assert "wrote" in (path.parent / "run.log").read_text()  # the run's own log, not just JAX's


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
