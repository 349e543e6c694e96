"""Plots a reader can use: robust colour limits, shared scales, the benchmark figure."""

import numpy as np
import pytest

from deltajax import plots


def test_robust_limits_ignore_a_few_near_singular_values():
    v = np.concatenate([np.linspace(0.5, 1.2, 10_000), [7.5, 9.0, np.nan]])
    lo, hi = plots.robust_limits(v)
    assert 0.5 <= lo < 0.52 and 1.18 < hi <= 1.2


def test_index_slices_share_one_robust_colour_scale_and_axes():
    x = y = np.linspace(-0.4, 0.4, 41)
    rng = np.random.default_rng(0)
    a = rng.uniform(0.5, 1.2, (2, 41, 41))
    a[0, 0, 0] = 50.0  # one near-singular point
    fig = plots.index_slices(x, y, [0.3, 0.4], {"A": a, "B": a * 0.9}, label="omega_v")
    axes = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]
    meshes = [ax.collections[0] for ax in axes]
    assert len(meshes) == 4 and len({m.get_clim() for m in meshes}) == 1
    assert meshes[0].get_clim()[1] < 2.0  # not stretched to 50 by one point
    (cbar,) = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    assert "percentile" in cbar.get_ylabel()
    assert len({ax.get_xlim() for ax in axes}) == 1 and len({ax.get_ylim() for ax in axes}) == 1


def test_workspace_3d_panels_share_limits_and_colour_scale():
    x = y = np.linspace(-0.4, 0.4, 21)
    z = np.linspace(0.0, 0.6, 16)
    X, Y, Z = np.meshgrid(x, y, z, indexing="ij")
    big = X ** 2 + Y ** 2 + (Z - 0.35) ** 2 < 0.09
    small = X ** 2 + Y ** 2 + (Z - 0.35) ** 2 < 0.03
    fig = plots.workspace_3d(x, y, z, {"big": big, "small": small})
    axes = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]
    assert len(axes) == 2
    for get in ("get_xlim", "get_ylim", "get_zlim"):
        assert getattr(axes[0], get)() == getattr(axes[1], get)()
    assert axes[0].collections[0].norm.vmin == axes[1].collections[0].norm.vmin


def test_bench_rates_plot():
    fig = plots.bench_rates({"numpy": 1e5, "jax fast float64": 5e5}, "numpy")
    ax = fig.axes[0]
    assert ax.get_xscale() == "log" and "higher is better" in ax.get_xlabel()
    assert any("x5" in t.get_text() for t in ax.texts)


def test_actuator_lines_stay_distinguishable_when_equal():
    import matplotlib.pyplot as plt

    t = np.linspace(0, 1, 50)
    tau = np.stack([np.sin(t), np.cos(t), np.sin(t)], axis=1)  # actuators 1 and 3 coincide
    fig, ax = plt.subplots()
    plots.actuator_lines(ax, t, tau)
    l1, _, l3 = ax.get_lines()
    assert (l1.get_linestyle(), l1.get_linewidth()) != (l3.get_linestyle(), l3.get_linewidth())
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["actuator 1", "actuator 2", "actuator 3"]
    plt.close(fig)


def test_bench_rates_from_staged_results(tmp_path):
    from deltajax.io import ResultsFile

    res = ResultsFile(tmp_path / "r.h5")
    res.put("bench", "numpy_rate", 1e5, units="1/s")
    res.put("bench/float64", "rate", 4e5, units="1/s")
    res.put("bench/float64", "compile_time", 3.0, units="s")
    fig = plots.bench_rates_from_results(res)
    labels = [t.get_text() for t in fig.axes[0].get_yticklabels()]
    assert labels == ["numpy", "float64 jax fast"]


def test_dynamics_cycle_plots_draw_actuators_in_distinguishable_styles():
    """dynamics_cycle's torque, Adept-profile and platform plots go through plots.actuator_lines: actuators 1
    and 3 of the GA motion (symmetric in them) no longer hide one behind the other."""
    import types

    import matplotlib

    matplotlib.use("Agg")
    figs = []
    t = np.linspace(0.0, 1.0, 30)
    three = np.stack([np.sin(t), np.cos(t), np.sin(t)], axis=1)  # 1 and 3 equal
    prof = types.SimpleNamespace(t=t, tau=three, theta_dot=three, theta_ddot=three, p=three, p_dot=three,
                                 p_ddot=three, R_dot=np.zeros_like(t), force_R=np.zeros_like(t))
    figs.append(("torques", plots.cycle_torques(prof, "title")))
    half = types.SimpleNamespace(t=t, tau=0.5 * three, theta_dot=0.5 * three, theta_ddot=0.5 * three)
    figs.append(("r_adept_profiles", plots.adept_profiles("r", prof, half, 0.5)))
    figs.append(("r_ga_motion_platform", plots.cycle_platform(prof, "title")))
    assert [n for n, _ in figs] == ["torques", "r_adept_profiles", "r_ga_motion_platform"]
    for _name, fig in figs:
        for ax in fig.axes:
            lines = ax.get_lines()
            styles = {(ln.get_color(), str(ln.get_linestyle()), ln.get_linewidth()) for ln in lines[:3]}
            assert len(lines) >= 3 and len(styles) == 3, _name
        assert fig.axes[0].get_legend() is not None or fig.legends
        matplotlib.pyplot.close(fig)
    adept = figs[1][1]
    for row in range(3):  # nominal vs minimum cycle time: compared on one y scale per row
        left, right = adept.axes[2 * row], adept.axes[2 * row + 1]
        assert left.get_ylim() == right.get_ylim()


def test_index_slices_ticks_stay_inside_the_panels():
    """Neighbouring panels' end tick labels ('0.4' and '-0.4') must not run into each other."""
    x = y = np.linspace(-0.4, 0.4, 41)
    a = np.ones((1, 41, 41))
    fig = plots.index_slices(x, y, [0.3], {"A": a, "B": a}, label="omega_v")
    for ax in [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]:
        for ticks, (lo, hi) in ((ax.get_xticks(), ax.get_xlim()), (ax.get_yticks(), ax.get_ylim())):
            assert len(ticks) >= 3 and all(lo < t < hi for t in ticks), (ticks, lo, hi)
            assert min(ticks) - lo > 0.05 * (hi - lo) and hi - max(ticks) > 0.05 * (hi - lo)


def test_workspace_3d_titles_give_the_volume_and_ticks_stay_inside():
    x = y = np.linspace(-0.4, 0.4, 21)
    z = np.linspace(0.0, 0.6, 16)
    X, Y, Z = np.meshgrid(x, y, z, indexing="ij")
    mask = X ** 2 + Y ** 2 + (Z - 0.35) ** 2 < 0.09
    fig = plots.workspace_3d(x, y, z, {"A": mask})
    (ax,) = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]
    vol = mask.sum() * 0.04 * 0.04 * 0.04
    assert f"V = {vol:.4g} m$^3$" in ax.get_title() and f"{mask.sum()} reachable grid points" in ax.get_title()
    for ticks, (lo, hi) in ((ax.get_xticks(), ax.get_xlim()), (ax.get_yticks(), ax.get_ylim())):
        assert len(ticks) >= 3 and min(ticks) - lo > 0.05 * (hi - lo) and hi - max(ticks) > 0.05 * (hi - lo)


def test_reconfig_motion_landscape_legend_shows_the_white_fixed_line():
    import matplotlib
    import matplotlib.colors as mcolors

    matplotlib.use("Agg")
    t, Rg = np.linspace(0.0, 0.5, 6), np.linspace(0.15, 0.45, 7)
    figs = [plots.motion_landscape("adept", t, Rg, np.full((6, 7), 0.6), {"fixed": np.full(6, 0.27)}, "k_tilde")]
    (ax,) = [a for a in figs[0].axes if a.get_label() != "<colorbar>"]
    frame = mcolors.to_rgb(ax.get_legend().get_frame().get_facecolor())
    line = mcolors.to_rgb(ax.get_lines()[0].get_color())
    assert np.abs(np.subtract(frame, line)).sum() > 0.5  # the legend's handle differs from its background
    matplotlib.pyplot.close(figs[0])


@pytest.mark.slow
def test_only_run_selects_a_matplotlib_backend():
    """One plotting home, one backend choice: no module of the package but run.py (the CLI, before any job runs)
    calls matplotlib.use, and importing deltajax.plots (every figure module) leaves the user's backend alone."""
    import pathlib
    import re
    import subprocess
    import sys

    import deltajax

    root = pathlib.Path(deltajax.__file__).parent
    callers = sorted(str(f.relative_to(root)) for f in root.rglob("*.py")
                     if re.search(r"matplotlib\s*\.\s*use\s*\(|\bmpl\s*\.\s*use\s*\(", f.read_text()))
    assert callers == ["run.py"], callers
    # a fresh interpreter: the backend a user selected (here "svg") survives importing every figure module
    code = ("import matplotlib; matplotlib.use('svg'); import deltajax.plots, deltajax.plots.core, "
            "deltajax.plots.workspace, deltajax.plots.bench, deltajax.plots.dynamics, deltajax.plots.motion, "
            "deltajax.plots.designer, deltajax.jobs.designer_report, deltajax.jobs.reconfig_motion; "
            "import matplotlib.pyplot as plt; fig = deltajax.plots.bench_rates({'a': 1.0, 'b': 2.0}, 'a'); "
            "print(matplotlib.get_backend()); plt.close(fig)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**__import__("os").environ, "MPLBACKEND": ""}).stdout.split()
    assert out[-1].lower() == "svg", out


def test_ga_pareto_draws_the_floor_and_the_floor_step_designs():
    # the floor rule's line (1.2 x the baseline's regular volume, maximised) and the floor step's verified designs
    # are what a reader needs to see why the recommendation is where it is
    from types import SimpleNamespace

    from deltajax.jobs.designer_report import floor_line
    from deltajax.plots.designer import ga_pareto

    names = ["baseline", "ga_best", "pareto_0", "pareto_1", "pareto_2", "floor_0", "floor_1"]
    pk = np.array([195.0, 210.0, 217.0, 216.0, 214.0, 216.5, 205.0])
    vol = np.array([0.0265, 0.025, 0.030, 0.032, 0.035, 0.0322, 0.033])
    V = {"picks_per_min": pk, "regular_volume": vol, "regular_volume_fixed": vol / 4,
         "feasible": np.ones(len(names), np.int8), "front": np.array([2, 5, 4]), "design_name": names,
         "F": np.stack([-pk / pk[0], -vol / vol[0]], axis=1), "attrs": {"recommended": 5, "hypervolume": 1.6}}
    s = SimpleNamespace(objectives=SimpleNamespace(primary="picks_per_min", names=("picks_per_min", "regular_volume")), recommend="floor", recommend_floor=1.2, recommend_band=0.02)
    objs, units = ["picks_per_min", "regular_volume"], {"picks_per_min": "1/min", "regular_volume": "m^3"}
    fig = ga_pareto(V, objs, s, units, floor=floor_line(V, objs, s))
    ax = fig.axes[0]
    labels = {ln.get_label(): ln for ln in ax.get_lines()}
    floor = labels["floor: 1.2 x the baseline's regular_volume"]
    assert np.allclose(floor.get_ydata(), 1.2 * 0.0265 * 1e3)              # plotted in litres
    steps = labels["floor step (descents at the floor, verified)"]
    np.testing.assert_allclose(steps.get_xdata(), pk[5:])
    s.recommend = "knee"                                                     # another rule: no floor line
    assert floor_line(V, objs, s) is None
    fig = ga_pareto(V, objs, s, units, floor=floor_line(V, objs, s))
    assert not any(str(ln.get_label()).startswith("floor:") for ln in fig.axes[0].get_lines())


def test_ga_pareto_of_a_continued_run_marks_the_earlier_front_and_finds_the_ga_best_by_name():
    # experiment.continue_from: the earlier run's front is carried ("earlier_*"), and when the GA kept one of those
    # designs as its best, no "ga_best" row exists (verify attrs ga_best_design names it)
    from types import SimpleNamespace

    from deltajax.plots.designer import ga_pareto

    names = ["baseline", "pareto_0", "pareto_1", "earlier_pareto_0", "earlier_floor_0"]
    pk = np.array([195.0, 214.0, 216.6, 216.0, 216.4])
    vol = np.array([0.0265, 0.034, 0.0322, 0.033, 0.0323])
    V = {"picks_per_min": pk, "regular_volume": vol, "regular_volume_fixed": vol / 4,
         "feasible": np.ones(len(names), np.int8), "front": np.array([2, 1]), "design_name": names,
         "attrs": {"recommended": 2, "hypervolume": 1.6, "ga_best_design": "earlier_floor_0"}}
    s = SimpleNamespace(objectives=SimpleNamespace(primary="picks_per_min", names=("picks_per_min", "regular_volume")), recommend="floor", recommend_floor=1.2, recommend_band=0.02)
    fig = ga_pareto(V, ["picks_per_min", "regular_volume"], s, {"picks_per_min": "1/min", "regular_volume": "m^3"})
    labels = {ln.get_label(): ln for ln in fig.axes[0].get_lines()}
    np.testing.assert_allclose(labels["GA best on picks_per_min"].get_xdata(), [216.4])
    np.testing.assert_allclose(labels["the earlier run's front (experiment.continue_from; its verified values)"]
                               .get_xdata(), [216.0, 216.4])
    np.testing.assert_allclose(labels["candidates, feasible, dominated"].get_xdata(), [216.0])  # GA best apart


def test_reconfig_motion_torque_methods_stay_distinguishable_where_they_agree():
    import matplotlib

    matplotlib.use("Agg")
    from deltajax.jobs import reconfig_motion as job

    t = np.linspace(0.0, 1.0, 20)
    tau = np.stack([np.sin(t), np.cos(t), t], axis=1)
    figs = [plots.motion_torques("adept", t, {m: {"tau": tau} for m in job.METHODS})]
    for ax in figs[0].axes:
        styles = {(str(ln.get_linestyle()), ln.get_linewidth()) for ln in ax.get_lines()}
        assert len(ax.get_lines()) == len(job.METHODS) == len(styles)
    matplotlib.pyplot.close(figs[0])


def _drawn(*args, **kwargs):
    """A figure function or savefig patched in where ``plots=false`` must draw nothing."""
    raise AssertionError("a figure was built with plots=false")


def test_the_main_jobs_figures_are_not_drawn_with_plots_false(monkeypatch):
    """``plots=false``: the main job's plots stage and its datasheets build no figure (an A4 page takes ~1 s to
    lay out) -- not only write none."""
    from types import SimpleNamespace

    from deltajax.jobs import datasheet as DJ
    from deltajax.jobs import designer_report as R

    for name in ("ga_convergence", "ga_pareto", "datasheet_page"):
        monkeypatch.setattr(plots, name, _drawn)
    ctx = SimpleNamespace(plots=False, progress=lambda it, **kw: it, log=lambda msg: None, savefig=_drawn,
                          results=SimpleNamespace(flush=lambda: None))
    R.plots(ctx, {}, ("picks_per_min",), None)
    sheet = SimpleNamespace(working_diameter=0.5, working_height=0.1, reachable_volume=0.1, max_payload=1.0,
                            rows=lambda: [])
    monkeypatch.setattr(DJ, "datasheet", lambda *args, **kwargs: sheet)
    monkeypatch.setattr(DJ, "save", lambda *args: None)
    DJ.write(ctx, [("design", None, None, 20.0, None)])


@pytest.mark.slow   # the toy dynamics job in-process (~5 s warm)
def test_the_dynamics_and_motion_jobs_draw_nothing_with_plots_false(monkeypatch, tmp_path):
    """``plots=false``: no figure of experiment=dynamics_cycle is built (the toy run, every figure function
    patched to fail), nor of experiment=reconfig_motion's plots stage."""
    from types import SimpleNamespace

    from toy_jobs import overrides

    from deltajax.jobs import reconfig_motion
    from deltajax.run import run_experiment

    for name in ("adept_profiles", "cycle_platform", "cycle_torques", "motion_landscape", "motion_profiles",
                 "motion_torques"):
        monkeypatch.setattr(plots, name, _drawn)
    path = run_experiment("dynamics_cycle", overrides("dynamics_cycle", "plots=false"), run_dir=tmp_path / "run")
    assert path.exists() and not list(path.parent.glob("*.png"))
    done = []
    st = SimpleNamespace(s=None, cases={"adept": None}, ctx=SimpleNamespace(plots=False, savefig=_drawn),
                         bar=SimpleNamespace(update=done.append))
    reconfig_motion._plot_case(st, "adept")
    assert done == [1]
