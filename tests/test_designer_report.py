"""What the main job shows a designer: the GA convergence series in picks/min (best of each generation and a
best so far consistent with it, the initial population's best where it came from there), the table's change
column with its better/worse verdict, each design's feasibility on the table's own (fine) grids."""

import math

import numpy as np
import pytest

from deltajax.io import load
from deltajax.jobs import designer_report as R
from deltajax.plots import convergence_series

BASE = 120.0   # baseline picks/min on the search grids: the GA's fitness is -picks / BASE


def _ga_group(gen_best_picks, best_so_far_picks, feasible):
    """A staged ``ga`` group of a picks/min-only GA: fitness -picks / BASE, 1e3 + violation when infeasible."""
    gp = np.asarray(gen_best_picks, float)
    feas = np.asarray(feasible, bool)
    gbf = np.where(feas, -gp / BASE, 1e3 + 0.5)
    best = np.asarray([-p / BASE if np.isfinite(p) else 1e3 + 0.5 for p in best_so_far_picks])
    return {"best_fitness": best, "gen_best_fitness": gbf, "gen_best_picks_per_min": gp,
            "gen_best_feasible": feas.astype(np.uint8), "gen_feasible_fraction": np.linspace(0.2, 0.8, len(gp)),
            "attrs": {"objective": "primary objective picks_per_min", "baseline_primary": BASE}}


def test_convergence_in_picks_per_min_with_the_initial_populations_best():
    """Generation 1's best (130) is below the best so far (150: a seed of the initial population); generation 3
    beats it (160). The series says so: from_initial for generations 1-2, and best so far >= each generation's."""
    G = _ga_group([130.0, 140.0, 160.0, 155.0], [150.0, 150.0, 160.0, 160.0], [True] * 4)
    c = convergence_series(G, picks_per_fitness=BASE)
    np.testing.assert_array_equal(c["generation"], [1, 2, 3, 4])
    np.testing.assert_allclose(c["gen_best"], [130.0, 140.0, 160.0, 155.0])
    np.testing.assert_allclose(c["best_so_far"], [150.0, 150.0, 160.0, 160.0], rtol=1e-12)
    assert list(c["from_initial"]) == [True, True, False, False]
    assert c["initial_best"] == pytest.approx(150.0, rel=1e-12) and c["baseline"] == BASE
    assert np.all(c["best_so_far"] >= np.fmax.accumulate(c["gen_best"]) * (1 - 1e-12))


def test_convergence_infeasible_generations_and_other_objectives():
    """Infeasible generation bests are NaN, not a 1e3 penalty in picks/min; without the fitness-to-picks scale
    (another objective) the initial population's best is unknown (NaN) and still flagged."""
    G = _ga_group([90.0, 140.0, 135.0], [math.nan, 140.0, 140.0], [False, True, True])
    c = convergence_series(G, picks_per_fitness=BASE)
    assert np.isnan(c["gen_best"][0]) and np.isnan(c["best_so_far"][0])
    np.testing.assert_allclose(c["best_so_far"][1:], [140.0, 140.0])
    assert not np.any(c["from_initial"]) and np.isnan(c["initial_best"])
    G = _ga_group([130.0, 160.0], [150.0, 160.0], [True, True])
    c = convergence_series(G, picks_per_fitness=None)
    assert list(c["from_initial"]) == [True, False] and np.isnan(c["best_so_far"][0])
    assert c["best_so_far"][1] == 160.0 and np.isnan(c["baseline"])


@pytest.mark.parametrize("x, y, sense, text", [
    (100.0, 121.7, -1, "+21.7 % better"),    # higher is better, went up
    (100.0, 90.0, -1, "-10.0 % worse"),
    (2.0, 1.5, 1, "-25.0 % better"),          # lower is better (e.g. utilisation), went down
    (2.0, 2.5, 1, "+25.0 % worse"),
    (0.2, 0.25, 0, "+25.0 %"),                # describes the design: no verdict
    (1.0, 1.0, -1, "0.0 % same"),
    (-0.006, 0.007, -1, "better"),            # a margin from negative to positive: no %, still a verdict
    (0.0, -1.0, -1, "worse"), (-1.0, -1.0, -1, "same"), (-1.0, 2.0, 0, "-"), (1.0, math.nan, -1, "-")])
def test_change_column_says_better_or_worse(x, y, sense, text):
    assert R.change_text(x, y, sense) == text


class _Log:
    def __init__(self):
        self.lines = []

    def log(self, msg):
        self.lines.append(msg)


def _summary_data(base_feasible=True):
    metrics = ["picks_per_min", "peak_utilisation", "gear_ratio"]
    S = {"metric_name": metrics, "metric_units": ["1/min", "1", "1"],
         "direction": ["higher is better", "lower is better", "describes the design"],
         "baseline": np.array([100.0, 0.8, 10.0]), "recommended": np.array([121.7, 0.9, 12.0]),
         "baseline_fixed_R": np.array([100.0, 0.8, 10.0]), "recommended_fixed_R": np.array([121.7, 0.9, 12.0]),
         "parameter_name": ["upper_arm"], "parameter_units": ["m"], "baseline_params": np.array([0.2]),
         "recommended_params": np.array([0.22]), "attrs": {"recommended": "pareto_0", "rule_text": "best"}}
    V = {"design_name": ["baseline", "ga_best", "pareto_0"], "feasible": np.array([base_feasible, 1, 1], np.uint8),
         "constraint_names": ["task_in_good_workspace", "cycle_rate"],
         "constraint_values": np.array([[0.0 if base_feasible else 0.3, -0.1], [-0.1, -0.1], [-0.2, 0.0]])}
    return {"summary": S, "verify": V}


def test_printed_table_marks_better_worse_and_fine_grid_feasibility():
    ctx = _Log()
    R.print_summary(ctx, _summary_data())
    rows = {line.split()[0]: line for line in ctx.lines if line.startswith("  ") and len(line.split()) > 2}
    assert "+21.7 % better" in rows["picks_per_min"]
    assert "+12.5 % worse" in rows["peak_utilisation"]
    assert "+20.0 %" in rows["gear_ratio"] and "better" not in rows["gear_ratio"].split("|")[0]
    text = "\n".join(ctx.lines)
    assert "baseline on the fine grids: feasible" in text and "recommended on the fine grids: feasible" in text
    ctx = _Log()
    R.print_summary(ctx, _summary_data(base_feasible=False))
    assert "baseline on the fine grids: infeasible, violates task_in_good_workspace" in "\n".join(ctx.lines)


@pytest.mark.slow   # the session's toy run of the main job (shared with tests/test_ga_reconfig.py)
def test_toy_run_convergence_matches_the_gas_own_record(toy_run):
    """On a real run: the best so far in picks/min is the GA's own best fitness converted (fitness = -picks /
    |baseline picks|), never below a generation's best, and the best generation's so far once one beat the
    initial population."""
    data = load(toy_run("ga_reconfig"))
    G = data["ga"]
    scale = abs(float(G["attrs"]["baseline_primary"]))
    c = convergence_series(G, picks_per_fitness=scale)
    best = np.asarray(G["best_fitness"], float)
    ok = best < 1e3
    np.testing.assert_allclose(c["best_so_far"][ok], -best[ok] * scale, rtol=1e-9)
    assert np.all(np.isnan(c["best_so_far"][~ok]))
    fin = np.isfinite(c["gen_best"]) & ok
    assert np.all(c["best_so_far"][fin] >= c["gen_best"][fin] * (1 - 1e-12))
    own = ~c["from_initial"] & ok
    np.testing.assert_allclose(c["best_so_far"][own], np.fmax.accumulate(c["gen_best"])[own], rtol=1e-12)


@pytest.mark.slow   # the same shared toy run
def test_toy_run_log_has_no_warning_that_the_verified_table_contradicts(toy_run):
    """The baseline's search-grid violations are a note that defers to the verified table, and the table states
    the baseline's feasibility on its own (fine) grids."""
    text = (toy_run("ga_reconfig").parent / "run.log").read_text()
    assert "warning: the baseline violates" not in text
    for line in text.splitlines():
        if "baseline violates" in line:
            assert "on the coarse search grids" in line and "verified table at the end" in line
            assert "authoritative" in line
    # the table is the certified one (the certify stage), and says so per design
    assert "baseline certified: " in text and "recommended certified: feasible" in text


def test_certify_lines_say_which_designs_regular_workspace_is_certified():
    nan = float("nan")
    Cg = {"row": np.array([0, 3]), "design_name": np.array(["baseline", "pareto_1"], dtype=object),
          "regular_volume": np.array([0.022, 0.0279]), "regular_volume_change": np.array([0.0011, nan]),
          "peak_utilisation_change": np.array([1e-7, 2e-5]), "doublings": np.array([1, 2]),
          "regular_certified": np.array([1, 0], np.uint8),
          "attrs": {"tolerance_regular_volume": 0.005, "tolerance_peak_utilisation": 1e-4}}
    base, left = R.certify_lines(Cg)
    assert base == ("  certified baseline: regular volume 22 L (doubling the density moved it 0.11 %, tolerance 0.5 %);"
                    " every figure within its tolerance")
    assert left == ("  certified pareto_1: task and cycle figures (regular volume 27.9 L: the verification's; the rule "
                    "moved on before its rays were doubled); every figure within its tolerance")
    Cg["peak_utilisation_change"][1] = 3e-4          # a figure that did not settle is named, the regular one never
    assert R.certify_lines(Cg)[1].endswith("; NOT within tolerance: peak_utilisation")
