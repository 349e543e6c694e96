"""deltajax.io.differences: two results files compared dataset by dataset and attribute by attribute (bit for bit
or to a tolerance, NaN equal to NaN), run bookkeeping (time, commit, wall time) and ignored patterns left out."""

import time

import numpy as np
import pytest

from deltajax import io as dio


def _write(path, *, scale=1.0, extra=False, attr="a", nan=False):
    res = dio.ResultsFile(path, attrs={"experiment": "demo", "wall_time_s": time.perf_counter()})
    v = np.linspace(0.0, 1.0, 5) * scale
    if nan:
        v[2] = np.nan
    res.put("g", "v", v, units="m")
    res.put("g", "timing_s", np.asarray(time.perf_counter()), units="s")
    res.put("g", "n", np.arange(3), units="1")
    res.set_attrs("g", kind=attr)
    if extra:
        res.put("h", "w", np.ones(2), units="1")
    res.flush(final=True)
    return path


@pytest.mark.slow
def test_the_same_results_compare_clean_whatever_their_run_bookkeeping(tmp_path):
    a = _write(tmp_path / "a.h5", nan=True)
    time.sleep(1.1)                                   # another start/end time and wall time
    b = _write(tmp_path / "b.h5", nan=True)
    assert dio.differences(a, b, ignore=["*/timing*"]) == []
    assert any(line.startswith("g/timing_s") for line in dio.differences(a, b))


def test_every_kind_of_difference_is_named(tmp_path):
    a = _write(tmp_path / "a.h5")
    b = _write(tmp_path / "b.h5", scale=1.0 + 1e-15, extra=True, attr="b")
    d = dio.differences(a, b, ignore=["*/timing*"])
    assert any(line.startswith("g/v: values differ at") for line in d)
    assert "h/: group only in b" in d
    assert any(line.startswith("g@kind: 'a' != 'b'") for line in d)
    # to a tolerance, the last-bit change is no difference
    assert not any(line.startswith("g/v") for line in dio.differences(a, b, ignore=["*/timing*"], rtol=1e-12))


def test_exact_patterns_and_one_group(tmp_path):
    a = _write(tmp_path / "a.h5")
    b = _write(tmp_path / "b.h5", scale=1.0 + 1e-15, extra=True)
    # bit for bit whatever the tolerance where a pattern says so
    d = dio.differences(a, b, ignore=["*/timing*"], rtol=1e-12, exact=["g/v"])
    assert any(line.startswith("g/v: values differ at") for line in d)
    # one group: the other group and the root attributes are left out
    d = dio.differences(a, b, ignore=["*/timing*"], group="h")
    assert d == ["h/: group only in b"]
    assert dio.differences(a, b, ignore=["*/timing*"], rtol=1e-12, group="g") == []
