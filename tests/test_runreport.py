"""The main job's run report (deltajax/runreport.py, deltajax/plots/report.py): what the page holds, that its
numbers are the verified ones, the report stage of experiment=ga_reconfig and ``python -m deltajax.report``.
The page in a real browser: tests/test_runreport_browser.py."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import deltajax.io as dio
from deltajax.io import load

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def run(toy_run):
    """The session's toy main-job run: (results.h5, its data)."""
    path = toy_run("ga_reconfig")
    return path, load(path)


def _problem(path, data):
    from deltajax.runreport import _run_problem

    return _run_problem(data, path)


@pytest.mark.slow  # the session's toy main-job run
def test_job_writes_a_self_contained_report(run):
    path, data = run
    assert data["attrs"]["ga_reconfig_stages"].split(",")[-3:] == ["plots", "export", "report"]
    page = (path.parent / "report.html").read_text()
    assert page.startswith("<!DOCTYPE html>")
    # plotly.js inline, once; the rest of the page names no address at all (nothing to fetch)
    import plotly

    js = plotly.offline.get_plotlyjs()
    assert page.count(js) == 1 and len(js) > 1_000_000
    rest = page.replace(js, "")
    assert "http" not in rest and "<script src" not in rest and "<link" not in rest
    assert rest.count("Plotly.newPlot(") == 3
    for key in ("fig-front", "fig-workspace", "fig-torque"):
        assert f'id="{key}"' in page
    rec = data["summary"]["attrs"]["recommended"]
    assert f"Recommended: <b>{rec}</b>" in page


@pytest.mark.slow  # the session's toy main-job run
def test_front_hover_lists_each_designs_parameters_and_constraints(run):
    from deltajax.optimize.designer import DESIGN_UNITS
    from deltajax.plots.report import front_figure

    path, data = run
    V = data["verify"]
    s, space, _ = _problem(path, data)
    fig = front_figure(V, list(s.objectives.names), DESIGN_UNITS, space.names, [space.units(n) for n in space.names])
    names = [str(n) for n in V["design_name"]]
    texts = {}
    for tr in fig.data:
        for t in tr.hovertext:
            texts.setdefault(t.split("</b>")[0][3:], t)
    front = np.asarray(V["front"], int)
    rec = int(V["attrs"]["recommended"])
    assert {names[i] for i in front} | {names[0], names[rec]} <= set(texts)
    for i in set(front) | {0, rec}:
        t = texts[names[i]]
        for j, p in enumerate(space.names):
            u = space.units(p)
            assert f"{p}: {V['params'][i, j]:.5g}{'' if u == '1' else ' ' + u}<br>" in t + "<br>"
        assert f"picks_per_min: {V['picks_per_min'][i]:.5g} 1/min" in t
        for c, g in zip(V["constraint_names"], V["constraint_values"][i]):
            assert f"{c}: {g:.3g}" in t
    traces = {tr.name: tr for tr in fig.data}
    base = traces[next(n for n in traces if n.startswith("baseline"))]
    assert base.x[0] == pytest.approx(V[s.objectives.names[0]][0])
    rtr = traces[f"recommended ({names[rec]})"]
    assert rtr.y[0] == pytest.approx(V[s.objectives.names[1]][rec] * (1e3 if DESIGN_UNITS[s.objectives.names[1]] == "m^3" else 1))
    assert len(traces["verified Pareto front"].x) == len(front)


@pytest.mark.slow  # the session's toy main-job run
def test_torque_speed_points_are_the_verified_cycle(run):
    """At the verified motion time, the cycle's motor points reproduce the verification's peak and speed
    utilisation of the recommendation and of the baseline (the same cycle, motor and gearbox)."""
    import jax.numpy as jnp

    from deltajax.runreport import _motor_points

    path, data = run
    V = data["verify"]
    _, space, pb = _problem(path, data)
    for i in (int(V["attrs"]["recommended"]), 0):
        design = space.decode(jnp.asarray(V["genes"][i]))
        tau, om, ok = _motor_points(design, space.reconfigurable, float(V["R_operating"][i]),
                                    float(V["cycle_time"][i]), pb)
        assert ok and tau.shape == om.shape == (pb.cycle.n_samples, 3)
        env = np.asarray(pb.motor.envelope(jnp.asarray(om)))
        np.testing.assert_allclose(np.max(np.abs(tau) / env), V["peak_utilisation"][i], rtol=1e-9)
        np.testing.assert_allclose(np.max(np.abs(om)) / float(pb.motor.max_speed), V["speed_utilisation"][i],
                                   rtol=1e-9)


@pytest.mark.slow  # a compile or a CLI start, over 3 s
def test_motor_side_is_the_drive_loads_conversion():
    """deltajax.constraints.motor_side turns cycle_profile's arm efforts into the motor loads drive_loads
    reports (peak torque, top speed)."""
    import jax.numpy as jnp

    import deltajax as dj
    from deltajax import constraints as C

    robot = dj.presets.franco2026(fixed_R=0.2, with_mass=True)
    cyc = dj.adept_cycle((0.0, 0.0, 0.45), duration=0.6, n_samples=21)
    motor = C.Motor(peak_torque=3.0, rated_torque=1.2, max_speed=600.0, corner_speed=400.0, rotor_inertia=1e-4,
                    efficiency=0.9)
    loads = C.drive_loads(robot, cyc, motor, 20.0, payload_mass=0.5)
    prof = dj.cycle_profile(C.with_drive(robot, motor, 20.0, 0.5), cyc)
    assert bool(np.all(np.asarray(prof.ok)))                       # every sample reachable: no NaN compared
    tau, om = C.motor_side(prof.tau, prof.theta_dot, motor, 20.0)
    np.testing.assert_allclose(np.max(np.abs(np.asarray(tau)), axis=0), loads.peak_torque, rtol=1e-9)
    np.testing.assert_allclose(np.max(np.abs(np.asarray(om)), axis=0), loads.max_speed, rtol=1e-9)
    assert float(jnp.max(jnp.abs(tau))) > 0


def test_report_refuses_what_it_cannot_draw(tmp_path):
    """Bad input is one ReportError line naming the file or the value, before anything compiles."""
    from deltajax.runreport import ReportError, write_report

    with pytest.raises(ReportError, match="no results file"):
        write_report(tmp_path / "nothing")
    p = tmp_path / "results.h5"
    res = dio.ResultsFile(p)              # a run killed before its verification
    res.set_attrs(ga_reconfig_stages="screen,ga")
    res.put("ga", "best_fitness", np.zeros(2), units="1")
    res.flush()
    with pytest.raises(ReportError, match="workspace_points must be an integer >= 5, got 2"):
        write_report(p, tmp_path / "r.html", workspace_points=2)
    with pytest.raises(ReportError, match=r"not finished its verification \(stages done: screen,ga\); resume it"):
        write_report(tmp_path)
    assert not (tmp_path / "report.html").exists()


@pytest.mark.slow  # a compile or a CLI start, over 3 s
def test_report_cli_bad_input_is_one_line(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    out = subprocess.run([sys.executable, "-m", "deltajax.report", str(tmp_path)], cwd=REPO, env=env,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert out.stderr.strip() == f"python -m deltajax.report: {tmp_path} holds no results.h5"


@pytest.mark.slow
def test_report_cli_writes_the_report(tmp_path, run):
    shutil.copy(run[0], tmp_path / "results.h5")
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    out = subprocess.run([sys.executable, "-m", "deltajax.report", str(tmp_path)], cwd=REPO, env=env,
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip() == f"report -> {tmp_path / 'report.html'}"
    page = (tmp_path / "report.html").read_text()
    assert page.count("Plotly.newPlot(") == 3 and "views computed in float64" in page
    assert "RuntimeWarning" not in out.stderr


@pytest.mark.slow
def test_finished_run_from_before_the_report_stage_gets_only_its_report(tmp_path, run):
    """A run killed in its report stage (the plots done, the run directory not marked complete) is resumed by
    writing report.html alone, and the stage is marked once the file is there. (A run that completed before the
    report stage existed is complete: ``python -m deltajax.report <run dir>`` writes its report.)"""
    import json

    from toy_jobs import overrides

    from deltajax.run import run_experiment

    src = run[0].parent
    d = tmp_path / "run"
    shutil.copytree(src, d)
    (d / "report.html").unlink()
    manifest = json.loads((d / "deltajax_run.json").read_text())
    manifest["status"] = "running"
    (d / "deltajax_run.json").write_text(json.dumps(manifest))
    # as a deltajax before the report stage left it: written through ResultsFile (an edited file is refused)
    stored = dio.read(d / "results.h5", verify=True)
    res = dio.ResultsFile(d / "results.h5")
    res.attrs.update({k: v for k, v in stored.attrs.items() if k != "start_time"},
                     ga_reconfig_stages="screen,ga,pareto,refine,verify,results,plots")
    for group, variables in stored.variables.items():
        if group:
            res.set_attrs(group, **stored.group_attrs[group])
            res.put_variables(group, variables)
    res.flush()
    (d / "ga_pareto.png").unlink()
    before = load(d / "results.h5")["verify"]["picks_per_min"]
    run_experiment("ga_reconfig", overrides("ga_reconfig"), run_dir=d)
    data = load(d / "results.h5")
    assert data["attrs"]["ga_reconfig_stages"].endswith(",plots,export,report")
    assert (d / "report.html").stat().st_size > 1_000_000
    assert not (d / "ga_pareto.png").exists()                          # no stage before it ran again
    np.testing.assert_array_equal(data["verify"]["picks_per_min"], before)


@pytest.mark.slow   # compiles the good test twice per case (~10 s each)
@pytest.mark.parametrize("reconfigurable", [True, False], ids=["R_per_point", "fixed_R"])
def test_workspace_figure_marks_a_point_good_where_the_full_test_holds_at_some_R(reconfigurable):
    """The figure's good points (the searches' skipping test: its necessary condition first, a point's R only until
    one is good) are the full good test's any over R, point by point."""
    import math

    import jax
    import jax.numpy as jnp

    import deltajax as dj
    from deltajax import constraints as C
    from deltajax.runreport import _good_any

    spec = C.GoodSpec(joints=C.JointModel(limit=math.radians(55), elbow_neutral=math.radians(90),
                                          platform_neutral=math.radians(40)),
                      links=C.LinkModel(forearm_radius=0.02, upper_arm_radius=0.025, clearance=0.005,
                                        plate_overhang=0.03), threshold=0.3)
    robot = dj.presets.franco2026(R_step=0.051) if reconfigurable else dj.presets.franco2026(fixed_R=0.2)
    at = robot.at if reconfigurable else robot.with_base_radius
    Rs = robot.R_samples() if reconfigurable else robot.base_radius[None]
    plate = (robot.R_max if reconfigurable else robot.base_radius) + 0.03
    g = np.linspace(-0.35, 0.35, 8)
    P = jnp.asarray(np.stack(np.meshgrid(g, g, np.linspace(0.2, 0.65, 6), indexing="ij"), -1).reshape(-1, 3))
    full = jax.vmap(lambda R: jax.vmap(lambda p: C.good_point(at(R), p, spec, plate_radius=plate).good)(P))(Rs)
    got = np.asarray(_good_any(robot, reconfigurable, Rs, P, plate, spec))
    np.testing.assert_array_equal(got, np.asarray(jnp.any(full, axis=0)))
    assert 0 < got.sum() < len(got)
