"""Chunked grid jobs with progress and checkpoint/resume (host side).

Every job walks the grid in chunks of ``chunk_size`` points, so working memory is bounded at any grid size;
outputs are one value per grid point (NumPy arrays, or ``.npy`` memory maps in the checkpoint directory).
When the grid is mirror-symmetric (:attr:`Grid.mirror_symmetric`) only the half y >= 0 is computed and the
other half is copied: the kernels evaluate every point at (x, |y|, z), so the copy is bit-identical to
computing it.

Checkpoint/resume: the chunks run on the one engine, :func:`deltajax.workspace.chunks.run_chunks`; with
``checkpoint_dir`` the outputs live in ``<dir>/<name>.npy`` memory maps and ``<dir>/state.json`` records the
finished chunks with a sha256 of each (:class:`deltajax.workspace.chunks.MemmapCheckpoint`). A killed run
restarts at the first unfinished chunk; chunks are deterministic, so the result is bit-for-bit that of an
uninterrupted run. A checkpoint written with other parameters, or a damaged one, is refused with an error
naming the directory rather than silently used.

Jobs::

    fixed_workspace(robot, grid, ...)            -> GridJob(ok, fields, complete)   fields NaN outside
    reconfigurable_workspace(recon, grid, ...)   -> GridJob(ok, {}, complete)        some R sample reaches
    redundancy_grid(recon, grid, mask=..., ...)  -> GridJob(ok, fields incl. "R_star", "k_star", complete)
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
from pathlib import Path
from typing import Mapping, Optional, Sequence

import numpy as np

from ..geometry import Delta, ReconfigurableDelta
from ..indices import INDEX_NAMES
from .chunks import CheckpointMismatch, run_chunks
from .grid import Grid
from .redundancy import nb_params, reach_k_range_host, resolve_redundancy_host, SCREEN_MARGIN
from .stats import stats_from_partials

__all__ = ["GridJob", "run_chunks", "fixed_workspace", "reconfigurable_workspace", "redundancy_grid", "computed_points",
           "CheckpointMismatch", "reach_box", "face_count"]


@dataclasses.dataclass(frozen=True, eq=False)
class GridJob:
    """Result of a grid job; arrays have the grid's shape (nx, ny, nz).

    A dataclass, not a NamedTuple: ``job.count`` is the number of reachable points, not ``tuple.count``.

    Attributes:
        ok: reachable / feasible mask.
        fields: name -> array (NaN outside ``ok``).
        complete: False when stopped early by ``max_chunks`` (resume to finish).
        stats: with ``stats=True``: {index: {"min", "max", "mean", "count"}} over the job's points (None when
            not asked for or not complete).
    """

    ok: np.ndarray
    fields: dict
    complete: bool
    stats: Optional[dict] = None

    @property
    def count(self) -> int:
        """Number of reachable / feasible grid points."""
        return int(np.count_nonzero(self.ok))


# -- grid layout (mirror halving) ------------------------------------------------------------------------

class _Layout:
    """Items of a job: the whole grid, or its y >= 0 half when the grid is mirror-symmetric."""

    def __init__(self, grid: Grid, mirror: bool):
        nx, ny, nz = grid.shape
        self.grid = grid
        self.mirror = bool(mirror and grid.mirror_symmetric)
        self.j0 = ny // 2 if self.mirror else 0
        self.shape = (nx, ny - self.j0, nz)
        self.n = int(np.prod(self.shape))
        # weights of the items in full-grid statistics: a mirror-half item stands for itself and its image,
        # except on the mirror plane y = 0 (the half's first row when ny is odd)
        self.weights = (1.0 if ny % 2 else 2.0, 2.0) if self.mirror else (1.0, 1.0)

    def points(self, start: int, stop: int) -> np.ndarray:
        nx, nyh, nz = self.shape
        idx = np.arange(start, stop, dtype=np.int64)
        i, rem = np.divmod(idx, nyh * nz)
        j, k = np.divmod(rem, nz)
        g = self.grid
        return np.stack([g.x[i], g.y[j + self.j0], g.z[k]], axis=-1)

    def points_into(self, start: int, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> None:
        """Coordinates of items start, start + 1, ... (``len(x)`` of them) written into preallocated buffers."""
        from . import numba_fields

        g = self.grid
        numba_fields.grid_points(np.asarray(g.x, np.float64), np.asarray(g.y, np.float64), np.asarray(g.z, np.float64),
                        self.j0, self.shape[1], start, x, y, z)

    def take(self, full: np.ndarray, start: int, stop: int) -> np.ndarray:
        """Values of a full-grid array at items start:stop."""
        return full[:, self.j0:, :].reshape(-1)[start:stop] if full.ndim == 3 else full[start:stop]

    def take_all(self, full: np.ndarray) -> np.ndarray:
        """Per-item values (flat, contiguous) of a full-grid array: one copy for the whole job."""
        return np.ascontiguousarray(full[:, self.j0:, :]).reshape(-1) if full.ndim == 3 else np.asarray(full)

    def expand(self, flat: np.ndarray) -> np.ndarray:
        """Full-grid array (nx, ny, nz) from per-item values."""
        half = np.asarray(flat).reshape(self.shape)
        if not self.mirror:
            return np.array(half)
        nx, ny, nz = self.grid.shape
        full = np.empty((nx, ny, nz), dtype=half.dtype)
        full[:, self.j0:, :] = half
        full[:, :self.j0, :] = half[:, ::-1, :][:, :self.j0, :]
        return full

    def expand_all(self, arrays: dict, names) -> dict:
        """:meth:`expand` of each named per-item array, releasing each one (and its memory map) once expanded:
        the peak is the full-grid outputs plus one per-item array, not both sets."""
        out = {}
        for n in names:
            out[n] = self.expand(arrays.pop(n))
        return out


class _ChunkStats:
    """Per-chunk partial statistics (min, max, weighted sum, weighted count) of the index fields, kept in
    ``<checkpoint_dir>/stats_partials.npy`` when checkpointing so that a resumed job still has those of the
    chunks it does not recompute (a chunk without them is an error, never a silently shorter mean)."""

    def __init__(self, lay: _Layout, n_chunks: int, names, checkpoint_dir):
        self.lay, self.names = lay, tuple(names)
        shape = (n_chunks, len(self.names), 4)
        path = None if checkpoint_dir is None else Path(checkpoint_dir) / "stats_partials.npy"
        if path is not None and path.exists() and (Path(checkpoint_dir) / "state.json").exists():
            self.parts = np.load(path, mmap_mode="r+")
            if self.parts.shape != shape:
                raise CheckpointMismatch(f"{path} has shape {self.parts.shape}, this job needs {shape}; use another "
                                         f"directory")
        elif path is not None:
            Path(checkpoint_dir).mkdir(parents=True, exist_ok=True)
            self.parts = np.lib.format.open_memmap(path, mode="w+", dtype=np.float64, shape=shape)
            self.parts[:] = np.nan
            self.parts.flush()
        else:
            self.parts = np.full(shape, np.nan)

    def add(self, chunk: int, start: int, vals: np.ndarray) -> None:
        """Partial statistics of chunk ``chunk`` (items from ``start``), ``vals`` (len(names), n)."""
        from . import numba_fields

        numba_fields.partial_stats(vals, start, self.lay.shape[2], self.lay.shape[1], *self.lay.weights,
                          np.asarray(self.parts[chunk]))
        if isinstance(self.parts, np.memmap):
            self.parts.flush()  # before run_chunks records the chunk as done

    def result(self, complete: bool) -> Optional[dict]:
        if not complete:
            return None
        missing = np.flatnonzero(np.isnan(self.parts[:, 0, 3]))
        if missing.size:
            raise CheckpointMismatch(f"index statistics of chunks {missing[:5].tolist()} are missing from the "
                                     f"checkpoint (written by an older version?); rerun into a fresh directory")
        return stats_from_partials(self.parts, self.names)


class _ChunkCounters:
    """Per-chunk work counters, kept in ``<checkpoint_dir>/work_partials.npy`` when checkpointing (like
    :class:`_ChunkStats`): a resumed job reports the work of every chunk, those of earlier processes included, the
    same numbers as an uninterrupted run (-1: the chunk has not been computed)."""

    def __init__(self, names, n_chunks: int, checkpoint_dir):
        self.names = tuple(names)
        self.resumed = None  # items found done in the checkpoint, once known
        shape = (n_chunks, len(self.names))
        path = None if checkpoint_dir is None else Path(checkpoint_dir) / "work_partials.npy"
        if path is not None and path.exists() and (Path(checkpoint_dir) / "state.json").exists():
            self.parts = np.load(path, mmap_mode="r+")
            if self.parts.shape != shape or self.parts.dtype != np.int64:
                raise CheckpointMismatch(f"{path} holds {self.parts.dtype}{self.parts.shape}, this job needs "
                                         f"int64{shape}; use another directory")
        elif path is not None:
            Path(checkpoint_dir).mkdir(parents=True, exist_ok=True)
            self.parts = np.lib.format.open_memmap(path, mode="w+", dtype=np.int64, shape=shape)
            self.parts[:] = -1
            self.parts.flush()
        else:
            self.parts = np.full(shape, -1, np.int64)

    def set(self, chunk: int, counters: Mapping[str, int]) -> None:
        if self.resumed is None:
            self.resumed = 0  # the first chunk computed: nothing was resumed
        self.parts[chunk] = [int(counters[n]) for n in self.names]
        if isinstance(self.parts, np.memmap):
            self.parts.flush()  # before run_chunks records the chunk as done

    def totals(self, done_chunks: int) -> dict:
        """The counters summed over the first ``done_chunks`` chunks (all of them must have been recorded)."""
        part = np.asarray(self.parts[:done_chunks])
        missing = np.flatnonzero((part < 0).any(axis=1))
        if missing.size:
            raise CheckpointMismatch(f"work counters of chunks {missing[:5].tolist()} are missing from the checkpoint "
                                     f"(written by an older version?); rerun into a fresh directory")
        return {n: int(part[:, i].sum()) for i, n in enumerate(self.names)}


def _robot_desc(robot: Delta) -> dict:
    return {k: float(np.asarray(getattr(robot, k))) for k in
            ("base_radius", "platform_radius", "upper_arm", "forearm", "theta_min", "theta_max")}


def _grid_desc(grid: Grid) -> dict:
    return {"shape": grid.shape, "h": grid.h, "x0": float(grid.x[0]), "y0": float(grid.y[0]), "z0": float(grid.z[0])}


def computed_points(grid: Grid, mirror: bool = True) -> int:
    """How many points a grid job computes: the whole grid, or its y >= 0 half under mirror halving (the total of
    its progress bar: create the bar with it, ``ctx.progress(total=computed_points(grid))``)."""
    return _Layout(grid, mirror).n


def _progress_total(progress, total):
    """Correct the bar's total to the points actually computed when the caller created it with another one,
    whether the caller passed the bar or its ``update`` method (``progress=bar.update``: the bar is ``__self__``).
    A bar created with :func:`computed_points` is left alone (no second line in a log file)."""
    bar = getattr(progress, "__self__", progress)
    if progress is not None and hasattr(bar, "reset") and getattr(bar, "total", None) != total:
        bar.reset(total=total)


def fixed_workspace(robot: Delta, grid: Grid, *, fields: bool = True, b_v: float = 2.0, b_f: float = 4.2,
                    beta: float = 0.5, field_dtype=np.float64, chunk_size: int = 1 << 20, mirror: bool = True,
                    checkpoint_dir: Optional[os.PathLike] = None, progress=None,
                    max_chunks: Optional[int] = None, keep: Optional[Sequence[str]] = None,
                    stats: bool = False, sv_method: str = "jacobi") -> GridJob:
    """Reachable mask (and every index, NaN outside) of a fixed robot over ``grid``.

    Args:
        robot: the robot (concrete values).
        grid: the grid.
        fields: also compute the index fields (else only the mask, IK only).
        b_v, b_f, beta: parameters of k~.
        field_dtype: dtype of the stored fields (float32 halves the memory of 2 mm grids).
        chunk_size: points per chunk.
        mirror: compute the y >= 0 half only (exact, see module docstring).
        checkpoint_dir, max_chunks: checkpoint/resume (see :func:`run_chunks`).
        progress: callable(n) called with the points finished per chunk (``tqdm.update``).
        keep: index fields returned on the grid (default: all of :data:`deltajax.INDEX_NAMES`); the others
            are still computed for ``stats`` but never stored (memory of 2 mm grids).
        stats: also return min / max / mean of every index over the reachable points (``GridJob.stats``, the
            format of :func:`deltajax.workspace.index_stats`, of the values in ``field_dtype``), accumulated
            chunk by chunk.
        sv_method: ``"jacobi"`` (exact singular values, default) or ``"fast"`` (the closed-form cubic of
            :func:`deltajax.indices.sym3_top2`, ~1e-9 relative, ~1e-8 within 1e-5 m of the robot's axis).
    """
    from . import numba_fields

    keep = _check_keep(keep, INDEX_NAMES) if fields else ()
    if sv_method not in numba_fields.SV_METHODS:
        raise ValueError(f"sv_method must be one of {tuple(numba_fields.SV_METHODS)}, got {sv_method!r}")
    method = numba_fields.SV_METHODS[sv_method]
    lay = _Layout(grid, mirror)
    q = _robot_desc(robot)
    lim = numba_fields.limits_tuple(q["theta_min"], q["theta_max"])
    kt = numba_fields.kt_tuple(b_v, b_f, beta)
    outputs = {"ok": (np.bool_, False)}
    outputs.update({n: (field_dtype, np.nan) for n in keep})
    n_chunks = max(1, math.ceil(lay.n / chunk_size))
    acc = _ChunkStats(lay, n_chunks, INDEX_NAMES, checkpoint_dir) if (stats and fields) else None
    # chunk buffers, allocated once and reused: fresh arrays per chunk cost page faults, not arithmetic
    m = min(chunk_size, lay.n)
    xb, yb, zb = np.empty(m), np.empty(m), np.empty(m)
    okb = np.empty(m, np.bool_)
    outb = np.empty((numba_fields.N_IDX, m)) if fields else None
    castb = outb if (outb is None or np.dtype(field_dtype) == np.float64) else np.empty((numba_fields.N_IDX, m), field_dtype)
    cols = {n: i for i, n in enumerate(INDEX_NAMES)}
    R, r, L1, L2 = q["base_radius"], q["platform_radius"], q["upper_arm"], q["forearm"]

    def compute(start, stop):
        n = stop - start
        x, y, z, ok = xb[:n], yb[:n], zb[:n], okb[:n]
        lay.points_into(start, x, y, z)
        if not fields:
            numba_fields.parallel(lambda a, b: numba_fields.fixed_mask(x[a:b], y[a:b], z[a:b], R, r, L1, L2, lim, ok[a:b]), n)
            return {"ok": ok}
        out = outb[:, :n]
        numba_fields.parallel(lambda a, b: numba_fields.fixed_fields(x[a:b], y[a:b], z[a:b], R, r, L1, L2, lim, kt,
                                                   numba_fields.rows(out, a, b), ok[a:b], method), n)
        vals = castb[:, :n]
        if vals is not out:
            vals[...] = out
        if acc is not None:
            acc.add(start // chunk_size, start, vals)
        res = {"ok": ok}
        res.update({k: vals[cols[k]] for k in keep})
        return res

    _progress_total(progress, lay.n)
    fp = {"job": "fixed", "robot": q, "grid": _grid_desc(grid), "fields": fields, "kt": [b_v, b_f, beta],
          "mirror": lay.mirror}
    if keep != tuple(INDEX_NAMES) or acc is not None or method != numba_fields.JACOBI:  # older checkpoints stay valid
        fp.update(keep=list(keep), stats=acc is not None, sv_method=sv_method)
    arrays, complete = run_chunks(lay.n, chunk_size, compute, outputs, checkpoint_dir=checkpoint_dir,
                                  fingerprint=fp, progress=progress, max_chunks=max_chunks)
    st = None if acc is None else acc.result(complete)
    out = lay.expand_all(arrays, list(outputs))
    ok = out.pop("ok")
    return GridJob(ok=ok, fields=out, complete=complete, stats=st)


def _check_keep(keep, names) -> tuple:
    if keep is None:
        return tuple(names)
    keep = tuple(keep)
    for n in keep:
        if n not in names:
            raise ValueError(f"keep: {n!r} is not one of {tuple(names)}")
    return keep


def _recon_desc(recon: ReconfigurableDelta) -> dict:
    d = _robot_desc(recon.robot)
    d.update(R_min=float(np.asarray(recon.R_min)), R_step=float(np.asarray(recon.R_step)), n_R=recon.n_R)
    return d


def reconfigurable_workspace(recon: ReconfigurableDelta, grid: Grid, *, chunk_size: int = 1 << 20,
                             mirror: bool = True, checkpoint_dir: Optional[os.PathLike] = None, progress=None,
                             max_chunks: Optional[int] = None) -> GridJob:
    """Mask of grid points reachable by *some* R sample (IK within limits), chunked with checkpoints.

    Each point tests only the samples of its closed-form reach range and stops at the first feasible one.
    """
    from . import numba_fields

    lay = _Layout(grid, mirror)
    q = nb_params(recon)

    def compute(start, stop):
        pts = lay.points(start, stop)
        k_lo, k_stop = reach_k_range_host(recon, pts)
        ok = np.empty(len(pts), np.bool_)
        numba_fields.parallel(lambda a, b: numba_fields.any_reach(pts[a:b], k_lo[a:b], k_stop[a:b], q["R_min"], q["R_step"], q["r"],
                                                q["L1"], q["L2"], q["lim"], ok[a:b]), len(pts))
        return {"ok": ok}

    _progress_total(progress, lay.n)
    arrays, complete = run_chunks(lay.n, chunk_size, compute, {"ok": (np.bool_, False)},
                                  checkpoint_dir=checkpoint_dir,
                                  fingerprint={"job": "reconf", "robot": _recon_desc(recon), "grid": _grid_desc(grid),
                                               "mirror": lay.mirror},
                                  progress=progress, max_chunks=max_chunks)
    return GridJob(ok=lay.expand(arrays["ok"]), fields={}, complete=complete)


def redundancy_grid(recon: ReconfigurableDelta, grid: Grid, *, mask: Optional[np.ndarray] = None,
                    criterion: str = "k_tilde", mode: str = "fast", b_v: float = 2.0, b_f: float = 4.2,
                    beta: float = 0.5, field_dtype=np.float64, chunk_size: int = 1 << 18,
                    checkpoint_dir: Optional[os.PathLike] = None, progress=None,
                    max_chunks: Optional[int] = None, work: Optional[dict] = None, screen: bool = True,
                    screen_margin: Optional[float] = None, keep: Optional[Sequence[str]] = None,
                    stats: bool = False, R_dtype=np.float64) -> GridJob:
    """Redundancy resolution at every grid point (or those in ``mask``), with every index at R*.

    Args:
        recon: the reconfigurable robot.
        grid: the grid.
        mask: bool (nx, ny, nz) of points to solve (e.g. the fixed robot's workspace for Tables 6-8);
            ``None`` = all. In fast mode it must be mirror-symmetric when the grid is (it is for masks
            computed by this module).
        criterion, b_v, b_f, beta: as in :func:`deltajax.workspace.resolve_redundancy`.
        mode: ``"fast"`` (mirror half + closed-form reach ranges) or ``"exact"`` (all points, all samples).
        field_dtype: dtype of the stored index fields.
        chunk_size, checkpoint_dir, progress, max_chunks: see :func:`run_chunks`.
        work: if a dict, receives the work counters (window samples, exact kernel evaluations, screened
            samples, fallbacks; see :func:`deltajax.workspace.resolve_redundancy_host`) of every finished chunk,
            those of earlier processes included (kept per chunk in the checkpoint): a resumed job reports what an
            uninterrupted one does.
        screen, screen_margin: fast mode's screen-and-verify (see ``resolve_redundancy_host``); the selection
            does not depend on them, so they are not part of the checkpoint fingerprint.
        keep: fields returned on the grid, among :data:`deltajax.INDEX_NAMES`, ``"R_star"`` and ``"k_star"``
            (default: all); the others are never stored (memory of 2 mm grids).
        stats: also return min / max / mean of every index at R* over the solved points (``GridJob.stats``,
            the format of :func:`deltajax.workspace.index_stats`, of the values in ``field_dtype``),
            accumulated chunk by chunk.
        R_dtype: dtype of the stored ``"R_star"`` (float32 halves its memory on 2 mm grids; the selection is
            ``k_star`` either way).

    Returns:
        :class:`GridJob`: ``ok`` (a feasible sample exists), fields: every index at R*, ``"R_star"`` (m),
        ``"k_star"`` (int32, -1 where none) -- those in ``keep``.
    """
    if screen_margin is None:
        screen_margin = SCREEN_MARGIN
    all_fields = {"k_star": (np.int32, -1), "R_star": (R_dtype, np.nan)}
    all_fields.update({n: (field_dtype, np.nan) for n in INDEX_NAMES})
    keep = _check_keep(keep, tuple(all_fields))
    lay = _Layout(grid, mirror=(mode == "fast"))
    outputs = {"ok": (np.bool_, False)}
    outputs.update({n: all_fields[n] for n in all_fields if n in keep})
    n_chunks = max(1, math.ceil(lay.n / chunk_size))
    counts = _ChunkCounters(("samples", "full", "points", "screened", "fallback"), n_chunks, checkpoint_dir)
    acc = _ChunkStats(lay, n_chunks, INDEX_NAMES, checkpoint_dir) if stats else None
    need_indices = acc is not None or any(n in INDEX_NAMES for n in keep)
    sel_all = None if mask is None else lay.take_all(np.asarray(mask, bool))  # once, not per chunk
    # chunk buffers, allocated once and reused
    m = min(chunk_size, lay.n)
    ptsb = np.empty((m, 3))
    okb, kb, Rb = np.empty(m, np.bool_), np.empty(m, np.int32), np.empty(m)
    valsb = np.empty((len(INDEX_NAMES), m), field_dtype)
    cols = {n: i for i, n in enumerate(INDEX_NAMES)}

    def compute(start, stop):
        n = stop - start
        pts, ok, k, R, vals = ptsb[:n], okb[:n], kb[:n], Rb[:n], valsb[:, :n]
        lay.points_into(start, pts[:, 0], pts[:, 1], pts[:, 2])
        ok.fill(False)
        k.fill(-1)
        R.fill(np.nan)
        vals.fill(np.nan)
        sel = None if sel_all is None else sel_all[start:stop]
        w = dict.fromkeys(counts.names, 0)
        if sel is None or sel.any():
            red, w = resolve_redundancy_host(recon, pts if sel is None else pts[sel], criterion, mode=mode, b_v=b_v,
                                             b_f=b_f, beta=beta, mirror=False, screen=screen,
                                             screen_margin=screen_margin, return_indices=need_indices)
            idx = slice(None) if sel is None else sel
            ok[idx] = red.ok
            k[idx] = red.k
            R[idx] = red.R
            if need_indices:
                vals[:, idx] = red.indices.T
        if acc is not None:
            acc.add(start // chunk_size, start, vals)
        counts.set(start // chunk_size, w)
        res = {"ok": ok, "k_star": k, "R_star": R}
        res.update({c: vals[i] for c, i in cols.items()})
        return res

    _progress_total(progress, lay.n)
    fp = {"job": "redundancy", "robot": _recon_desc(recon), "grid": _grid_desc(grid), "criterion": criterion,
          "mode": mode, "kt": [b_v, b_f, beta],
          "mask": None if mask is None else hashlib.sha256(np.packbits(mask)).hexdigest()[:16]}
    if keep != tuple(all_fields) or acc is not None or np.dtype(R_dtype) != np.float64:
        fp.update(keep=list(keep), stats=acc is not None)  # (the defaults keep older checkpoints valid)
    done_items = [0]  # items finished, earlier processes' included (run_chunks reports those first)

    def advance(n: int) -> None:
        if work is not None and done_items[0] == 0 and counts.resumed is None:  # the resumed chunks, first
            counts.resumed = n
            counts.totals(math.ceil(n / chunk_size))  # their counters are there: refused now, not at the end
        done_items[0] += n
        if progress is not None:
            progress(n)

    arrays, complete = run_chunks(lay.n, chunk_size, compute, outputs, checkpoint_dir=checkpoint_dir,
                                  fingerprint=fp, progress=advance, max_chunks=max_chunks)
    if work is not None:  # every finished chunk's, those of the processes before a resume included
        work.update(counts.totals(math.ceil(done_items[0] / chunk_size)))
    st = None if acc is None else acc.result(complete)
    out = lay.expand_all(arrays, list(outputs))
    ok = out.pop("ok")
    return GridJob(ok=ok, fields=out, complete=complete, stats=st)


# -- box from the reach bound, truncation -----------------------------------------------------------------

def _sin_range(lo: float, hi: float) -> tuple[float, float]:
    """(min, max) of sin over the angle interval [lo, hi] (rad)."""
    if hi - lo >= 2 * math.pi:
        return -1.0, 1.0
    ends = [math.sin(lo), math.sin(hi)]
    k_hi = math.floor((hi - math.pi / 2) / (2 * math.pi))  # largest pi/2 + 2 pi k <= hi
    k_lo = math.floor((hi + math.pi / 2) / (2 * math.pi))  # largest -pi/2 + 2 pi k <= hi
    top = 1.0 if math.pi / 2 + 2 * math.pi * k_hi >= lo else max(ends)
    bottom = -1.0 if -math.pi / 2 + 2 * math.pi * k_lo >= lo else min(ends)
    return bottom, top


def reach_box(robot: Delta, R_max: Optional[float] = None) -> tuple[tuple[float, float], ...]:
    """A box (m, z down) holding every point the platform centre can reach: ((x0, x1), (y0, y1), (z0, z1)).

    Closed form: chain i's platform joint is within L2 of its elbow, which lies at (R - r + L1 cos theta) u_i +
    L1 sin theta e_z from the base centre shifted by the platform offset, so the centre p satisfies, for every
    chain, |p_h - (R - r) u_i| <= L1 max|cos theta| + L2 horizontally and L1 min sin theta - L2 <= p_z <=
    L1 max sin theta + L2 over the joint range. The box is the intersection of the three chains' boxes.

    Args:
        robot: the robot (concrete values).
        R_max: for a reconfigurable robot, the largest base radius (the box then holds every R up to it;
            R - r enters only through the horizontal centres, and the union over R is taken end to end).
    """
    q = _robot_desc(robot)
    L1, L2 = q["upper_arm"], q["forearm"]
    lo, hi = q["theta_min"], q["theta_max"]
    if not (math.isfinite(lo) and math.isfinite(hi)):
        lo, hi = -math.pi, math.pi
    s_lo, s_hi = _sin_range(lo, hi)
    c_lo, c_hi = _sin_range(lo + math.pi / 2, hi + math.pi / 2)  # cos theta = sin(theta + pi/2)
    rho = L1 * max(abs(c_lo), abs(c_hi)) + L2
    ds = [q["base_radius"] - q["platform_radius"]]
    if R_max is not None:
        ds.append(float(R_max) - q["platform_radius"])
        ds += [0.0] if ds[0] < 0.0 < ds[1] else []  # R = r inside the range: the boxes' union is widest there
    boxes = []
    for d in ds:
        cx = [d * math.cos(2 * math.pi * i / 3) for i in range(3)]
        cy = [d * math.sin(2 * math.pi * i / 3) for i in range(3)]
        boxes.append(((max(cx) - rho, min(cx) + rho), (max(cy) - rho, min(cy) + rho)))
    x = (min(b[0][0] for b in boxes), max(b[0][1] for b in boxes))
    y = (min(b[1][0] for b in boxes), max(b[1][1] for b in boxes))
    return x, y, (L1 * s_lo - L2, L1 * s_hi + L2)


def face_count(mask: np.ndarray) -> int:
    """Number of True points of a 3-D mask on the faces of its box (each counted once).

    A reachable point on a face means the reachable set may continue outside the grid: a volume computed from
    the mask is then a lower bound, not the workspace volume.
    """
    m = np.asarray(mask, dtype=bool)
    inner = m[1:-1, 1:-1, 1:-1].sum() if min(m.shape) > 2 else 0
    return int(m.sum() - inner)
