"""Robots shipped with deltajax (the CLI's ``configs/robot/*.yaml``). Each function returns a validated robot.

Numbers and their sources:

* ``franco2026``: Franco-López et al. 2026, Table 1 and §5.1: R in [0.138, 0.495] m sampled every 1 mm
  (358 samples; the paper's "385" is a digit swap), r = 0.065 m, L1 = 0.200 m, L2 = 0.400 m,
  theta in [-40 deg, 110 deg]; the fixed (non-reconfigurable) variant has R = 0.200 m.
* ``boundary2d``: the boundary-search paper's Table 1: L1 = 1.73, L2 = 2.66, R - r = 1.74 (we put r = 0),
  no joint limits; the workspace is taken on one side of the base plate (z > 0).
* ``franco2026(with_mass=True)``: the link masses of the GA paper (Hasanlu 2025, Table 3, the robot of its
  ref. [34]): upper arm ("Link 1") 1.5895 kg, forearm ("Link 2") 0.0408 kg, end effector 0.1108 kg. The paper
  gives no rotor inertia, gear ratio, elbow hardware or carriage mass: direct drive, no rotor, zero.
* ``industrial``: an industrial-size picker of the ~1.1 m working-diameter, 1 kg payload class (ABB IRB 360
  FlexPicker class). Its numbers are *our engineering estimates*, not manufacturer data (manufacturers do not
  publish link masses): R = 0.200 m, r = 0.050 m, L1 = 0.350 m, L2 = 0.800 m, theta in [-50, 95] deg;
  upper arm 0.90 kg (carbon tube + aluminium hub, centre of mass at 0.4 L1, rod inertia factor 1/12),
  0.10 kg elbow hardware, 0.30 kg per forearm pair (carbon rods + ball cups), 0.60 kg plate, 0.1 kg payload
  (the payload at which the standard 25/305/25 mm cycle is usually quoted), an AC servo rotor of
  1.0e-4 kg m^2 behind a 20:1 gearbox. See ``INDUSTRIAL_LIMITS`` for the matching actuator limits.
"""

from __future__ import annotations

import math
from typing import Optional, Union

import equinox as eqx

from .geometry import Delta, ReconfigurableDelta
from .drive import Motor
from .mass import MassModel

__all__ = ["franco2026", "boundary2d", "industrial", "franco2026_mass", "industrial_mass", "PRESETS", "get",
           "INDUSTRIAL_LIMITS", "FRANCO2026_LIMITS", "servo_750w", "INDUSTRIAL_GEAR_RATIO"]

#: Arm-side actuator limits for ``industrial``: a ~750 W servo (peak about 7 N m, 5000 rpm) behind 20:1,
#: i.e. 140 N m and 5000 rpm / 20 = 26.2 rad/s at the arm (estimates, see the module docstring).
INDUSTRIAL_LIMITS = {"torque": 140.0, "speed": 26.2}
#: Illustrative limits for ``franco2026`` (the paper gives no motor data): 20 N m, 10 rad/s at the arm.
FRANCO2026_LIMITS = {"torque": 20.0, "speed": 10.0}


#: Gear ratio of ``industrial`` (motor speed / arm speed), the 20:1 of :func:`industrial_mass`.
INDUSTRIAL_GEAR_RATIO = 20.0


def servo_750w(efficiency: float = 0.9) -> Motor:
    """A 750 W-class AC servo (motor side), the drive :func:`industrial` is sized for.

    Catalogue values of the Panasonic MINAS A6 MSMF082L1 (750 W, 200 V, low inertia, no brake): rated
    torque 2.39 N m, peak (instantaneous) torque 7.16 N m, rated speed 3000 r/min, maximum speed 6000 r/min,
    rotor inertia 1.51e-4 kg m^2. The peak torque is taken as available up to 4500 r/min and falling linearly
    to zero at 6000 r/min (a straight-line reading of the catalogue's torque-speed curve, an approximation).
    ``efficiency``: of the gearbox (0.9: a typical single-stage planetary gearhead).
    """
    rpm = 2.0 * math.pi / 60.0
    return Motor(peak_torque=7.16, rated_torque=2.39, max_speed=6000.0 * rpm, corner_speed=4500.0 * rpm,
                 rotor_inertia=1.51e-4, efficiency=efficiency)


def franco2026_mass(payload_mass: float = 0.0) -> MassModel:
    """GA paper Table 3 masses (Link 1 = upper arm 1.5895 kg, Link 2 = forearm 0.0408 kg, end effector 0.1108 kg)."""
    return MassModel(upper_arm_mass=1.5895, forearm_mass=0.0408, platform_mass=0.1108, payload_mass=payload_mass)


def industrial_mass(payload_mass: float = 0.1) -> MassModel:
    """Mass model of :func:`industrial` (engineering estimates, see the module docstring)."""
    return MassModel(upper_arm_mass=0.90, upper_arm_com_fraction=0.4, upper_arm_inertia_factor=1.0 / 12.0,
                     rotor_inertia=1.0e-4, gear_ratio=20.0, elbow_mass=0.10, forearm_mass=0.30,
                     forearm_elbow_fraction=0.5, platform_mass=0.60, payload_mass=payload_mass)


def _attach(robot: Delta, mass: MassModel) -> Delta:
    return eqx.tree_at(lambda d: d.mass, robot, mass, is_leaf=lambda x: x is None)

FRANCO2026_R_RANGE = (0.138, 0.495, 0.001)


def franco2026(fixed_R: Optional[float] = None, *, R_step: float = FRANCO2026_R_RANGE[2],
               with_mass: bool = False) -> Union[Delta, ReconfigurableDelta]:
    """The reconfigurable Delta of Franco-López et al. 2026.

    Args:
        fixed_R: if given, return the fixed-geometry robot with this base radius (m) (the paper's
            comparison robot is ``fixed_R=0.200``); if ``None``, the reconfigurable robot.
        R_step: spacing of the R samples for redundancy resolution (m).
        with_mass: attach the GA paper's Table 3 mass model (:func:`franco2026_mass`) for dynamics.
    """
    base = Delta.from_degrees(base_radius=0.200 if fixed_R is None else fixed_R, platform_radius=0.065,
                              upper_arm=0.200, forearm=0.400, theta_min_deg=-40.0, theta_max_deg=110.0)
    if with_mass:
        base = _attach(base, franco2026_mass())
    if fixed_R is not None:
        return base
    return ReconfigurableDelta.from_range(base, FRANCO2026_R_RANGE[0], FRANCO2026_R_RANGE[1], R_step)


def boundary2d() -> Delta:
    """The robot of the boundary-search paper (its Table 1): L1 = 1.73, L2 = 2.66, R - r = 1.74, no limits."""
    return Delta(base_radius=1.74, platform_radius=0.0, upper_arm=1.73, forearm=2.66,
                 theta_min=-math.inf, theta_max=math.inf)


def industrial(*, with_mass: bool = True, payload_mass: float = 0.1) -> Delta:
    """An industrial-size Delta (1.1 m working-diameter class) with an estimated mass model (module docstring)."""
    robot = Delta.from_degrees(base_radius=0.200, platform_radius=0.050, upper_arm=0.350, forearm=0.800,
                               theta_min_deg=-50.0, theta_max_deg=95.0)
    return _attach(robot, industrial_mass(payload_mass)) if with_mass else robot


PRESETS = {"franco2026": franco2026, "boundary2d": boundary2d, "industrial": industrial}


def get(name: str, **kwargs):
    """Look a preset up by name; raises ``KeyError`` listing the known names."""
    try:
        fn = PRESETS[name]
    except KeyError:
        raise KeyError(f"unknown robot preset {name!r}; known: {sorted(PRESETS)}") from None
    return fn(**kwargs)
