"""CLI experiment reconfig_motion on tiny sizes: results layout, the method ordering, config errors."""

import numpy as np
import pytest

from deltajax.config import ConfigError
from deltajax.io import load
from deltajax.run import run_experiment

TINY = ["experiment.R_step=0.007", "experiment.cases.adept.n_samples=11", "experiment.cases.task.samples_per_segment=5",
        "experiment.refine.enabled=false", "progress=false", "plots=false",
        "experiment.cases.task.points=[[0.0,0.0,0.30],[0.15,0.08,0.42],[-0.12,0.12,0.45]]"]


@pytest.mark.slow
def test_reconfig_motion_tiny(toy_run):
    path = toy_run("reconfig_motion")  # TINY's sizes: the session's shared toy run (tests/toy_jobs.py)
    out = load(path)["reconfig_motion"]
    for case, K in (("adept", 11), ("task", 9)):
        g = out[case]
        assert g["t"].shape == (K,) and g["units"]["t"] == "s"
        assert g["value_table"].shape == (K, 52)
        summ = g["summary"]
        methods = [m.decode() if isinstance(m, bytes) else m for m in summ["method"]]
        assert methods == ["fixed", "pointwise", "path_dp", "path_refined"]
        mean = dict(zip(methods, summ["mean_value"]))
        # path-optimal is never worse than the best fixed R and never better than the unconstrained pointwise R*
        assert mean["fixed"] <= mean["path_dp"] + 1e-12 <= mean["pointwise"] + 2e-12
        within = dict(zip(methods, summ["within_drive_limits"]))
        assert within["path_dp"] == 1 and within["path_refined"] == 1 and within["fixed"] == 1
        assert g["path_dp"]["screw_torque"].shape == (K,) and g["path_dp"]["units"]["screw_torque"] == "N m"
        assert np.all(np.isfinite(g["path_dp"]["tau"]))
    assert out["attrs"]["mechanism"] == "screw_linkage"


def test_reconfig_motion_config_errors(tmp_path):
    with pytest.raises(ConfigError, match="experiment.drive"):
        run_experiment("reconfig_motion", TINY + ["experiment.drive.speed=-1"], run_dir=tmp_path / "a")
    with pytest.raises(ConfigError, match="experiment.cases.adept.boundary"):
        run_experiment("reconfig_motion", TINY + ["experiment.cases.adept.boundary=periodic"], run_dir=tmp_path / "b")
    with pytest.raises(ConfigError, match="experiment.R_step"):
        run_experiment("reconfig_motion", TINY[1:] + ["experiment.R_step=0.0013"], run_dir=tmp_path / "c")
