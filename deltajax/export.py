"""Take a design out of deltajax: MuJoCo MJCF and URDF (+ loop-closure sidecar) of one robot.

    xml = dj.export.mjcf(robot)                          # string; mjcf(robot, path="robot.xml") writes it
    dj.export.urdf(robot, path="robot.urdf")             # writes robot.urdf and robot.loops.json
    state = dj.export.joint_state(robot, p, p_dot, p_ddot, theta, ...)   # deltajax state -> MuJoCo joints

**Frames.** deltajax works in its base frame with z pointing *down* (docs/CONVENTIONS.md). Both exports use
the z-up frame of :func:`deltajax.to_z_up`, the base frame rotated by pi about x: (x, y, z) -> (x, -y, -z)
(right-handed; chain 0 stays on +x, chain i lies at angle -alpha_i about +z, gravity is -z). Origin: the base
centre. Every body frame is named after its part; lengths in m, masses in kg, inertias in kg m^2, angles in rad.

**Model** (MJCF and URDF alike; the mass model is the robot's :class:`~deltajax.MassModel`, the same numbers
the dynamics use):

* ``base`` (fixed). For a :class:`~deltajax.ReconfigurableDelta`: ``carriage_i`` on a radial slide ``R_i``
  (axis: the chain's radial direction, qpos = R - R_ref with R_ref the robot's nominal base radius, range
  [R_min - R_ref, R_max - R_ref]) carrying ``carriage_mass``; the three slides are coupled (equalities
  R_1 = R_0, R_2 = R_0) and driven by one actuator ``R`` on the fixed tendon (R_0 + R_1 + R_2) / 3, whose
  force is deltajax's ``force_R`` (N, total radial force, positive outward).
* ``arm_i`` on hinge ``theta_i`` at A_i: body frame x along the arm's radial direction at theta = 0, y the
  hinge axis, so qpos = theta_i exactly (positive downward, as in deltajax). Mass upper arm + elbow hardware
  (``elbow_mass`` at L1), centre of mass and inertia about the hinge as in :meth:`MassModel.arm_inertia`;
  ``armature`` = n^2 J_rotor (the reflected rotor); a ``motor`` actuator with ``gear`` = n, so ``ctrl`` is the
  motor-side torque (N m) and the arm torque is n ctrl (gearbox efficiency not modelled).
* ``forearm_i`` on ball joint ``ball_i`` at the elbow B_i (the parallelogram as one rod, as in deltajax): the
  rod runs along the body's -z axis from B_i (origin) to C_i (site ``forearm_end_i`` at (0, 0, -L2)); mass
  ``forearm_mass`` at (1 - s) L2 from B_i and inertia ``MassModel.forearm_inertia(L2)`` perpendicular to the
  rod: ``rigid_rod`` gives k m L2^2, ``point_split`` gives s (1 - s) m L2^2, which reproduces the point split
  (s m at B, (1 - s) m at C) exactly: same mass, centre of mass and inertia, hence the same kinetic energy.
  The spin about the rod's own axis is a free, dynamically irrelevant degree of freedom; it carries
  :data:`SPIN_INERTIA_FRACTION` of the perpendicular inertia so that the mass matrix stays positive.
* ``platform`` on three world-axis slides ``platform_x/y/z`` (the parallelograms keep it from rotating; qpos =
  its centre P in the z-up frame), mass ``platform_mass``, sites ``platform_joint_i`` at C_i - P; ``payload``
  a welded child body of ``payload_mass`` at P (omitted when 0).
* Loop closures: MJCF ``<connect site1="forearm_end_i" site2="platform_joint_i"/>`` (i = 0, 1, 2). Contacts off.
  A keyframe ``home`` holds an assembled configuration (platform at ``home``, default on the axis mid-way down
  the reach box).

**URDF** (the open tree; URDF has no loops): the same links, each ball joint written as three revolute joints
x, y, z (``ball_i_x``, ``ball_i_y``, ``ball_i_z``) through two massless links, the platform on three prismatic
joints from ``base``. The **sidecar** (JSON, written next to the URDF as ``<name>.loops.json``)::

    {"format": "deltajax-loop-closures", "version": 1, "urdf": "<file name>",
     "frame": "z up (deltajax.to_z_up), m",
     "loop_closures": [{"name": "loop_0", "type": "ball",
                        "link1": "forearm_0", "point1": [0, 0, -L2],     # in link1's frame
                        "link2": "platform", "point2": [r, 0, 0]}, ...],  # in link2's frame; 3 entries
     "coupled_joints": [{"joint": "R_1", "equals": "R_0"}, ...],         # reconfigurable only
     "actuated_joints": ["theta_0", "theta_1", "theta_2"(, "R_0")], "gear_ratio": n}

Each closure says: the two points coincide (a spherical joint: three scalar constraints).
"""

from __future__ import annotations

import json
import math
import os
from typing import Optional, Sequence, Union
from xml.sax.saxutils import quoteattr

import numpy as np
import equinox as eqx

from .drive import Motor, with_drive
from .geometry import CHAIN_ANGLES, Delta, ReconfigurableDelta
from .kinematics import ik
from .workspace.measure import reach_box

__all__ = ["mjcf", "urdf", "joint_state", "urdf_configuration", "ExportError", "SPIN_INERTIA_FRACTION", "SIDECAR_FORMAT",
           "sidecar_path"]

#: inertia about a forearm's own axis / its perpendicular inertia (the spin is not modelled by deltajax)
SPIN_INERTIA_FRACTION = 1e-3
#: ``format`` of the URDF's loop-closure sidecar
SIDECAR_FORMAT = "deltajax-loop-closures"
#: inertia of a body that only translates or only rotates about one axis, on its unused axes (kg m^2)
_TINY = 1e-9


class ExportError(ValueError):
    """The robot cannot be exported (names the field and the value)."""


# -- geometry in the export frame (z up) -------------------------------------------------------------------------

def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _up(v) -> np.ndarray:
    v = np.asarray(v, float)
    return np.array([v[0], -v[1], -v[2]])


def _chain_yaw(i: int) -> float:
    """Yaw of chain i's frames about +z in the z-up frame (deltajax's alpha_i mirrored)."""
    return -CHAIN_ANGLES[i]


def _quat_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of the smallest rotation taking unit vector a to unit vector b."""
    w = 1.0 + float(a @ b)
    if w < 1e-12:
        raise ExportError("a forearm points straight back along its reference axis; no unique ball quaternion")
    q = np.concatenate([[w], np.cross(a, b)])
    return q / np.linalg.norm(q)


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _parts(robot):
    """(fixed Delta at the reference R, ReconfigurableDelta or None, mass model) with checks."""
    recon = robot if isinstance(robot, ReconfigurableDelta) else None
    base = robot.robot if recon is not None else robot
    if not isinstance(base, Delta):
        raise ExportError(f"robot must be a deltajax.Delta or ReconfigurableDelta, got {type(robot).__name__}")
    if base.mass is None:
        raise ExportError("robot.mass is None: the export needs a mass model (e.g. presets.industrial() or "
                          "presets.franco2026(with_mass=True))")
    return base, recon, base.mass


def _f(x) -> str:
    return " ".join(repr(float(v)) for v in np.atleast_1d(np.asarray(x, float)))


def _arm_inertial(base: Delta, mm):
    """(mass, com x, inertia about the com along the hinge) of upper arm + elbow hardware, arm frame."""
    L1 = float(base.upper_arm)
    ma, me = float(mm.upper_arm_mass), float(mm.elbow_mass)
    c = float(mm.upper_arm_com_fraction) * L1
    m = ma + me
    if not m > 0:
        raise ExportError(f"upper_arm_mass + elbow_mass must be > 0 kg for a moving arm body, got {m!r}")
    x = (ma * c + me * L1) / m
    I = float(mm.upper_arm_inertia_factor) * ma * L1 * L1 + ma * (c - x) ** 2 + me * (L1 - x) ** 2
    return m, x, max(I, _TINY)


def _forearm_inertial(base: Delta, mm):
    """(mass, com distance from B along the rod, perpendicular inertia about the com) per the forearm model."""
    L2 = float(base.forearm)
    m = float(mm.forearm_mass)
    if not m > 0:
        raise ExportError(f"forearm_mass must be > 0 kg for a ball-jointed forearm body, got {m!r}")
    s = float(mm.forearm_elbow_fraction)
    return m, (1.0 - s) * L2, max(float(mm.forearm_inertia(base.forearm)), _TINY)


def _drive(robot, motor: Optional[Motor], gear_ratio):
    """(robot with the drive, n, J_rotor); motor/gear_ratio replace the mass model's as in with_drive."""
    base, recon, mm = _parts(robot)
    if motor is not None or gear_ratio is not None:
        n = float(mm.gear_ratio) if gear_ratio is None else float(gear_ratio)
        if not (math.isfinite(n) and n > 0):
            raise ExportError(f"gear_ratio must be > 0 (motor speed / arm speed), got {gear_ratio!r}")
        if motor is not None:
            base = with_drive(base, motor, n)
        else:
            base = eqx.tree_at(lambda d: d.mass.gear_ratio, base, mm.gear_ratio * 0 + n)
        mm = base.mass
    return base, recon, mm, float(mm.gear_ratio), float(mm.rotor_inertia)


def _default_home(base: Delta) -> np.ndarray:
    (_, _), (_, _), (z0, z1) = reach_box(base)
    return np.array([0.0, 0.0, 0.5 * (max(z0, 0.0) + z1)])


def joint_state(robot, p, p_dot=None, p_ddot=None, theta=None, theta_dot=None, theta_ddot=None, *, R=None,
                R_dot=0.0, R_ddot=0.0) -> dict:
    """The exported model's joint values for a deltajax state (base frame, z down, SI units).

    Args:
        robot: the exported robot (a :class:`~deltajax.ReconfigurableDelta` for the R slides).
        p, p_dot, p_ddot: platform centre (m), velocity, acceleration (base frame, z down).
        theta, theta_dot, theta_ddot: actuated angles (rad) and rates; default: IK of ``p`` and zero rates.
        R, R_dot, R_ddot: base radius (m; default the nominal one) and its rates (m/s, m/s^2).

    Returns:
        {joint name: (qpos, qvel, qacc)}: scalars for hinges and slides; for ``ball_i`` a quaternion (w, x, y, z)
        and the angular velocity / acceleration relative to ``arm_i`` in ``forearm_i``'s frame (MuJoCo's ball
        convention), with no spin about the rod.
    """
    base, recon, _ = _parts(robot)
    R_ref = float(base.base_radius)
    R = R_ref if R is None else float(R)
    z3 = np.zeros(3)
    p = np.asarray(p, float)
    v = z3 if p_dot is None else np.asarray(p_dot, float)
    a = z3 if p_ddot is None else np.asarray(p_ddot, float)
    if theta is None:
        sol = ik(base.with_base_radius(R), p)
        if not bool(sol.ok):
            raise ExportError(f"p = {p.tolist()} m (z down) is not reachable at R = {R} m")
        theta = np.asarray(sol.theta, float)
    th = np.asarray(theta, float)
    thd = z3 if theta_dot is None else np.asarray(theta_dot, float)
    thdd = z3 if theta_ddot is None else np.asarray(theta_ddot, float)
    L1, L2, r = float(base.upper_arm), float(base.forearm), float(base.platform_radius)
    P, V, A = _up(p), _up(v), _up(a)
    out = {}
    for i in range(3):
        Rz = _rz(_chain_yaw(i))
        er, ey = Rz[:, 0], Rz[:, 1]
        c, s = math.cos(th[i]), math.sin(th[i])
        B = R * er + Rz @ np.array([L1 * c, 0.0, -L1 * s])
        Bd = R_dot * er + Rz @ np.array([-L1 * s * thd[i], 0.0, -L1 * c * thd[i]])
        Bdd = R_ddot * er + Rz @ np.array([-L1 * (c * thd[i] ** 2 + s * thdd[i]), 0.0,
                                           L1 * (s * thd[i] ** 2 - c * thdd[i])])
        C, Cd, Cdd = P + r * er, V, A
        u, ud, udd = (C - B) / L2, (Cd - Bd) / L2, (Cdd - Bdd) / L2
        R_arm = Rz @ _ry(th[i])
        q = _quat_between(np.array([0.0, 0.0, -1.0]), R_arm.T @ (u / np.linalg.norm(u)))
        R_f = R_arm @ _quat_matrix(q)
        w_f, al_f = np.cross(u, ud), np.cross(u, udd)
        w_a, al_a = thd[i] * ey, thdd[i] * ey
        out[f"theta_{i}"] = (th[i], thd[i], thdd[i])
        out[f"ball_{i}"] = (q, R_f.T @ (w_f - w_a), R_f.T @ (al_f - al_a + np.cross(w_f, w_a)))
        if recon is not None:
            out[f"R_{i}"] = (R - R_ref, float(R_dot), float(R_ddot))
    for k, ax in enumerate("xyz"):
        out[f"platform_{ax}"] = (P[k], V[k], A[k])
    return out


# -- MJCF ---------------------------------------------------------------------------------------------------------

def _write(text: str, path) -> str:
    if path is not None:
        tmp = f"{os.fspath(path)}.tmp"
        with open(tmp, "w") as fh:
            fh.write(text)
        os.replace(tmp, path)
    return text


def mjcf(robot: Union[Delta, ReconfigurableDelta], *, motor: Optional[Motor] = None,
         gear_ratio: Optional[float] = None, payload_mass: Optional[float] = None, home: Optional[Sequence[float]] = None,
         name: str = "deltajax_delta", timestep: float = 0.001, path=None) -> str:
    """MuJoCo MJCF of ``robot`` (see the module docstring for the model and the frames).

    Args:
        robot: a :class:`~deltajax.Delta` or :class:`~deltajax.ReconfigurableDelta` with a mass model.
        motor: optional :class:`~deltajax.constraints.Motor`: its rotor inertia gives the armature and its peak
            torque the actuators' ``ctrlrange`` (motor side, N m).
        gear_ratio: n (default: the mass model's ``gear_ratio``).
        payload_mass: kg, replaces the mass model's payload.
        home: platform centre of the ``home`` keyframe (m, base frame, z down).
        name: model name.
        timestep: s.
        path: if given, the file to write (atomically); the string is returned either way.
    """
    base, recon, mm, n, J_rotor = _drive(robot, motor, gear_ratio)
    if payload_mass is not None:
        pm = float(payload_mass)
        if not (math.isfinite(pm) and pm >= 0):
            raise ExportError(f"payload_mass must be >= 0 kg, got {payload_mass!r}")
        mm = mm.with_payload(pm)
    ts = float(timestep)
    if not (math.isfinite(ts) and ts > 0):
        raise ExportError(f"timestep must be > 0 s, got {timestep!r}")
    R_ref, L1, L2, r = (float(x) for x in (base.base_radius, base.upper_arm, base.forearm, base.platform_radius))
    m_arm, x_arm, I_arm = _arm_inertial(base, mm)
    m_fa, x_fa, I_fa = _forearm_inertial(base, mm)
    lo, hi = float(base.theta_min), float(base.theta_max)
    hinge_range = f' range="{_f([lo, hi])}"' if math.isfinite(lo) and math.isfinite(hi) else ""
    home_p = _default_home(base) if home is None else np.asarray(home, float)
    L = []
    a = L.append
    a(f'<mujoco model={quoteattr(name)}>')
    a('  <!-- exported by deltajax.export: z-up frame = deltajax base frame rotated by pi about x (to_z_up); '
      'SI units -->')
    a('  <compiler angle="radian" inertiafromgeom="false" autolimits="true"/>')
    a(f'  <option timestep="{ts!r}" gravity="0 0 {-float(mm.gravity)!r}">')
    a('    <flag contact="disable"/>')
    a('  </option>')
    a('  <default><geom contype="0" conaffinity="0" rgba="0.6 0.6 0.7 1"/>'
      '<equality solref="0.004 1" solimp="0.9999 0.9999 0.001"/></default>')
    a('  <worldbody>')
    a(f'    <body name="base"><geom name="base_plate" type="cylinder" size="{_f([R_ref + 0.05, 0.01])}" '
      f'pos="0 0 0.01"/></body>')
    for i in range(3):
        yaw = _chain_yaw(i)
        er = _rz(yaw)[:, 0]
        ind = "    "
        if recon is not None:
            rng = [float(recon.R_min) - R_ref, float(recon.R_max) - R_ref]
            mc = float(mm.carriage_mass)
            a(f'{ind}<body name="carriage_{i}" pos="{_f(R_ref * er)}" euler="0 0 {yaw!r}">')
            a(f'{ind}  <joint name="R_{i}" type="slide" axis="1 0 0" range="{_f(rng)}"/>')
            a(f'{ind}  <inertial pos="0 0 0" mass="{max(mc, _TINY)!r}" diaginertia="{_f([_TINY] * 3)}"/>')
            ind += "  "
            a(f'{ind}<body name="arm_{i}">')
        else:
            a(f'{ind}<body name="arm_{i}" pos="{_f(R_ref * er)}" euler="0 0 {yaw!r}">')
        a(f'{ind}  <joint name="theta_{i}" type="hinge" axis="0 1 0" armature="{n * n * J_rotor!r}"{hinge_range}/>')
        a(f'{ind}  <inertial pos="{_f([x_arm, 0, 0])}" mass="{m_arm!r}" diaginertia="{_f([_TINY, I_arm, I_arm])}"/>')
        a(f'{ind}  <geom type="capsule" fromto="0 0 0 {L1!r} 0 0" size="0.015"/>')
        a(f'{ind}  <body name="forearm_{i}" pos="{_f([L1, 0, 0])}">')
        a(f'{ind}    <joint name="ball_{i}" type="ball"/>')
        a(f'{ind}    <inertial pos="{_f([0, 0, -x_fa])}" mass="{m_fa!r}" '
          f'diaginertia="{_f([I_fa, I_fa, SPIN_INERTIA_FRACTION * I_fa])}"/>')
        a(f'{ind}    <geom type="capsule" fromto="0 0 0 0 0 {-L2!r}" size="0.008" rgba="0.3 0.3 0.3 1"/>')
        a(f'{ind}    <site name="forearm_end_{i}" pos="{_f([0, 0, -L2])}"/>')
        a(f'{ind}  </body>')
        a(f'{ind}</body>')
        if recon is not None:
            a('    </body>')
    a('    <body name="platform">')
    for ax, vec in zip("xyz", ("1 0 0", "0 1 0", "0 0 1")):
        a(f'      <joint name="platform_{ax}" type="slide" axis="{vec}"/>')
    a(f'      <inertial pos="0 0 0" mass="{max(float(mm.platform_mass), _TINY)!r}" diaginertia="{_f([_TINY] * 3)}"/>')
    a(f'      <geom type="cylinder" size="{_f([r + 0.01, 0.005])}"/>')
    for i in range(3):
        a(f'      <site name="platform_joint_{i}" pos="{_f(r * _rz(_chain_yaw(i))[:, 0])}"/>')
    pm = float(mm.payload_mass)
    if pm > 0:
        a(f'      <body name="payload"><inertial pos="0 0 0" mass="{pm!r}" diaginertia="{_f([_TINY] * 3)}"/>'
          f'<geom type="box" size="0.02 0.02 0.02" pos="0 0 -0.02" rgba="0.8 0.4 0.1 1"/></body>')
    a('    </body>')
    a('  </worldbody>')
    if recon is not None:
        a('  <tendon><fixed name="R">' + "".join(f'<joint joint="R_{i}" coef="{1.0 / 3.0!r}"/>' for i in range(3))
          + '</fixed></tendon>')
    a('  <equality>')
    for i in range(3):
        a(f'    <connect name="loop_{i}" site1="forearm_end_{i}" site2="platform_joint_{i}"/>')
    if recon is not None:
        for i in (1, 2):
            a(f'    <joint name="R_couple_{i}" joint1="R_{i}" joint2="R_0"/>')
    a('  </equality>')
    a('  <actuator>')
    cr = ""
    if motor is not None:
        cr = f' ctrlrange="{_f([-float(motor.peak_torque), float(motor.peak_torque)])}"'
    for i in range(3):
        a(f'    <motor name="motor_{i}" joint="theta_{i}" gear="{n!r}"{cr}/>')
    if recon is not None:
        a('    <motor name="R" tendon="R" gear="1"/>')
    a('  </actuator>')
    try:
        st = joint_state(robot, home_p)
    except ExportError as e:
        raise ExportError(f"home: {e} (pass home=)") from None
    a(f'  <keyframe><key name="home" qpos="{_f(_qpos_vector(st, recon is not None))}"/></keyframe>')
    a('</mujoco>')
    return _write("\n".join(L) + "\n", path)


def _qpos_vector(state: dict, recon: bool) -> np.ndarray:
    """qpos in the MJCF's joint order (per chain: R_i, theta_i, ball_i; then platform x, y, z)."""
    out = []
    for i in range(3):
        if recon:
            out.append([state[f"R_{i}"][0]])
        out.append([state[f"theta_{i}"][0]])
        out.append(state[f"ball_{i}"][0])
    out.append([state[f"platform_{ax}"][0] for ax in "xyz"])
    return np.concatenate([np.atleast_1d(np.asarray(x, float)) for x in out])


# -- URDF ---------------------------------------------------------------------------------------------------------

def sidecar_path(urdf_path) -> str:
    """The loop-closure sidecar written next to ``urdf_path`` (``x.urdf`` -> ``x.loops.json``)."""
    root, _ = os.path.splitext(os.fspath(urdf_path))
    return root + ".loops.json"


def _inertial(m, com, ixx, iyy, izz) -> str:
    return (f'<inertial><origin xyz="{_f(com)}" rpy="0 0 0"/><mass value="{m!r}"/>'
            f'<inertia ixx="{ixx!r}" ixy="0" ixz="0" iyy="{iyy!r}" iyz="0" izz="{izz!r}"/></inertial>')


def urdf_configuration(robot, p, theta=None, *, R=None) -> dict:
    """{URDF joint name: value} of the assembled configuration with the platform at ``p`` (m, base frame, z
    down; ``theta`` default: IK; ``R`` default: the nominal base radius): each ball as its x, y, z revolutes."""
    st = joint_state(robot, p, theta=theta, R=R)
    out = {}
    for name, (q, _, _) in st.items():
        if name.startswith("ball_"):
            M = _quat_matrix(np.asarray(q))             # = Rx(a) Ry(b) Rz(c)
            out[f"{name}_x"] = math.atan2(-M[1, 2], M[2, 2])
            out[f"{name}_y"] = math.asin(max(-1.0, min(1.0, M[0, 2])))
            out[f"{name}_z"] = math.atan2(-M[0, 1], M[0, 0])
        else:
            out[name] = float(q)
    return out


def urdf(robot: Union[Delta, ReconfigurableDelta], *, motor: Optional[Motor] = None,
         gear_ratio: Optional[float] = None, payload_mass: Optional[float] = None, name: str = "deltajax_delta",
         path=None) -> tuple:
    """URDF of the open tree of ``robot`` and its loop-closure sidecar (module docstring: format, frames).

    Args: as :func:`mjcf`; ``path``: the ``.urdf`` file to write (the sidecar goes to :func:`sidecar_path`).

    Returns:
        (urdf text, sidecar dict).
    """
    base, recon, mm, n, _ = _drive(robot, motor, gear_ratio)
    R_ref, L1, L2, r = (float(x) for x in (base.base_radius, base.upper_arm, base.forearm, base.platform_radius))
    m_arm, x_arm, I_arm = _arm_inertial(base, mm)
    m_fa, x_fa, I_fa = _forearm_inertial(base, mm)
    pm = float(mm.payload_mass if payload_mass is None else payload_mass)
    if not (math.isfinite(pm) and pm >= 0):
        raise ExportError(f"payload_mass must be >= 0 kg, got {payload_mass!r}")
    effort = n * float(motor.efficiency) * float(motor.peak_torque) if motor is not None else 0.0
    speed = float(motor.max_speed) / n if motor is not None else 0.0
    lo, hi = float(base.theta_min), float(base.theta_max)
    lo, hi = (lo, hi) if math.isfinite(lo) and math.isfinite(hi) else (-math.pi, math.pi)
    L = ['<?xml version="1.0"?>', f'<robot name={quoteattr(name)}>',
         '  <!-- exported by deltajax.export: z-up frame (deltajax.to_z_up), SI units; open tree, loop closures in '
         'the .loops.json sidecar; limit effort/velocity 0 = not given -->',
         '  <link name="base"/>']
    a = L.append
    massless = '<inertial><mass value="0"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>'

    def joint(jname, kind, parent, child, xyz=(0, 0, 0), rpy=(0, 0, 0), axis=None, limit=None):
        s = (f'  <joint name="{jname}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
             f'<origin xyz="{_f(xyz)}" rpy="{_f(rpy)}"/>')
        if axis is not None:
            s += f'<axis xyz="{_f(axis)}"/>'
        if limit is not None:
            s += f'<limit lower="{limit[0]!r}" upper="{limit[1]!r}" effort="{limit[2]!r}" velocity="{limit[3]!r}"/>'
        a(s + '</joint>')

    actuated = []
    for i in range(3):
        yaw = _chain_yaw(i)
        er = _rz(yaw)[:, 0]
        parent = "base"
        if recon is not None:
            a(f'  <link name="carriage_{i}">{_inertial(max(float(mm.carriage_mass), 0.0), (0, 0, 0), 0, 0, 0)}</link>')
            joint(f"R_{i}", "prismatic", "base", f"carriage_{i}", R_ref * er, (0, 0, yaw), (1, 0, 0),
                  (float(recon.R_min) - R_ref, float(recon.R_max) - R_ref, 0.0, 0.0))
            parent, xyz, rpy = f"carriage_{i}", (0, 0, 0), (0, 0, 0)
        else:
            xyz, rpy = R_ref * er, (0, 0, yaw)
        a(f'  <link name="arm_{i}">{_inertial(m_arm, (x_arm, 0, 0), 0.0, I_arm, I_arm)}</link>')
        joint(f"theta_{i}", "revolute", parent, f"arm_{i}", xyz, rpy, (0, 1, 0), (lo, hi, effort, speed))
        actuated.append(f"theta_{i}")
        a(f'  <link name="ball_{i}_link_x">{massless}</link>')
        a(f'  <link name="ball_{i}_link_y">{massless}</link>')
        a(f'  <link name="forearm_{i}">{_inertial(m_fa, (0, 0, -x_fa), I_fa, I_fa, SPIN_INERTIA_FRACTION * I_fa)}'
          '</link>')
        joint(f"ball_{i}_x", "continuous", f"arm_{i}", f"ball_{i}_link_x", (L1, 0, 0), axis=(1, 0, 0))
        joint(f"ball_{i}_y", "continuous", f"ball_{i}_link_x", f"ball_{i}_link_y", axis=(0, 1, 0))
        joint(f"ball_{i}_z", "continuous", f"ball_{i}_link_y", f"forearm_{i}", axis=(0, 0, 1))
    if recon is not None:
        actuated.append("R_0")
    a(f'  <link name="platform_link_x">{massless}</link>')
    a(f'  <link name="platform_link_y">{massless}</link>')
    a(f'  <link name="platform">{_inertial(float(mm.platform_mass) + pm, (0, 0, 0), 0, 0, 0)}</link>')
    big = 10.0 * (L1 + L2 + R_ref)
    joint("platform_x", "prismatic", "base", "platform_link_x", axis=(1, 0, 0), limit=(-big, big, 0.0, 0.0))
    joint("platform_y", "prismatic", "platform_link_x", "platform_link_y", axis=(0, 1, 0), limit=(-big, big, 0.0, 0.0))
    joint("platform_z", "prismatic", "platform_link_y", "platform", axis=(0, 0, 1), limit=(-big, big, 0.0, 0.0))
    a('</robot>')
    text = "\n".join(L) + "\n"
    fname = os.path.basename(os.fspath(path)) if path is not None else f"{name}.urdf"
    side = {"format": SIDECAR_FORMAT, "version": 1, "urdf": fname, "frame": "z up (deltajax.to_z_up), m",
            "loop_closures": [{"name": f"loop_{i}", "type": "ball", "link1": f"forearm_{i}",
                               "point1": [0.0, 0.0, -L2], "link2": "platform",
                               "point2": [float(v) for v in r * _rz(_chain_yaw(i))[:, 0]]} for i in range(3)],
            "coupled_joints": ([{"joint": f"R_{i}", "equals": "R_0"} for i in (1, 2)] if recon is not None else []),
            "actuated_joints": actuated, "gear_ratio": n,
            "payload_mass": pm}
    if path is not None:
        _write(text, path)
        _write(json.dumps(side, indent=1) + "\n", sidecar_path(path))
    return text, side
