"""Operating mode of a reconfigurable design in the designer's problem: one R per task, or R(t) along the cycle.

``per_task`` (the default, :func:`deltajax.optimize.designer.evaluate_designer`): the robot reconfigures once per
task and runs the cycle at one R, chosen among ``n_R_operating`` candidates by the designer's constraints
(the most picks/min among the feasible ones).

``path`` (:func:`path_operating`): the robot moves R *during* the cycle, around that per-task R.
For one design (pure, jit/vmap-able over a population):

1. **Plan** (exact DP of :mod:`deltajax.motion`: :func:`deltajax.motion.path_tables` and its Viterbi ``path_dp``) on
   a planning grid: time = the M + 1 control-point instants u = m / M of a periodic spline (``segments`` M), R =
   a window of ``n_R`` samples R_lo + k delta inside [R_min, R_max] holding the per-task R as a sample, with
   delta = min(speed h, accel h^2, range / n_R) (h = T_plan / M), so the drive can move one step per control
   point. Maximised: the integral (or the minimum) of the good-workspace index; subject to every planning sample
   reachable with the passive joints and links clear (the designer's enabled constraints,
   :func:`deltajax.constraints.good_point`), the closed-cycle boundary (R repeats, at rest at u = 0), the speed
   and acceleration limits (traced per design inside static bands) and |F_R| <= L(R) at the control points. L(R)
   is the drive's force limit and, with a screw mechanism configured, the motor torque limit seen at the R joint,
   tau_max gear efficiency / |dR/dphi| (the driving direction: a back-driven screw needs less). The planning
   time T_plan is the per-task R's fastest cycle (the nominal duration when that is not finite): the drive must
   keep up with the cycle as the robot runs it.
2. **Realise**: R(u) = the periodic uniform cubic B-spline with the plan as control points (C2 across the
   cycle's repetition; its speed and acceleration lie in the convex hull of the control points' differences).
3. **Choose and run the cycle.** Three candidates: the spline, the constant per-task R and the window's constant
   R best on the exact criterion (cycle samples). For each, inverse dynamics with moving R
   (:func:`deltajax.cycle_profile` via :func:`deltajax.constraints.cycle_rate` / ``drive_loads``) give T_motor,
   the fastest time for the arm motors, and T_drive, the fastest for the R drive (smallest T with the
   time-scaled R(t) inside the speed, acceleration, force and screw-torque limits at every cycle sample;
   monotone in T, bisection); the cycle runs at T = max(T_motor, T_drive): picks/min = 60 / (T + 2 dwell),
   motor loads at T. Chosen: feasible at every cycle sample and running first, then the most picks/min, then the
   higher criterion (``path_accepted`` = 1 when the spline wins). So the path mode never runs fewer picks/min
   than the per-task R whenever that R, held constant, is within the R drive's limits at its own cycle time
   (the R drive must hold R against the arms' radial force even when R does not move), nor than the window's
   best-index constant R (tested).
4. **Margins** at T (limit - worst value over the cycle samples, in the drive's units): ``R_speed_margin``
   (m/s), ``R_accel_margin`` (m/s^2), ``R_force_margin`` (N), ``screw_torque_margin`` (N m, screw mechanism
   only); with ``screw_torque_peak`` (N m), ``R_path_min`` / ``R_path_max`` (m), the planning window
   ``R_window_min`` / ``R_window_max`` (m), ``path_index_mean`` (time mean
   of the index along R(t)) and ``path_index_mean_fixed`` (at the per-task R), ``cycle_time_drive`` (s). The
   limits bind twice: in the plan at T_plan, and through T_drive (the cycle slows down rather than exceed them),
   so every margin is >= 0 whenever the cycle runs (tested). A design whose R drive cannot hold even the static
   load gets T = inf, zero picks/min: the designer's cycle-rate constraint counts it as violated.

The task cylinder is judged as in ``per_task`` (at the per-task R, which stays the fixed-R variant): the path mode
changes how the *cycle* is run, not which task the design serves.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping, Optional

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import constraints as C
from ..cycle import cycle_profile, log_bisect
from ..mechanism import Mechanism, drive_profile, example_screw_linkage
from ..geometry import ReconfigurableDelta
from ..motion import AGGREGATES, path_dp, path_tables, with_R
from ..motion_refine import spline_basis
from ..trajectory import Cycle
from .good import design_good_test

__all__ = ["MODES", "MECHANISM_NAMES", "OperatingError", "OperatingSpec", "OPERATING_UNITS", "OPERATING_SENSE",
           "FIXED_VARIANT_METRICS", "spec_from_settings", "path_operating", "not_evaluated",
           "u_rates"]

MODES = ("per_task", "path")
MECHANISM_NAMES = ("none", "screw_linkage")
#: metrics of the path mode (NaN in per_task mode) and their units
OPERATING_UNITS = {"R_speed_margin": "m/s", "R_accel_margin": "m/s^2", "R_force_margin": "N",
                   "screw_torque_margin": "N m", "screw_torque_peak": "N m", "R_path_min": "m", "R_path_max": "m",
                   "R_window_min": "m", "R_window_max": "m",
                   "path_index_mean": "1", "path_index_mean_fixed": "1", "path_index_mean_plan": "1",
                   "path_accepted": "1", "cycle_time_drive": "s", "cycle_time_motor": "s"}
OPERATING_SENSE = {"R_speed_margin": -1, "R_accel_margin": -1, "R_force_margin": -1, "screw_torque_margin": -1,
                   "screw_torque_peak": 1, "path_index_mean": -1, "path_index_mean_fixed": -1}
#: cycle metrics whose per-task (fixed-R) value is also reported as ``<name>_fixed``
FIXED_VARIANT_METRICS = ("picks_per_min", "cycle_time", "peak_utilisation", "rms_utilisation", "speed_utilisation",
                         "joint_margin_deg", "interference_margin")


class OperatingError(ValueError):
    """Invalid operating-mode setting; the message names the field (dotted path) and the value."""


@dataclasses.dataclass(frozen=True, eq=False)
class OperatingSpec:
    """How a reconfigurable design runs the cycle (host object, static under jit).

    Attributes:
        mode: ``"per_task"`` or ``"path"``.
        aggregate: path criterion, ``"integral"`` or ``"min"`` of the good-workspace index along the cycle.
        n_R: R samples of the planning window (odd >= 3).
        segments: M, control points of the periodic spline R(t) = the DP's samples per cycle (>= 3).
        speed, accel, force: R drive limits (m/s, m/s^2, N; ``inf``: none).
        mechanism: the reconfiguration mechanism (``None``: not modelled).
        motor_torque: the mechanism's motor torque limit (N m; ``inf``: none).
    """

    mode: str = "per_task"
    aggregate: str = "integral"
    n_R: int = 17
    segments: int = 8
    speed: float = math.inf
    accel: float = math.inf
    force: float = math.inf
    mechanism: Optional[Mechanism] = None
    motor_torque: float = math.inf

    def __post_init__(self):
        for name, lo in (("n_R", 3), ("segments", 3)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise OperatingError(f"OperatingSpec.{name} must be an integer >= {lo}, got {v!r}")
        for name, options in (("mode", MODES), ("aggregate", AGGREGATES)):
            if getattr(self, name) not in options:
                raise OperatingError(f"OperatingSpec.{name} must be one of {list(options)}, got "
                                     f"{getattr(self, name)!r}")
        for name, unit in (("speed", "m/s"), ("accel", "m/s^2"), ("force", "N"), ("motor_torque", "N m")):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v) or not v > 0:
                raise OperatingError(f"OperatingSpec.{name} must be > 0 {unit} (inf: none), got {v!r}")
        if self.mechanism is None and math.isfinite(self.motor_torque):
            raise OperatingError(f"OperatingSpec.motor_torque={self.motor_torque!r} N m needs a mechanism")


def spec_from_settings(s: Mapping[str, Any], R_range: Optional[tuple] = None) -> OperatingSpec:
    """:class:`OperatingSpec` from the settings' ``reconfig`` dict (:mod:`deltajax.config.ga_reconfig`). ``R_range`` (m): the R range the screw
    linkage must cover (the design space's smallest R_min .. largest R_max), required with
    ``mechanism=screw_linkage`` (:func:`deltajax.mechanism.example_screw_linkage` sized for it)."""
    mech = None
    if s["mechanism"] == "screw_linkage":
        if R_range is None:
            raise OperatingError("experiment.reconfig.mechanism=screw_linkage needs the design space's R range "
                                 "(experiment.design.bounds.R_min and R_max)")
        try:
            mech = example_screw_linkage(float(R_range[0]), float(R_range[1]))
        except ValueError as err:
            raise OperatingError(f"experiment.reconfig.mechanism=screw_linkage for R {R_range[0]!r}..{R_range[1]!r} "
                                 f"m: {err}") from None
    dr = s["drive"]
    return OperatingSpec(mode=s["mode"], aggregate=s["aggregate"], n_R=s["n_R"],
                         segments=s["segments"], speed=dr["speed"],
                         accel=dr["acceleration"], force=dr["force"], mechanism=mech, motor_torque=s["motor_torque"])


def u_rates(R: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(dR/du, d2R/du2) of K samples over u in [0, 1]: the differences of :func:`deltajax.motion.discrete_rates`
    (central inside, one-sided / the neighbour's second difference at the ends), in jnp for jit/vmap."""
    K = R.shape[0]
    du = 1.0 / (K - 1)
    v = jnp.concatenate([(R[1:2] - R[:1]) / du, (R[2:] - R[:-2]) / (2 * du), (R[-1:] - R[-2:-1]) / du])
    a_in = (R[2:] - 2 * R[1:-1] + R[:-2]) / (du * du)
    return v, jnp.concatenate([a_in[:1], a_in, a_in[-1:]])


def _force_limit(spec: OperatingSpec, R):
    """(L(R) (N), mechanism ok) at base radii R: min(force, tau_max gear efficiency / |dR/dphi|)."""
    dt = R.dtype
    L = jnp.full(R.shape, spec.force, dt)
    if spec.mechanism is None:
        return L, jnp.ones(R.shape, bool)
    m = spec.mechanism

    def one(r):
        q, ok = m.inverse(r)
        st = m.state(q)
        return st.ratio, ok & st.ok & ~st.singular

    ratio, ok = jax.vmap(one)(R)
    lim = spec.motor_torque * m.gear_ratio * m.efficiency / jnp.abs(ratio)
    return jnp.where(ok, jnp.minimum(L, lim.astype(dt)), 0.0), ok


def not_evaluated(dtype) -> dict:
    """The path metrics of a design evaluated in ``per_task`` mode (or a fixed design): NaN."""
    return {k: jnp.asarray(jnp.nan, dtype) for k in OPERATING_UNITS}


def periodic_basis(K: int, M: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Periodic uniform cubic B-spline on u in [0, 1] with M control points c_0..c_{M-1} (knot spacing 1 / M) at
    the K cycle samples u_j = j / (K - 1): (B, B', B'') (K, M) with u-derivatives. Control point c_m peaks at
    u = m / M. Built from :func:`deltajax.motion_refine.spline_basis` (M + 3 clamped controls mapped onto the
    periodic ones), so R(u), R'(u), R''(u) are continuous across the cycle's repetition."""
    u = np.linspace(0.0, 1.0, K)
    B, B1, B2, _ = spline_basis(u, 1.0, M + 3)
    P = np.zeros((M + 3, M))
    P[np.arange(M + 3), (np.arange(M + 3) - 1) % M] = 1.0
    return B @ P, B1 @ P, B2 @ P


def _window(spec: "OperatingSpec", design, R_op, h):
    """(R_lo, delta): the planning R grid R_lo + k delta, k < spec.n_R, inside [R_min, R_max], holding R_op as
    a sample; delta = min(speed h, accel h^2, range / n_R) so that one step per control point is allowed."""
    n = spec.n_R
    rng = design.R_max - design.R_min
    d = rng / n
    if math.isfinite(spec.speed):
        d = jnp.minimum(d, spec.speed * h)
    if math.isfinite(spec.accel):
        d = jnp.minimum(d, spec.accel * h * h)
    lo_steps = jnp.floor((R_op - design.R_min) / d * (1 + 1e-12))
    hi_steps = jnp.floor((design.R_max - R_op) / d * (1 + 1e-12))
    m = jnp.clip((n - 1) // 2, (n - 1) - hi_steps, lo_steps)
    return R_op - m * d, d, m.astype(jnp.int32)


#: static caps of the DP's bands on the planning grid (the traced limits act inside; never optimistic)
_W_CAP, _A_CAP = 4, 8


def path_operating(pb, design, R_op, T_plan, task_joint_margin, task_interference_margin, *,
                   return_profile: bool = False):
    """Path-mode metrics of ONE reconfigurable design (pure; vmap over a population). See the module docstring.

    Args:
        pb: the :class:`deltajax.optimize.designer.DesignerProblem` (``pb.operating`` an :class:`OperatingSpec`).
        design: :class:`deltajax.ReconfigurableDelta` with a mass model.
        R_op: the per-task operating R (m): the window centre and the constant path R(t) must beat.
        T_plan: planning cycle time (s), the per-task R's fastest cycle (non-finite: the nominal duration).
        task_joint_margin, task_interference_margin: the task cylinder's margins at the per-task R (rad, m).

        return_profile: also return the profile: a dict with ``R`` (K,) m, ``R_u`` / ``R_uu`` (K,) its
            u-derivatives (m, u in [0, 1]), ``cycle`` (the cycle carrying R(t) at T_plan), ``T_plan`` (s).

    Returns:
        ``picks_per_min``, ``cycle_time``, ``peak_utilisation``, ``rms_utilisation``, ``speed_utilisation``,
        ``joint_margin_deg``, ``interference_margin`` at R(t), and every key of :data:`OPERATING_UNITS`.
    """
    spec: OperatingSpec = pb.operating
    robot = design.robot
    dt = robot.upper_arm.dtype
    gear = robot.mass.gear_ratio
    robot_d = C.with_drive(robot, pb.motor, gear, pb.payload)
    T_nom = jnp.asarray(pb.cycle.duration, dt)
    T_plan = jnp.where(jnp.isfinite(T_plan) & (T_plan > 0), T_plan, T_nom).astype(dt)
    cyc = eqx.tree_at(lambda c: (c.u, c.x, c.dx, c.ddx, c.duration), pb.cycle,
                      (pb.cycle.u.astype(dt), pb.cycle.x.astype(dt), pb.cycle.dx.astype(dt),
                       pb.cycle.ddx.astype(dt), T_plan))
    K, M, n = cyc.x.shape[0], spec.segments, spec.n_R
    h = T_plan / M
    gt = design_good_test(design, pb.good, pb.links.plate_overhang)

    # (1) plan: the exact DP on the control points (proxy samples at u = m / M, m = 0..M, closed) x window R grid
    R_lo, dR, m_op = _window(spec, design, R_op, h)
    win = ReconfigurableDelta(robot=robot_d, R_min=R_lo, R_step=dR, n_R=n)
    idx = np.rint(np.arange(M + 1) * (K - 1) / M).astype(int)
    sub = Cycle(u=cyc.u[idx], x=cyc.x[idx], dx=cyc.dx[idx], ddx=cyc.ddx[idx], duration=T_plan, space=cyc.space)
    tab = path_tables(win, sub, pb.good.index, beta=pb.good.beta)
    Rk = tab.R
    chk = jax.vmap(lambda R: jax.vmap(lambda p: gt.point(R, p))(sub.x))(Rk)
    cell_ok = jnp.ones((M + 1, n), bool)
    if "passive_joints" in pb.enabled:
        cell_ok = cell_ok & (chk.joint_margin.T >= 0)
    if "interference" in pb.enabled:
        cell_ok = cell_ok & (chk.interference_margin.T >= 0)
    L, mech_ok = _force_limit(spec, Rk)
    feasible = tab.feasible & cell_ok & mech_ok[None, :]
    # |F| <= L(R)  <=>  |F / L(R)| <= 1: the DP's scalar force limit on normalised coefficients (L = inf: none)
    coef = jnp.where(feasible[..., None], tab.force_coef / L[None, :, None], 0.0)
    w = min(n - 1, _W_CAP)
    a = min(2 * w, _A_CAP)
    args = (tab.value, feasible, coef, tab.weights, dR, h, jnp.asarray(1.0, dt))
    kw = dict(w=w, a=a, primary_min=spec.aggregate == "min", speed=spec.speed, accel=spec.accel)
    P, S = jax.lax.map(lambda k0: path_dp(*args, k0, boundary="closed", backtrack=False, **kw)[:2], jnp.arange(n))
    k0 = jnp.argmax(jnp.where(P == jnp.max(P), S, -jnp.inf))
    P, S, plan = path_dp(*args, k0, boundary="closed", backtrack=True, **kw)
    planned = jnp.isfinite(P)

    # (2) realise: periodic cubic B-spline through the plan's control points. Candidates: the spline, the
    # constant per-task R and the window's best constant R on the exact criterion (cycle samples)
    B, B1, B2 = (jnp.asarray(x, dt) for x in periodic_basis(K, M))
    ctrl = R_lo + plan[:M].astype(dt) * dR
    consts = jnp.broadcast_to(Rk[:, None], (n, K))
    pcc = _cycle_checks(gt, cyc.x, consts)
    ok_c, integ_c, crit_c = _criterion(pb, spec, pcc, K, dt)
    best_c = jnp.argmax(jnp.where(ok_c, crit_c, -jnp.inf))           # ties: the smaller R
    zero = jnp.zeros((K,), dt)
    rows = jnp.stack([B @ ctrl, consts[m_op], consts[best_c]])         # (3, K)
    rows_u = jnp.stack([B1 @ ctrl, zero, zero])
    rows_uu = jnp.stack([B2 @ ctrl, zero, zero])
    pcs = _cycle_checks(gt, cyc.x, rows[:1])
    ok_s, integ_s, _ = _criterion(pb, spec, pcs, K, dt)
    ok_row = jnp.stack([ok_s[0] & planned, ok_c[m_op], ok_c[best_c]])
    integ = jnp.stack([integ_s[0], integ_c[m_op], integ_c[best_c]])
    jm = jnp.stack([_nanmin(pcs.joint_margin[0]), _nanmin(pcc.joint_margin[m_op]), _nanmin(pcc.joint_margin[best_c])])
    im = jnp.stack([_nanmin(pcs.interference_margin[0]), _nanmin(pcc.interference_margin[m_op]),
                    _nanmin(pcc.interference_margin[best_c])])

    # (3) per candidate: fastest cycle for the arm motors and for the R drive; it runs at the slower of the two
    cand = jax.vmap(lambda R, Ru, Ruu: _run_cycle(pb, spec, robot, robot_d, cyc, T_plan, T_nom, R, Ru, Ruu))(
        rows, rows_u, rows_uu)
    ppm = cand["picks_per_min"]
    runs = ok_row & jnp.isfinite(ppm) & (ppm > 0)
    best_p = jnp.max(jnp.where(runs, ppm, -jnp.inf))
    top = runs & (ppm >= best_p * (1 - 1e-12))
    # feasible and running first, then the most picks/min, then the higher criterion; none: the per-task R
    sel = jnp.where(jnp.any(runs), jnp.argmax(jnp.where(top, integ, -jnp.inf)), 1)
    out = {k: v[sel] for k, v in cand.items()}
    R, Ru = rows[sel], rows_u[sel]
    out.update({
        "joint_margin_deg": jnp.rad2deg(jnp.minimum(task_joint_margin, jm[sel])),
        "interference_margin": jnp.minimum(task_interference_margin, im[sel]),
        "R_path_min": jnp.min(R), "R_path_max": jnp.max(R),
        "R_window_min": R_lo, "R_window_max": R_lo + (n - 1) * dR,
        "path_index_mean": integ[sel], "path_index_mean_fixed": integ[1],
        "path_index_mean_plan": integ[0], "path_accepted": (sel == 0).astype(dt),
    })
    if spec.mechanism is not None:
        Tl = jnp.where(jnp.isfinite(out["cycle_time"]), out["cycle_time"], T_nom)
        drv = drive_profile(spec.mechanism, R, Ru / Tl, out.pop("force_R"))
        peak = jnp.where(jnp.all(drv.ok), jnp.max(jnp.abs(drv.effort)), jnp.nan)
        out["screw_torque_peak"] = peak
        out["screw_torque_margin"] = spec.motor_torque - peak
    else:
        out.pop("force_R")
        out["screw_torque_peak"] = out["screw_torque_margin"] = jnp.asarray(jnp.nan, dt)
    cyc_R = with_R(cyc, R, Ru / T_plan, rows_uu[sel] / (T_plan * T_plan))
    out = {k: jnp.asarray(v, dt) for k, v in out.items()}
    if return_profile:
        return out, {"R": R, "R_u": Ru, "R_uu": rows_uu[sel], "cycle": cyc_R, "T_plan": T_plan}
    return out


def _nanmin(a):
    return jnp.where(jnp.any(jnp.isnan(a)), jnp.nan, jnp.min(a))


def _cycle_checks(gt, x, rows):
    """The design's good test ``gt`` (:func:`deltajax.constraints.good_point`) at (x_j, rows[i, j]) for every row i:
    (rows, K) fields."""
    return jax.vmap(lambda Rrow: jax.vmap(lambda p, r: gt.point(r, p))(x, Rrow))(rows)


def _criterion(pb, spec, pc, K, dt):
    """(feasible, time-mean index, criterion) per row of :func:`_cycle_checks` (the designer's enabled checks)."""
    ok = jnp.all(pc.reachable & jnp.isfinite(pc.index), axis=1)
    if "passive_joints" in pb.enabled:
        ok = ok & jnp.all(pc.joint_margin >= 0, axis=1)
    if "interference" in pb.enabled:
        ok = ok & jnp.all(pc.interference_margin >= 0, axis=1)
    wts = jnp.ones((K,), dt).at[0].set(0.5).at[-1].set(0.5) / (K - 1)
    integ = jnp.sum(wts[None, :] * jnp.where(jnp.isfinite(pc.index), pc.index, 0.0), axis=1)
    return ok, integ, (integ if spec.aggregate == "integral" else jnp.min(pc.index, axis=1))


def _run_cycle(pb, spec, robot, robot_d, cyc, T_plan, T_nom, R, Ru, Ruu):
    """Cycle metrics of one R(u) profile (u-derivatives Ru, Ruu): T = max(T_motor, T_drive) and the margins."""
    dt = R.dtype
    gear = robot.mass.gear_ratio
    cyc_R = with_R(cyc, R, Ru / T_plan, Ruu / (T_plan * T_plan))
    rate = C.cycle_rate(robot, cyc_R, pb.motor, gear, dwell=pb.dwell, payload_mass=pb.payload)
    prof1 = cycle_profile(robot_d, cyc_R, 1.0)
    fa, fg = prof1.force_R_inertial_unit, prof1.force_R_gravity
    Lp, mech_p = _force_limit(spec, R)
    vmax, amax = jnp.max(jnp.abs(Ru)), jnp.max(jnp.abs(Ruu))

    def drive_ok(T):
        # no slack: the returned T (the bracket's feasible end) meets every limit as computed below
        return ((vmax <= spec.speed * T) & (amax <= spec.accel * T * T)
                & jnp.all(jnp.abs(fa / (T * T) + fg) <= Lp) & jnp.all(mech_p))

    T_drive = log_bisect(drive_ok, 1e-3, 60.0, dt)
    T = jnp.maximum(rate.cycle_time, T_drive)
    Tl = jnp.where(jnp.isfinite(T), T, T_nom)
    loads = C.drive_loads(robot, cyc_R, pb.motor, gear, duration=Tl, dwell=pb.dwell, payload_mass=pb.payload)
    dw = jnp.asarray(pb.dwell, dt)
    ppm = jnp.where(jnp.isfinite(T), 60.0 / (T + 2.0 * dw), jnp.where(jnp.isnan(T), jnp.nan, 0.0))
    F = fa / (Tl * Tl) + fg
    return {"picks_per_min": ppm, "cycle_time": T, "cycle_time_drive": T_drive, "cycle_time_motor": rate.cycle_time,
            "peak_utilisation": loads.peak_utilisation, "rms_utilisation": loads.rms_utilisation,
            "speed_utilisation": loads.speed_utilisation, "R_speed_margin": spec.speed - vmax / Tl,
            "R_accel_margin": spec.accel - amax / (Tl * Tl), "R_force_margin": spec.force - jnp.max(jnp.abs(F)),
            "force_R": F}
