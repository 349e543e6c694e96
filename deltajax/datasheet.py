"""A vendor-style one-page datasheet of one Delta design with its drive.

    ds = dj.datasheet(dj.presets.industrial(), dj.presets.servo_750w(), 20.0)
    ds.rows()                      # the picks/min-vs-payload table, one dict per payload, units in ds.UNITS

What it holds (all SI units unless the field name says otherwise; frame: base frame, z down, docs/CONVENTIONS.md):

* **geometry and masses**: R, r, L1, L2 (m), the joint range (rad), the link masses (kg) of the robot's
  :class:`~deltajax.MassModel` and its forearm model.
* **drive**: the :class:`~deltajax.constraints.Motor` (motor side) and the gear ratio n; the arm-side peak
  torque n eta T_peak (N m) and speed limit omega_max / n (rad/s).
* **working range**: the regular cylinder D x H (the largest cylinder on the z axis with H / D = ``hd_ratio``
  inside the reachable set, :func:`deltajax.regular.regular_workspace` refined to its continuous measure) and
  the reachable volume (:func:`deltajax.workspace.volume`, count h^3 at spacing ``h``). A vendor's "working
  range D x H" is this cylinder.
* **cycle rate vs payload** on the standard 25/305/25 mm go-and-back cycle (:func:`deltajax.adept_cycle`, one
  pick per cycle) centred at ``centre`` (default: the middle of the regular cylinder), for each payload of
  ``payloads`` (kg) and the largest payload that completes the cycle within the motor envelope (bisection on
  the payload over :func:`deltajax.constraints.cycle_rate`, which bisects the motion time T itself). Two
  columns: **motion only** (60 / T_min) and **vendor-equivalent** (60 / (T_min + 2 dwell), the dwells at pick
  and place holding the static load in the RMS too; ``vendor_dwell`` = 35 ms as ABB's vacuum delay). ABB's
  published figures also include a 90 deg tool rotation, which this model has not (no rotary axis): the
  vendor column is an upper bound of what ABB would quote for the same arm.
* per payload at T_min: the peak (torque-speed envelope) and RMS (thermal) motor utilisations (one of them
  is 1 at T_min: the binding limit), the speed utilisation and the platform's peak acceleration in g.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Optional, Sequence, Union

import jax
import jax.numpy as jnp
import numpy as np

from .drive import Motor, cycle_rate
from .geometry import Delta, ReconfigurableDelta
from .kinematics import ik
from .mass import STANDARD_GRAVITY
from .regular import polar_grid, regular_workspace
from .tracing import shared_program
from .trajectory import adept_cycle
from .workspace.measure import reach_box, volume

__all__ = ["Datasheet", "DatasheetError", "datasheet", "DEFAULT_PAYLOADS", "VENDOR_DWELL", "UNITS", "ROW_FIELDS"]

#: payloads of the table (kg); the largest feasible payload is appended as the last row
DEFAULT_PAYLOADS = (0.0, 0.1, 0.5, 1.0, 2.0, 3.0)
#: s, dwell per end of the vendor-equivalent column (ABB IRB 360: 2 x 35 ms vacuum delay per cycle)
VENDOR_DWELL = 0.035

#: per-payload table columns and their units
ROW_FIELDS = (
    ("payload", "kg", "payload carried by the platform"),
    ("picks_per_min", "1/min", "picks per minute, motion only (60 / T_min)"),
    ("picks_per_min_vendor", "1/min", "picks per minute with a dwell at pick and place (60 / (T_min + 2 dwell))"),
    ("cycle_time", "s", "shortest go-and-back motion time T_min within the motor limits"),
    ("cycle_time_vendor", "s", "T_min when the dwells also load the RMS (thermal) limit"),
    ("peak_utilisation", "1", "max |tau_motor| / torque-speed envelope at T_min"),
    ("rms_utilisation", "1", "RMS motor torque / rated torque at T_min"),
    ("speed_utilisation", "1", "max motor speed / motor max speed at T_min"),
    ("peak_acceleration_g", "1", "peak platform acceleration at T_min / standard gravity (NaN: no T_min)"),
)
#: units of every field of :class:`Datasheet` (and of the table columns)
UNITS = {
    "base_radius": "m", "platform_radius": "m", "upper_arm": "m", "forearm": "m", "theta_min": "rad",
    "theta_max": "rad", "upper_arm_mass": "kg", "forearm_mass": "kg", "elbow_mass": "kg", "platform_mass": "kg",
    "gear_ratio": "1", "arm_peak_torque": "N m", "arm_max_speed": "rad/s", "working_diameter": "m",
    "working_height": "m", "working_z_top": "m", "working_volume": "m^3", "reachable_volume": "m^3",
    "volume_h": "m", "centre": "m", "dwell": "s", "max_payload": "kg",
    **{name: unit for name, unit, _ in ROW_FIELDS},
}


class DatasheetError(ValueError):
    """Invalid datasheet input (names the field and the value, in the user's units)."""


@dataclasses.dataclass(frozen=True)
class Datasheet:
    """One design's datasheet (units in :data:`UNITS`; per-payload arrays share the ``payload`` axis, whose
    last entry is ``max_payload``).

    Attributes:
        base_radius, platform_radius, upper_arm, forearm: R, r, L1, L2 (m).
        theta_min, theta_max: actuated joint range (rad).
        upper_arm_mass, forearm_mass, elbow_mass, platform_mass: kg (forearm: both rods of one parallelogram).
        forearm_model: the mass model's forearm model (``rigid_rod`` / ``point_split``).
        motor: the motor (motor side), gear_ratio: n = motor speed / arm speed.
        arm_peak_torque: n eta T_peak (N m), arm_max_speed: omega_max / n (rad/s), both at the arm.
        working_diameter, working_height, working_z_top, working_volume: the regular cylinder (m, m^3; it spans
            z in [z_top, z_top + H], z down).
        reachable_volume: m^3, at grid spacing ``volume_h`` (m); ``volume_truncated`` flags a box cut-off.
        centre: (3,) centre of the pick-place line of the standard cycle (m, base frame, z down).
        dwell: s per end in the vendor column.
        payload ... peak_acceleration_g: (P,) arrays, see :data:`ROW_FIELDS`.
        max_payload: kg, the largest payload with a finite T_min (motion only).
        name: label of the design.
    """

    name: str
    base_radius: float
    platform_radius: float
    upper_arm: float
    forearm: float
    theta_min: float
    theta_max: float
    upper_arm_mass: float
    forearm_mass: float
    elbow_mass: float
    platform_mass: float
    forearm_model: str
    motor: Motor
    gear_ratio: float
    arm_peak_torque: float
    arm_max_speed: float
    working_diameter: float
    working_height: float
    working_z_top: float
    working_volume: float
    reachable_volume: float
    volume_h: float
    volume_truncated: bool
    centre: tuple
    dwell: float
    max_payload: float
    payload: np.ndarray
    picks_per_min: np.ndarray
    picks_per_min_vendor: np.ndarray
    cycle_time: np.ndarray
    cycle_time_vendor: np.ndarray
    peak_utilisation: np.ndarray
    rms_utilisation: np.ndarray
    speed_utilisation: np.ndarray
    peak_acceleration_g: np.ndarray

    UNITS = UNITS

    def rows(self) -> list:
        """The payload table, one dict per payload (keys: :data:`ROW_FIELDS` names)."""
        return [{name: float(getattr(self, name)[k]) for name, _, _ in ROW_FIELDS} for k in range(len(self.payload))]

    def scalars(self) -> dict:
        """Every scalar field (name -> float / str / bool), the motor's fields as ``motor_<name>``."""
        out = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.name == "motor":
                out.update({f"motor_{k}": float(getattr(v, k)) for k in MOTOR_FIELDS})
            elif f.name == "centre":
                out["centre"] = tuple(float(x) for x in v)
            elif not isinstance(v, np.ndarray):
                out[f.name] = v
        return out


#: Motor fields and units (motor side)
MOTOR_FIELDS = {"peak_torque": "N m", "rated_torque": "N m", "max_speed": "rad/s", "corner_speed": "rad/s",
                "rotor_inertia": "kg m^2", "efficiency": "1"}


def _positive(name: str, value, unit: str) -> float:
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise DatasheetError(f"{name} must be a positive number ({unit}), got {value!r}")
    return v


def _rate(robot, cycle, motor, gear_ratio, dwell, payload):
    """:func:`deltajax.cycle_rate` as one program, kept across processes (:func:`deltajax.tracing.shared_program`:
    a new process reads it back instead of tracing the inverse dynamics again); ``gear_ratio``, ``dwell`` and
    ``payload`` are passed as arrays of the robot's dtype."""
    dt = robot.upper_arm.dtype
    prog = shared_program("datasheet_rate", None, None, (), lambda: jax.jit(_rate_traced), persist=True)
    return prog(robot, cycle, motor, *(jnp.asarray(v, dt) for v in (gear_ratio, dwell, payload)))


def _rate_traced(robot, cycle, motor, gear_ratio, dwell, payload):
    return cycle_rate(robot, cycle, motor, gear_ratio, dwell=dwell, payload_mass=payload)


def _max_payload(robot, cycle, motor, n, *, tol: float = 1e-4, upper: float = 1000.0) -> float:
    """Largest payload (kg) with a finite motion time T_min (bisection; the load grows with the payload)."""
    feasible = lambda m: bool(np.isfinite(float(_rate(robot, cycle, motor, n, 0.0, m).cycle_time)))  # noqa: E731
    if not feasible(0.0):
        return 0.0
    lo, hi = 0.0, 1.0
    while feasible(hi):
        lo, hi = hi, 2.0 * hi
        if hi > upper:
            raise DatasheetError(f"the cycle stays within the motor limits beyond a payload of {upper} kg: "
                                 "check the motor and gear ratio")
    while hi - lo > tol * max(hi, 1e-3):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if feasible(mid) else (lo, mid)
    return lo


def regular_cylinder(robot: Delta, hd_ratio: float, *, n_r: int = 41, n_phi: int = 7, n_z: int = 61):
    """The regular cylinder (H / D = ``hd_ratio``) of the reachable set of ``robot`` (R frozen): a polar grid
    over the reach bound, refined (:func:`deltajax.regular.regular_workspace` with ``refine=True``)."""
    (x0, x1), (y0, y1), (z0, z1) = reach_box(robot)
    r_max = max(abs(x0), abs(x1), abs(y0), abs(y1))
    pts, r, z = polar_grid(r_max, max(z0, 0.0), z1, n_r, n_phi, n_z)
    dt = robot.upper_arm.dtype
    h = float(hd_ratio)
    prog = shared_program("datasheet_cylinder", None, None, (h,),
                          lambda: jax.jit(functools.partial(_regular_cylinder, hd_ratio=h)), persist=True)
    return prog(robot, jnp.asarray(pts, dt), jnp.asarray(r), jnp.asarray(z))


def _regular_cylinder(robot: Delta, pts, r, z, *, hd_ratio: float):
    """:func:`regular_cylinder`'s evaluation as one program (evaluated op by op it dispatched ~2 000 operations and
    compiled ~90 small programs per design), kept across processes like :func:`_rate`'s."""
    return regular_workspace(lambda p: ik(robot, p).ok, pts, r, z, hd_ratio, refine=True)


def datasheet(robot: Union[Delta, ReconfigurableDelta], motor: Motor, gear_ratio: float, *,
              payloads: Sequence[float] = DEFAULT_PAYLOADS, vendor_dwell: float = VENDOR_DWELL,
              centre: Optional[Sequence[float]] = None, hd_ratio: float = 0.25, volume_h: float = 0.01,
              n_samples: int = 201, R: Optional[float] = None, name: str = "design",
              cylinder_grid: tuple = (41, 7, 61)) -> Datasheet:
    """The datasheet of ``robot`` driven by ``motor`` through a gearbox of ratio ``gear_ratio``.

    Args:
        robot: a :class:`~deltajax.Delta` with a mass model, or a :class:`~deltajax.ReconfigurableDelta`
            (then evaluated at base radius ``R``, default its nominal one; the reachable volume is over its
            whole R range).
        motor: the motor (motor side); its rotor inertia replaces the mass model's (:func:`with_drive`).
        gear_ratio: n, motor speed / arm speed.
        payloads: kg, the table's payloads (the largest feasible one is appended).
        vendor_dwell: s per end for the vendor-equivalent column (ABB: 35 ms vacuum delay).
        centre: (3,) m, base frame z down: centre of the standard cycle; default the middle of the regular
            cylinder.
        hd_ratio: H / D of the regular cylinder (vendors quote e.g. 1130 x 250 mm: about 0.22).
        volume_h: m, grid spacing of the reachable volume.
        n_samples: samples of the cycle (odd: one sample exactly at the place point).
        R: m, base radius of a reconfigurable robot.
        name: label.
        cylinder_grid: (rings, angles, levels) of the regular cylinder's polar grid.

    Raises:
        DatasheetError: bad input (one line naming the field and the value), no mass model, or the cycle not
            reachable at ``centre``.
    """
    n = _positive("gear_ratio", gear_ratio, "motor speed / arm speed")
    dwell = float(vendor_dwell)
    if not (math.isfinite(dwell) and dwell >= 0):
        raise DatasheetError(f"vendor_dwell must be >= 0 s, got {vendor_dwell!r}")
    hd_ratio = _positive("hd_ratio", hd_ratio, "height / diameter")
    volume_h = _positive("volume_h", volume_h, "m")
    pl = [float(p) for p in payloads]
    bad = [p for p in pl if not (math.isfinite(p) and p >= 0)]
    if bad:
        raise DatasheetError(f"payloads must be >= 0 kg, got {bad[0]!r}")
    if int(n_samples) < 3:
        raise DatasheetError(f"n_samples must be >= 3, got {n_samples!r}")
    full = robot
    if isinstance(robot, ReconfigurableDelta):
        R = float(robot.robot.base_radius) if R is None else R
        if not float(robot.R_min) <= float(R) <= float(robot.R_max):
            raise DatasheetError(f"R must be in [{float(robot.R_min)}, {float(robot.R_max)}] m, got {R!r}")
        robot = robot.at(R)
    if robot.mass is None:
        raise DatasheetError("robot.mass is None: a datasheet needs a mass model (e.g. presets.industrial() or "
                             "presets.franco2026(fixed_R=0.2, with_mass=True))")
    mm = robot.mass
    if centre is not None:
        centre = tuple(float(c) for c in centre)
        if len(centre) != 3 or not all(math.isfinite(c) for c in centre):
            raise DatasheetError(f"centre must be 3 finite coordinates (m, z down), got {centre!r}")
    if len(cylinder_grid) != 3 or min(int(g) for g in cylinder_grid) < 2:
        raise DatasheetError(f"cylinder_grid must be 3 counts >= 2 (rings, angles, levels), got {cylinder_grid!r}")
    cyl = regular_cylinder(robot, hd_ratio, n_r=cylinder_grid[0], n_phi=cylinder_grid[1], n_z=cylinder_grid[2])
    D, H, z_top = float(cyl.diameter), float(cyl.height), float(cyl.z_top)
    if centre is None:
        if not D > 0:
            raise DatasheetError("the regular cylinder is empty (no reachable axis point on the grid): pass centre=")
        centre = (0.0, 0.0, z_top + 0.5 * H)
    dtype = robot.upper_arm.dtype
    cycle = adept_cycle(centre, n_samples=int(n_samples), dtype=dtype)
    vol = volume(full, volume_h)

    rates = {k: [] for k, _, _ in ROW_FIELDS}
    max_pl = _max_payload(robot, cycle, motor, n)
    acc_unit = float(np.max(np.linalg.norm(np.asarray(cycle.ddx), axis=-1)))   # |p''| at T = 1 s
    for p in pl + [max_pl]:
        a = _rate(robot, cycle, motor, n, 0.0, p)
        v = _rate(robot, cycle, motor, n, dwell, p)
        T = float(a.cycle_time)
        if math.isnan(T):
            raise DatasheetError(f"the standard 25/305/25 mm cycle centred at {centre} m (z down) leaves the "
                                 "workspace or crosses a singularity: pass another centre")
        rates["payload"].append(p)
        rates["picks_per_min"].append(float(a.picks_per_min))
        rates["picks_per_min_vendor"].append(float(v.picks_per_min))
        rates["cycle_time"].append(T)
        rates["cycle_time_vendor"].append(float(v.cycle_time))
        rates["peak_utilisation"].append(float(a.loads.peak_utilisation))
        rates["rms_utilisation"].append(float(a.loads.rms_utilisation))
        rates["speed_utilisation"].append(float(a.loads.speed_utilisation))
        # no cycle within the limits (T_min = inf, picks/min 0): no acceleration to report
        rates["peak_acceleration_g"].append(acc_unit / (T * T) / STANDARD_GRAVITY if math.isfinite(T) else math.nan)
    eta = float(motor.efficiency)
    return Datasheet(
        name=name, base_radius=float(robot.base_radius), platform_radius=float(robot.platform_radius),
        upper_arm=float(robot.upper_arm), forearm=float(robot.forearm), theta_min=float(robot.theta_min),
        theta_max=float(robot.theta_max), upper_arm_mass=float(mm.upper_arm_mass),
        forearm_mass=float(mm.forearm_mass), elbow_mass=float(mm.elbow_mass), platform_mass=float(mm.platform_mass),
        forearm_model=mm.forearm_model, motor=motor, gear_ratio=n,
        arm_peak_torque=n * eta * float(motor.peak_torque), arm_max_speed=float(motor.max_speed) / n,
        working_diameter=D, working_height=H, working_z_top=z_top, working_volume=float(cyl.volume),
        reachable_volume=float(vol.volume), volume_h=volume_h, volume_truncated=bool(vol.truncated),
        centre=centre, dwell=dwell, max_payload=max_pl,
        **{k: np.asarray(v, float) for k, v in rates.items()})
