"""The CLI as a user meets it: clean errors, --help, the default job, degrees/full-turn limits, the float32 warning."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

import deltajax as dj
from deltajax.geometry import GeometryError

REPO = Path(__file__).resolve().parent.parent


def _cli(*args, cwd=REPO, env_extra=None, timeout=300):
    env = {**os.environ, "PYTHONPATH": str(REPO), **(env_extra or {})}
    env.pop("HYDRA_FULL_ERROR", None) if not (env_extra and "HYDRA_FULL_ERROR" in env_extra) else None
    return subprocess.run([sys.executable, "-m", "deltajax.run", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=timeout)


def _error_lines(stderr: str) -> list:
    return [ln for ln in stderr.splitlines() if ln.strip() and not ln.startswith("[deltajax] worker")]


@pytest.mark.slow
def test_user_error_is_one_line_exit_2_and_logged(tmp_path):
    out = _cli("experiment=indices_examples", "robot.theta_min_deg=120", f"hydra.run.dir={tmp_path}")
    assert out.returncode == 2, out.stderr
    lines = _error_lines(out.stderr)
    assert lines == ["ERROR: robot: joint limits inverted or empty: theta_min_deg=120 deg must be < "
                     "theta_max_deg=110 deg"], out.stderr
    assert "Traceback" not in out.stderr + out.stdout
    # rejected before the run directory was claimed: nothing is written there (run.log only logs owned runs)
    assert not (tmp_path / "run.log").exists()
    full = _cli("experiment=indices_examples", "robot.forearm=-0.4", f"hydra.run.dir={tmp_path}",
                env_extra={"HYDRA_FULL_ERROR": "1"})
    assert full.returncode != 0 and "Traceback" in full.stderr and "forearm must be > 0 m, got -0.4" in full.stderr


@pytest.mark.slow
def test_unknown_experiment_lists_the_choices():
    out = _cli("experiment=ga_reconfg")
    assert out.returncode == 2
    (line,) = _error_lines(out.stderr)
    assert "experiment=ga_reconfg" in line and "ga_reconfig" in line and "bench_kernel" in line


@pytest.mark.slow
def test_help_lists_every_experiment_and_bare_run_is_the_main_job():
    out = _cli("--help")
    assert out.returncode == 0
    exps = sorted(p.stem for p in (REPO / "configs" / "experiment").glob("*.yaml"))
    for name in exps:
        (line,) = [ln for ln in out.stdout.splitlines() if ln.strip().startswith(name + " ")]
        assert len(line.split(maxsplit=1)[1]) > 20  # a real one-line description
    assert "ga_reconfig" in out.stdout.split("experiments")[1].splitlines()[1]  # the main job first
    cfg = _cli("--cfg", "job")
    assert cfg.returncode == 0 and "name: ga_reconfig" in cfg.stdout


def test_joint_limits_in_degrees_and_full_turn():
    kw = dict(base_radius=0.2, platform_radius=0.065, upper_arm=0.2, forearm=0.4)
    with pytest.raises(GeometryError, match=r"theta_min_deg=120 deg must be < theta_max_deg=110 deg"):
        dj.Delta.from_degrees(theta_min_deg=120, theta_max_deg=110, **kw)
    with pytest.raises(GeometryError, match=r"400 deg must be <= 360 deg"):
        dj.Delta.from_degrees(theta_min_deg=-200, theta_max_deg=200, **kw)
    import math

    import jax.numpy as jnp

    full = dj.Delta(theta_min=-math.pi, theta_max=math.pi, **kw)          # "no limit", written as [-pi, pi]
    full_deg = dj.Delta.from_degrees(theta_min_deg=-180, theta_max_deg=180, **kw)
    free = dj.Delta(**kw)
    p = jnp.array([0.05, -0.03, 0.3])
    for rob in (full, full_deg):
        assert bool(dj.ik(rob, p).ok.all()) == bool(dj.ik(free, p).ok.all()) is True
    with pytest.raises(GeometryError, match=r"must be <= 2\*pi"):
        dj.Delta(theta_min=-math.pi, theta_max=math.pi + 1e-6, **kw)


def _count_float32_warnings(prefix: str) -> str:
    code = prefix + (
        "import warnings, deltajax as dj\n"
        "kw = dict(base_radius=0.2, platform_radius=0.065, upper_arm=0.2, forearm=0.4)\n"
        "with warnings.catch_warnings(record=True) as w:\n"
        "    warnings.simplefilter('always')\n"
        "    dj.Delta(**kw); dj.Delta(**kw); dj.presets.franco2026()\n"
        "print(sum(issubclass(x.category, dj.Float32Warning) for x in w))\n"
    )
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    env.pop("JAX_ENABLE_X64", None)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


@pytest.mark.slow
def test_float32_warning_once_unless_requested():
    assert _count_float32_warnings("") == "1"  # forgot jax_enable_x64: warned once per process, not per robot
    assert _count_float32_warnings("import jax; jax.config.update('jax_enable_x64', True)\n") == "0"
    assert _count_float32_warnings("from deltajax._precision import float32_requested; float32_requested()\n") == "0"


# -- API: one-call volume, result objects, progress totals -------------------------------------------------------
def test_workspace_volume_one_call_matches_a_big_grid_and_flags_truncation(monkeypatch):
    import io

    import numpy as np
    from tqdm import tqdm

    from deltajax import workspace as ws
    from deltajax.workspace import measure as vol_mod

    robot = dj.presets.franco2026(fixed_R=0.2)
    h = 0.02
    res = dj.workspace.volume(robot, h=h)
    assert not res.truncated and res.count > 0 and res.volume == pytest.approx(res.count * h ** 3)
    # the same lattice in a generous box: the reach-sized box misses nothing
    big = ws.make_grid((-1.0, 1.0), (-1.0, 1.0), (-1.0, 1.0), h)
    ref = ws.fixed_workspace(robot, big, fields=False)
    assert ref.count == res.count and isinstance(ref.count, int)  # GridJob.count: points, not tuple.count
    # a box that cuts the workspace off is flagged, never reported as complete
    monkeypatch.setattr(vol_mod, "reach_box", lambda r: ((-0.2, 0.2), (-0.2, 0.2), (0.0, 0.3)))
    cut = dj.workspace.volume(robot, h=h)
    assert cut.truncated and cut.count < res.count
    monkeypatch.undo()
    rec = dj.workspace.volume(dj.presets.franco2026(), h=0.04)
    assert rec.reconfigurable and not rec.truncated and rec.volume > dj.workspace.volume(robot, h=0.04).volume
    with pytest.raises(ValueError, match=r"h must be a positive grid spacing in m, got -0.01"):
        dj.workspace.volume(robot, h=-0.01)
    # grid progress bars end at 100 % under mirror halving (bar.update passed, as the experiments do)
    g = ws.make_grid((-0.4, 0.4), (-0.4, 0.4), (0.0, 0.6), 0.05)
    with tqdm(total=g.n_points, file=io.StringIO()) as bar:
        ws.fixed_workspace(robot, g, fields=False, chunk_size=500, progress=bar.update)
        assert bar.n == bar.total and bar.total < g.n_points


def test_console_logging_goes_through_tqdm_and_keeps_routing():
    import io
    import logging

    from deltajax.runlog import BelowWarning, TqdmHandler, console_through_tqdm

    root = logging.getLogger()
    out, err = logging.StreamHandler(sys.stdout), logging.StreamHandler(sys.stderr)
    out.addFilter(BelowWarning())
    err.setLevel(logging.WARNING)
    f = logging.StreamHandler(io.StringIO())  # a file-like handler: left alone
    saved = list(root.handlers)
    root.handlers = [out, err, f]
    try:
        with console_through_tqdm():
            new = list(root.handlers)
            assert [type(h) for h in new] == [TqdmHandler, TqdmHandler, logging.StreamHandler]
            assert new[0].stream is sys.stdout and new[0].filters == out.filters  # info -> stdout only
            assert new[1].stream is sys.stderr and new[1].level == logging.WARNING  # warnings -> stderr
            assert new[2] is f
        assert root.handlers == [out, err, f]  # restored
    finally:
        root.handlers = saved


@pytest.mark.slow
def test_import_creates_no_arrays():
    """Importing deltajax must not start a JAX backend (sweep workers set XLA threads and host devices after the
    import, and a default built at import would freeze the float precision before the caller chooses it)."""
    code = ("import deltajax\nfrom jax._src import xla_bridge\n"
            "assert not xla_bridge.backends_are_initialized(), 'import deltajax initialised a JAX backend'")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])})
    assert out.returncode == 0, out.stderr[-2000:]


# --- a mistyped key without '+': one line listing the valid keys, exit 2 ---------------------------------

@pytest.mark.parametrize("args, expected", [
    (["robot.forarm=0.4"], ["robot.forarm is not a setting of robot", "did you mean robot.forearm?",
                            "valid keys: R_range, base_radius, forearm,"]),
    (["experiment=workspace_grid", "experiment.grid.hh=0.1"],
     ["experiment.grid.hh is not a setting of experiment.grid (experiment workspace_grid)", "valid keys: bounds, h,"]),
    (["experiment.pareto.ref_mx=1"],  # ga_reconfig (no schema): the keys of the composed block
     ["experiment.pareto.ref_mx is not a setting of experiment.pareto (experiment ga_reconfig)", "ref_min_factor"]),
    (["sed=3"], ["sed is not a setting at the top level (did you mean seed?)", "precision"]),
    (["robot.mass.upper=1"], ["robot.mass.upper is not a setting of robot.mass", "upper_arm_mass"]),
    (["robot.forearm=abc"], ["robot.forearm: Value 'abc'", "Float"]),
    (["robot=foo"], ["robot=foo is not a choice of robot; choose one of: boundary2d, franco2026, industrial"]),
    (["robot.forearm=0.4,0.5"], ["robot.forearm=0.4,0.5 lists several values: add -m"]),
    (["-m", "experiment=workspace_grid,reconfig_indices", "experiment.grid.h=0.1"],
     ["experiment.grid is not a setting of experiment reconfig_indices", "store_fields"]),
])
def test_composition_errors_are_one_line_listing_valid_keys(args, expected):
    from deltajax.run import check_overrides

    line = check_overrides(args)
    assert line is not None and "\n" not in line and "+" not in line.split("valid keys")[0], line
    for part in expected:
        assert part in line, (part, line)


@pytest.mark.slow
def test_composition_check_passes_good_command_lines():
    from deltajax.run import check_overrides

    for args in (["robot.forearm=0.45", "hydra.run.dir=/nonexistent/x"], ["--cfg", "job", "seed=3"],
                 ["-m", "experiment=workspace_grid", "experiment.grid.h=0.1,0.2", "hydra/launcher=joblib"],
                 ["+robot.forarm=1"]):  # '+' keys are refused later by config.check_keys (tested in test_faults)
        assert check_overrides(args) is None, args


@pytest.mark.slow
def test_mistyped_key_cli_and_api(tmp_path):
    out = _cli("robot.forarm=0.4", f"hydra.run.dir={tmp_path}")
    assert out.returncode == 2, out.stderr
    (line,) = _error_lines(out.stderr)
    assert line.startswith("ERROR: robot.forarm is not a setting of robot") and "forearm" in line
    assert "+robot" not in out.stderr and not any(tmp_path.iterdir())
    full = _cli("robot.forarm=0.4", f"hydra.run.dir={tmp_path}", env_extra={"HYDRA_FULL_ERROR": "1"})
    assert full.returncode != 0 and "Traceback" in full.stderr  # Hydra's own error, with the traceback
    from deltajax.config import ConfigError
    from deltajax.run import run_experiment

    with pytest.raises(ConfigError, match=r"experiment.grid.hh is not a setting .*valid keys: bounds, h"):
        run_experiment("workspace_grid", ["experiment.grid.hh=0.1"], run_dir=tmp_path / "api")
    assert not (tmp_path / "api").exists()


@pytest.mark.slow
def test_one_reach_bound_for_volume_and_grid_jobs():
    """dj.workspace.volume sizes its box with the grid jobs' reach bound (driver.reach_box), over the whole R
    range of a reconfigurable robot, also when the range crosses R = r (where the union of the boxes is widest)."""
    import numpy as np

    from deltajax.workspace import driver, make_grid, measure, reachable_mask

    robot = dj.presets.franco2026(fixed_R=0.2)
    assert measure.reach_box(robot) == driver.reach_box(robot)
    recon = dj.presets.franco2026()
    assert measure.reach_box(recon) == driver.reach_box(recon.robot.with_base_radius(recon.R_min),
                                                        R_max=float(recon.R_max))
    base = dj.Delta(base_radius=0.05, platform_radius=0.1, upper_arm=0.3, forearm=0.5)
    crossing = dj.ReconfigurableDelta.from_range(base, 0.02, 0.2, 0.06)  # R - r from -0.08 to +0.1 m
    box = measure.reach_box(crossing)
    big = make_grid((-1.0, 1.0), (-1.0, 1.0), (-1.0, 1.0), 0.08)
    pts = big.points()
    for R in (0.02, 0.1, 0.2):
        # the union holds the box of every R of the range (R = r = 0.1 m: the widest one)
        one = driver.reach_box(base.with_base_radius(R))
        assert all(box[i][0] <= one[i][0] and one[i][1] <= box[i][1] for i in range(3)), (R, one, box)
        inside = pts[np.asarray(reachable_mask(base.with_base_radius(R), pts))]
        assert len(inside) > 0
        for i in range(3):
            assert box[i][0] <= inside[:, i].min() and inside[:, i].max() <= box[i][1], (R, i, box[i])
    assert not dj.workspace.volume(crossing, h=0.05).truncated


@pytest.mark.slow
def test_float32_warning_points_at_the_users_line(tmp_path):
    """The warning names the line that built the robot, not equinox's __check_init__ machinery."""
    script = tmp_path / "user_script.py"
    script.write_text("import warnings, deltajax as dj\n"
                      "with warnings.catch_warnings(record=True) as w:\n"
                      "    warnings.simplefilter('always')\n"
                      "    dj.Delta(base_radius=0.2, platform_radius=0.065, upper_arm=0.2, forearm=0.4)\n"
                      "(x,) = [x for x in w if issubclass(x.category, dj.Float32Warning)]\n"
                      "print(x.filename, x.lineno)\n")
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    env.pop("JAX_ENABLE_X64", None)
    out = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == [str(script), "4"]


def test_file_sizes_tool_measures_the_uncompressed_size(tmp_path, capsys):
    """experiments/file_sizes.py (the before/after figures in docs/BENCHMARKS.md): same data, no filters."""
    import importlib.util

    import h5py
    import numpy as np

    from deltajax.io import ResultsFile

    spec = importlib.util.spec_from_file_location("file_sizes", REPO / "experiments" / "file_sizes.py")
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    x = np.linspace(-0.4, 0.4, 81)
    mask = (x[:, None, None] ** 2 + x[None, :, None] ** 2 + x[None, None, :] ** 2) < 0.1
    res = ResultsFile(tmp_path / "r.h5")
    for n in "xyz":
        res.put_axis("workspace", n, x, units="m")
    res.put("workspace", "reachable", mask, units="1", dims=("x", "y", "z"))
    path = res.flush()
    raw = tool.uncompressed_copy(str(path), str(tmp_path / "plain.h5"))
    assert raw == mask.size + 3 * x.nbytes
    with h5py.File(tmp_path / "plain.h5") as f:
        d = f["workspace/reachable"]
        assert d.compression is None and d.chunks is None and d.attrs["units"] == "1"
        np.testing.assert_array_equal(d[()], mask)
    assert (tmp_path / "plain.h5").stat().st_size > 10 * path.stat().st_size


@pytest.mark.slow
def test_an_internal_error_is_reported_as_itself(tmp_path):
    """A bug inside a job (not a user error) shows its own exception, not a NameError from run.py's handler."""
    code = ("import sys, deltajax.run as r\n"
            "def boom(*a, **k):\n"
            "    raise RuntimeError('boom inside the job')\n"
            "r.execute = boom\n"
            f"sys.exit(r.cli(['experiment=indices_examples', 'hydra.run.dir={tmp_path}']))\n")
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    env.pop("HYDRA_FULL_ERROR", None)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 1
    assert "RuntimeError: boom inside the job" in out.stderr and "NameError" not in out.stderr, out.stderr
