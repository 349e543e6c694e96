"""The floor step (deltajax.optimize.floor.solve_floor): which descents it runs and which iterates it verifies,
on a stand-in problem whose answer is known in closed form (no compile: the descent and the evaluators are
replaced by exact NumPy functions of the genes). The step on the real problem is checked end to end by
tests/test_ga_reconfig.py (the toy job)."""

import types

import numpy as np
import pytest

import deltajax.optimize.floor as FL
from deltajax.config import ConfigError
from deltajax.optimize.workflow import floor_limits, objective_matrix, recommend

OBJS = ["picks_per_min", "regular_volume"]
SENSE = np.array([-1.0, -1.0])                 # both maximised
STEP = 0.05                                    # the stand-in descent: gene 0 grows by STEP per step


def _metrics(X, vol_factor):
    X = np.atleast_2d(X)
    return {"picks_per_min": 200.0 + 20.0 * X[:, 0], "regular_volume": vol_factor * (0.040 - 0.02 * X[:, 0]),
            "feasible": (X[:, 1] < 0.9).astype(np.uint8)}


def _fake_descent(calls):
    def descent_paths(pb, space, genes, objs, scale, primary, *, steps, learning_rate, penalty):
        calls.append(np.array(genes))
        k = np.arange(steps + 1)[None, :, None] * np.eye(genes.shape[1])[0] * STEP
        return np.zeros((len(genes), steps)), np.clip(genes[:, None, :] + k, 0.0, 1.0)
    return descent_paths


@pytest.fixture
def problem(monkeypatch):
    calls = []
    monkeypatch.setattr(FL, "descent_paths", _fake_descent(calls))
    space = types.SimpleNamespace(dim=2)
    search = lambda X: _metrics(X, 1.0)         # noqa: E731
    fine = lambda X: _metrics(X, 0.98)           # the fine grids measure 2 % less volume
    cand = np.array([[0.0, 0.0], [0.10, 0.0], [0.05, 0.0], [0.60, 0.0], [0.20, 0.95]])   # baseline first
    mv = fine(cand)
    scale_v = SENSE / np.abs(np.array([mv[o][0] for o in OBJS]))
    scale = SENSE / np.abs(np.array([search(cand[:1])[o][0] for o in OBJS]))
    Fv = objective_matrix(mv, OBJS, scale_v)
    front = np.array([1, 2, 3])                 # row 3 is below the floor, row 4 infeasible (not on the front)
    return types.SimpleNamespace(space=space, search=search, fine=fine, cand=cand, Fv=Fv, front=front,
                                 scale=scale, scale_v=scale_v, calls=calls)


def _solve(p, floor, **kw):
    lim = floor_limits(2, 0, floor, SENSE)
    return FL.solve_floor(None, p.space, p.cand, p.Fv, p.front, OBJS, p.scale, "picks_per_min", lim,
                          evaluate=p.search, evaluate_cheap=p.search, evaluate_fine=p.fine, steps=4, **kw)


def test_floor_limits_and_the_rule_use_the_same_floor():
    np.testing.assert_allclose(floor_limits(3, 1, 1.25, [-1, -1, 1]), [-1.25, np.inf, 0.8])
    # recommend(rule="floor") takes the best primary among front points at or above the floor
    F = np.array([[-1.0, -1.0], [-1.10, -1.19], [-1.05, -1.21], [-1.02, -1.40]])
    assert recommend(F, np.arange(4), "floor", 0, floor=1.2) == 2


def test_solve_floor_reaches_the_floor_from_every_start_that_meets_it(problem):
    # fine volume 0.98 (0.04 - 0.02 g0) >= 0.81 x the fine baseline's 0.98 x 0.04  <=>  g0 <= 0.38
    ticks = []
    fo = _solve(problem, 0.81, rounds=4, n_fine=4, progress=ticks.append)
    assert sum(ticks) == 5                      # 4 rounds + the fine verification (the bar ends full)
    np.testing.assert_array_equal(np.sort(fo.starts), [1, 2])          # the front points at or above the floor
    # each path continued past its first round (4 steps) until it crossed the floor at g0 = 0.38: the best
    # iterate is the last one below 0.38, then that path's previous one (the margin)
    g0 = fo.genes[:, 0]
    assert g0[0] == pytest.approx(0.35) and g0[1] == pytest.approx(0.35)
    assert fo.step[0] in (5, 6) and max(fo.step) > 4
    assert sorted(np.round(g0, 6))[:2] == [0.30, 0.30]
    # the prediction (search x the start's fine/search ratio) is exact here, and every verified design meets the
    # floor on the fine grids and is better than its start
    Ff = objective_matrix(fo.metrics, OBJS, problem.scale_v)
    np.testing.assert_allclose(fo.predicted, Ff, rtol=1e-12)
    assert np.all(Ff[:, 1] <= -0.81 + 1e-12)
    assert np.all(Ff[:, 0] < problem.Fv[fo.start, 0])
    # the recommendation over the verified designs plus the step's is the floor's optimum among them
    F = np.concatenate([problem.Fv, Ff])
    assert recommend(F, np.arange(len(F)), "floor", 0, floor=0.81) >= len(problem.cand)


def test_solve_floor_stops_after_its_rounds_and_finds_nothing_without_a_start(problem):
    ticks = []
    fo = _solve(problem, 0.81, rounds=1, n_fine=8, progress=ticks.append)
    assert len(problem.calls) == 1 and max(fo.step) == 4                 # one round: the paths' ends
    assert sum(ticks) == 2                                               # the round and the fine verification
    assert fo.genes[:, 0].max() == pytest.approx(0.30)
    problem.calls.clear()
    ticks.clear()
    fo = _solve(problem, 1.5, rounds=4, n_fine=8, progress=ticks.append)  # no front point meets this floor
    assert len(fo.starts) == 0 and len(fo.genes) == 0 and problem.calls == [] and sum(ticks) == 5


@pytest.mark.slow
def test_floor_solve_config_is_checked_before_anything_runs():
    from hydra import compose, initialize_config_dir

    from deltajax.config import ga_reconfig_settings
    from deltajax.run import CONFIG_DIR

    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(config_name="config", overrides=["experiment=ga_reconfig"])
        s = ga_reconfig_settings(cfg.experiment)
        assert (s.floor_solve.enabled, s.floor_solve.rounds, s.floor_solve.candidates) == (True, 4, 8)
        # another rule with the step on is valid (the job skips the step and says so): a rule override alone works
        assert ga_reconfig_settings(compose(config_name="config", overrides=[
            "experiment=ga_reconfig", "experiment.recommend=knee"]).experiment).recommend == "knee"
        for ov, msg in [(["experiment.floor_solve.rounds=0"], "experiment.floor_solve.rounds"),
                        (["+experiment.floor_solve.steps=3"], "experiment.floor_solve: unknown keys steps")]:
            bad = compose(config_name="config", overrides=["experiment=ga_reconfig", *ov])
            with pytest.raises(ConfigError, match=msg):
                ga_reconfig_settings(bad.experiment)
