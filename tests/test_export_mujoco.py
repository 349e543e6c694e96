"""dj.export.mjcf in MuJoCo: the exported models load, MuJoCo's inverse dynamics of the closed loops equals
dj.cycle_profile along the standard cycle (both forearm models, a moving R), and a forward simulation driven by
deltajax's torques follows the cycle."""

import equinox as eqx
import mujoco
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import deltajax as dj
from deltajax import trajectory as tr

#: MuJoCo's inverse dynamics vs deltajax, relative to the peak |effort| of the profile
ID_RTOL = 1e-9
#: forward simulation: largest platform-position error over one cycle (m) and the largest loop-closure violation (m)
SIM_POS_TOL = 2.5e-4
SIM_LOOP_TOL = 1e-5


def franco(R_moving=False, forearm_model="rigid_rod"):
    rec = dj.presets.franco2026(with_mass=True)
    # a carriage mass, so the R actuator's inertial term is exercised
    mass = rec.robot.mass.with_forearm_model(forearm_model)
    mass = eqx.tree_at(lambda m: m.carriage_mass, mass, mass.carriage_mass * 0 + 0.4)
    rec = eqx.tree_at(lambda r: r.robot.mass, rec, mass)
    return rec if R_moving else rec.robot


def industrial(forearm_model="rigid_rod"):
    rob = dj.presets.industrial()
    return eqx.tree_at(lambda d: d.mass, rob, rob.mass.with_forearm_model(forearm_model))


CENTRES = {"franco2026": (0.0, 0.0, 0.4), "industrial": (0.0, 0.0, 0.7)}


def load(robot, **kw):
    model = mujoco.MjModel.from_xml_string(dj.export.mjcf(robot, **kw))
    model.opt.jacobian = mujoco.mjtJacobian.mjJAC_DENSE
    return model, mujoco.MjData(model)


def set_state(model, data, state):
    for name, (q, v, a) in state.items():
        j = model.joint(name)
        n_q, n_v = (4, 3) if model.jnt_type[j.id] == mujoco.mjtJoint.mjJNT_BALL else (1, 1)
        qa, va = model.jnt_qposadr[j.id], model.jnt_dofadr[j.id]
        data.qpos[qa:qa + n_q] = q
        data.qvel[va:va + n_v] = v
        data.qacc[va:va + n_v] = a


def mujoco_efforts(model, data, state):
    """(actuator forces, loop residual): qfrc_inverse of mj_inverse (constraints off) = actuator moment^T f +
    J_eq^T lambda, solved by least squares for f and the loop-closure multipliers lambda."""
    set_state(model, data, state)
    model.opt.disableflags = 0
    mujoco.mj_forward(model, data)                          # efc_J of the connect and coupling equalities
    eq = data.efc_type[:data.nefc] == mujoco.mjtConstraint.mjCNSTR_EQUALITY
    J_eq = data.efc_J.reshape(data.nefc, model.nv)[eq]
    loop_vel = np.abs(J_eq @ data.qvel).max()
    set_state(model, data, state)                           # mj_forward overwrote qacc
    model.opt.disableflags = mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
    mujoco.mj_inverse(model, data)
    moment = np.zeros((model.nu, model.nv))
    mujoco.mju_sparse2dense(moment, data.actuator_moment, data.moment_rownnz, data.moment_rowadr, data.moment_colind)
    A = np.concatenate([moment.T, J_eq.T], axis=1)
    x, *_ = np.linalg.lstsq(A, data.qfrc_inverse, rcond=None)
    model.opt.disableflags = 0
    return x[:model.nu], np.abs(A @ x - data.qfrc_inverse).max(), loop_vel


def states(robot, cycle, prof):
    recon = isinstance(robot, dj.ReconfigurableDelta)
    T = float(cycle.duration)
    R_dd = np.asarray(cycle.ddR) / T ** 2 if recon else np.zeros(cycle.n_samples)
    for k in range(cycle.n_samples):
        yield dj.export.joint_state(robot, prof.p[k], prof.p_dot[k], prof.p_ddot[k], prof.theta[k], prof.theta_dot[k],
                                    prof.theta_ddot[k], R=float(prof.R[k]) if recon else None,
                                    R_dot=float(prof.R_dot[k]), R_ddot=float(R_dd[k]))


@pytest.mark.parametrize("robot", [dj.presets.industrial(), dj.presets.franco2026(with_mass=True),
                                   dj.presets.franco2026(fixed_R=0.2, with_mass=True)], ids=["industrial", "franco2026",
                                                                                         "franco2026_fixed"])
def test_exported_model_loads_assembled(robot):
    model, data = load(robot)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    mujoco.mj_forward(model, data)
    assert model.nu == (4 if isinstance(robot, dj.ReconfigurableDelta) else 3)
    for i in range(3):
        gap = data.site(f"forearm_end_{i}").xpos - data.site(f"platform_joint_{i}").xpos
        assert np.abs(gap).max() < 1e-12
    base = robot.robot if isinstance(robot, dj.ReconfigurableDelta) else robot
    m = base.mass
    # total mass: MuJoCo's subtree of the world = every link of the mass model once
    total = 3 * (m.upper_arm_mass + m.elbow_mass + m.forearm_mass) + m.platform_mass + m.payload_mass
    if isinstance(robot, dj.ReconfigurableDelta):
        total = total + 3 * max(float(m.carriage_mass), 1e-9)
    assert model.body_subtreemass[0] == pytest.approx(float(total), rel=1e-9)
    n = float(m.gear_ratio)
    assert model.dof_armature[model.jnt_dofadr[model.joint("theta_0").id]] == pytest.approx(n * n * float(m.rotor_inertia))


CASES = [("industrial", "rigid_rod", False), ("industrial", "point_split", False),
         ("franco2026", "rigid_rod", False), ("franco2026", "point_split", True), ("franco2026", "rigid_rod", True)]


@pytest.mark.parametrize("name, forearm_model, R_moving", CASES)
@pytest.mark.slow
def test_mujoco_inverse_dynamics_matches_cycle_profile(name, forearm_model, R_moving):
    robot = industrial(forearm_model) if name == "industrial" else franco(R_moving, forearm_model)
    cycle = tr.adept_cycle(CENTRES[name], duration=0.4, n_samples=9)
    if R_moving:
        cycle = tr.with_R_profile(cycle, 0.2, amplitude=0.02)
    prof = dj.cycle_profile(robot.robot if R_moving else robot, cycle)
    assert bool(np.all(prof.ok))
    model, data = load(robot)
    n = float((robot.robot if R_moving else robot).mass.gear_ratio)
    scale = np.abs(np.asarray(prof.tau)).max()
    for k, st in enumerate(states(robot, cycle, prof)):
        f, resid, loop_vel = mujoco_efforts(model, data, st)
        assert loop_vel < 1e-12 * (1 + scale)                       # the joint state closes the loops
        assert resid < ID_RTOL * scale                             # loops + actuators explain all of qfrc
        np.testing.assert_allclose(n * f[:3], np.asarray(prof.tau[k]), rtol=0, atol=ID_RTOL * scale)
        if R_moving:
            fscale = np.abs(np.asarray(prof.force_R)).max()
            assert abs(f[3] - float(prof.force_R[k])) <= ID_RTOL * fscale


@pytest.mark.slow
@pytest.mark.parametrize("name", ["industrial", "franco2026_R"])
def test_forward_simulation_tracks_cycle(name):
    """Open loop: MuJoCo integrates the exported model driven by deltajax's torques (held over each step at their
    midpoint value, RK4) and the platform follows the cycle within SIM_POS_TOL. The held torque leaves a local
    error of jerk dt^3 / 12 per step (O(dt^2) over the cycle, amplified by the open loop): on industrial 400 steps
    drift 1.5 mm, 1000 steps 0.09 mm (franco2026 with R moving: 0.03 mm). Loop gaps stay below 1e-6 m with the
    export's constraint impedance (solimp 0.9999)."""
    R_moving = name.endswith("_R")
    robot = industrial() if name == "industrial" else franco(R_moving)
    base = robot.robot if R_moving else robot
    steps, T = 1000, 0.4
    cycle = tr.adept_cycle(CENTRES[name.split("_")[0]], duration=T, n_samples=2 * steps + 1)
    if R_moving:
        cycle = tr.with_R_profile(cycle, 0.2, amplitude=0.02)
    prof = dj.cycle_profile(base, cycle)
    model, data = load(robot, timestep=T / steps)
    model.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    first = next(states(robot, cycle, prof))
    set_state(model, data, first)
    mujoco.mj_forward(model, data)
    n = float(base.mass.gear_ratio)
    P = model.joint("platform_x").qposadr[0]
    err = loop = 0.0
    for s in range(steps):
        mid = 2 * s + 1
        data.ctrl[:3] = np.asarray(prof.tau[mid]) / n
        if R_moving:
            data.ctrl[3] = float(prof.force_R[mid])
        mujoco.mj_step(model, data)
        target = dj.to_z_up(prof.p[2 * s + 2])
        err = max(err, np.abs(data.qpos[P:P + 3] - np.asarray(target)).max())
        loop = max(loop, max(np.abs(data.site(f"forearm_end_{i}").xpos - data.site(f"platform_joint_{i}").xpos).max()
                             for i in range(3)))
    print(f"{name}: max platform error {err:.3g} m, max loop gap {loop:.3g} m")
    assert err < SIM_POS_TOL and loop < SIM_LOOP_TOL


@settings(max_examples=6, deadline=None)
@given(scale=st.floats(0.3, 3.0), fore=st.floats(1.6, 2.6), arm_mass=st.floats(0.05, 3.0),
       fore_mass=st.floats(0.01, 1.0), s=st.floats(0.2, 0.8), plate=st.floats(0.0, 1.0))
def test_any_design_exports_assembled(scale, fore, arm_mass, fore_mass, s, plate):
    mass = dj.MassModel(upper_arm_mass=arm_mass, forearm_mass=fore_mass, forearm_elbow_fraction=s,
                        forearm_inertia_factor=0.5 * s * (1 - s), platform_mass=plate, gear_ratio=10.0,
                        rotor_inertia=1e-5)
    robot = dj.Delta.from_degrees(base_radius=0.2 * scale, platform_radius=0.05 * scale, upper_arm=0.3 * scale,
                                  forearm=0.3 * fore * scale, theta_min_deg=-60.0, theta_max_deg=100.0, mass=mass)
    model, data = load(robot)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    mujoco.mj_forward(model, data)
    assert np.abs(data.efc_pos[:data.nefc]).max() < 1e-12 * scale
    assert model.body_subtreemass[0] == pytest.approx(3 * (arm_mass + fore_mass) + max(plate, 1e-9), rel=1e-9)


def test_motor_sets_armature_gear_and_ctrlrange():
    motor = dj.presets.servo_750w()
    model, _ = load(dj.presets.industrial(), motor=motor, gear_ratio=25.0)
    dof = model.jnt_dofadr[model.joint("theta_1").id]
    assert model.dof_armature[dof] == pytest.approx(25.0 ** 2 * float(motor.rotor_inertia))
    act = model.actuator("motor_1")
    assert act.gear[0] == 25.0
    np.testing.assert_allclose(act.ctrlrange, [-float(motor.peak_torque), float(motor.peak_torque)])
