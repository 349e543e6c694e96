"""Worst cases found, not sampled: the regular workspace by rays, the worst points of the task cylinder and the
cycle, with a convergence check at doubled density, and every constraint's margin in units.

* :func:`ray_cylinders` / :func:`ray_cylinder`: the regular workspace (largest axis-centred cylinder with a given
  H/D inside a good set) from *rays*: a ray (phi, z) of the 60 deg wedge (the Delta's three-fold + mirror
  symmetry) gives the first bad radius rho*(phi, z) (dense samples along the ray, then the first bad interval
  searched again, ``n_levels`` times: a bad island between the old grid's rings, e.g. where a forearm passes
  through the base plate, is found, not skipped). The profile rho(z) = min over phi of rho* is refined in passes
  of ``n_z`` x ``n_phi`` rays each, every pass placed where the previous one left the answer uncertain: (0) a
  coarse grid over the whole z range; (1) a grid of levels zoomed onto the cylinder found so far; (2, 3) the
  same levels with the phi rays zoomed twice onto each level's smallest radius (a dip between two phi rays is
  found, not interpolated); (4, 5) the levels next to the cylinder's two ends, zoomed twice onto the end
  brackets (where the height binds the ends set the volume); (6) a final check of the winning cylinder: rays at
  phi midway between the grid's, at ``n_z`` levels from its top disc to its bottom disc, and the diameter shrunk
  to twice the smallest radius found there. Between passes the cylinder is the largest one over the profile,
  counting every profile sample that its span touches plus the nearest sample beyond each end (so the answer
  never leans on an unsampled gap). All passes run in one loop with one call of the good test: one traced copy
  per compiled program, and the searches of several good sets (e.g. "any of the design's R samples" and "the
  operating R") share it.
* :func:`worst_in_cylinder`: the minimum of a scalar field over a task cylinder: dense samples, then a
  coordinate-wise golden section in (rho, phi, z) from the worst samples.
* :func:`cycle_path`: the problem's cycle path at any normalised time (:func:`deltajax.trajectory.adept_path`).
* :func:`certify_design`: one design on one problem: the regular workspace (rays), the task cylinder's worst index,
  joint margin and clearance, the cycle's worst joint margin and clearance and the motors' peak utilisation (dense
  samples in t, then a golden section in t from the worst samples, :mod:`deltajax.optimize.cycle_worst`; the cycle
  time is the fastest at which the refined peak holds) and RMS utilisation (an integral: the dense samples'
  trapezoidal rule, checked by the doubling), at a density and at twice it, doubled again (at most
  :data:`MAX_EXTRA_DOUBLINGS` more times) while a figure moved more than its tolerance; the figures are those of the
  densest evaluation, with the change the last doubling made (``*_change``) against the stated tolerances
  (:data:`TOLERANCES`) and the doublings made (``doublings``).
* :func:`design_margins`: every constraint's margin in units from a design's metrics (numpy, any batch shape).
* :func:`grid_cylinder_bounds`: an independent brute-force check on a dense point grid (no rays).
* :func:`overlay`: a results file's ``verify`` group with the certified figures in place (what the summary, the
  plots, the report and the tolerance stage read).

Pure JAX, float64, vmappable (the good test is :func:`deltajax.constraints.good_point`).
"""

from __future__ import annotations

import math
from typing import Any, Callable, Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ..trajectory import adept_cycle, adept_path
from ..tracing import shared_program
from .designer import evaluate_designer, FEASIBILITY_TOL


__all__ = ["TOLERANCES", "RAY_DENSITY", "RAY_PASSES", "RayDensity", "ray_cylinders", "ray_cylinder",
           "worst_in_cylinder", "certify_design", "certified_program", "design_margins", "MARGIN_UNITS", "cycle_at",
           "grid_cylinder_bounds", "CERTIFIED_METRICS", "CYCLE_METRICS", "feasible_certified", "overlay",
           "MAX_EXTRA_DOUBLINGS", "SHARED_DOUBLINGS", "cycle_path", "describe", "REGULAR_FIGURES", "certify_by_rule"]

#: Stated accuracy of a certified figure: doubling the density moves it by no more than this.
#: regular_volume: relative; joint margin: deg; clearance: m; utilisations: ratio (relative to 1).
TOLERANCES = {"regular_volume": 0.005, "joint_margin_deg": 0.05, "interference_margin": 1e-4,
              "rms_utilisation": 1e-4, "peak_utilisation": 1e-4, "task_index_min": 1e-3}

#: Doublings of the density beyond the first that :func:`certify_design` makes while a figure moved more than its
#: tolerance.
MAX_EXTRA_DOUBLINGS = 2

#: Doublings whose task-cylinder and cycle searches :func:`certify_design` runs in the first density's program (one
#: program sized for the last of them): a second doubling then reads and compiles no program of its own (~2 s read,
#: ~70 CPU-s compiled on the default problem) for ~0.1 CPU-s more per evaluation below that size.
SHARED_DOUBLINGS = 2

from .cycle_worst import cycle_worst  # noqa: E402
from .good import design_good_test  # noqa: E402
from .rays import (RAY_DENSITY, RAY_PASSES, RayDensity, ray_cylinder, ray_cylinders,  # noqa: F401
                   worst_in_cylinder)


def cycle_at(pb, n_samples: int):
    """The problem's cycle resampled with ``n_samples`` (same path, law and duration)."""
    cyc = pb.settings["cycle"]
    return adept_cycle(pb.settings["cycle_centre"], duration=float(cyc["duration"]), n_samples=int(n_samples),
                       law=str(cyc["law"]))


def cycle_path(pb) -> Callable:
    """The problem's cycle path at any normalised times: ``u (k,) -> (x, x', x'')`` (the path :func:`cycle_at`
    samples, :func:`deltajax.trajectory.adept_path`)."""
    centre, law = pb.settings["cycle_centre"], str(pb.settings["cycle"]["law"])
    return lambda u: adept_path(u, centre, law=law)


#: The regular-workspace figures of :func:`certify_design` (the ray searches; the rest is the task and the cycle).
REGULAR_FIGURES = ("regular_volume", "regular_diameter", "regular_height", "regular_z_top", "regular_volume_fixed",
                   "regular_diameter_fixed")


def _regular_once(pb, design, R_op, density: RayDensity) -> dict:
    """The regular-workspace figures (:data:`REGULAR_FIGURES`) at one ray density (traced; ``R_op``: the operating
    R): the ray searches of "any of the design's R samples" and, for a reconfigurable design, the operating R."""
    gt = design_good_test(design, pb.good, pb.links.plate_overhang)
    Rs, dt = gt.R_samples(), (design.robot if gt.reconfigurable else design).upper_arm.dtype
    reg_s = pb.settings["regular"]
    sets = [Rs, jnp.asarray(R_op, dt)[None]] if gt.reconfigurable else [Rs]
    cyl = ray_cylinders(gt.good, sets, float(reg_s["r_max"]), float(reg_s["z_min"]),
                        float(reg_s["z_max"]), pb.hd_ratio, density, dt, possible_R=gt.possible)
    return {"regular_volume": cyl[0].volume, "regular_diameter": cyl[0].diameter, "regular_height": cyl[0].height,
            "regular_z_top": cyl[0].z_top, "regular_volume_fixed": cyl[-1].volume,
            "regular_diameter_fixed": cyl[-1].diameter}


def _task_cycle_once(pb, design, R_op, task_shape: tuple, cycle_shape: int, counts) -> dict:
    """The task cylinder's and the cycle's certified figures (traced; ``R_op``: the operating R) at the sample
    counts ``counts`` (4,) (task rings, angles, levels; cycle samples), each at most its array size
    (``task_shape``, ``cycle_shape``): one compiled program serves every density up to those sizes."""
    gt = design_good_test(design, pb.good, pb.links.plate_overhang)
    robot0 = design.robot if gt.reconfigurable else design
    at, chk, dt = gt.at, gt.point, robot0.upper_arm.dtype
    t = pb.settings["task"]
    worst, _ = worst_in_cylinder(lambda p: jnp.stack([(c := chk(R_op, p)).index, c.joint_margin,
                                                      c.interference_margin]),
                                 float(t["diameter"]), float(t["height"]), float(t["z_top"]), *task_shape,
                                 counts=counts[:3])
    idx, jm_t, im_t = worst[0], worst[1], worst[2]
    cw = cycle_worst(at(R_op), cycle_path(pb), int(cycle_shape), float(pb.settings["cycle"]["duration"]),
                     lambda p: ((c := chk(R_op, p.astype(dt))).joint_margin, c.interference_margin), pb.motor,
                     robot0.mass.gear_ratio, dwell=pb.dwell, payload_mass=pb.payload, n_valid=counts[3])
    rate = cw.rate
    return {"task_index_min": idx,
            "joint_margin_deg": jnp.rad2deg(jnp.minimum(jm_t, cw.joint_margin)),
            "interference_margin": jnp.minimum(im_t, cw.interference_margin),
            "picks_per_min": rate.picks_per_min, "cycle_time": rate.cycle_time,
            "peak_utilisation": rate.loads.peak_utilisation, "rms_utilisation": rate.loads.rms_utilisation,
            "speed_utilisation": rate.loads.speed_utilisation}


def _densities(pb, density, task_samples, cycle_samples):
    """The verification's densities (rays, task samples, cycle samples) of ``pb`` where not given."""
    if density is None:
        density = RAY_DENSITY if pb.rw_rays is None else RayDensity(*pb.rw_rays)
    if task_samples is None:
        t = pb.settings["task"]
        task_samples = (int(t["n_r"]) + 1, 2 * int(t["n_phi"]) - 1, int(t["n_z"]) + 2)
    if cycle_samples is None:    # the peak converges as the square of the spacing: 8x the verification's
        cycle_samples = 8 * (int(pb.cycle.n_samples) - 1) + 1
    return RayDensity(*density), tuple(int(n) for n in task_samples), int(cycle_samples)


def certified_program(pb, density: RayDensity, task_samples: tuple, cycle_samples: int, *,
                      rays: bool = True, padded_to: tuple = None) -> Callable:
    """``(design, R_operating) -> {figure: ()}`` at one density: the ray searches (one jitted program per
    density) and the task cylinder's and cycle's searches (one jitted program per array size ``padded_to`` =
    (task samples, cycle samples), default the density's own, that serves every density up to it: the certify
    stage's doublings share one). One program per (content of ``pb``, density or size) in this process
    (:func:`deltajax.tracing.shared_program`), kept across processes: the baseline and the recommendation (and
    any design re-derived later) share each compilation. ``rays=False``: without the ray searches (the
    regular-workspace figures NaN)."""
    task, cycle = tuple(int(n) for n in task_samples), int(cycle_samples)
    shape_t, shape_c = (task, cycle) if padded_to is None else (tuple(int(n) for n in padded_to[0]),
                                                                   int(padded_to[1]))
    if len(task) != 3 or len(shape_t) != 3 or any(not 2 <= n <= m for n, m in zip(task + (cycle,),
                                                                                 shape_t + (shape_c,))):
        raise ValueError(f"sample counts {task + (cycle,)} must be >= 2 and within the program's size "
                         f"{shape_t + (shape_c,)}")
    tkey = ("task_cycle", shape_t, shape_c)
    tc = shared_program("certified", pb, None, tkey, lambda: jax.jit(
        lambda d, R, n: _task_cycle_once(pb, d, R, tkey[1], tkey[2], n)), persist=True)
    counts = np.asarray(task + (cycle,), np.int32)
    if rays:
        rkey = ("rays", tuple(int(n) for n in density))
        rp = shared_program("certified", pb, None, rkey, lambda: jax.jit(
            lambda d, R: _regular_once(pb, d, R, RayDensity(*rkey[1]))), persist=True)

    def run(design, R_operating):
        if rays:
            out = dict(rp(design, R_operating))
        else:
            nan = jnp.asarray(jnp.nan, (design.robot if hasattr(design, "robot") else design).upper_arm.dtype)
            out = {k: nan for k in REGULAR_FIGURES}
        out.update(tc(design, R_operating, counts))
        return out

    return run


def certify_design(pb, design, R_operating=None, *, density=None, task_samples=None,
                   cycle_samples=None, reference: Mapping[str, float] = None,
                   regular_first: Mapping[str, float] = None,
                   max_extra_doublings: int = MAX_EXTRA_DOUBLINGS, regular: bool = True) -> dict:
    """Certified figures of one design (a :class:`deltajax.Delta` or :class:`deltajax.ReconfigurableDelta`) on
    the designer's problem ``pb`` (:class:`deltajax.optimize.designer.DesignerProblem`) at its operating R
    (``R_operating``; None: the one :func:`deltajax.optimize.designer.evaluate_designer` chooses): every figure
    evaluated at a density and at twice it (rays: ``density``, default the problem's ``rw_rays`` or
    :data:`RAY_DENSITY`; task cylinder samples (rings, angles, levels): ``task_samples``, default one ring, angles
    doubled and two levels more than the problem's task grid; cycle samples: ``cycle_samples``, default eight times
    the problem's, then a golden section in t from the worst samples of the joint margin, the clearance and the
    peak torque utilisation (:func:`deltajax.optimize.cycle_worst.cycle_worst`; the RMS torque is an integral,
    for which the dense samples and the doubling are the method). Where a figure moved more than its tolerance
    the density is doubled again, at most ``max_extra_doublings`` more times, until every figure settles.

    Returns the figures of the last (densest) evaluation, ``<name>_first`` the first density's, ``<name>_change``
    the change the last doubling made (relative for the volume, in the figure's units otherwise),
    ``<name>_tolerance``, ``doublings`` (how many times the first density was doubled: 1 when the first doubling
    settled every figure), ``cycle_samples`` (the cycle samples reached) and ``converged`` (every change of the
    last doubling within :data:`TOLERANCES`; False only when even the last allowed doubling moved a figure more) and
    ``regular_certified`` (the regular-workspace figures certified too; see ``regular``).
    The cycle is evaluated at its fastest feasible duration at each density. ``reference``: the figures already
    evaluated at the first density (e.g. by an earlier call): then only the doubled evaluations run.
    ``regular_first``: the regular-workspace figures (:data:`REGULAR_FIGURES`) already found by the same ray search
    at the first density and the same operating R (the verification's, :func:`deltajax.optimize.designer.
    evaluate_designer` on the same problem: its ``rw_rays`` are the first density): then the first evaluation
    runs without the ray searches and takes them from it. ``regular=False`` (with ``regular_first``): the task
    cylinder's and the cycle's figures alone are certified (no ray search at any density; the doublings settle
    those figures) and the regular-workspace figures are ``regular_first``'s, their change NaN; the certify stage
    certifies a design so first and runs its rays only if the rule stays with it. ``regular_certified`` says
    which. Host function (numpy floats); jitted inside: the ray
    searches one program per density, the task cylinder and the cycle one program for the first density and its
    first :data:`SHARED_DOUBLINGS` doublings (each evaluation its own samples in it), one per further doubling."""
    if not (isinstance(max_extra_doublings, int) and max_extra_doublings >= 0):
        raise ValueError(f"max_extra_doublings must be an integer >= 0, got {max_extra_doublings!r}")
    if not regular and regular_first is None:
        raise ValueError("regular=False takes the regular-workspace figures from regular_first, which is missing")
    dt = (design.robot if hasattr(design, "robot") else design).upper_arm.dtype
    if R_operating is None:
        R_operating = jax.jit(lambda d: evaluate_designer(pb, d, regular=False)["R_operating"])(design)
    R_op = jnp.asarray(R_operating, dt)
    d, t, c = _densities(pb, density, task_samples, cycle_samples)
    # one task-and-cycle program for the first density and its first SHARED_DOUBLINGS doublings (within the allowed
    # ones): sized for the last of them, each evaluation runs its own counts in it
    shared = min(1 + max_extra_doublings, SHARED_DOUBLINGS)
    size = (tuple((n - 1) * 2 ** shared + 1 for n in t), (c - 1) * 2 ** shared + 1)
    if reference is not None:
        a = dict(reference)
    elif regular_first is not None:
        if density is not None or pb.rw_rays is None:
            raise ValueError("regular_first: the first density must be the problem's own rays (pb.rw_rays), as "
                             "the verification searched them")
        missing = [k for k in REGULAR_FIGURES if k not in regular_first]
        if missing:
            raise ValueError(f"regular_first lacks {', '.join(missing)}")
        a = certified_program(pb, d, t, c, rays=False, padded_to=size)(design, R_op)
        a = {k: float(v) for k, v in a.items()}
        a.update({k: float(regular_first[k]) for k in REGULAR_FIGURES})
    else:
        a = {k: float(v) for k, v in certified_program(pb, d, t, c, padded_to=size)(design, R_op).items()}
    first = {k: float(a[k]) for k in TOLERANCES}
    settled = {k: tol for k, tol in TOLERANCES.items() if regular or k not in REGULAR_FIGURES}   # doubled here
    for doublings in range(1, 2 + max_extra_doublings):
        d, t, c = d.doubled(), tuple(2 * n - 1 for n in t), 2 * c - 1
        b = certified_program(pb, d, t, c, rays=regular, padded_to=size if doublings <= shared else None)(
            design, R_op)
        b = {k: float(v) for k, v in b.items()}
        if not regular:
            b.update({k: a[k] for k in REGULAR_FIGURES})
        change = {k: _change(k, float(a[k]), b[k]) if k in settled else math.nan for k in TOLERANCES}
        ok = all(change[k] <= tol for k, tol in settled.items())
        if ok or all(change[k] <= tol or (math.isnan(a[k]) and math.isnan(b[k])) for k, tol in settled.items()):
            break           # NaN at both densities (e.g. unreachable): a denser search cannot settle it
        a = b
    out = dict(b)
    out.update({f"{k}_first": x for k, x in first.items()})
    for k, tol in TOLERANCES.items():
        out[f"{k}_change"] = change[k]
        out[f"{k}_tolerance"] = tol
    out["converged"] = ok
    out["regular_certified"] = bool(regular)
    out["doublings"] = doublings
    out["cycle_samples"] = c
    out["R_operating"] = float(R_op)
    return out


def certify_by_rule(choose: Callable[[], int], certify: Callable[[int, bool], None], *, max_full: int = 4
                    ) -> tuple[int, dict]:
    """The certify stage's loop: the baseline (row 0) certified with its regular workspace (its certified volume
    sets the floor rule's floor), then the rule's answer ``choose()`` (a row; -1: none; the figures certified so
    far in place) certified until it is a fully certified design: a design the rule picks is first certified
    without its ray searches (``certify(i, False)``: its task and cycle figures, ~0.1 CPU-s, which often move the
    rule on, e.g. a lower certified picks/min), and with them (``certify(i, True)``: ~4-20 CPU-s) only when the
    rule still picks it. At most ``max_full`` designs besides the baseline are certified with their regular
    workspace; the last of them is the answer even if the rule would move again. Returns (the answer, {row:
    whether its regular workspace is certified}) for every design certified."""
    done = {}

    def run(i, regular):
        certify(i, regular)
        done[i] = regular

    run(0, True)
    full = 0
    while True:
        rec = choose()
        if rec < 0 or done.get(rec):
            return rec, done
        if rec not in done:
            run(rec, False)          # the cheap figures first: they may move the rule on
            continue
        run(rec, True)
        full += 1
        if full >= max_full:
            return rec, done


def describe(c: Mapping[str, Any]) -> str:
    """One line of a :func:`certify_design` result: each figure with the change the last doubling made and its
    tolerance, the density reached, and whether every figure settled."""
    reg = c.get("regular_certified", True)
    return (", ".join(f"{k} {c[k]:.5g} (doubling moved it {c[k + '_change']:.2g}, tolerance {c[k + '_tolerance']:g})"
                      if reg or k not in REGULAR_FIGURES else f"{k} {c[k]:.5g} (the verification's, not certified)"
                      for k in TOLERANCES) + f"; density doubled {c['doublings']}x (cycle {c['cycle_samples']} samples)"
            + ("" if c["converged"] else "; NOT within every tolerance"))


def _change(k: str, x: float, y: float) -> float:
    """The change doubling made to figure ``k`` (relative for the regular volume); NaN: not within tolerance."""
    return abs(y / x - 1.0) if k == "regular_volume" and x > 0 else abs(y - x)


# -- margins ---------------------------------------------------------------------------------------------------

#: Units of :func:`design_margins`' entries.
MARGIN_UNITS = {"task_index_margin": "1", "joint_margin_deg": "deg", "interference_clearance_mm": "mm",
                "peak_headroom": "1", "rms_headroom": "1", "speed_headroom": "1", "picks_over_min": "1/min",
                "size_budget_margin_mm": "mm", "regular_volume_over_floor": "m^3"}


def design_margins(m: Mapping[str, np.ndarray], *, threshold: float, min_picks: float, max_arm_sum,
                   volume_floor=None) -> dict:
    """Every constraint's margin in units (positive: met by that much) from metrics ``m`` (any batch shape):
    task index margin = worst index - threshold; joint margin (deg, the smaller of both joints' cone margins
    over the task and the cycle); interference clearance (mm, beyond the required clearance); peak, RMS and
    speed headroom 1 - utilisation; picks/min over the required rate; size budget margin (mm, max L1 + L2 -
    (L1 + L2); NaN without a budget); regular volume over the floor rule's floor (m^3; NaN without a floor: the
    rule's threshold, not a constraint)."""
    f = lambda k: np.asarray(m[k], float)  # noqa: E731
    return {"task_index_margin": f("task_index_min") - threshold,
            "joint_margin_deg": f("joint_margin_deg"),
            "interference_clearance_mm": 1e3 * f("interference_margin"),
            "peak_headroom": 1.0 - f("peak_utilisation"), "rms_headroom": 1.0 - f("rms_utilisation"),
            "speed_headroom": 1.0 - f("speed_utilisation"), "picks_over_min": f("picks_per_min") - min_picks,
            "size_budget_margin_mm": (1e3 * (max_arm_sum - f("arm_sum")) if max_arm_sum is not None
                                      else np.full_like(f("arm_sum"), np.nan)),
            "regular_volume_over_floor": (f("regular_volume") - volume_floor if volume_floor is not None
                                          else np.full_like(f("regular_volume"), np.nan))}


# -- an independent check: a dense point grid and every window of levels ---------------------------------------------

def grid_cylinder_bounds(good: np.ndarray, r: np.ndarray, z: np.ndarray, hd_ratio: float) -> dict:
    """Brute-force bounds on the regular workspace from good flags on a dense polar grid (a method independent
    of :func:`ray_cylinders`: no rays, no bisection, no local search): ``good`` (n_z, n_r, n_phi) on rings ``r``
    (r[0] = 0), levels ``z`` (uniform) and angles over the wedge. Per level, the last good ring before the first
    bad one (lower) and the first bad ring (upper, r_max + dr when none); every window of levels [a, b] scanned:
    lower volume with height z_b - z_a and the lower radii, upper volume with height z_(b+1) - z_(a-1) and the
    upper radii, and a mid estimate (midpoints). Returns volumes (m^3) ``lower``, ``mid``, ``upper``."""
    good = np.asarray(good, bool)
    nz, nr, _ = good.shape
    dr, dz = r[1] - r[0], z[1] - z[0]
    prefix = np.cumprod(good, axis=1).astype(bool)                     # rings 0..j all good, per angle
    n_good = prefix.sum(axis=1)                                         # (nz, nphi) good rings from the axis
    last = np.where(n_good > 0, r[np.maximum(n_good - 1, 0)], -1.0)     # radius of the last good ring
    first_bad = np.where(n_good < nr, r[np.minimum(n_good, nr - 1)], r[-1] + dr)
    lo_k = np.min(last, axis=1)
    hi_k = np.where(np.min(n_good, axis=1) > 0, np.min(first_bad, axis=1), 0.0)
    out = {}
    for name, rad, extra in (("lower", lo_k, 0.0), ("mid", 0.5 * (lo_k + np.maximum(hi_k, 0.0)), 1.0),
                             ("upper", hi_k, 2.0)):
        best = 0.0
        for a in range(nz):
            mm = np.inf
            for b in range(a, nz):
                mm = min(mm, rad[b])
                if mm <= 0:
                    break
                H = z[b] - z[a] + extra * dz
                D = min(2.0 * mm, H / hd_ratio)
                best = max(best, math.pi / 4.0 * D * D * hd_ratio * D)
        out[name] = best
    return out


# -- the certified figures in place of the verified ones ---------------------------------------------------------------

#: Certified metrics of the cycle run at the operating R: with ``experiment.reconfig.mode=path`` (R(t) along the
#: cycle) they certify the fixed-R variant (``<metric>_fixed``), not the path's figures.
CYCLE_METRICS = ("picks_per_min", "cycle_time", "peak_utilisation", "rms_utilisation", "speed_utilisation",
                 "joint_margin_deg", "interference_margin")

#: Metrics :func:`certify_design` returns that replace the verification's values of a certified design.
CERTIFIED_METRICS = REGULAR_FIGURES + ("task_index_min", "joint_margin_deg", "interference_margin", "picks_per_min",
                                       "cycle_time", "peak_utilisation", "rms_utilisation", "speed_utilisation")


def feasible_certified(m: Mapping[str, np.ndarray], pb) -> np.ndarray:
    """Every enabled constraint met by the metrics ``m`` (certified figures: the worst index instead of the good
    fraction; NaN: not met), up to :data:`deltajax.optimize.designer.FEASIBILITY_TOL`."""
    ok = np.ones(np.shape(m["picks_per_min"]), bool)
    en = set(pb.enabled)
    with np.errstate(invalid="ignore"):
        if "task_in_good_workspace" in en:
            ok &= (m["task_index_min"] >= pb.good.threshold - FEASIBILITY_TOL)
        if "task_in_good_workspace" in en or "passive_joints" in en:
            ok &= m["joint_margin_deg"] >= -FEASIBILITY_TOL
        if "task_in_good_workspace" in en or "interference" in en:
            ok &= m["interference_margin"] >= -FEASIBILITY_TOL
        ok &= np.isfinite(m["picks_per_min"]) & (m["picks_per_min"] > 0)
        ok &= m["picks_per_min"] >= pb.min_picks - FEASIBILITY_TOL
        if pb.max_arm_sum is not None:
            ok &= m["arm_sum"] <= pb.max_arm_sum * (1.0 + FEASIBILITY_TOL)
    return ok


def overlay(data: Mapping) -> dict:
    """The ``verify`` group of a loaded results file with the certified designs' figures (group ``certify``) in
    place of the verified ones, ``feasible`` and ``front`` as certified, ``F`` recomputed (normalised by the
    certified baseline) and ``margins`` (``{name: ((n,), units)}``); the ``verify`` group itself when there is no
    ``certify`` group. The recommendation (attribute ``recommended``) is the one the certify stage wrote into
    ``verify`` (and a robust tolerance stage after it)."""
    V = data.get("verify")
    Cg = data.get("certify")
    if V is None or not Cg or "row" not in Cg:
        return V
    out = dict(V)
    rows = np.asarray(Cg["row"], int).reshape(-1)
    path = Cg.get("attrs", {}).get("cycle_variant") == "fixed_R"     # mode=path: the cycle figures are the fixed R's
    for k in CERTIFIED_METRICS + ("feasible",):
        if path and k in CYCLE_METRICS and f"{k}_fixed" in V:
            b = np.array(V[f"{k}_fixed"], dtype=float, copy=True).reshape(-1)
            b[rows] = np.asarray(Cg[k], float).reshape(-1)
            out[f"{k}_fixed"] = b
            continue
        if k in V and k in Cg:
            a = np.array(V[k], dtype=float, copy=True).reshape(-1)
            kf = f"{k}_fixed"       # the fixed-R variant's cycle figures: the same where R does not move (per_task)
            if kf in V and kf not in CERTIFIED_METRICS and np.array_equal(
                    np.asarray(V[kf], float).reshape(-1)[rows], a[rows], equal_nan=True):
                b = np.array(V[kf], dtype=float, copy=True).reshape(-1)
                b[rows] = np.asarray(Cg[k], float).reshape(-1)
                out[kf] = b
            a[rows] = np.asarray(Cg[k], float).reshape(-1)
            out[k] = a
    if "feasible" in Cg:
        out["feasible"] = out["feasible"].astype(np.uint8)
    if "front" in Cg:
        out["front"] = np.asarray(Cg["front"], int)
    if "F" in Cg:
        out["F"] = np.asarray(Cg["F"], float)
    out["margins"] = {k: (np.asarray(Cg[f"margin_{k}"], float).reshape(-1), u) for k, u in MARGIN_UNITS.items()
                      if f"margin_{k}" in Cg}
    return out
