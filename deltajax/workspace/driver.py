"""Chunked grid jobs with progress and checkpoint/resume (host side).

Every job walks the grid in chunks of ``chunk_size`` points, so working memory is bounded at any grid size;
outputs are one value per grid point (NumPy arrays, or ``.npy`` memory maps in the checkpoint directory).
When the grid is mirror-symmetric (:attr:`Grid.mirror_symmetric`) only the half y >= 0 is computed and the
other half is copied: the kernels evaluate every point at (x, |y|, z), so the copy is bit-identical to
computing it.

Checkpoint/resume: with ``checkpoint_dir`` the outputs live in ``<dir>/<name>.npy`` memory maps and
``<dir>/state.json`` records the number of finished chunks, rewritten atomically (temporary file + rename)
after the chunk's data is flushed. A killed run restarts at the first unfinished chunk; chunks are
deterministic, so the result is bit-for-bit that of an uninterrupted run. A checkpoint written with other
parameters (its fingerprint differs) is refused with an error rather than silently mixed.

Jobs::

    fixed_workspace(robot, grid, ...)            -> GridJob(ok, fields, complete)   fields NaN outside
    reconfigurable_workspace(recon, grid, ...)   -> GridJob(ok, {}, complete)        some R sample reaches
    redundancy_grid(recon, grid, mask=..., ...)  -> GridJob(ok, fields incl. "R_star", "k_star", complete)
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
from pathlib import Path
from typing import Any, Callable, NamedTuple, Optional

import numpy as np

from ..geometry import Delta, ReconfigurableDelta
from ..indices import INDEX_NAMES
from .grid import Grid

__all__ = ["GridJob", "run_chunks", "fixed_workspace", "reconfigurable_workspace", "redundancy_grid",
           "CheckpointMismatch"]


class CheckpointMismatch(RuntimeError):
    """The checkpoint directory holds a run with different parameters."""


@dataclasses.dataclass(frozen=True, eq=False)
class GridJob:
    """Result of a grid job; arrays have the grid's shape (nx, ny, nz).

    A dataclass, not a NamedTuple: ``job.count`` is the number of reachable points, not ``tuple.count``.

    Attributes:
        ok: reachable / feasible mask.
        fields: name -> array (NaN outside ``ok``).
        complete: False when stopped early by ``max_chunks`` (resume to finish).
    """

    ok: np.ndarray
    fields: dict
    complete: bool

    @property
    def count(self) -> int:
        """Number of reachable / feasible grid points."""
        return int(np.count_nonzero(self.ok))


def _fingerprint(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]


def run_chunks(n_items: int, chunk_size: int, compute: Callable[[int, int], dict], outputs: dict, *,
               checkpoint_dir: Optional[os.PathLike] = None, fingerprint: Any = None,
               progress: Optional[Callable[[int], None]] = None, max_chunks: Optional[int] = None
               ) -> tuple[dict, bool]:
    """Run ``compute(start, stop) -> {name: array[stop - start, ...]}`` over ``n_items`` in chunks.

    Args:
        n_items: number of items (grid points).
        chunk_size: items per chunk.
        compute: the chunk function (deterministic).
        outputs: name -> (dtype, fill value) of each per-item output.
        checkpoint_dir: resume from / checkpoint into this directory (memory-mapped outputs).
        fingerprint: JSON-able description of the job; a checkpoint with another fingerprint is refused.
        progress: called with the number of items finished after each chunk (e.g. ``tqdm.update``).
        max_chunks: stop after this many chunks in *this call* (simulates a kill; resume later).

    Returns:
        (outputs, complete).
    """
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be >= 1, got {chunk_size!r}")
    n_chunks = max(1, math.ceil(n_items / chunk_size))
    fp = _fingerprint({"n": n_items, "chunk": chunk_size, "job": fingerprint,
                       "outputs": {k: str(np.dtype(v[0])) for k, v in outputs.items()}})
    done = 0
    arrays: dict = {}
    state_path = None
    if checkpoint_dir is not None:
        ck = Path(checkpoint_dir)
        ck.mkdir(parents=True, exist_ok=True)
        state_path = ck / "state.json"
        if state_path.exists():
            state = json.loads(state_path.read_text())
            if state.get("fingerprint") != fp:
                raise CheckpointMismatch(f"checkpoint {ck} was written by a different job "
                                         f"(fingerprint {state.get('fingerprint')} != {fp}); use another directory")
            done = int(state["done_chunks"])
            for name in outputs:
                arrays[name] = np.load(ck / f"{name}.npy", mmap_mode="r+")
        else:
            for name, (dtype, fill) in outputs.items():
                arr = np.lib.format.open_memmap(ck / f"{name}.npy", mode="w+", dtype=dtype, shape=(n_items,))
                arr[:] = fill
                arrays[name] = arr
            _write_state(state_path, fp, 0, n_chunks)
    else:
        arrays = {name: np.full(n_items, fill, dtype=dtype) for name, (dtype, fill) in outputs.items()}
    if progress is not None and done:
        progress(min(done * chunk_size, n_items))
    ran = 0
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
        if state_path is not None:
            for a in arrays.values():
                a.flush()
            _write_state(state_path, fp, done, n_chunks)
        if progress is not None:
            progress(stop - start)
    return arrays, done >= n_chunks


def _write_state(path: Path, fp: str, done: int, n_chunks: int) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps({"fingerprint": fp, "done_chunks": done, "n_chunks": n_chunks}))
    os.replace(tmp, path)


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

    def points(self, start: int, stop: int) -> np.ndarray:
        nx, nyh, nz = self.shape
        idx = np.arange(start, stop, dtype=np.int64)
        i, rem = np.divmod(idx, nyh * nz)
        j, k = np.divmod(rem, nz)
        g = self.grid
        return np.stack([g.x[i], g.y[j + self.j0], g.z[k]], axis=-1)

    def take(self, full: np.ndarray, start: int, stop: int) -> np.ndarray:
        """Values of a full-grid array at items start:stop."""
        return full[:, self.j0:, :].reshape(-1)[start:stop] if full.ndim == 3 else full[start:stop]

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


def _robot_desc(robot: Delta) -> dict:
    return {k: float(np.asarray(getattr(robot, k))) for k in
            ("base_radius", "platform_radius", "upper_arm", "forearm", "theta_min", "theta_max")}


def _grid_desc(grid: Grid) -> dict:
    return {"shape": grid.shape, "h": grid.h, "x0": float(grid.x[0]), "y0": float(grid.y[0]), "z0": float(grid.z[0])}


def _progress_total(progress, total):
    """Set the bar's total to the points actually computed (half the grid under mirror halving), whether the
    caller passed the bar or its ``update`` method (``progress=bar.update``: the bar is ``__self__``)."""
    bar = getattr(progress, "__self__", progress)
    if progress is not None and hasattr(bar, "reset"):
        bar.reset(total=total)


def fixed_workspace(robot: Delta, grid: Grid, *, fields: bool = True, b_v: float = 2.0, b_f: float = 4.2,
                    beta: float = 0.5, field_dtype=np.float64, chunk_size: int = 1 << 20, mirror: bool = True,
                    checkpoint_dir: Optional[os.PathLike] = None, progress=None,
                    max_chunks: Optional[int] = None) -> GridJob:
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
    """
    from . import _nb

    lay = _Layout(grid, mirror)
    q = _robot_desc(robot)
    lim = _nb.limits_tuple(q["theta_min"], q["theta_max"])
    kt = _nb.kt_tuple(b_v, b_f, beta)
    outputs = {"ok": (np.bool_, False)}
    if fields:
        outputs.update({n: (field_dtype, np.nan) for n in INDEX_NAMES})

    def compute(start, stop):
        pts = lay.points(start, stop)
        ok = np.empty(len(pts), np.bool_)
        if not fields:
            _nb.parallel(lambda a, b: _nb.fixed_mask(pts[a:b], q["base_radius"], q["platform_radius"], q["upper_arm"],
                                                     q["forearm"], lim, ok[a:b]), len(pts))
            return {"ok": ok}
        out = np.empty((len(pts), _nb.N_IDX))
        _nb.parallel(lambda a, b: _nb.fixed_fields(pts[a:b], q["base_radius"], q["platform_radius"], q["upper_arm"],
                                                   q["forearm"], lim, kt, out[a:b], ok[a:b]), len(pts))
        res = {"ok": ok}
        res.update({n: out[:, i] for i, n in enumerate(INDEX_NAMES)})
        return res

    _progress_total(progress, lay.n)
    arrays, complete = run_chunks(lay.n, chunk_size, compute, outputs, checkpoint_dir=checkpoint_dir,
                                  fingerprint={"job": "fixed", "robot": q, "grid": _grid_desc(grid), "fields": fields,
                                               "kt": [b_v, b_f, beta], "mirror": lay.mirror},
                                  progress=progress, max_chunks=max_chunks)
    ok = lay.expand(arrays["ok"])
    out = {n: lay.expand(arrays[n]) for n in outputs if n != "ok"}
    return GridJob(ok=ok, fields=out, complete=complete)


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
    from . import _nb
    from .redundancy import _nb_params, reach_k_range_host

    lay = _Layout(grid, mirror)
    q = _nb_params(recon)

    def compute(start, stop):
        pts = lay.points(start, stop)
        k_lo, k_stop = reach_k_range_host(recon, pts)
        ok = np.empty(len(pts), np.bool_)
        _nb.parallel(lambda a, b: _nb.any_reach(pts[a:b], k_lo[a:b], k_stop[a:b], q["R_min"], q["R_step"], q["r"],
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
                    screen_margin: Optional[float] = None) -> GridJob:
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
            samples, fallbacks; see :func:`deltajax.workspace.resolve_redundancy_host`) of this call.
        screen, screen_margin: fast mode's screen-and-verify (see ``resolve_redundancy_host``); the selection
            does not depend on them, so they are not part of the checkpoint fingerprint.

    Returns:
        :class:`GridJob`: ``ok`` (a feasible sample exists), fields: every index at R*, ``"R_star"`` (m),
        ``"k_star"`` (int32, -1 where none).
    """
    from .redundancy import SCREEN_MARGIN, resolve_redundancy_host

    if screen_margin is None:
        screen_margin = SCREEN_MARGIN
    lay = _Layout(grid, mirror=(mode == "fast"))
    outputs = {"ok": (np.bool_, False), "k_star": (np.int32, -1), "R_star": (np.float64, np.nan)}
    outputs.update({n: (field_dtype, np.nan) for n in INDEX_NAMES})
    counters = {"samples": 0, "full": 0, "points": 0, "screened": 0, "fallback": 0}

    def compute(start, stop):
        pts = lay.points(start, stop)
        sel = np.ones(len(pts), bool) if mask is None else lay.take(mask, start, stop).astype(bool)
        res = {n: np.full(len(pts), fill, dtype=dt) for n, (dt, fill) in outputs.items()}
        if sel.any():
            red, w = resolve_redundancy_host(recon, pts[sel], criterion, mode=mode, b_v=b_v, b_f=b_f, beta=beta,
                                             mirror=False, screen=screen, screen_margin=screen_margin)
            for k in counters:
                counters[k] += w[k]
            res["ok"][sel] = red.ok
            res["k_star"][sel] = red.k
            res["R_star"][sel] = red.R
            for i, n in enumerate(INDEX_NAMES):
                res[n][sel] = red.indices[:, i]
        return res

    _progress_total(progress, lay.n)
    fp = {"job": "redundancy", "robot": _recon_desc(recon), "grid": _grid_desc(grid), "criterion": criterion,
          "mode": mode, "kt": [b_v, b_f, beta],
          "mask": None if mask is None else hashlib.sha256(np.packbits(mask)).hexdigest()[:16]}
    arrays, complete = run_chunks(lay.n, chunk_size, compute, outputs, checkpoint_dir=checkpoint_dir,
                                  fingerprint=fp, progress=progress, max_chunks=max_chunks)
    if work is not None:
        work.update(counters)
    out = {n: lay.expand(arrays[n]) for n in outputs if n != "ok"}
    return GridJob(ok=lay.expand(arrays["ok"]), fields=out, complete=complete)
