"""experiments/gpu_check.py runs every job's JAX path at tiny size and agrees with the CPU (here: CPU vs CPU)."""

import sys
from pathlib import Path

import pytest


@pytest.mark.slow
def test_gpu_check_tiny(capsys):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import gpu_check

    assert gpu_check.main(["--scale", "1"]) == 0
    out = capsys.readouterr().out
    for name in ("kernel", "workspace", "redundancy", "GA fitness", "dynamics", "boundary"):
        assert name in out
    assert "DISAGREE" not in out
