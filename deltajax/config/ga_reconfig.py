"""The main job's settings: ``experiment.*`` of ``experiment=ga_reconfig`` (the designer's problem) as one tree of
frozen dataclasses (:class:`GaReconfigSettings`, a block per config block), each field's range, unit and choices
declared once and checked by the one generic reader (:func:`deltajax.config.readers.read_settings`). The run built
from them (design space, problem, GA configuration, identity, a continued run's earlier run) is
:mod:`deltajax.config.ga_reconfig_run`'s."""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping, Optional

from .readers import ConfigError, check_fits, read_field, read_settings, setting
from ..motion import AGGREGATES
from ..optimize.operating import MECHANISM_NAMES, MODES
from ..tolerance import ToleranceError, Tolerances
from ..optimize.ga import GAConfig, GAError
from ..indices import INDEX_NAMES, INDEX_RANGES
from ..optimize.designer import OBJECTIVES

__all__ = ["GaReconfigSettings", "ga_reconfig_settings", "DESIGN_POINT_BYTES", "RECOMMEND_RULES", "reconfig_settings",
           "RECONFIG_KEYS", "DRIVE_UNITS", "tolerances_of", "ga_config", "DesignBlock", "TaskBlock",
           "GoodWorkspaceBlock", "JointsBlock", "LinksBlock", "MotorBlock", "CycleBlock", "RegularWorkspaceBlock",
           "ObjectivesBlock", "ConstraintsBlock", "ScreenBlock", "ParetoBlock", "RefineBlock", "FloorSolveBlock",
           "VerifyBlock", "ToleranceBlock", "MarginsBlock", "RobustBlock"]

#: the keys of ``experiment.reconfig`` and the units of its drive limits
RECONFIG_KEYS = {"mode", "aggregate", "n_R", "segments", "drive", "mechanism", "motor_torque"}
DRIVE_UNITS = {"speed": "m/s", "acceleration": "m/s^2", "force": "N"}


def _num(b: Mapping[str, Any], key: str, where: str, unit: str) -> float:
    v = b.get(key)
    if v is None:
        return math.inf
    if isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v) or not v > 0:
        raise ConfigError(f"{where}.{key} must be a number > 0 {unit} or null (no limit), got {v!r}")
    return float(v)


def reconfig_settings(block: Optional[Mapping[str, Any]], where: str = "experiment.reconfig") -> dict:
    """Validate the ``experiment.reconfig`` block (plain values; ``None``: all defaults) into a plain dict.

    Raises:
        ConfigError: one line naming the field and the value in its unit.
    """
    b = {} if block is None else block
    if not isinstance(b, Mapping):
        raise ConfigError(f"{where} must be a mapping, got {b!r}")
    for k in b:
        if k not in RECONFIG_KEYS:
            raise ConfigError(f"{where}.{k}: unknown key; valid keys: {sorted(RECONFIG_KEYS)}")
    out = {}
    for name, options, default in (("mode", MODES, "per_task"), ("aggregate", AGGREGATES, "integral"),
                                   ("mechanism", MECHANISM_NAMES, "none")):
        v = b.get(name, default)
        if v not in options:
            raise ConfigError(f"{where}.{name} must be one of {list(options)}, got {v!r}")
        out[name] = v
    for name, default, lo in (("n_R", 17, 3), ("segments", 8, 3)):
        v = b.get(name, default)
        if isinstance(v, bool) or not isinstance(v, int) or v < lo:
            raise ConfigError(f"{where}.{name} must be an integer >= {lo}, got {v!r}")
        out[name] = v
    d = b.get("drive") or {}
    if not isinstance(d, Mapping):
        raise ConfigError(f"{where}.drive must be a mapping with keys {list(DRIVE_UNITS)}, got {d!r}")
    for k in d:
        if k not in DRIVE_UNITS:
            raise ConfigError(f"{where}.drive.{k}: unknown key; valid keys: {list(DRIVE_UNITS)}")
    out["drive"] = {k: _num(d, k, f"{where}.drive", u) for k, u in DRIVE_UNITS.items()}
    out["motor_torque"] = _num(b, "motor_torque", where, "N m")
    if out["mechanism"] == "none" and math.isfinite(out["motor_torque"]):
        raise ConfigError(f"{where}.motor_torque={out['motor_torque']!r} N m needs {where}.mechanism="
                             f"screw_linkage (got mechanism=none)")
    return out


def tolerances_of(block: "ToleranceBlock"):
    """The :class:`deltajax.tolerance.Tolerances` of a checked ``experiment.tolerance`` block (mm, deg, %)."""
    try:
        return Tolerances(length=float(block.length_mm) * 1e-3, joint_offset_deg=float(block.joint_offset_deg),
                          mass=float(block.mass_percent) / 100.0, motor=float(block.motor_percent) / 100.0,
                          distribution=str(block.distribution))
    except ToleranceError as err:
        raise ConfigError(f"experiment.tolerance: {err}") from None


def ga_config(block: Mapping[str, Any], seed: int = 0):
    """The :class:`deltajax.optimize.GAConfig` of ``experiment.ga`` (unknown keys refused; its invariants checked
    by :meth:`GAConfig.validate`, named here by their config path)."""
    known = {f.name for f in dataclasses.fields(GAConfig)} - {"seed"}
    extra = set(block) - known
    if extra:
        raise ConfigError(f"experiment.ga: unknown keys {sorted(extra)}; known: {sorted(known)}")
    kw = {k: block[k] for k in block}
    for k in ("population_size", "generations", "checkpoint_every"):
        if k in kw and isinstance(kw[k], float) and float(kw[k]).is_integer():
            kw[k] = int(kw[k])
    try:
        return GAConfig(seed=int(seed), **kw).validate()
    except (GAError, TypeError) as err:
        raise ConfigError(str(err).replace("GAConfig.", "experiment.ga.", 1)) from None


# ---- ga_reconfig: the designer's problem. Every block of experiment.* is one frozen dataclass below, each field's
# range, unit and choices declared once (readers.setting) and checked by the one generic reader
# (readers.read_settings); a block's cross-field rules are its _check. The design space, the GA's configuration and
# the problem are then built by deltajax.optimize.workflow (errors there become ConfigError here).

#: a lower bound of the memory of one evaluated point of a design (one 3x3 Jacobian in float32), for the refusal
#: of populations that cannot be evaluated at once
DESIGN_POINT_BYTES = 9 * 4

from ..optimize.certify import MAX_EXTRA_DOUBLINGS  # noqa: E402  the certify stage's default
from ..optimize.workflow import RECOMMEND_RULES  # noqa: E402  the one list (the rules of workflow.recommend)


def _index_names():
    return INDEX_NAMES


def _bounds(path: str, v: Any) -> dict:
    if not isinstance(v, Mapping) or not v:
        raise ConfigError(f"{path} must be a non-empty mapping, got {v!r}")
    return dict(v)


def _int_list(n: int, lo: int):
    def read(path: str, v: Any) -> tuple:
        if not (isinstance(v, (list, tuple)) and len(v) == n and all(isinstance(x, int) and not isinstance(x, bool)
                                                                     and x >= lo for x in v)):
            raise ConfigError(f"{path} must be a list of {n} integers >= {lo}, got {v!r}")
        return tuple(v)
    return read


def _objective_names(path: str, v: Any) -> tuple:
    if not isinstance(v, (list, tuple)) or not v:
        raise ConfigError(f"{path} must be a non-empty list from {list(OBJECTIVES)}, got {v!r}")
    for nm in v:
        if nm not in OBJECTIVES:
            raise ConfigError(f"{path}: unknown objective {nm!r}; known: {list(OBJECTIVES)}")
    if len(set(v)) != len(v):
        raise ConfigError(f"{path} has duplicates: {list(v)!r}")
    return tuple(v)


def _weights(path: str, v: Any) -> dict:
    if not isinstance(v, Mapping):
        raise ConfigError(f"{path} must be a mapping, got {v!r}")
    return {k: read_field(f"{path}.{k}", x, lo=0) for k, x in v.items()}


def _continue_from(path: str, v: Any) -> Optional[str]:
    if v is not None and (not isinstance(v, str) or not v.strip()):
        raise ConfigError(f"{path} must be null or the path of a finished ga_reconfig run (its directory or "
                          f"results.h5), got {v!r}")
    return v


def _recommend(path: str, v: Any) -> str:
    if v not in RECOMMEND_RULES:
        raise ConfigError(f"{path} must be one of {', '.join(RECOMMEND_RULES)}, got {v!r}")
    return v


@dataclasses.dataclass(frozen=True, kw_only=True)
class DesignBlock:
    """``experiment.design``: the design space (genes and their bounds; R samples of a reconfigurable design)."""
    n_R: int = setting(lo=2)
    bounds: dict = setting(read=_bounds)


@dataclasses.dataclass(frozen=True, kw_only=True)
class TaskBlock:
    """``experiment.task``: the task cylinder and its search samples (rings, angles over the 60 deg wedge, levels)."""
    diameter: float = setting(lo=0, lo_open=True, unit="m")
    height: float = setting(lo=0, lo_open=True, unit="m")
    z_top: float = setting(lo=0, lo_open=True, unit="m")
    n_r: int = setting(lo=1)
    n_phi: int = setting(lo=2)   # both ends of the 60 deg wedge
    n_z: int = setting(lo=2)


@dataclasses.dataclass(frozen=True, kw_only=True)
class GoodWorkspaceBlock:
    """``experiment.good_workspace``: the index and its threshold that make a point good."""
    index: str = setting(choices=_index_names)
    threshold: float = setting()
    beta: float = setting(lo=0, hi=1)

    def _check(self, path: str) -> None:
        lo, hi = INDEX_RANGES[self.index]  # a threshold outside the index's range selects every point or none
        read_field(f"{path}.threshold", self.threshold, lo=lo, hi=hi)


@dataclasses.dataclass(frozen=True, kw_only=True)
class JointsBlock:
    """``experiment.joints``: the passive joints' kind, cone limit and neutral axes (degrees)."""
    kind: str = setting(choices=("ball", "universal"))
    limit_deg: float = setting(lo=0, lo_open=True, hi=180, unit="deg")
    elbow_neutral_deg: float = setting(lo=-180, hi=180, unit="deg")
    platform_neutral_deg: float = setting(lo=-180, hi=180, unit="deg")


@dataclasses.dataclass(frozen=True, kw_only=True)
class LinksBlock:
    """``experiment.links``: link radii, required clearance and the base plate's overhang (m)."""
    forearm_radius: float = setting(lo=0, hi=1)
    upper_arm_radius: float = setting(lo=0, hi=1)
    clearance: float = setting(lo=0, hi=1)
    plate_overhang: float = setting(lo=-1, hi=1)


@dataclasses.dataclass(frozen=True, kw_only=True)
class MotorBlock:
    """``experiment.motor``: the drive (torques at the motor shaft, speeds, rotor inertia, gearbox)."""
    peak_torque: float = setting(lo=0, lo_open=True, unit="N m")
    rated_torque: float = setting(lo=0, lo_open=True, unit="N m")
    max_speed: float = setting(lo=0, lo_open=True, unit="rad/s")
    corner_speed: float = setting(lo=0, lo_open=True, unit="rad/s")
    rotor_inertia: float = setting(lo=0, unit="kg m^2")
    efficiency: float = setting(lo=0, lo_open=True, hi=1)
    gear_ratio: float = setting(lo=0, lo_open=True)

    def _check(self, path: str) -> None:
        if self.rated_torque > self.peak_torque:
            raise ConfigError(f"{path}.rated_torque={self.rated_torque!r} N m must be <= {path}.peak_torque="
                              f"{self.peak_torque!r} N m")
        if self.corner_speed > self.max_speed:
            raise ConfigError(f"{path}.corner_speed={self.corner_speed!r} rad/s must be <= {path}.max_speed="
                              f"{self.max_speed!r} rad/s")


@dataclasses.dataclass(frozen=True, kw_only=True)
class CycleBlock:
    """``experiment.cycle``: the pick-and-place cycle and its search samples."""
    payload: float = setting(lo=0, unit="kg")
    dwell: float = setting(lo=0, unit="s")
    duration: float = setting(lo=0, lo_open=True, unit="s")
    n_samples: int = setting(lo=5)
    law: str = setting(choices=("poly5", "cycloidal", "modified_trapezoid"))
    n_R_operating: int = setting(lo=1)

    def _check(self, path: str) -> None:
        if self.n_samples % 2 == 0:
            raise ConfigError(f"{path}.n_samples must be odd (a sample at the place point), got {self.n_samples}")


@dataclasses.dataclass(frozen=True, kw_only=True)
class RegularWorkspaceBlock:
    """``experiment.regular_workspace``: the regular cylinder's shape, its search grid and, with ``search_refine``,
    the continuous measure in the search (bisection and golden-section steps; rings, angles, levels)."""
    hd_ratio: float = setting(lo=0, lo_open=True)
    r_max: float = setting(lo=0, lo_open=True, unit="m")
    z_min: float = setting(lo=0, unit="m")
    z_max: float = setting(lo=0, lo_open=True, unit="m")
    n_r: int = setting(lo=2)
    n_phi: int = setting(lo=2)
    n_z: int = setting(lo=2)
    search_refine: bool = setting(False)
    search_refine_steps: tuple = setting((10, 8), read=_int_list(2, 1))
    search_refine_samples: tuple = setting((3, 2, 3), read=_int_list(3, 2))

    GRID = ("hd_ratio", "r_max", "z_min", "z_max", "n_r", "n_phi", "n_z")

    def grid(self) -> dict:
        """The cylinder's shape and search grid, as :meth:`DesignerProblem.build` takes them."""
        return {k: getattr(self, k) for k in self.GRID}

    def _check(self, path: str) -> None:
        if not self.z_min < self.z_max:
            raise ConfigError(f"{path}.z_min={self.z_min!r} m must be < z_max={self.z_max!r} m")


@dataclasses.dataclass(frozen=True, kw_only=True)
class ObjectivesBlock:
    """``experiment.objectives``: Pareto or weighted, the objectives, the GA's primary one and the weights."""
    mode: str = setting(choices=("pareto", "weighted"))
    names: tuple = setting(read=_objective_names)
    primary: str = setting()
    weights: dict = setting(read=_weights)

    def _check(self, path: str) -> None:
        names = list(self.names)
        if self.primary not in names:
            raise ConfigError(f"{path}.primary must be one of {path}.names {names!r}, got {self.primary!r}")
        for k in self.weights:
            if k not in names:
                raise ConfigError(f"{path}.weights.{k}: not in {path}.names {names!r}")
        if self.mode == "weighted" and not any(w > 0 for w in self.weights.values()):
            raise ConfigError(f"{path}.weights: all weights are zero (objectives.mode=weighted)")
        if self.mode == "pareto" and len(names) < 2:
            raise ConfigError(f"{path}.names needs >= 2 objectives for mode=pareto, got {names!r}")


@dataclasses.dataclass(frozen=True, kw_only=True)
class ConstraintsBlock:
    """``experiment.constraints``: which constraints hold, the required rate and the arm-length budget."""
    task_in_good_workspace: bool = setting()
    passive_joints: bool = setting()
    interference: bool = setting()
    min_picks_per_min: float = setting(lo=0)
    max_arm_sum: Optional[float] = setting(lo=0, lo_open=True, unit="m")

    GEOMETRIC = ("task_in_good_workspace", "passive_joints", "interference")


@dataclasses.dataclass(frozen=True, kw_only=True)
class ScreenBlock:
    """``experiment.screen``: the scrambled-Sobol screen of the gene box."""
    enabled: bool = setting()
    log2_size: int = setting(lo=0, hi=24)
    seed_fraction: float = setting(lo=0, hi=1)


@dataclasses.dataclass(frozen=True, kw_only=True)
class ParetoBlock:
    """``experiment.pareto``: the NSGA-II stage."""
    enabled: bool = setting()
    population_size: int = setting(lo=4)
    generations: int = setting(lo=1)
    ref_min_factor: float = setting(lo=1, lo_open=True)


@dataclasses.dataclass(frozen=True, kw_only=True)
class RefineBlock:
    """``experiment.refine``: the optax descent from the front's points."""
    enabled: bool = setting()
    steps: int = setting(lo=1)
    learning_rate: float = setting(lo=0, lo_open=True, hi=1)
    penalty: float = setting(lo=0)


@dataclasses.dataclass(frozen=True, kw_only=True)
class FloorSolveBlock:
    """``experiment.floor_solve``: the epsilon-constraint step of ``recommend=floor``; absent: off."""
    enabled: bool = setting()
    rounds: int = setting(lo=1)
    candidates: int = setting(lo=1)


@dataclasses.dataclass(frozen=True, kw_only=True)
class VerifyBlock:
    """``experiment.verify``: the fine grids of the verification and the certify stage's further doublings."""
    n_R: int = setting(lo=2)
    n_R_operating: int = setting(lo=1)
    task_n_r: int = setting(lo=1)
    task_n_phi: int = setting(lo=2)
    task_n_z: int = setting(lo=2)
    cycle_samples: int = setting(lo=5)
    # further doublings while a certified figure moves more than its tolerance (absent: the default)
    certify_doublings: int = setting(MAX_EXTRA_DOUBLINGS, lo=0, hi=4)
    rw_n_r: int = setting(lo=2)
    rw_n_phi: int = setting(lo=2)
    rw_n_z: int = setting(lo=2)

    def points(self) -> int:
        """Evaluated points of one design on the fine grids."""
        return (self.n_R * (self.task_n_r * self.task_n_phi * self.task_n_z + self.rw_n_r * self.rw_n_phi *
                            self.rw_n_z) + self.n_R_operating * self.cycle_samples)

    def _check(self, path: str) -> None:
        if self.cycle_samples % 2 == 0:
            raise ConfigError(f"{path}.cycle_samples must be odd and >= 5, got {self.cycle_samples!r}")


@dataclasses.dataclass(frozen=True, kw_only=True)
class ToleranceBlock:
    """``experiment.tolerance``: the Monte Carlo of :mod:`deltajax.tolerance` (lengths in mm, masses and motor
    constants in percent); absent: off."""
    enabled: bool = setting()
    samples: int = setting(lo=1, hi=10 ** 7)
    seed: int = setting(lo=0, hi=2 ** 32 - 1)
    distribution: str = setting(choices=("uniform", "normal"))
    length_mm: float = setting(lo=0, hi=10, unit="mm")
    joint_offset_deg: float = setting(lo=0, hi=5, unit="deg")
    mass_percent: float = setting(lo=0, hi=50, unit="%")
    motor_percent: float = setting(lo=0, hi=50, unit="%")

    def _check(self, path: str) -> None:
        tolerances_of(self)          # the Monte Carlo's own invariants, before anything compiles


@dataclasses.dataclass(frozen=True, kw_only=True)
class MarginsBlock:
    """``experiment.robust.margins``: the margin every constraint must hold by in a robust run's search,
    verification and certification: the good-workspace index threshold raised by ``index``, the passive joints'
    limit lowered by ``joint_deg``, the links' required clearance raised by ``clearance_mm``, the motor's peak and
    rated torque derated by ``motor_percent`` (the cycle is planned with that torque headroom). Absent or 0: the
    constraint as stated."""
    index: float = setting(0.0, lo=0)
    joint_deg: float = setting(0.0, lo=0, hi=180, hi_open=True, unit="deg")
    clearance_mm: float = setting(0.0, lo=0, hi=1000, hi_open=True, unit="mm")
    motor_percent: float = setting(0.0, lo=0, hi=100, hi_open=True, unit="%")


@dataclasses.dataclass(frozen=True, kw_only=True)
class RobustBlock:
    """``experiment.robust``: the robust recommendation (every constraint in >= ``probability`` of the Monte
    Carlo samples) and the margins the search requires; absent: off."""
    enabled: bool = setting()
    probability: float = setting(lo=0, lo_open=True, hi=1)
    confirm_seed: int = setting(lo=0, hi=2 ** 32 - 1)
    max_candidates: int = setting(lo=1)
    margins: MarginsBlock = setting(MarginsBlock())     # absent or null: every margin 0


def _ga(path: str, v: Any):
    return ga_config({} if v is None else v)   # read_settings hands on plain values


def _reconfig(path: str, v: Any) -> dict:
    return reconfig_settings(v, path)


@dataclasses.dataclass(frozen=True, kw_only=True)
class GaReconfigSettings:
    """The main job's settings: ``experiment.*`` of ``experiment=ga_reconfig``, one typed block per config block
    (SI units; angles in degrees, lengths in mm and percentages where the name says so), read once by
    :func:`ga_reconfig_settings`."""
    name: str = setting("ga_reconfig")
    resume: str = setting("auto", choices=("auto", "never", "must"))
    stop_after: Optional[int] = setting(None, lo=1)
    # a finished run (its directory or results.h5) this run continues with more budget; None: a new search
    continue_from: Optional[str] = setting(None, read=_continue_from)
    design: DesignBlock = setting()
    task: TaskBlock = setting()
    good_workspace: GoodWorkspaceBlock = setting()
    joints: JointsBlock = setting()
    links: LinksBlock = setting()
    motor: MotorBlock = setting()
    cycle: CycleBlock = setting()
    regular_workspace: RegularWorkspaceBlock = setting()
    objectives: ObjectivesBlock = setting()
    constraints: ConstraintsBlock = setting()
    screen: ScreenBlock = setting()
    ga: Any = setting(None, read=_ga)              # the GA's deltajax.optimize.GAConfig (absent: its defaults)
    pareto: ParetoBlock = setting()
    refine: RefineBlock = setting()
    recommend: str = setting(read=_recommend)
    recommend_floor: float = setting(1.2, lo=0, lo_open=True)
    recommend_band: float = setting(0.02, lo=0, hi=1)
    floor_solve: FloorSolveBlock = setting(FloorSolveBlock(enabled=False, rounds=0, candidates=0))
    verify: VerifyBlock = setting()
    tolerance: ToleranceBlock = setting(ToleranceBlock(
        enabled=False, samples=0, seed=0, distribution="uniform", length_mm=0.0, joint_offset_deg=0.0, mass_percent=0.0,
        motor_percent=0.0))
    robust: RobustBlock = setting(RobustBlock(enabled=False, probability=1.0, confirm_seed=0, max_candidates=1))
    # rtmode: the R(t) operating spec's settings (deltajax.optimize.operating.spec_from_settings takes this mapping)
    reconfig: Optional[dict] = setting(None, read=_reconfig)

    @property
    def search_refine(self) -> tuple:
        """The continuous regular-workspace measure in the search: () off, else ((bisection, golden-section steps),
        (rings, angles, levels) of the unit cylinder) for :func:`deltajax.constraints.refine_cylinder`."""
        rw = self.regular_workspace
        return (rw.search_refine_steps, rw.search_refine_samples) if rw.search_refine else ()

    def _check(self, path: str) -> "GaReconfigSettings":
        task, rw, gw = self.task, self.regular_workspace, self.good_workspace
        if task.z_top + task.height > rw.z_max or task.z_top < rw.z_min or task.diameter / 2 > rw.r_max:
            raise ConfigError(f"{path}.task (z {task.z_top!r}..{task.z_top + task.height!r} m, radius "
                              f"{task.diameter / 2!r} m) must lie inside {path}.regular_workspace's grid "
                              f"(z {rw.z_min!r}..{rw.z_max!r} m, r <= {rw.r_max!r} m)")
        out = self
        if self.ga is None:
            out = dataclasses.replace(out, ga=ga_config({}))
        if self.reconfig is None:
            out = dataclasses.replace(out, reconfig=reconfig_settings(None, f"{path}.reconfig"))
        # every member of a generation is evaluated at once on the search grids: refuse a population that cannot fit
        per_design = self.design.n_R * (task.n_r * task.n_phi * task.n_z + rw.n_r * rw.n_phi * rw.n_z) + \
            self.cycle.n_R_operating * self.cycle.n_samples
        for key, size in (("ga.population_size", out.ga.population_size),
                          ("pareto.population_size", self.pareto.population_size)):
            check_fits(f"{path}.{key}", size, float(size) * per_design * DESIGN_POINT_BYTES,
                       f"{size:.3g} designs x {per_design} evaluated points each at once (a 3x3 Jacobian per point)")
        m, lim = self.robust.margins, self.joints.limit_deg
        if m.joint_deg > 0 and m.joint_deg >= lim:
            raise ConfigError(f"{path}.robust.margins.joint_deg must be < {path}.joints.limit_deg ({lim:g} deg), "
                              f"got {m.joint_deg!r} deg")
        top = INDEX_RANGES[gw.index][1]
        if m.index > 0 and top is not None and gw.threshold + m.index >= top:
            raise ConfigError(f"{path}.robust.margins.index must be < {top:g} - {path}.good_workspace.threshold "
                              f"({top - gw.threshold:g}; the index {gw.index} is at most {top:g}), got {m.index!r}")
        if self.robust.enabled and not self.tolerance.enabled:
            raise ConfigError(f"{path}.robust.enabled=true needs the tolerance stage: set "
                              f"{path}.tolerance.enabled=true")
        if self.robust.enabled and self.robust.confirm_seed == self.tolerance.seed:
            raise ConfigError(f"{path}.robust.confirm_seed={self.robust.confirm_seed!r} must differ from "
                              f"{path}.tolerance.seed (the confirmation is a fresh Monte Carlo)")
        # the verification's fine grids, one design at least evaluated at once
        fine = self.verify.points()
        check_fits(f"{path}.verify", dataclasses.asdict(self.verify), float(fine) * DESIGN_POINT_BYTES,
                   f"{fine:.3g} evaluated points of a design")
        return out


def ga_reconfig_settings(ectx: Mapping[str, Any]) -> GaReconfigSettings:
    """Validate every field of ``experiment`` (one ``ConfigError`` line naming field and value)."""
    return read_settings(GaReconfigSettings, ectx, "experiment")
