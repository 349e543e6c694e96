"""Build library objects from (Hydra/OmegaConf or plain dict) configuration, validating first: the only code
that knows config paths. Field readers and :class:`ConfigError` live in ``readers.py``, the main job's reader in
``ga_reconfig.py``; everything else (robot, mass, grids, every other experiment's spec, validators) is here.

Every error raised here names the config field and the value, before anything is compiled.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping, Optional, Tuple

from ..geometry import Delta, GeometryError, ReconfigurableDelta
from ..mass import FOREARM_MODELS, MASS_FIELDS, MassError, MassModel

__all__ = ["ConfigError", "robot_from_config", "mass_from_config", "validate_config", "check_keys", "valid_keys",
           "register_schemas", "TOP_LEVEL_KEYS",
           "EXPERIMENT_SETTINGS", "EXPERIMENT_SCHEMAS", "BenchKernelSettings",
           "PaperGridSettings", "IndicesExamplesSettings", "DatasheetSettings", "GaReconfigSettings", "source_run",
           "WorkspaceGridSettings", "ReconfigIndicesSettings", "grid_plan", "DynamicsCycleSettings",
           "BoundarySearchSettings", "ReconfigMotionSettings",
           "GaReconfigSetup"]


from .readers import (ConfigError, check_fits, read_choice, read_field, read_names,  # noqa: E402,F401
                      read_vector)  # the one set of readers
from .ga_reconfig import (GaReconfigSettings, GaReconfigSetup, validate_ga_reconfig, validate_ga_reconfig_run_dir,  # noqa: E402,F401
                          ga_reconfig_build, ga_reconfig_settings)

def robot_from_config(cfg: Mapping[str, Any], prefix: str = "robot") -> Tuple[Delta, Optional[ReconfigurableDelta]]:
    """Build the robot described by a ``configs/robot/*.yaml`` entry.

    Fields: ``base_radius``, ``platform_radius``, ``upper_arm``, ``forearm`` (m), ``theta_min_deg``,
    ``theta_max_deg`` (deg, ``null`` = unlimited), optional ``R_range: {min, max, step}`` (m) for a
    reconfigurable robot and optional ``mass`` (used by the dynamics).

    Returns:
        (fixed robot, reconfigurable robot or ``None``). The fixed robot has R = ``base_radius``.

    Raises:
        ConfigError: a missing or invalid field; the message names ``robot.<field>`` and the value.
    """
    kw = {key: read_field(f"{prefix}.{key}", cfg.get(key), unit="m")
          for key in ("base_radius", "platform_radius", "upper_arm", "forearm")}
    lo = read_field(f"{prefix}.theta_min_deg", cfg.get("theta_min_deg"), none=True, unit="deg")
    hi = read_field(f"{prefix}.theta_max_deg", cfg.get("theta_max_deg"), none=True, unit="deg")
    mass_cfg = cfg.get("mass") if hasattr(cfg, "get") else None
    mass = None
    if mass_cfg is not None:
        mass = mass_from_config(mass_cfg, kw, prefix=f"{prefix}.mass")
    try:
        robot = Delta.from_degrees(theta_min_deg=lo, theta_max_deg=hi, mass=mass, **kw)
    except GeometryError as e:
        raise ConfigError(f"{prefix}: {e}") from None
    rng = cfg.get("R_range") if hasattr(cfg, "get") else None
    if rng is None:
        return robot, None
    p = f"{prefix}.R_range"
    r_min, r_max, r_step = (read_field(f"{p}.{k}", rng.get(k), unit="m") for k in ("min", "max", "step"))
    if r_step > 0 and r_max >= r_min:  # the R samples (one float64 each at least), before anything holds them
        check_fits(f"{p}.step", r_step, 8.0 * _n_steps(r_min, r_max, r_step), "the R samples", unit="m")
    try:
        recon = ReconfigurableDelta.from_range(robot, r_min, r_max, r_step)
    except GeometryError as e:
        raise ConfigError(f"{p}: {e}") from None
    return robot, recon


def _n_steps(lo: float, hi: float, step: float) -> int:
    """Samples of the inclusive range [lo, hi] every ``step`` (an estimate: no array is built)."""
    return math.floor((hi - lo) / step + 1e-6) + 1


def check_reach_over_range(cfg: Mapping[str, Any], recon: ReconfigurableDelta, prefix: str = "robot") -> None:
    """Something must be reachable at every R of ``robot.R_range`` (for jobs that use the range).

    The "can reach nothing" test of :class:`deltajax.Delta` is monotone in R, so both ends suffice.
    """
    rb, rng = recon.robot, cfg.get("R_range")
    for end, R in (("min", float(recon.R_min)), ("max", float(recon.R_max))):
        try:
            Delta(base_radius=R, platform_radius=rb.platform_radius, upper_arm=rb.upper_arm, forearm=rb.forearm,
                  theta_min=rb.theta_min, theta_max=rb.theta_max, mass=rb.mass)
        except GeometryError as e:
            raise ConfigError(f"{prefix}.R_range.{end}={rng.get(end)!r} m: at R = {R:g} m the {e}") from None


# =============================================================================================================
# Validation of every experiment field, before anything is computed (called by run.execute after the robot)
# =============================================================================================================
#: Top-level keys of the composed config (configs/config.yaml and the `# @package _global_` experiment files).
TOP_LEVEL_KEYS = ("robot", "experiment", "seed", "precision", "plots", "progress", "compilation_cache", "fresh",
                  "shard", "n_shards", "beta", "source")
#: experiments that read the top-level ``source`` (what they describe); any other experiment refuses it
SOURCE_EXPERIMENTS = ("datasheet",)

def _validate_top(cfg: Mapping[str, Any]) -> None:
    read_field("seed", cfg.get("seed"), kind="int", lo=0, hi=2 ** 32 - 1)  # NumPy's and JAX's seed range
    read_choice("precision", cfg.get("precision"), ("float64", "float32"))
    for k in ("plots", "progress", "fresh"):
        if k in cfg:
            read_field(k, cfg.get(k), kind="bool")
    n_shards = read_field("n_shards", cfg.get("n_shards", 1), kind="int", lo=1)
    read_field("shard", cfg.get("shard", 0), kind="int", lo=0, hi=n_shards - 1)


def _grid_fits(path: str, h: float, axes, bytes_per_point: float) -> None:
    """Refuse a grid whose points (``bytes_per_point`` each, a lower bound of what the job holds per point) or
    axes do not fit in memory, from the axis lengths alone (before any axis is built)."""
    n = [math.floor((hi - lo) / h + 1e-6) + 1 for lo, hi in axes]
    total = float(n[0]) * n[1] * n[2]
    check_fits(path, h, max(total * bytes_per_point, 16.0 * max(n)),
          f"a grid of {n[0]} x {n[1]} x {n[2]} = {total:.3g} points", unit="m")


def workspace_grid_from_config(g: Mapping[str, Any], robot=None, bytes_per_point: float = 1.0):
    """The grid of ``experiment.grid`` (h, x, y, z, bounds in m); an axis given as null is sized from the robot's
    reach bound (:func:`deltajax.workspace.driver.reach_box`, widened outwards to whole steps of h, y symmetric).
    Every axis must have positive width; a grid of more than the machine's memory at ``bytes_per_point`` is
    refused before it is built."""
    from ..workspace import make_grid
    from ..workspace.driver import reach_box

    h = read_field("experiment.grid.h", g.get("h"), lo=0, lo_open=True, unit="m")
    box = reach_box(robot) if robot is not None else None

    def pair(i, key):
        v = g.get(key)
        if v is None and box is not None:  # from the reach bound, on whole steps of h (y symmetric: mirror halving)
            lo, hi = box[i]
            if key == "y":
                n = math.ceil(max(-lo, hi) / h - 1e-9)
                return -n * h, n * h
            return math.floor(lo / h + 1e-9) * h, math.ceil(hi / h - 1e-9) * h
        lo, hi = read_vector(f"experiment.grid.{key}", v, 2)
        if not hi > lo:  # a zero-width box has no volume: its "volume" would be count h^3 of a plane
            raise ConfigError(f"experiment.grid.{key} must be [lo, hi] with lo < hi (m), got {[lo, hi]!r}")
        return lo, hi

    bounds = g.get("bounds")
    auto = [k for k in ("x", "y", "z") if g.get(k) is None]
    if auto and bounds is not None:
        raise ConfigError(f"experiment.grid.bounds must be null when the grid is sized from the reach bound "
                          f"(experiment.grid.{'/'.join(auto)}=null), got {bounds!r}")
    if bounds is not None:
        if not hasattr(bounds, "__len__") or len(bounds) != 3:
            raise ConfigError(f"experiment.grid.bounds must be null or [[x0,x1],[y0,y1],[z0,z1]] (m), "
                              f"got {bounds!r}")
        bounds = [read_vector(f"experiment.grid.bounds[{i}]", b, 2) for i, b in enumerate(bounds)]
        for (lo, hi), k in zip(bounds, "xyz"):
            if not hi > lo:
                raise ConfigError(f"experiment.grid.bounds ({k}) must have lo < hi (m), got {[lo, hi]!r}")
    axes = (pair(0, "x"), pair(1, "y"), pair(2, "z"))
    _grid_fits("experiment.grid.h", h, axes, bytes_per_point)
    try:
        return make_grid(*axes, h, bounds=bounds)
    except ValueError as err:
        raise ConfigError(f"experiment.grid: {err}") from None


def paper_grid_from_config(e: Mapping[str, Any], bytes_per_point: float = 1.0):
    """The Franco-López 2026 grid at spacing ``experiment.h`` (m, default 0.002); refused before it is built when
    its points at ``bytes_per_point`` do not fit in memory."""
    from ..workspace import franco2026_grid

    h = read_field("experiment.h", e.get("h", 0.002), lo=0, lo_open=True, unit="m")
    _grid_fits("experiment.h", h, ((-0.4, 0.4), (-0.4, 0.4), (0.0, 0.6 - h)), bytes_per_point)
    try:
        return franco2026_grid(h)
    except ValueError as err:
        raise ConfigError(f"experiment.h={h!r}: {err}") from None


@dataclasses.dataclass(frozen=True)
class WorkspaceGridSettings:
    """``experiment=workspace_grid``: the grid (m), this job's shard of ``n_shards``, points per chunk, the index
    fields stored, the devices used (resolved), the k~ parameters, the backend (resolved: ``auto`` is Numba on a
    CPU in float64, else JAX), resume/checkpoint/stop settings and what identifies the numbers for a resume
    (``robot_key``, ``precision``)."""

    grid: Any
    shard: int
    n_shards: int
    chunk_points: int
    store: tuple
    n_dev: int
    params: dict
    backend: str
    resume: bool
    checkpoint_s: float
    stop_after: Optional[int]
    robot_key: dict
    precision: str
    plan: Any = None     # this shard's chunks of whole x-planes (:func:`grid_plan`)


def grid_plan(shape, chunk_points: int, n_devices: int, shard: int, n_shards: int):
    """The :class:`deltajax.workspace.chunks.ShardPlan` of a workspace grid job; its refusals are
    :class:`ConfigError` (they name a setting)."""
    from ..workspace.chunks import ShardPlan

    try:
        return ShardPlan(shape, chunk_points, n_devices, shard, n_shards)
    except ValueError as e:
        raise ConfigError(str(e)) from None


def workspace_grid_settings(e, cfg, robot, recon) -> WorkspaceGridSettings:
    import importlib.util

    import jax

    from ..indices import INDEX_NAMES

    store = read_names("experiment.store", e.get("store"), INDEX_NAMES)
    itemsize = 8 if cfg.get("precision") == "float64" else 4
    # per point of this shard: the reachable mask (1 byte) and every stored index field
    grid = workspace_grid_from_config(e.get("grid") or {}, robot,
                                      bytes_per_point=(1 + itemsize * len(store)) / int(cfg.get("n_shards", 1) or 1))
    params = dict(b_v=read_field("experiment.b_v", e.get("b_v"), lo=0, lo_open=True),
                  b_f=read_field("experiment.b_f", e.get("b_f"), lo=0, lo_open=True),
                  beta=read_field("experiment.beta", e.get("beta"), lo=0, hi=1, lo_open=True, hi_open=True))
    chunk = read_field("experiment.chunk_points", e.get("chunk_points"), kind="int", lo=1)
    backend = read_choice("experiment.backend", e.get("backend", "auto"), ("auto", "jax", "numba"))
    dev = e.get("devices", "all")
    n_avail = jax.local_device_count()
    n_dev = n_avail if dev in ("all", None) else read_field("experiment.devices", dev, kind="int", lo=1, hi=n_avail)
    f64 = cfg.get("precision") == "float64"
    if backend == "auto":  # what measures faster (experiments/bench_multidevice.py): Numba on CPU in float64
        backend = "numba" if (jax.default_backend() == "cpu" and f64
                              and importlib.util.find_spec("numba") is not None) else "jax"
    elif backend == "numba" and not f64:
        raise ConfigError("experiment.backend=numba computes in float64: use precision=float64 or backend=jax")
    return WorkspaceGridSettings(
        grid=grid, shard=int(cfg.get("shard", 0)), n_shards=int(cfg.get("n_shards", 1)), chunk_points=chunk,
        store=tuple(store), n_dev=n_dev, params=params, backend=backend,
        resume=read_field("experiment.resume", e.get("resume", True), kind="bool"),
        checkpoint_s=read_field("experiment.checkpoint_s", e.get("checkpoint_s"), lo=0, unit="s"),
        stop_after=read_field("experiment.stop_after", e.get("stop_after"), kind="int", lo=1, none=True),
        robot_key={k: str(v) for k, v in cfg.get("robot").items()}, precision=str(cfg.get("precision")),
        plan=grid_plan(grid.shape, chunk, n_dev, int(cfg.get("shard", 0)), int(cfg.get("n_shards", 1))))


@dataclasses.dataclass(frozen=True)
class PaperGridSettings:
    """``experiment=reconfig_workspace``: the Franco-López 2026 grid, points per chunk, checkpoints on."""

    grid: Any
    chunk_points: int
    checkpoint: bool


def paper_grid_settings(e, cfg, robot, recon, bytes_per_point: float = 2.0) -> PaperGridSettings:
    # reconfig_workspace: two reachable masks (fixed R, some R) of 1 byte per point
    grid = paper_grid_from_config(e, bytes_per_point)
    out = PaperGridSettings(grid=grid,
                            chunk_points=read_field("experiment.chunk_points", e.get("chunk_points"), kind="int", lo=1),
                            checkpoint=read_field("experiment.checkpoint", e.get("checkpoint", True), kind="bool"))
    if recon is None:
        raise ConfigError(f"experiment={e.get('name')} needs a reconfigurable robot: robot.R_range is null")
    return out


@dataclasses.dataclass(frozen=True)
class ReconfigIndicesSettings:
    """``experiment=reconfig_indices``: the paper's grid, points per chunk, checkpoints on, the selection criterion
    and mode (``fast``: the reach interval prunes R samples; ``exact``: every R), the k~ parameters (``beta`` is the
    top-level one), the index of the Fig 8 planes at heights ``slices_z`` (m), the index fields stored."""

    grid: Any
    chunk_points: int
    checkpoint: bool
    criterion: str
    mode: str
    b_v: float
    b_f: float
    beta: float
    slice_index: str
    slices_z: tuple
    store_fields: tuple


def reconfig_indices_settings(e, cfg, robot, recon) -> ReconfigIndicesSettings:
    from ..indices import INDEX_NAMES

    store = read_names("experiment.store_fields", e.get("store_fields"), INDEX_NAMES)
    # per point: two masks, R* and every stored field at R* and at fixed R (float32), the slice index field
    paper = paper_grid_settings(e, cfg, robot, recon, bytes_per_point=2 + 4 * (2 * len(store) + 2))
    grid = paper.grid
    z0, z1 = float(grid.z[0]), float(grid.z[-1])
    # a plane of the grid below the base (the nearest is drawn)
    zs = tuple(read_field(f"experiment.slices_z[{i}]", z, lo=max(z0, 0.0), hi=z1, lo_open=z0 <= 0.0, unit="m")
               for i, z in enumerate(e.get("slices_z") or []))
    return ReconfigIndicesSettings(
        grid=grid, chunk_points=paper.chunk_points, checkpoint=paper.checkpoint,
        beta=read_field("beta", cfg.get("beta"), lo=0, hi=1, lo_open=True, hi_open=True),
        b_v=read_field("experiment.b_v", e.get("b_v"), lo=0, lo_open=True),
        b_f=read_field("experiment.b_f", e.get("b_f"), lo=0, lo_open=True),
        criterion=read_choice("experiment.criterion", e.get("criterion"), INDEX_NAMES),
        mode=read_choice("experiment.mode", e.get("mode"), ("fast", "exact")),
        slice_index=read_choice("experiment.slice_index", e.get("slice_index"), INDEX_NAMES),
        slices_z=zs, store_fields=tuple(store))


@dataclasses.dataclass(frozen=True)
class BenchKernelSettings:
    """``experiment=bench_kernel``: points timed (JAX kernel, NumPy reference), points per block (0: one vmap),
    best of ``repeats`` warm timings, the evaluated robot's base radius ``R`` (m), the dtypes timed."""

    n_points: int
    n_baseline: int
    block: int
    repeats: int
    R: float
    dtypes: tuple


def bench_kernel_settings(e, cfg, robot, recon) -> BenchKernelSettings:
    n = {k: read_field(f"experiment.{k}", e.get(k), kind="int", lo=1) for k in ("n_points", "n_baseline", "repeats")}
    block = read_field("experiment.block", e.get("block"), kind="int", lo=0)   # 0: one plain vmap
    for k in ("n_points", "n_baseline"):  # the points (3 coordinates) and their index values, float64
        check_fits(f"experiment.{k}", e.get(k), float(e.get(k)) * 8 * 12, f"{e.get(k)} points")
    dtypes = read_names("experiment.dtypes", e.get("dtypes"), ("float32", "float64"), min_len=1)
    if cfg.get("precision") != "float64" and "float64" in dtypes:
        raise ConfigError("experiment.dtypes lists float64, which needs precision=float64 (got precision="
                          f"{cfg.get('precision')})")
    return BenchKernelSettings(block=block, R=read_field("experiment.R", e.get("R"), lo=0, lo_open=True, unit="m"),
                               dtypes=tuple(dtypes), **n)


def _point_below_base(path: str, v: Any) -> list:
    """A platform position (m) in the half-space z > 0 below the base (the base frame's z points down)."""
    p = read_vector(path, v, 3)
    if not p[2] > 0:
        raise ConfigError(f"{path}={p!r} m lies above the base plane: a platform position needs z > 0 m (the base "
                          f"frame's z points down), got z = {p[2]!r} m")
    return p


@dataclasses.dataclass(frozen=True)
class IndicesExamplesSettings:
    """``experiment=indices_examples``: the R curves' step (m), the paper's example points (m, base frame, z down),
    the k~ parameters and the Jacobian form."""

    R_step: float
    points: tuple
    b_v: float
    b_f: float
    beta: float
    matrix: str


def indices_examples_settings(e, cfg=None, robot=None, recon=None) -> IndicesExamplesSettings:
    """``experiment.*`` of indices_examples (the paper's example points, the R curve step)."""
    if recon is None:
        raise ConfigError("experiment=indices_examples needs a reconfigurable robot: robot.R_range is null")
    from ..indices import INDEX_NAMES

    R_step = read_field("experiment.R_step", e.get("R_step"), lo=0, lo_open=True, unit="m")
    points = [_point_below_base(f"experiment.points[{i}]", p) for i, p in enumerate(e.get("points") or [])]
    n_R = _n_steps(float(recon.R_min), float(recon.R_max), R_step)  # every index at every R of each point's curve
    check_fits("experiment.R_step", R_step, 8.0 * n_R * max(1, len(points)) * len(INDEX_NAMES),
          f"{n_R:.3g} R samples of each point's index curves", unit="m")
    return IndicesExamplesSettings(
        R_step=R_step, points=tuple(tuple(p) for p in points),
        b_v=read_field("experiment.b_v", e.get("b_v"), lo=0, lo_open=True),
        b_f=read_field("experiment.b_f", e.get("b_f"), lo=0, lo_open=True),
        beta=read_field("experiment.beta", e.get("beta"), lo=0, hi=1, lo_open=True, hi_open=True),
        matrix=read_choice("experiment.matrix", e.get("matrix"), ("theta3x3", "full3x4")))


def _cycle_setup(s, path: str) -> dict:
    out = dict(centre=read_vector(f"{path}.centre", s.get("centre"), 3),
               heading_deg=read_field(f"{path}.heading_deg", s.get("heading_deg"), unit="deg"))
    for k, unit in (("duration", "s"), ("torque_limit", "N m"), ("speed_limit", "rad/s")):
        out[k] = read_field(f"{path}.{k}", s.get(k), lo=0, lo_open=True, unit=unit)
    return out


@dataclasses.dataclass(frozen=True)
class DynamicsCycleSettings:
    """``experiment=dynamics_cycle``: the inverse-dynamics formulation, cycle samples, motion law and blend, the
    presets analysed besides the config robot (named ``cfg_name``), each robot's cycle setup (centre m, heading
    deg, duration s, torque N m and speed rad/s limits), the GA paper's motion (rad, s), the moving-R amplitude (m)."""

    method: str
    n_samples: int
    law: str
    blend: float
    robots: tuple
    cfg_name: str
    setups: dict
    ga_amplitude: float
    ga_duration: float
    recon_R_amplitude: float


def dynamics_cycle_spec(e, cfg=None, robot=None, recon=None) -> DynamicsCycleSettings:
    """``experiment.*`` of dynamics_cycle; ``setups`` holds one entry per analysed robot name (its own block or
    ``default``), the config robot's under ``cfg_name``."""
    from .. import presets
    from ..trajectory import MOTION_LAWS

    if robot is not None and robot.mass is None:
        raise ConfigError("experiment=dynamics_cycle needs a mass model: add a `mass:` block to the robot config "
                          f"(robot.mass), robot {(cfg or {}).get('robot', {}).get('name')!r} has none")
    robots = list(e.get("robots") or [])
    for name in robots:
        read_choice("experiment.robots entry", name, presets.PRESETS)
    cfg_name = "robot" if cfg is None else str(cfg.get("robot", {}).get("name", "robot"))
    blocks = e.get("setups") or {}
    setups = {}
    for name in [cfg_name] + robots:
        key = name if name in blocks else "default"
        if key not in blocks:
            raise ConfigError(f"experiment.setups.{name} (or experiment.setups.default) is required")
        setups[name] = _cycle_setup(blocks.get(key), f"experiment.setups.{key}")
    gm = e.get("ga_motion") or {}
    amp = read_field("experiment.recon_R_amplitude", e.get("recon_R_amplitude"), lo=0, unit="m")
    if recon is not None and amp != 0.0:
        R0, lo, hi = float(recon.robot.base_radius), float(recon.R_min), float(recon.R_max)
        if not (lo <= R0 - amp and R0 + amp <= hi + 1e-12):
            raise ConfigError(f"experiment.recon_R_amplitude={amp!r} m takes R = {R0} +- {amp} m outside "
                              f"[{lo}, {hi}] m")
    n_samples = read_field("experiment.n_samples", e.get("n_samples"), kind="int", lo=11)
    # positions, velocities and accelerations of every analysed robot's cycle (float64), at least
    check_fits("experiment.n_samples", n_samples, 72.0 * n_samples * len(setups), f"{len(setups)} cycles of "
          f"{n_samples} samples")
    return DynamicsCycleSettings(
                method=read_choice("experiment.method", e.get("method"), ("virtual_work", "lagrange")),
                n_samples=n_samples,
                law=read_choice("experiment.law", e.get("law"), MOTION_LAWS),
                blend=read_field("experiment.blend", e.get("blend"), lo=0, hi=1, hi_open=True),
                robots=tuple(robots), cfg_name=cfg_name, setups=setups,
                ga_amplitude=read_field("experiment.ga_motion.amplitude", gm.get("amplitude"), lo=0, lo_open=True,
                                    unit="rad"),
                ga_duration=read_field("experiment.ga_motion.duration", gm.get("duration"), lo=0, lo_open=True, unit="s"),
                recon_R_amplitude=amp)


def _search_centre(path: str, v: Any, centre: list, robot) -> None:
    """A boundary search starts from its centre: outside the workspace it would measure nothing (a NaN sector
    volume); refused unless the inverse kinematics of ``centre`` succeeds within the joint limits."""
    if robot is None:
        return
    from ..workspace.grid import reachable_point

    if not bool(reachable_point(robot, centre)):
        raise ConfigError(f"{path}={v!r} m puts the search centre {centre!r} m outside the robot's workspace (no "
                          f"inverse kinematics within the joint limits there); choose a reachable centre")


@dataclasses.dataclass(frozen=True)
class DatasheetSettings:
    """``experiment=datasheet`` and the top-level ``source`` (kg, s, m, N m, rad/s); ``kind``: "preset" or
    "run_dir"."""

    source: str
    kind: str
    payloads: tuple
    vendor_dwell: float
    hd_ratio: float
    volume_h: float
    n_samples: int
    cylinder_grid: tuple
    centre: Optional[tuple]
    R: Optional[float]
    motor: dict
    gear_ratio: float
    source_space: Any = None            # kind "run_dir": the source run's design space, rebuilt from its settings
    source_motor: Optional[dict] = None  # kind "run_dir": the source run's motor settings


def source_run(src: str) -> tuple:
    """(design space, motor settings) of the ga_reconfig run in directory ``src`` (its stored config rebuilt)."""
    import os

    import yaml

    from .. import io

    try:
        attrs = io.read(os.path.join(src, "results.h5"), max_elements=0).attrs
        cfg = yaml.safe_load(attrs["config"])
    except (OSError, KeyError, ValueError, yaml.YAMLError) as err:
        raise ConfigError(f"source={src!r}: its results.h5 cannot be read as a run ({type(err).__name__}: "
                          f"{err})") from None
    if not isinstance(cfg, Mapping) or (cfg.get("experiment") or {}).get("name") != "ga_reconfig":
        name = (cfg.get("experiment") or {}).get("name") if isinstance(cfg, Mapping) else None
        raise ConfigError(f"source={src!r} is a {name!r} run, not ga_reconfig")
    robot, recon = robot_from_config(cfg["robot"])
    s, space = ga_reconfig_build(cfg["experiment"], robot, recon)[:2]
    return space, s.motor


def datasheet_settings(e, cfg=None, robot=None, recon=None) -> DatasheetSettings:
    """``experiment.*`` and the top-level ``source`` of the datasheet job (kg, s, m, N m, rad/s).

    ``source``: a :data:`deltajax.presets.PRESETS` name (with ``experiment.motor`` and ``experiment.gear_ratio``) or
    a ga_reconfig run directory (its baseline and recommended designs with the run's own motor and gear ratios).
    """
    import os

    from .. import presets

    src = (cfg or {}).get("source")
    if src is None or str(src) == "":
        raise ConfigError("source is required: a preset name (" + ", ".join(sorted(presets.PRESETS))
                          + ") or a ga_reconfig run directory (containing results.h5)")
    src = str(src)
    if src in presets.PRESETS:
        kind = "preset"
    elif os.path.isfile(os.path.join(os.path.expanduser(src), "results.h5")):
        kind = "run_dir"
        src = os.path.abspath(os.path.expanduser(src))
    else:
        raise ConfigError(f"source={src!r} is neither a preset ({', '.join(sorted(presets.PRESETS))}) nor a run "
                          "directory with a results.h5")
    pos = lambda k, unit: read_field(f"experiment.{k}", e.get(k), lo=0, lo_open=True, unit=unit)  # noqa: E731
    payloads = [read_field(f"experiment.payloads[{i}]", p, lo=0, unit="kg") for i, p in enumerate(e.get("payloads") or [])]
    if not payloads:
        raise ConfigError("experiment.payloads must list at least one payload (kg)")
    grid = e.get("cylinder_grid") or []
    if len(grid) != 3:
        raise ConfigError(f"experiment.cylinder_grid must be [rings, angles, levels], got {list(grid)!r}")
    mcfg = e.get("motor") or {}
    motor = {k: read_field(f"experiment.motor.{k}", mcfg.get(k), lo=0, lo_open=(k != "rotor_inertia"), unit=u)
             for k, u in (("peak_torque", "N m"), ("rated_torque", "N m"), ("max_speed", "rad/s"),
                          ("corner_speed", "rad/s"), ("rotor_inertia", "kg m^2"), ("efficiency", "1"))}
    for lo_k, hi_k, unit in (("rated_torque", "peak_torque", "N m"), ("corner_speed", "max_speed", "rad/s")):
        if motor[lo_k] > motor[hi_k]:
            raise ConfigError(f"experiment.motor.{lo_k}={motor[lo_k]!r} {unit} must be <= experiment.motor.{hi_k}="
                              f"{motor[hi_k]!r} {unit}")
    if motor["efficiency"] > 1:
        raise ConfigError(f"experiment.motor.efficiency must be in (0, 1], got {motor['efficiency']!r}")
    centre = e.get("centre")
    R = e.get("R")
    return DatasheetSettings(
        source=src, kind=kind, payloads=tuple(payloads),
        vendor_dwell=read_field("experiment.vendor_dwell", e.get("vendor_dwell"), lo=0, unit="s"),
        hd_ratio=pos("hd_ratio", "1"), volume_h=pos("volume_h", "m"),
        n_samples=read_field("experiment.n_samples", e.get("n_samples"), kind="int", lo=3),
        cylinder_grid=tuple(read_field(f"experiment.cylinder_grid[{i}]", g, kind="int", lo=2)
                            for i, g in enumerate(grid)),
        centre=None if centre is None else tuple(read_vector("experiment.centre", centre, 3)),
        R=None if R is None else read_field("experiment.R", R, lo=0, lo_open=True, unit="m"),
        motor=motor, gear_ratio=pos("gear_ratio", "motor speed / arm speed"),
        **(dict(zip(("source_space", "source_motor"), source_run(src))) if kind == "run_dir" else {}))


@dataclasses.dataclass(frozen=True)
class BoundarySearchSettings:
    """``experiment=boundary_search`` (m, deg): the search centre, bisection tolerance and ray length, angular
    steps, predictor, half space, volume rule, profile samples, the reference grid (spacing, box), the centre sweep
    and the timing repeats."""

    eps: float
    rho_max: float
    grid_h: float
    sweep_step_deg: float
    centre: list
    steps_deg: list
    predictor: str
    volume_rule: str
    profile_samples: int
    grid_box: list
    centre_sweep_z: list
    half_space: bool
    timing_repeats: int


def boundary_search_spec(e, cfg=None, robot=None, recon=None) -> BoundarySearchSettings:
    """``experiment.*`` of boundary_search (m, deg)."""
    from ..workspace import boundary as B

    pos = lambda k, unit: read_field(f"experiment.{k}", e.get(k), lo=0, lo_open=True, unit=unit)  # noqa: E731
    out = dict(eps=pos("eps", "m"), rho_max=pos("rho_max", "m"), grid_h=pos("grid_h", "m"),
               sweep_step_deg=pos("sweep_step_deg", "deg"),
               centre=read_vector("experiment.centre", e.get("centre"), 3))
    _search_centre("experiment.centre", out["centre"], out["centre"], robot)
    if out["rho_max"] <= out["eps"]:
        raise ConfigError(f"experiment.rho_max must exceed experiment.eps, got {out['rho_max']} m <= {out['eps']} m")
    steps = [read_field(f"experiment.steps_deg[{i}]", s, lo=0, lo_open=True, unit="deg")
             for i, s in enumerate(e.get("steps_deg") or [])]
    if not steps:
        raise ConfigError("experiment.steps_deg must list at least one angular step (deg)")
    for s in steps:
        try:
            B.angle_grid(s)
        except (ValueError, TypeError) as err:
            raise ConfigError(f"experiment.steps_deg: {err}") from None
    out["steps_deg"] = steps
    out["predictor"] = read_choice("experiment.predictor", e.get("predictor"), B.PREDICTORS)
    out["volume_rule"] = read_choice("experiment.volume_rule", e.get("volume_rule"), B.VOLUME_RULES)
    out["profile_samples"] = read_field("experiment.profile_samples", e.get("profile_samples"), kind="int", lo=2)
    box = e.get("grid_box")
    if not hasattr(box, "__len__") or len(box) != 3:
        raise ConfigError(f"experiment.grid_box must be [[x0, x1], [y0, y1], [z0, z1]] (m), got {box!r}")
    box = [read_vector(f"experiment.grid_box[{i}]", b, 2) for i, b in enumerate(box)]
    for (a, b), name in zip(box, "xyz"):
        if not b > a:
            raise ConfigError(f"experiment.grid_box {name} side must have lo < hi (m), got {[a, b]!r}")
        k = (b - a) / out["grid_h"]
        if abs(k - round(k)) > 1e-6 * k:
            raise ConfigError(f"experiment.grid_box {name} side ({a}, {b}) m is not a whole number of "
                              f"experiment.grid_h = {out['grid_h']} m")
    out["grid_box"] = box
    out["centre_sweep_z"] = [read_field(f"experiment.centre_sweep_z[{i}]", z, unit="m")
                             for i, z in enumerate(e.get("centre_sweep_z") or [])]
    for i, z in enumerate(out["centre_sweep_z"]):  # each swept centre starts a search as the centre does
        _search_centre(f"experiment.centre_sweep_z[{i}]", z, [out["centre"][0], out["centre"][1], z], robot)
    out["half_space"] = read_field("experiment.half_space", e.get("half_space", True), kind="bool")
    out["timing_repeats"] = read_field("experiment.timing_repeats", e.get("timing_repeats", 3), kind="int", lo=1)
    return BoundarySearchSettings(**out)


#: the numeric settings of experiment.mechanism (deltajax.mechanism.example_screw_linkage / DirectRadial), with the
#: ranges the mechanism needs, checked in the units the config writes them in
MECHANISM_FIELDS = {
    "lead": dict(lo=0, lo_open=True, unit="m"), "d2": dict(lo=0, lo_open=True, unit="m"), "d3": dict(unit="m"),
    "sweep_deg": dict(lo=0, hi=90, lo_open=True, hi_open=True, unit="deg"),
    "efficiency": dict(lo=0, hi=1, lo_open=True), "back_efficiency": dict(lo=0, hi=1, lo_open=True),
    "gear_ratio": dict(lo=0, lo_open=True), "assembly": dict(kind="int", choices=(1, -1)),
    "nut_side": dict(kind="int", choices=(1, -1)),
}


@dataclasses.dataclass(frozen=True)
class ReconfigMotionSettings:
    """``experiment=reconfig_motion``: the selection criterion and aggregate, the k~ parameters, the R step (m) and
    the robot's R samples at it (``recon``), the arms' torque (N m) and speed (rad/s) limits, the R drive limits
    (:class:`deltajax.RDriveLimits`), the reconfiguration mechanism (and its range check), the spline
    refinement, and each case's (Cartesian cycle, boundary condition)."""

    criterion: str
    aggregate: str
    b_v: float
    b_f: float
    R_step: float
    torque_limit: float
    speed_limit: float
    beta: float
    drive: Any
    recon: Any
    mech: Any
    refine: dict
    cases: dict
    mech_info: Optional[dict] = None


def reconfig_motion_spec(e, cfg=None, robot=None, recon=None, dtype=None) -> ReconfigMotionSettings:
    """``experiment.*`` of reconfig_motion as plain values and library objects: the R drive limits
    (:class:`deltajax.RDriveLimits`), the reconfiguration mechanism, and each case's Cartesian cycle."""
    import jax.numpy as jnp

    from .. import trajectory as tr
    from ..indices import INDEX_NAMES
    from ..mechanism import MECHANISMS, DirectRadial, example_screw_linkage
    from ..motion import AGGREGATES, BOUNDARIES, RDriveLimits

    if recon is None:
        raise ConfigError("experiment=reconfig_motion needs a reconfigurable robot: robot.R_range is null")
    if recon.robot.mass is None:
        raise ConfigError("experiment=reconfig_motion needs a mass model: robot.mass is null")
    pos = lambda k, unit="": read_field(f"experiment.{k}", e.get(k), lo=0, lo_open=True, unit=unit)  # noqa: E731
    out = dict(criterion=read_choice("experiment.criterion", e.get("criterion", "k_tilde"), INDEX_NAMES),
               aggregate=read_choice("experiment.aggregate", e.get("aggregate", "integral"), AGGREGATES),
               b_v=pos("b_v"), b_f=pos("b_f"), R_step=pos("R_step", "m"), torque_limit=pos("torque_limit", "N m"),
               speed_limit=pos("speed_limit", "rad/s"),
               beta=read_field("experiment.beta", e.get("beta", 0.5), lo=0, hi=1, lo_open=True, hi_open=True))
    d = e.get("drive")
    if d is None:
        raise ConfigError("experiment.drive is required (speed m/s, acceleration m/s^2, force N)")
    lim = {k: read_field(f"experiment.drive.{k}", d.get(k), lo=0, lo_open=True, unit=unit)
           for k, unit in (("speed", "m/s"), ("acceleration", "m/s^2"), ("force", "N"))}
    out["drive"] = RDriveLimits(**lim)
    try:  # the DP's R samples: the robot's range at experiment.R_step
        out["recon"] = ReconfigurableDelta.from_range(recon.robot, float(recon.R_min), float(recon.R_max),
                                                      out["R_step"])
    except GeometryError as err:
        raise ConfigError(f"experiment.R_step={out['R_step']!r} m: {err}") from None
    # the DP's table: every R sample at every time sample of a case (3 at least)
    check_fits("experiment.R_step", out["R_step"], 3 * 8.0 * out["recon"].n_R,
          f"{out['recon'].n_R:.3g} R samples at each time sample", unit="m")
    mech = dict(e.get("mechanism") or {})
    kind = read_choice("experiment.mechanism.kind", mech.pop("kind", "screw_linkage"), MECHANISMS)
    for k, v in mech.items():  # in the units the config gives them (the linkage stores lead as a pitch in m/rad)
        if k in MECHANISM_FIELDS:
            rule = dict(MECHANISM_FIELDS[k])
            choices = rule.pop("choices", None)
            mech[k] = read_field(f"experiment.mechanism.{k}", v, **rule)
            if choices is not None and mech[k] not in choices:
                raise ConfigError(f"experiment.mechanism.{k} must be one of {', '.join(map(str, choices))}, "
                                  f"got {v!r}")
    try:
        if kind == "direct":
            out["mech"] = DirectRadial(**mech)
        else:
            R0, R1 = float(recon.R_min), float(recon.R_max)
            out["mech"] = example_screw_linkage(R0, R1, **mech)
            out["mech_info"] = out["mech"].check_range(R0, R1)
    except (TypeError, ValueError) as err:
        raise ConfigError(f"experiment.mechanism: {err}") from None
    ref = e.get("refine") or {}
    out["refine"] = dict(enabled=read_field("experiment.refine.enabled", ref.get("enabled", True), kind="bool"),
                         n_ctrl=read_field("experiment.refine.n_ctrl", ref.get("n_ctrl", 16), kind="int", lo=6),
                         steps=read_field("experiment.refine.steps", ref.get("steps", 150), kind="int", lo=1),
                         learning_rate=read_field("experiment.refine.learning_rate", ref.get("learning_rate", 2e-4),
                                              lo=0, lo_open=True))
    cases = e.get("cases")
    if not cases:
        raise ConfigError("experiment.cases must list at least one case")
    dtype = jnp.result_type(float) if dtype is None else dtype
    out["cases"] = {}
    for name, c in cases.items():
        p = f"experiment.cases.{name}"
        kind = read_choice(f"{p}.kind", c.get("kind"), ("adept", "task"))
        boundary = read_choice(f"{p}.boundary", c.get("boundary", "free"), BOUNDARIES)
        law = read_choice(f"{p}.law", c.get("law", "poly5"), tr.MOTION_LAWS)
        # the cycle's samples (position, velocity, acceleration) and the DP's table over them and the R samples
        key = "n_samples" if kind == "adept" else "samples_per_segment"
        per = read_field(f"{p}.{key}", c.get(key), kind="int", lo=3 if kind == "adept" else 2)
        n_t = per * (1 if kind == "adept" else max(1, len(c.get("points") or [])))
        check_fits(f"{p}.{key}", per, n_t * (72.0 + 8.0 * out["recon"].n_R),
              f"{n_t} cycle samples x {out['recon'].n_R} R samples (the DP's table)")
        try:
            if kind == "adept":
                cyc = tr.adept_cycle(read_vector(f"{p}.centre", c.get("centre"), 3),
                                     heading=math.radians(read_field(f"{p}.heading_deg", c.get("heading_deg"), unit="deg")),
                                     duration=read_field(f"{p}.duration", c.get("duration"), lo=0, lo_open=True, unit="s"),
                                     law=law, blend=read_field(f"{p}.blend", c.get("blend", 0.5), lo=0, hi=1, hi_open=True),
                                     n_samples=read_field(f"{p}.n_samples", c.get("n_samples"), kind="int", lo=3),
                                     dtype=dtype)
            else:
                pts = [read_vector(f"{p}.points[{i}]", q, 3) for i, q in enumerate(c.get("points") or [])]
                cyc = tr.task_path(pts, segment_duration=read_field(f"{p}.segment_duration", c.get("segment_duration"),
                                                                lo=0, lo_open=True, unit="s"),
                                   law=law, samples_per_segment=read_field(f"{p}.samples_per_segment",
                                                                       c.get("samples_per_segment"), kind="int", lo=2),
                                   closed=read_field(f"{p}.closed", c.get("closed", False), kind="bool"), dtype=dtype)
        except ValueError as err:
            if isinstance(err, ConfigError):
                raise
            raise ConfigError(f"{p}: {err}") from None
        out["cases"][name] = (cyc, boundary)
    return ReconfigMotionSettings(**out)



#: Experiments that use the robot's R range (the others only use the fixed robot, R = base_radius).
R_RANGE_EXPERIMENTS = ("reconfig_workspace", "reconfig_indices", "indices_examples", "ga_reconfig", "dynamics_cycle")

#: experiment name -> builder(experiment cfg, whole cfg, robot, recon) of the job's settings: every field checked
#: (one ConfigError line naming it), returned as the object the run hands to the job (``RunContext.settings``).
EXPERIMENT_SETTINGS = {
    "workspace_grid": workspace_grid_settings,
    "reconfig_workspace": paper_grid_settings,
    "reconfig_indices": reconfig_indices_settings,
    "indices_examples": indices_examples_settings,
    "bench_kernel": bench_kernel_settings,
    "dynamics_cycle": dynamics_cycle_spec,
    "boundary_search": boundary_search_spec,
    "reconfig_motion": reconfig_motion_spec,
    "ga_reconfig": validate_ga_reconfig,
    "datasheet": datasheet_settings,
}


#: experiment name -> a check of its settings against the run directory (``run_dir``), where a setting can name it
RUN_DIR_CHECKS = {"ga_reconfig": validate_ga_reconfig_run_dir}


def validate_config(cfg: Mapping[str, Any], robot=None, recon=None, *, run_dir=None) -> Any:
    """Check every field of the composed config before anything is computed, and build the job's settings.

    Top-level keys (unknown ones rejected, types and ranges), then the experiment block with its builder in
    :data:`EXPERIMENT_SETTINGS` (types, ranges, NaN, cross-field rules). The robot block is checked by
    :func:`robot_from_config`.

    Returns:
        the job's settings (what the run hands to the job as ``RunContext.settings``; the job reads no config).

    Raises:
        ConfigError: one line naming the field (dotted path) and the value.
    """
    check_keys(cfg)
    _validate_top(cfg)
    e = cfg.get("experiment") or {}
    if cfg.get("source") is not None and e.get("name") not in SOURCE_EXPERIMENTS:
        raise ConfigError(f"source={cfg.get('source')!r} is read only by experiment="
                          f"{'|'.join(SOURCE_EXPERIMENTS)}, not by experiment={e.get('name')}")
    if recon is not None and e.get("name") in R_RANGE_EXPERIMENTS:
        check_reach_over_range(cfg.get("robot"), recon)
    if run_dir is not None and e.get("name") in RUN_DIR_CHECKS:
        RUN_DIR_CHECKS[e.get("name")](e, run_dir)
    build = EXPERIMENT_SETTINGS.get(e.get("name"))
    return None if build is None else build(e, cfg, robot, recon)


from ..schemas import EXPERIMENT_SCHEMAS, RobotSchema, register_schemas, schema_keys, unknown_key  # noqa: E402


def check_keys(cfg: Mapping[str, Any]) -> None:
    """Reject keys that no schema knows, including those added with ``+key=value`` (Hydra adds them even to a
    structured config), listing the valid keys of that block.

    Raises:
        ConfigError: one line naming the unknown key and the valid ones.
    """
    extra = [k for k in cfg.keys() if k not in TOP_LEVEL_KEYS]
    if extra:
        raise ConfigError(f"unknown top-level key(s) {', '.join(map(str, extra))}; "
                          f"valid keys: {', '.join(TOP_LEVEL_KEYS)}")
    e = cfg.get("experiment")
    blocks = (("robot", cfg.get("robot"), RobotSchema),
              ("experiment", e, EXPERIMENT_SCHEMAS.get(e.get("name")) if e is not None else None))
    for path, node, schema in blocks:
        msg = None if node is None or schema is None else unknown_key(node, schema, path)
        if msg is not None:
            raise ConfigError(msg)


def valid_keys(full_key: str, experiment: Optional[str] = None) -> Optional[list]:
    """The valid keys of the block holding ``full_key`` (e.g. ``"robot.forarm"`` -> the robot's keys), from the
    schemas; ``None`` when no schema covers it. For error messages of Hydra's composition, which name the
    unknown key but not the valid ones (``Key 'forarm' not in 'RobotSchema'``)."""
    parts = full_key.split(".")
    if len(parts) == 1:
        return list(TOP_LEVEL_KEYS)
    schema = RobotSchema if parts[0] == "robot" else EXPERIMENT_SCHEMAS.get(experiment or "")
    if parts[0] not in ("robot", "experiment") or schema is None:
        return None
    return schema_keys(schema, parts[1:-1])


def mass_from_config(mass_cfg: Mapping[str, Any], geometry_kwargs: Optional[Mapping[str, Any]] = None,
                     prefix: str = "robot.mass") -> MassModel:
    """Build a :class:`MassModel` from a ``mass:`` config block, validating every field first.

    Fields: those of :class:`MassModel` (``upper_arm_mass`` required, the others default as documented;
    ``forearm_model`` is ``rigid_rod`` or ``point_split``) plus,
    instead of ``upper_arm_inertia_factor``, an absolute ``upper_arm_inertia`` (kg m^2 about the upper arm's
    centre of mass), converted with the config's ``upper_arm`` length L1 (taken from ``geometry_kwargs``).

    Args:
        mass_cfg: mapping (OmegaConf or dict).
        geometry_kwargs: the robot's geometry (``upper_arm`` in m) for the inertia conversion.
        prefix: dotted path used in error messages.

    Raises:
        ConfigError: unknown, missing, non-numeric or out-of-range field; the message names
            ``<prefix>.<field>`` and the value.
    """
    known = {name for name, _u, _k in MASS_FIELDS} | {"upper_arm_inertia", "forearm_model"}
    keys = list(mass_cfg.keys())
    for k in keys:
        if k not in known:
            raise ConfigError(f"{prefix}.{k} is not a mass-model field; valid keys: {', '.join(sorted(known))}")
    ranges = {"nonneg": dict(lo=0), "pos": dict(lo=0, lo_open=True), "frac": dict(lo=0, hi=1)}
    kinds = {name: kind for name, _u, kind in MASS_FIELDS}
    units = {name: u for name, u, _k in MASS_FIELDS if u != "1"} | {"upper_arm_inertia": "kg m^2"}
    values: dict[str, Any] = {}
    for k in keys:
        v = mass_cfg[k]
        if v is None:
            continue
        if k == "forearm_model":
            values[k] = str(read_choice(f"{prefix}.forearm_model", v, FOREARM_MODELS))
        else:
            values[k] = read_field(f"{prefix}.{k}", v, unit=units.get(k, ""), **ranges[kinds.get(k, "nonneg")])
    if values.get("forearm_model") == "point_split" and "forearm_inertia_factor" in values:
        raise ConfigError(f"{prefix}.forearm_inertia_factor={values['forearm_inertia_factor']!r} applies to "
                          "forearm_model: rigid_rod only (point_split's inertia is that of its two end masses)")
    if "upper_arm_mass" not in values:
        raise ConfigError(f"{prefix}.upper_arm_mass is required")
    if "upper_arm_inertia" in values:
        if "upper_arm_inertia_factor" in values:
            raise ConfigError(f"{prefix}: give upper_arm_inertia or upper_arm_inertia_factor, not both")
        inertia = values.pop("upper_arm_inertia")
        L1 = None if geometry_kwargs is None else geometry_kwargs.get("upper_arm")
        m = values["upper_arm_mass"]
        if L1 is None or not float(L1) > 0:
            raise ConfigError(f"{prefix}.upper_arm_inertia needs the robot's upper_arm length, got {L1!r}")
        if inertia > 0 and m == 0:
            raise ConfigError(f"{prefix}.upper_arm_inertia={inertia!r} kg m^2 needs upper_arm_mass > 0")
        values["upper_arm_inertia_factor"] = 0.0 if m == 0 else inertia / (m * float(L1) ** 2)
    try:
        return MassModel(**values)
    except MassError as e:  # the rigid-rod inertia bound couples two fields; the message names them
        raise ConfigError(f"{prefix}.{e}") from None
