"""Robot model: presets, validation errors that name the field, frames, pytree behaviour."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import deltajax as dj
from deltajax.config import ConfigError, robot_from_config


def test_franco2026_preset_matches_spec():
    rec = dj.presets.franco2026()
    assert rec.n_R == 358  # 0.138 + 0.001 k, k = 0..357 (the paper's "385" is a digit swap)
    R = np.asarray(rec.R_samples())
    assert R[0] == pytest.approx(0.138, abs=1e-15) and R[-1] == pytest.approx(0.495, abs=1e-12)
    np.testing.assert_allclose(np.diff(R), 0.001, rtol=1e-9)
    fixed = dj.presets.franco2026(fixed_R=0.2)
    assert float(fixed.base_radius) == 0.2 and float(rec.robot.base_radius) == 0.2
    assert math.degrees(float(fixed.theta_min)) == pytest.approx(-40.0)
    assert math.degrees(float(fixed.theta_max)) == pytest.approx(110.0)
    assert float(rec.at(0.3).base_radius) == 0.3 and float(rec.at(0.3).forearm) == 0.4


def test_boundary2d_preset():
    b = dj.presets.boundary2d()
    assert float(b.R_minus_r) == pytest.approx(1.74)
    assert float(b.upper_arm) == 1.73 and float(b.forearm) == 2.66
    assert not np.isfinite(float(b.theta_min)) and not np.isfinite(float(b.theta_max))


@pytest.mark.parametrize(
    "kwargs, field",
    [
        (dict(base_radius=-0.2), "base_radius"),
        (dict(upper_arm=0.0), "upper_arm"),
        (dict(forearm=-1.0), "forearm"),
        (dict(platform_radius=-0.01), "platform_radius"),
        (dict(base_radius=float("nan")), "base_radius"),
        (dict(theta_min=1.0, theta_max=0.5), "theta_min"),
        (dict(theta_min=0.5, theta_max=0.5), "theta_max"),
        (dict(forearm=0.05), "reach nothing"),  # L2 shorter than every horizontal offset
    ],
)
def test_invalid_geometry_names_field(kwargs, field):
    base = dict(base_radius=0.2, platform_radius=0.065, upper_arm=0.2, forearm=0.4, theta_min=-0.7, theta_max=1.9)
    base.update(kwargs)
    with pytest.raises(dj.GeometryError, match=field):
        dj.Delta(**base)


def test_invalid_R_range():
    robot = dj.presets.franco2026(fixed_R=0.2)
    with pytest.raises(dj.GeometryError, match="empty R range"):
        dj.ReconfigurableDelta.from_range(robot, 0.3, 0.2, 0.001)
    with pytest.raises(dj.GeometryError, match="R_step"):
        dj.ReconfigurableDelta.from_range(robot, 0.1, 0.2, 0.0)
    with pytest.raises(dj.GeometryError, match="R_min"):
        dj.ReconfigurableDelta.from_range(robot, -0.1, 0.2, 0.001)


def test_config_errors_name_field():
    good = dict(base_radius=0.2, platform_radius=0.065, upper_arm=0.2, forearm=0.4, theta_min_deg=-40,
                theta_max_deg=110, R_range=dict(min=0.138, max=0.495, step=0.001))
    robot, recon = robot_from_config(good)
    assert recon.n_R == 358
    with pytest.raises(ConfigError, match=r"robot\.forearm"):
        robot_from_config({**good, "forearm": "long"})
    with pytest.raises(ConfigError, match=r"^robot\.forearm must be > 0 m, got -0\.4 m$"):
        robot_from_config({**good, "forearm": -0.4})
    with pytest.raises(ConfigError, match=r"^robot: missing keys upper_arm$"):
        robot_from_config({k: v for k, v in good.items() if k != "upper_arm"})
    with pytest.raises(ConfigError, match=r"robot\.R_range.*empty R range"):
        robot_from_config({**good, "R_range": dict(min=0.5, max=0.2, step=0.001)})
    with pytest.raises(ConfigError, match="theta_max"):
        robot_from_config({**good, "theta_min_deg": 120})


def test_z_up_round_trip():
    p = jnp.array([[0.1, -0.2, 0.3], [0.0, 0.05, 0.25]])
    q = dj.to_z_up(p)
    np.testing.assert_array_equal(np.asarray(q[:, 2]), -np.asarray(p[:, 2]))
    np.testing.assert_array_equal(np.asarray(dj.from_z_up(q)), np.asarray(p))
    # right-handed: a proper rotation (det +1) that keeps chain 0 on +x
    M = np.asarray(dj.to_z_up(jnp.eye(3)))
    assert np.linalg.det(M) == pytest.approx(1.0)


@pytest.mark.slow
def test_robot_is_a_pytree_that_vmaps_over_designs():
    rec = dj.presets.franco2026()
    Rs = jnp.array([0.2, 0.3, 0.4])
    robots = jax.vmap(rec.at)(Rs)  # traced values skip validation
    assert robots.base_radius.shape == (3,)
    p = jnp.array([0.0, 0.0, 0.3])
    ok = jax.vmap(lambda r: dj.ik(r, p).ok)(robots)
    assert ok.shape == (3,) and bool(ok.all())
