"""Configuration errors: one line naming the field, the value in the user's unit, unknown keys listed plainly;
one grid reader in deltajax.config."""

import pytest

from deltajax import config as C
from deltajax.config import ConfigError
from deltajax.config import dynamics as config_dynamics
from deltajax.config.readers import read_settings


def test_one_grid_reader_in_config():
    from deltajax.jobs import workspace_grid as job

    assert not hasattr(job, "_grid_from_config") and not hasattr(job, "workspace_grid_from_config")


def test_config_errors_give_the_value_in_the_users_unit_on_one_line():
    cases = [(lambda: C.workspace_grid_from_config({"h": -0.01}), "experiment.grid.h must be > 0 m, got -0.01 m"),
             (lambda: C.paper_grid_from_config({"h": "x"}), "experiment.h must be a number (m), got 'x'"),
             (lambda: C.boundary_search_spec({"centre": [0, 0, 1.6], "eps": 0.01, "steps_deg": [2.0], "rho_max": 1.0,
                                              "predictor": "tangent", "volume_rule": "pyramid", "profile_samples": 8,
                                              "grid_h": 0.1, "grid_box": [[-1, 1], [-1, 1], [0, 1]],
                                              "sweep_step_deg": -2}),
              "experiment.sweep_step_deg must be > 0 deg, got -2.0 deg"),
             (lambda: C.robot_from_config({"base_radius": 0.2, "platform_radius": 0.05, "upper_arm": 0.3,
                                           "forearm": 0.8, "theta_min_deg": "low", "theta_max_deg": None}),
              "robot.theta_min_deg must be a number (deg), got 'low'"),
             (lambda: read_settings(config_dynamics.CycleSetupBlock, {"centre": [0, 0, 0.4], "heading_deg": 0,
                                                                     "duration": 0, "torque_limit": 20.0,
                                                                     "speed_limit": 10.0}, "experiment.setups.x"),
              "experiment.setups.x.duration must be > 0 s, got 0.0 s"),
             (lambda: C.read_choice("experiment.mode", "slow", ("fast", "exact")),
              "experiment.mode must be one of exact, fast, got 'slow'")]
    for call, message in cases:
        with pytest.raises(ConfigError) as err:
            call()
        assert str(err.value) == message


def test_unknown_keys_are_listed_plainly_not_as_a_python_list():
    with pytest.raises(ConfigError) as err:
        C.check_keys({"robot": {"forarm": 0.4}, "experiment": None})
    msg = str(err.value)
    assert msg.startswith("robot.forarm is not a setting of robot; valid keys: R_range, base_radius, ")
    assert "[" not in msg and "'" not in msg and "\n" not in msg
    with pytest.raises(ConfigError, match=r"^unknown top-level key\(s\) foo; valid keys: robot, experiment, seed"):
        C.check_keys({"foo": 1})


def test_a_datasheet_source_that_is_not_a_readable_run_is_one_line(tmp_path):
    (tmp_path / "results.h5").write_bytes(b"not an HDF5 file")
    with pytest.raises(ConfigError, match=r"^source=.*: its results.h5 cannot be read as a run") as err:
        C.source_run(str(tmp_path))
    assert "\n" not in str(err.value)
