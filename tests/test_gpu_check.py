"""experiments/gpu_check.py runs every job's JAX path at tiny size (on a CPU-only machine each path once: there
is no device to compare with the CPU; its comparison, ``_agree``, is checked on its own), the Table-6 JAX
selection equals the Numba job path, and the main job runs end to end with per-stage times."""

import re
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
import gpu_check  # noqa: E402


def test_agreement_is_equal_masks_and_close_finite_values():
    a = {"x": np.array([1.0, np.nan, np.inf, 2.0]), "ok": np.array([True, False]), "k": np.array([3, 4])}
    assert gpu_check._agree(a, {"x": np.array([1.0 + 1e-12, np.nan, np.inf, 2.0]), "ok": a["ok"], "k": a["k"]})
    assert not gpu_check._agree(a, {**a, "x": np.array([1.0 + 1e-6, np.nan, np.inf, 2.0])})   # beyond rtol 1e-9
    assert not gpu_check._agree(a, {**a, "x": np.array([1.0, 0.0, np.inf, 2.0])})            # NaN became a number
    assert not gpu_check._agree(a, {**a, "ok": np.array([True, True])})                       # a mask differs
    assert not gpu_check._agree(a, {**a, "k": np.array([3, 5])})                              # an integer differs


@pytest.mark.slow
def test_gpu_check_tiny(capsys):
    assert gpu_check.main(["--scale", "1"]) == 0
    out = capsys.readouterr().out
    for name in ("kernel", "workspace", "redundancy", "GA fitness", "dynamics", "boundary",
                 "designer batch_evaluator", "Table-6 resolve_redundancy"):
        assert re.search(rf"^{re.escape(name)} .* [0-9.e+]+/s  ran \(the device is the CPU\)$", out, re.M), name
    assert re.search(r"^Table-6 JAX vs Numba selection +identical$", out, re.M)
    assert "DISAGREE" not in out and "all paths ran (no device other than the CPU)" in out
    # the main job at toy size, end to end: every search stage timed, and the totals
    assert "main job ga_reconfig (toy size)" in out
    for stage in ("screen", "ga", "pareto", "refine", "verify", "total wall s", "total CPU-s"):
        assert re.search(rf"^  {re.escape(stage)} +[0-9.]+", out, re.M), stage
