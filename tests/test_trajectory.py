"""Motion laws, cycles, and joint motion from IK (closed-form loop derivatives vs autodiff of IK)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import deltajax as dj
from deltajax import dynamics as dyn
from deltajax import trajectory as tr

_profile = jax.jit(dj.cycle_profile)  # one compilation per cycle structure for this file
PEAK_ACC = {"poly5": 10.0 / math.sqrt(3.0), "cycloidal": 2.0 * math.pi, "modified_trapezoid": 4.888}


@pytest.mark.parametrize("name", sorted(tr.MOTION_LAWS))
@pytest.mark.slow
def test_motion_law_boundary_values_and_derivatives(name):
    law = tr.motion_law(name)
    t = jnp.linspace(0.0, 1.0, 2001)
    s, ds, dds = law(t)
    assert float(s[0]) == 0.0 and abs(float(s[-1]) - 1.0) < 1e-14
    assert abs(float(ds[0])) < 1e-14 and abs(float(ds[-1])) < 1e-12
    assert bool(jnp.all(jnp.diff(s) >= -1e-15))  # monotone rest-to-rest
    # derivatives are the derivatives (autodiff of the law itself, inside the open interval)
    tin = jnp.linspace(0.01, 0.99, 97)
    np.testing.assert_allclose(jax.vmap(jax.grad(lambda x: law(x)[0]))(tin), law(tin)[1], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(jax.vmap(jax.grad(lambda x: law(x)[1]))(tin), law(tin)[2], rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(float(jnp.max(jnp.abs(dds))), PEAK_ACC[name], rtol=2e-4)
    # the velocity integrates to the displacement (trapezoid on a fine grid)
    assert abs(float(jnp.trapezoid(ds, t)) - 1.0) < 1e-6
    # symmetry of rest-to-rest laws: s(1 - t) = 1 - s(t)
    np.testing.assert_allclose(law(1.0 - tin)[0], 1.0 - law(tin)[0], atol=1e-13)


def test_unknown_law_and_bad_inputs_raise():
    with pytest.raises(ValueError, match="unknown motion law"):
        tr.motion_law("bang_bang")
    with pytest.raises(ValueError, match="blend"):
        tr.adept_cycle(blend=1.0)
    with pytest.raises(ValueError, match="duration"):
        tr.adept_cycle(duration=0.0)
    with pytest.raises(ValueError, match="centre"):
        tr.adept_cycle((0.0, 0.3))


@settings(max_examples=10)
@given(heading=st.floats(-math.pi, math.pi), blend=st.floats(0.0, 0.9),
       law=st.sampled_from(sorted(tr.MOTION_LAWS)))
def test_adept_cycle_geometry(heading, blend, law):
    c = (0.05, -0.03, 0.4)
    cyc = tr.adept_cycle(c, heading=heading, blend=blend, law=law, n_samples=4001)
    x = np.asarray(cyc.x)
    e = np.array([math.cos(heading), math.sin(heading), 0.0])
    along = (x - np.asarray(c)) @ e
    np.testing.assert_allclose(x[0], x[-1], atol=1e-15)                      # closed cycle
    np.testing.assert_allclose(x[0], np.asarray(c) - 0.1525 * e, atol=1e-12)  # starts at the pick point
    np.testing.assert_allclose(x[2000], np.asarray(c) + 0.1525 * e, atol=1e-12)  # place point at half time
    assert abs(along.max() - along.min() - 0.305) < 1e-12
    assert abs(x[:, 2].min() - (0.4 - 0.025)) < 1e-12 and abs(x[:, 2].max() - 0.4) < 1e-12  # 25 mm up (-z)
    lateral = x[:, :2] @ np.array([-e[1], e[0]]) - np.asarray(c)[:2] @ np.array([-e[1], e[0]])
    np.testing.assert_allclose(lateral, 0.0, atol=1e-12)                      # a planar gate path
    np.testing.assert_allclose(cyc.dx[0], 0.0, atol=1e-12)
    np.testing.assert_allclose(cyc.dx[2000], 0.0, atol=1e-12)                  # rest at the place point
    # u-derivatives consistent with the samples: cumulative trapezoid integration of dx gives x, of ddx gives dx
    # (robust to the jerk jumps at segment ends, where central differences of ddx lag by O(h))
    h = 1.0 / 4000
    dx, ddx = np.asarray(cyc.dx), np.asarray(cyc.ddx)
    x_int = x[0] + np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * h * (dx[1:] + dx[:-1]), axis=0)])
    dx_int = dx[0] + np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * h * (ddx[1:] + ddx[:-1]), axis=0)])
    np.testing.assert_allclose(x_int, x, atol=1e-6 * np.abs(x).max())
    np.testing.assert_allclose(dx_int, dx, atol=1e-4 * np.abs(dx).max())


@pytest.mark.slow
def test_ga_paper_motion_is_the_papers():
    cyc = tr.ga_paper_motion(n_samples=101)
    t = np.asarray(cyc.time())
    np.testing.assert_allclose(t[-1], 2 * math.pi)
    x, xd, xdd = (np.asarray(a) for a in cyc.rates())
    np.testing.assert_allclose(x[:, 0], 0.25 * np.sin(t), atol=1e-14)
    np.testing.assert_allclose(x[:, 2], 0.25 * np.sin(t), atol=1e-14)
    np.testing.assert_allclose(x[:, 1], 0.25 * np.cos(t), atol=1e-14)
    np.testing.assert_allclose(xd[:, 1], -0.25 * np.sin(t), atol=1e-13)
    np.testing.assert_allclose(xdd[:, 0], -0.25 * np.sin(t), atol=1e-13)
    robot = dj.presets.franco2026(fixed_R=0.2, with_mass=True)
    prof = _profile(robot, cyc)
    assert bool(jnp.all(prof.ok))
    # FK of the joint path reproduces the platform path, and IK of it returns the joint path
    p = jax.vmap(lambda th: dj.fk(robot, th).p)(jnp.asarray(x))
    np.testing.assert_allclose(prof.p, p, atol=1e-13)
    np.testing.assert_allclose(jax.vmap(lambda q: dj.ik(robot, q).theta)(p), x, atol=1e-12)


def _ik_theta(robot, p):
    return dj.ik(robot, p).theta


@jax.jit
def _joint_rates_both_ways(R, p, pd, pdd, Rd, Rdd):
    """Closed-form joint rates vs autodiff of IK along the curve s -> (p + s pd + s^2/2 pdd, R + s Rd + ...)."""
    robot = dj.presets.franco2026(fixed_R=0.2).with_base_radius(R)
    m = dyn.joint_motion(robot, p, pd, pdd, Rd, Rdd)

    def theta_of(s):
        rob = robot.with_base_radius(R + s * Rd + 0.5 * s * s * Rdd)
        return _ik_theta(rob, p + s * pd + 0.5 * s * s * pdd)

    s0 = jnp.zeros(())
    _, thd = jax.jvp(theta_of, (s0,), (jnp.ones(()),))
    thdd = jax.jvp(lambda s: jax.jvp(theta_of, (s,), (jnp.ones(()),))[1], (s0,), (jnp.ones(()),))[1]
    back = dyn.platform_motion(robot, m.theta, m.theta_dot, m.theta_ddot, Rd, Rdd)
    return m, thd, thdd, back


@settings(max_examples=15)
@given(xy=st.lists(st.floats(-0.12, 0.12), min_size=2, max_size=2), z=st.floats(0.3, 0.45),
       pd=st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3),
       pdd=st.lists(st.floats(-30.0, 30.0), min_size=3, max_size=3),
       R=st.floats(0.15, 0.35), Rd=st.floats(-0.5, 0.5), Rdd=st.floats(-5.0, 5.0))
@pytest.mark.slow
def test_joint_motion_matches_autodiff_of_ik_and_round_trips(xy, z, pd, pdd, R, Rd, Rdd):
    p = jnp.asarray([xy[0], xy[1], z])
    m, thd, thdd, back = _joint_rates_both_ways(R, p, jnp.asarray(pd), jnp.asarray(pdd), Rd, Rdd)
    assert bool(m.ok)
    np.testing.assert_allclose(m.theta_dot, thd, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(m.theta_ddot, thdd, rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(back.p, p, atol=1e-12)
    np.testing.assert_allclose(back.p_dot, pd, atol=1e-10)
    np.testing.assert_allclose(back.p_ddot, pdd, atol=1e-8)


@pytest.mark.slow
def test_reachability_checked_along_the_whole_path():
    """A move that leaves the workspace part-way is flagged at exactly the unreachable samples."""
    robot = dj.presets.franco2026(fixed_R=0.2, with_mass=True)
    cyc = tr.point_to_point((0.0, 0.0, 0.3), (0.0, 0.0, 0.7), n_samples=61)
    prof = _profile(robot, cyc)
    ik_ok = np.asarray(jax.vmap(lambda q: dj.ik(robot, q).ok)(cyc.x))
    assert ik_ok.any() and not ik_ok.all()
    np.testing.assert_array_equal(np.asarray(prof.ok), ik_ok)
    assert np.isnan(np.asarray(prof.tau)[~ik_ok]).all() and np.isfinite(np.asarray(prof.tau)[ik_ok]).all()


def test_R_profile_and_time_scaling():
    cyc = tr.with_R_profile(tr.ga_paper_motion(n_samples=21), 0.2, 0.25, amplitude=0.01)
    np.testing.assert_allclose(float(cyc.R[0]), 0.2, atol=1e-15)
    np.testing.assert_allclose(float(cyc.R[-1]), 0.25, atol=1e-14)
    _, xd1, xdd1 = cyc.rates(1.0)
    _, xd2, xdd2 = cyc.rates(2.0)
    np.testing.assert_allclose(xd2, xd1 / 2)
    np.testing.assert_allclose(xdd2, xdd1 / 4)
    assert float(cyc.at_duration(3.0).duration) == 3.0
