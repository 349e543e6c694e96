"""Run directories (deltajax.rundir): a results file to resume over is checked through io.read."""

import pytest


def test_rundir_checks_a_results_file_through_io_read(tmp_path):
    import inspect

    import h5py

    from deltajax import rundir
    from deltajax.rundir import RunDirError

    assert "h5py" not in inspect.getsource(rundir)
    good = tmp_path / "good.h5"
    with h5py.File(good, "w") as f:
        f.create_group("a").attrs["x"] = 1
        f["a"].create_dataset("v", data=[1.0, 2.0])
    rundir._check_readable(good)
    rundir._check_readable(tmp_path / "missing.h5")  # nothing to resume over
    for name, data in (("garbage.h5", b"garbage" * 100), ("cut.h5", good.read_bytes()[:800])):
        (tmp_path / name).write_bytes(data)
        with pytest.raises(RunDirError, match=rf"cannot resume: .*{name} is not a readable HDF5 file.*fresh=true"):
            rundir._check_readable(tmp_path / name)
