"""Tolerance analysis: how likely a built robot holds every constraint of the designer's problem.

A seeded Monte Carlo over stated manufacturing and model tolerances (:class:`Tolerances`). Each sample perturbs the
design and the models, then evaluates every constraint of the designer's problem
(:func:`deltajax.optimize.designer.evaluate_designer`, ``regular=False``: the regular workspace is an objective, not
a constraint) exactly as the nominal design was judged; the samples are vmapped and evaluated in chunks (bounded
memory). :func:`analyse` returns, per design, the probability that each constraint and that every constraint holds,
the picks/min distribution and the constraint values' percentiles.

What is perturbed (``distribution="uniform"``: each deviation uniform in [-tol, +tol], every part inside its
tolerance; ``"normal"``: Gaussian with the tolerance as 3 sigma, not truncated), one deviation per quantity:

* **Lengths** (``length``, m): upper arm L1, forearm L2, platform radius r, base radius R (a fixed design) or the
  reconfiguration range's ends R_min and R_max (a reconfigurable one; each end its own deviation, so the R samples
  and the operating-R candidates between them move with them; the base plate, R_max + overhang, follows R_max). The size
  budget (L1 + L2 <= max_arm_sum) limits the drawing, so it is judged on the nominal lengths, also by the rule that
  chooses a sample's operating R.
* **Joint offsets** (``joint_offset_deg``, deg): the actuated joints' zero (the actuated-angle limits theta_min
  and theta_max shift by it), the elbow sockets' neutral axis and the platform sockets' neutral axis (each shifted
  in the chain plane; the passive joints' cone is centred on that axis, so the cone limit moves with it).
* **Masses** (``mass``, relative): the mass model's upper arm, elbow, forearm, platform and carriage masses, and the
  payload (zero masses stay zero).
* **Motor constants** (``motor``, relative): every :class:`deltajax.constraints.Motor` field (peak and rated
  torque, maximum and corner speed, rotor inertia, gearbox efficiency; efficiency capped at 1 and the corner speed
  at the maximum speed).

Simplifications, because the model is symmetric (one geometry for all three chains): each deviation is shared by
the three arms (the arms are perturbed alike, not independently), and an offset acts in the chain plane only. The
operating R of a reconfigurable design is chosen per sample by the problem's own rule (the built robot is set up
for the task), and the picks/min is the sample's fastest feasible cycle: a slower built robot still runs the
cycle, only slower, so a tolerance shows in the picks/min distribution (and ``p_reaches_nominal_picks``) rather
than in the cycle-rate constraint unless ``min_picks_per_min`` is set. A sample first tests the rule's first
:data:`FIRST_CANDIDATES` candidates (most picks per minute first) and, where none of them holds, all of them: the
rule's choice either way, with a fraction of the good tests where a fast candidate holds.

``operating_R="nominal"`` holds a reconfigurable design at its nominal operating R instead (moved by the R
actuator's deviation, that of R_min): the stricter question "does the built robot hold at the R its datasheet
gives", where the default lets it re-choose its R among the problem's candidates.

A NaN (unreachable) margin counts as a violated constraint (the designer's rule), and a NaN picks/min never becomes
a number: it ranks below every number in the percentiles (a percentile that falls on it is NaN), the mean is over
the finite samples, and the count is reported (``picks_nan``).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, Mapping, Optional, Sequence

import numpy as np
import equinox as eqx
import jax.numpy as jnp
import jax

from .geometry import ReconfigurableDelta
from .optimize.designer import CONSTRAINT_NAMES, evaluate_designer, FEASIBILITY_TOL

__all__ = ["Tolerances", "ToleranceError", "analyse", "perturb", "deviations",
           "describe", "design_summary", "select", "PER_DESIGN", "PARAMETERS", "PERCENTILES", "CONSTRAINT_METRICS", "DISTRIBUTIONS",
           "DEFAULT_SAMPLES", "FIRST_CANDIDATES"]

DEFAULT_SAMPLES = 1000
DISTRIBUTIONS = ("uniform", "normal")
#: percentiles reported (with the minimum and the mean)
PERCENTILES = (1.0, 5.0, 50.0, 95.0, 99.0)

#: The perturbed quantities in sample-column order: (name, tolerance group, unit of the deviation). Length
#: deviations in m, joint offsets in deg, the others relative (1).
PARAMETERS = (
    ("upper_arm", "length", "m"), ("forearm", "length", "m"), ("platform_radius", "length", "m"),
    ("base_radius_or_R_min", "length", "m"), ("R_max", "length", "m"),
    ("actuated_zero", "joint_offset_deg", "deg"), ("elbow_neutral", "joint_offset_deg", "deg"),
    ("platform_neutral", "joint_offset_deg", "deg"),
    ("upper_arm_mass", "mass", "1"), ("elbow_mass", "mass", "1"), ("forearm_mass", "mass", "1"),
    ("platform_mass", "mass", "1"), ("carriage_mass", "mass", "1"), ("payload", "mass", "1"),
    ("peak_torque", "motor", "1"), ("rated_torque", "motor", "1"), ("max_speed", "motor", "1"),
    ("corner_speed", "motor", "1"), ("rotor_inertia", "motor", "1"), ("efficiency", "motor", "1"),
)
_COL = {n: i for i, (n, _, _) in enumerate(PARAMETERS)}
_MASS_FIELDS = ("upper_arm_mass", "elbow_mass", "forearm_mass", "platform_mass", "carriage_mass")
_MOTOR_FIELDS = ("peak_torque", "rated_torque", "max_speed", "corner_speed", "rotor_inertia", "efficiency")

#: The metric behind each constraint of :data:`deltajax.optimize.designer.CONSTRAINT_NAMES` (in units), with the
#: sense of "better" (+1: higher is better) used to rank NaN as the worst value.
CONSTRAINT_METRICS = {"task_in_good_workspace": ("task_good_fraction", 1), "passive_joints": ("joint_margin_deg", 1),
                      "interference": ("interference_margin", 1), "cycle_rate": ("picks_per_min", 1),
                      "size_budget": ("arm_sum", -1)}
_KEPT = ("g", "picks_per_min", "task_good_fraction", "joint_margin_deg", "interference_margin", "arm_sum",
         "rms_utilisation", "peak_utilisation", "R_operating")


class ToleranceError(ValueError):
    """Invalid tolerance settings; the message names the field and the value."""


@dataclasses.dataclass(frozen=True)
class Tolerances:
    """Manufacturing and model tolerances (see the module docstring for what each one perturbs).

    Attributes:
        length: +- tolerance of L1, L2, r and R (or R_min and R_max), m.
        joint_offset_deg: +- offset of the actuated joints' zero and of the passive sockets' neutral axes, deg.
        mass: +- relative tolerance of the masses and the payload (0.05: 5 %).
        motor: +- relative tolerance of the motor constants (0.05: 5 %).
        distribution: ``"uniform"`` (in +- tolerance) or ``"normal"`` (tolerance = 3 sigma).
    """

    length: float = 0.2e-3
    joint_offset_deg: float = 0.1
    mass: float = 0.05
    motor: float = 0.05
    distribution: str = "uniform"

    def __post_init__(self):
        if self.distribution not in DISTRIBUTIONS:
            raise ToleranceError(f"Tolerances.distribution must be one of {', '.join(DISTRIBUTIONS)}, got "
                                 f"{self.distribution!r}")
        for name, hi in (("length", 0.01), ("joint_offset_deg", 5.0), ("mass", 0.5), ("motor", 0.5)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not 0 <= v <= hi:
                raise ToleranceError(f"Tolerances.{name} must be a number in [0, {hi:g}], got {v!r}")

    def scale(self) -> np.ndarray:
        """The tolerance of each column of :data:`PARAMETERS` (its unit)."""
        return np.asarray([float(getattr(self, g)) for _, g, _ in PARAMETERS])

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def deviations(tol: Tolerances, samples: int, seed: int) -> np.ndarray:
    """(samples, len(PARAMETERS)) deviations in their units (numpy's PCG64 seeded with ``seed``; the same seed
    gives the same samples whatever the chunking)."""
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 1:
        raise ToleranceError(f"samples must be an integer >= 1, got {samples!r}")
    rng = np.random.default_rng(int(seed))
    k = len(PARAMETERS)
    z = rng.uniform(-1.0, 1.0, (samples, k)) if tol.distribution == "uniform" else rng.normal(0.0, 1.0 / 3.0,
                                                                                               (samples, k))
    return z * tol.scale()[None, :]


def perturb(pb, design, dev):
    """(problem, design) of one sample: ``dev`` (len(PARAMETERS),) deviations applied (traced values are fine).

    Zero deviations give back the same numbers exactly (every change is ``x + 0`` or ``x * (1 + 0)``).
    """
    recon = isinstance(design, ReconfigurableDelta)
    robot = design.robot if recon else design
    d = {n: dev[i] for n, i in _COL.items()}
    off = jnp.deg2rad(d["actuated_zero"])
    robot = eqx.tree_at(lambda r: (r.upper_arm, r.forearm, r.platform_radius, r.theta_min, r.theta_max),
                        robot, (robot.upper_arm + d["upper_arm"], robot.forearm + d["forearm"],
                                robot.platform_radius + d["platform_radius"], robot.theta_min + off,
                                robot.theta_max + off))
    if robot.mass is not None:
        mass = robot.mass
        robot = eqx.tree_at(lambda r: tuple(getattr(r.mass, f) for f in _MASS_FIELDS), robot,
                            tuple(getattr(mass, f) * (1.0 + d[f]) for f in _MASS_FIELDS))
    if recon:
        # R_min and R_max each move by their own deviation: R_step takes the difference (exact at zero)
        d_lo, d_hi = d["base_radius_or_R_min"], d["R_max"]
        design = eqx.tree_at(lambda r: (r.robot, r.R_min, r.R_step), design,
                             (robot, design.R_min + d_lo, design.R_step + (d_hi - d_lo) / max(design.n_R - 1, 1)))
    else:
        design = eqx.tree_at(lambda r: r.base_radius, robot, robot.base_radius + d["base_radius_or_R_min"])
    m = pb.motor
    vals = {f: getattr(m, f) * (1.0 + d[f]) for f in _MOTOR_FIELDS}
    vals["efficiency"] = jnp.minimum(vals["efficiency"], 1.0)
    vals["corner_speed"] = jnp.minimum(vals["corner_speed"], vals["max_speed"])
    motor = eqx.tree_at(lambda x: tuple(getattr(x, f) for f in _MOTOR_FIELDS), m,
                        tuple(vals[f] for f in _MOTOR_FIELDS))
    joints = eqx.tree_at(lambda j: (j.elbow_neutral, j.platform_neutral), pb.joints,
                         (pb.joints.elbow_neutral + jnp.deg2rad(d["elbow_neutral"]),
                          pb.joints.platform_neutral + jnp.deg2rad(d["platform_neutral"])))
    good = eqx.tree_at(lambda g: g.joints, pb.good, joints)
    pb = dataclasses.replace(pb, motor=motor, joints=joints, good=good, payload=pb.payload * (1.0 + d["payload"]))
    return pb, design


def _frozen(pb, design, r_op, d_lo):
    """(problem, design) whose only operating-R candidate is ``r_op`` (the nominal operating R) moved by the
    R actuator's deviation ``d_lo``; the R range's top (hence the base plate) stays the sample's."""
    top = design.R_max
    lo = r_op + d_lo
    design = eqx.tree_at(lambda r: (r.R_min, r.R_step), design, (lo, (top - lo) / max(design.n_R - 1, 1)))
    return dataclasses.replace(pb, n_R_operating=1), design


#: operating-R candidates a sample tests first, in the order of the rule that chooses among them (most picks per
#: minute first): a sample with no feasible one among them is evaluated again with every candidate. In 48 probed
#: samples of the default run's baseline the first feasible candidate was the second in that order
FIRST_CANDIDATES = 2


def _program(pb, space, frozen: bool = False, candidates: int = 0):
    """``(genes (B, d), dev (B, K), r_op (B,)) -> {metric: (B, ...)}``: one sample per row, jitted, shared by
    content; ``frozen``: the operating R held at ``r_op`` (a reconfigurable design); ``candidates``: only the
    rule's first operating-R candidates tested (``resolved``: a feasible one among them; evaluate_designer)."""
    from .optimize.programs import shared_program

    def build():
        def one(genes, dev, r_op):
            nominal = space.decode(genes)
            drawn = nominal.robot if space.reconfigurable else nominal
            p, des = perturb(pb, nominal, dev)
            if frozen:
                p, des = _frozen(p, des, r_op, dev[_COL["base_radius_or_R_min"]])
            # the size budget limits the drawing: the rule chooses the operating R with the nominal lengths' verdict
            out = evaluate_designer(p, des, regular=False, drawn_arm_sum=drawn.upper_arm + drawn.forearm,
                                    candidates=candidates)
            return {k: out[k] for k in _KEPT + (("resolved",) if candidates else ())}

        return jax.jit(jax.vmap(one))

    return shared_program("tolerance_samples", pb, space, (bool(frozen), int(candidates)), build, persist=True)


def _evaluate(pb, space, frozen, rows_g, rows_d, rows_r, chunk, progress) -> dict:
    """Every row through the program that tests the rule's first :data:`FIRST_CANDIDATES` operating-R candidates,
    then the rows it did not settle through the one that tests them all (where both settle: the same choice, the
    values to the last bits)."""
    out = _rows(_program(pb, space, frozen, FIRST_CANDIDATES), rows_g, rows_d, rows_r, chunk, progress)
    settled = out.pop("resolved", None)             # None: FIRST_CANDIDATES = 0 tests every candidate at once
    again = np.flatnonzero(~settled) if settled is not None else ()
    if len(again):
        full = _rows(_program(pb, space, frozen), rows_g[again], rows_d[again], rows_r[again], chunk, None)
        for k, v in full.items():
            out[k][again] = v
    return out


def _rows(f, rows_g, rows_d, rows_r, chunk, progress) -> dict:
    """``f`` over the rows in chunks of ``chunk`` (the last padded with the first row to the compiled size)."""
    total, parts = len(rows_g), []
    for s0 in range(0, total, chunk):
        a, b, r = rows_g[s0:s0 + chunk], rows_d[s0:s0 + chunk], rows_r[s0:s0 + chunk]
        m = len(a)
        if m < chunk:
            a, b, r = (np.concatenate([x, np.repeat(x[:1], chunk - m, axis=0)]) for x in (a, b, r))
        parts.append({k: np.asarray(v)[:m] for k, v in f(a, b, r).items()})
        if progress is not None:
            progress(m)
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def _ranked_percentiles(x: np.ndarray, sense: int, qs=PERCENTILES) -> np.ndarray:
    """Percentiles of ``x`` over its last axis with NaN ranked worst (below every number when ``sense`` = +1,
    higher is better; above when -1): a percentile that falls among the NaN samples is NaN (never a number)."""
    x = np.asarray(x, float)
    worst = -np.inf if sense > 0 else np.inf
    y = np.where(np.isnan(x), worst, x)
    p = np.percentile(y, qs, axis=-1, method="inverted_cdf")
    p = np.moveaxis(np.asarray(p), 0, -1)
    return np.where(np.isinf(p) & (p == worst), np.nan, p)


def _clopper_pearson_lower(k: np.ndarray, n: int, conf: float = 0.95) -> np.ndarray:
    """One-sided lower confidence bound of a probability with ``k`` successes in ``n`` trials."""
    from scipy.stats import beta

    k = np.asarray(k, float)
    return np.where(k > 0, beta.ppf(1.0 - conf, np.maximum(k, 1.0), n - k + 1.0), 0.0)


def analyse(pb, space, genes, tolerances: Optional[Tolerances] = None, *, samples: int = DEFAULT_SAMPLES,
            seed: int = 0, chunk: int = 8, operating_R: str = "chosen",
            progress: Optional[Callable[[int], Any]] = None) -> dict:
    """Monte Carlo tolerance analysis of designs of the designer's problem.

    Args:
        pb: the :class:`deltajax.optimize.designer.DesignerProblem` (e.g. the verification problem).
        space: the :class:`deltajax.optimize.DesignSpace` that decodes ``genes``.
        genes: (n, d) (or (d,)) gene vectors of the designs.
        tolerances: :class:`Tolerances` (default: the stated ones).
        samples: Monte Carlo samples per design (the same deviations for every design: common random numbers).
        seed: seed of the deviations (:func:`deviations`).
        chunk: samples evaluated at once (memory is bounded by one chunk; the answers do not depend on it). On the
            default verification problem 8 cost the fewest CPU-seconds, a quarter fewer than 16 or 64
            (docs/BENCHMARKS.md).
        operating_R: ``"chosen"``: each sample's operating R chosen by the problem's rule (the built robot set up
            for its task); ``"nominal"``: held at the nominal design's operating R (plus the R actuator's deviation,
            that of R_min), as a robot run at its datasheet's R. The same for a fixed design.
        progress: called with the number of samples done after each chunk.

    Returns:
        A dict of host arrays (n = designs, c = constraints, q = :data:`PERCENTILES`):
        ``p_holds`` (n, c) and ``p_all`` (n,) the fraction of samples in which each / every constraint holds
        (``p_all_lower95`` its one-sided 95 % Clopper-Pearson lower bound); ``nominal_feasible`` (n,),
        ``nominal_picks_per_min`` (n,), ``nominal_g`` (n, c): the unperturbed design evaluated by the same program;
        ``picks_mean`` (over finite samples), ``picks_min``, ``picks_percentiles`` (n, q), ``picks_nan`` (n,) the
        samples whose cycle is unreachable, ``p_reaches_nominal_picks`` (n,); ``g_percentiles`` (n, c, q) of the
        normalised constraint values (<= 0 holds; NaN margins count as a full violation, 1) and
        ``metric_percentiles`` (n, c, q) of the metric behind each constraint in its units
        (:data:`CONSTRAINT_METRICS`, NaN ranked worst); ``samples``, ``seed``, ``tolerances`` (a dict),
        ``deviations`` (samples, len(PARAMETERS)); ``constraint_names``, ``enabled`` (c,) bool.
    """
    tol = Tolerances() if tolerances is None else tolerances
    if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
        raise ToleranceError(f"chunk must be an integer >= 1, got {chunk!r}")
    if operating_R not in ("chosen", "nominal"):
        raise ToleranceError(f"operating_R must be 'chosen' or 'nominal', got {operating_R!r}")
    G = np.atleast_2d(np.asarray(genes, float))
    dev = deviations(tol, samples, seed)
    n, S = len(G), int(samples)
    # row 0 of every design: zero deviations (the nominal design through the same program)
    D = np.concatenate([np.zeros((1, dev.shape[1])), dev])
    rows_g = np.repeat(G, S + 1, axis=0)
    rows_d = np.tile(D, (n, 1))
    frozen = operating_R == "nominal" and space.reconfigurable
    r_op = np.zeros(len(G))
    if frozen:   # the nominal designs' operating R, by the problem's rule
        r_op = _evaluate(pb, space, False, G, np.zeros((len(G), dev.shape[1])), r_op, chunk, None)["R_operating"]
    out = _evaluate(pb, space, frozen, rows_g, rows_d, np.repeat(r_op, S + 1), chunk, progress)
    out = {k: v.reshape((n, S + 1) + v.shape[1:]) for k, v in out.items()}
    nom = {k: v[:, 0] for k, v in out.items()}
    smp = {k: v[:, 1:] for k, v in out.items()}
    # the size budget limits the drawing: judged on the nominal lengths, not on each built robot's
    j = CONSTRAINT_NAMES.index("size_budget")
    smp["g"][:, :, j] = nom["g"][:, None, j]
    smp["arm_sum"][:] = nom["arm_sum"][:, None]
    holds = smp["g"] <= FEASIBILITY_TOL                      # (n, S, c); NaN compares False: violated
    all_hold = np.all(holds, axis=2)
    picks = smp["picks_per_min"]
    finite = np.isfinite(picks)
    with np.errstate(invalid="ignore"):
        mean = np.where(finite.any(axis=1), np.nansum(np.where(finite, picks, 0.0), axis=1)
                        / np.maximum(finite.sum(axis=1), 1), np.nan)
    k_all = all_hold.sum(axis=1)
    enabled = np.asarray([nm in pb.enabled for nm in CONSTRAINT_NAMES])
    metric_pct = np.stack([_ranked_percentiles(smp[CONSTRAINT_METRICS[nm][0]], CONSTRAINT_METRICS[nm][1])
                           for nm in CONSTRAINT_NAMES], axis=1)
    return {
        "p_holds": holds.mean(axis=1), "p_all": k_all / S, "p_all_lower95": _clopper_pearson_lower(k_all, S),
        "nominal_feasible": np.all(nom["g"] <= FEASIBILITY_TOL, axis=1), "nominal_g": nom["g"],
        "nominal_picks_per_min": nom["picks_per_min"],
        "picks_mean": mean, "picks_min": np.where(finite.all(axis=1), np.min(np.where(finite, picks, np.inf),
                                                                              axis=1), np.nan),
        "picks_percentiles": _ranked_percentiles(picks, 1), "picks_nan": (~finite).sum(axis=1),
        "p_reaches_nominal_picks": np.mean(picks >= nom["picks_per_min"][:, None] * (1 - 1e-12), axis=1),
        "g_percentiles": _ranked_percentiles(np.swapaxes(np.where(np.isnan(smp["g"]), 1.0, smp["g"]), 1, 2), -1),
        "metric_percentiles": metric_pct,
        "samples": S, "seed": int(seed), "tolerances": tol.as_dict(), "deviations": dev, "operating_R": operating_R,
        "constraint_names": tuple(CONSTRAINT_NAMES), "enabled": enabled,
    }


#: the per-design entries of an :func:`analyse` result (leading axis: design)
PER_DESIGN = ("p_holds", "p_all", "p_all_lower95", "nominal_feasible", "nominal_g", "nominal_picks_per_min",
              "picks_mean", "picks_min", "picks_percentiles", "picks_nan", "p_reaches_nominal_picks", "g_percentiles",
              "metric_percentiles")


def select(results: Sequence[Mapping[str, Any]], picks: Sequence[tuple]) -> dict:
    """One :func:`analyse`-shaped result of designs taken from several results of the same samples:
    ``picks`` = ``[(result index, design index), ...]`` (the shared entries come from the first result)."""
    first = results[0]
    for r in results[1:]:
        if any(r[k] != first[k] for k in ("seed", "samples", "tolerances", "operating_R")):
            raise ToleranceError("select: results of different Monte Carlo samples cannot be combined")
    out = {k: v for k, v in first.items() if k not in PER_DESIGN}
    for k in PER_DESIGN:
        out[k] = np.stack([np.asarray(results[j][k])[i] for j, i in picks])
    return out


def describe(tol: Tolerances) -> str:
    """The tolerances in words (stored with the results and printed)."""
    dist = "uniform in +- tolerance" if tol.distribution == "uniform" else "normal, tolerance = 3 sigma"
    return (f"lengths (L1, L2, r, R or R_min/R_max) +-{tol.length * 1e3:g} mm, joint offsets (actuated zero, elbow "
            f"and platform socket axes) +-{tol.joint_offset_deg:g} deg, masses and payload +-{100 * tol.mass:g} %, "
            f"motor constants +-{100 * tol.motor:g} %; {dist}; one deviation per quantity, shared by the three arms")


def design_summary(result: Mapping[str, Any], i: int) -> dict:
    """The headline figures of design ``i`` of an :func:`analyse` result (host floats)."""
    q = list(PERCENTILES)
    pp = result["picks_percentiles"][i]
    return {"p_all": float(result["p_all"][i]), "p_all_lower95": float(result["p_all_lower95"][i]),
            "picks_p5": float(pp[q.index(5.0)]), "picks_p50": float(pp[q.index(50.0)]),
            "picks_p95": float(pp[q.index(95.0)]), "picks_nominal": float(result["nominal_picks_per_min"][i])}
