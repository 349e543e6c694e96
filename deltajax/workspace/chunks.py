"""The one chunk / shard / checkpoint engine of the grid jobs (host side).

* :func:`run_chunks` walks ``n_items`` items in chunks of ``chunk_size`` (bounded working memory at any grid
  size), resuming at the first unfinished chunk of a checkpoint and committing a new one after each chunk (or
  every ``checkpoint_every_s`` seconds). Chunks are deterministic, so a resumed job ends bit for bit like an
  uninterrupted one.
* Checkpoint stores behind one contract (``open(n_items, chunk_size, outputs)`` -> the arrays and the items
  already done, validated; ``commit(arrays, done_items)`` -> the chunks done so far made durable;
  ``commit_last``: whether the last chunk is committed too): :class:`MemmapCheckpoint` here (``.npy`` memory
  maps and a ``state.json`` with a sha256 per finished chunk, in a checkpoint directory: the jobs of
  :mod:`deltajax.workspace.driver`), and the CLI stage engine's results-file store
  (:class:`deltajax.jobs.stages.ChunkCheckpoint`: ``workspace_grid``, whose partial file is a readable result
  and a mergeable shard, its attributes sealed by :func:`seal`). A checkpoint written with other parameters, or
  damaged (unreadable, out of range, resized, a finished chunk that no longer matches its checksum) is refused
  (:class:`CheckpointMismatch` here), never silently recomputed or used.
* :class:`ShardPlan` cuts a grid of x-planes into chunks and gives one shard of N its contiguous block of
  them, on chunk boundaries, so that every point is computed in the same chunk position as in a single run.
* :func:`plane_statistics`, :func:`plane_summary` and :func:`reduce_plane_shards` (the shard reducer
  registered as ``"workspace_planes"`` in :mod:`deltajax.sweeps.reducers`): per-x-plane partial statistics and
  the whole-grid figures made from them, the same NumPy code for a single run and for merged shards.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
from pathlib import Path
from typing import Any, Callable, Mapping, Optional, Sequence

import numpy as np

from ..io import write_atomic

__all__ = ["CheckpointMismatch", "run_chunks", "MemmapCheckpoint", "ShardPlan", "seal", "fingerprint",
           "plane_statistics", "plane_summary", "reduce_plane_shards"]


class CheckpointMismatch(RuntimeError):
    """The checkpoint holds a run with different parameters, or is damaged."""


def fingerprint(obj: Any) -> str:
    """Short sha256 of a JSON-able description of a job: the one identity hash, of the memory-mapped store's
    checkpoint (:class:`MemmapCheckpoint`, whose callers are library functions with no run) and of a CLI run
    (:func:`deltajax.config.ga_reconfig_run.job_fingerprint`; a CLI job's checkpoints in results.h5 carry the
    run's, :class:`deltajax.jobs.stages.Checkpoint`)."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]


# -- the engine --------------------------------------------------------------------------------------------------

def run_chunks(n_items: int, chunk_size: int, compute: Callable[[int, int], dict], outputs: dict, *,
               checkpoint_dir: Optional[os.PathLike] = None, fingerprint: Any = None,
               progress: Optional[Callable[[int], None]] = None, max_chunks: Optional[int] = None,
               checkpoint: Optional[Any] = None, checkpoint_every_s: float = 0.0) -> tuple[dict, bool]:
    """Run ``compute(start, stop) -> {name: array[stop - start, ...]}`` over ``n_items`` in chunks.

    Args:
        n_items: number of items (grid points, x-planes).
        chunk_size: items per chunk.
        compute: the chunk function (deterministic).
        outputs: name -> (dtype, fill value) of each per-item output.
        checkpoint_dir: resume from / checkpoint into this directory (a :class:`MemmapCheckpoint`).
        fingerprint: JSON-able description of the job; a checkpoint with another fingerprint is refused.
        progress: called with the number of items finished after each chunk (e.g. ``tqdm.update``).
        max_chunks: stop after this many chunks in *this call* (as if killed; resume later).
        checkpoint: another checkpoint store (e.g. the stage engine's, :class:`deltajax.jobs.stages.ChunkCheckpoint`)
            instead of ``checkpoint_dir``.
        checkpoint_every_s: commit at most this often (0: after every chunk).

    Returns:
        (outputs, complete).
    """
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size!r}")
    n_chunks = max(1, math.ceil(n_items / chunk_size))
    if checkpoint is None and checkpoint_dir is not None:
        checkpoint = MemmapCheckpoint(checkpoint_dir, fingerprint)
    if checkpoint is None:
        arrays, done_items = {n: np.full(n_items, fill, dtype=dt) for n, (dt, fill) in outputs.items()}, 0
    else:
        arrays, done_items = checkpoint.open(n_items, chunk_size, outputs)
    if not (0 <= done_items <= n_items and (done_items % chunk_size == 0 or done_items == n_items)):
        raise CheckpointMismatch(f"checkpoint {checkpoint}: {done_items} items done is not a whole number of "
                                 f"chunks of {chunk_size} within {n_items}")
    done = math.ceil(done_items / chunk_size)
    if progress is not None and done_items:
        progress(done_items)
    ran = 0
    t_commit = time.monotonic()
    while done < n_chunks:
        if max_chunks is not None and ran >= max_chunks:
            break
        start = done * chunk_size
        stop = min(n_items, start + chunk_size)
        res = compute(start, stop)
        for name in outputs:
            arrays[name][start:stop] = res[name]
        done += 1
        ran += 1
        last = done >= n_chunks or (max_chunks is not None and ran >= max_chunks)
        if checkpoint is not None and (not last or checkpoint.commit_last) and \
                time.monotonic() - t_commit >= checkpoint_every_s:
            checkpoint.commit(arrays, min(n_items, done * chunk_size))
            t_commit = time.monotonic()
        if progress is not None:
            progress(stop - start)
    return arrays, done >= n_chunks


# -- checkpoint stores ------------------------------------------------------------------------------------------

class MemmapCheckpoint:
    """Outputs in ``<dir>/<name>.npy`` memory maps; ``<dir>/state.json`` records the finished chunks with a
    sha256 of each one's outputs, rewritten atomically after the chunk's data is flushed."""

    commit_last = True  # the state says "complete" once the last chunk is in

    def __init__(self, directory: os.PathLike, job: Any = None):
        self.dir = Path(directory)
        self.job = job
        self.state = self.dir / "state.json"

    def __str__(self) -> str:
        return str(self.dir)

    def _damaged(self, what: str) -> CheckpointMismatch:
        return CheckpointMismatch(f"checkpoint {self.dir} is damaged ({what}); delete that directory to recompute it")

    def open(self, n_items: int, chunk_size: int, outputs: dict) -> tuple[dict, int]:
        self.n, self.chunk, self.names = n_items, chunk_size, list(outputs)
        self.n_chunks = max(1, math.ceil(n_items / chunk_size))
        self.fp = fingerprint({"n": n_items, "chunk": chunk_size, "job": self.job,
                               "outputs": {k: str(np.dtype(v[0])) for k, v in outputs.items()}})
        self.dir.mkdir(parents=True, exist_ok=True)
        arrays: dict = {}
        if not self.state.exists():
            for name, (dtype, fill) in outputs.items():
                arr = np.lib.format.open_memmap(self.dir / f"{name}.npy", mode="w+", dtype=dtype, shape=(n_items,))
                arr[:] = fill
                arrays[name] = arr
            self.sums: list = []
            self._write(0)
            return arrays, 0
        try:
            state = json.loads(self.state.read_text())
            done = int(state["done_chunks"])
            self.sums = [str(h) for h in state["chunk_sha256"]]
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise self._damaged(f"state.json unreadable: {type(e).__name__}") from None
        if state.get("fingerprint") != self.fp:
            raise CheckpointMismatch(f"checkpoint {self.dir} was written by a different job "
                                     f"(fingerprint {state.get('fingerprint')} != {self.fp}); use another directory")
        if not 0 <= done <= self.n_chunks or len(self.sums) != done:
            raise self._damaged(f"done_chunks={done} with {len(self.sums)} checksums, {self.n_chunks} chunks in "
                                f"the job")
        for name, (dtype, _) in outputs.items():
            try:
                arrays[name] = np.load(self.dir / f"{name}.npy", mmap_mode="r+")
            except (OSError, ValueError) as e:
                raise self._damaged(f"{name}.npy unreadable: {type(e).__name__}") from None
            if arrays[name].shape != (n_items,) or arrays[name].dtype != np.dtype(dtype):
                raise self._damaged(f"{name}.npy holds {arrays[name].dtype}{arrays[name].shape}, expected "
                                    f"{np.dtype(dtype)}({n_items},)")
        for c in range(done):
            a, b = c * chunk_size, min(n_items, (c + 1) * chunk_size)
            if _chunk_sha256({k: v[a:b] for k, v in arrays.items()}) != self.sums[c]:
                raise self._damaged(f"chunk {c} (items {a}:{b}) does not match its checksum")
        return arrays, min(n_items, done * chunk_size)

    def commit(self, arrays: dict, done_items: int) -> None:
        for a in arrays.values():
            a.flush()
        done = math.ceil(done_items / self.chunk)
        for c in range(len(self.sums), done):
            a, b = c * self.chunk, min(self.n, (c + 1) * self.chunk)
            self.sums.append(_chunk_sha256({k: arrays[k][a:b] for k in self.names}))
        self._write(done)

    def _write(self, done: int) -> None:
        write_atomic(self.state, json.dumps({"fingerprint": self.fp, "done_chunks": done, "n_chunks": self.n_chunks,
                                             "chunk_sha256": self.sums}).encode())


def _chunk_sha256(arrays: dict) -> str:
    h = hashlib.sha256()
    for k in sorted(arrays):
        h.update(k.encode())
        h.update(memoryview(np.ascontiguousarray(arrays[k])).cast("B"))
    return h.hexdigest()


def seal(key: str, done: int, start: int, stop: int) -> str:
    """Checksum of the attributes a resume from a results file trusts (its datasets carry their own): the resume
    key (the run's fingerprint), the items done and the shard's range."""
    return hashlib.sha256(json.dumps([key, int(done), int(start), int(stop)]).encode()).hexdigest()


# -- shards of a grid of x-planes ---------------------------------------------------------------------------------

class ShardPlan:
    """Chunks of whole x-planes and the contiguous block of them one shard of ``n_shards`` computes.

    Raises:
        ValueError: ``n_shards`` outside 1..(number of chunks), or ``shard`` outside 0..n_shards-1 (the message
            names the field and says how to get more chunks).
    """

    def __init__(self, shape: Sequence[int], chunk_points: int, n_devices: int, shard: int, n_shards: int):
        nx, ny, nz = (int(s) for s in shape)
        self.shape = (nx, ny, nz)
        self.plane = ny * nz
        self.planes_per_chunk = max(1, min(nx, int(chunk_points) // self.plane))
        self.n_chunks = math.ceil(nx / self.planes_per_chunk)
        if not 1 <= n_shards <= self.n_chunks:
            raise ValueError(f"n_shards must be in 1..{self.n_chunks} (the grid has {self.n_chunks} chunks of "
                             f"{self.planes_per_chunk} x-planes; lower experiment.chunk_points for more), "
                             f"got {n_shards!r}")
        if not 0 <= shard < n_shards:
            raise ValueError(f"shard must be in 0..{n_shards - 1} (n_shards={n_shards}), got {shard!r}")
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


# -- per-plane statistics and their shard reducer -----------------------------------------------------------------

def plane_statistics(ok: np.ndarray, values: np.ndarray) -> dict[str, np.ndarray]:
    """Per-x-plane partial statistics.

    Args:
        ok: bool[k, m] reachability of the k planes' m points.
        values: float[k, m, n_index].

    Returns:
        ``plane_count`` int64[k] and ``plane_n`` (int64), ``plane_sum``, ``plane_min``, ``plane_max``
        [k, n_index] over the reachable points whose value is finite (min/max are +inf/-inf for none), in the
        dtype of ``values``.

    One pass over the values (:func:`deltajax.workspace.numba_fields.plane_stats`, Numba) instead of NumPy's five full-size
    temporaries, which took half of a 2 mm ``workspace_grid`` run; the same numbers bit for bit (the sums in
    NumPy's order for this layout: each plane's points one after the other, masked entries as +0.0; tested
    against the NumPy form in tests/test_workspace_plane_stats.py).
    """
    values = np.ascontiguousarray(values)
    ok = np.ascontiguousarray(ok, dtype=np.bool_)
    k, m, c = values.shape
    if ok.shape != (k, m):
        raise ValueError(f"plane_statistics: ok has shape {ok.shape}, values {values.shape}")
    out = {"plane_count": np.empty(k, np.int64), "plane_n": np.empty((k, c), np.int64),
           "plane_sum": np.empty((k, c), values.dtype), "plane_min": np.empty((k, c), values.dtype),
           "plane_max": np.empty((k, c), values.dtype)}
    from . import numba_fields                                  # Numba on first use: importing this module stays cheap

    numba_fields.plane_stats(ok, values, out["plane_count"], out["plane_n"], out["plane_sum"], out["plane_min"],
                          out["plane_max"])
    return out


def _face_count(planes: Mapping[str, np.ndarray], x_faces: tuple[bool, bool]) -> np.int64:
    """Reachable points on the grid's faces: the y/z faces of every plane, plus whole first/last x-planes."""
    pc, pf = planes["plane_count"], planes["plane_face_count"]
    n = int(pf.sum())
    if len(pc) and x_faces[0]:
        n += int(pc[0] - pf[0])
    if len(pc) > 1 and x_faces[1]:
        n += int(pc[-1] - pf[-1])
    return np.int64(n)


def plane_summary(planes: Mapping[str, np.ndarray], names: Sequence[str], h: float, n_points: int,
                  box_volume: float, x_faces: tuple[bool, bool] = (True, True)) -> dict[str, np.ndarray]:
    """Whole-grid figures from per-plane statistics: count, volume (count h^3), volume_box (count / N V_box),
    fraction, face_count / truncated, and ``<index>_min/_max/_mean`` (NaN where no point has a finite value)."""
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


def reduce_plane_shards(data: Mapping[str, np.ndarray], shard_attrs: Sequence[Mapping[str, Any]]):
    """Shard reducer ``"workspace_planes"``: the whole-grid figures of merged per-plane statistics, and the
    merged file's checkpoint attributes (``planes_done``, ``complete``, ``resume_seal``)."""
    a0 = shard_attrs[0]
    names = [str(s) for s in data["index"]]
    scalars = plane_summary(data, names, float(a0["h"]), int(a0["n_points"]), float(a0["box_volume"]))
    planes_done = sum(int(a["planes_done"]) for a in shard_attrs)
    size = int(a0["shard_axis_size"])
    return scalars, {"planes_done": planes_done, "complete": int(planes_done == size),
                     "resume_seal": seal(str(a0["resume_key"]), planes_done, 0, size)}
