"""Design objectives and constraints, compiled and vmapped over a whole population.

Everything is computed by the workspace engine (:mod:`deltajax.workspace`) and the dynamics
(:mod:`deltajax.dynamics`, :mod:`deltajax.trajectory`); this module only places the samples, picks the
operating configuration and combines the numbers.

Metrics of one design (``METRICS``; units in :data:`METRIC_UNITS`, sense in :data:`SENSE`):

* ``volume``: workspace volume (m^3). Reconfigurable designs: a point counts if *some* R sample reaches it
  (:func:`deltajax.workspace.reconfigurable_reachable`, "R chosen per point"); fixed designs:
  :func:`deltajax.workspace.reachable_mask`.
* ``volume_fixed``: volume of the design frozen at its nominal R (for reconfigurable designs the baseline R
  clipped into the design's range; equal to ``volume`` for fixed designs).
* ``good_volume``: volume where the index (``task.index``, k~ by default) is >= ``workspace.good_threshold``,
  at the best R per point for reconfigurable designs (:func:`deltajax.workspace.resolve_redundancy`).
* ``task_index_mean`` / ``task_index_min``: mean / min of the index over the task cylinder (R per point);
  unreachable task points count as 0.
* ``task_coverage``: fraction of the task cylinder that is reachable with index >= ``task.k_min``.
* ``peak_torque``: max over actuators and time of |tau| on the standard pick-and-place ("Adept") cycle at its
  nominal duration (N m), :func:`deltajax.cycle.cycle_metrics`.
* ``cycle_time``: minimum duration of that cycle under the motor torque and speed limits (s).
* ``peak_speed``: end-effector speed (m/s) the motors give at ``motor_speed`` rad/s each, max over the
  directions |thetadot_i| <= motor_speed (the four vertex sign patterns of the box), averaged over the task
  cylinder points reachable at the operating R: mean_p max_s |J_theta(p) s| * motor_speed.

Operating configuration of a reconfigurable design for the task: the cycle is run at one R (reconfigure once
per task, then run), namely the one of ``cycle.n_R_operating`` evenly spaced candidates in [R_min, R_max] with
the smallest peak torque among those where the whole cycle is reachable (the dynamics along a cycle dominate
the cost of a design, hence a few candidates rather than all R samples); ``peak_torque``, ``cycle_time`` and ``peak_speed`` are taken at that R.

Sampling: the workspace volume is a quadrature over a cylindrical grid in one sixth of the workspace
(0 <= phi <= 60 deg), cell midpoints with weights r dr dphi dz, times 6: a Delta's workspace has the
symmetry of the triangle (3 rotations x the mirror y -> -y), so that sixth is a fundamental domain. The
grid covers every design in the bounds (radius and depth from the largest possible reach).

Constraints (designer's): the task cylinder must have ``task_coverage >= task.coverage_min`` (default: all of
it reachable with index >= k_min: "task in the good workspace, minimum k~ there"), and the pick-and-place
cycle must be reachable (joint limits included) at the operating R; optionally a size budget
L1 + L2 <= ``constraints.max_arm_sum`` (without it a bigger robot always has a bigger workspace). Violation
v = max(0, coverage_min - coverage) + [cycle not reachable] + max(0, L1 + L2 - max_arm_sum) / max_arm_sum. Handling (``constraints.handling``):

* ``feasibility_first`` (default, Deb's rules as one scalar): feasible designs get their objective value,
  infeasible ones ``INFEASIBLE_OFFSET + v``. Feasible values are bounded far below the offset, so every
  feasible design beats every infeasible one and infeasible ones are ranked by violation.
* ``penalty``: objective + ``constraints.penalty`` * v.

Population level (:func:`make_fitness`, :func:`evaluate_population`, ``screen=True``): the R sweeps of the volume
and of the task coverage run for the whole population at once, skipping only samples that cannot change the
answer (:func:`~deltajax.optimize.screens.reach_cover`, :func:`~deltajax.optimize.screens.task_cover`: a certified closed-form exclusion, one exact sample per point,
then the exact sweep of the undecided points in ``lax.while_loop`` chunks); the flags, hence the fitness, are
the per-design sweeps' bit for bit (tests/test_ga_fitness.py). :func:`evaluate_design` stays the per-design,
vmappable form.

Fitness (minimised): sum_j w_j * s_j * m_j / m_j(baseline), s_j = -1 for metrics to maximise, +1 to minimise.
The baseline design therefore has fitness sum_j w_j s_j, and -0.1 below it means "10 % better, weighted".
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping, Optional, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ..cycle import Limits, cycle_metrics
from ..geometry import Delta, ReconfigurableDelta
from ..jacobian import jq_theta, jx_det, jx_row
from ..kinematics import (chain_local, design_ok, limit_terms, loop_closure, loop_vectors,
                          safe_point)
from ..trajectory import adept_cycle
from ..workspace import (index_fields, mirrored_point_indices, reachable_mask, reconfigurable_reachable,
                         resolve_redundancy)
from .screens import reach_cover, task_cover

__all__ = ["METRICS", "METRIC_UNITS", "SENSE", "Problem", "ObjectiveError", "evaluate_design",
           "evaluate_population", "make_fitness", "wedge_points", "cylinder_points", "INFEASIBLE_OFFSET",
           "fitness_from_metrics", "speed_vertices", "soft_margin", "soft_membership"]

METRICS = ("volume", "volume_fixed", "good_volume", "task_index_mean", "task_index_min", "task_coverage",
           "peak_torque", "cycle_time", "peak_speed")
METRIC_UNITS = {"volume": "m^3", "volume_fixed": "m^3", "good_volume": "m^3", "task_index_mean": "1",
                "task_index_min": "1", "task_coverage": "1", "peak_torque": "N m", "cycle_time": "s",
                "peak_speed": "m/s", "R_operating": "m", "violation": "1", "feasible": "1"}
#: +1: minimise, -1: maximise.
SENSE = {"volume": -1, "volume_fixed": -1, "good_volume": -1, "task_index_mean": -1, "task_index_min": -1,
         "task_coverage": -1, "peak_torque": 1, "cycle_time": 1, "peak_speed": -1}
INFEASIBLE_OFFSET = 1.0e3


class ObjectiveError(ValueError):
    """Invalid objective/constraint configuration (names the config field and the value)."""


def wedge_points(r_max: float, z_max: float, n_r: int, n_phi: int, n_z: int) -> tuple[np.ndarray, np.ndarray]:
    """Cell midpoints of a cylindrical grid over one sixth of the workspace and their volume weights.

    Returns:
        (points (N, 3) m, weights (N,) m^3); ``weights.sum()`` is the volume of the whole cylinder
        pi r_max^2 z_max (the factor 6 is included).
    """
    dr, dphi, dz = r_max / n_r, (math.pi / 3.0) / n_phi, z_max / n_z
    r = (np.arange(n_r) + 0.5) * dr
    phi = (np.arange(n_phi) + 0.5) * dphi
    z = (np.arange(n_z) + 0.5) * dz
    R, P, Z = np.meshgrid(r, phi, z, indexing="ij")
    pts = np.stack([R * np.cos(P), R * np.sin(P), Z], axis=-1).reshape(-1, 3)
    w = (6.0 * R * dr * dphi * dz).reshape(-1)
    return pts, w


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
    designs verified on 3 x 12 x 5 such samples ran 2-6 % slower on a finer grid (docs/REPRODUCTION.md
    §5.2).

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


#: Motor-speed sign patterns |thetadot_i| = 1 (the box's vertices up to a global sign).
speed_vertices = np.array([[1, 1, 1], [1, 1, -1], [1, -1, 1], [-1, 1, 1]], dtype=float)


@dataclasses.dataclass(frozen=True, eq=False)
class Problem:
    """Everything static about the design problem (host object; identity-hashed so jitted fitness caches).

    Build with :meth:`from_config`. Attributes hold NumPy sample arrays and plain settings.
    """

    ws_points: np.ndarray
    ws_weights: np.ndarray
    task_points: np.ndarray
    cycle: Any
    limits: Any
    motor_speed: float
    index: str
    good_threshold: float
    k_min: float
    coverage_min: float
    weights: Mapping[str, float]
    handling: str
    penalty: float
    n_R_operating: int = 4
    max_arm_sum: Optional[float] = None
    beta: float = 0.5
    b_v: float = 2.0
    b_f: float = 4.2
    baseline: Optional[Mapping[str, float]] = None
    settings: Mapping[str, Any] = dataclasses.field(default_factory=dict)

    @property
    def needed(self) -> frozenset:
        """Metrics the fitness needs (others are skipped inside the GA for speed)."""
        return frozenset(self.weights) | {"task_coverage"}

    def with_baseline(self, baseline: Mapping[str, float]) -> "Problem":
        return dataclasses.replace(self, baseline={k: float(v) for k, v in baseline.items()})

    @staticmethod
    def from_config(cfg: Mapping[str, Any], *, r_max: float, z_max: float, prefix: str = "experiment") -> "Problem":
        """Build from the experiment config (``workspace``, ``task``, ``cycle``, ``objectives``, ``constraints``).

        Args:
            cfg: mapping with those sub-mappings (the weighted-sum problem of ``experiments/bench_ga.py``; the
                main job's designer problem is :mod:`deltajax.optimize.designer`).
            r_max, z_max: extent of the workspace quadrature (m), from the design bounds.
        """
        def sub(name):
            v = cfg.get(name) if hasattr(cfg, "get") else None
            return v if v is not None else {}

        def num(m, key, default, where, lo=None, integer=False):
            v = m.get(key, default) if hasattr(m, "get") else default
            if isinstance(v, bool) or v is None:
                raise ObjectiveError(f"{prefix}.{where}.{key} must be a number, got {v!r}")
            try:
                f = float(v)
            except (TypeError, ValueError):
                raise ObjectiveError(f"{prefix}.{where}.{key} must be a number, got {v!r}") from None
            if not math.isfinite(f) or (lo is not None and f < lo):
                raise ObjectiveError(f"{prefix}.{where}.{key} must be finite and >= {lo}, got {v!r}")
            if integer:
                if not f.is_integer():
                    raise ObjectiveError(f"{prefix}.{where}.{key} must be an integer, got {v!r}")
                return int(f)
            return f

        ws, task, cyc, obj, con = sub("workspace"), sub("task"), sub("cycle"), sub("objectives"), sub("constraints")
        pts, w = wedge_points(r_max, z_max, num(ws, "n_r", 12, "workspace", 2, True),
                              num(ws, "n_phi", 4, "workspace", 1, True), num(ws, "n_z", 12, "workspace", 2, True))
        diameter = num(task, "diameter", 0.3, "task", 0.0)
        height = num(task, "height", 0.1, "task", 0.0)
        z_top = num(task, "z_top", 0.35, "task", 0.0)
        tpts = cylinder_points(diameter, height, z_top, num(task, "n_r", 2, "task", 1, True),
                               num(task, "n_phi", 6, "task", 2, True), num(task, "n_z", 3, "task", 2, True))
        index = str(task.get("index", "k_tilde"))
        from ..indices import INDEX_NAMES

        if index not in INDEX_NAMES:
            raise ObjectiveError(f"{prefix}.task.index must be one of {INDEX_NAMES}, got {index!r}")
        centre = (0.0, 0.0, z_top + height / 2.0)
        try:
            cycle = adept_cycle(centre, duration=num(cyc, "duration", 0.5, "cycle", 1e-6),
                                n_samples=num(cyc, "n_samples", 48, "cycle", 3, True),
                                law=str(cyc.get("law", "poly5")))
            limits = Limits(torque=num(cyc, "torque_limit", 60.0, "cycle", 1e-9),
                            speed=num(cyc, "speed_limit", 30.0, "cycle", 1e-9))
        except ValueError as e:
            raise ObjectiveError(f"{prefix}.cycle: {e}") from None
        weights_cfg = obj.get("weights", None) if hasattr(obj, "get") else None
        if not weights_cfg:
            raise ObjectiveError(f"{prefix}.objectives.weights is empty: choose from {list(METRICS)}")
        weights = {}
        for k, v in dict(weights_cfg).items():
            if k not in METRICS:
                raise ObjectiveError(f"{prefix}.objectives.weights.{k}: unknown metric; known: {list(METRICS)}")
            wv = num(weights_cfg, k, None, "objectives.weights", 0.0)
            if wv > 0:
                weights[str(k)] = wv
        if not weights:
            raise ObjectiveError(f"{prefix}.objectives.weights: all weights are zero")
        handling = str(con.get("handling", "feasibility_first"))
        if handling not in ("feasibility_first", "penalty"):
            raise ObjectiveError(f"{prefix}.constraints.handling must be 'feasibility_first' or 'penalty', "
                                 f"got {handling!r}")
        cov = num(con, "coverage_min", 1.0, "constraints", 0.0)
        if cov > 1.0:
            raise ObjectiveError(f"{prefix}.constraints.coverage_min must be in [0, 1], got {cov!r}")
        return Problem(
            ws_points=pts, ws_weights=w, task_points=tpts, cycle=cycle, limits=limits,
            motor_speed=num(cyc, "motor_speed", 10.0, "cycle", 1e-9), index=index,
            good_threshold=num(ws, "good_threshold", 0.3, "workspace", 0.0), k_min=num(con, "k_min", 0.2,
                                                                                       "constraints", 0.0),
            coverage_min=cov, weights=weights, handling=handling,
            penalty=num(con, "penalty", 10.0, "constraints", 0.0),
            max_arm_sum=(None if con.get("max_arm_sum", None) is None
                         else num(con, "max_arm_sum", None, "constraints", 1e-9)),
            n_R_operating=num(cyc, "n_R_operating", 4, "cycle", 1, True), beta=num(task, "beta", 0.5, "task", 0.0),
            settings={"r_max": r_max, "z_max": z_max, "task_diameter": diameter, "task_height": height,
                      "task_z_top": z_top, "cycle_centre": centre})


def _index_at_points(pb: Problem, design, pts, differentiable: bool = False):
    """(ok, index value) at ``pts``: R per point (best index) for reconfigurable designs.

    ``differentiable=True`` keeps the selected R sample fixed (stop_gradient) and re-evaluates the index there
    with the single-point kernel, so that gradients flow through R_k = R_min + k R_step and the geometry
    without passing through the infeasible samples of the sweep (whose NaN partials would poison them).
    """
    if isinstance(design, ReconfigurableDelta):
        red = resolve_redundancy(design, pts, criterion=pb.index, b_v=pb.b_v, b_f=pb.b_f, beta=pb.beta)
        if not differentiable:
            return red.ok, jnp.where(red.ok, red.value, 0.0)
        k = jax.lax.stop_gradient(jnp.where(red.ok, red.k, 0))
        Rk = design.R_min + k.astype(design.R_min.dtype) * design.R_step
        ok, ind = jax.vmap(lambda q, R: mirrored_point_indices(design.at(R), q, b_v=pb.b_v, b_f=pb.b_f,
                                                               beta=pb.beta, sv_method="jacobi"))(
            pts, Rk)
        v = getattr(ind, pb.index)
        ok = ok & red.ok & jnp.isfinite(v)
        return ok, jnp.where(ok, v, 0.0)
    ok, fields = index_fields(design, pts, b_v=pb.b_v, b_f=pb.b_f, beta=pb.beta)
    v = fields[pb.index]
    ok = ok & jnp.isfinite(v)
    return ok, jnp.where(ok, v, 0.0)


def _ee_speed(robot: Delta, pts, motor_speed):
    """Mean over the reachable ``pts`` of the max end-effector speed with |thetadot_i| <= motor_speed (m/s);
    0 if none is reachable.

    Per point: the core's algebraic IK (cos/sin theta, no atan2 round trip), unit forearm vectors and the Jq
    diagonal (:func:`deltajax.kinematics.loop_vectors`, :func:`deltajax.jacobian.jq_theta`), then
    v = Jx^-1 diag(L1 d) s for the four vertex patterns s by the adjugate of Jx (flat scalars): the classic
    Jacobian J[:, 1:] of :func:`deltajax.jacobian.jacobian` applied to s, to rounding (kappa(Jx) eps).
    """
    L1, L2, lim = robot.upper_arm, robot.forearm, limit_terms(robot.theta_min, robot.theta_max)

    def one(p):
        p, usable = safe_point(robot, p)
        rows, d, ok = [], [], design_ok(robot) & usable
        for i in range(3):
            x, y, z = chain_local(p[0], p[1], p[2], i)
            dx = x + robot.platform_radius - robot.base_radius
            lc = loop_closure(dx, y, z, L1, L2, lim)
            ux, uy, uz = loop_vectors(dx, y, z, lc.cos, lc.sin, L1, L2)
            rows.extend(jx_row(ux, uy, uz, i))
            d.append(L1 * jq_theta(ux, uz, lc.cos, lc.sin))
            ok = ok & lc.ok
        eye = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
        a = [jnp.where(ok, v, e) for v, e in zip(rows, eye)]  # double where: finite off the workspace
        det = jx_det(*a)
        det = jnp.where(det != 0.0, det, 1.0)
        adj = (a[4] * a[8] - a[5] * a[7], a[2] * a[7] - a[1] * a[8], a[1] * a[5] - a[2] * a[4],
               a[5] * a[6] - a[3] * a[8], a[0] * a[8] - a[2] * a[6], a[2] * a[3] - a[0] * a[5],
               a[3] * a[7] - a[4] * a[6], a[1] * a[6] - a[0] * a[7], a[0] * a[4] - a[1] * a[3])
        best = None
        for sv in speed_vertices:
            b = [d[k] * float(sv[k]) for k in range(3)]
            w2 = sum((adj[3 * r] * b[0] + adj[3 * r + 1] * b[1] + adj[3 * r + 2] * b[2]) ** 2 for r in range(3))
            best = w2 if best is None else jnp.maximum(best, w2)
        return jnp.sqrt(best) / jnp.abs(det) * motor_speed, ok

    s, ok = jax.vmap(one)(pts)
    n = jnp.sum(ok)
    return jnp.where(n > 0, jnp.sum(jnp.where(ok, s, 0.0)) / jnp.maximum(n, 1), 0.0)


def _smin(x, t, axis=-1):
    """Smooth minimum -t log sum exp(-x / t) (<= min x; t -> 0 gives min)."""
    return -t * jax.scipy.special.logsumexp(-x / t, axis=axis)


def soft_margin(robot: Delta, p, t: float = 0.01):
    """Signed, dimensionless reachability margin of one point (> 0 inside the workspace), smooth a.e.

    Per chain: the IK discriminant rho^2 - m^2 (see :func:`deltajax.ik_cos_sin`) over L1^2 (loop closure)
    and, where the loop closes, cos(theta - mid) - cos(half) (joint limits, mid/half of the limit interval);
    combined by a smooth minimum over the two and over the chains. Same algebra as the core's IK test, so
    ``soft_margin > 0`` agrees with :func:`deltajax.workspace.reachable_mask` (up to the smooth-min slack).
    """
    from ..kinematics import chain_local, limit_terms, loop_closure

    lim = limit_terms(robot.theta_min, robot.theta_max)
    L1 = robot.upper_arm
    a, b = [], []
    for i in range(3):
        x, y, z = chain_local(p[0], jnp.abs(p[1]), p[2], i)
        lc = loop_closure(x + robot.platform_radius - robot.base_radius, y, z, L1, robot.forearm, lim)
        ai = lc.disc / (L1 * L1)
        a.append(ai)
        b.append(jnp.where(lc.reach, jnp.where(lim.cos_half < -1.0, 1.0, lc.margin), ai))  # unlimited: 1
    a, b = jnp.stack(a), jnp.stack(b)
    per_chain = _smin(jnp.stack([a, b], axis=-1), t)
    return _smin(per_chain, t)


def soft_membership(design, pts, tau: float):
    """Smooth workspace membership sigmoid(margin / tau) of ``pts``; the margin of a reconfigurable design
    is the smooth maximum over its R samples (R chosen per point)."""
    if isinstance(design, ReconfigurableDelta):
        Rs = design.R_samples()
        marg = jax.vmap(lambda R: jax.vmap(lambda q: soft_margin(design.at(R), q))(pts))(Rs)  # (n_R, N)
        marg = -_smin(-marg, 0.01, axis=0)
    else:
        marg = jax.vmap(lambda q: soft_margin(design, q))(pts)
    return jax.nn.sigmoid(marg / tau)


def evaluate_design(pb: Problem, design, needed: Optional[Sequence[str]] = None, *,
                    smooth: Optional[float] = None) -> dict[str, jax.Array]:
    """All (or the ``needed``) metrics of one design, plus ``violation`` and ``feasible``; pure, vmappable.

    Args:
        pb: the problem.
        design: a :class:`Delta` (fixed) or :class:`ReconfigurableDelta`.
        needed: metric names to compute (default: all of :data:`METRICS`).
        smooth: ``None`` for the true metrics. A temperature tau > 0 gives the *differentiable relaxation*
            used by :mod:`deltajax.optimize.refine`: workspace membership sigmoid(margin / tau)
            (:func:`soft_membership`), index thresholds sigmoid((index - threshold) / tau), and the operating
            R kept at the selected candidate with gradients through that candidate only. tau -> 0 recovers
            the true metrics (tested).
    """
    return _evaluate(pb, design, needed, smooth, None)


def _evaluate(pb: Problem, design, needed, smooth, covered, reach=None) -> dict[str, jax.Array]:
    """:func:`evaluate_design`; ``covered`` (N_task,) bool: the task points' coverage flags computed for the
    whole population by :func:`task_cover` (then the task index terms are not computed and must not be
    needed), or ``None``: the per-design exact sweep; ``reach`` (N_ws,) bool: the workspace points'
    reachability from :func:`reach_cover`, or ``None``: the per-design sweep."""
    need = set(METRICS if needed is None else needed)
    need.add("task_coverage")
    recon = isinstance(design, ReconfigurableDelta)
    robot0 = design.robot if recon else design
    dt = robot0.upper_arm.dtype
    pts = jnp.asarray(pb.ws_points, dt)
    w = jnp.asarray(pb.ws_weights, dt)
    tpts = jnp.asarray(pb.task_points, dt)
    out: dict[str, jax.Array] = {}

    def step(x):  # indicator x >= 0, or its relaxation
        return (x >= 0).astype(dt) if smooth is None else jax.nn.sigmoid(x / smooth)

    if "volume" in need:
        if smooth is None:
            if reach is None:
                reach = reconfigurable_reachable(design, pts) if recon else reachable_mask(design, pts)
            out["volume"] = jnp.sum(jnp.where(reach, w, 0.0))
        else:
            out["volume"] = jnp.sum(w * soft_membership(design, pts, smooth))
    if "volume_fixed" in need:
        if smooth is None:
            out["volume_fixed"] = jnp.sum(jnp.where(reachable_mask(robot0, pts), w, 0.0))
        else:
            out["volume_fixed"] = jnp.sum(w * soft_membership(robot0, pts, smooth))
    if "good_volume" in need:
        ok, v = _index_at_points(pb, design, pts, smooth is not None)
        out["good_volume"] = jnp.sum(w * jnp.where(ok, step(v - pb.good_threshold), 0.0))
    if covered is not None:  # the population-level certified coverage (task_cover): same flags as below
        out["task_coverage"] = jnp.mean(covered.astype(dt))
    elif pb.coverage_min > 0 or need & {"task_index_mean", "task_index_min"} or smooth is None:
        ok_t, v_t = _index_at_points(pb, design, tpts, smooth is not None)
        out["task_index_mean"] = jnp.mean(v_t)
        out["task_index_min"] = jnp.min(v_t) if smooth is None else _smin(v_t, smooth)
        out["task_coverage"] = jnp.mean(jnp.where(ok_t, step(v_t - pb.k_min), 0.0))
    else:  # relaxation without any task term: skip the redundancy sweep (and its gradient)
        out["task_coverage"] = jnp.ones((), dt)
    # The cycle is always evaluated: its reachability is a constraint.
    if recon:
        j = jnp.arange(pb.n_R_operating, dtype=dt) / max(pb.n_R_operating - 1, 1)
        Rs = design.R_min + j * (design.R_max - design.R_min)
        cm = jax.vmap(lambda R: cycle_metrics(design.at(R), pb.cycle, pb.limits))(Rs)
        peak = jnp.max(cm.peak_torque, axis=-1)
        good = cm.reachable & jnp.isfinite(peak)
        score = jnp.where(good, peak, jnp.inf)
        k = jnp.argmin(score)
        cycle_ok = jnp.isfinite(score[k])
        R_op, pk, ct = Rs[k], peak[k], cm.cycle_time[k]
        if smooth is not None:
            # Gradients through the selected candidate only (an argmin is piecewise differentiable like a
            # max); re-evaluating it keeps NaN partials of unreachable candidates out of the gradient.
            R_op = Rs[jax.lax.stop_gradient(k)]
            # Unreachable samples have NaN partials inside cycle_metrics; selecting on the *input* blocks them
            # from the gradient when the cycle is not reachable (the where's cotangent is 0 there).
            d_in = jax.tree_util.tree_map(lambda a: jnp.where(cycle_ok, a, jax.lax.stop_gradient(a)),
                                          design.at(R_op))
            cm1 = cycle_metrics(d_in, pb.cycle, pb.limits)
            pk, ct = jnp.max(cm1.peak_torque), cm1.cycle_time
        op = design.at(jnp.where(cycle_ok, R_op, Rs[0]))
        out["peak_torque"] = jnp.where(cycle_ok, pk, jnp.nan)
        out["cycle_time"] = jnp.where(cycle_ok, ct, jnp.nan)
        out["R_operating"] = jnp.where(cycle_ok, R_op, jnp.nan)
    else:
        cm = cycle_metrics(design, pb.cycle, pb.limits)
        cycle_ok = cm.reachable & jnp.all(jnp.isfinite(cm.peak_torque))
        op = design
        out["peak_torque"] = jnp.where(cycle_ok, jnp.max(cm.peak_torque), jnp.nan)
        out["cycle_time"] = jnp.where(cycle_ok, cm.cycle_time, jnp.nan)
        out["R_operating"] = jnp.where(cycle_ok, design.base_radius, jnp.nan)
    if "peak_speed" in need:
        out["peak_speed"] = _ee_speed(op, tpts, pb.motor_speed)
    # 1e-9: the coverage is a mean of 0/1 flags, exact only up to rounding
    violation = jnp.maximum(pb.coverage_min - out["task_coverage"] - 1e-9, 0.0) + jnp.where(cycle_ok, 0.0, 1.0)
    if pb.max_arm_sum is not None:  # size budget: L1 + L2 <= max_arm_sum (relative excess)
        violation = violation + jnp.maximum((robot0.upper_arm + robot0.forearm) / pb.max_arm_sum - 1.0 - 1e-9, 0.0)
    out["violation"] = violation
    out["feasible"] = violation <= 0.0
    return out


def fitness_from_metrics(pb: Problem, m: Mapping[str, jax.Array]) -> jax.Array:
    """Scalar fitness (minimised) of one design's metrics; see the module docstring."""
    if pb.baseline is None:
        raise ObjectiveError("Problem.baseline is not set: call problem.with_baseline(metrics of the baseline)")
    f = 0.0
    for name, wgt in pb.weights.items():
        ref = pb.baseline[name]
        if not (math.isfinite(ref) and ref != 0.0):
            raise ObjectiveError(f"baseline {name} = {ref!r} cannot normalise the objective; drop its weight")
        f = f + wgt * SENSE[name] * m[name] / abs(ref)
    f = jnp.where(jnp.isfinite(f), f, INFEASIBLE_OFFSET / 2)  # a NaN metric only on infeasible designs
    f = jnp.clip(f, -INFEASIBLE_OFFSET / 2, INFEASIBLE_OFFSET / 2)
    v = m["violation"]
    if pb.handling == "feasibility_first":
        return jnp.where(v > 0.0, INFEASIBLE_OFFSET + v, f)
    return f + pb.penalty * v


def evaluate_population(pb: Problem, space, genes: jax.Array, needed: Optional[Sequence[str]] = None, *,
                        screen: bool = True):
    """Metrics of a population of genes (P, d) -> {name: (P,)}; decodes with the design space.

    ``screen=True`` (default), for a reconfigurable population: the volume's reachability comes from
    :func:`reach_cover` and, when the task index terms (``task_index_mean``/``task_index_min``) are not
    needed, the task coverage from :func:`task_cover`, each for the whole population at once (the same flags
    as the per-design sweeps with a fraction of their evaluations; the task index terms are then absent from
    the result). ``False``: every design runs the sweeps of :func:`evaluate_design`.
    """
    need = set(METRICS if needed is None else needed) | {"task_coverage"}
    designs = jax.vmap(space.decode)(genes)
    if not (screen and isinstance(designs, ReconfigurableDelta)):
        return jax.vmap(lambda d: evaluate_design(pb, d, needed))(designs)
    reach = covered = None
    if "volume" in need:
        reach = reach_cover(designs, pb.ws_points).reachable
    if not need & {"task_index_mean", "task_index_min"}:
        covered = task_cover(pb, designs).covered
    return jax.vmap(lambda d, c, r: _evaluate(pb, d, needed, None, c, r))(designs, covered, reach)


def make_fitness(pb: Problem, space, *, screen: bool = True):
    """``genes (P, d) -> (fitness (P,), aux)`` for :func:`deltajax.optimize.run_ga` (jit-able, vmapped).

    ``aux`` holds the needed metrics, ``violation`` and ``feasible`` of each design. ``screen``: see
    :func:`evaluate_population` (the fitness is the same either way; ``False`` is the exact per-design sweep).
    """
    needed = tuple(sorted(pb.needed | {"peak_torque"}))

    def fitness(genes):
        m = evaluate_population(pb, space, genes, needed, screen=screen)
        fit = jax.vmap(lambda mm: fitness_from_metrics(pb, mm))(m)
        return fit, m

    return fitness
