"""Leftovers of the layout/sweeps/usability branches (cleanup): one grid reader, units in config errors, progress
bars with the right totals, dynamics_cycle's plots in plots.py, rundir reading HDF5 through io.read."""

import pytest

from deltajax import config as C
from deltajax.config import ConfigError


def test_one_grid_reader_in_config():
    from deltajax.jobs import workspace_grid as job

    assert not hasattr(job, "_grid_from_config")
    assert job.workspace_grid_from_config is C.workspace_grid_from_config


def test_config_errors_give_the_value_in_the_users_unit_on_one_line():
    cases = [(lambda: C.workspace_grid_from_config({"h": -0.01}), "experiment.grid.h must be > 0 m, got -0.01 m"),
             (lambda: C.paper_grid_from_config({"h": "x"}), "experiment.h must be a number (m), got 'x'"),
             (lambda: C.boundary_search_spec({"eps": 0.01, "rho_max": 1.0, "grid_h": 0.1, "sweep_step_deg": -2}),
              "experiment.sweep_step_deg must be > 0 deg, got -2.0 deg"),
             (lambda: C.robot_from_config({"base_radius": 0.2, "platform_radius": 0.05, "upper_arm": 0.3,
                                           "forearm": 0.8, "theta_min_deg": "low", "theta_max_deg": None}),
              "robot.theta_min_deg must be a number (deg), got 'low'"),
             (lambda: C._cycle_setup({"centre": [0, 0, 0.4], "heading_deg": 0, "duration": 0}, "experiment.setups.x"),
              "experiment.setups.x.duration must be > 0 s, got 0.0 s"),
             (lambda: C._choice("experiment.mode", "slow", ("fast", "exact")),
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


def test_grid_bars_start_with_the_computed_total_and_are_never_reset():
    import io

    from tqdm import tqdm

    import deltajax as dj
    from deltajax import workspace as ws
    from deltajax.workspace.driver import computed_points

    robot = dj.presets.franco2026(fixed_R=0.2)
    g = ws.make_grid((-0.4, 0.4), (-0.4, 0.4), (0.0, 0.6), 0.1)
    assert computed_points(g) < g.n_points == computed_points(g, mirror=False)
    log = io.StringIO()
    with tqdm(total=computed_points(g), file=log, mininterval=0) as bar:
        resets = []
        reset = bar.reset
        bar.reset = lambda total=None: (resets.append(total), reset(total))
        ws.fixed_workspace(robot, g, fields=False, chunk_size=100, progress=bar.update)
        assert bar.n == bar.total == computed_points(g) and resets == []
    assert f"0/{g.n_points}" not in log.getvalue()


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
    with h5py.File(good, "r+") as f:  # readable, but edited: refused too (issue 30)
        f["a"].attrs["x"] = 2
    with pytest.raises(RunDirError, match=r"cannot resume: .*good.h5 fails verification: .*'x'.*fresh=true"):
        rundir._check_results(good, "resume")


def test_reconfig_motion_torque_methods_stay_distinguishable_where_they_agree():
    import matplotlib
    import numpy as np

    matplotlib.use("Agg")
    from deltajax import plots
    from deltajax.jobs import reconfig_motion as job

    t = np.linspace(0.0, 1.0, 20)
    tau = np.stack([np.sin(t), np.cos(t), t], axis=1)
    figs = [plots.motion_torques("adept", t, {m: {"tau": tau} for m in job.METHODS})]
    for ax in figs[0].axes:
        styles = {(str(ln.get_linestyle()), ln.get_linewidth()) for ln in ax.get_lines()}
        assert len(ax.get_lines()) == len(job.METHODS) == len(styles)
    matplotlib.pyplot.close(figs[0])


@pytest.mark.slow
def test_jobs_show_progress_over_their_stages(tmp_path, capfd):
    from deltajax.run import run_experiment

    run_experiment("indices_examples", ["progress=true", "plots=false", "experiment.R_step=1e-3"],
                   run_dir=tmp_path / "ie")
    err = capfd.readouterr().err.replace("\r", "\n")
    assert "indices_examples: 100%" in err and "6/6" in err
