"""Experiment ``workspace_grid``: reachability and every index on a grid, shardable across jobs and devices.

    python -m deltajax.run experiment=workspace_grid experiment.grid.h=0.002          # one process
    python -m deltajax.run -m experiment=workspace_grid n_shards=4 shard=0,1,2,3     # 4 jobs, merged at the end

The grid (inclusive end points, :func:`deltajax.workspace.make_grid`) is cut into chunks of whole x-planes
(``experiment.chunk_points`` points each, padded to a fixed shape so that one compilation serves all of
them). Each chunk is split over this process's JAX devices (``jax.sharding``; on a CPU node the
:class:`deltajax.sweep.WorkerEnv` callback exposes one host device per CPU). With ``n_shards=N`` the chunks
are divided among N jobs; ``shard=i`` computes the i-th contiguous block of x-planes. Because the shard
boundaries fall on chunk boundaries, every point is computed in the same chunk position with the same
compiled code as in a single run, and the per-plane partial statistics are reduced by the same NumPy code
(:func:`reduce_shards`), so merged shards (:func:`deltajax.sweep.merge_shards`) equal a single run bit for
bit.

Results, group ``workspace`` (dims x, y, z; SPEC §5):
``reachable`` (uint8), the fields listed in ``experiment.store`` (NaN outside the workspace), per-plane
statistics ``plane_count`` (x) and ``plane_n/_sum/_min/_max`` (x, index) over the reachable points with a
finite value, and the scalars ``count``, ``volume`` (count h^3), ``volume_box`` (count / N V_box),
``fraction`` and ``<index>_min/_max/_mean``. Checkpoints every ``experiment.checkpoint_s`` seconds; with
``experiment.resume=true`` a rerun into the same directory continues from the last checkpoint.
"""

from __future__ import annotations

import functools
import importlib.util
import json
import math
import os
import time
from typing import Any, Mapping, Sequence

import numpy as np

from ..config import ConfigError
from ..rundir import CheckpointError, RunDirError

GROUP = "workspace"
REDUCER = "deltajax.jobs.workspace_grid:reduce_shards"

__all__ = ["run", "reduce_shards", "GridPlan", "plan_chunks", "make_evaluator", "make_numba_evaluator",
           "plane_statistics"]


# ---------------------------------------------------------------------------------------------------------
# configuration
# ---------------------------------------------------------------------------------------------------------
def _grid_from_config(g: Mapping[str, Any], robot=None):
    """The grid of ``experiment.grid``; an axis given as null is sized from the robot's reach bound
    (:func:`deltajax.workspace.driver.reach_box`, widened outwards to whole steps of h, y symmetric)."""
    from ..workspace import make_grid
    from ..workspace.driver import reach_box

    h = g.get("h")
    if not isinstance(h, (int, float)) or isinstance(h, bool) or not h > 0 or not math.isfinite(h):
        raise ConfigError(f"experiment.grid.h must be a positive number (m), got {h!r}")
    box = reach_box(robot) if robot is not None else None

    def pair(i, key):
        v = g.get(key)
        if v is None and box is not None:  # from the reach bound, on whole steps of h (y symmetric: mirror halving)
            lo, hi = box[i]
            if key == "y":
                n = math.ceil(max(-lo, hi) / h - 1e-9)
                return -n * h, n * h
            return math.floor(lo / h + 1e-9) * h, math.ceil(hi / h - 1e-9) * h
        try:
            lo, hi = (float(t) for t in v)
        except (TypeError, ValueError):
            raise ConfigError(f"experiment.grid.{key} must be [lo, hi] in m (or null: from the reach bound), "
                              f"got {v!r}") from None
        return lo, hi

    bounds = g.get("bounds")
    auto = [k for k in ("x", "y", "z") if g.get(k) is None]
    if auto and bounds is not None:
        raise ConfigError(f"experiment.grid.bounds must be null when the grid is sized from the reach bound "
                          f"(experiment.grid.{'/'.join(auto)}=null), got {bounds!r}")
    if bounds is not None:
        try:
            bounds = [[float(a), float(b)] for a, b in bounds]
            assert len(bounds) == 3
        except (TypeError, ValueError, AssertionError):
            raise ConfigError(f"experiment.grid.bounds must be null or [[x0,x1],[y0,y1],[z0,z1]] (m), "
                              f"got {g.get('bounds')!r}") from None
    try:
        return make_grid(pair(0, "x"), pair(1, "y"), pair(2, "z"), float(h), bounds=bounds)
    except ValueError as e:
        raise ConfigError(f"experiment.grid: {e}") from None


class GridPlan:
    """Chunks of whole x-planes and the slice of them one shard computes (host-side bookkeeping)."""

    def __init__(self, shape: Sequence[int], chunk_points: int, n_devices: int, shard: int, n_shards: int):
        nx, ny, nz = (int(s) for s in shape)
        self.shape = (nx, ny, nz)
        self.plane = ny * nz
        self.planes_per_chunk = max(1, min(nx, int(chunk_points) // self.plane))
        self.n_chunks = math.ceil(nx / self.planes_per_chunk)
        if not 1 <= n_shards <= self.n_chunks:
            raise ConfigError(f"n_shards must be in 1..{self.n_chunks} (the grid has {self.n_chunks} chunks of "
                              f"{self.planes_per_chunk} x-planes; lower experiment.chunk_points for more), "
                              f"got {n_shards!r}")
        if not 0 <= shard < n_shards:
            raise ConfigError(f"shard must be in 0..{n_shards - 1} (n_shards={n_shards}), got {shard!r}")
        self.shard, self.n_shards = shard, n_shards
        self.chunk0 = shard * self.n_chunks // n_shards
        self.chunk1 = (shard + 1) * self.n_chunks // n_shards
        self.x_start = self.chunk0 * self.planes_per_chunk
        self.x_stop = min(nx, self.chunk1 * self.planes_per_chunk)
        # fixed padded length: one compilation, and a multiple of the device count for even sharding
        n = self.planes_per_chunk * self.plane
        self.chunk_len = -(-n // n_devices) * n_devices

    def chunk_planes(self, c: int) -> tuple[int, int]:
        """Global x-plane range [a, b) of chunk ``c``."""
        a = c * self.planes_per_chunk
        return a, min(self.shape[0], a + self.planes_per_chunk)


def plan_chunks(shape, chunk_points, n_devices=1, shard=0, n_shards=1) -> GridPlan:
    """See :class:`GridPlan`."""
    return GridPlan(shape, chunk_points, n_devices, shard, n_shards)


# ---------------------------------------------------------------------------------------------------------
# device kernel
# ---------------------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=8)  # one jitted function per setting: repeated runs in a process compile once
def make_evaluator(n_devices: int, *, b_v: float, b_f: float, beta: float):
    """A jitted ``f(robot, points[n, 3]) -> (ok[n], values[n, n_index])`` sharded over ``n_devices`` devices.

    ``n`` must be a multiple of ``n_devices``; the points are split along their first axis, the robot is
    replicated. Per-point results do not depend on the split (elementwise kernel).
    """
    import jax
    import jax.numpy as jnp
    from jax.sharding import Mesh, NamedSharding, PartitionSpec as P

    from ..workspace import FIELD_NAMES, index_fields

    devices = jax.local_devices()[:n_devices]
    mesh = Mesh(np.asarray(devices), ("d",))
    rows = NamedSharding(mesh, P("d", None))
    flat = NamedSharding(mesh, P("d"))
    repl = NamedSharding(mesh, P())

    def f(robot, pts):
        ok, fields = index_fields(robot, pts, b_v=b_v, b_f=b_f, beta=beta)
        return ok, jnp.stack([fields[n] for n in FIELD_NAMES], axis=-1)

    jf = jax.jit(f, out_shardings=(flat, rows))

    def evaluate(robot, pts):
        robot = jax.device_put(robot, repl)
        return jf(robot, jax.device_put(pts, rows))

    return evaluate


def make_numba_evaluator(grid, *, b_v: float, b_f: float, beta: float):
    """``f(robot, a, b) -> (ok[n], values[n, n_index])`` for the x-planes ``a:b`` of ``grid``, on the CPU
    threads of :func:`deltajax.workspace.fixed_workspace` (Numba, ``NUMBA_NUM_THREADS``; float64)."""
    from ..workspace import FIELD_NAMES, Grid, fixed_workspace

    def evaluate(robot, a: int, b: int):
        # the same coordinate values as the full grid (sliced, not rebuilt), so shards see identical points
        sub = Grid(x=grid.x[a:b], y=grid.y, z=grid.z, h=grid.h, bounds=grid.bounds)
        job = fixed_workspace(robot, sub, fields=True, b_v=b_v, b_f=b_f, beta=beta, chunk_size=sub.n_points,
                              mirror=True)
        vals = np.stack([job.fields[n] for n in FIELD_NAMES], axis=-1)
        return job.ok.reshape(-1), vals.reshape(-1, len(FIELD_NAMES))

    return evaluate


# ---------------------------------------------------------------------------------------------------------
# statistics (NumPy, shared by the single run and the shard merge so that both are bit-identical)
# ---------------------------------------------------------------------------------------------------------
def plane_statistics(ok: np.ndarray, values: np.ndarray) -> dict[str, np.ndarray]:
    """Per-x-plane partial statistics.

    Args:
        ok: bool[k, m] reachability of the k planes' m points.
        values: float[k, m, n_index].

    Returns:
        ``plane_count`` int64[k] and ``plane_n`` (int64), ``plane_sum``, ``plane_min``, ``plane_max``
        [k, n_index] over the reachable points whose value is finite (min/max are +inf/-inf for none).
    """
    finite = ok[..., None] & np.isfinite(values)
    return {
        "plane_count": ok.sum(axis=1, dtype=np.int64),
        "plane_n": finite.sum(axis=1, dtype=np.int64),
        "plane_sum": np.where(finite, values, 0.0).sum(axis=1),
        "plane_min": np.where(finite, values, np.inf).min(axis=1),
        "plane_max": np.where(finite, values, -np.inf).max(axis=1),
    }


def _face_count(planes: Mapping[str, np.ndarray], x_faces: tuple[bool, bool]) -> np.int64:
    """Reachable points on the grid's faces: the y/z faces of every plane, plus whole first/last x-planes."""
    pc, pf = planes["plane_count"], planes["plane_face_count"]
    n = int(pf.sum())
    if len(pc) and x_faces[0]:
        n += int(pc[0] - pf[0])
    if len(pc) > 1 and x_faces[1]:
        n += int(pc[-1] - pf[-1])
    return np.int64(n)


def _summary(planes: Mapping[str, np.ndarray], names: Sequence[str], h: float, n_points: int,
             box_volume: float, x_faces: tuple[bool, bool] = (True, True)) -> dict[str, np.ndarray]:
    count = np.int64(planes["plane_count"].sum())
    faces = _face_count(planes, x_faces)
    n = planes["plane_n"].sum(axis=0)
    total = planes["plane_sum"].sum(axis=0)
    vmin = planes["plane_min"].min(axis=0)
    vmax = planes["plane_max"].max(axis=0)
    out = {
        "count": count,
        "volume": np.float64(count * h ** 3),
        "volume_box": np.float64(count / n_points * box_volume),
        "fraction": np.float64(count / n_points),
        # reachable points on the box faces: the workspace continues outside the grid, volume is a lower bound
        "face_count": faces,
        "truncated": np.uint8(faces > 0),
    }
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(n > 0, total / np.maximum(n, 1), np.nan)
    nan = np.asarray(np.nan, total.dtype)
    for i, name in enumerate(names):  # NaN when no reachable point has a finite value
        out[f"{name}_min"] = np.where(n[i] > 0, vmin[i], nan)
        out[f"{name}_max"] = np.where(n[i] > 0, vmax[i], nan)
        out[f"{name}_mean"] = mean[i].astype(total.dtype)
    return out


def reduce_shards(data: Mapping[str, np.ndarray], shard_attrs: Sequence[Mapping[str, Any]]):
    """``shard_reduce`` of group ``workspace``: recompute the whole-grid scalars from the merged planes."""
    a0 = shard_attrs[0]
    names = [str(s) for s in data["index"]]
    scalars = _summary(data, names, float(a0["h"]), int(a0["n_points"]), float(a0["box_volume"]))
    planes_done = sum(int(a["planes_done"]) for a in shard_attrs)
    size = int(a0["shard_axis_size"])
    return scalars, {"planes_done": planes_done, "complete": int(planes_done == size),
                     "resume_seal": _seal(str(a0["resume_key"]), planes_done, 0, size)}


# ---------------------------------------------------------------------------------------------------------
# the experiment
# ---------------------------------------------------------------------------------------------------------
def _int(cfg, key: str, field: str, lo: int = None) -> int:
    v = cfg.get(key)
    if not isinstance(v, int) or isinstance(v, bool) or (lo is not None and v < lo):
        raise ConfigError(f"{field} must be an integer{'' if lo is None else f' >= {lo}'}, got {v!r}")
    return v


def run(ctx) -> None:
    import jax

    from ..workspace import FIELD_NAMES

    cfg = ctx.cfg
    ex = cfg.experiment
    grid = _grid_from_config(ex.grid, ctx.robot)
    shard = _int(cfg, "shard", "shard", 0)
    n_shards = _int(cfg, "n_shards", "n_shards", 1)
    chunk_points = _int(ex, "chunk_points", "experiment.chunk_points", 1)
    store = list(ex.get("store") or [])
    for name in store:
        if name not in FIELD_NAMES:
            raise ConfigError(f"experiment.store: {name!r} is not an index; choose from {list(FIELD_NAMES)}")
    dev_cfg = ex.get("devices", "all")
    n_avail = jax.local_device_count()
    if dev_cfg in ("all", None):
        n_dev = n_avail
    elif isinstance(dev_cfg, int) and not isinstance(dev_cfg, bool) and 1 <= dev_cfg <= n_avail:
        n_dev = dev_cfg
    else:
        raise ConfigError(f"experiment.devices must be 'all' or an integer in 1..{n_avail}, got {dev_cfg!r}")
    params = {k: float(ex.get(k)) for k in ("b_v", "b_f", "beta")}
    plan = GridPlan(grid.shape, chunk_points, n_dev, shard, n_shards)
    nx, ny, nz = grid.shape
    xs = slice(plan.x_start, plan.x_stop)
    n_local = plan.x_stop - plan.x_start
    n_idx = len(FIELD_NAMES)
    dtype = np.dtype(ctx.dtype)

    backend = ex.get("backend", "auto")
    if backend not in ("auto", "jax", "numba"):
        raise ConfigError(f"experiment.backend must be 'auto', 'jax' or 'numba', got {backend!r}")
    if backend == "auto":  # what measures faster (experiments/bench_multidevice.py): Numba on CPU in float64
        backend = "numba" if (jax.default_backend() == "cpu" and dtype == np.float64
                              and importlib.util.find_spec("numba") is not None) else "jax"
    elif backend == "numba" and dtype != np.float64:
        raise ConfigError("experiment.backend=numba computes in float64: use precision=float64 or backend=jax")
    # a key for resuming: everything that determines the numbers (the shard is checked separately)
    key = json.dumps({"grid": [grid.x[0], grid.x[-1], grid.y[0], grid.y[-1], grid.z[0], grid.z[-1], grid.h],
                      "robot": {k: str(v) for k, v in ctx.cfg.robot.items()}, "params": params,
                      "chunk": plan.planes_per_chunk, "store": store,
                      "precision": str(cfg.precision), "backend": backend}, sort_keys=True)
    reach = np.zeros((n_local, ny, nz), np.uint8)
    fields = {name: np.full((n_local, ny, nz), np.nan, dtype) for name in store}
    planes = {"plane_count": np.zeros(n_local, np.int64), "plane_face_count": np.zeros(n_local, np.int64),
              "plane_n": np.zeros((n_local, n_idx), np.int64),
              "plane_sum": np.zeros((n_local, n_idx), dtype), "plane_min": np.full((n_local, n_idx), np.inf, dtype),
              "plane_max": np.full((n_local, n_idx), -np.inf, dtype)}
    done = 0  # planes of this shard finished
    if ctx.results.path.exists():
        if not ex.get("resume", True):
            raise RunDirError(f"{ctx.results.path} exists and experiment.resume=false: add fresh=true to start over, "
                              f"or choose another hydra.run.dir")
        done = _resume(ctx, key, plan, reach, fields, planes)
    x_faces = (plan.x_start == 0, plan.x_stop == nx)

    def stage(planes_done: int) -> None:
        r = ctx.results
        r.put_axis(GROUP, "x", grid.x[xs], units="m")
        r.put_axis(GROUP, "y", grid.y, units="m")
        r.put_axis(GROUP, "z", grid.z, units="m")
        r.put_axis(GROUP, "index", np.asarray(FIELD_NAMES, dtype=object), units="1")
        r.put(GROUP, "reachable", reach, units="1", dims=("x", "y", "z"),
              attrs={"description": "IK solvable for all chains with theta within limits"})
        for name in store:
            r.put(GROUP, name, fields[name], units="1", dims=("x", "y", "z"),
                  attrs={"description": f"{name} (theta3x3, homogenised by L1); NaN outside the workspace"})
        r.put(GROUP, "plane_count", planes["plane_count"], units="1", dims=("x",))
        r.put(GROUP, "plane_face_count", planes["plane_face_count"], units="1", dims=("x",),
              attrs={"description": "reachable points of the x-plane on the y and z faces of the grid box"})
        for k in ("plane_n", "plane_sum", "plane_min", "plane_max"):
            r.put(GROUP, k, planes[k], units="1", dims=("x", "index"))
        for k, v in _summary(planes, FIELD_NAMES, grid.h, grid.n_points, grid.box_volume, x_faces).items():
            r.put(GROUP, k, v, units={"count": "1", "volume": "m^3", "volume_box": "m^3"}.get(k, "1"), dims=())
        r.set_attrs(GROUP, shard_axis="x", shard=shard, n_shards=n_shards, shard_start=plan.x_start,
                    shard_stop=plan.x_stop, shard_axis_size=nx, shard_reduce=REDUCER, planes_done=planes_done,
                    complete=int(planes_done == n_local), resume_key=key, h=grid.h, n_points=grid.n_points,
                    box_volume=grid.box_volume, b_v=params["b_v"], b_f=params["b_f"], beta=params["beta"],
                    chunk_planes=plan.planes_per_chunk,
                    resume_seal=_seal(key, planes_done, plan.x_start, plan.x_stop),
                    description="fixed-R workspace grid: reachability, indices and their statistics")

    if backend == "jax":
        evaluate = make_evaluator(n_dev, **params)
    else:
        evaluate = make_numba_evaluator(grid, **params)
    robot = ctx.robot
    first = plan.chunk0 + done // plan.planes_per_chunk
    ctx.log(f"workspace_grid: grid {nx}x{ny}x{nz} = {grid.n_points} points, shard {shard}/{n_shards} "
            f"x[{plan.x_start}:{plan.x_stop}], {plan.chunk1 - first} chunks of {plan.planes_per_chunk} planes, "
            + (f"JAX on {n_dev} device(s)" if backend == "jax" else
               f"Numba on {os.environ.get('NUMBA_NUM_THREADS', 'all')} thread(s)"))
    t_ckpt = time.monotonic()
    t0 = time.perf_counter()
    n_eval = 0
    first_chunk_s, n_first = None, 0  # the first chunk includes compilation: timed apart
    every = float(ex.get("checkpoint_s", 60.0))
    stop_after = ex.get("stop_after")  # stop as if killed after this many chunks (tests the resume path)
    last = plan.chunk1 if stop_after is None else min(plan.chunk1, first + int(stop_after))
    for c in ctx.progress(range(first, last), total=last - first, desc="workspace_grid"):
        a, b = plan.chunk_planes(c)
        idx = np.arange(a * plan.plane, b * plan.plane, dtype=np.int64)
        if backend == "jax":
            pad = np.full(plan.chunk_len - idx.size, idx[0], np.int64)
            pts = grid.points_at(np.concatenate([idx, pad])).astype(dtype)
            ok, vals = evaluate(robot, pts)
        else:
            ok, vals = evaluate(robot, a, b)
        ok = np.asarray(ok)[: idx.size].reshape(b - a, plan.plane)
        vals = np.asarray(vals)[: idx.size].reshape(b - a, plan.plane, n_idx).astype(dtype, copy=False)
        n_eval += idx.size
        if first_chunk_s is None:
            first_chunk_s, n_first = time.perf_counter() - t0, idx.size
        la, lb = a - plan.x_start, b - plan.x_start
        reach[la:lb] = ok.reshape(b - a, ny, nz)
        for name in store:
            fields[name][la:lb] = vals[..., FIELD_NAMES.index(name)].reshape(b - a, ny, nz)
        for k, v in plane_statistics(ok, vals).items():
            planes[k][la:lb] = v
        okp = ok.reshape(b - a, ny, nz)
        planes["plane_face_count"][la:lb] = (okp.sum(axis=(1, 2)) - okp[:, 1:-1, 1:-1].sum(axis=(1, 2))
                                             if min(ny, nz) > 2 else okp.sum(axis=(1, 2)))
        done = lb
        if time.monotonic() - t_ckpt > every and c + 1 < last:
            stage(done)
            ctx.results.flush()
            t_ckpt = time.monotonic()
    elapsed = time.perf_counter() - t0
    stage(done)
    warm_s, warm_n = elapsed - (first_chunk_s or 0.0), n_eval - n_first
    if warm_n == 0:  # a single chunk: its time includes compilation
        warm_s, warm_n = elapsed, n_eval
    rate = warm_n / warm_s if warm_s > 0 else 0.0
    ctx.results.set_attrs(points_evaluated=n_eval, points_per_s=rate, first_chunk_s=first_chunk_s or 0.0,
                          devices_used=n_dev if backend == "jax" else 0, backend=backend, worker_env=os.environ.get("DELTAJAX_WORKER_ENV", ""))
    s = _summary(planes, FIELD_NAMES, grid.h, grid.n_points, grid.box_volume, x_faces)
    if int(s["face_count"]):
        ctx.log(f"WARNING: {int(s['face_count'])} reachable points lie on the faces of the grid box: the workspace "
                f"continues outside it, so the volume below is a lower bound (widen experiment.grid.x/y/z, or set "
                f"them to null to size the box from the robot's reach bound)")
    if done < n_local:
        ctx.complete = False
        ctx.log(f"stopped after {done} of {n_local} x-planes (experiment.stop_after): rerun into {ctx.run_dir} "
                f"to resume")
    ctx.log(f"shard {shard}/{n_shards}: {int(s['count'])} reachable points, volume {float(s['volume']):.6g} m^3 "
            f"(count h^3), {float(s['volume_box']):.6g} m^3 (count/N V_box); "
            f"{rate / 1e6:.2f} M points/s after the first chunk ({first_chunk_s or 0.0:.1f} s with compilation)")
    if cfg.get("plots", True) and n_shards == 1:
        _plot(ctx, grid, reach)


def _seal(key: str, planes_done: int, start: int, stop: int) -> str:
    """Checksum of the attributes a resume trusts (the datasets carry their own checksums, deltajax.io)."""
    import hashlib

    return hashlib.sha256(json.dumps([key, int(planes_done), int(start), int(stop)]).encode()).hexdigest()


def _resume(ctx, key, plan, reach, fields, planes) -> int:
    """Load the finished planes of the checkpoint in results.h5 into the arrays; refuse a damaged one."""
    import h5py

    from ..io import ChecksumError, read_checked

    path = ctx.results.path
    n_local = plan.x_stop - plan.x_start

    def refuse(what: str):
        return CheckpointError(f"cannot resume from {path}: {what}; move it away to keep it, or add fresh=true to "
                               f"start over")

    try:
        with h5py.File(path, "r") as f:
            g = f.get(GROUP)
            if g is None:
                raise refuse(f"it has no group {GROUP!r}")
            a = g.attrs
            try:
                done = int(a["planes_done"])
                ok_seal = a.get("resume_seal") == _seal(a["resume_key"], done, a["shard_start"], a["shard_stop"])
            except (KeyError, TypeError, ValueError):
                raise refuse("its checkpoint attributes are missing or malformed") from None
            if not ok_seal:
                raise refuse("its checkpoint attributes (planes_done, resume_key, shard range) do not match their "
                             "checksum (the file is damaged or was edited)")
            if a["resume_key"] != key or [int(a["shard_start"]), int(a["shard_stop"])] != [plan.x_start, plan.x_stop]:
                raise refuse("it was written by another grid, robot, backend or shard")
            if not 0 <= done <= n_local:
                raise refuse(f"planes_done={done} is outside 0..{n_local}")
            data = {"reachable": read_checked(g["reachable"])}
            for name in list(fields) + list(planes):
                data[name] = read_checked(g[name])
    except ChecksumError as e:
        raise refuse(str(e).split(": ", 1)[-1].replace(f"{path}:", "")) from None
    except (OSError, KeyError) as e:
        raise refuse(f"it is unreadable or incomplete ({type(e).__name__}: {str(e).split('(')[0].strip()})") from None
    for name, arr in data.items():
        want = reach.shape if name == "reachable" or name in fields else planes[name].shape
        if arr.shape != want:
            raise refuse(f"{GROUP}/{name} has shape {arr.shape}, this run expects {want}")
    counts = data["reachable"][:done].reshape(done, -1).sum(axis=1, dtype=np.int64)
    if not np.array_equal(counts, data["plane_count"][:done]):
        raise refuse("plane_count does not match the reachable mask")
    reach[:done] = data["reachable"][:done]
    for name in fields:
        fields[name][:done] = data[name][:done]
    for k in planes:
        planes[k][:done] = data[k][:done]
    ctx.log(f"resuming: {done} x-planes already done")
    return done


def _plot(ctx, grid, reach) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    area = reach.sum(axis=(0, 1)) * grid.h ** 2
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.6))
    a1.plot(grid.z, area)
    a1.set_xlabel("z (m, down)")
    a1.set_ylabel("reachable area (m$^2$)")
    j = int(np.argmin(np.abs(grid.y)))
    a2.imshow(reach[:, j, :].T, origin="upper", aspect="equal",
              extent=(grid.x[0], grid.x[-1], grid.z[-1], grid.z[0]), cmap="Greys")
    a2.set_xlabel("x (m)")
    a2.set_ylabel("z (m)")
    a2.set_title(f"reachable, y = {grid.y[j]:.3f} m")
    fig.tight_layout()
    ctx.savefig(fig, "workspace_grid")
