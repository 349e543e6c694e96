"""The main job end to end at toy size: reruns into one directory (complete, resumed, no-op), kill-and-resume
bit-identical at every stage, Pareto on/off, feasibility of every front point, config validation."""

import logging
import math

import h5py
import numpy as np
import pytest

from deltajax.config import ConfigError
from deltajax.io import ResultsFile, load
from deltajax.rundir import restage
from deltajax.run import run_experiment
from deltajax.rundir import RunDirError

from toy_jobs import GA_STAGES_OFF, overrides

TOY = overrides("ga_reconfig")  # tests/toy_jobs.py: the suite's one toy size of the main job
VOLATILE = {"start_time", "end_time", "wall_time_s", "git_commit"}


def _datasets(path):
    """{group/name: array} of every dataset, and {group: attrs} without timings."""
    out, attrs = {}, {}
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                out[name] = obj[()]
            else:
                attrs[name] = {k: v for k, v in obj.attrs.items() if not k.startswith("time_")}
        f.visititems(visit)
        attrs["/"] = {k: v for k, v in f.attrs.items() if k not in VOLATILE}
    return out, attrs


def _assert_same(a, b):
    da, aa = _datasets(a)
    db, ab = _datasets(b)
    assert sorted(da) == sorted(db)
    for k in da:
        np.testing.assert_array_equal(da[k], db[k], err_msg=k)
    for g in aa:
        assert sorted(aa[g]) == sorted(ab[g]), g
        for k in aa[g]:
            if k not in ("stopped_after", "resumed_from"):
                np.testing.assert_array_equal(aa[g][k], ab[g][k], err_msg=f"{g}@{k}")


@pytest.fixture(scope="module")
def full_run(toy_run):
    return toy_run("ga_reconfig")  # the session's uninterrupted toy run (shared with tests/test_jobs.py)


@pytest.mark.slow
def test_toy_run_front_feasible_summary_and_units(full_run):
    data = load(full_run)
    V = data["verify"]
    front = np.asarray(V["front"]).reshape(-1)
    assert np.all(V["feasible"][front] == 1)                       # every reported front point is feasible
    assert np.all(V["constraint_values"][front] <= 1e-9)
    S = data["summary"]
    assert list(S["metric_name"])[:2] == ["picks_per_min", "regular_volume"]
    assert S["attrs"]["recommended"] in list(V["design_name"])
    rec = list(V["design_name"]).index(S["attrs"]["recommended"])
    # the summary pairs the recommended design's numbers with its own parameters
    np.testing.assert_array_equal(S["recommended_params"], V["params"][rec])
    # the summary's figures are the certified ones (group certify), for the certified recommendation
    Cg = data["certify"]
    assert Cg["attrs"]["recommended_name"] == S["attrs"]["recommended"] and V["attrs"]["recommended"] == rec
    rows = list(np.asarray(Cg["row"]).reshape(-1))
    assert 0 in rows and rec in rows and Cg["certified"][rec] == 1 and Cg["certified"][0] == 1
    j = rows.index(rec)
    np.testing.assert_allclose(S["recommended"][0], Cg["picks_per_min"][j])
    np.testing.assert_allclose(S["recommended"][1], Cg["regular_volume"][j])
    assert Cg["feasible"][j] == 1
    # certified at twice the density: the change is stated, with the tolerances as attributes
    assert Cg["attrs"]["tolerance_regular_volume"] == 0.005 and Cg["attrs"]["tolerance_joint_margin_deg"] == 0.05
    assert np.all(Cg["peak_utilisation_change"] >= 0)
    # the baseline's and the recommendation's regular workspace certified (rays doubled); a design the rule left
    # after its task and cycle figures were certified keeps the verification's regular figures, their change NaN
    reg = np.asarray(Cg["regular_certified"]).astype(bool)
    assert reg[rows.index(0)] and reg[j]
    assert np.all(np.isfinite(Cg["regular_volume_change"][reg])) and np.all(np.isnan(Cg["regular_volume_change"][~reg]))
    np.testing.assert_array_equal(Cg["regular_volume"][~reg], np.asarray(V["regular_volume"])[np.asarray(rows)[~reg]])
    # doubled again while a figure moved more than its tolerance: the density reached is stored, within the cap
    nd, cap = np.asarray(Cg["doublings"]), int(Cg["attrs"]["max_extra_doublings"])
    assert np.all((nd >= 1) & (nd <= 1 + cap)) and np.all(Cg["converged"][nd < 1 + cap] == 1)
    first = (np.asarray(Cg["cycle_samples"]) - 1) / 2.0 ** nd + 1          # the first density's cycle samples
    assert np.all(first == first[0]) and first[0] > 1
    # the verification found the regular workspace by the same rays: the first density is the verified figure
    np.testing.assert_allclose(Cg["regular_volume_first"], np.asarray(V["regular_volume"])[rows], rtol=1e-9)
    # every verified design carries its margins in units; the summary holds both designs' and the log prints them
    n = len(V["design_name"])
    assert Cg["margin_joint_margin_deg"].shape == (n,) and Cg["units"]["margin_interference_clearance_mm"] == "mm"
    np.testing.assert_allclose(S["recommended_margins"][list(S["margin_name"]).index("task_index_margin")],
                               Cg["task_index_min"][j] - 0.3)
    cons = [i for i, k in enumerate(S["margin_name"]) if k != "regular_volume_over_floor"]   # the rule's, not a limit
    rm = np.asarray(S["recommended_margins"])[cons]
    assert np.all(rm[np.isfinite(rm)] >= -1e-9)                 # the certified recommendation meets every constraint
    log = (full_run.parent / "run.log").read_text()
    assert "margins (>= 0" in log and "interference_clearance_mm" in log and "certified baseline:" in log
    # fixed-R variant: same task at the same R, only the regular workspace differs
    np.testing.assert_allclose(S["recommended_fixed_R"][0], Cg["picks_per_min"][j])
    np.testing.assert_allclose(S["recommended_fixed_R"][1], Cg["regular_volume_fixed"][j])
    assert S["recommended_fixed_R"][1] <= S["recommended"][1] + 1e-15   # R per point can only add
    assert V["units"]["picks_per_min"] == "1/min" and V["units"]["regular_volume"] == "m^3"
    assert "ga/checkpoint" in {k for k in _datasets(full_run)[1]}
    assert data["attrs"]["ga_reconfig_stages"] == ("screen,ga,pareto,refine,verify,certify,tolerance,results,plots,"
                                                   "export,report")
    # the tolerance stage: the baseline and the recommendation, their probability printed with the summary
    T = data["tolerance"]
    roles = list(T["role"])
    assert roles == ["baseline", "recommended"] and T["attrs"]["samples"] == 200
    assert list(T["design_name"]) == ["baseline", S["attrs"]["recommended"]]
    assert np.all((T["p_all"] >= 0) & (T["p_all"] <= T["p_holds"].min(axis=1)))
    assert T["units"]["picks_percentiles"] == "1/min" and T["picks_percentiles"].shape == (2, 5)
    assert S["attrs"]["recommended_p_all_constraints_hold"] == T["p_all"][1]
    assert list(T["frozen_R"]["role"]) == roles and T["frozen_R"]["p_all"].shape == (2,)   # at the nominal R
    assert f"recommended ({S['attrs']['recommended']}): every constraint holds in {100 * T['p_all'][1]:.1f} %" in log
    # the refined winners: accepted only if feasible and no objective worse, and verified like every candidate
    R = data["refine"]
    acc = np.asarray(R["accepted"]).astype(bool)
    assert np.all(R["F_after"][acc] <= R["F_before"][acc] + 1e-12)
    assert np.all(R["F_after"][~acc] == R["F_before"][~acc])
    assert sum(n.startswith("refined_") for n in V["design_name"]) == int(acc.sum())
    # the GA was seeded by the screen's best: its best is at least as good as the screen's best
    ga = data["ga"]["attrs"]
    ga_best_picks = -float(ga["fitness_best"]) * float(ga["baseline_primary"])    # fitness = -picks / |baseline|
    assert ga_best_picks >= float(data["screen"]["top_primary"][0]) * (1 - 1e-12)
    assert "recommend_rule_text" in V["attrs"] and "1.2 x the verified baseline" in V["attrs"]["recommend_rule_text"]


def _logged(caplog):
    text = caplog.text
    caplog.clear()
    return text


@pytest.mark.slow
def test_rerun_three_times_into_one_dir(full_run, tmp_path, caplog, monkeypatch):
    # 1: killed after 2 generations; 2: resumed inside the GA, then killed after the verify stage (before the
    # summary is written); 3: resumed and completed; 4: a no-op that says so (the run's lines go through the
    # "deltajax" logger: console and run.log). Both kills in one directory: one job run, not two (this test and
    # test_kill_and_resume_is_bit_identical each ran the whole toy job, ~90 s cold each)
    import deltajax.jobs.designer_report as job

    caplog.set_level(logging.INFO, logger="deltajax")
    run_experiment("ga_reconfig", TOY + ["experiment.stop_after=2"], run_dir=tmp_path)
    assert "stopped after 2 generations" in _logged(caplog)
    real = job.summary

    def killed(*args, **kw):
        raise KeyboardInterrupt

    monkeypatch.setattr(job, "summary", killed)
    with pytest.raises(KeyboardInterrupt):
        run_experiment("ga_reconfig", TOY, run_dir=tmp_path)
    assert "resuming the GA from generation 2" in _logged(caplog)
    # killed after the verify, certify and tolerance stages: every stage up to them is in the file, the summary is not
    assert load(tmp_path / "results.h5")["attrs"]["ga_reconfig_stages"] == ("screen,ga,pareto,refine,verify,certify,"
                                                                           "tolerance")
    monkeypatch.setattr(job, "summary", real)
    p = run_experiment("ga_reconfig", TOY, run_dir=tmp_path)
    snap = tmp_path / "after_resume.h5"
    snap.write_bytes(p.read_bytes())
    run_experiment("ga_reconfig", TOY, run_dir=tmp_path)
    out = _logged(caplog)
    assert "complete results of this ga_reconfig run; nothing to do" in out and "starting the GA" not in out
    _assert_same(snap, p)
    # killed inside the GA and after the verify stage, resumed each time: bit-identical to the uninterrupted run
    _assert_same(full_run, p)
    assert load(p)["ga"]["checkpoint"]["attrs"]["generations_done"] == 4   # the checkpoint survives


#: pareto off with the refine stage on, in weighted mode: one shared run (``toy_run``) serves both
#: test_pareto_disabled_runs_end_to_end[True] and test_weighted_mode_runs_and_says_so (each was its own run,
#: ~125 s cold each); pareto off in the default mode is the GA_STAGES_OFF run
WEIGHTED_NO_PARETO = ("experiment.objectives.mode=weighted", "experiment.pareto.enabled=false")


@pytest.mark.slow
@pytest.mark.parametrize("refine", [True, False])
def test_pareto_disabled_runs_end_to_end(toy_run, refine):
    if refine:
        p = toy_run("ga_reconfig", *WEIGHTED_NO_PARETO)
    else:
        p = toy_run("ga_reconfig", *GA_STAGES_OFF)  # the session's one run with the optional stages off
    data = load(p)
    assert "pareto" not in data and ("refine" in data) == refine
    names = list(data["verify"]["design_name"])
    n_ref = int(np.sum(data["refine"]["accepted"])) if refine else 0
    n_floor = sum(n.startswith("floor_") for n in names)      # the floor step is off in the GA_STAGES_OFF run
    assert names == (["baseline", "ga_best"] + [f"refined_{i}" for i in range(n_ref)]
                     + [f"floor_{i}" for i in range(n_floor)])
    assert ("floor" in data) == (n_floor > 0) and (n_floor == 0 or refine)
    assert data["summary"]["attrs"]["recommended"] in names + ["none"]
    stages = data["attrs"]["ga_reconfig_stages"].split(",")
    assert ("refine" in stages) == refine and "pareto" not in stages


@pytest.mark.slow
def test_pareto_on_refine_and_screen_off(tmp_path, caplog, monkeypatch):
    # the same run covers the floor step's skip path at no extra cost: on, but another recommend rule (knee), so
    # the job skips it with a log line (the floor step off is the GA_STAGES_OFF run); the certify stage's path
    # where the recommendation turns out infeasible once certified (made so here: the run's one feasible candidate,
    # so no design is recommended); and the job's progress bars (on here) each end full, n == total
    import deltajax.optimize.certify as CE
    from deltajax.run import RunContext

    bars, make = [], RunContext.progress
    monkeypatch.setattr(RunContext, "progress", lambda self, *a, **kw: bars.append(make(self, *a, **kw)) or bars[-1])
    certified, certify = [], CE.certify_design

    def certify_design(*a, **kw):
        certified.append(dict(certify(*a, **kw)))
        if len(certified) == 2:                           # the baseline, then the first recommendation
            certified[-1]["joint_margin_deg"] = -1.0
        return certified[-1]

    monkeypatch.setattr(CE, "certify_design", certify_design)
    caplog.set_level(logging.INFO, logger="deltajax")
    p = run_experiment("ga_reconfig", TOY + ["experiment.refine.enabled=false", "experiment.screen.enabled=false",
                                             "experiment.floor_solve.enabled=true", "experiment.recommend=knee",
                                             "progress=true"],
                       run_dir=tmp_path)
    assert len(certified) == 2 and "certified pareto_0: " in caplog.text and "infeasible once certified" in caplog.text
    assert "certified recommendation: none (the verification's was pareto_0)" in caplog.text
    assert len(bars) >= 5 and all(b.n == b.total for b in bars), [(b.desc, b.n, b.total) for b in bars]
    data = load(p)
    assert data["summary"]["attrs"]["recommended"] == "none"
    assert "refine" not in data and "screen" not in data and "pareto" in data
    assert "floor step: skipped (it solves for the floor rule's answer; experiment.recommend=knee)" in caplog.text
    assert "floor" not in data and not any(str(n).startswith("floor_") for n in data["verify"]["design_name"])
    V = data["verify"]
    front = np.asarray(V["front"]).reshape(-1)
    assert np.all(V["feasible"][front] == 1) and np.all(V["constraint_values"][front] <= 1e-9)


@pytest.mark.slow
def test_a_different_config_into_a_finished_dir_is_refused(full_run):
    before = full_run.read_bytes()
    with pytest.raises(RunDirError, match=r"other settings: experiment.cycle.payload=0.5 there, 1.0 now"):
        run_experiment("ga_reconfig", TOY + ["experiment.cycle.payload=1.0"], run_dir=full_run.parent)
    assert full_run.read_bytes() == before


@pytest.mark.parametrize("override, match", [
    ("experiment.pareto.population_size=0", "experiment.pareto.population_size must be >= 4, got 0"),
    ("experiment.joints.limit_deg=nan", "experiment.joints.limit_deg must be a finite number"),
    ("experiment.motor.rated_torque=10", "experiment.motor.rated_torque=10.0 N m must be <="),
    ("experiment.objectives.primary=volume", "experiment.objectives.primary must be one of"),
    ("experiment.objectives.names=[picks_per_min,volume]", "unknown objective 'volume'"),
    ("+experiment.task.radius=0.1", "experiment.task.radius is not a setting of experiment.task; valid keys: diameter"),
    # the settings' declaration is also the structured config Hydra composes against (config.readers.schema_of)
    ("experiment.task.n_r=abc", "experiment.task.n_r: Value 'abc' of type 'str' could not be converted to Integer"),
    ("experiment.task.radius=0.1", "valid keys: diameter, height, n_phi, n_r, n_z, z_top"),  # no + needed
    ("experiment.cycle.n_samples=48", "must be odd"),
    ("experiment.verify.rw_n_r=0", "experiment.verify.rw_n_r must be >= 2, got 0"),
    ("experiment.regular_workspace.z_min=0.9", "z_min=0.9 m must be < z_max"),
    ("experiment.task.z_top=0.9", "experiment.task"),
    ("experiment.design.bounds.gear_ratio=[0,10]", "gear_ratio: must be > 0"),
    ("experiment.ga.generations=-1", "experiment.ga.generations"),
    ("experiment.constraints.max_arm_sum=-1", "experiment.constraints.max_arm_sum must be > 0"),
    ("experiment.cycle.law=linear", "experiment.cycle.law must be one of"),
    ("experiment.continue_from=5", "experiment.continue_from must be null or the path of a finished ga_reconfig"),
])
def test_bad_config_is_one_line_naming_the_field(override, match, tmp_path):
    with pytest.raises(ConfigError, match=match.replace("[", r"\[").replace("(", r"\(")) as ei:
        run_experiment("ga_reconfig", TOY + [override], run_dir=tmp_path)
    assert "\n" not in str(ei.value)
    assert not (tmp_path / "results.h5").exists()


def test_knee_point_of_a_convex_front():
    from deltajax.optimize.designer import knee_point

    t = np.linspace(0, 1, 21)
    F = np.stack([t, (1 - np.sqrt(t)) ** 2], axis=1)     # symmetric front: knee at f1 = f2 = 1/4
    k = knee_point(F)
    assert math.isclose(F[k, 0], 0.25, abs_tol=0.05) and math.isclose(F[k, 1], 0.25, abs_tol=0.05)
    assert knee_point(F[:1]) == 0


@pytest.mark.slow
def test_weighted_mode_runs_and_says_so(toy_run):
    p = toy_run("ga_reconfig", *WEIGHTED_NO_PARETO)  # shared with test_pareto_disabled_runs_end_to_end[True]
    # the run's lines (the "deltajax" logger) are in its run.log, whichever test ran it
    assert "weighted sum 1 x picks_per_min + 1 x regular_volume" in (p.parent / "run.log").read_text()
    assert "weighted sum" in load(p)["ga"]["attrs"]["objective"]


@pytest.mark.slow
def test_floor_step_designs_are_verified_and_can_only_improve_the_recommendation(full_run):
    """The floor step (experiment.floor_solve, on by default): its designs are verified like every candidate,
    each descended from a verified front point that meets the floor, and the recommendation over all verified
    designs is at least as good on the rule's terms as over the designs before the step."""
    from deltajax.optimize.designer import DESIGN_SENSE
    from deltajax.optimize.pareto import non_dominated
    from deltajax.optimize.workflow import floor_limits, recommend

    data = load(full_run)
    V, Fl = data["verify"], data["floor"]
    names = list(V["design_name"])
    rows = np.asarray(Fl["verify_row"]).reshape(-1)
    assert len(rows) >= 1 and [names[i] for i in rows] == [f"floor_{i}" for i in range(len(rows))]
    assert rows[0] == len(names) - len(rows)                        # appended after every other candidate
    objs = list(V["attrs"]["objectives"].split(","))
    sense = np.asarray([DESIGN_SENSE[o] for o in objs])
    F, feas = np.asarray(V["F"]), np.asarray(V["feasible"]).astype(bool)
    floor = float(V["attrs"]["recommend_floor"])
    lim = floor_limits(len(objs), 0, floor, sense)
    for st in Fl["start"]:                                            # each start met the floor on the fine grids
        assert np.all(F[names.index(st)] <= lim)
    assert np.all(np.asarray(Fl["step"]) >= 1)

    def rule(n):                                                      # the floor rule over the first n designs
        ok = np.flatnonzero(feas[:n] & np.all(np.isfinite(F[:n]), axis=1))
        return recommend(F, ok[non_dominated(F[ok])], "floor", 0, floor=floor, sense=sense)

    rec, before = rule(len(names)), rule(rows[0])
    assert rec == int(V["attrs"]["recommended"])
    if np.all(F[before] <= lim):                                     # the rule's answer before the step met the floor
        assert np.all(F[rec] <= lim) and F[rec, 0] <= F[before, 0]


@pytest.mark.slow
def test_a_continued_run_keeps_the_earlier_answer_and_can_only_improve_it(full_run, tmp_path, caplog):
    """experiment.continue_from (more budget for a finished run): the earlier run's verified front joins the
    candidates with its stored metrics (bit for bit), so the recommendation is never one the earlier run's
    recommendation dominates and the verified front's hypervolume never drops — here with another seed and a
    *smaller* GA, where an independent run would land anywhere."""
    from deltajax.optimize.designer import DESIGN_SENSE

    with caplog.at_level(logging.INFO, logger="deltajax"):
        p = run_experiment("ga_reconfig", TOY + [f"experiment.continue_from={full_run.parent}", "seed=1",
                                                 "experiment.ga.generations=2"], run_dir=tmp_path / "more")
    old, new = load(full_run)["verify"], load(p)["verify"]
    assert new["attrs"]["continued_from"] == str(full_run)
    names, old_names = list(new["design_name"]), list(old["design_name"])
    objs = old["attrs"]["objectives"].split(",")
    for r in np.asarray(old["front"]).reshape(-1):                     # every earlier front point, as verified there
        i = names.index(f"earlier_{old_names[r]}")
        np.testing.assert_array_equal(new["genes"][i], old["genes"][r])
        for k in objs + ["feasible", "constraint_values", "R_operating"]:
            np.testing.assert_array_equal(new[k][i], old[k][r], err_msg=k)
    assert new["attrs"]["ga_best_design"] in names                  # "ga_best", or the carried design it kept
    assert (p.parent / "ga_pareto.png").exists()
    carried = [i for i, n in enumerate(names) if n.startswith("earlier_")]
    for i in set(range(1, len(names))) - set(carried):              # no design verified twice under two names
        assert not np.any(np.all(new["genes"][carried] == new["genes"][i], axis=1)), names[i]
    sense = np.asarray([DESIGN_SENSE[o] for o in objs])
    a = np.asarray([old[o][int(old["attrs"]["recommended"])] for o in objs]) * -sense   # larger is better
    b = np.asarray([new[o][int(new["attrs"]["recommended"])] for o in objs]) * -sense
    assert not (np.all(a >= b) and np.any(a > b)), (a, b)
    assert new["attrs"]["hypervolume"] >= old["attrs"]["hypervolume"]
    assert "continued run: the earlier recommendation earlier_" in caplog.text
    # a continued run continued again (its search stages off): every name unique, the first run's front still there
    p2 = run_experiment("ga_reconfig", TOY + [f"experiment.continue_from={p}", *GA_STAGES_OFF],
                        run_dir=tmp_path / "again")
    again = load(p2)["verify"]
    names2 = list(again["design_name"])
    assert len(set(names2)) == len(names2)
    assert {f"earlier_{n}" for n in np.asarray(new["design_name"])[np.asarray(new["front"]).reshape(-1)]} <= set(names2)
    assert again["attrs"]["hypervolume"] >= new["attrs"]["hypervolume"]


@pytest.mark.slow
def test_continue_from_refuses_another_problem_an_unfinished_run_and_its_own_dir(full_run, tmp_path):
    """One line naming experiment.continue_from (and the differing setting), before anything is computed."""
    cases = [([f"experiment.continue_from={full_run.parent}", "experiment.cycle.payload=1.0"],
              r"experiment.continue_from: .* is a run of another problem \(experiment.cycle.payload=0.5 there, "
              r"1.0 now\)"),
             ([f"experiment.continue_from={tmp_path / 'nowhere'}"], "is neither a run directory"),
             ([f"experiment.continue_from={tmp_path / 'own'}", "fresh=true"], "is this run's own directory")]
    unfinished = ResultsFile(tmp_path / "unfinished.h5")  # written as by a run stopped after its GA stage
    restage(unfinished, full_run)
    unfinished.set_attrs(ga_reconfig_stages="screen,ga")
    unfinished = unfinished.flush()
    cases.append(([f"experiment.continue_from={unfinished}"], r"has not finished its verification \(stages done: "
                                                               r"screen,ga\)"))
    own = tmp_path / "own"
    own.mkdir()
    (own / "results.h5").write_bytes(full_run.read_bytes())
    for n, (extra, match) in enumerate(cases):
        run_dir = own if "own" in extra[0] else tmp_path / f"run{n}"
        before = (own / "results.h5").read_bytes()
        with pytest.raises((ConfigError, RunDirError), match=match) as ei:
            run_experiment("ga_reconfig", TOY + extra, run_dir=run_dir)
        assert "\n" not in str(ei.value)
        assert (own / "results.h5").read_bytes() == before
        assert not run_dir.exists() or run_dir == own                 # refused before the directory is claimed
