"""Reconfiguration mechanisms: loop closure, dR/dphi vs jacfwd and finite differences, singular positions,
inverse, validation, virtual-work efforts."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import deltajax as dj
from deltajax.mechanism import DirectRadial, ScrewLinkage, drive_profile, example_screw_linkage

MECH = example_screw_linkage()
FIELDS = ("R_f", "R_r", "d1", "d2", "d3", "pitch")


def _loop_residual(m, phi, alpha):
    return ((m.R_f + m.R_r * jnp.cos(alpha) - m.d3) ** 2 + (m.d1 + m.pitch * phi - m.R_r * jnp.sin(alpha)) ** 2
            - m.d2 ** 2)


@pytest.mark.slow
def test_example_covers_franco2026_range_without_singularity():
    info = MECH.check_range(0.138, 0.495)
    assert info["phi_min"] == pytest.approx(0.0, abs=1e-9)
    assert info["min_transmission"] > 0.38
    phi, ok = MECH.inverse(0.138)
    assert bool(ok) and float(MECH.position(phi)) == pytest.approx(0.138, abs=1e-12)


@pytest.mark.slow
def test_both_assembly_branches_close_the_loop():
    phis = jnp.linspace(-50.0, 250.0, 31)
    both, ok = jax.vmap(MECH.angles)(phis)
    assert bool(jnp.all(ok))
    for col in range(2):
        res = jax.vmap(lambda p, a: _loop_residual(MECH, p, a))(phis, both[:, col])
        assert float(jnp.max(jnp.abs(res))) < 1e-13
    # the two branches are different configurations of the same screw angle
    assert float(jnp.min(jnp.abs(both[:, 0] - both[:, 1]))) > 1e-3


@pytest.mark.parametrize("assembly", [1, -1])
@pytest.mark.slow
def test_ratio_matches_jacfwd_and_finite_differences(assembly):
    m = ScrewLinkage(**{f: getattr(MECH, f) for f in FIELDS}, assembly=assembly)
    phis = np.linspace(-40.0, 240.0, 15)
    for phi in phis:
        st = m.state(phi)
        if not bool(st.ok) or bool(st.singular):
            continue
        h = 1e-4
        fd = (float(m.position(phi + h)) - float(m.position(phi - h))) / (2 * h)
        jf = float(jax.jacfwd(m.position)(jnp.asarray(phi)))
        assert float(st.ratio) == pytest.approx(jf, rel=1e-10, abs=1e-15)
        assert float(st.ratio) == pytest.approx(fd, rel=1e-6, abs=1e-12)


@pytest.mark.slow
def test_inverse_is_the_inverse_of_position():
    Rs = jnp.linspace(0.138, 0.495, 41)
    phi, ok = jax.vmap(MECH.inverse)(Rs)
    assert bool(jnp.all(ok))
    np.testing.assert_allclose(np.asarray(jax.vmap(MECH.position)(phi)), np.asarray(Rs), atol=1e-12)
    assert np.all(np.diff(np.asarray(phi)) > 0)   # monotone working range
    _, ok_out = MECH.inverse(0.9)                  # beyond R_f + R_r
    assert not bool(ok_out)


def test_singular_positions_are_flagged_as_data():
    table = MECH.singular_positions()
    assert {k: v.shape[1] for k, v in table.items()} == {"dead_centre": 2, "coupler_normal": 2, "rocker_radial": 2}
    seen = {"dead_centre": 0, "coupler_normal": 0, "rocker_radial": 0}
    for kind, rows in table.items():
        for phi, beta in rows:
            branches = (1, -1) if beta == 0 else (int(beta),)
            for b in branches:
                m = ScrewLinkage(**{f: getattr(MECH, f) for f in FIELDS}, assembly=b)
                st = m.state(phi)
                assert bool(st.ok)
                assert bool(getattr(st, kind)), (kind, phi, b)
                seen[kind] += 1
                if kind == "dead_centre":
                    assert np.isnan(float(st.ratio))   # infinite transmission ratio is not a number
                else:
                    assert abs(float(st.ratio)) < 1e-8
    assert all(v > 0 for v in seen.values())
    # away from them: no flag, finite ratio
    st = MECH.state(80.0)
    assert not bool(st.singular) and np.isfinite(float(st.ratio))


def test_no_assembly_is_data_not_an_error():
    st = MECH.state(1e4)
    assert not bool(st.ok) and np.isnan(float(st.R))


@pytest.mark.parametrize("field,value", [("R_r", -0.1), ("d2", 0.0), ("pitch", float("nan")),
                                         ("efficiency", 1.5), ("d1", float("inf"))])
def test_validation_names_field_and_value(field, value):
    kw = {f: float(getattr(MECH, f)) for f in FIELDS}
    kw[field] = value
    with pytest.raises(ValueError, match=f"ScrewLinkage.{field}"):
        ScrewLinkage(**kw)
    with pytest.raises(ValueError, match="ScrewLinkage.assembly"):
        ScrewLinkage(**{f: float(getattr(MECH, f)) for f in FIELDS}, assembly=0)
    with pytest.raises(ValueError, match="DirectRadial.efficiency"):
        DirectRadial(efficiency=0.0)


def test_check_range_refuses_a_range_through_a_singularity():
    # above R_max the working branch ends where the coupler turns perpendicular to the screw (Y = 0, R ~ 0.530 m)
    with pytest.raises(ValueError, match="ScrewLinkage cannot reach R = 0.5"):
        MECH.check_range(0.138, 0.54)
    rows = MECH.singular_positions()["coupler_normal"]
    R_end = [float(MECH.position(p)) for p, b in rows if b == MECH.assembly]
    assert any(0.495 < r < 0.54 for r in R_end)
    assert MECH.check_range(0.138, 0.525)["min_transmission"] > 0


def test_effort_is_virtual_work_with_efficiency():
    phi = jnp.asarray(60.0)
    ratio = MECH.ratio(phi)
    F = jnp.asarray(25.0)
    drive = MECH.effort(phi, 1.0, F)           # motor delivers power
    back = MECH.effort(phi, -1.0, F)           # load back-drives
    assert float(drive) == pytest.approx(float(F * ratio / MECH.efficiency))
    assert float(back) == pytest.approx(float(F * ratio * MECH.back_efficiency))
    # power balance: effort * phidot = F_R * Rdot / eta while driving
    phid = 3.0
    assert float(drive) * phid == pytest.approx(float(F) * float(ratio) * phid / float(MECH.efficiency))
    d = DirectRadial(efficiency=0.8)
    assert float(d.effort(0.3, 0.1, F)) == pytest.approx(25.0 / 0.8)
    assert float(d.ratio(0.3)) == 1.0


@pytest.mark.slow
def test_drive_profile_along_R():
    R = jnp.linspace(0.15, 0.45, 11)
    Rd = jnp.full((11,), 0.2)
    F = jnp.linspace(-10.0, 10.0, 11)
    dp = drive_profile(MECH, R, Rd, F)
    assert bool(jnp.all(dp.ok))
    np.testing.assert_allclose(np.asarray(dp.q_dot * dp.ratio), 0.2, rtol=1e-12)
    assert dj.mechanism.MECHANISMS["screw_linkage"] is example_screw_linkage


@pytest.mark.slow
def test_reconfiguration_drive_reports_motor_torque_along_R():
    robot = dj.presets.franco2026(fixed_R=0.2, with_mass=True)
    cyc = dj.trajectory.with_R_profile(
        dj.trajectory.point_to_point([-0.05, 0.0, 0.38], [0.05, 0.02, 0.42], duration=0.5, n_samples=21), 0.20, 0.26)
    prof, drv = dj.mechanism.reconfiguration_drive(robot, cyc, MECH)
    assert bool(jnp.all(prof.ok)) and bool(jnp.all(drv.ok))
    # virtual work: motor power = F_R Rdot / eta while driving, * eta_back when back-driven
    p_motor = np.asarray(drv.effort * drv.q_dot)
    p_load = np.asarray(prof.force_R * prof.R_dot)
    eta = np.where(p_load >= 0, 1 / float(MECH.efficiency), float(MECH.back_efficiency))
    np.testing.assert_allclose(p_motor, p_load * eta, rtol=1e-10, atol=1e-12)
    with pytest.raises(ValueError, match="cycle.R is None"):
        dj.mechanism.reconfiguration_drive(robot, dj.trajectory.point_to_point([0, 0, 0.4], [0.01, 0, 0.4]), MECH)
