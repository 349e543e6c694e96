"""Configuration read once: config.py reads every job's fields once, papers.py holds the published numbers,
the cycle names live in cycle.py, and the jobs' validation happens before the claim."""

import pytest
from omegaconf import OmegaConf

import deltajax as dj
from deltajax import config as C
from deltajax.config import ConfigError

from _config_helpers import compose, validate


def test_cycle_names_live_in_cycle_and_import_patches_no_module():
    import deltajax.dynamics as dynamics

    assert dj.Limits is dj.cycle.Limits and dj.cycle_metrics is dj.cycle.cycle_metrics
    assert dj.cycle_profile is dj.cycle.cycle_profile and dj.cycle.CycleMetrics is dj.cycle.CycleMetrics
    # importing deltajax sets no attribute on another module: dynamics holds only what it defines or imports
    assert not {"Limits", "CycleProfile", "CycleMetrics", "cycle_profile", "cycle_metrics", "within_limits",
                "min_cycle_time_bisection"} & set(vars(dynamics))


def test_papers_hold_the_numbers_the_jobs_store():
    from deltajax.jobs import boundary_search, reconfig_workspace

    assert boundary_search.PAPER is dj.papers.BOUNDARY_SEARCH
    assert reconfig_workspace.PAPER is dj.papers.FRANCO2026_VOLUMES
    assert dj.papers.FRANCO2026_EXAMPLES["table4"]["indices"]["sigma_min_f"] == 2.4592   # printed (a misprint)
    assert "sigma_min_f" not in dj.papers.example_indices()["table4"]
    assert dj.papers.example_indices(include_misprints=True)["table4"]["sigma_min_f"] == 2.4592
    assert set(dj.papers.FRANCO2026_INDEX_STATS) == {0.25, 0.5, 0.75}


@pytest.mark.slow  # ~3.4 CPU-s: the first eager JAX ops of the cases (the job reuses them)
def test_reconfig_motion_is_validated_before_the_claim():
    validate(compose("reconfig_motion"))  # float64 (conftest), as the CLI at its default precision
    for override, message in (("experiment.drive.force=0", r"experiment\.drive\.force must be > 0"),
                              ("experiment.R_step=0.0013", r"experiment\.R_step=0\.0013 m"),
                              ("experiment.refine.n_ctrl=3", r"experiment\.refine\.n_ctrl must be >= 6"),
                              ("experiment.cases.adept.law=linear", r"experiment\.cases\.adept\.law")):
        with pytest.raises(ConfigError, match=message):
            validate(compose("reconfig_motion", override))


def test_job_specs_are_plain_values_read_once():
    cfg = compose("dynamics_cycle")
    robot, recon = C.robot_from_config(cfg.robot)
    spec = C.dynamics_cycle_spec(cfg.experiment, cfg, robot, recon)
    assert spec.n_samples == 401 and spec.method == "virtual_work"
    assert spec.analysed() == list(dict.fromkeys([spec.cfg_name, "franco2026", "industrial"]))
    assert spec.setup("industrial").torque_limit == 140.0 and spec.setup("no_block") == spec.setups["default"]
    with pytest.raises(ConfigError, match=r"experiment\.n_samples must be >= 11, got 5"):
        C.dynamics_cycle_spec(OmegaConf.merge(cfg.experiment, {"n_samples": 5}), cfg, robot, recon)
    b = C.boundary_search_spec(compose("boundary_search").experiment)
    assert b.steps_deg == [2.0, 1.0] and isinstance(b.half_space, bool)


def test_grid_readers_live_in_config():
    g = C.paper_grid_from_config({"h": 0.02})
    assert g.shape == (41, 41, 30)
    with pytest.raises(ConfigError, match=r"experiment\.h must be > 0"):
        C.paper_grid_from_config({"h": -0.1})
    with pytest.raises(ConfigError, match=r"^experiment\.grid\.x must be \[lo, hi\]"):
        C.workspace_grid_from_config({"h": 0.1, "x": [1.0, 0.0], "y": [0, 1], "z": [0, 1]})
