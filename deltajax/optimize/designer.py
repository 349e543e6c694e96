"""The designer's problem: objectives and constraints as a Delta designer states them.

A design (fixed or reconfigurable, plus a gear ratio) is judged on a *task*: a cylinder on the z axis that
the robot must serve inside its good workspace, and the standard 25/305/25 mm pick-and-place cycle at the
task's centre with a payload (and optional dwells), driven by given servo motors through the design's
gearbox. Everything is computed by :mod:`deltajax.constraints` on the public core.

**Operating R** (reconfigurable designs): the robot reconfigures once per task and then runs at one R. The
operating R is chosen among ``n_R_operating`` evenly spaced candidates in [R_min, R_max] by the *same*
constraints as the design: among the candidates where the task cylinder lies in the good workspace, the
joints and links are clear over the task and along the cycle, and the motors can run the cycle, the one with
the most picks per minute (ties: the smaller R). A fixed design has one candidate, its R.
With ``mode="path"`` (config ``experiment.reconfig.mode``) the reconfigurable design runs the cycle with R(t)
around that per-task R, path-optimal under the R drive's limits (:mod:`deltajax.optimize.operating`); the
per-task values of the cycle metrics stay reported as ``<metric>_fixed`` (the fixed-R variant) in both modes.

Metrics (:data:`DESIGN_METRICS`, units :data:`DESIGN_UNITS`, sense :data:`DESIGN_SENSE`: +1 lower is better,
-1 higher is better):

* ``picks_per_min``: cycle rate at the operating R (1/min), :func:`deltajax.constraints.picks_per_minute`.
* ``regular_volume`` / ``regular_diameter``: the largest cylinder with the configured H/D inside the good
  workspace with R chosen per point (any R sample; for a fixed design its R) (m^3, m); on the search grids the
  grid's answer (:func:`deltajax.constraints.largest_cylinder`) or its continuous refinement
  (:func:`deltajax.constraints.refine_cylinder`, ``rw_refine``); on the verification grids found by rays
  (:func:`deltajax.optimize.rays.ray_cylinders`, ``rw_rays``: the first bad radius of every ray, so a bad region
  between the samples of a grid is found, not skipped).
* ``regular_volume_fixed``: the same with R frozen at the operating R (what the design gives without
  reconfiguring during the task).
* ``peak_utilisation`` / ``rms_utilisation`` / ``speed_utilisation``: motor loads at the picks/min cycle time.
* ``task_good_fraction``, ``joint_margin_deg`` (deg), ``interference_margin`` (m): over the task samples and
  the cycle samples at the operating R.
* ``R_operating`` (m), ``gear_ratio`` (1), ``arm_sum`` (L1 + L2, m).

Constraints (``g <= 0`` feasible, up to :data:`FEASIBILITY_TOL`, each normalised by a stated scale so that pymoo's summed violation is
meaningful): task in the good workspace (1 - task_good_fraction), passive joints (-margin / limit),
interference (-margin / 0.01 m), cycle rate (min_picks - picks) / max(min_picks, 1) (the cycle must be
reachable and runnable: a NaN or zero rate counts as a full violation), size budget (L1 + L2) / max_arm_sum - 1.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping, Optional, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from .. import constraints as C
from ..geometry import ReconfigurableDelta
from ..trajectory import adept_cycle
from .good import design_good_test
from . import operating as OP  # rtmode: the "R(t) along the cycle" operating mode
from .rays import first_open, good_where_possible, ray_cylinders, RayDensity, settle_good

__all__ = ["DesignerProblem", "DESIGN_METRICS", "DESIGN_UNITS", "DESIGN_SENSE", "CONSTRAINT_NAMES",
           "evaluate_designer", "knee_point", "cylinder_points"]

DESIGN_UNITS = {
    "picks_per_min": "1/min", "regular_volume": "m^3", "regular_diameter": "m", "regular_height": "m",
    "regular_z_top": "m", "regular_volume_fixed": "m^3", "regular_diameter_fixed": "m",
    "peak_utilisation": "1", "rms_utilisation": "1", "speed_utilisation": "1", "task_good_fraction": "1",
    "task_index_min": "1", "joint_margin_deg": "deg", "interference_margin": "m", "R_operating": "m",
    "gear_ratio": "1", "arm_sum": "m", "cycle_time": "s",
}
# rtmode: the path mode's drive margins and the per-task (fixed-R) values of the cycle metrics
DESIGN_UNITS.update({**OP.OPERATING_UNITS, **{f"{m}_fixed": DESIGN_UNITS[m] for m in OP.FIXED_VARIANT_METRICS}})
DESIGN_METRICS = tuple(DESIGN_UNITS)
DESIGN_SENSE = {"picks_per_min": -1, "regular_volume": -1, "regular_diameter": -1, "regular_volume_fixed": -1,
                "regular_diameter_fixed": -1, "peak_utilisation": 1, "rms_utilisation": 1, "speed_utilisation": 1,
                "task_good_fraction": -1, "task_index_min": -1, "joint_margin_deg": -1,
                "interference_margin": -1, "cycle_time": 1, "arm_sum": 1, "regular_height": -1}
DESIGN_SENSE.update({**OP.OPERATING_SENSE,  # rtmode
                     **{f"{m}_fixed": DESIGN_SENSE[m] for m in OP.FIXED_VARIANT_METRICS}})
#: Objectives a designer may choose (the others are reported, or describe the design).
OBJECTIVES = ("picks_per_min", "regular_volume", "regular_diameter", "regular_volume_fixed", "peak_utilisation",
              "rms_utilisation", "joint_margin_deg", "interference_margin", "task_index_min", "arm_sum")
CONSTRAINT_NAMES = ("task_in_good_workspace", "passive_joints", "interference", "cycle_rate", "size_budget")
INTERFERENCE_SCALE = 0.01  # m, normalises the interference violation
#: Constraint values up to this are satisfied: a size budget met exactly (0.2 + 0.4 = 0.6000000000000001 m) or
#: a coverage mean of 1.0 computed as 0.99999999999999994 must not make the baseline infeasible.
FEASIBILITY_TOL = 1e-9


def cylinder_points(diameter: float, height: float, z_top: float, n_r: int, n_phi: int, n_z: int) -> np.ndarray:
    """Task-region samples: ``n_r`` rings (radii D/2 * i / n_r, i = 1..n_r: the outermost on the surface) x
    ``n_phi`` >= 2 angles on the wedge phi in [0, 60 deg], both ends, at ``n_z`` heights from ``z_top`` to
    ``z_top + height`` (z down), (N, 3) m.

    The wedge is the whole cylinder by the robot's three-fold and mirror symmetry (chains at 0, 120, 240 deg:
    every point-wise quantity -- reachability, indices, joint and interference margins -- is the same at
    phi, -phi and phi + 120 deg; tests/test_task_symmetry.py), as for the regular workspace's
    :func:`deltajax.regular.polar_grid`. Its ends lie on the mirror planes, where the angular derivative of each
    such quantity vanishes, so the planes hold extremes of the task constraint; samples offset from them (the
    earlier grid: full circle, (i + 1/2) 360/n_phi, none at a multiple of 30 deg) missed the binding points, and
    designs verified on 3 x 12 x 5 such samples ran 2-6 % slower on a finer grid.

    The axis itself is left out on purpose: there the three-fold symmetry makes two singular values equal,
    where closed-form singular values have no derivative (the relaxation needs gradients at every sample).
    """
    if n_phi < 2:
        raise ValueError(f"cylinder_points needs n_phi >= 2 (both ends of the 60 deg wedge), got {n_phi}")
    zs = np.linspace(z_top, z_top + height, n_z)
    rs = diameter / 2.0 * np.arange(1, n_r + 1) / n_r
    phis = np.linspace(0.0, math.pi / 3.0, n_phi)
    pts = [[r * math.cos(p), r * math.sin(p), z] for z in zs for r in rs for p in phis]
    return np.asarray(pts, dtype=float)


@dataclasses.dataclass(frozen=True, eq=False)
class DesignerProblem:
    """Static description of the designer's problem (host object; identity-hashed so jitted code caches).

    Attributes:
        task_points: (N, 3) samples of the task cylinder (m, base frame, z down).
        cycle: the pick-and-place :class:`deltajax.Cycle` at the task centre.
        motor, joints, links, good: the models of :mod:`deltajax.constraints`.
        payload: kg; dwell: s at pick and at place.
        rw_points, rw_r, rw_z: the regular-workspace grid (:func:`deltajax.constraints.polar_grid`).
        hd_ratio: height / diameter of the regular-workspace cylinder.
        n_R_operating: operating-R candidates of a reconfigurable design.
        min_picks: required cycle rate (1/min; 0: only "the cycle runs").
        max_arm_sum: size budget L1 + L2 (m) or None.
        enabled: which of :data:`CONSTRAINT_NAMES` are active (the others are reported, not enforced).
        rw_refine: refine the grid's regular workspace to the continuous measure of
            :func:`deltajax.constraints.refine_cylinder` (the search grids; or the grid's measure there).
        rw_rays: the regular workspace found by rays instead (:func:`deltajax.optimize.rays.ray_cylinders`, the
            fields of a :class:`deltajax.optimize.rays.RayDensity`; the verification): no point grid is
            evaluated, ``rw_refine`` is unused.
        mode: operating mode of a reconfigurable design, ``"per_task"`` (one R per task, the candidates above) or
            ``"path"`` (R(t) along the cycle under the R drive's limits, :mod:`deltajax.optimize.operating`).
        operating: the :class:`deltajax.optimize.operating.OperatingSpec` (drive limits, mechanism) of ``mode``.
    """

    task_points: np.ndarray
    cycle: Any
    motor: C.Motor
    joints: C.JointModel
    links: C.LinkModel
    good: C.GoodSpec
    payload: float
    dwell: float
    rw_points: np.ndarray
    rw_r: np.ndarray
    rw_z: np.ndarray
    hd_ratio: float
    n_R_operating: int
    min_picks: float
    max_arm_sum: Optional[float]
    enabled: tuple
    settings: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    mode: str = "per_task"                          # rtmode
    operating: Optional[OP.OperatingSpec] = None    # rtmode
    rw_refine: bool = False                         # continuous regular workspace (constraints.refine_cylinder)
    rw_refine_steps: tuple = (C.REFINE_BISECT, C.REFINE_GOLDEN)   # (bisection, golden-section) steps
    rw_refine_samples: tuple = C.REFINE_SAMPLES     # (rings, angles, levels) of the unit cylinder
    rw_rays: Optional[tuple] = None                 # regular workspace found by rays (certify.RayDensity)

    def __post_init__(self):  # rtmode
        if self.mode not in OP.MODES:
            raise OP.OperatingError(f"DesignerProblem.mode must be one of {list(OP.MODES)}, got {self.mode!r}")
        if self.operating is None:
            object.__setattr__(self, "operating", OP.OperatingSpec(mode=self.mode))
        elif self.operating.mode != self.mode:
            raise OP.OperatingError(f"DesignerProblem.mode={self.mode!r} but operating.mode="
                                    f"{self.operating.mode!r}")

    @staticmethod
    def build(*, task: Mapping[str, float], cycle: Mapping[str, Any], motor: C.Motor, joints: C.JointModel,
              links: C.LinkModel, good: C.GoodSpec, regular: Mapping[str, float], n_R_operating: int,
              min_picks: float, max_arm_sum: Optional[float], enabled: Sequence[str],
              operating: Optional[OP.OperatingSpec] = None, rw_refine: bool = False,
              rw_refine_steps: Sequence[int] = (C.REFINE_BISECT, C.REFINE_GOLDEN),
              rw_refine_samples: Sequence[int] = C.REFINE_SAMPLES,
              rw_rays: Optional[Sequence[int]] = None) -> "DesignerProblem":
        """Build from validated plain values (see :mod:`deltajax.jobs.ga_reconfig` for the config)."""
        tp = cylinder_points(task["diameter"], task["height"], task["z_top"], int(task["n_r"]), int(task["n_phi"]),
                             int(task["n_z"]))
        tp = np.concatenate([tp, [[0.0, 0.0, task["z_top"]], [0.0, 0.0, task["z_top"] + task["height"]]]])
        centre = (0.0, 0.0, task["z_top"] + task["height"] / 2.0)
        cyc = adept_cycle(centre, duration=float(cycle["duration"]), n_samples=int(cycle["n_samples"]),
                          law=str(cycle["law"]))
        pts, r, z = C.polar_grid(regular["r_max"], regular["z_min"], regular["z_max"], int(regular["n_r"]),
                                 int(regular["n_phi"]), int(regular["n_z"]))
        return DesignerProblem(task_points=tp, cycle=cyc, motor=motor, joints=joints, links=links, good=good,
                               payload=float(cycle["payload"]), dwell=float(cycle["dwell"]), rw_points=pts,
                               rw_r=r, rw_z=z, hd_ratio=float(regular["hd_ratio"]),
                               n_R_operating=int(n_R_operating), min_picks=float(min_picks),
                               max_arm_sum=None if max_arm_sum is None else float(max_arm_sum),
                               enabled=tuple(enabled),
                               settings={"task": dict(task), "cycle": dict(cycle), "regular": dict(regular),
                                         "cycle_centre": centre},
                               mode=operating.mode if operating is not None else "per_task", operating=operating,
                               rw_refine=bool(rw_refine),
                               rw_refine_steps=tuple(int(n) for n in rw_refine_steps),
                               rw_refine_samples=tuple(int(n) for n in rw_refine_samples),
                               rw_rays=None if rw_rays is None else tuple(int(n) for n in rw_rays))


def _violations(pb: DesignerProblem, m: Mapping[str, jax.Array], arm_sum) -> jax.Array:
    """Normalised constraint values g (>0: violated by that much), in :data:`CONSTRAINT_NAMES` order;
    disabled constraints are 0. NaN margins (unreachable) count as a full violation (1)."""
    def nz(x):
        return jnp.where(jnp.isnan(x), 1.0, x)

    lim = jnp.rad2deg(pb.joints.limit)
    g = {
        "task_in_good_workspace": 1.0 - m["task_good_fraction"],
        "passive_joints": nz(-m["joint_margin_deg"] / lim),
        "interference": nz(-m["interference_margin"] / INTERFERENCE_SCALE),
        "cycle_rate": jnp.where(jnp.isfinite(m["picks_per_min"]) & (m["picks_per_min"] > 0),
                                (pb.min_picks - m["picks_per_min"]) / max(pb.min_picks, 1.0), 1.0),
        "size_budget": (arm_sum / pb.max_arm_sum - 1.0) if pb.max_arm_sum is not None else 0.0 * arm_sum,
    }
    return jnp.stack([jnp.where(n in pb.enabled, jnp.asarray(g[n], arm_sum.dtype), 0.0) for n in CONSTRAINT_NAMES])


def _nanmin(a, axis=-1):
    """min with NaN propagation: an unreachable sample makes the margin NaN (never silently satisfied)."""
    return jnp.where(jnp.any(jnp.isnan(a), axis=axis), jnp.nan, jnp.min(a, axis=axis))


#: Pairs per full good test call of :func:`_good_where_possible`, as a fraction of all pairs (1/GRID_CHUNKS each).
GRID_CHUNKS = 16


def _good_where_possible(good, possible, Rs, pts, decided=None):
    """``good(R, p)`` at every (R in ``Rs``, p in ``pts``), (nR, nP) bools, with the full test run only where the
    cheap necessary condition ``possible(R, p)`` holds (:func:`deltajax.optimize.rays.good_where_possible` on the
    R-major pairs, 1/GRID_CHUNKS of them per call): on the default problem's grid 6-56 % of the pairs are possible,
    28 % on average over Sobol designs (reach and the index exclude the rest)."""
    nR, nP = Rs.shape[0], pts.shape[0]
    M = nR * nP
    iR = jnp.repeat(jnp.arange(nR), nP)
    iP = jnp.tile(jnp.arange(nP), nR)
    return good_where_possible(good, possible, Rs[iR], pts[iP], -(-M // GRID_CHUNKS), decided).reshape(nR, nP)


def _all_any_good(good, possible, Rs, pts, decided=None):
    """``all(any(good(R, p) for R in Rs) for p in pts)``, the test of a cylinder's samples with R chosen per point
    (:func:`deltajax.constraints.refine_cylinder` in :func:`evaluate_designer`), with fewer full good tests: only
    pairs that pass the cheap necessary condition ``possible``; first one pair per point (its first possible R in
    the order of ``Rs``), then rounds of len(pts) pairs taken point by point from the points not yet good (all
    their remaining possible R, so a point with no good R is found bad within a round or two); it stops as soon
    as every point has a good R (True) or a point has none left (False). The answer does not depend on which
    pairs are tested or in what order (the good test is pure), so it is the full any/all's. ``decided``: a cheaper
    test deciding most pairs (:func:`deltajax.optimize.rays.settle_good`)."""
    nS, nR = pts.shape[0], Rs.shape[0]
    M = nS * nR
    maybe = jax.vmap(lambda p: jax.vmap(lambda R: possible(R, p))(Rs))(pts)       # (nS, nR): point-major order
    K = nS
    has = jnp.any(maybe, axis=1)
    first = jnp.argmax(maybe, axis=1)                 # each point's first possible R (round 0)

    def remaining(tested, sat):
        return maybe & ~tested & ~sat[:, None]

    def cond(st):
        c, tested, sat = st
        stuck = jnp.any(~sat & ~jnp.any(remaining(tested, sat), axis=1))
        return (c == 0) | (~jnp.all(sat) & ~stuck)

    def body(st):                                     # one compiled copy of the good test for every round
        c, tested, sat = st
        pick, live = first_open(remaining(tested, sat).reshape(-1), K)
        r0 = c == 0
        iS = jnp.where(r0, jnp.arange(nS), pick // nR)
        iR = jnp.where(r0, first, pick % nR)
        live = jnp.where(r0, has, live)
        g = settle_good(good, decided, Rs[iR], pts[iS], live) & live
        tested = tested.reshape(-1).at[jnp.where(live, iS * nR + iR, M)].set(True, mode="drop").reshape(nS, nR)
        sat = sat.at[jnp.where(g, iS, nS)].set(True, mode="drop")
        return c + 1, tested, sat

    _, _, sat = jax.lax.while_loop(cond, body, (jnp.int32(0), jnp.zeros((nS, nR), bool), jnp.zeros((nS,), bool)))
    return jnp.all(sat)


def evaluate_designer(pb: DesignerProblem, design, *, regular: bool = True, drawn_arm_sum=None,
                      candidates: int = 0) -> dict[str, jax.Array]:
    """Every metric of one design plus ``g`` (constraint values, (5,)), ``violation`` (sum of positive parts)
    and ``feasible``; pure and vmappable. ``regular=False`` skips the regular workspace (NaN).

    The good test (:func:`deltajax.constraints.good_point`) runs where a consumer reads it: at the operating-R
    candidates at the task cylinder's and the cycle's samples (their constraints choose the operating R), and for
    the regular workspace (rays, or the grid and its refinement) at the design's R samples and the chosen operating
    R, there only where its cheap necessary condition holds (:func:`deltajax.constraints.good_point_possible`) and
    mostly settled by :func:`deltajax.constraints.good_point_decided`.

    ``drawn_arm_sum``: the L1 + L2 that the size budget judges (default: the design's own). The tolerance Monte
    Carlo passes the nominal design's: the budget limits the drawing, not each built robot.

    ``candidates`` (with ``regular=False``): only the first ``candidates`` operating-R candidates in the order of
    the rule that chooses among them (most picks per minute first, then the smaller R) are tested, and ``resolved``
    says whether one of them is feasible: then the rule's choice is the full evaluation's (it takes the first
    feasible candidate in that order) and so are the values (the same functions at the same inputs, in another
    compiled program: XLA may round the last bit differently). Where none is, evaluate again without ``candidates``.
    """
    recon = isinstance(design, ReconfigurableDelta)
    robot0 = design.robot if recon else design
    dt = robot0.upper_arm.dtype
    gear = robot0.mass.gear_ratio
    if recon:
        j = jnp.arange(pb.n_R_operating, dtype=dt) / max(pb.n_R_operating - 1, 1)
        Rc = design.R_min + j * (design.R_max - design.R_min)
        Rs = design.R_samples() if regular else jnp.zeros((0,), dt)
    else:
        Rc = robot0.base_radius[None]
        Rs = jnp.zeros((0,), dt)
    gt = design_good_test(design, pb.good, pb.links.plate_overhang)
    at = gt.at

    def rates(Rs):   # the cycle's rate at each of the operating-R candidates ``Rs``
        return jax.vmap(lambda R: C.cycle_rate(at(R), pb.cycle, pb.motor, gear, dwell=pb.dwell,
                                               payload_mass=pb.payload))(Rs)

    sel = None
    if candidates and not regular and candidates < Rc.shape[0]:   # the rule's order: its first candidates only
        rate_all = rates(Rc)
        sel = jnp.argsort(-jnp.nan_to_num(rate_all.picks_per_min, nan=-1.0), stable=True)[:candidates]
        Rc = Rc[sel]
    nc, ns = Rc.shape[0], Rs.shape[0]
    arm_sum = robot0.upper_arm + robot0.forearm if drawn_arm_sum is None else jnp.asarray(drawn_arm_sum, dt)
    rays = regular and pb.rw_rays is not None        # the regular workspace found by rays: no point grid
    tp = jnp.asarray(pb.task_points, dt)
    cp = pb.cycle.x.astype(dt)
    n_t = tp.shape[0]
    # each good test where a consumer reads it: the operating-R candidates at the task and cycle samples (their
    # constraints choose the operating R); the regular workspace (rays or grid, below) tests its own pairs
    cand = jax.vmap(lambda R: jax.vmap(lambda p: gt.point(R, p))(jnp.concatenate([tp, cp])))(Rc)    # (nc, P)
    t_sl, c_sl = slice(0, n_t), slice(n_t, None)
    rate = rates(Rc) if sel is None else jax.tree_util.tree_map(lambda x: x[sel], rate_all)
    cands = {
        "task_good_fraction": jnp.mean(cand.good[:, t_sl].astype(dt), axis=1),
        "task_index_min": _nanmin(cand.index[:, t_sl]),
        "joint_margin_deg": jnp.rad2deg(jnp.minimum(_nanmin(cand.joint_margin[:, t_sl]),
                                                    _nanmin(cand.joint_margin[:, c_sl]))),
        "interference_margin": jnp.minimum(_nanmin(cand.interference_margin[:, t_sl]),
                                           _nanmin(cand.interference_margin[:, c_sl])),
        "picks_per_min": rate.picks_per_min,
        "cycle_time": rate.cycle_time,
        "peak_utilisation": rate.loads.peak_utilisation,
        "rms_utilisation": rate.loads.rms_utilisation,
        "speed_utilisation": rate.loads.speed_utilisation,
    }
    viol_c = jax.vmap(lambda i: jnp.sum(jnp.maximum(_violations(pb, {k: v[i] for k, v in cands.items()}, arm_sum)
                                                   - FEASIBILITY_TOL, 0.0)))(jnp.arange(nc))
    # feasible candidates first, then the most picks per minute, then the smaller R (argmax takes the first)
    score = jnp.where(viol_c <= 0, jnp.nan_to_num(cands["picks_per_min"], nan=-1.0), -1e9 - viol_c)
    k = jnp.argmax(score)
    out = {n: v[k] for n, v in cands.items()}
    out["R_operating"] = Rc[k]
    if candidates:
        out["resolved"] = jnp.any(viol_c <= 0) if sel is not None else jnp.asarray(True)
    out["gear_ratio"] = gear * jnp.ones((), dt)
    out["arm_sum"] = arm_sum
    nan = jnp.asarray(jnp.nan, dt)

    # the good test (flag; settled where its closed-form plate and joint tests decide it: the search grid, its
    # refinement, the rays; its cheap necessary condition: every user skips pairs where it fails)
    good_at, decided, possible = gt.good, gt.decided_settle, gt.possible

    if rays:   # every ray search of both good sets (R per point; the operating R) in one call of the good test
        sets = [Rs, Rc[k][None]] if recon else [Rc[k][None]]
        cyl = ray_cylinders(good_at, sets,
                            float(pb.rw_r[-1]), float(pb.rw_z[0]), float(pb.rw_z[-1]), pb.hd_ratio,
                            RayDensity(*pb.rw_rays), dt,
                            possible_R=possible, decided_R=decided)
        reg, regf = cyl[0], cyl[-1]
        out.update(regular_volume=reg.volume, regular_diameter=reg.diameter, regular_height=reg.height,
                   regular_z_top=reg.z_top, regular_volume_fixed=regf.volume, regular_diameter_fixed=regf.diameter)
    elif regular:
        r, z = jnp.asarray(pb.rw_r, dt), jnp.asarray(pb.rw_z, dt)
        grid = pb.rw_points.shape[:3]
        rw = jnp.asarray(pb.rw_points, dt).reshape(-1, 3)

        # good tests only where the cheap necessary condition holds (reach, index, plate), mostly decided cheaply
        def good_grid(R_set):
            return _good_where_possible(good_at, possible, R_set, rw, decided)

        if recon:   # the R samples and the operating R in one call (one compiled copy of the test)
            g_all = good_grid(jnp.concatenate([Rs, Rc[k][None]]))
            g_s, g_k = g_all[:ns], g_all[ns].reshape(grid)                      # (ns, grid points); the operating R
            g_any = jnp.any(g_s, axis=0).reshape(grid)
        else:
            g_k = good_grid(Rc[k][None])[0].reshape(grid)
            g_any = g_k
        reg = C.largest_cylinder(jnp.all(g_any, axis=2), r, z, pb.hd_ratio)
        regf = C.largest_cylinder(jnp.all(g_k, axis=2), r, z, pb.hd_ratio)
        if pb.rw_refine:   # continuous measure, bracketed by the grid's answer (same good test, same R samples)
            good_any = ((lambda p: jnp.any(jax.vmap(lambda R: good_at(R, p))(Rs))) if recon
                        else (lambda p: good_at(Rc[k], p)))
            all_any = None
            if recon:   # R samples tried in the order of their good grid points, most first
                rank = jnp.argsort(-jnp.sum(g_s, axis=1), stable=True)
                all_any = lambda P: _all_any_good(  # noqa: E731
                    good_at, possible, Rs[rank], P, decided)
            nb, ng = pb.rw_refine_steps
            unit = C.cylinder_samples(pb.hd_ratio, *pb.rw_refine_samples)
            reg = C.refine_cylinder(good_any, reg, r, z, pb.hd_ratio, unit=unit, n_bisect=nb, n_golden=ng,
                                    all_good=all_any)
            regf = C.refine_cylinder(lambda p: good_at(Rc[k], p), regf, r, z, pb.hd_ratio, unit=unit, n_bisect=nb,
                                     n_golden=ng,
                                     all_good=lambda P: _all_any_good(good_at, possible, Rc[k][None], P, decided))
        out.update(regular_volume=reg.volume, regular_diameter=reg.diameter, regular_height=reg.height,
                   regular_z_top=reg.z_top, regular_volume_fixed=regf.volume, regular_diameter_fixed=regf.diameter)
    else:
        out.update({n: nan for n in ("regular_volume", "regular_diameter", "regular_height", "regular_z_top",
                                     "regular_volume_fixed", "regular_diameter_fixed")})
    # -- rtmode: operating mode (deltajax/optimize/operating.py). The per-task R's cycle metrics stay reported as
    # <m>_fixed (the fixed-R variant); in mode "path" the cycle metrics become those of R(t) along the cycle.
    out.update({f"{n}_fixed": out[n] for n in OP.FIXED_VARIANT_METRICS})
    if recon and pb.mode == "path":
        out.update(OP.path_operating(pb, design, Rc[k], out["cycle_time"], _nanmin(cand.joint_margin[:, t_sl])[k],
                                     _nanmin(cand.interference_margin[:, t_sl])[k]))
    else:
        out.update(OP.not_evaluated(dt))
    # -- end rtmode
    g = _violations(pb, out, arm_sum)
    out["g"] = g
    out["violation"] = jnp.sum(jnp.maximum(g - FEASIBILITY_TOL, 0.0))
    out["feasible"] = out["violation"] <= 0.0
    return out


def knee_point(F: np.ndarray) -> int:
    """Knee of a front (minimised objectives, rows = points): the point farthest from the hyperplane through
    the extreme points, in objectives normalised to [0, 1] over the front (Das 1999; Deb & Gupta 2011).
    With one point, 0; when the extremes are degenerate, the point with the smallest normalised sum."""
    F = np.asarray(F, float)
    n, m = F.shape
    if n <= 2:
        return int(np.argmin(F.sum(axis=1))) if n else -1
    lo, hi = F.min(axis=0), F.max(axis=0)
    Fn = (F - lo) / np.where(hi > lo, hi - lo, 1.0)
    ext = np.stack([Fn[np.argmin(Fn[:, j])] for j in range(m)])   # best point of each objective
    try:
        w = np.linalg.solve(ext, np.ones(m))                         # hyperplane w . f = 1 through them
    except np.linalg.LinAlgError:
        return int(np.argmin(Fn.sum(axis=1)))
    d = (1.0 - Fn @ w) / np.linalg.norm(w)                           # > 0: below the plane (toward the ideal)
    return int(np.argmax(d))
