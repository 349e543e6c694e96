"""Experiment ``workspace_grid``: reachability and every index on a grid, shardable across jobs and devices.

    python -m deltajax.run experiment=workspace_grid experiment.grid.h=0.002          # one process
    python -m deltajax.run -m experiment=workspace_grid n_shards=4 shard=0,1,2,3     # 4 jobs, merged at the end

The grid (inclusive end points, :func:`deltajax.workspace.make_grid`) is cut into chunks of whole x-planes
(``experiment.chunk_points`` points each, padded to a fixed shape so that one compilation serves all of
them). Each chunk is split over this process's JAX devices by x-planes (``jax.shard_map``; on a CPU node the
:class:`deltajax.sweeps.WorkerEnv` callback exposes one host device per CPU); each device evaluates the y >= 0
half of its planes on a mirror-symmetric grid and runs the full kernel only where a cheap reach pre-test passes,
compacted into fixed-size blocks (:func:`deltajax.workspace.evaluators.make_grid_evaluator`; the kernel's values bit
for bit). With ``n_shards=N`` the chunks
are divided among N jobs; ``shard=i`` computes the i-th contiguous block of x-planes. Because the shard
boundaries fall on chunk boundaries, every point is computed in the same chunk position with the same
compiled code as in a single run, and the per-plane partial statistics are reduced by the same NumPy code
(:func:`deltajax.workspace.chunks.reduce_plane_shards`, the shard reducer ``"workspace_planes"``), so merged
shards (:func:`deltajax.sweeps.merge_shards`) equal a single run bit for bit. Chunks, shards and checkpoints
run on the one engine (:mod:`deltajax.workspace.chunks`), with results.h5 as the checkpoint.

Results, group ``workspace`` (dims x, y, z; docs/results.md):
``reachable`` (uint8), the fields listed in ``experiment.store`` (NaN outside the workspace), per-plane
statistics ``plane_count`` (x) and ``plane_n/_sum/_min/_max`` (x, index) over the reachable points with a
finite value, and the scalars ``count``, ``volume`` (count h^3), ``volume_box`` (count / N V_box),
``fraction`` and ``<index>_min/_max/_mean``. Checkpoints every ``experiment.checkpoint_s`` seconds; with
``experiment.resume=true`` a rerun into the same directory continues from the last checkpoint.
"""

from __future__ import annotations

import functools
import json
import os
import time

import numpy as np

from ..rundir import CheckpointError, RunDirError
from .stages import Runner, Stage, State

from ..workspace.evaluators import (make_evaluator, make_grid_evaluator,  # (the job's kernels; also benchmarked)
                                make_numba_evaluator)
from ..workspace.chunks import CheckpointMismatch, plane_statistics, plane_summary, run_chunks, seal
from ..workspace import FIELD_NAMES
from .. import plots

GROUP = "workspace"
#: the registered shard reducer (deltajax.sweeps.reducers) of group ``workspace``
REDUCER = "workspace_planes"

__all__ = ["run", "make_evaluator", "make_grid_evaluator", "make_numba_evaluator"]


# ---------------------------------------------------------------------------------------------------------
# the experiment
# ---------------------------------------------------------------------------------------------------------
def run(ctx) -> None:
    """The grid job: its settings read and checked once, then its stages: ``grid`` (this shard's chunks on the
    chunk engine, checkpointed into and resumed from results.h5 by the stage engine), ``store`` (results and
    summary) and ``plots``. The run's fingerprint (its checkpoint's ``resume_key``) is the resume key."""
    st = State(ctx=ctx, **_settings(ctx))
    Runner(ctx, "workspace_grid", resumable=False, fingerprint=st.key).run(STAGES, st)


def _settings(ctx) -> dict:
    """What the stages read besides the job's settings ``s`` (checked before the run:
    config.workspace_grid_settings; the stages read them as ``st.s``): the resume key and the arrays the chunks
    fill (this shard's x-planes). RunDirError when a results file exists and experiment.resume=false."""
    s = ctx.settings                 # checked before the run (config.workspace_grid_settings)
    grid, store, params, backend, plan = s.built_grid, list(s.store), s.params, s.backend, s.plan
    nx, ny, nz = grid.shape
    n_local = plan.x_stop - plan.x_start
    n_idx = len(FIELD_NAMES)
    dtype = np.dtype(ctx.dtype)
    # a key for resuming: everything that determines the numbers (the shard is checked separately)
    key = json.dumps({"grid": [grid.x[0], grid.x[-1], grid.y[0], grid.y[-1], grid.z[0], grid.z[-1], grid.h],
                      "robot": s.robot_key, "params": params,
                      "chunk": plan.planes_per_chunk, "store": store,
                      "precision": s.precision, "backend": backend}, sort_keys=True)
    reach = np.zeros((n_local, ny, nz), np.uint8)
    fields = {name: np.full((n_local, ny, nz), np.nan, dtype) for name in store}
    planes = {"plane_count": np.zeros(n_local, np.int64), "plane_face_count": np.zeros(n_local, np.int64),
              "plane_n": np.zeros((n_local, n_idx), np.int64),
              "plane_sum": np.zeros((n_local, n_idx), dtype), "plane_min": np.full((n_local, n_idx), np.inf, dtype),
              "plane_max": np.full((n_local, n_idx), -np.inf, dtype)}
    if ctx.results.path.exists() and not s.resume:
        raise RunDirError(f"{ctx.results.path} exists and experiment.resume=false: add fresh=true to start over, "
                          f"or choose another hydra.run.dir")
    return dict(s=s, n_local=n_local, n_idx=n_idx, dtype=dtype, key=key, reach=reach, fields=fields,
                planes=planes, arrays={"reachable": reach, **fields, **planes},
                x_faces=(plan.x_start == 0, plan.x_stop == nx), plots=ctx.plots)


def _store_grid(st: State, planes_done: int) -> None:
    """Stage this shard's arrays, statistics and attributes into the results (what the grid stage's checkpoint
    commits too): ``planes_done`` x-planes of ``st.n_local`` are finished."""
    r, grid, plan, planes, params = st.ctx.results, st.s.built_grid, st.s.plan, st.planes, st.s.params
    key = st.runner.fingerprint          # the run's identity, which the grid stage's checkpoint carries
    r.put_axis(GROUP, "x", grid.x[plan.x_start:plan.x_stop], units="m")
    r.put_axis(GROUP, "y", grid.y, units="m")
    r.put_axis(GROUP, "z", grid.z, units="m")
    r.put_axis(GROUP, "index", np.asarray(FIELD_NAMES, dtype=object), units="1")
    r.put(GROUP, "reachable", st.reach, units="1", dims=("x", "y", "z"),
          attrs={"description": "IK solvable for all chains with theta within limits"})
    for name in st.s.store:
        r.put(GROUP, name, st.fields[name], units="1", dims=("x", "y", "z"),
              attrs={"description": f"{name} (theta3x3, homogenised by L1); NaN outside the workspace"})
    r.put(GROUP, "plane_count", planes["plane_count"], units="1", dims=("x",))
    r.put(GROUP, "plane_face_count", planes["plane_face_count"], units="1", dims=("x",),
          attrs={"description": "reachable points of the x-plane on the y and z faces of the grid box"})
    for k in ("plane_n", "plane_sum", "plane_min", "plane_max"):
        r.put(GROUP, k, planes[k], units="1", dims=("x", "index"))
    for k, v in plane_summary(planes, FIELD_NAMES, grid.h, grid.n_points, grid.box_volume, st.x_faces).items():
        r.put(GROUP, k, v, units={"count": "1", "volume": "m^3", "volume_box": "m^3"}.get(k, "1"), dims=())
    r.set_attrs(GROUP, shard_axis="x", shard=st.s.shard, n_shards=st.s.n_shards, shard_start=plan.x_start,
                shard_stop=plan.x_stop, shard_axis_size=grid.shape[0], shard_reduce=REDUCER,
                planes_done=planes_done, complete=int(planes_done == st.n_local), resume_key=key, h=grid.h,
                n_points=grid.n_points, box_volume=grid.box_volume, b_v=params["b_v"], b_f=params["b_f"],
                beta=params["beta"], chunk_planes=plan.planes_per_chunk,
                resume_seal=seal(key, planes_done, plan.x_start, plan.x_stop),
                description="fixed-R workspace grid: reachability, indices and their statistics")


def _check(data, done: int) -> str:
    """Why a checkpoint's first ``done`` x-planes are inconsistent ("" when they are not)."""
    counts = data["reachable"][:done].reshape(done, -1).sum(axis=1, dtype=np.int64)
    return "" if np.array_equal(counts, data["plane_count"][:done]) else \
        "plane_count does not match the reachable mask"


def _chunk(st: State, la: int, lb: int) -> dict:
    """One chunk: this shard's x-planes ``la:lb`` evaluated, as the arrays the chunk engine stores (and times the
    first chunk, which includes compilation)."""
    plan, timing, (_, ny, nz) = st.s.plan, st.timing, st.s.built_grid.shape
    a, b = plan.x_start + la, plan.x_start + lb  # global x-planes of this chunk
    n = (b - a) * plan.plane
    ok, vals = st.evaluate(st.ctx.robot, a, b)  # both backends: the planes' rows first (the JAX path pads after)
    ok = np.asarray(ok)[:n].reshape(b - a, plan.plane)
    vals = np.asarray(vals)[:n].reshape(b - a, plan.plane, st.n_idx).astype(st.dtype, copy=False)
    timing["n_eval"] += n
    if timing["first_s"] is None:
        timing["first_s"], timing["n_first"] = time.perf_counter() - st.t0, n
    okp = ok.reshape(b - a, ny, nz)
    out = {"reachable": okp, **plane_statistics(ok, vals)}
    out.update({name: vals[..., FIELD_NAMES.index(name)].reshape(b - a, ny, nz) for name in st.s.store})
    out["plane_face_count"] = (okp.sum(axis=(1, 2)) - okp[:, 1:-1, 1:-1].sum(axis=(1, 2))
                               if min(ny, nz) > 2 else okp.sum(axis=(1, 2)))
    return out


def _grid(st: State) -> None:
    """Every chunk of this shard on the chunk engine (:func:`deltajax.workspace.chunks.run_chunks`), checkpointed
    into results.h5 every ``experiment.checkpoint_s`` seconds and resumed from it (the runner's
    :class:`deltajax.jobs.stages.ChunkCheckpoint`: of this run and shard, verified); ``experiment.stop_after``
    stops after that many chunks as if killed (the run is then incomplete). Hands on ``done`` (x-planes) and the
    evaluation rate (points/s after the first chunk)."""
    ctx, plan, grid = st.ctx, st.s.plan, st.s.built_grid
    checkpoint = st.runner.chunk_checkpoint("grid", GROUP, st.arrays, span=(plan.x_start, plan.x_stop),
                                            save=lambda res, arrays, done: _store_grid(st, done), check=_check,
                                            done_attr="planes_done", what="workspace grid",
                                            note=lambda arrays, done: f"{done} of {st.n_local} x-planes")
    if st.s.backend == "jax":
        st.evaluate = make_grid_evaluator(grid, st.s.n_dev, planes=plan.planes_per_chunk, dtype=st.dtype,
                                          **st.s.params)
    else:
        st.evaluate = make_numba_evaluator(grid, **st.s.params)
    nx, ny, nz = grid.shape
    ctx.log(f"workspace_grid: grid {nx}x{ny}x{nz} = {grid.n_points} points, shard {st.s.shard}/{st.s.n_shards} "
            f"x[{plan.x_start}:{plan.x_stop}], {plan.chunk1 - plan.chunk0} chunks of {plan.planes_per_chunk} "
            f"planes, " + (f"JAX on {st.s.n_dev} device(s)" if st.s.backend == "jax" else
                           f"Numba on {os.environ.get('NUMBA_NUM_THREADS', 'all')} thread(s)"))
    st.t0 = time.perf_counter()
    st.timing = {"n_eval": 0, "first_s": None, "n_first": 0}  # the first chunk includes compilation: timed apart
    stop_after = st.s.stop_after  # stop as if killed after this many chunks (tests the resume path)
    progress = {"done": 0}
    with ctx.progress(total=st.n_local, desc="workspace_grid x-planes") as bar:
        def advance(n: int) -> None:
            if progress["done"] == 0 and n and st.timing["first_s"] is None:
                ctx.log(f"resuming: {n} x-planes already done")
            progress["done"] += n
            bar.update(n)

        try:
            run_chunks(st.n_local, plan.planes_per_chunk, functools.partial(_chunk, st),
                       {n: (a.dtype, None) for n, a in st.arrays.items()}, checkpoint=checkpoint,
                       checkpoint_every_s=st.s.checkpoint_s, progress=advance,
                       max_chunks=None if stop_after is None else int(stop_after))
        except CheckpointMismatch as e:
            raise CheckpointError(str(e)) from None
    st.done = progress["done"]  # planes of this shard finished
    elapsed = time.perf_counter() - st.t0
    n_eval, first_chunk_s, n_first = st.timing["n_eval"], st.timing["first_s"], st.timing["n_first"]
    warm_s, warm_n = elapsed - (first_chunk_s or 0.0), n_eval - n_first
    if warm_n == 0:  # a single chunk: its time includes compilation
        warm_s, warm_n = elapsed, n_eval
    st.rate = warm_n / warm_s if warm_s > 0 else 0.0


def _store(st: State) -> None:
    """The shard's results and the run's evaluation figures; a stopped run (``experiment.stop_after``) is marked
    incomplete (resumable)."""
    ctx, grid, plan, done, first_chunk_s = st.ctx, st.s.built_grid, st.s.plan, st.done, st.timing["first_s"]
    _store_grid(st, done)
    # points_evaluated: the work of the whole run (every finished x-plane, those of the processes before a resume
    # included: what an uninterrupted run reports); the rate is this process's
    ctx.results.set_attrs(points_evaluated=done * plan.plane, points_evaluated_this_process=st.timing["n_eval"],
                          points_per_s=st.rate, first_chunk_s=first_chunk_s or 0.0,
                          devices_used=st.s.n_dev if st.s.backend == "jax" else 0, backend=st.s.backend,
                          worker_env=os.environ.get("DELTAJAX_WORKER_ENV", ""))
    s = plane_summary(st.planes, FIELD_NAMES, grid.h, grid.n_points, grid.box_volume, st.x_faces)
    if int(s["face_count"]):
        ctx.log(f"WARNING: {int(s['face_count'])} reachable points lie on the faces of the grid box: the workspace "
                f"continues outside it, so the volume below is a lower bound (widen experiment.grid.x/y/z, or set "
                f"them to null to size the box from the robot's reach bound)")
    if done < st.n_local:
        ctx.complete = False
        ctx.log(f"stopped after {done} of {st.n_local} x-planes (experiment.stop_after): rerun into {ctx.run_dir} "
                f"to resume")
    ctx.log(f"shard {st.s.shard}/{st.s.n_shards}: {int(s['count'])} reachable points, volume {float(s['volume']):.6g} "
            f"m^3 (count h^3), {float(s['volume_box']):.6g} m^3 (count/N V_box); "
            f"{st.rate / 1e6:.2f} M points/s after the first chunk ({first_chunk_s or 0.0:.1f} s with compilation)")


def _plots(st: State) -> None:
    """The reachable set's figure (a single run only: a shard holds part of the grid)."""
    st.ctx.savefig(plots.workspace_grid(st.s.built_grid, st.reach), "workspace_grid")


STAGES = (
    Stage("grid", _grid),
    Stage("store", _store),
    Stage("plots", _plots, when=lambda st: st.plots and st.s.n_shards == 1),
)
