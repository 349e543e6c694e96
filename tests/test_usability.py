"""Issue 13: clean CLI errors, --help, the default job, degrees/full-turn limits, the float32 warning."""

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

    from deltajax.run import BelowWarning, _console_through_tqdm, _TqdmHandler

    root = logging.getLogger()
    out, err = logging.StreamHandler(sys.stdout), logging.StreamHandler(sys.stderr)
    out.addFilter(BelowWarning())
    err.setLevel(logging.WARNING)
    f = logging.StreamHandler(io.StringIO())  # a file-like handler: left alone
    saved = list(root.handlers)
    root.handlers = [out, err, f]
    try:
        with _console_through_tqdm():
            new = list(root.handlers)
            assert [type(h) for h in new] == [_TqdmHandler, _TqdmHandler, logging.StreamHandler]
            assert new[0].stream is sys.stdout and new[0].filters == out.filters  # info -> stdout only
            assert new[1].stream is sys.stderr and new[1].level == logging.WARNING  # warnings -> stderr
            assert new[2] is f
        assert root.handlers == [out, err, f]  # restored
    finally:
        root.handlers = saved


def test_import_creates_no_arrays():
    """Importing deltajax must not start a JAX backend (sweep workers set XLA threads and host devices after the
    import, and a default built at import would freeze the float precision before the caller chooses it)."""
    code = ("import deltajax\nfrom jax._src import xla_bridge\n"
            "assert not xla_bridge.backends_are_initialized(), 'import deltajax initialised a JAX backend'")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])})
    assert out.returncode == 0, out.stderr[-2000:]
