"""deltajax.tolerance (Monte Carlo over manufacturing and model tolerances) and the robust recommendation: zero
tolerances reproduce the nominal answer, an edge design holds about half the time, bigger tolerances hold less often,
NaN counts as violated, the samples are seeded, bad settings are one line, and the robust choice."""

import dataclasses

import numpy as np
import pytest

import deltajax as dj
from deltajax.config import ConfigError
from deltajax.tolerance import Tolerances, ToleranceError

from _config_helpers import compose
from _programs import kept

TOY_PROBLEM = ["experiment.design.n_R=3", "experiment.task.n_r=1", "experiment.task.n_phi=3", "experiment.task.n_z=2",
               "experiment.cycle.n_samples=11", "experiment.cycle.n_R_operating=2",
               "experiment.regular_workspace.n_r=6", "experiment.regular_workspace.n_phi=2",
               "experiment.regular_workspace.n_z=6"]
ZERO = Tolerances(length=0.0, joint_offset_deg=0.0, mass=0.0, motor=0.0)


@pytest.fixture(scope="module")
def toy():
    """(search problem, design space, genes of the baseline and two other designs) at the toy size."""
    from deltajax.config import ga_reconfig_build, robot_from_config

    cfg = compose("ga_reconfig", *TOY_PROBLEM)
    robot, recon = robot_from_config(cfg.robot)
    _, space, pb, _ = ga_reconfig_build(cfg.experiment, robot, recon)
    # the baseline (infeasible on the toy grids) and two designs the toy run verified feasible
    genes = np.stack([space.baseline_genes(), [0.1666, 0.3011, 0.6156, 0.403, 0.3265, 0.5855],
                      [0.7993, 0.8097, 0.7768, 0.4842, 0.2803, 0.603]])
    return pb, space, genes


def _nominal(pb, space, genes):
    from deltajax.optimize.workflow import batch_evaluator

    return batch_evaluator(pb, space, 4, regular=False)(genes)


@pytest.mark.slow   # compiles the designer's program for its problem (~20 CPU-s)
def test_zero_tolerances_reproduce_the_nominal_feasibility_and_picks_exactly(toy):
    pb, space, genes = toy
    nom = _nominal(pb, space, genes)
    a = dj.tolerance.analyse(pb, space, genes, ZERO, samples=6, seed=3, chunk=8)
    assert nom["feasible"].any() and not nom["feasible"].all()     # both verdicts are exercised
    np.testing.assert_array_equal(a["p_all"], nom["feasible"].astype(float))    # exactly 1 or 0
    np.testing.assert_array_equal(a["nominal_feasible"], nom["feasible"])
    np.testing.assert_array_equal(a["p_holds"], (nom["g"] <= 1e-9).astype(float))
    # a degenerate distribution: every percentile, the mean and the minimum are the nominal picks/min
    for k in ("picks_percentiles",):
        np.testing.assert_allclose(a[k], np.repeat(nom["picks_per_min"][:, None], a[k].shape[1], 1), rtol=1e-12)
    np.testing.assert_allclose(a["picks_min"], nom["picks_per_min"], rtol=1e-12)
    np.testing.assert_allclose(a["picks_mean"], nom["picks_per_min"], rtol=1e-12)
    assert np.all(a["p_reaches_nominal_picks"] == 1.0)
    # held at the nominal operating R: zero deviations leave it the design's chosen R, so the same verdicts
    z = dj.tolerance.analyse(pb, space, genes, ZERO, samples=2, seed=3, chunk=8, operating_R="nominal")
    np.testing.assert_array_equal(z["p_all"], nom["feasible"].astype(float))
    np.testing.assert_allclose(z["picks_percentiles"][:, 2], nom["picks_per_min"], rtol=1e-12)


@pytest.mark.slow   # compiles the designer's program for its problem (~20 CPU-s)
def test_a_design_on_the_cycle_rate_edge_holds_about_half_the_time(toy):
    pb, space, genes = toy
    nom = _nominal(pb, space, genes[1:2])
    edge = dataclasses.replace(pb, min_picks=float(nom["picks_per_min"][0]))   # required rate = its own rate
    a = dj.tolerance.analyse(edge, space, genes[1:2], samples=400, seed=0)
    j = list(a["constraint_names"]).index("cycle_rate")
    assert 0.4 < a["p_holds"][0, j] < 0.6
    # an independent count: the fraction of samples at or above the nominal rate, from the picks distribution
    assert a["p_holds"][0, j] == pytest.approx(a["p_reaches_nominal_picks"][0], abs=1e-12)
    assert a["p_all"][0] <= a["p_holds"][0, j]


@pytest.mark.slow   # compiles the designer's program for its problem (~20 CPU-s)
def test_bigger_tolerances_hold_less_often_on_a_design_near_an_edge(toy):
    pb, space, genes = toy
    nom = _nominal(pb, space, genes[1:2])
    near = dataclasses.replace(pb, min_picks=0.98 * float(nom["picks_per_min"][0]))
    ps = []
    for k in (0.25, 1.0, 3.0):
        t = Tolerances(length=0.2e-3 * k, joint_offset_deg=0.1 * k, mass=0.05 * k, motor=0.05 * k)
        ps.append(dj.tolerance.analyse(near, space, genes[1:2], t, samples=200, seed=1)["p_holds"][0, 3])
    assert ps[0] >= ps[1] >= ps[2] and ps[2] < ps[0] and ps[0] == 1.0


@pytest.mark.slow   # compiles the designer's program for its problem (~20 CPU-s)
def test_unreachable_counts_as_violated_and_never_as_a_number(toy):
    from deltajax.trajectory import adept_cycle

    pb, space, genes = toy
    far = dataclasses.replace(pb, task_points=pb.task_points + np.asarray([0.0, 0.0, 5.0]),
                              cycle=adept_cycle((0.0, 0.0, 5.0), duration=0.5, n_samples=11, law="poly5"))
    a = dj.tolerance.analyse(far, space, genes[:1], samples=8, seed=0)
    names = list(a["constraint_names"])
    assert a["p_all"][0] == 0.0
    for c in ("task_in_good_workspace", "passive_joints", "interference", "cycle_rate"):
        assert a["p_holds"][0, names.index(c)] == 0.0
    assert a["picks_nan"][0] == 8
    assert np.all(np.isnan(a["picks_percentiles"])) and np.isnan(a["picks_mean"][0]) and np.isnan(a["picks_min"][0])
    assert np.all(np.isnan(a["metric_percentiles"][0, names.index("passive_joints")]))
    assert np.all(a["g_percentiles"][0, names.index("passive_joints")] == 1.0)     # a full violation


def _samples(pb, space, genes, n, **kw):
    """``evaluate_designer(regular=False, **kw)`` of ``n`` tolerance samples of each design (host arrays)."""
    import jax

    from deltajax.optimize.designer import evaluate_designer

    rows = np.repeat(genes, n, axis=0)
    dev = np.tile(dj.tolerance.deviations(Tolerances(), n, 0), (len(genes), 1))

    def one(g, d):
        p, des = dj.tolerance.perturb(pb, space.decode(g), d)
        return evaluate_designer(p, des, regular=False, **kw)

    # kept across sessions (tests/_programs.py): tracing the designer's evaluation took seconds per program
    program = kept(jax.jit(jax.vmap(one)), "tolerance_evaluate", __file__, pb, space, tuple(sorted(kw.items())))
    return {k: np.asarray(v) for k, v in program(rows, dev).items()}


@pytest.mark.slow   # compiles the designer's program twice (~20 CPU-s)
def test_the_rules_first_candidates_give_the_full_answer_where_one_is_feasible(toy, monkeypatch):
    # the toy problem has two operating-R candidates: candidates=1 tests the rule's first (the faster) alone
    pb, space, genes = toy
    full = _samples(pb, space, genes, 12)
    first = _samples(pb, space, genes, 12, candidates=1)
    ok = first["resolved"]
    assert ok.any() and not ok.all()                       # both outcomes exercised
    assert np.all(full["feasible"][ok])                     # settled only where a feasible candidate was found
    # the same choice; the values of the same functions at the same inputs, compiled into another program (XLA may
    # fuse and round differently: the last bit)
    np.testing.assert_array_equal(first["R_operating"][ok], full["R_operating"][ok])
    for k, v in full.items():
        np.testing.assert_allclose(first[k][ok], v[ok], rtol=1e-13, atol=1e-15, err_msg=k)
    # the Monte Carlo settles what it can on the rule's first candidate and evaluates the rest in full: its answer is
    # that of every candidate tested at once
    monkeypatch.setattr(dj.tolerance, "FIRST_CANDIDATES", 1)
    a = dj.tolerance.analyse(pb, space, genes, samples=12, seed=0)
    monkeypatch.setattr(dj.tolerance, "FIRST_CANDIDATES", 0)
    b = dj.tolerance.analyse(pb, space, genes, samples=12, seed=0)
    for k, v in b.items():
        if isinstance(v, np.ndarray):
            np.testing.assert_allclose(a[k], v, rtol=1e-13, atol=1e-15, err_msg=k)
    for k in ("p_all", "p_holds", "picks_nan"):                # the verdicts exactly
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


@pytest.mark.slow   # compiles the designer's program three times (~30 CPU-s)
def test_a_built_robot_is_judged_by_the_size_budget_of_its_drawing(toy):
    """The rule that chooses a sample's operating R sees the size budget of the nominal (drawn) lengths: a built
    robot whose arms came out longer than a budget its drawing meets is not infeasible (every candidate was, and the
    rule fell back to the least violation: the first candidate without another violation, not the fastest)."""
    pb, space, genes = toy
    d = space.decode(genes[2]).robot
    arms = float(d.upper_arm + d.forearm)
    # a budget 1 mm under the nominal arms: every built robot exceeds it (each length within +- 0.2 mm)
    tight = dataclasses.replace(pb, max_arm_sum=arms - 1e-3)
    off = dataclasses.replace(pb, max_arm_sum=None, enabled=tuple(c for c in pb.enabled if c != "size_budget"))
    drawn = arms - 2e-3                                                        # a drawing that meets it
    built = _samples(tight, space, genes[2:3], 12)
    judged = _samples(tight, space, genes[2:3], 12, drawn_arm_sum=drawn)
    free = _samples(off, space, genes[2:3], 12)
    j = list(dj.optimize.designer.CONSTRAINT_NAMES).index("size_budget")
    assert np.all(built["g"][:, j] > 0) and np.all(judged["g"][:, j] < 0)
    np.testing.assert_array_equal(judged["R_operating"], free["R_operating"])
    np.testing.assert_array_equal(judged["picks_per_min"], free["picks_per_min"])
    # judged on the built arms every sample is infeasible, whatever its operating R (the rule's fallback branch);
    # judged on the drawing, as feasible as without the budget
    assert not built["feasible"].any() and free["feasible"].any()
    np.testing.assert_array_equal(judged["feasible"], free["feasible"])


def test_percentiles_rank_nan_as_the_worst_value():
    from deltajax.tolerance import _ranked_percentiles

    x = np.concatenate([np.arange(1.0, 91.0), np.full(10, np.nan)])     # 10 % unreachable
    p = _ranked_percentiles(x, 1, (1.0, 5.0, 50.0, 99.0))                # higher is better: NaN lowest
    assert np.isnan(p[0]) and np.isnan(p[1]) and p[2] == 40.0 and p[3] == 89.0
    p = _ranked_percentiles(x, -1, (1.0, 50.0, 95.0))                    # lower is better: NaN highest
    assert p[0] == 1.0 and p[1] == 50.0 and np.isnan(p[2])


@pytest.mark.slow   # compiles the designer's program for its problem (~20 CPU-s)
def test_samples_are_seeded_and_do_not_depend_on_the_chunking(toy):
    pb, space, genes = toy
    a = dj.tolerance.analyse(pb, space, genes[:2], samples=12, seed=5, chunk=8)
    b = dj.tolerance.analyse(pb, space, genes[:2], samples=12, seed=5, chunk=32)
    c = dj.tolerance.analyse(pb, space, genes[:2], samples=12, seed=6, chunk=8)
    np.testing.assert_array_equal(a["deviations"], b["deviations"])
    np.testing.assert_array_equal(a["p_holds"], b["p_holds"])
    np.testing.assert_allclose(a["picks_percentiles"], b["picks_percentiles"], rtol=1e-12)
    assert not np.array_equal(a["deviations"], c["deviations"])
    assert a["seed"] == 5 and a["samples"] == 12 and a["tolerances"]["length"] == 0.2e-3
    # the stated distributions: uniform inside +- tolerance, normal with the tolerance as 3 sigma
    d = dj.tolerance.deviations(Tolerances(), 20000, 0)
    assert np.all(np.abs(d) <= Tolerances().scale()) and np.abs(d[:, 0]).max() > 0.99 * 0.2e-3
    n = dj.tolerance.deviations(Tolerances(distribution="normal"), 20000, 0)
    assert np.std(n[:, 0]) == pytest.approx(0.2e-3 / 3, rel=0.03)


@pytest.mark.parametrize("override, match", [
    ("experiment.tolerance.samples=0", r"^experiment\.tolerance\.samples must be in \[1, 10000000\], got 0$"),
    ("experiment.tolerance.length_mm=-0.2", r"^experiment\.tolerance\.length_mm must be in \[0, 10\] mm, got -0\.2 mm$"),
    ("experiment.tolerance.distribution=triangle", r"^experiment\.tolerance\.distribution must be one of normal, "),
    ("experiment.tolerance.mass_percent=nan", r"^experiment\.tolerance\.mass_percent must be a finite number"),
    ("experiment.robust.probability=1.5", r"^experiment\.robust\.probability must be in \(0, 1\], got 1\.5$"),
    ("experiment.robust.confirm_seed=0", r"^experiment\.robust\.confirm_seed=0 must differ from experiment\.tolerance"),
    ("experiment.verify.certify_doublings=-1", r"^experiment\.verify\.certify_doublings must be in \[0, 4\], "
                                               r"got -1$"),
    ("experiment.robust.margins.joint_deg=-1", r"^experiment\.robust\.margins\.joint_deg must be in \[0, 180\) deg, "
                                               r"got -1\.0 deg$"),
    ("experiment.robust.margins.joint_deg=55", r"^experiment\.robust\.margins\.joint_deg must be < "
                                               r"experiment\.joints\.limit_deg \(55 deg\), got 55\.0 deg$"),
    ("experiment.robust.margins.index=0.7", r"^experiment\.robust\.margins\.index must be < 1 - "
                                            r"experiment\.good_workspace\.threshold \(0\.7; "),
    ("experiment.robust.margins.motor_percent=100", r"^experiment\.robust\.margins\.motor_percent must be in "
                                                    r"\[0, 100\) %, got 100\.0 %$"),
])
def test_bad_tolerance_settings_are_one_line_naming_the_field(override, match):
    from deltajax.config import ga_reconfig_settings

    extra = ["experiment.robust.enabled=true"] if "robust" in override else []
    with pytest.raises(ConfigError, match=match) as e:
        ga_reconfig_settings(compose("ga_reconfig", override, *extra).experiment)
    assert "\n" not in str(e.value)


def test_robust_needs_the_tolerance_stage_and_tolerances_are_checked():
    from deltajax.config import ga_reconfig_settings

    with pytest.raises(ConfigError, match=r"^experiment\.robust\.enabled=true needs the tolerance stage"):
        ga_reconfig_settings(compose("ga_reconfig", "experiment.robust.enabled=true",
                                     "experiment.tolerance.enabled=false").experiment)
    with pytest.raises(ToleranceError, match=r"^Tolerances\.mass must be a number in \[0, 0\.5\], got -0\.1$"):
        Tolerances(mass=-0.1)
    with pytest.raises(ToleranceError, match=r"^Tolerances\.distribution must be one of uniform, normal"):
        Tolerances(distribution="triangle")


def _fake(p):
    return {"p_all": np.asarray([p])}


def test_robust_choice_applies_the_rule_among_designs_that_hold_and_confirms_with_fresh_samples():
    from deltajax.optimize.robust import robust_choice

    # five feasible designs on one front (objective 0: primary, minimised); the rule: the best primary
    F = np.asarray([[-5.0, -1.0], [-4.0, -2.0], [-3.0, -3.0], [-2.0, -4.0], [-1.0, -5.0]])
    p_sel = {0: 0.5, 1: 0.995, 2: 0.999, 3: 1.0, 4: 1.0}
    p_new = {0: 0.5, 1: 0.97, 2: 0.995, 3: 1.0, 4: 1.0}           # row 1 passes the selection, not the fresh check
    calls = []

    def analyse_rows(rows, seed):
        calls.append((tuple(rows), seed))
        return _fake((p_sel if seed == 0 else p_new)[rows[0]])

    def rule(nd):
        return int(nd[np.argmin(F[nd, 0])])

    rc = robust_choice(analyse_rows, F, np.ones(5, bool), rule, 0.99, 0, 1, 10)
    assert rc.chosen == 2 and rc.checked == (0, 1, 2)
    assert rc.p_selection == (0.5, 0.995, 0.999) and np.isnan(rc.p_confirm[0]) and rc.p_confirm[1:] == (0.97, 0.995)
    assert calls == [((0,), 0), ((1,), 0), ((1,), 1), ((2,), 0), ((2,), 1)]
    # a dominated design joins the front once the designs dominating it are set aside
    F2 = np.asarray([[-5.0, -5.0], [-4.0, -4.0]])
    rc = robust_choice(lambda rows, seed: _fake({0: 0.2, 1: 1.0}[rows[0]]), F2, np.ones(2, bool),
                       lambda nd: int(nd[np.argmin(F2[nd, 0])]), 0.99, 0, 1, 10)
    assert rc.chosen == 1
    # none holds: exhausted; the cap stops early
    rc = robust_choice(lambda rows, seed: _fake(0.5), F, np.ones(5, bool), rule, 0.99, 0, 1, 10)
    assert rc.chosen == -1 and rc.exhausted and len(rc.checked) == 5
    rc = robust_choice(lambda rows, seed: _fake(0.5), F, np.ones(5, bool), rule, 0.99, 0, 1, 2)
    assert rc.chosen == -1 and not rc.exhausted and len(rc.checked) == 2
    # infeasible designs are never chosen
    rc = robust_choice(lambda rows, seed: _fake(1.0), F, np.asarray([False, False, True, True, True]), rule, 0.99,
                       0, 1, 10)
    assert rc.chosen == 2


class _Ctx:
    """What the job's stage functions use of the run context: log lines and progress bars."""

    def __init__(self):
        self.lines = []

    def log(self, msg):
        self.lines.append(msg)

    def progress(self, total=None, desc=""):
        class Bar:
            def update(self, n):
                pass

            def close(self):
                pass

        return Bar()


@pytest.mark.slow
def test_robust_mode_at_toy_size_picks_a_design_that_holds_in_fresh_samples(toy_run, tmp_path):
    # the toy run's verified candidates, the stage run again with tolerances large enough (2 mm, 1 deg) that its
    # nominal recommendation fails in some samples: the robust one must hold in >= 99 % of a fresh Monte Carlo
    from toy_jobs import TOY

    from deltajax.config import ga_reconfig_build, robot_from_config
    from deltajax.io import ResultsFile, load
    from deltajax.jobs.ga_reconfig import _tolerance
    from deltajax.jobs.stages import State
    from deltajax.optimize.designer import DESIGN_SENSE
    from deltajax.optimize.workflow import designer_problem

    path = toy_run("ga_reconfig")
    V = load(path)["verify"]
    cfg = compose("ga_reconfig", *TOY["ga_reconfig"], "experiment.robust.enabled=true",
                  "experiment.tolerance.length_mm=2.0", "experiment.tolerance.joint_offset_deg=1.0",
                  "experiment.tolerance.samples=200")
    robot, recon = robot_from_config(cfg.robot)
    s, space, _, _ = ga_reconfig_build(cfg.experiment, robot, recon)
    objs = list(s.objectives.names)
    res, ctx = ResultsFile(tmp_path / "results.h5"), _Ctx()
    _tolerance(State(ctx=ctx, res=res, path=path, s=s, space=space, objs=objs, jp=objs.index(s.objectives.primary),
                     sense=np.asarray([DESIGN_SENSE[o] for o in objs], float)))
    res.flush()
    out = load(tmp_path / "results.h5")
    T, a = out["tolerance"], out["tolerance"]["robust"]["attrs"]
    roles = list(T["role"])
    rec, nominal = T["verify_row"][roles.index("recommended")], T["verify_row"][roles.index("nominal_recommended")]
    assert a["robust_recommended"] != "none" and rec != nominal          # the nominal one does not hold
    assert T["p_all"][roles.index("nominal_recommended")] < 0.99 <= T["p_all"][roles.index("recommended")]
    assert a["p_robust_confirm"] >= 0.99 and out["verify"]["attrs"]["recommended"] == rec
    assert out["verify"]["attrs"]["recommended_nominal"] == nominal
    assert V["feasible"][rec] == 1
    # an independent check of the choice: another seed, more samples
    space_v = dataclasses.replace(space, n_R=s.verify.n_R)
    tol = Tolerances(length=2e-3, joint_offset_deg=1.0)
    check = dj.tolerance.analyse(designer_problem(s, fine=True), space_v, V["genes"][rec], tol, samples=500, seed=77)
    assert check["p_all"][0] >= 0.97
    assert any("robustness costs" in line or "robust recommendation" in line for line in ctx.lines)


@pytest.mark.slow
def test_margins_tighten_every_constraint_by_the_stated_amount_and_the_nominal_problem_keeps_them(toy):
    # experiment.robust.margins: the search's problem with each constraint tightened by exactly its margin; the
    # nominal problem (the tolerance stage's) and a run with zero margins are the problem as stated
    import math

    from deltajax.config import ga_reconfig_build, robot_from_config
    from deltajax.optimize.workflow import batch_evaluator, designer_problem, required_margins
    from deltajax.tracing import content_key

    pb, space, genes = toy
    cfg = compose("ga_reconfig", *TOY_PROBLEM, "experiment.robust.margins.joint_deg=1.5",
                  "experiment.robust.margins.clearance_mm=2.0", "experiment.robust.margins.index=0.02",
                  "experiment.robust.margins.motor_percent=10")
    robot, recon = robot_from_config(cfg.robot)
    s, _, pb_t, _ = ga_reconfig_build(cfg.experiment, robot, recon)
    assert required_margins(s) == {"index": 0.02, "joint_deg": 1.5, "clearance_mm": 2.0, "motor_percent": 10.0}
    nom = designer_problem(s, nominal=True)
    assert content_key(nom) == content_key(pb)                      # zero margins: the stated problem
    assert float(pb_t.joints.limit) == pytest.approx(math.radians(s.joints.limit_deg - 1.5), rel=1e-15)
    assert float(pb_t.good.joints.limit) == float(pb_t.joints.limit)
    assert float(pb_t.good.threshold) == pytest.approx(float(pb.good.threshold) + 0.02, rel=1e-15)
    assert float(pb_t.good.links.clearance) == pytest.approx(float(pb.links.clearance) + 2e-3, rel=1e-15)
    for k in ("peak_torque", "rated_torque"):
        assert float(getattr(pb_t.motor, k)) == pytest.approx(0.9 * float(getattr(pb.motor, k)), rel=1e-15)
    assert float(pb_t.motor.max_speed) == float(pb.motor.max_speed)
    # evaluated: the margins move by exactly the stated amounts where both choose the same operating R, the
    # derated motor runs the cycle slower, and a design feasible with margins is feasible as stated
    mt, mn = batch_evaluator(pb_t, space, 4, regular=False)(genes), _nominal(pb, space, genes)
    same = np.asarray(mt["R_operating"]) == np.asarray(mn["R_operating"])
    assert same.any()
    np.testing.assert_allclose(np.asarray(mt["joint_margin_deg"])[same],
                               np.asarray(mn["joint_margin_deg"])[same] - 1.5, atol=1e-9)
    np.testing.assert_allclose(np.asarray(mt["interference_margin"])[same],
                               np.asarray(mn["interference_margin"])[same] - 2e-3, atol=1e-12)
    np.testing.assert_array_equal(np.asarray(mt["task_index_min"])[same], np.asarray(mn["task_index_min"])[same])
    assert np.all(np.asarray(mt["picks_per_min"])[same] < np.asarray(mn["picks_per_min"])[same])
    assert np.all(~np.asarray(mt["feasible"], bool) | np.asarray(mn["feasible"], bool))


def test_a_continued_run_may_change_the_budget_but_not_the_margins():
    from deltajax.config.ga_reconfig_run import problem_differences

    old = {"experiment": {"ga": {"generations": 10}, "robust": {"enabled": False}}, "seed": 0}
    zero = {"experiment": {"ga": {"generations": 40}, "robust": {"enabled": True, "margins": {
        "index": 0.0, "joint_deg": 0.0, "clearance_mm": 0.0, "motor_percent": 0.0}}}, "seed": 3}
    assert problem_differences(old, zero) == []        # a run made before margins existed: the same problem
    one = {"experiment": {"robust": {"margins": {"joint_deg": 1.0}}}}
    assert problem_differences(zero, one) == [("experiment.robust.margins.joint_deg", 0.0, 1.0)]
    assert problem_differences(old, one) == [("experiment.robust.margins.joint_deg", "<unset>", 1.0)]


def test_export_of_a_run_without_a_feasible_design_says_so_and_writes_no_files(tmp_path):
    from deltajax.io import ResultsFile
    from deltajax.jobs.ga_reconfig import _export
    from deltajax.jobs.stages import State

    res = ResultsFile(tmp_path / "results.h5")
    res.set_attrs("summary", recommended="none")        # what the results stage stores when nothing is feasible
    res.flush()
    ctx = _Ctx()
    ctx.run_dir = tmp_path
    _export(State(ctx=ctx, path=tmp_path / "results.h5", space=None, s=None))
    assert ctx.lines == ["export: no recommended design (no feasible candidate on the fine grids), so no "
                         "datasheets and no model files"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.h5"]
