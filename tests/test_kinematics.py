"""IK/FK identities, Jacobians against autodiff, failure as data, no retracing."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import deltajax as dj

FRANCO = dj.presets.franco2026()
FREE = dj.Delta(base_radius=0.2, platform_radius=0.065, upper_arm=0.2, forearm=0.4)  # no joint limits


@jax.jit
def _ik_both(robot, p):
    return dj.ik(robot, p, branch="outer"), dj.ik(robot, p, branch="inner")


@jax.jit
def _fk_both(robot, theta):
    return dj.fk(robot, theta, mode="lower"), dj.fk(robot, theta, mode="upper")


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


angles = st.floats(min_value=-0.6, max_value=1.8)
radii = st.floats(min_value=0.14, max_value=0.49)


@given(t0=angles, t1=angles, t2=angles, R=radii)
def test_ik_of_fk_recovers_theta_on_one_branch_per_chain(t0, t1, t2, R):
    robot = FREE.with_base_radius(R)
    theta = jnp.array([t0, t1, t2])
    lower, upper = _fk_both(robot, theta)
    if not bool(lower.ok):
        return  # the forearms cannot close the loop for this theta: nothing to invert
    for f in (lower, upper):
        out, inn = _ik_both(robot, f.p)
        assert bool(out.ok) and bool(inn.ok)
        err = np.minimum(np.abs(_wrap(np.asarray(out.theta - theta))), np.abs(_wrap(np.asarray(inn.theta - theta))))
        assert err.max() < 1e-8


@given(x=st.floats(-0.3, 0.3), y=st.floats(-0.3, 0.3), z=st.floats(0.05, 0.55), R=radii)
def test_fk_of_ik_is_identity_in_the_matching_mode(x, y, z, R):
    robot = FREE.with_base_radius(R)
    p = jnp.array([x, y, z])
    sol, _ = _ik_both(robot, p)
    if not bool(sol.ok):
        return
    lower, upper = _fk_both(robot, sol.theta)
    d_lo = float(jnp.linalg.norm(lower.p - p))
    d_up = float(jnp.linalg.norm(upper.p - p))
    assert min(d_lo, d_up) < 1e-9
    # Below every elbow the platform is the "lower" assembly mode (larger z).
    if z > float(jnp.max(dj.elbows(robot, sol.theta)[:, 2])) + 1e-6:
        assert d_lo < 1e-9


def test_ik_reference_point_and_branches():
    # Table 4 configuration: R = 0.20465, p = (0, 0, 0.2) -> theta = -3.39378 deg on all chains
    robot = FRANCO.at(0.20465)
    sol = dj.ik(robot, jnp.array([0.0, 0.0, 0.2]))
    np.testing.assert_allclose(np.degrees(np.asarray(sol.theta)), -3.39378, atol=5e-6)
    # branch formula of docs/CONVENTIONS.md written with atan2/acos (independent of the algebraic form)
    dx, pz, L1, L2 = 0.065 - 0.20465, 0.2, 0.2, 0.4
    K = dx * dx + pz * pz + L1 * L1 - L2 * L2
    rho = math.hypot(dx, pz)
    outer = math.atan2(pz, dx) - math.acos(K / (2 * L1 * rho))
    inner = math.atan2(pz, dx) + math.acos(K / (2 * L1 * rho))
    free = FREE.with_base_radius(0.20465)
    np.testing.assert_allclose(np.asarray(dj.ik(free, jnp.array([0.0, 0.0, 0.2])).theta), _wrap(outer), atol=1e-12)
    np.testing.assert_allclose(np.asarray(dj.ik(free, jnp.array([0.0, 0.0, 0.2]), branch="inner").theta),
                               _wrap(inner), atol=1e-12)


@pytest.mark.slow
def test_failure_is_data_in_batches():
    pts = jnp.array([
        [0.0, 0.0, 0.3],      # reachable
        [jnp.nan, 0.0, 0.3],  # NaN
        [jnp.inf, 0.0, 0.3],  # inf
        [0.0, 0.0, 5.0],      # far out of reach
        [0.0, 0.0, 0.58],     # reachable by the loop but beyond the joint limits? (checked below)
    ])
    res = jax.jit(jax.vmap(dj.ik, in_axes=(None, 0)))(FRANCO.robot, pts)
    ok = np.asarray(res.ok)
    assert ok[0] and not ok[1] and not ok[2] and not ok[3]
    reason = np.asarray(res.reason)
    assert (reason[1] == dj.kinematics.IK_NONFINITE).all() and (reason[2] == dj.kinematics.IK_NONFINITE).all()
    assert (reason[3] == dj.kinematics.IK_UNREACHABLE).all()
    assert np.isnan(np.asarray(res.theta)[~ok]).all()
    ind = jax.vmap(dj.indices, in_axes=(None, 0, 0))(FRANCO.robot, pts, res.theta)
    assert np.isnan(np.asarray(ind.k_tilde)[~ok]).all() and np.isfinite(np.asarray(ind.k_tilde)[ok]).all()


@pytest.mark.slow
def test_joint_limit_flag():
    robot = FRANCO.robot
    # On a grid through the workspace, the limited robot's verdict equals "the free robot solves the point and
    # every free theta lies in [-40, 110] deg", and the reason code says which chains broke the limit.
    g = jnp.linspace(-0.35, 0.35, 9)
    pts = jnp.stack(jnp.meshgrid(g, g, jnp.linspace(0.05, 0.58, 9), indexing="ij"), -1).reshape(-1, 3)
    ik_b = jax.vmap(dj.ik, in_axes=(None, 0))
    free, lim = ik_b(FREE, pts), ik_b(robot, pts)
    th = np.degrees(np.asarray(free.theta))
    within = (th >= -40.0) & (th <= 110.0)
    np.testing.assert_array_equal(np.asarray(lim.ok), np.asarray(free.ok) & within.all(axis=1))
    solved = np.asarray(free.ok)
    assert ((np.asarray(lim.reason)[solved] == dj.kinematics.IK_JOINT_LIMIT) == ~within[solved]).all()
    assert (~within[solved]).any() and within[solved].all(axis=1).any()  # both cases occur
    # an explicit out-of-limit case: theta = -35 deg is allowed, tighten the limit to -30 deg
    tight = dj.Delta.from_degrees(base_radius=0.22842, platform_radius=0.065, upper_arm=0.2, forearm=0.4,
                                  theta_min_deg=-30, theta_max_deg=110)
    r = dj.ik(tight, jnp.array([0.0, 0.0, 0.1153]))
    assert not bool(r.ok) and (np.asarray(r.reason) == dj.kinematics.IK_JOINT_LIMIT).all()


def test_fk_degenerate_cases_flagged():
    # Tangent spheres: Table 2 pose (type-1 singularity, forearms horizontal) is reported as tangent, still ok
    robot = FRANCO.at(0.465)
    f = dj.fk(robot, jnp.full((3,), math.pi / 2))
    assert bool(f.ok) and int(f.reason) == dj.kinematics.FK_TANGENT
    np.testing.assert_allclose(np.asarray(f.p), [0, 0, 0.2], atol=1e-6)
    # No intersection: forearms too short for the elbows' spread
    g = dj.fk(FREE.with_base_radius(0.49), jnp.array([0.0, 0.0, 0.0]))
    assert not bool(g.ok) and int(g.reason) == dj.kinematics.FK_NO_INTERSECTION and np.isnan(np.asarray(g.p)).all()
    # Coincident centres: R - r + L1 cos(theta) = 0 for all chains (R = r, theta = 90 deg)
    h = dj.fk(FREE.with_base_radius(0.065), jnp.full((3,), math.pi / 2))
    assert not bool(h.ok) and int(h.reason) == dj.kinematics.FK_DEGENERATE_CENTRES
    n = dj.fk(FREE, jnp.array([jnp.nan, 0.0, 0.0]))
    assert not bool(n.ok) and int(n.reason) == dj.kinematics.FK_NONFINITE


def _fk_q(q):
    return dj.fk(FREE.with_base_radius(q[0]), q[1:]).p


_jac_fd = jax.jit(jax.jacfwd(_fk_q))
_jac_an = jax.jit(lambda q, p: dj.jacobian(FREE.with_base_radius(q[0]), p, q[1:]))


@jax.jit
def _fk_and_inv_cond(q):
    """fk at q = (R, theta) and the indices' inverse condition number there: one compiled call per example (the
    eager fk and indices dispatched hundreds of small programs per hypothesis example, ~1.5 CPU-s a test)."""
    robot = FREE.with_base_radius(q[0])
    f = dj.fk(robot, q[1:])
    return f, dj.indices(robot, f.p, q[1:]).inv_cond


@given(t0=angles, t1=angles, t2=angles, R=radii)
@pytest.mark.slow
def test_analytic_jacobian_matches_autodiff_of_fk(t0, t1, t2, R):
    q = jnp.array([R, t0, t1, t2])
    f, inv_cond = _fk_and_inv_cond(q)
    if not bool(f.ok) or int(f.reason) == dj.kinematics.FK_TANGENT:
        return
    if not float(inv_cond) > 1e-3:
        return  # too close to a singularity for a meaningful relative comparison
    J = np.asarray(_jac_an(q, f.p))
    Jfd = np.asarray(_jac_fd(q))
    np.testing.assert_allclose(J, Jfd, rtol=1e-8, atol=1e-10 * np.abs(Jfd).max())


def test_passive_angles_meaning():
    # Table 3: theta_i2 is within 0.1 deg of 180 (folded) at R = 0.22842, z = 0.1153
    rb = FRANCO.at(0.22842)
    p = jnp.array([0.0, 0.0, 0.1153])
    th2, th3 = dj.passive_angles(rb, p, dj.ik(rb, p).theta)
    assert np.all(np.abs(np.abs(np.degrees(np.asarray(th2))) - 180.0) < 0.1)
    np.testing.assert_allclose(np.degrees(np.asarray(th3)), 90.0, atol=1e-9)  # on the axis: in-plane forearm
    # direct check of the definition: forearm direction = (s3 c12, c3, s3 s12) in the local frame
    p = jnp.array([0.05, -0.03, 0.3])
    rb = FRANCO.at(0.25)
    th = dj.ik(rb, p).theta
    th2, th3 = dj.passive_angles(rb, p, th)
    u = np.asarray(dj.kinematics.forearm_units(rb, p, th))
    t12 = np.asarray(th + th2)
    s3 = np.sin(np.asarray(th3))
    np.testing.assert_allclose(u, np.stack([s3 * np.cos(t12), np.cos(np.asarray(th3)), s3 * np.sin(t12)], -1),
                               atol=1e-12)


@pytest.mark.slow
def test_new_parameter_values_do_not_retrace():
    traces = []

    @jax.jit
    def f(robot, p):
        traces.append(1)
        s = dj.ik(robot, p)
        return dj.indices(robot, p, s.theta).k_tilde

    p = jnp.array([0.0, 0.0, 0.3])
    for R in (0.2, 0.25, 0.3):
        f(FRANCO.at(R), p)
    f(FRANCO.at(0.2), p + 0.01)
    f(dj.Delta(base_radius=0.3, platform_radius=0.05, upper_arm=0.25, forearm=0.5, theta_min=-1.0, theta_max=2.0), p)
    assert len(traces) == 1


@pytest.mark.slow
def test_gradients_finite_and_correct():
    from jax.test_util import check_grads

    robot = FRANCO.at(0.3)

    def k_of_p(p):
        return dj.point_indices(robot, p)[1].k_tilde

    def theta_of_p(p):
        return dj.ik(robot, p).theta

    p = jnp.array([0.03, -0.02, 0.33])
    check_grads(k_of_p, (p,), order=1, modes=("rev",), atol=1e-6, rtol=1e-6)
    check_grads(theta_of_p, (p,), order=1, modes=("fwd", "rev"), atol=1e-6, rtol=1e-6)

    # At unreachable / NaN points the masked outputs carry finite (zero) gradients: the double-where guard.
    def masked(p):
        sol = dj.ik(robot, p)
        return jnp.sum(jnp.where(sol.ok, sol.theta, 0.0))

    for bad in (jnp.array([0.0, 0.0, 5.0]), jnp.array([jnp.nan, 0.0, 0.3])):
        g = jax.grad(masked)(bad)
        assert np.isfinite(np.asarray(g)).all()
    # gradient with respect to design parameters (a GA/optax refinement differentiates through the robot)
    g = jax.grad(lambda L2: dj.point_indices(robot.__class__(base_radius=0.3, platform_radius=0.065, upper_arm=0.2,
                                                             forearm=L2, theta_min=robot.theta_min,
                                                             theta_max=robot.theta_max), p)[1].k_tilde)(0.4)
    assert np.isfinite(float(g)) and float(g) != 0.0
