"""Design space, evosax GA loop (bounds, reproducibility, bit-identical kill-and-resume), the recommendation
rules and the designer's optax refinement. Tiny sizes: population 8, 16 generations, coarse samples."""


import os

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import deltajax as dj
from deltajax.optimize import DesignSpace, DesignSpaceError, GAConfig, GAError, reflect_unit, run_ga

BOUNDS = {"R_min": [0.10, 0.20], "R_max": [0.30, 0.55], "platform_radius": [0.04, 0.09],
          "upper_arm": [0.14, 0.30], "forearm": [0.30, 0.55]}


def _space(n_R=4):
    return DesignSpace.from_bounds(dj.presets.franco2026(with_mass=True), BOUNDS, n_R=n_R)


SPACE = _space()


# -- design space ----------------------------------------------------------------------------------------------

@given(st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64)), min_size=5, max_size=5))
def test_every_gene_vector_decodes_inside_the_bounds(genes):
    g = jnp.asarray(genes, dtype=jnp.float64)
    u = reflect_unit(g)
    assert bool(jnp.all((u >= 0) & (u <= 1)))
    p = np.asarray(SPACE.to_params(g))
    assert np.all(p >= np.asarray(SPACE.lower)) and np.all(p <= np.asarray(SPACE.upper))
    d = SPACE.decode(g)  # traced-free decode validates the robot (GeometryError would fail the test)
    assert float(d.R_min) < float(d.R_max)
    assert 0.14 <= float(d.robot.upper_arm) <= 0.30


def test_reflection_is_identity_inside_and_mirror_outside():
    g = jnp.asarray([0.0, 0.25, 1.0, 1.25, -0.25, 2.5, -3.75])
    np.testing.assert_allclose(reflect_unit(g), [0.0, 0.25, 1.0, 0.75, 0.25, 0.5, 0.25], atol=1e-15)


def test_baseline_round_trip_and_mass_scaling():
    g = SPACE.baseline_genes()
    assert SPACE.baseline_inside()
    d = SPACE.decode(jnp.asarray(g))
    np.testing.assert_allclose([float(d.R_min), float(d.R_max), float(d.robot.upper_arm)], [0.138, 0.495, 0.2],
                               rtol=1e-12)
    g2 = np.array(g)
    g2[3] = 1.0  # L1 = 0.30 = 1.5 x baseline
    d2 = SPACE.decode(jnp.asarray(g2))
    np.testing.assert_allclose(float(d2.robot.mass.upper_arm_mass), 1.5895 * 1.5, rtol=1e-12)
    np.testing.assert_allclose(float(d2.robot.mass.forearm_mass), 0.0408, rtol=1e-12)


@pytest.mark.parametrize("bounds, match", [
    ({"upper_arm": [0.3, 0.2]}, "experiment.design.bounds.upper_arm"),
    ({"wheel": [0, 1]}, "unknown design parameter"),
    ({"R_min": [0.1, 0.4], "R_max": [0.3, 0.5]}, "disjoint"),
    ({"base_radius": [0.1, 0.3]}, "R_min/R_max"),
    ({"forearm": [-0.1, 0.3]}, "lengths must be > 0"),
])
def test_bad_bounds_name_the_field(bounds, match):
    with pytest.raises(DesignSpaceError, match=match):
        DesignSpace.from_bounds(dj.presets.franco2026(), bounds, prefix="experiment.design.bounds")


# -- GA loop ---------------------------------------------------------------------------------------------------

def sphere(genes):
    f = jnp.sum((genes - 0.3) ** 2, axis=1)
    inside = jnp.all((genes >= 0) & (genes <= 1), axis=1)
    return f, {"feasible": inside, "f": f}


CFG = GAConfig(algorithm="simple_ga", population_size=8, generations=16, checkpoint_every=8, sigma=0.2, seed=3)


@pytest.mark.slow
def test_ga_converges_stays_in_bounds_and_is_reproducible():
    a = run_ga(sphere, 4, CFG)
    b = run_ga(sphere, 4, CFG)
    assert a.generations_done == 16
    # every evaluated design of every generation was inside [0,1]^d
    np.testing.assert_array_equal(a.history["gen_feasible_fraction"], np.ones(16))
    assert np.all((a.final_population >= 0) & (a.final_population <= 1))
    assert a.history["best_fitness"][-1] < a.history["gen_mean_fitness"][0]
    assert np.all(np.diff(a.history["best_fitness"]) <= 0)  # best-so-far is monotone
    np.testing.assert_array_equal(a.best_genes, b.best_genes)  # same seed, same result
    np.testing.assert_array_equal(a.history["gen_best_genes"], b.history["gen_best_genes"])
    c = run_ga(sphere, 4, GAConfig(**{**CFG.__dict__, "seed": 4}))
    assert not np.array_equal(a.history["gen_best_genes"], c.history["gen_best_genes"])


@pytest.mark.slow
def test_kill_and_resume_is_bit_identical(tmp_path):
    """Killed after its first checkpoint (committed into results.h5 through the stage engine, as the main job does)
    and resumed in a new process: the very same result."""
    import types

    from deltajax.io import ResultsFile
    from deltajax.jobs.designer_state import GA_CHECKPOINT
    from deltajax.jobs.stages import Runner

    def checkpoint():
        ctx = types.SimpleNamespace(results=ResultsFile(tmp_path / "results.h5"), log=lambda line: None)
        return Runner(ctx, "ga_reconfig", resumable=False, fingerprint="run").checkpoint("ga", **GA_CHECKPOINT)

    full = run_ga(sphere, 4, CFG)
    killed = run_ga(sphere, 4, CFG, save_checkpoint=checkpoint().commit, stop_after=8)  # "killed" after 8
    assert killed.generations_done == 8
    ck = checkpoint().load()  # what a new process finds on disk
    assert ck["generations_done"] == 8
    resumed = run_ga(sphere, 4, CFG, checkpoint=ck)
    assert resumed.resumed_from == 8
    np.testing.assert_array_equal(resumed.best_genes, full.best_genes)
    assert resumed.best_fitness == full.best_fitness
    np.testing.assert_array_equal(resumed.final_population, full.final_population)
    for k, v in full.history.items():
        np.testing.assert_array_equal(resumed.history[k], v, err_msg=k)
    with pytest.raises(GAError, match=r"checkpoint leaf \d+ is .* expected"):  # another optimiser's state: refused
        run_ga(sphere, 4, GAConfig(**{**CFG.__dict__, "population_size": 12}), checkpoint=ck)


def test_second_ga_selectable():
    cfg = GAConfig(algorithm="mr15_ga", population_size=8, generations=8, checkpoint_every=8, sigma=0.2)
    r = run_ga(sphere, 4, cfg)
    assert r.best_fitness < 0.2
    np.testing.assert_array_equal(r.history["gen_feasible_fraction"], np.ones(8))
    with pytest.raises(GAError, match=r"^GAConfig\.algorithm must be one of"):   # the library names its own field
        GAConfig(algorithm="cmaes").validate()
    from deltajax.config import ConfigError
    from deltajax.config.ga_reconfig import ga_config

    with pytest.raises(ConfigError, match=r"^experiment\.ga\.algorithm must be one of"):  # the config its path
        ga_config({"algorithm": "cmaes"})


@pytest.mark.slow
def test_ga_seeded_with_several_designs_keeps_the_best_seed():
    seeds = np.asarray([[0.3, 0.3, 0.3, 0.31], [0.9, 0.9, 0.9, 0.9], [0.1, 0.2, 0.3, 0.4]])
    cfg = GAConfig(**{**CFG.__dict__, "generations": 2, "checkpoint_every": 2})
    r = run_ga(sphere, 4, cfg, init_genes=seeds)
    # the best seed (fitness 1e-4) is never lost: the GA's best is at least as good
    assert r.best_fitness <= 1e-4 + 1e-15


def test_recommendation_rules_on_a_front():
    from deltajax.optimize.workflow import recommend

    # minimised, baseline-normalised objectives: primary (picks) column 0, regular volume column 1
    F = np.asarray([[-1.30, -0.90], [-1.29, -1.10], [-1.275, -1.30], [-1.20, -1.60], [-1.00, -2.00]])
    front = np.arange(5)
    assert recommend(F, front, "primary", 0) == 0
    assert recommend(F, front, "band", 0, band=0.02) == 2        # picks within 2 % of 1.30, then the most volume
    assert recommend(F, front, "band", 0, band=0.0) == 0
    assert recommend(F, front, "band", 0, band=0.25) == 4
    # stable by construction: perturbing the points outside the band does not move the recommendation
    G = F.copy()
    G[3:] += np.asarray([[0.05, -0.3], [0.1, 0.2]])
    assert recommend(G, front, "band", 0, band=0.02) == 2
    assert recommend(F, np.zeros((0,), int), "band", 0) == -1
    assert recommend(F, front[[4, 1]], "band", 0, band=0.02) == 1


@pytest.mark.slow
def test_refine_designs_accepts_only_feasible_improvements_and_fails_loudly(designer_small):
    from deltajax.optimize.workflow import batch_evaluator, refine_designs

    pb, space, scale, objs = designer_small
    g0 = np.stack([space.baseline_genes(), np.full(space.dim, 0.5)])
    # the toy ga_reconfig job's programs (tests/toy_jobs.py): its evaluators (batch: its NSGA-II population; 256
    # without the regular workspace) and its refine descent (2 winners, 3 steps, the default learning rate and
    # penalty), shared in-process (deltajax.optimize.workflow keeps them by content) and through the XLA cache
    ev, ev_cheap = batch_evaluator(pb, space, 8), batch_evaluator(pb, space, 256, regular=False)
    ro = refine_designs(pb, space, g0, objs, scale, "picks_per_min", steps=3, learning_rate=0.01, penalty=10.0,
                        evaluate=ev, evaluate_cheap=ev_cheap)
    assert ro.accepted.any()                       # an improvement exists here, so the rule below is exercised
    assert np.all(ro.F_after[ro.accepted] <= ro.F_before[ro.accepted] + 1e-12)
    assert np.all(ro.F_after[ro.accepted, 0] < ro.F_before[ro.accepted, 0])
    np.testing.assert_array_equal(ro.genes_after[~ro.accepted], ro.genes_before[~ro.accepted])
    # a loss whose gradient is NaN (sqrt of a negative gene combination) must stop the refinement, never be zeroed;
    # the loss reads only the primary and g, so a stand-in evaluation (compiles in seconds) tests the same guard
    import deltajax.optimize.designer as D
    from deltajax.optimize import programs as PR

    real = D.evaluate_designer

    def broken(pb_, design, **kw):
        L1 = design.robot.upper_arm
        return {"picks_per_min": jnp.sqrt(L1 - 10.0), "g": jnp.zeros(len(D.CONSTRAINT_NAMES), L1.dtype)}

    kept = dict(PR.PROGRAMS)
    PR.PROGRAMS.clear()  # the descent is kept by the problem's content: trace it afresh with the broken loss
    cache = os.environ.get("DELTAJAX_PROGRAM_CACHE")
    os.environ["DELTAJAX_PROGRAM_CACHE"] = ""   # ... and not from the programs kept on disk (same content)
    try:
        PR.evaluate_designer = broken   # the name the designer's programs call
        with pytest.raises(FloatingPointError, match="non-finite gradient of the designer's loss for design 0"):
            refine_designs(pb, space, g0[:1], objs, scale, "picks_per_min", steps=3, learning_rate=0.01,
                           penalty=10.0, evaluate=ev, evaluate_cheap=ev_cheap)
    finally:
        PR.evaluate_designer = real
        if cache is None:
            os.environ.pop("DELTAJAX_PROGRAM_CACHE", None)
        else:
            os.environ["DELTAJAX_PROGRAM_CACHE"] = cache
        PR.PROGRAMS.clear()
        PR.PROGRAMS.update(kept)


@pytest.fixture(scope="module")
def designer_small():
    from hydra import compose, initialize_config_dir

    from deltajax.config import ga_reconfig_build, robot_from_config
    from deltajax.optimize.workflow import batch_evaluator
    from deltajax.run import CONFIG_DIR

    toy = ["experiment.design.n_R=3", "experiment.task.n_r=1", "experiment.task.n_phi=3", "experiment.task.n_z=2",
           "experiment.cycle.n_samples=11", "experiment.cycle.n_R_operating=2", "experiment.regular_workspace.n_r=6",
           "experiment.regular_workspace.n_phi=2", "experiment.regular_workspace.n_z=6"]
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(config_name="config", overrides=["experiment=ga_reconfig"] + toy)
    robot, recon = robot_from_config(cfg.robot)
    s, space, pb, _ = ga_reconfig_build(cfg.experiment, robot, recon)
    objs = ["picks_per_min", "regular_volume"]
    b = batch_evaluator(pb, space, 8)(space.baseline_genes()[None])  # the toy job's batch: one compiled program
    return pb, space, -1.0 / np.abs(np.asarray([b[o][0] for o in objs])), objs


# -- a design's good test ------------------------------------------------------------------------------------------

def test_design_good_test_is_the_constraints_good_test_of_the_robot_at_R_with_the_designs_plate(monkeypatch):
    # every consumer (evaluator, rays, certify, R(t) mode, report) builds the good test here: its robot at R, its R
    # samples and its base plate (the largest R plus the overhang), and each of its four tests is constraints' own
    # function called with that robot, the spec and that plate
    from deltajax import constraints as C
    from deltajax.optimize.good import design_good_test

    spec = C.GoodSpec(joints=C.JointModel(limit=np.radians(50), platform_neutral=np.radians(40)),
                      links=C.LinkModel(), threshold=0.3)
    calls = []
    for name in ("good_point", "good_point_possible", "good_point_decided"):
        monkeypatch.setattr(C, name, lambda robot, p, s, *, plate_radius, name=name: calls.append(
            (name, float(robot.base_radius), p, s, float(plate_radius))) or C.PointCheck(*(name,) * 5))
    recon = SPACE.decode(jnp.full((SPACE.dim,), 0.5))
    fixed = recon.at(0.25)
    p = jnp.asarray([0.1, 0.05, 0.6])
    for design, top, Rs in ((recon, recon.R_max, recon.R_samples()), (fixed, 0.25, jnp.asarray([0.25]))):
        gt = design_good_test(design, spec, 0.02)
        assert gt.reconfigurable == (design is recon)
        assert float(gt.plate) == float(top) + 0.02
        np.testing.assert_array_equal(gt.R_samples(), Rs)
        R = float(Rs[-1])
        assert float(gt.at(R).base_radius) == R and float(gt.at(R).upper_arm) == float(recon.robot.upper_arm)
        calls.clear()
        assert gt.point(R, p).good == "good_point" and gt.good(R, p) == "good_point"
        gt.possible(R, p), gt.decided(R, p)
        assert [c[0] for c in calls] == ["good_point", "good_point", "good_point_possible", "good_point_decided"]
        assert all(c[1] == R and c[2] is p and c[3] is spec and c[4] == float(top) + 0.02 for c in calls)
