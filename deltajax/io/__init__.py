"""HDF5 results (docs/results.md): one self-describing file per run, written atomically, and the one reader.

The bottom of the import graph: this package imports nothing else from deltajax. This module is the writer
(:class:`ResultsFile`, :func:`write_atomic`) and the package's face: every public name of its modules is
importable from ``deltajax.io``. :mod:`deltajax.io.reader` holds the one reader, :func:`read`; it keeps every
dataset's dimensions, units and attributes, and :func:`load` (plain Python/NumPy), :func:`open_xarray`
(xarray), :func:`differences`, the sweep merge and summaries (:mod:`deltajax.sweeps`) and the results-file
checkpoint (:mod:`deltajax.workspace.chunks`) are views of what it returns. :mod:`deltajax.io.integrity` holds
the checksums and the integrity record that both sides use.

Layout: root attributes (version, git commit, resolved config as YAML, experiment, seed, precision,
backend/device, start/end time); one group per kind of result (``robot``, ``workspace``, ``boundary``,
``dynamics``, ``ga``, ``pareto``, ``refine``, ``bench``, nested groups allowed with "a/b" names). Every dataset
has a ``units`` attribute and every dimension is an HDF5 dimension scale, so that
``xarray.open_dataset(path, group=..., engine="h5netcdf")`` opens each group.

Writes are atomic: the whole file is built in memory, written to a temporary name unique to the writer
(``.<name>.<pid>.<random>.tmp`` in the same directory) and renamed over the old one, so a reader (or a killed
run) never sees a half-written file and two writers never share a temporary. A full disk or another I/O error
raises :class:`ResultsWriteError` (one line: the path, the cause, that the previous file is intact, what to
do) and leaves no temporary behind. Every dataset carries a ``checksum`` attribute (``sha256:<hex>`` of its
data), and the file's HDF5 user block holds an integrity record (:data:`INTEGRITY_MAGIC`, then JSON): a checksum
of every attribute of every group (the root's bookkeeping: stages done, generations done, ...) and of each
group's members (datasets, subgroups and the datasets' attributes). ``read(..., verify=True)`` and
:func:`verify_file` check both, so a resume and a finished run's rerun refuse a damaged or edited file (a value, a
deleted ``checksum`` attribute, an edited attribute, a removed dataset, a file without a record). Host-side
only; never call inside jit.
"""

from __future__ import annotations

import datetime as _dt
import errno as _errno
import hashlib
import itertools
import os
import subprocess
import uuid
from pathlib import Path
from typing import Any, Mapping, Optional, Sequence

import h5py
import numpy as np

from .integrity import (INTEGRITY_MAGIC, ChecksumError, checksum, dataset_hash, integrity_record, read_checked,
                        record_size_bound, recorded_attrs, to_python, userblock_size)
from .reader import (RUN_ATTRS, Contents, ResultsGroupError, Variable, differences, groups, load, load_groups,
                     open_xarray, read, verify_file)

__all__ = ["ResultsFile", "ResultsWriteError", "ChecksumError", "ResultsGroupError", "load", "read", "Contents",
           "Variable", "groups", "load_groups", "read_checked", "checksum", "write_atomic", "git_commit",
           "RESERVED_NAMES", "verify_file", "INTEGRITY_MAGIC", "open_xarray", "to_python", "differences", "RUN_ATTRS"]

RESERVED_NAMES = ("attrs", "units")

# Self-describing, compact files: every dataset also gets a CF-style ``long_name`` (LONG_NAMES, or
# the writer's, or its name) and a ``z`` axis in m ``positive: "down"`` (the base frame's convention);
# datasets of COMPRESS_MIN_ELEMENTS or more elements are chunked (about CHUNK_BYTES per chunk, whole trailing
# axes first) and gzip-compressed with the shuffle filter, which every HDF5/netCDF reader decodes:
# reachability masks shrink ~50-100x, index fields several-fold. :func:`groups` lists a file's groups, and
# :func:`load`/:func:`open_xarray` name them when asked for a missing one.

#: datasets with at least this many elements are chunked and compressed (smaller ones are stored contiguous)
COMPRESS_MIN_ELEMENTS = 4096
#: target bytes per chunk (uncompressed)
CHUNK_BYTES = 1 << 20
#: gzip level (4: most of the ratio of level 9 at a fraction of its time)
GZIP_LEVEL = 4

#: ``long_name`` of datasets whose name is shared across experiments (others: given by the writer, or the
#: name with spaces).
LONG_NAMES = {
    "x": "x coordinate of the platform centre (base frame)",
    "y": "y coordinate of the platform centre (base frame)",
    "z": "z coordinate of the platform centre (base frame, positive down)",
    "t": "time",
    "R": "base radius R",
    "R_star": "base radius R* selected by the redundancy resolution",
    "k_star": "index of the selected R sample (-1: none feasible)",
    "inv_cond": "inverse condition number 1/k of the homogenised theta-block",
    "sigma_min_v": "smallest singular value (velocity), sigma_min,v",
    "sigma_min_f": "force transmission sigma_min,f = 1/s1",
    "omega_v": "velocity volume index omega_v = s1 s2 s3",
    "omega_f": "force volume index omega_f = 1/omega_v",
    "k_tilde": "combined index k~ (Franco-Lopez 2026)",
    "manipulability": "Yoshikawa manipulability",
    "imi": "inverse manipulability index 1/sqrt(det(J J^T))",
    "reachable": "reachable (IK solvable for all chains, theta within limits)",
    "reachable_fixed": "reachable by the fixed robot",
    "reachable_reconfigurable": "reachable by the reconfigurable robot at some R sample",
    "theta": "actuated joint angle theta (positive down)",
    "theta_dot": "actuated joint speed",
    "theta_ddot": "actuated joint acceleration",
    "tau": "actuator torque",
    "force_R": "force of the R actuator",
    "p": "platform centre position (base frame)",
    "p_dot": "platform centre velocity (base frame)",
    "p_ddot": "platform centre acceleration (base frame)",
    "peak_joint_speed": "peak actuated joint speed max |theta_dot|",
    "peak_joint_acceleration": "peak actuated joint acceleration max |theta_ddot|",
    "peak_speed": "peak end-effector speed the motors give (m/s; joint speeds are peak_joint_speed)",
    "R_operating": "operating base radius R on the pick-and-place cycle",
    "volume": "workspace volume",
    "count": "number of reachable grid points",
}


def _chunk_shape(shape: Sequence[int], itemsize: int, target: int = CHUNK_BYTES) -> tuple:
    """Chunk of about ``target`` bytes: whole trailing axes, the leading axes cut first (x-slabs of a grid)."""
    chunk = [max(1, int(n)) for n in shape]
    for i in range(len(chunk)):
        total = int(np.prod(chunk)) * itemsize
        if total <= target:
            break
        chunk[i] = max(1, -(-chunk[i] // -(-total // target)))  # ceil divisions in integers
    return tuple(chunk)


def git_commit(cwd: Optional[os.PathLike] = None) -> str:
    """The current git commit of the deltajax checkout (or of ``cwd``), '' when not in a repository."""
    here = Path(cwd) if cwd is not None else Path(__file__).resolve().parent
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return ""
    return out.stdout.strip() if out.returncode == 0 else ""


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


class _Var:
    __slots__ = ("data", "units", "dims", "attrs")

    def __init__(self, data, units, dims, attrs):
        self.data, self.units, self.dims, self.attrs = data, units, dims, attrs


class ResultsFile:
    """Stage results in memory and write them atomically to ``path`` on :meth:`flush`.

    Example::

        res = ResultsFile(run_dir / "results.h5", attrs={"experiment": "demo"})
        res.put_axis("workspace", "z", z, units="m")
        res.put("workspace", "volume", v, units="m^3")
        res.put("workspace", "reachable", mask, units="1", dims=("x", "y", "z"))
        res.flush()
    """

    def __init__(self, path: os.PathLike, attrs: Optional[Mapping[str, Any]] = None):
        self.path = Path(path)
        self.attrs: dict[str, Any] = {"start_time": _now()}
        self.attrs.update(attrs or {})
        self._groups: dict[str, dict[str, _Var]] = {}
        self._group_attrs: dict[str, dict[str, Any]] = {}

    # -- staging ---------------------------------------------------------------------------------------------
    def put(self, group: str, name: str, data: Any, *, units: str, dims: Optional[Sequence[str]] = None,
            attrs: Optional[Mapping[str, Any]] = None, long_name: Optional[str] = None) -> None:
        """Stage dataset ``group/name``.

        Args:
            group: group path, e.g. ``"workspace"`` or ``"workspace/fixed"``.
            name: dataset name (not ``attrs``/``units``).
            data: array-like (converted with ``np.asarray``; JAX arrays are copied to host).
            units: SI units string ("m", "rad", "N m", "1" for dimensionless).
            dims: names of the dimensions; each must be an axis staged with :meth:`put_axis` in the same group,
                or is created as an index axis of the right length. ``None``: ``<name>_dim<i>`` index axes.
            attrs: extra attributes.
            long_name: CF ``long_name`` (default: :data:`LONG_NAMES`, else the name with spaces).
        """
        if name in RESERVED_NAMES or "/" in name:
            raise ValueError(f"dataset name {name!r} is reserved or contains '/'")
        arr = np.asarray(data)
        if arr.dtype.kind == "U":
            arr = arr.astype(object)
        if dims is None:
            dims = tuple(f"{name}_dim{i}" for i in range(arr.ndim))
        dims = tuple(dims)
        if len(dims) != arr.ndim:
            raise ValueError(f"{group}/{name}: {len(dims)} dims for an array of rank {arr.ndim}")
        g = self._groups.setdefault(group, {})
        for d, n in zip(dims, arr.shape):
            if d in g and d != name:
                if g[d].data.shape != (n,):
                    raise ValueError(f"{group}/{name}: axis {d!r} has length {g[d].data.shape}, data has {n}")
            elif d != name:
                g[d] = _Var(np.arange(n), "1", (d,), {"index_axis": 1, "long_name": f"index along {d}"})
        a = dict(attrs or {})
        a.setdefault("long_name", long_name or LONG_NAMES.get(name) or name.replace("_", " "))
        if name == "z" and dims == ("z",) and units == "m":
            a.setdefault("positive", "down")  # the base frame's z points down (docs/CONVENTIONS.md)
        g[name] = _Var(arr, units, dims, a)

    def put_axis(self, group: str, name: str, values: Any, *, units: str,
                 attrs: Optional[Mapping[str, Any]] = None, long_name: Optional[str] = None) -> None:
        """Stage a 1-D coordinate axis (an HDF5 dimension scale) named ``name`` in ``group``."""
        arr = np.asarray(values)
        if arr.ndim != 1:
            raise ValueError(f"axis {group}/{name} must be 1-D, got shape {arr.shape}")
        self.put(group, name, arr, units=units, dims=(name,), attrs=attrs, long_name=long_name)

    def put_variables(self, group: str, variables: Mapping[str, "Variable"]) -> None:
        """Stage the :class:`Variable` s of a group as :func:`read` returns them (axes first), e.g. to carry
        what an existing file holds into a new one."""
        for name, v in variables.items():
            if v.is_axis:
                self.put_axis(group, name, v.data, units="" if v.units is None else v.units, attrs=v.attrs)
        for name, v in variables.items():
            if not v.is_axis:
                self.put(group, name, v.data, units="" if v.units is None else v.units, dims=v.dims, attrs=v.attrs)

    def staged(self, prefix: str = "") -> list:
        """(group, name, data, units) of every staged dataset whose group starts with ``prefix`` (axes too)."""
        return [(g, n, v.data, v.units) for g, variables in self._groups.items() if g.startswith(prefix)
                for n, v in variables.items()]

    def set_attrs(self, group: Optional[str] = None, **attrs: Any) -> None:
        """Set root attributes (``group=None``) or attributes of a group."""
        if group is None:
            self.attrs.update(attrs)
        else:
            self._group_attrs.setdefault(group, {}).update(attrs)

    def has(self, group: str, name: Optional[str] = None) -> bool:
        """Whether a group (or a dataset in it) has been staged."""
        return group in self._groups and (name is None or name in self._groups[group])

    # -- writing ---------------------------------------------------------------------------------------------
    def flush(self, *, final: bool = False) -> Path:
        """Write everything staged so far atomically; ``final=True`` also records the end time.

        Raises:
            ResultsWriteError: the file could not be written (disk full, I/O error); the previous file at
                ``path`` is untouched and no temporary file is left.
        """
        if final:
            self.attrs["end_time"] = _now()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(self.path, self._image())
        return self.path

    def _image(self) -> bytes:
        # The file is built in memory (HDF5 core driver) and written to disk with plain OS calls. Writing through
        # HDF5's own file driver, a full disk made File.close() fail half-way and the surviving dataset ids
        # segfaulted at garbage collection (exit 139); now HDF5 never sees an I/O error.
        block = userblock_size(self._record_size_bound())
        f = h5py.File(f"deltajax-image-{os.getpid()}-{next(_IMAGE_IDS)}", "w", driver="core",
                      backing_store=False, block_size=1 << 22, userblock_size=block)
        known: dict[str, dict[str, str]] = {}   # group -> dataset -> its checksum in the integrity record
        try:
            for k, v in self.attrs.items():
                f.attrs[k] = _attr_value(v)
            for gname, variables in self._groups.items():
                g = f.require_group(gname)
                for k, v in self._group_attrs.get(gname, {}).items():
                    g.attrs[k] = _attr_value(v)
                dsets = self._write_group(g, variables)
                mine = known.setdefault(g.name.strip("/"), {})
                for n, v in variables.items():
                    dsets[n].attrs["checksum"] = cs = checksum(v.data)
                    mine[n] = _dataset_hash(dsets[n], v, cs)
            for gname, gattrs in self._group_attrs.items():
                if gname not in self._groups:
                    g = f.require_group(gname)
                    for k, v in gattrs.items():
                        g.attrs[k] = _attr_value(v)
            f.flush()
            names = self._group_names()
            for n in names - {""}:   # every group is known as one to its parent
                parent, _, leaf = n.rpartition("/")
                known.setdefault(parent, {})[leaf] = "group"
            record = integrity_record(f, known, sorted(names))
            if len(record) > block:
                raise RuntimeError(f"{self.path}: integrity record of {len(record)} bytes exceeds the user block "
                                   f"({block} bytes)")  # a bug in _record_size_bound, never the user's input
            # the core driver's image starts at the superblock: the user block goes in front of it
            return record.ljust(block, b"\0") + f.id.get_file_image()
        finally:
            f.close()

    def _group_names(self) -> set:
        """Every group of the file ("" for the root, "a/b"): the staged groups and the groups above them."""
        names = {""}
        for g in list(self._groups) + list(self._group_attrs):
            parts = [p for p in g.strip("/").split("/") if p]
            names.update("/".join(parts[:i]) for i in range(1, len(parts) + 1))
        return names

    def _record_size_bound(self) -> int:
        """An upper bound on the size of the integrity record (:func:`~deltajax.io.integrity.integrity_record`) of
        this file."""
        names = self._group_names()
        keys = (list(self.attrs) + [k for a in self._group_attrs.values() for k in a]
                + [k for v in self._groups.values() for k in v] + [n.rpartition("/")[2] for n in names])
        return record_size_bound(names, keys)

    @staticmethod
    def _write_group(g: h5py.Group, variables: dict[str, _Var]) -> dict:
        """Write a group's staged datasets; returns them by name."""
        axes = {n for n, v in variables.items() if v.dims == (n,)}
        dsets = {}
        for n, v in variables.items():
            data = v.data
            if data.dtype == object:
                dset = g.create_dataset(n, data=data.astype(h5py.string_dtype()))
            elif data.size >= COMPRESS_MIN_ELEMENTS and data.ndim >= 1:
                dset = g.create_dataset(n, data=data, chunks=_chunk_shape(data.shape, data.dtype.itemsize),
                                        compression="gzip", compression_opts=GZIP_LEVEL, shuffle=True)
            else:
                dset = g.create_dataset(n, data=data)
            dset.attrs["units"] = v.units
            for k, a in v.attrs.items():
                if k == "index_axis":
                    continue
                dset.attrs[k] = _attr_value(a)
            dsets[n] = dset
        for n in axes:
            dsets[n].make_scale(n)
        for n, v in variables.items():
            if n in axes:
                continue
            for i, d in enumerate(v.dims):
                dsets[n].dims[i].attach_scale(dsets[d])
        return dsets


_IMAGE_IDS = itertools.count()

#: the integrity record's checksum of a dataset (:func:`~deltajax.io.integrity.dataset_hash`, of its attributes
#: as HDF5 reads them back) by what was written as its attributes: each flush rewrites every staged dataset, and
#: reading its attributes back through h5py to checksum them was most of a flush (~0.3 s of ~0.6 s per flush of
#: the toy main job's file); the same written attributes read back the same, so each is read back once
_DATASET_HASHES: dict = {}
_DATASET_HASHES_MAX = 1 << 14   # entries of ~0.2 kB (a run writes a few hundred datasets)


def _written_key(x: Any) -> tuple:
    """What an attribute value written to HDF5 is, exactly (its Python type, dtype, shape and content)."""
    a = np.asarray(x)
    if a.dtype.kind == "O":
        return (type(x).__qualname__, a.shape, tuple((type(i).__qualname__, repr(i)) for i in a.reshape(-1)))
    return (type(x).__module__, type(x).__qualname__, a.dtype.str, a.shape, checksum(a))


def _dataset_hash(dset: h5py.Dataset, v: _Var, cs: str) -> str:
    """:func:`~deltajax.io.integrity.dataset_hash` of a dataset just written from ``v`` (checksum ``cs``): read
    back from ``dset`` the first time these attributes are written, remembered after that."""
    written = (cs, _written_key(v.units),
               tuple((k, _written_key(_attr_value(a))) for k, a in v.attrs.items() if k != "index_axis"))
    key = hashlib.sha256(repr(written).encode()).digest()
    h = _DATASET_HASHES.get(key)
    if h is None:
        h = dataset_hash(recorded_attrs(dset))
        if len(_DATASET_HASHES) >= _DATASET_HASHES_MAX:
            _DATASET_HASHES.pop(next(iter(_DATASET_HASHES)))
        _DATASET_HASHES[key] = h
    return h


class ResultsWriteError(OSError):
    """A results file could not be written (disk full, I/O error); the previous file at the path is intact."""

    def __str__(self) -> str:  # one line, without OSError's "[Errno N]" prefix
        return str(self.strerror)



def _write_all(fd: int, data: bytes) -> None:
    view, n = memoryview(data), 0
    while n < len(view):
        n += os.write(fd, view[n:])


def write_atomic(path: os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary name unique to this writer, fsync, then rename.

    Raises:
        ResultsWriteError: one line naming the path, the cause and what to do; no temporary is left.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        try:
            _write_all(fd, data)
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except OSError as e:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        cause = "no space left on device" if e.errno == _errno.ENOSPC else (e.strerror or str(e))
        kept = f"the previous {path.name} there is intact" if path.exists() else "nothing was written"
        raise ResultsWriteError(e.errno, f"cannot write {path} ({len(data) / 1e6:.1f} MB): {cause}; {kept}. "
                                         f"Free space (or fix the cause) and rerun the same command to resume"
                                ) from None


def _attr_value(v: Any) -> Any:
    if v is None:
        return ""
    if isinstance(v, (str, bytes, int, float, bool, np.generic, np.ndarray)):
        return v
    if isinstance(v, (list, tuple)):
        try:
            return np.asarray(v)
        except Exception:  # noqa: BLE001 - ragged lists are stored as their repr
            return repr(v)
    return str(v)


