"""The reconfigurable design's operating mode in ga_reconfig, "R per task" or
"R(t) along the cycle" under the R drive's limits (deltajax/optimize/operating.py)."""

import math

import h5py
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from deltajax import motion
from deltajax.config import ConfigError, robot_from_config
from deltajax.cycle import cycle_profile
from deltajax.jobs.ga_reconfig import build
from deltajax.mechanism import drive_profile
from deltajax.motion_refine import spline_basis
from deltajax.optimize import operating as OP
from deltajax.optimize.designer import DESIGN_UNITS, evaluate_designer
from deltajax.run import CONFIG_DIR, run_experiment
from deltajax.trajectory import Cycle

from _programs import kept
from toy_jobs import overrides

# the designer's toy sizes (tests/test_ga_reconfig.py), with n_R = 7 so that the 4 per-task candidates are R samples
SMALL = ["experiment.design.n_R=7", "experiment.task.n_r=1", "experiment.task.n_phi=3", "experiment.task.n_z=2",
         "experiment.cycle.n_samples=11", "experiment.cycle.n_R_operating=4", "experiment.reconfig.mode=path",
         "experiment.reconfig.n_R=9", "experiment.reconfig.segments=4"]
# the suite's one toy size of the main job (tests/toy_jobs.py: small screen and refine stage too)
TOY = overrides("ga_reconfig")


def _problem(overrides):
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(config_name="config", overrides=["experiment=ga_reconfig", *overrides])
    robot, recon = robot_from_config(cfg.robot)
    s, space, pb, _ = build(cfg.experiment, robot, recon)
    return s, space, pb


# -- configuration ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("override, words", [
    ("experiment.reconfig.mode=moving", ["experiment.reconfig.mode", "moving"]),
    ("experiment.reconfig.drive.speed=-0.1", ["experiment.reconfig.drive.speed", "-0.1", "m/s"]),
    ("experiment.reconfig.drive.acceleration=nan", ["experiment.reconfig.drive.acceleration", "nan", "m/s^2"]),
    ("experiment.reconfig.drive.force=0", ["experiment.reconfig.drive.force", "0", "N"]),
    ("experiment.reconfig.motor_torque=2.0", ["experiment.reconfig.motor_torque", "2.0", "N m", "screw_linkage"]),
    ("experiment.reconfig.n_R=2", ["experiment.reconfig.n_R", "2"]),
    ("experiment.reconfig.aggregate=mean", ["experiment.reconfig.aggregate", "mean"]),
    ("+experiment.reconfig.drive.jerk=1", ["experiment.reconfig.drive.jerk", "unknown"]),
])
def test_bad_settings_are_one_line_errors(override, words):
    with pytest.raises(ConfigError) as e:
        _problem([override])
    msg = str(e.value)
    assert "\n" not in msg and all(w in msg for w in words), msg


@pytest.mark.slow
def test_defaults_are_per_task_and_path_builds_a_spec():
    s, _, pb = _problem([])
    assert pb.mode == "per_task" and s.reconfig["mode"] == "per_task"
    _, _, pb = _problem(["experiment.reconfig.mode=path", "experiment.reconfig.mechanism=screw_linkage",
                         "experiment.reconfig.motor_torque=1.5"])
    op = pb.operating
    assert pb.mode == op.mode == "path" and op.mechanism is not None and op.motor_torque == 1.5
    assert (op.speed, op.accel, op.force) == (0.3, 10.0, 150.0)


# -- pieces -----------------------------------------------------------------------------------------------------

def test_u_rates_match_motion_discrete_rates():
    R = np.random.default_rng(0).uniform(0.2, 0.3, 9)
    v, a = OP.u_rates(jnp.asarray(R))
    v0, a0 = motion.discrete_rates(R, 1.0 / 8)
    np.testing.assert_allclose(v, v0, rtol=1e-12)
    np.testing.assert_allclose(a, a0, rtol=1e-12)


def test_periodic_basis_is_periodic_and_reproduces_constants():
    B, B1, B2 = OP.periodic_basis(41, 6)
    np.testing.assert_allclose(B.sum(axis=1), 1.0, atol=1e-12)
    c = np.random.default_rng(1).normal(size=6)
    for X in (B, B1, B2):
        np.testing.assert_allclose((X @ c)[0], (X @ c)[-1], atol=1e-9)        # C2 across the repetition
    # derivatives agree with central differences of the spline itself
    u = np.linspace(0, 1, 41)
    np.testing.assert_allclose(np.gradient(B @ c, u)[5:-5], (B1 @ c)[5:-5], atol=0.05 * np.abs(B1 @ c).max())
    assert spline_basis(u, 1.0, 9)[0].shape == (41, 9)


# -- the path mode on one design --------------------------------------------------------------------------------
# Two compiled functions shared by the tests below: the per-task evaluation (which gives R_op and the planning
# time) and the path mode of :func:`operating.path_operating` with its profile, on a problem with the screw
# linkage's motor torque as a limit too.

TORQUE = 1.0  # N m, the screw motor's limit in these tests


#: the array fields of a cartesian :class:`deltajax.trajectory.Cycle`
CYCLE_FIELDS = ("u", "x", "dx", "ddx", "duration", "R", "dR", "ddR")


@pytest.fixture(scope="module")
def small():
    s, space, pb = _problem(SMALL + ["experiment.reconfig.mechanism=screw_linkage",
                                     f"experiment.reconfig.motor_torque={TORQUE}"])
    _, _, pb0 = _problem([o for o in SMALL if "reconfig.mode" not in o])
    # both programs kept across sessions (tests/_programs.py): tracing the path mode was most of this
    # fixture's ~16 s
    per_task = kept(jax.jit(lambda g: evaluate_designer(pb0, space.decode(g), regular=False)), "per_task",
                    __file__, pb0, space)

    @jax.jit
    def path_fields(g, R_op, T_plan):   # the profile's cycle as its fields: the kept program's outputs are read
        # back through pickle, which does not keep equinox's field sentinels (a Cycle read back would not unflatten)
        m, prof = OP.path_operating(pb, space.decode(g), R_op, T_plan, jnp.nan, jnp.nan, return_profile=True)
        assert prof["cycle"].space == "cartesian"
        return m, {**prof, "cycle": {k: getattr(prof["cycle"], k) for k in CYCLE_FIELDS}}

    path_fields = kept(path_fields, "path_operating", __file__, pb, space)

    def path(g, R_op, T_plan):
        m, prof = path_fields(g, R_op, T_plan)
        return m, {**prof, "cycle": Cycle(**prof["cycle"])}

    # two designs feasible at these sizes: the baseline with a 0.39 m forearm (with its 0.40 m one, the task samples
    # on the mirror planes fail -- task and interference -- at all 4 per-task R candidates) and a faster design
    genes = np.stack([space.from_params([0.138, 0.495, 0.065, 0.2, 0.39, 20.0]),
                      space.from_params([0.15, 0.40, 0.06, 0.20, 0.39, 25.0])])
    out = []
    for g in genes:
        m0 = jax.tree_util.tree_map(np.asarray, per_task(jnp.asarray(g)))
        m, prof = path(jnp.asarray(g), m0["R_operating"], m0["cycle_time"])
        out.append((m0, jax.tree_util.tree_map(np.asarray, m), prof))
    return s, space, pb, pb0, genes, out


@pytest.mark.slow  # shares one ~60-100 s compile (module fixture) under load
def test_path_mode_never_violates_the_limits(small):
    """At the cycle time the path mode reports, the public inverse dynamics with moving R (independent of the
    bisection) and the screw mechanism's drive profile stay within every R drive limit; margins >= 0 and match."""
    from deltajax.constraints import with_drive

    s, space, pb, _, genes, out = small
    op = pb.operating
    ran = 0
    for g, (m0, m, prof) in zip(genes, out):
        assert np.isfinite(m["screw_torque_peak"]) or not m["picks_per_min"] > 0
        if not (np.isfinite(m["picks_per_min"]) and m["picks_per_min"] > 0):
            continue
        ran += 1
        d = space.decode(jnp.asarray(g))
        T = float(m["cycle_time"])
        assert T >= float(m["cycle_time_drive"]) - 1e-12
        rob = with_drive(d.robot, pb.motor, d.robot.mass.gear_ratio, pb.payload)
        p = cycle_profile(rob, prof["cycle"], T)
        Rd = np.asarray(prof["R_u"]) / T
        Rdd = np.asarray(prof["R_uu"]) / T ** 2
        F = np.asarray(p.force_R)
        np.testing.assert_allclose(np.asarray(p.R), np.asarray(prof["R"]))
        np.testing.assert_allclose(np.asarray(p.R_dot), Rd, atol=1e-12)
        assert np.all(np.abs(Rd) <= op.speed * (1 + 1e-6)) and np.all(np.abs(Rdd) <= op.accel * (1 + 1e-6))
        assert np.all(np.abs(F) <= op.force * (1 + 1e-6))
        drv = drive_profile(op.mechanism, p.R, p.R_dot, p.force_R)
        assert np.all(np.abs(np.asarray(drv.effort)) <= TORQUE * (1 + 1e-6))
        assert float(np.abs(np.asarray(drv.effort)).max()) == pytest.approx(float(m["screw_torque_peak"]), rel=1e-9)
        for k, lim in (("R_speed_margin", op.speed), ("R_accel_margin", op.accel), ("R_force_margin", op.force),
                       ("screw_torque_margin", TORQUE)):
            assert m[k] >= -1e-6 * lim, (k, m[k])
        assert m["R_force_margin"] == pytest.approx(op.force - np.abs(F).max(), rel=1e-9, abs=1e-9)
        assert np.all(np.asarray(prof["R"]) >= float(d.R_min) - 1e-12)
        assert np.all(np.asarray(prof["R"]) <= float(d.R_max) + 1e-12)
    assert ran >= 1


@pytest.mark.slow  # shares one ~60-100 s compile (module fixture) under load
def test_path_mode_at_least_as_good_as_fixed_R_and_per_task(small):
    """R(t) runs at least the per-task R's picks/min whenever that R, held constant, is within the R drive's limits
    at its own cycle time (checked here independently with the public inverse dynamics), and its index along the
    cycle is never below the per-task R's when it runs as many picks/min. (The plan itself is the exact DP,
    never below the best constant plan on its grid: test_dp_with_traced_limits_equals_bands_and_brute_force.)"""
    from deltajax.constraints import with_drive

    s, space, pb, _, genes, out = small
    op = pb.operating
    checked = 0
    for g, (m0, m, prof) in zip(genes, out):
        if not (m0["feasible"] and m0["picks_per_min"] > 0):
            continue
        d = space.decode(jnp.asarray(g))
        T0, R_op = float(m0["cycle_time"]), float(m0["R_operating"])
        rob = with_drive(d.robot.with_base_radius(R_op), pb.motor, d.robot.mass.gear_ratio, pb.payload)
        p0 = cycle_profile(rob, pb.cycle, T0)                                # constant R: no R profile
        dp = drive_profile(op.mechanism, jnp.full_like(p0.force_R, R_op), jnp.zeros_like(p0.force_R), p0.force_R)
        const_ok = (np.abs(np.asarray(p0.force_R)).max() <= op.force
                    and np.abs(np.asarray(dp.effort)).max() <= TORQUE)
        if not const_ok:
            continue
        checked += 1
        assert float(m["picks_per_min"]) >= float(m0["picks_per_min"]) * (1 - 1e-9)
        if float(m["picks_per_min"]) <= float(m0["picks_per_min"]) * (1 + 1e-9):
            assert float(m["path_index_mean"]) >= float(m["path_index_mean_fixed"]) - 1e-12
    assert checked >= 1


@pytest.mark.slow
def test_dp_with_traced_limits_equals_bands_and_brute_force():
    """motion.path_dp with the traced speed/accel masks inside wide static bands = the DP with the exact bands
    (w, a) from the same limits = brute force over every sample path (tiny instance)."""
    rng = np.random.default_rng(5)
    K, n = 5, 4
    val = jnp.asarray(rng.uniform(0, 1, (K, n)))
    fe = jnp.asarray(rng.uniform(0, 1, (K, n)) > 0.15)
    coef = jnp.zeros((K, n, 4))
    wts = jnp.ones(K)
    dR, dt = 0.01, 0.1
    for speed, accel in ((0.1, 1.0), (0.2, 1.0), (0.1, 2.0), (math.inf, 1.0)):
        w = n - 1 if math.isinf(speed) else int(math.floor(speed * dt / dR * (1 + 1e-9)))
        a = min(2 * w, int(math.floor(accel * dt * dt / dR * (1 + 1e-9))))
        P1, S1, _ = motion.path_dp_jit(val, fe, coef, wts, dR, dt, 1.0, 0, w=w, a=a, primary_min=False, boundary="free",
                               backtrack=True)
        P2, S2, path = motion.path_dp_jit(val, fe, coef, wts, dR, dt, 1.0, 0, w=n - 1, a=2 * (n - 1), primary_min=False,
                                  boundary="free", backtrack=True, speed=speed, accel=accel)
        best = -np.inf
        fe_np, val_np = np.asarray(fe), np.asarray(val)
        for ks in np.ndindex(*(n,) * K):
            ks = np.asarray(ks)
            if not fe_np[np.arange(K), ks].all():
                continue
            if np.any(np.abs(np.diff(ks)) > w) or np.any(np.abs(np.diff(ks, 2)) > a):
                continue
            best = max(best, float(val_np[np.arange(K), ks].sum()))
        assert float(P1) == pytest.approx(best) and float(P2) == pytest.approx(best), (speed, accel)


@pytest.mark.slow  # shares one ~60-100 s compile (module fixture) under load
def test_per_task_mode_reports_path_metrics_as_nan_and_fixed_equal(small):
    s, space, pb, pb0, genes, out = small
    m = out[0][0]
    for k in OP.OPERATING_UNITS:
        assert np.isnan(float(m[k])), k
    for k in OP.FIXED_VARIANT_METRICS:
        assert float(m[k]) == float(m[f"{k}_fixed"]) or (np.isnan(float(m[k])) and np.isnan(float(m[f"{k}_fixed"])))
    assert all(k in DESIGN_UNITS for k in m if k not in ("g", "violation", "feasible"))


# -- the job end to end -----------------------------------------------------------------------------------------

#: the verification grids and continuous regular-workspace settings of the path-mode run equal its search
#: grids' (the toy's search grids, the verification's default refine settings), so the verify stage's problem is
#: the search problem and reuses its compiled evaluation (deltajax.optimize.workflow keeps programs by content):
#: one compile of the path mode's evaluation with the regular workspace instead of two
VERIFY_AS_SEARCH = ["experiment.verify.cycle_samples=11", "experiment.verify.rw_n_r=6", "experiment.verify.rw_n_z=6",
                    "experiment.regular_workspace.search_refine_steps=[12,14]",
                    "experiment.regular_workspace.search_refine_samples=[4,3,5]"]


@pytest.mark.slow
def test_job_runs_with_mode_path_and_reports_both_variants(tmp_path):
    # The screen, the refine stage and the floor step are off: each compiles the path mode once more (the screen's
    # evaluation without the regular workspace, refine and the floor step its gradient): from an empty XLA cache,
    # under load ~9, the stages took screen 259 s, GA 354 s, refine 646 s wall (2026-12-01). Nothing below reads
    # the screen, refine or the floor step; the GA, NSGA-II, verification and summary in path mode are checked.
    # The tolerance stage is off too: its Monte Carlo runs the path mode per sample (4.5 min of the suite's time),
    # and tests/test_tolerance.py checks it.
    p = run_experiment("ga_reconfig", TOY + VERIFY_AS_SEARCH + [
        "experiment.reconfig.mode=path", "experiment.reconfig.n_R=9", "experiment.reconfig.segments=4",
        "experiment.screen.enabled=false", "experiment.refine.enabled=false",
        "experiment.floor_solve.enabled=false", "experiment.tolerance.enabled=false"], run_dir=tmp_path)
    with h5py.File(p, "r") as f:
        V, S = f["verify"], f["summary"]
        for k, u in (("R_speed_margin", "m/s"), ("R_accel_margin", "m/s^2"), ("R_force_margin", "N"),
                     ("picks_per_min_fixed", "1/min"), ("R_path_min", "m")):
            assert V[k].attrs["units"] == u, k
        feas = V["feasible"][()].astype(bool)
        runs = feas & (V["picks_per_min"][()] > 0)
        assert runs.any()
        for k in ("R_speed_margin", "R_accel_margin", "R_force_margin"):
            assert np.all(V[k][()][runs] >= -1e-6), k
        names = [x.decode() if isinstance(x, bytes) else x for x in S["metric_name"][()]]
        assert "R_force_margin" in names and "picks_per_min" in names
        i = names.index("picks_per_min")
        rec = S["recommended"][()]
        recf = S["recommended_fixed_R"][()]
        assert np.isfinite(rec[i]) and np.isfinite(recf[i])
        assert S.attrs["operating_mode"] == "path"
