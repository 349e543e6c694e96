"""The task cylinder is sampled on the 60 deg wedge, both ends (deltajax.optimize.cylinder_points).

Why that is the whole cylinder: every point-wise quantity of the good-workspace check (reachability, the index,
the passive-joint and interference margins) is the same at phi, -phi and phi + 120 deg, by the robot's three-fold
and mirror symmetry -- checked here on the points themselves, for the baseline and for random designs of the main
job's design space. Why the ends: there the angular derivative of each such quantity vanishes (it is even in
phi about the plane), so the mirror planes hold extremes of the task constraint, which the earlier offset grid
never sampled (docs/REPRODUCTION.md §5.2).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from deltajax import constraints as C
from deltajax.optimize.designer import cylinder_points

SPEC = C.GoodSpec(joints=C.JointModel(limit=math.radians(55), elbow_neutral=math.radians(90),
                                      platform_neutral=math.radians(40)),
                  links=C.LinkModel(forearm_radius=0.02, upper_arm_radius=0.025, clearance=0.005,
                                    plate_overhang=0.03),
                  threshold=0.3)


def test_samples_span_the_wedge_with_both_ends_and_the_rim():
    p = cylinder_points(0.30, 0.10, 0.40, 2, 5, 3)
    assert p.shape == (2 * 5 * 3, 3)
    phi = np.degrees(np.arctan2(p[:, 1], p[:, 0]))
    np.testing.assert_allclose(np.unique(np.round(phi, 9)), [0.0, 15.0, 30.0, 45.0, 60.0], atol=1e-9)
    np.testing.assert_allclose(np.unique(np.round(np.hypot(p[:, 0], p[:, 1]), 12)), [0.075, 0.15])
    np.testing.assert_allclose(np.unique(p[:, 2]), [0.40, 0.45, 0.50])
    with pytest.raises(ValueError, match="n_phi >= 2"):
        cylinder_points(0.30, 0.10, 0.40, 2, 1, 3)


@jax.jit
def _checks(robot, pts):
    c = jax.vmap(lambda p: C.good_point(robot, p, SPEC))(pts)
    return jnp.stack([c.reachable.astype(pts.dtype), c.index, c.joint_margin, c.interference_margin], axis=-1)


def _images(p):
    """p, its mirror image in the plane through chain 1 (y -> -y), and its rotations by 120 and 240 deg."""
    out = [p, p * np.array([1.0, -1.0, 1.0])]
    for k in (1, 2):
        a = 2.0 * math.pi * k / 3.0
        rot = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
        out.append(p @ rot.T)
    return out


def _robots():
    from hydra import compose, initialize_config_dir

    from deltajax.config import ga_reconfig_build, robot_from_config
    from deltajax.run import CONFIG_DIR

    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(config_name="config", overrides=["experiment=ga_reconfig"])
    robot, recon = robot_from_config(cfg.robot)
    _, space, _, _ = ga_reconfig_build(cfg.experiment, robot, recon)
    genes = np.concatenate([space.baseline_genes()[None], np.random.default_rng(7).uniform(0, 1, (2, space.dim))])
    out = []
    for g in genes:
        d = space.decode(jnp.asarray(g))
        for R in (float(d.R_min), 0.5 * float(d.R_min + d.R_max)):
            out.append(d.at(R))
    return out


@pytest.mark.slow
def test_point_checks_are_symmetric_so_the_wedge_is_the_whole_cylinder():
    rng = np.random.default_rng(0)
    r = 0.15 * np.sqrt(rng.uniform(0, 1, 12))
    phi = rng.uniform(0, 2 * math.pi, 12)
    pts = np.stack([r * np.cos(phi), r * np.sin(phi), rng.uniform(0.40, 0.50, 12)], axis=-1)
    images = _images(pts)
    n_reachable = 0
    for robot in _robots():
        vals = [np.asarray(_checks(robot, jnp.asarray(q))) for q in images]
        for v in vals[1:]:
            np.testing.assert_array_equal(v[:, 0], vals[0][:, 0])          # reachable at every image or none
            np.testing.assert_allclose(v, vals[0], rtol=1e-9, atol=1e-12, equal_nan=True)
        n_reachable += int(vals[0][:, 0].sum())
    assert n_reachable >= 12  # the comparison saw reachable points, not only NaN margins
