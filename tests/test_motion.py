"""Path-level redundancy resolution: DP exact vs brute force, limits respected, >= best fixed R, pointwise
equals the workspace resolver, exact force polynomial, smooth refinement, task paths."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _motion_helpers import brute_force as _brute
from _motion_helpers import random_tables as _random_tables

import deltajax as dj
from deltajax import motion as mo
from deltajax.geometry import ReconfigurableDelta


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(2))
def test_dp_equals_brute_force_on_random_tables(seed):
    tab = _random_tables(seed)
    dt = 0.05
    for (w, a, fmax) in [(1, 1, 4.0), (2, 1, 3.0), (3, 6, math.inf)]:
        for aggregate in mo.AGGREGATES:
            for boundary in mo.BOUNDARIES:
                res = mo.resolve_tables(tab, dt, w, a, fmax, aggregate=aggregate, boundary=boundary)
                bf = _brute(tab, dt, w, a, fmax, aggregate, boundary)
                assert res.score == bf, (w, a, fmax, aggregate, boundary)
                assert res.ok == np.isfinite(bf[0])
                if res.ok:   # the returned path achieves the score and satisfies the bands
                    assert mo.path_score(tab, res.k, aggregate) == bf
                    assert np.all(np.abs(np.diff(res.k)) <= w) and np.all(np.abs(np.diff(res.k, 2)) <= a)
                    assert np.all(np.abs(res.force_R) <= fmax)


# -- on the robot -----------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def tiny():
    base = dj.presets.franco2026(fixed_R=0.2, with_mass=True)
    recon = ReconfigurableDelta.from_range(base, 0.14, 0.22, 0.02)
    cyc = dj.trajectory.point_to_point([-0.12, 0.06, 0.36], [0.12, -0.05, 0.42], duration=0.4, n_samples=5)
    tab = jax.jit(mo.path_tables, static_argnames="criterion")(recon, cyc, "sigma_min_v")
    return recon, cyc, tab


@pytest.mark.slow
def test_robot_instance_exact_limits_and_baselines(tiny):
    recon, cyc, tab = tiny
    dt = 0.1
    F0 = np.abs(np.asarray(tab.force_coef)[..., 0])
    for lim, aggregate, boundary in [
            (dj.RDriveLimits(speed=0.25, acceleration=2.5, force=float(np.nanmedian(F0)) + 4.0), "integral", "free"),
            (dj.RDriveLimits(speed=0.45, acceleration=4.5), "min", "rest"),
            (dj.RDriveLimits(), "integral", "rest")]:
        res = dj.resolve_path(recon, cyc, "sigma_min_v", limits=lim, aggregate=aggregate, boundary=boundary,
                              tables=tab)
        w, a = res.bands
        assert res.score == _brute(tab, dt, w, a, float(lim.force), aggregate, boundary)
        assert res.ok and mo.path_constraints_ok(res, lim, dt, 0.02)
        fixed = dj.motion.fixed_path(tab, lim, aggregate, dt)
        assert fixed.ok and res.score >= fixed.score
    assert res.bands == (recon.n_R - 1, 2 * (recon.n_R - 1))   # unlimited drive


@pytest.mark.slow
def test_pointwise_equals_workspace_resolver(tiny):
    recon, cyc, tab = tiny
    pw = dj.motion.pointwise_path(tab, dt=0.1)
    ref = dj.workspace.resolve_redundancy(recon, cyc.x, "sigma_min_v")
    np.testing.assert_array_equal(np.asarray(ref.ok), True)
    np.testing.assert_allclose(pw.value, np.asarray(ref.value), rtol=1e-12)
    np.testing.assert_allclose(pw.R, np.asarray(ref.R), rtol=0, atol=1e-15)


@pytest.mark.slow
def test_force_is_exactly_quadratic_in_Rdot_and_affine_in_Rddot(tiny):
    recon, cyc, tab = tiny
    x, xd, xdd = cyc.rates()
    rng = np.random.default_rng(0)
    j = np.array([0, 2, 3, 4])
    k = np.array([1, 3, 2, 4])
    v = rng.uniform(-0.8, 0.8, 4)
    acc = rng.uniform(-20, 20, 4)
    F, _, ok = mo.path_forces(recon.robot, cyc, x[j], xd[j], xdd[j], tab.R[k], jnp.asarray(v), jnp.asarray(acc))
    c = np.asarray(tab.force_coef)[j, k]
    assert bool(jnp.all(ok))
    np.testing.assert_allclose(np.asarray(F), c[:, 0] + v * c[:, 1] + v ** 2 * c[:, 2] + acc * c[:, 3],
                               rtol=1e-10, atol=1e-10)


def test_limits_validation_names_field():
    with pytest.raises(ValueError, match="RDriveLimits.speed"):
        dj.RDriveLimits(speed=-1.0)
    with pytest.raises(ValueError, match="RDriveLimits.force"):
        dj.RDriveLimits(force=float("nan"))
    with pytest.raises(ValueError, match="aggregate"):
        mo.resolve_tables(_random_tables(0), 0.1, 1, 1, aggregate="mean")


def test_task_path_rates_are_derivatives():
    pts = [[0.0, 0.0, 0.35], [0.1, 0.05, 0.40], [-0.08, 0.1, 0.38]]
    cyc = dj.motion.task_path(pts, segment_duration=0.4, samples_per_segment=41)
    assert cyc.n_samples == 81 and float(cyc.duration) == pytest.approx(0.8)
    x, xd, _ = cyc.rates()
    t = np.asarray(cyc.time())
    fd = np.gradient(np.asarray(x), t, axis=0)
    np.testing.assert_allclose(np.asarray(xd)[1:-1], fd[1:-1], atol=4e-3)   # O(dt^2) central differences
    np.testing.assert_allclose(np.asarray(x)[[0, 40, 80]], pts, atol=1e-15)
    with pytest.raises(ValueError, match="task points"):
        dj.motion.task_path([[0, 0, 0.3]])


@pytest.mark.slow
def test_refinement_accepts_only_improvements_within_limits():
    # a coarse R grid (40 mm): a smooth R(t) between the samples beats the exact DP on the samples
    base = dj.presets.franco2026(fixed_R=0.2, with_mass=True)
    recon = ReconfigurableDelta.from_range(base, 0.14, 0.30, 0.04)
    cyc = dj.trajectory.point_to_point([-0.12, 0.06, 0.36], [0.12, -0.05, 0.42], duration=0.5, n_samples=11)
    lim = dj.RDriveLimits(speed=1.0, acceleration=40.0, force=60.0)
    dp = dj.resolve_path(recon, cyc, "k_tilde", limits=lim, boundary="rest")
    ref = dj.refine_path(recon, cyc, dp, "k_tilde", limits=lim, boundary="rest", n_ctrl=6, steps=60,
                         learning_rate=1e-3)
    assert ref.dp_score == dp.score
    assert ref.accepted, ref.reason
    assert ref.score > dp.score and ref.score == ref.spline_score
    assert np.all(np.abs(ref.R_dot) <= 1.0) and np.all(np.abs(ref.R_ddot) <= 40.0)
    assert np.all(np.abs(ref.force_R) <= 60.0) and abs(ref.R_dot[0]) < 1e-9 and abs(ref.R_dot[-1]) < 1e-9
    assert np.all((ref.R >= 0.14) & (ref.R <= 0.30))
    # the exact criterion of the returned profile is the reported score
    vals = [float(getattr(dj.point_indices(recon.at(r), p)[1], "k_tilde")) for r, p in zip(ref.R, np.asarray(cyc.x))]
    np.testing.assert_allclose(vals, ref.value, rtol=1e-12)


@pytest.mark.slow
def test_path_optimum_is_vmappable_over_designs(tiny):
    recon, cyc, _ = tiny
    lim = dj.RDriveLimits(speed=0.45, acceleration=4.5, force=40.0)
    w, a = mo.path_bands(recon, cyc, lim)
    designs = [recon, jax.tree.map(lambda x: x, recon)]
    designs[1] = ReconfigurableDelta(robot=recon.robot.__class__(**{**{f: getattr(recon.robot, f) for f in (
        "base_radius", "platform_radius", "upper_arm", "theta_min", "theta_max", "mass")}, "forearm": 0.42}),
        R_min=recon.R_min, R_step=recon.R_step, n_R=recon.n_R)
    pop = jax.tree.map(lambda *xs: jnp.stack(xs), *designs)
    for boundary in ("rest", "closed"):
        P, S = jax.jit(jax.vmap(lambda r: mo.path_optimum(r, cyc, "sigma_min_v", w=w, a=a, force_limit=40.0,
                                                          boundary=boundary)))(pop)
        for i, d in enumerate(designs):
            ref = dj.resolve_path(d, cyc, "sigma_min_v", limits=lim, boundary=boundary)
            assert (float(P[i]), float(S[i])) == pytest.approx(ref.score, rel=1e-12)
