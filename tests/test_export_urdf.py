"""dj.export.urdf: the open tree loads in yourdfpy, its masses are the mass model's, and the sidecar's three
loop-closure pairs coincide in an assembled configuration."""

import json

import numpy as np
import pytest

import deltajax as dj


@pytest.mark.parametrize("robot, p", [(dj.presets.industrial(), (0.1, -0.05, 0.7)),
                                      (dj.presets.franco2026(with_mass=True), (0.05, 0.08, 0.4))],
                         ids=["industrial", "franco2026"])
@pytest.mark.slow
def test_urdf_loads_and_loops_close(tmp_path, robot, p):
    import yourdfpy  # here, not at collection: ~1 s of imports (trimesh, scipy.spatial) in every xdist worker

    path = tmp_path / "design.urdf"
    motor = dj.presets.servo_750w()
    text, side = dj.export.urdf(robot, motor=motor, gear_ratio=20.0, path=path)
    assert path.read_text() == text
    assert json.loads((tmp_path / "design.loops.json").read_text()) == side
    assert side["format"] == dj.export.SIDECAR_FORMAT and side["urdf"] == "design.urdf"
    recon = isinstance(robot, dj.ReconfigurableDelta)
    assert side["actuated_joints"] == ["theta_0", "theta_1", "theta_2"] + (["R_0"] if recon else [])
    assert len(side["coupled_joints"]) == (2 if recon else 0)
    model = yourdfpy.URDF.load(str(path), build_scene_graph=True, load_meshes=False)
    base = robot.robot if recon else robot
    m = base.mass
    total = sum(link.inertial.mass for link in model.robot.links if link.inertial is not None)
    expect = 3 * (m.upper_arm_mass + m.elbow_mass + m.forearm_mass) + m.platform_mass + m.payload_mass
    assert total == pytest.approx(float(expect) + (3 * float(m.carriage_mass) if recon else 0.0), rel=1e-12)
    assert model.joint_map["theta_0"].limit.effort == pytest.approx(20.0 * 0.9 * 7.16)
    R = 0.25 if recon else None
    cfg = dj.export.urdf_configuration(robot, p, R=R)
    model.update_cfg({name: cfg[name] for name in model.actuated_joint_names})
    for loop in side["loop_closures"]:
        a = model.get_transform(loop["link1"], "base") @ np.append(loop["point1"], 1.0)
        b = model.get_transform(loop["link2"], "base") @ np.append(loop["point2"], 1.0)
        assert np.abs(a - b).max() < 1e-12, loop["name"]
    # the platform sits at p in the z-up frame
    np.testing.assert_allclose(model.get_transform("platform", "base")[:3, 3], dj.to_z_up(np.asarray(p)), atol=1e-12)
