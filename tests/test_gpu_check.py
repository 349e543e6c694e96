"""experiments/gpu_check.py runs every job's JAX path at tiny size and agrees with the CPU (here: CPU vs CPU),
the Table-6 JAX selection equals the Numba job path, and the main job runs end to end with per-stage times."""

import re
import sys
from pathlib import Path

import pytest


@pytest.mark.slow
def test_gpu_check_tiny(capsys):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import gpu_check

    assert gpu_check.main(["--scale", "1"]) == 0
    out = capsys.readouterr().out
    for name in ("kernel", "workspace", "redundancy", "GA fitness", "dynamics", "boundary",
                 "designer batch_evaluator", "Table-6 resolve_redundancy"):
        assert re.search(rf"^{re.escape(name)}.* agree$", out, re.M), name
    assert re.search(r"^Table-6 JAX vs Numba selection +identical$", out, re.M)
    assert "DISAGREE" not in out
    # the main job at toy size, end to end: every search stage timed, and the totals
    assert "main job ga_reconfig (toy size)" in out
    for stage in ("screen", "ga", "pareto", "refine", "verify", "total wall s", "total CPU-s"):
        assert re.search(rf"^  {re.escape(stage)} +[0-9.]+", out, re.M), stage
