"""Inverse dynamics: three formulations agree, energy is conserved, closed-form cases, cycle metrics."""

import math
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from omegaconf import OmegaConf

import deltajax as dj
from deltajax import cycle as cyc
from deltajax import dynamics as dyn
from deltajax import trajectory as tr
from deltajax.config import ConfigError, robot_from_config
from deltajax.config import mass_from_config
from deltajax.mass import MassModel

# Every mass-model term switched on (rotor, gear, elbow hardware, carriage, payload, off-centre arm).
FULL_MASS = MassModel(upper_arm_mass=1.2, upper_arm_com_fraction=0.37, upper_arm_inertia_factor=0.05,
                      rotor_inertia=2e-4, gear_ratio=7.0, elbow_mass=0.06, forearm_mass=0.09,
                      forearm_elbow_fraction=0.4, platform_mass=0.3, payload_mass=0.25, carriage_mass=0.8)
ROBOT = eqx.tree_at(lambda d: d.mass, dj.presets.franco2026(fixed_R=0.25), FULL_MASS, is_leaf=lambda x: x is None)
assert FULL_MASS.forearm_model == "rigid_rod"  # the default
# The same masses with the point-split forearm, and a heavier rigid rod with a non-uniform mass distribution.
FULL_MASS_PS = FULL_MASS.with_forearm_model("point_split")
FULL_MASS_ROD = eqx.tree_at(lambda m: (m.forearm_mass, m.forearm_inertia_factor), FULL_MASS,
                            (jnp.asarray(0.6), jnp.asarray(0.15)))
ROBOTS = {"rigid_rod": ROBOT,
          "point_split": eqx.tree_at(lambda d: d.mass, ROBOT, FULL_MASS_PS),
          "heavy_rod": eqx.tree_at(lambda d: d.mass, ROBOT, FULL_MASS_ROD)}
CONFIGS = Path(__file__).resolve().parent.parent / "configs"
LIMITS = cyc.Limits(torque=20.0, speed=10.0)
K = 101  # samples per cycle in these tests (one compilation of each jitted helper)

# Cached jitted helpers: one compilation per cycle structure, shared by the tests.
_profile = jax.jit(cyc.cycle_profile)
_metrics = jax.jit(cyc.cycle_metrics)
_bisect = jax.jit(cyc.min_cycle_time_bisection)
_within = jax.jit(cyc.within_limits)


def _vw_lagrange(robot, p, thd, thdd, Rd, Rdd):
    th = dj.ik(robot, p).theta
    return tuple(dyn.inverse_dynamics(robot, th, thd, thdd, Rd, Rdd, method=m) for m in ("virtual_work", "lagrange"))


_vw_lagrange_jit = jax.jit(_vw_lagrange)
_vec = st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3)


def _close(a, b, ref):
    scale = 1.0 + np.max(np.abs(np.asarray(ref)))
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=0, atol=1e-9 * scale)


@pytest.mark.parametrize("model", ["rigid_rod", "point_split", "heavy_rod"])
@settings(max_examples=12, deadline=None)
@given(xy=st.lists(st.floats(-0.12, 0.12), min_size=2, max_size=2), z=st.floats(0.3, 0.4), thd=_vec,
       thdd=_vec, R=st.floats(0.15, 0.3), Rd=st.floats(-1.0, 1.0), Rdd=st.floats(-5.0, 5.0))
@pytest.mark.slow
def test_lagrange_multipliers_equal_virtual_work(model, xy, z, thd, thdd, R, Rd, Rdd):
    robot = ROBOTS[model].with_base_radius(R)
    p = jnp.asarray([xy[0], xy[1], z])
    vw, lag = _vw_lagrange_jit(robot, p, jnp.asarray(thd), jnp.asarray(thdd), Rd, Rdd)
    assert bool(vw.ok) and bool(lag.ok)  # the sampled box is inside the workspace for every R
    _close(lag.tau, vw.tau, vw.tau)
    _close(lag.force_R, vw.force_R, vw.force_R)


@pytest.mark.slow
@pytest.mark.parametrize("model", ["rigid_rod", "point_split", "heavy_rod"])
def test_autodiff_lagrangian_equals_both(model):
    """Third formulation: Euler-Lagrange of the FK-based reduced Lagrangian, differentiated by JAX."""
    rng = np.random.default_rng(0)
    n = 4
    p = jnp.asarray(rng.uniform([-0.1, -0.1, 0.3], [0.1, 0.1, 0.45], (n, 3)))
    thd, thdd = jnp.asarray(rng.uniform(-3, 3, (n, 3))), jnp.asarray(rng.uniform(-20, 20, (n, 3)))
    R, Rd, Rdd = (jnp.asarray(rng.uniform(a, b, n)) for a, b in ((0.2, 0.3), (-1, 1), (-5, 5)))

    def three(R_, p_, *a):
        rob = ROBOTS[model].with_base_radius(R_)
        th = dj.ik(rob, p_).theta
        return tuple(dyn.inverse_dynamics(rob, th, *a, method=m) for m in dyn.METHODS)

    vw, lag, ad = jax.jit(jax.vmap(three))(R, p, thd, thdd, Rd, Rdd)
    assert bool(jnp.all(vw.ok))
    _close(ad.tau, vw.tau, vw.tau)
    _close(ad.force_R, vw.force_R, vw.force_R)
    _close(ad.tau, lag.tau, vw.tau)


def _joint_traj(t):
    """A smooth trajectory with moving R (joint angles by IK of a Lissajous platform path), for energy checks."""
    p = jnp.stack([0.1 * jnp.sin(1.3 * t), 0.08 * jnp.cos(0.9 * t), 0.38 + 0.06 * jnp.sin(2.1 * t)])
    R = 0.25 + 0.04 * jnp.sin(1.7 * t)
    return dj.ik(ROBOT.with_base_radius(R), p).theta, R


def _derivs(t):
    f = lambda s: _joint_traj(s)  # noqa: E731
    (th, R), (thd, Rd) = jax.jvp(f, (t,), (jnp.ones_like(t),))
    thdd, Rdd = jax.jvp(lambda s: jax.jvp(f, (s,), (jnp.ones_like(s),))[1], (t,), (jnp.ones_like(t),))[1]
    return th, thd, thdd, R, Rd, Rdd


@jax.jit
def _power_and_dEdt(t, base):
    th, thd, thdd, R, Rd, Rdd = _derivs(t)
    robot = base.with_base_radius(R)
    torques = dyn.inverse_dynamics(robot, th, thd, thdd, Rd, Rdd)

    def E(s):
        th_s, thd_s, thdd_s, R_s, Rd_s, Rdd_s = _derivs(s)
        rob = base.with_base_radius(R_s)
        T, V = dyn.energy(rob, dyn.platform_motion(rob, th_s, thd_s, thdd_s, Rd_s, Rdd_s))
        return T + V

    _, dEdt = jax.jvp(E, (t,), (jnp.ones_like(t),))
    power = jnp.dot(torques.tau, thd) + torques.force_R * Rd
    motion = dyn.platform_motion(robot, th, thd, thdd, Rd, Rdd)
    T_closed, V_closed = dyn.energy(robot, motion)
    T_ad, V_ad = dyn.energy_from_joints(robot, th, thd, Rd)
    return power, dEdt, T_closed - T_ad, V_closed - V_ad


@pytest.mark.parametrize("model", ["rigid_rod", "point_split", "heavy_rod"])
@pytest.mark.slow
def test_instantaneous_power_balance(model):
    """tau . thetadot + F_R Rdot = dE/dt at many instants, R moving; E incl. the rods' rotational energy.

    Also: the closed-form energy equals the literal one (FK positions, autodiff velocities, m/2 |v_c|^2 +
    I_c/2 |u x u'|^2 for the rods) to 1e-12 J.
    """
    for t in np.linspace(0.0, 3.0, 7):
        power, dEdt, dT, dV = _power_and_dEdt(jnp.asarray(t), ROBOTS[model])
        assert abs(float(power)) > 0.1
        assert abs(float(power - dEdt)) < 1e-9 * (1.0 + abs(float(power)))
        assert abs(float(dT)) < 1e-12 and abs(float(dV)) < 1e-12


@pytest.mark.parametrize("model", ["rigid_rod", "point_split"])
@pytest.mark.slow
def test_integrated_energy_balance_along_cycle(model):
    """Integral of tau . qdot dt over a Cartesian cycle with moving R = change of kinetic + potential energy."""
    rec = dj.presets.franco2026()
    robot = eqx.tree_at(lambda d: d.mass, rec.robot, ROBOTS[model].mass, is_leaf=lambda x: x is None)
    # Half an Adept cycle (ends at rest) is symmetric; use a straight move between different heights instead,
    # ending at a different potential energy, with R moving from 0.22 to 0.26 m.
    cycle = tr.point_to_point((-0.1, 0.02, 0.35), (0.08, -0.05, 0.42), duration=0.4, law="cycloidal",
                              n_samples=1001)
    cycle = tr.with_R_profile(cycle, 0.22, 0.26, amplitude=0.01)
    prof = _profile(robot, cycle)
    assert bool(jnp.all(prof.ok))
    power = jnp.sum(prof.tau * prof.theta_dot, axis=1) + prof.force_R * prof.R_dot
    t = np.asarray(prof.t)
    h = t[1] - t[0]
    w = np.ones(t.size)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0   # Simpson (n_samples odd)
    work = float(np.sum(w * np.asarray(power)) * h / 3.0)

    def E(k):
        rob = robot.with_base_radius(prof.R[k])
        motion = dyn.Motion(prof.p[k], prof.p_dot[k], prof.p_ddot[k], prof.theta[k], prof.theta_dot[k],
                            prof.theta_ddot[k], prof.R_dot[k], jnp.zeros(()), jnp.asarray(True))
        T, V = dyn.energy(rob, motion)
        return float(T + V)

    dE = E(-1) - E(0)
    assert abs(dE) > 0.05  # a real change of potential energy is being checked
    assert abs(work - dE) < 1e-8 * (1.0 + float(np.sum(np.abs(np.asarray(power))) * h))


def _on_axis(robot, z):
    """Closed form for a symmetric robot with the platform on the z axis (all three theta equal)."""
    R, r, L1, L2 = (float(getattr(robot, f)) for f in ("base_radius", "platform_radius", "upper_arm", "forearm"))
    # solve (R - r + L1 cos th)^2 + (z - L1 sin th)^2 = L2^2 for the outer branch by scalar Newton
    th = 0.3
    for _ in range(60):
        f = (R - r + L1 * math.cos(th)) ** 2 + (z - L1 * math.sin(th)) ** 2 - L2 ** 2
        df = -2 * (R - r + L1 * math.cos(th)) * L1 * math.sin(th) - 2 * (z - L1 * math.sin(th)) * L1 * math.cos(th)
        th -= f / df
    return th


def _with_model(robot, model):
    return eqx.tree_at(lambda d: d.mass, robot, robot.mass.with_forearm_model(model))


@pytest.mark.parametrize("model", ["rigid_rod", "point_split"])
@pytest.mark.slow
def test_static_holding_torque_closed_form(model):
    """On the axis, every arm holds g s cos(th) plus a third of the platform weight through its forearm.

    The same for both forearm models (same weight, same centre of mass): the static torques are unchanged.
    """
    robot = _with_model(dj.presets.industrial(), model)
    mm = robot.mass
    for z in (0.55, 0.7, 0.85):
        th = _on_axis(robot, z)
        R, r, L1, L2 = 0.2, 0.05, 0.35, 0.8
        ux = (r - R - L1 * math.cos(th)) / L2   # forearm unit vector in the chain plane (platform on axis)
        uz = (z - L1 * math.sin(th)) / L2
        s_arm = float(mm.arm_first_moment(L1))
        M = float(mm.moving_mass())
        g = float(mm.gravity)
        expected = -g * s_arm * math.cos(th) - M * g * L1 * (uz * math.cos(th) - ux * math.sin(th)) / (3 * uz)
        got = dyn.gravity_torques(robot, jnp.asarray([0.0, 0.0, z]), jnp.full((3,), th))
        np.testing.assert_allclose(got.tau, expected, rtol=1e-12)
        other = dyn.gravity_torques(_with_model(robot, "point_split"), jnp.asarray([0.0, 0.0, z]), jnp.full((3,), th))
        np.testing.assert_array_equal(got.tau, other.tau)
        np.testing.assert_array_equal(got.force_R, other.force_R)
        # the ik solution agrees with the scalar closed form
        np.testing.assert_allclose(dj.ik(robot, jnp.asarray([0.0, 0.0, z])).theta, th, rtol=1e-12)


@pytest.mark.parametrize("model", ["rigid_rod", "point_split"])
@pytest.mark.slow
def test_vertical_move_symmetric_robot(model):
    """Pure vertical move on the axis = a 1-DOF system: tau = I thdd - g s cos th + (M/3)(zdd - g) dz/dth.

    The rigid rod adds -J (h thdd + h'/2 thd^2) with |w'|^2 = h(th) thd^2, h = (L1 sin th)^2 + (z' - L1 cos th)^2
    (its kinetic energy is the point split's minus J/2 |w'|^2 per chain, J = m (s (1 - s) - I_c / (m L2^2))).
    """
    robot = _with_model(dj.presets.industrial(), model)
    mm = robot.mass
    R, r, L1, L2 = 0.2, 0.05, 0.35, 0.8
    cycle = tr.point_to_point((0.0, 0.0, 0.6), (0.0, 0.0, 0.8), duration=0.3, law="modified_trapezoid",
                              n_samples=K)
    prof = _profile(robot, cycle)
    th, thd, thdd = (np.asarray(a) for a in (prof.theta, prof.theta_dot, prof.theta_ddot))
    np.testing.assert_allclose(th - th[:, :1], 0.0, atol=1e-12)   # symmetry
    zf = lambda t: L1 * jnp.sin(t) + jnp.sqrt(L2 ** 2 - (R - r + L1 * jnp.cos(t)) ** 2)  # noqa: E731
    dz = jax.vmap(jax.grad(zf))(jnp.asarray(th[:, 0]))
    d2z = jax.vmap(jax.grad(jax.grad(zf)))(jnp.asarray(th[:, 0]))
    zdd = d2z * thd[:, 0] ** 2 + dz * thdd[:, 0]
    np.testing.assert_allclose(zdd, prof.p_ddot[:, 2], rtol=1e-9, atol=1e-9)
    I, s_arm, M, g = (float(x) for x in (mm.arm_inertia(L1), mm.arm_first_moment(L1), mm.moving_mass(), mm.gravity))
    expected = I * thdd[:, 0] - g * s_arm * np.cos(th[:, 0]) + M / 3.0 * (np.asarray(zdd) - g) * np.asarray(dz)
    hf = lambda t: (L1 * jnp.sin(t)) ** 2 + (jax.grad(zf)(t) - L1 * jnp.cos(t)) ** 2  # noqa: E731
    h = np.asarray(jax.vmap(hf)(jnp.asarray(th[:, 0])))
    dh = np.asarray(jax.vmap(jax.grad(hf))(jnp.asarray(th[:, 0])))
    J = float(mm.forearm_rotation_deficit())
    assert (J > 0.04) == (model == "rigid_rod")   # 0.3 kg / 6 for uniform rods, 0 for the point split
    expected = expected - J * (h * thdd[:, 0] + 0.5 * dh * thd[:, 0] ** 2)
    for i in range(3):
        np.testing.assert_allclose(prof.tau[:, i], expected, rtol=1e-10, atol=1e-10)
    # speed-limited cycle time of the 1-DOF move: max |theta'| / omega_max
    m = _metrics(robot, cycle, cyc.Limits(torque=jnp.inf, speed=2.0))
    assert abs(float(m.cycle_time) - float(np.max(np.abs(thd)) * 0.3 / 2.0)) < 1e-12


@pytest.mark.slow
def test_time_scaling_law_and_min_cycle_time():
    """tau(T) = a / T^2 + g exactly; the closed-form minimum cycle time matches a bisection on full profiles."""
    robot = dj.presets.franco2026(fixed_R=0.2, with_mass=True)
    cycle = tr.adept_cycle((0.0, 0.02, 0.42), heading=0.4, duration=0.5, n_samples=K)
    p1 = _profile(robot, cycle, 0.5)
    p2 = _profile(robot, cycle, 1.0)
    np.testing.assert_allclose(p2.tau - p2.tau_gravity, (p1.tau - p1.tau_gravity) / 4.0, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(p2.theta_dot, p1.theta_dot / 2.0, rtol=1e-12)
    for limits in (LIMITS, cyc.Limits(torque=5.0, speed=jnp.inf), cyc.Limits(torque=jnp.inf, speed=4.0)):
        m = _metrics(robot, cycle, limits)
        Tb = _bisect(robot, cycle, limits)
        assert bool(m.ok)
        assert abs(float(m.cycle_time) - float(Tb)) < 1e-9 * float(Tb)
        assert abs(float(m.cycles_per_minute) - 60.0 / float(m.cycle_time)) < 1e-9
        # at the minimum cycle time the binding limit is met with equality
        prof = _profile(robot, cycle, m.cycle_time)
        assert bool(_within(prof, limits, rtol=1e-9))
        assert not bool(_within(_profile(robot, cycle, 0.999 * m.cycle_time), limits))
    # gravity alone above the torque limit: no cycle time, flagged
    weak = _metrics(robot, cycle, cyc.Limits(torque=0.5))
    assert bool(weak.reachable) and not bool(weak.ok) and math.isinf(float(weak.cycle_time))


@pytest.mark.slow
def test_unreachable_cycle_is_masked_not_raised():
    """vmap over trajectories: an unreachable cycle gives ok=False and NaN metrics, no exception."""
    robot = dj.presets.franco2026(fixed_R=0.2, with_mass=True)
    cycles = jax.tree.map(lambda *a: jnp.stack(a), tr.adept_cycle((0.0, 0.0, 0.4), n_samples=K),
                          tr.adept_cycle((0.0, 0.0, 0.62), n_samples=K))
    m = jax.jit(jax.vmap(cyc.cycle_metrics, in_axes=(None, 0, None)))(robot, cycles, LIMITS)
    assert bool(m.ok[0]) and not bool(m.ok[1]) and not bool(m.reachable[1])
    assert int(m.n_bad[0]) == 0 and int(m.n_bad[1]) > 0
    assert np.isfinite(np.asarray(m.peak_torque[0])).all() and np.isnan(np.asarray(m.peak_torque[1])).all()
    assert np.isnan(float(m.cycle_time[1]))
    single = _metrics(robot, tr.adept_cycle((0.0, 0.0, 0.4), n_samples=K), LIMITS)
    np.testing.assert_allclose(m.cycle_time[0], single.cycle_time, rtol=1e-12)


TRACES = []


def _counted_metrics(robot, cycle, limits):
    TRACES.append(1)  # runs only while tracing
    return cyc.cycle_metrics(robot, cycle, limits)


_population_metrics = jax.jit(jax.vmap(_counted_metrics, in_axes=(0, None, None)))


@pytest.mark.slow
def test_vmap_over_designs_no_retrace_and_finite_gradient():
    robot = dj.presets.franco2026(fixed_R=0.2, with_mass=True)
    cycle = tr.adept_cycle((0.0, 0.0, 0.4), n_samples=K)

    def population(L1, m_arm):
        return jax.vmap(lambda a, b: eqx.tree_at(lambda d: (d.upper_arm, d.mass.upper_arm_mass), robot, (a, b)))(
            jnp.asarray(L1), jnp.asarray(m_arm))

    pop = _population_metrics(population([0.18, 0.2, 0.22, 0.24, 0.08], [1.0, 1.5, 2.0, 1.2, 1.0]), cycle, LIMITS)
    n = len(TRACES)
    pop2 = _population_metrics(population([0.19, 0.21, 0.23, 0.2, 0.2], [1.1, 1.6, 2.1, 1.3, 1.0]), cycle, LIMITS)
    assert len(TRACES) == n  # new designs: no retrace
    assert bool(jnp.all(pop.ok[:4])) and not bool(pop.ok[4])  # L1 = 0.08 m cannot reach z = 0.4 m
    assert np.isnan(float(pop.cycle_time[4])) and int(pop.n_bad[4]) > 0
    assert np.all(np.diff(np.asarray(pop.cycle_time[:4])) != 0) and bool(jnp.all(pop2.ok))
    one = eqx.tree_at(lambda d: (d.upper_arm, d.mass.upper_arm_mass), robot, (jnp.asarray(0.22), jnp.asarray(2.0)))
    np.testing.assert_allclose(pop.cycle_time[2], _metrics(one, cycle, LIMITS).cycle_time, rtol=1e-12)

    def cycle_time(L1, metrics=cyc.cycle_metrics):
        return metrics(eqx.tree_at(lambda d: d.upper_arm, robot, L1), cycle, LIMITS).cycle_time

    g = jax.jit(jax.grad(cycle_time))(jnp.asarray(0.2))
    h = 1e-6
    fd = (cycle_time(jnp.asarray(0.2 + h), _metrics) - cycle_time(jnp.asarray(0.2 - h), _metrics)) / (2 * h)
    assert np.isfinite(float(g)) and abs(float(g) - float(fd)) < 1e-4 * abs(float(fd))

    # peak and RMS torque (one variadic reduction with its own JVP) against central differences too
    def peak_rms(L1, metrics=cyc.cycle_metrics):
        m = metrics(eqx.tree_at(lambda d: d.upper_arm, robot, L1), cycle, LIMITS)
        return m.peak_torque[0] + 10.0 * m.rms_torque[1]

    g = jax.jit(jax.grad(peak_rms))(jnp.asarray(0.2))
    fd = (peak_rms(jnp.asarray(0.2 + h), _metrics) - peak_rms(jnp.asarray(0.2 - h), _metrics)) / (2 * h)
    assert np.isfinite(float(g)) and abs(float(g) - float(fd)) < 1e-4 * abs(float(fd))


@pytest.mark.slow
def test_reconfiguration_force_static():
    """At rest the R actuator carries the radial components of the forearm forces: sum_i Jq_i0 y_i."""
    rec = dj.presets.franco2026(with_mass=True)
    robot = rec.at(0.3)
    p = jnp.asarray([0.03, -0.02, 0.4])
    th = dj.ik(robot, p).theta
    st_ = dyn.gravity_torques(robot, p, th)
    jac = dj.jacobians(robot, p, th)
    M = float(robot.mass.moving_mass())
    y = np.linalg.solve(np.asarray(jac.Jx).T, np.array([0.0, 0.0, -M * 9.80665]))
    np.testing.assert_allclose(float(st_.force_R), float(np.asarray(jac.Jq)[:, 0] @ y), rtol=1e-12)
    # the arm masses add nothing: gravity is vertical and d(arm point)/dR is horizontal
    assert abs(float(st_.force_R)) > 1e-3


def test_mass_config_validation():
    base = {"name": "x", "base_radius": 0.2, "platform_radius": 0.065, "upper_arm": 0.2, "forearm": 0.4,
            "theta_min_deg": -40.0, "theta_max_deg": 110.0}
    good = dict(base, mass={"upper_arm_mass": 1.0, "upper_arm_inertia": 0.004, "forearm_mass": 0.04})
    robot, _ = robot_from_config(OmegaConf.create(good))
    assert abs(float(robot.mass.upper_arm_inertia_factor) - 0.004 / (1.0 * 0.2 ** 2)) < 1e-15
    bad_cases = [({"upper_arm_mass": -1.0}, "robot.mass.upper_arm_mass"),
                 ({"upper_arm_mass": 1.0, "forearm_elbow_fraction": 1.5}, "robot.mass.forearm_elbow_fraction"),
                 ({"upper_arm_mass": 1.0, "gear_ratio": 0.0}, "robot.mass.gear_ratio"),
                 ({"upper_arm_mass": 1.0, "platform_mass": "heavy"}, "robot.mass.platform_mass"),
                 ({"upper_arm_mass": 1.0, "rotor_inertia": float("nan")}, "robot.mass.rotor_inertia"),
                 ({"upper_arm_mass": 1.0, "wheels": 2}, "robot.mass: unknown keys wheels"),
                 ({"forearm_mass": 0.1}, "robot.mass.upper_arm_mass")]
    for mass, field in bad_cases:
        with pytest.raises(ConfigError, match=field.replace(".", r"\.")):
            robot_from_config(OmegaConf.create(dict(base, mass=mass)))
    with pytest.raises(ValueError, match="payload_mass"):
        MassModel(upper_arm_mass=1.0, payload_mass=-0.1)
    with pytest.raises(ValueError, match="mass model"):
        dyn.inverse_dynamics(dj.presets.franco2026(fixed_R=0.2), jnp.zeros(3), jnp.zeros(3), jnp.zeros(3))
    assert mass_from_config({"upper_arm_mass": 2}).upper_arm_mass == 2.0
    # the shipped configs parse and match the presets
    for name, preset in (("franco2026", dj.presets.franco2026(fixed_R=0.2, with_mass=True)),
                         ("industrial", dj.presets.industrial())):
        r, _ = robot_from_config(OmegaConf.load(CONFIGS / "robot" / f"{name}.yaml"))
        assert r.mass.forearm_model == preset.mass.forearm_model
        for leaf_a, leaf_b in zip(jax.tree.leaves(r.mass), jax.tree.leaves(preset.mass)):
            assert abs(float(leaf_a) - float(leaf_b)) < 1e-12


# ---------------------------------------------------------------------------------------------------------
# Independent reference: Newton-Euler on free-body diagrams (NumPy, no Lagrangian, no Jacobian, no lumping)
# ---------------------------------------------------------------------------------------------------------
def newton_euler(robot, p, pd, pdd, th, thd, thdd, R, Rd, Rdd):
    """Arm torques (K, 3) and R force (K,) from free-body diagrams of the arms, forearm rods and platform.

    Bodies: arm i (mass m_a at c L1, inertia about its centre kI m_a L1^2, elbow hardware m_e at B_i, reflected
    rotor n^2 J) rotating about -y_i through A_i = (R, 0, 0), A_i carried radially by the R actuator with the
    carriage m_c; forearm i, a slender rod from B_i to C_i = P + (r, 0, 0) (both parallelogram rods together:
    mass m_f, centre of mass x_c = s B + (1 - s) C, inertia I_c about it perpendicular to the rod); the platform,
    a point mass M_p = plate + payload at P. Gravity g along +z. The forearm's end forces F_B (arm on rod) and
    F_C (platform on rod) follow from the rod's Newton and Euler equations up to the axial force t_i; the
    platform's Newton equation gives the three t_i; the arm's Euler equation about A_i gives tau_i and the
    radial Newton equation of carriage + arm the R force. Rows of the state arrays are samples (chain frames
    rotate base vectors by alpha_i about z).
    """
    mm = robot.mass
    f = lambda x: np.asarray(x, dtype=float)  # noqa: E731
    L1, L2, r = float(robot.upper_arm), float(robot.forearm), float(robot.platform_radius)
    m_a, cf, kI = float(mm.upper_arm_mass), float(mm.upper_arm_com_fraction), float(mm.upper_arm_inertia_factor)
    m_e, m_f, s_f, m_c = float(mm.elbow_mass), float(mm.forearm_mass), float(mm.forearm_elbow_fraction), float(
        mm.carriage_mass)
    I_c = float(mm.forearm_inertia(L2))
    M_p = float(mm.platform_mass + mm.payload_mass)
    g = float(mm.gravity)
    I_arm = kI * m_a * L1 ** 2 + m_a * (cf * L1) ** 2 + m_e * L1 ** 2 + float(mm.gear_ratio) ** 2 * float(
        mm.rotor_inertia)
    p, pd, pdd, th, thd, thdd = (f(x) for x in (p, pd, pdd, th, thd, thdd))
    Kn = p.shape[0]
    R, Rd, Rdd = (np.broadcast_to(f(x), (Kn,)) for x in (R, Rd, Rdd))
    gz = np.array([0.0, 0.0, g])
    e_axis = np.array([0.0, -1.0, 0.0])  # +theta rotation axis in the chain frame
    rots = []
    for a in (0.0, 2 * math.pi / 3, 4 * math.pi / 3):
        ca, sa = math.cos(a), math.sin(a)
        rots.append(np.array([[ca, sa, 0.0], [-sa, ca, 0.0], [0.0, 0.0, 1.0]]))  # base -> chain i
    tau = np.empty((Kn, 3))
    FR = np.zeros(Kn)
    U = np.empty((Kn, 3, 3))           # base-frame unit rods (columns)
    Fperp = np.zeros((Kn, 3))          # sum of the non-axial parts of F_C (base frame)
    per_chain = []
    for i, Q in enumerate(rots):
        c, s = np.cos(th[:, i]), np.sin(th[:, i])
        ploc, aloc = p @ Q.T, pdd @ Q.T
        zero = np.zeros(Kn)
        a_A = np.stack([Rdd, zero, zero], axis=1)
        rB = L1 * np.stack([c, zero, s], axis=1)
        dB = np.stack([-s, zero, c], axis=1)          # d rB / d theta / L1
        ddB = np.stack([-c, zero, -s], axis=1)
        a_B = a_A + L1 * (dB * thdd[:, i:i + 1] + ddB * thd[:, i:i + 1] ** 2)
        a_ca = a_A + cf * L1 * (dB * thdd[:, i:i + 1] + ddB * thd[:, i:i + 1] ** 2)
        B = np.stack([R, zero, zero], axis=1) + rB
        C = ploc + np.array([r, 0.0, 0.0])
        w = C - B
        u = w / L2
        u_dd = (aloc - a_B) / L2
        a_c = s_f * a_B + (1.0 - s_f) * aloc
        v = (I_c / L2) * u_dd + (1.0 - s_f) * m_f * (a_c - gz)
        F_perp = v - np.sum(v * u, axis=1, keepdims=True) * u   # rod's moment equation about its centre of mass
        U[:, :, i] = u @ Q                                       # chain -> base (Q orthogonal)
        Fperp += F_perp @ Q
        per_chain.append((Q, u, F_perp, a_c, rB, a_A, a_ca, a_B))
    # platform: M_p (pdd - g) = -sum_i F_C,i,  F_C,i = t_i u_i + F_perp,i
    t = np.linalg.solve(U, (-M_p * (pdd - gz) - Fperp)[..., None])[..., 0]
    for i, (Q, u, F_perp, a_c, rB, a_A, a_ca, a_B) in enumerate(per_chain):
        F_C = t[:, i:i + 1] * u + F_perp
        F_B = m_f * (a_c - gz) - F_C                            # rod's Newton equation
        r_ca = rB * cf
        first = m_a * r_ca + m_e * rB
        tau[:, i] = (I_arm * thdd[:, i] + np.cross(first, a_A - gz) @ e_axis + np.cross(rB, F_B) @ e_axis)
        FR += m_c * a_A[:, 0] + m_a * a_ca[:, 0] + m_e * a_B[:, 0] + F_B[:, 0]
    return tau, FR


def _ne_check(robot, cycle, *, has_R=False):
    prof = _profile(robot, cycle)
    lag = jax.jit(cyc.cycle_profile, static_argnames="method")(robot, cycle, method="lagrange")
    assert bool(jnp.all(prof.ok))
    T = float(cycle.duration)
    Rdd = np.asarray(cycle.ddR) / T ** 2 if has_R else 0.0
    R = np.asarray(prof.R)
    tau_ne, fR_ne = newton_euler(robot, prof.p, prof.p_dot, prof.p_ddot, prof.theta, prof.theta_dot,
                                 prof.theta_ddot, R, prof.R_dot, Rdd)
    peak = float(np.max(np.abs(tau_ne)))
    for got in (prof, lag):
        np.testing.assert_allclose(np.asarray(got.tau), tau_ne, rtol=0, atol=1e-9 * peak)
        np.testing.assert_allclose(np.asarray(got.force_R), fR_ne, rtol=0,
                                   atol=1e-9 * max(float(np.max(np.abs(fR_ne))), peak))
    return prof


@pytest.mark.parametrize("preset", ["franco2026", "industrial"])
@pytest.mark.parametrize("model", ["rigid_rod", "point_split"])
@pytest.mark.slow
def test_newton_euler_reference_on_presets(preset, model):
    """Both presets, both forearm models: standard cycle and a 3-D move against free-body Newton-Euler, 1e-9."""
    if preset == "franco2026":
        robot, centre, move = (dj.presets.franco2026(fixed_R=0.2, with_mass=True), (0.0, 0.0, 0.4),
                               ((-0.12, 0.08, 0.36), (0.1, -0.06, 0.45)))
    else:
        robot, centre, move = (dj.presets.industrial(), (0.0, 0.0, 0.7),
                               ((-0.25, 0.15, 0.62), (0.2, -0.2, 0.82)))
    robot = _with_model(robot, model)
    _ne_check(robot, tr.adept_cycle(centre, heading=0.3, duration=0.5, n_samples=K))
    _ne_check(robot, tr.point_to_point(*move, duration=0.4, law="cycloidal", n_samples=K))


@pytest.mark.parametrize("model", ["rigid_rod", "point_split", "heavy_rod"])
@pytest.mark.slow
def test_newton_euler_reference_moving_R(model):
    """Every mass term on (rotor, carriage, payload, off-centre arm, non-uniform rods) and R moving."""
    cycle = tr.with_R_profile(tr.point_to_point((-0.1, 0.02, 0.35), (0.08, -0.05, 0.42), duration=0.4,
                                                law="cycloidal", n_samples=K), 0.22, 0.26, amplitude=0.01)
    _ne_check(ROBOTS[model], cycle, has_R=True)


@pytest.mark.slow
def test_rigid_rod_special_cases_and_difference():
    """rigid_rod with the two-end-mass inertia s (1 - s) is the point split; uniform rods need less torque."""
    robot = dj.presets.industrial()
    s = float(robot.mass.forearm_elbow_fraction)
    ends = eqx.tree_at(lambda d: d.mass.forearm_inertia_factor, robot, jnp.asarray(s * (1 - s)))
    split = _with_model(robot, "point_split")
    cycle = tr.adept_cycle((0.0, 0.0, 0.7), n_samples=K)
    a, b, c = (_profile(x, cycle) for x in (ends, split, robot))
    np.testing.assert_allclose(a.tau, b.tau, rtol=0, atol=1e-12 * float(np.max(np.abs(b.tau))))
    np.testing.assert_array_equal(b.tau_gravity, c.tau_gravity)   # static part identical
    # the independent estimate: ~7 % lower peak torque for industrial with uniform rods
    ratio = float(np.max(np.abs(c.tau)) / np.max(np.abs(b.tau)))
    assert 0.90 < ratio < 0.97


def test_forearm_model_validation():
    base = {"name": "x", "base_radius": 0.2, "platform_radius": 0.065, "upper_arm": 0.2, "forearm": 0.4,
            "theta_min_deg": -40.0, "theta_max_deg": 110.0}
    r, _ = robot_from_config(OmegaConf.create(dict(base, mass={"upper_arm_mass": 1.0,
                                                                "forearm_model": "point_split"})))
    assert r.mass.forearm_model == "point_split"
    r, _ = robot_from_config(OmegaConf.create(dict(base, mass={"upper_arm_mass": 1.0})))
    assert r.mass.forearm_model == "rigid_rod"
    bad = [({"forearm_model": "rods"}, r"robot\.mass\.forearm_model"),
           ({"forearm_inertia_factor": 0.3}, r"robot\.mass\.forearm_inertia_factor.*0\.25"),
           ({"forearm_inertia_factor": -0.1}, r"robot\.mass\.forearm_inertia_factor"),
           ({"forearm_model": "point_split", "forearm_inertia_factor": 0.1}, r"robot\.mass\.forearm_inertia_factor")]
    for extra, match in bad:
        with pytest.raises(ConfigError, match=match):
            robot_from_config(OmegaConf.create(dict(base, mass=dict({"upper_arm_mass": 1.0}, **extra))))
    with pytest.raises(ValueError, match="forearm_model"):
        MassModel(upper_arm_mass=1.0, forearm_model="rod")
    # a batch of designs keeps one model (static field): vmapped construction works and does not retrace
    pop = jax.vmap(lambda m: MassModel(upper_arm_mass=m, forearm_model="point_split"))(jnp.asarray([1.0, 2.0]))
    assert pop.forearm_model == "point_split" and pop.upper_arm_mass.shape == (2,)


@pytest.mark.slow
def test_dynamics_cycle_experiment_reports_both_forearm_models(toy_run):
    """The CLI job evaluates both forearm models on every robot/case and writes the comparison to HDF5."""
    from deltajax.io import load

    # n_samples=41, robots=[industrial]: the session's shared toy run (tests/toy_jobs.py; the CLI itself is
    # exercised through a subprocess by tests/test_io_cli.py)
    d = load(toy_run("dynamics_cycle"))["dynamics"]
    cmp_ = d["forearm_models"]
    assert list(cmp_["forearm_model"]) == ["rigid_rod", "point_split"]
    cases = list(cmp_["case"])
    assert "industrial/adept" in cases and "franco2026/adept" in cases
    ind = d["industrial"]["adept_forearm_models"]
    assert -0.09 < float(ind["rel_change_peak_torque"]) < -0.05      # ~ -7 %
    assert float(ind["rel_change_cycle_time"]) < 0
    # the robot's own model (rigid_rod, the preset default) is what the main metrics hold
    np.testing.assert_array_equal(ind["peak_torque"][0], d["industrial"]["adept_metrics"]["peak_torque"])


@pytest.mark.slow
@pytest.mark.parametrize("model", ["point_split", "rigid_rod"])
def test_benchmark_agrees_with_its_numpy_baseline(model, tmp_path):
    """experiments/bench_dynamics.py at a tiny size: every JAX form matches the independent NumPy torques."""
    import json
    import os
    import subprocess
    import sys

    from toy_jobs import JAX_CACHE

    repo = CONFIGS.parent
    # the session's persistent XLA cache through JAX's own variable (the script sets none): 4.9 s wall compiling
    # at this size, 2.2 s reading (the threshold is the session's, tests/conftest.py)
    env = {**os.environ, "PYTHONPATH": str(repo), "JAX_COMPILATION_CACHE_DIR": JAX_CACHE}
    out = subprocess.run([sys.executable, str(repo / "experiments" / "bench_dynamics.py"), "--designs", "6",
                          "--samples", "21", "--repeats", "1", "--forearm-model", model, "--json",
                          str(tmp_path / "b.json")], cwd=repo, env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    res = json.loads((tmp_path / "b.json").read_text())
    assert res["all_ok"] and max(res["max_abs_diff_numpy_jax_Nm"].values()) < 1e-9
    assert ("jax_old" in res["max_abs_diff_numpy_jax_Nm"]) == (model == "point_split")
