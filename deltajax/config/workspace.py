"""Reads ``experiment.*`` of the grid jobs and the kernel benchmark (the grids they share, refused before they
are built when they do not fit in memory):

- :class:`WorkspaceGridSettings` (``experiment=workspace_grid``): the grid (:func:`workspace_grid_from_config`) and
  its shard plan (:func:`grid_plan`);
- :class:`PaperGridSettings` (``experiment=reconfig_workspace``): the paper's grid (:func:`paper_grid_from_config`);
- :class:`ReconfigIndicesSettings` (``experiment=reconfig_indices``);
- :class:`BenchKernelSettings` (``experiment=bench_kernel``);
- :class:`IndicesExamplesSettings` (``experiment=indices_examples``).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping, Optional

from .readers import ConfigError, check_fits, read_choice, read_field, read_names, read_vector
from .robot import n_steps

__all__ = ["workspace_grid_from_config", "paper_grid_from_config", "WorkspaceGridSettings", "grid_plan",
           "workspace_grid_settings", "PaperGridSettings", "paper_grid_settings", "ReconfigIndicesSettings",
           "reconfig_indices_settings", "BenchKernelSettings", "bench_kernel_settings", "IndicesExamplesSettings",
           "indices_examples_settings"]


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
    n_R = n_steps(float(recon.R_min), float(recon.R_max), R_step)  # every index at every R of each point's curve
    check_fits("experiment.R_step", R_step, 8.0 * n_R * max(1, len(points)) * len(INDEX_NAMES),
          f"{n_R:.3g} R samples of each point's index curves", unit="m")
    return IndicesExamplesSettings(
        R_step=R_step, points=tuple(tuple(p) for p in points),
        b_v=read_field("experiment.b_v", e.get("b_v"), lo=0, lo_open=True),
        b_f=read_field("experiment.b_f", e.get("b_f"), lo=0, lo_open=True),
        beta=read_field("experiment.beta", e.get("beta"), lo=0, hi=1, lo_open=True, hi_open=True),
        matrix=read_choice("experiment.matrix", e.get("matrix"), ("theta3x3", "full3x4")))

