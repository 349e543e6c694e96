"""Progress bars: grid bars start with the computed total and are never reset; jobs show progress over their
stages."""

import pytest


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


@pytest.mark.slow
def test_jobs_show_progress_over_their_stages(tmp_path, capfd):
    from deltajax.run import run_experiment

    run_experiment("indices_examples", ["progress=true", "plots=false", "experiment.R_step=1e-3"],
                   run_dir=tmp_path / "ie")
    err = capfd.readouterr().err.replace("\r", "\n")
    assert "indices_examples: 100%" in err and "6/6" in err

