"""Run directories (deltajax.rundir): a results file to resume over is read and verified through deltajax.io."""

import pytest


def test_rundir_checks_a_results_file_through_io_read(tmp_path):
    import inspect

    import h5py

    from deltajax import rundir
    from deltajax.rundir import RunDirError

    assert "h5py" not in inspect.getsource(rundir)
    from deltajax.io import ResultsFile

    good = tmp_path / "good.h5"
    res = ResultsFile(good)
    res.set_attrs("a", x=1)
    res.put("a", "v", [1.0, 2.0], units="1")
    res.flush()
    rundir._check_results(good, "resume")
    rundir._check_results(tmp_path / "missing.h5", "resume")  # nothing to resume over
    for name, data in (("garbage.h5", b"garbage" * 100), ("cut.h5", good.read_bytes()[:800])):
        (tmp_path / name).write_bytes(data)
        with pytest.raises(RunDirError, match=rf"cannot resume: .*{name} is not a readable HDF5 file.*fresh=true"):
            rundir._check_results(tmp_path / name, "resume")
    with h5py.File(good, "r+") as f:  # readable, but edited: refused too
        f["a"].attrs["x"] = 2
    with pytest.raises(RunDirError, match=r"cannot resume: .*good.h5 fails verification: .*'x'.*fresh=true"):
        rundir._check_results(good, "resume")
