"""Reads ``experiment.*`` of the grid jobs and the kernel benchmark (the grids they share, refused before they
are built when they do not fit in memory). Each job's settings are one frozen dataclass mirroring its
``configs/experiment/<job>.yaml`` (fields in the YAML's order), every field's range, unit and choices declared once
(:func:`deltajax.config.readers.setting`) and checked by the one generic reader
(:func:`deltajax.config.readers.read_settings`); a builder adds only what needs context the block does not have
(the robot, the machine's memory, the JAX devices, the top-level keys):

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
import importlib.util

import jax

from .readers import ConfigError, check_fits, read_field, read_names, read_box, read_settings, read_vector, setting
from .robot import n_steps
from ..indices import INDEX_NAMES
from ..workspace import franco2026_grid, make_grid
from ..workspace.driver import reach_box
from ..workspace.chunks import ShardPlan

__all__ = ["workspace_grid_from_config", "paper_grid_from_config", "WorkspaceGridSettings", "GridBlock", "grid_plan",
           "workspace_grid_settings", "PaperGridSettings", "paper_grid_settings", "ReconfigIndicesSettings",
           "reconfig_indices_settings", "BenchKernelSettings", "bench_kernel_settings", "IndicesExamplesSettings",
           "indices_examples_settings"]


def _index_names():
    return INDEX_NAMES


def _index_list(path: str, v: Any) -> tuple:
    """A list of index names (any of :data:`deltajax.indices.INDEX_NAMES`; null: none)."""
    return tuple(read_names(path, v, _index_names()))


def _grid_fits(path: str, h: float, axes, bytes_per_point: float) -> None:
    """Refuse a grid whose points (``bytes_per_point`` each, a lower bound of what the job holds per point) or
    axes do not fit in memory, from the axis lengths alone (before any axis is built)."""
    n = [math.floor((hi - lo) / h + 1e-6) + 1 for lo, hi in axes]
    total = float(n[0]) * n[1] * n[2]
    check_fits(path, h, max(total * bytes_per_point, 16.0 * max(n)),
          f"a grid of {n[0]} x {n[1]} x {n[2]} = {total:.3g} points", unit="m")


# ---- experiment.grid of workspace_grid ----
def _axis(path: str, v: Any) -> tuple:
    """An axis [lo, hi] (m) of positive width."""
    lo, hi = read_vector(path, v, 2)
    if not hi > lo:  # a zero-width box has no volume: its "volume" would be count h^3 of a plane
        raise ConfigError(f"{path} must be [lo, hi] with lo < hi (m), got {[lo, hi]!r}")
    return lo, hi


def _box(path: str, v: Any) -> tuple:
    """The box [[x0,x1],[y0,y1],[z0,z1]] (m) of ``volume_box`` (null: the grid's end points)."""
    return tuple(tuple(b) for b in read_box(path, v, optional=True))


@dataclasses.dataclass(frozen=True, kw_only=True)
class GridBlock:
    """``experiment.grid`` (m): the axes [lo, hi] (null: sized from the robot's reach bound, whole steps of h), the
    spacing ``h`` and the box of ``volume_box`` (null: the grid's end points)."""
    x: Optional[tuple] = setting(None, read=_axis)
    y: Optional[tuple] = setting(None, read=_axis)
    z: Optional[tuple] = setting(None, read=_axis)
    h: float = setting(lo=0, lo_open=True, unit="m")
    bounds: Optional[tuple] = setting(None, read=_box)

    def _check(self, path: str) -> None:
        auto = [k for k in ("x", "y", "z") if getattr(self, k) is None]
        if auto and self.bounds is not None:
            raise ConfigError(f"{path}.bounds must be null when the grid is sized from the reach bound "
                              f"({path}.{'/'.join(auto)}=null), got {[list(b) for b in self.bounds]!r}")


def _grid_of(g: GridBlock, robot, bytes_per_point: float, path: str = "experiment.grid"):
    """The :class:`deltajax.workspace.Grid` of a checked ``experiment.grid`` block (null axes from the robot's
    reach bound), refused before it is built when it does not fit in memory."""
    h = g.h
    box = reach_box(robot) if robot is not None else None

    def pair(i, key):
        v = getattr(g, key)
        if v is not None:
            return v
        if box is None:
            raise ConfigError(f"{path}.{key}=null sizes the axis from the robot's reach bound: give [lo, hi] (m) "
                              f"where there is no robot")
        lo, hi = box[i]   # from the reach bound, on whole steps of h (y symmetric: mirror halving)
        if key == "y":
            n = math.ceil(max(-lo, hi) / h - 1e-9)
            return -n * h, n * h
        return math.floor(lo / h + 1e-9) * h, math.ceil(hi / h - 1e-9) * h

    axes = (pair(0, "x"), pair(1, "y"), pair(2, "z"))
    _grid_fits(f"{path}.h", h, axes, bytes_per_point)
    try:
        return make_grid(*axes, h, bounds=None if g.bounds is None else [list(b) for b in g.bounds])
    except ValueError as err:
        raise ConfigError(f"{path}: {err}") from None


def workspace_grid_from_config(g: Mapping[str, Any], robot=None, bytes_per_point: float = 1.0):
    """The grid of ``experiment.grid`` (h, x, y, z, bounds in m; :class:`GridBlock`); an axis given as null is
    sized from the robot's reach bound (:func:`deltajax.workspace.driver.reach_box`, widened outwards to whole
    steps of h, y symmetric). Every axis must have positive width; a grid of more than the machine's memory at
    ``bytes_per_point`` is refused before it is built."""
    return _grid_of(read_settings(GridBlock, g, "experiment.grid"), robot, bytes_per_point)


def _paper_grid(path: str, h: float, bytes_per_point: float):
    _grid_fits(path, h, ((-0.4, 0.4), (-0.4, 0.4), (0.0, 0.6 - h)), bytes_per_point)
    try:
        return franco2026_grid(h)
    except ValueError as err:
        raise ConfigError(f"{path}={h!r}: {err}") from None


def paper_grid_from_config(e: Mapping[str, Any], bytes_per_point: float = 1.0):
    """The Franco-López 2026 grid at spacing ``experiment.h`` (m, default 0.002); refused before it is built when
    its points at ``bytes_per_point`` do not fit in memory."""
    h = read_field("experiment.h", e.get("h", 0.002), lo=0, lo_open=True, unit="m")
    return _paper_grid("experiment.h", h, bytes_per_point)


# ---- workspace_grid ----
def _devices(path: str, v: Any) -> Any:
    """``all`` (null: all) or a count >= 1 of JAX devices (at most those present: checked by the builder)."""
    return "all" if v in ("all", None) else read_field(path, v, kind="int", lo=1)


@dataclasses.dataclass(frozen=True, kw_only=True)
class WorkspaceGridSettings:
    """``experiment=workspace_grid``: the grid block (m; ``built_grid`` is the :class:`deltajax.workspace.Grid`
    :func:`workspace_grid_settings` builds from it, the robot sizing null axes), the k~ parameters, the
    index fields stored, points per chunk, the backend (resolved by the builder: ``auto`` is Numba on a CPU in
    float64, else JAX), the devices used, resume/checkpoint/stop settings. Derived by the builder: this job's
    shard of ``n_shards`` (top-level keys), the devices resolved (``n_dev``), what identifies the numbers for a
    resume (``robot_key``, ``precision``) and the shard plan."""
    name: str = setting("workspace_grid")
    grid: GridBlock = setting()
    b_v: float = setting(lo=0, lo_open=True)
    b_f: float = setting(lo=0, lo_open=True)
    beta: float = setting(lo=0, hi=1, lo_open=True, hi_open=True)
    store: tuple = setting((), read=_index_list)
    chunk_points: int = setting(lo=1)
    backend: str = setting("auto", choices=("auto", "jax", "numba"))
    devices: Any = setting("all", read=_devices)     # 'all' or a count
    checkpoint_s: float = setting(60.0, lo=0, unit="s")
    resume: bool = setting(True)
    stop_after: Optional[int] = setting(None, lo=1)
    # derived (no config key): filled in by workspace_grid_settings
    shard: int = 0
    n_shards: int = 1
    n_dev: int = 1
    robot_key: Optional[dict] = None
    precision: str = "float64"
    plan: Any = None     # this shard's chunks of whole x-planes (:func:`grid_plan`)
    built_grid: Any = None   # the deltajax.workspace.Grid of the grid block

    @property
    def params(self) -> dict:
        """The k~ parameters as keyword arguments."""
        return dict(b_v=self.b_v, b_f=self.b_f, beta=self.beta)


def grid_plan(shape, chunk_points: int, n_devices: int, shard: int, n_shards: int):
    """The :class:`deltajax.workspace.chunks.ShardPlan` of a workspace grid job; its refusals are
    :class:`ConfigError` (they name a setting)."""
    try:
        return ShardPlan(shape, chunk_points, n_devices, shard, n_shards)
    except ValueError as e:
        raise ConfigError(str(e)) from None


def workspace_grid_settings(e, cfg, robot, recon) -> WorkspaceGridSettings:
    s = read_settings(WorkspaceGridSettings, e, "experiment")
    f64 = cfg.get("precision") == "float64"
    shard, n_shards = int(cfg.get("shard", 0)), int(cfg.get("n_shards", 1))
    # per point of this shard: the reachable mask (1 byte) and every stored index field
    grid = _grid_of(s.grid, robot, bytes_per_point=(1 + (8 if f64 else 4) * len(s.store)) / (n_shards or 1))
    n_avail = jax.local_device_count()
    n_dev = n_avail if s.devices == "all" else read_field("experiment.devices", s.devices, kind="int", lo=1,
                                                          hi=n_avail)
    backend = s.backend
    if backend == "auto":  # what measures faster (experiments/bench_multidevice.py): Numba on CPU in float64
        backend = "numba" if (jax.default_backend() == "cpu" and f64
                              and importlib.util.find_spec("numba") is not None) else "jax"
    elif backend == "numba" and not f64:
        raise ConfigError("experiment.backend=numba computes in float64: use precision=float64 or backend=jax")
    return dataclasses.replace(
        s, built_grid=grid, backend=backend, shard=shard, n_shards=n_shards, n_dev=n_dev,
        robot_key={k: str(v) for k, v in cfg.get("robot").items()}, precision=str(cfg.get("precision")),
        plan=grid_plan(grid.shape, s.chunk_points, n_dev, shard, n_shards))


# ---- reconfig_workspace ----
@dataclasses.dataclass(frozen=True, kw_only=True)
class PaperGridSettings:
    """``experiment=reconfig_workspace``: the spacing ``h`` (m) of the Franco-López 2026 grid, points per chunk,
    checkpoints on. Derived by :func:`paper_grid_settings`: the grid (refused when it does not fit in memory)."""
    name: str = setting("reconfig_workspace")
    h: float = setting(lo=0, lo_open=True, unit="m")
    chunk_points: int = setting(lo=1)
    checkpoint: bool = setting(True)
    grid: Any = None     # derived: the paper's grid at spacing h


def paper_grid_settings(e, cfg, robot, recon, bytes_per_point: float = 2.0) -> PaperGridSettings:
    # reconfig_workspace: two reachable masks (fixed R, some R) of 1 byte per point
    s = read_settings(PaperGridSettings, e, "experiment")
    s = dataclasses.replace(s, grid=_paper_grid("experiment.h", s.h, bytes_per_point))
    if recon is None:
        raise ConfigError(f"experiment={s.name} needs a reconfigurable robot: robot.R_range is null")
    return s


# ---- reconfig_indices ----
def _heights(path: str, v: Any) -> tuple:
    """Heights z (m; each inside the grid: checked by the builder, which has the grid); null: none."""
    if v is None:
        return ()
    if isinstance(v, (str, bytes, Mapping)) or not hasattr(v, "__iter__"):
        raise ConfigError(f"{path} must be a list of heights (m), got {v!r}")
    return tuple(read_field(f"{path}[{i}]", z, unit="m") for i, z in enumerate(v))


@dataclasses.dataclass(frozen=True, kw_only=True)
class ReconfigIndicesSettings:
    """``experiment=reconfig_indices``: the paper's grid spacing ``h`` (m), the selection criterion and mode
    (``fast``: the reach interval prunes R samples; ``exact``: every R), the k~ parameters, the index of the Fig 8
    planes at heights ``slices_z`` (m), points per chunk, checkpoints on, the index fields stored. Derived by
    :func:`reconfig_indices_settings`: the grid and ``beta`` (the top-level key, the paper's tables' k~ weight)."""
    name: str = setting("reconfig_indices")
    h: float = setting(lo=0, lo_open=True, unit="m")
    criterion: str = setting("k_tilde", choices=_index_names)
    mode: str = setting("fast", choices=("fast", "exact"))
    b_v: float = setting(lo=0, lo_open=True)
    b_f: float = setting(lo=0, lo_open=True)
    slices_z: tuple = setting((), read=_heights)
    slice_index: str = setting("omega_v", choices=_index_names)
    chunk_points: int = setting(lo=1)
    checkpoint: bool = setting(True)
    store_fields: tuple = setting((), read=_index_list)
    # derived (no config key): filled in by reconfig_indices_settings
    grid: Any = None
    beta: float = 0.5


def reconfig_indices_settings(e, cfg, robot, recon) -> ReconfigIndicesSettings:
    s = read_settings(ReconfigIndicesSettings, e, "experiment")
    # per point: two masks, R* and every stored field at R* and at fixed R (float32), the slice index field
    grid = _paper_grid("experiment.h", s.h, 2 + 4 * (2 * len(s.store_fields) + 2))
    if recon is None:
        raise ConfigError(f"experiment={s.name} needs a reconfigurable robot: robot.R_range is null")
    z0, z1 = float(grid.z[0]), float(grid.z[-1])
    # a plane of the grid below the base (the nearest is drawn)
    zs = tuple(read_field(f"experiment.slices_z[{i}]", z, lo=max(z0, 0.0), hi=z1, lo_open=z0 <= 0.0, unit="m")
               for i, z in enumerate(s.slices_z))
    return dataclasses.replace(s, grid=grid, slices_z=zs,
                               beta=read_field("beta", cfg.get("beta"), lo=0, hi=1, lo_open=True, hi_open=True))


# ---- bench_kernel ----
def _dtypes(path: str, v: Any) -> tuple:
    return tuple(read_names(path, v, ("float32", "float64"), min_len=1))


@dataclasses.dataclass(frozen=True, kw_only=True)
class BenchKernelSettings:
    """``experiment=bench_kernel``: points timed (JAX kernel, NumPy reference), points per block (0: one vmap),
    best of ``repeats`` warm timings, the evaluated robot's base radius ``R`` (m), the dtypes timed."""
    name: str = setting("bench_kernel")
    n_points: int = setting(lo=1)
    n_baseline: int = setting(lo=1)
    block: int = setting(4096, lo=0)    # 0: one plain vmap
    repeats: int = setting(lo=1)
    R: float = setting(lo=0, lo_open=True, unit="m")
    dtypes: tuple = setting(read=_dtypes)


def bench_kernel_settings(e, cfg, robot, recon) -> BenchKernelSettings:
    s = read_settings(BenchKernelSettings, e, "experiment")
    for k in ("n_points", "n_baseline"):  # the points (3 coordinates) and their index values, float64
        n = getattr(s, k)
        check_fits(f"experiment.{k}", n, float(n) * 8 * 12, f"{n} points")
    if cfg.get("precision") != "float64" and "float64" in s.dtypes:
        raise ConfigError("experiment.dtypes lists float64, which needs precision=float64 (got precision="
                          f"{cfg.get('precision')})")
    return s


# ---- indices_examples ----
def _point_below_base(path: str, v: Any) -> list:
    """A platform position (m) in the half-space z > 0 below the base (the base frame's z points down)."""
    p = read_vector(path, v, 3)
    if not p[2] > 0:
        raise ConfigError(f"{path}={p!r} m lies above the base plane: a platform position needs z > 0 m (the base "
                          f"frame's z points down), got z = {p[2]!r} m")
    return p


def _points_below_base(path: str, v: Any) -> tuple:
    return tuple(tuple(_point_below_base(f"{path}[{i}]", p)) for i, p in enumerate(v or []))


@dataclasses.dataclass(frozen=True, kw_only=True)
class IndicesExamplesSettings:
    """``experiment=indices_examples``: the R curves' step (m), the paper's example points (m, base frame, z down),
    the k~ parameters and the Jacobian form."""
    name: str = setting("indices_examples")
    R_step: float = setting(lo=0, lo_open=True, unit="m")
    points: tuple = setting((), read=_points_below_base)
    b_v: float = setting(lo=0, lo_open=True)
    b_f: float = setting(lo=0, lo_open=True)
    beta: float = setting(lo=0, hi=1, lo_open=True, hi_open=True)
    matrix: str = setting("theta3x3", choices=("theta3x3", "full3x4"))


def indices_examples_settings(e, cfg=None, robot=None, recon=None) -> IndicesExamplesSettings:
    """``experiment.*`` of indices_examples (the paper's example points, the R curve step)."""
    if recon is None:
        raise ConfigError("experiment=indices_examples needs a reconfigurable robot: robot.R_range is null")
    s = read_settings(IndicesExamplesSettings, e, "experiment")
    n_R = n_steps(float(recon.R_min), float(recon.R_max), s.R_step)  # every index at every R of each point's curve
    check_fits("experiment.R_step", s.R_step, 8.0 * n_R * max(1, len(s.points)) * len(_index_names()),
          f"{n_R:.3g} R samples of each point's index curves", unit="m")
    return s
