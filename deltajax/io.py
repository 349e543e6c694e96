"""HDF5 results (SPEC §5): one self-describing file per run, written atomically, and the one reader.

The bottom of the import graph: this module imports nothing else from deltajax. :func:`read` is the reader of
results files; it keeps every dataset's dimensions, units and attributes, and :func:`load` (plain
Python/NumPy), :func:`open_xarray` (xarray), the sweep merge and summaries (:mod:`deltajax.sweeps`) and the
results-file checkpoint (:mod:`deltajax.workspace.chunks`) are views of what it returns.

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

import dataclasses
import datetime as _dt
import errno as _errno
import hashlib
import itertools
import json
import os
import subprocess
import uuid
from pathlib import Path
from typing import Any, Mapping, Optional, Sequence

import h5py
import numpy as np

__all__ = ["ResultsFile", "ResultsWriteError", "ChecksumError", "ResultsGroupError", "load", "read", "Contents",
           "Variable", "groups",
           "read_checked", "checksum", "write_atomic", "git_commit", "RESERVED_NAMES", "verify_file",
           "INTEGRITY_MAGIC"]

RESERVED_NAMES = ("attrs", "units")

# Self-describing, compact files (issue 13): every dataset also gets a CF-style ``long_name`` (LONG_NAMES, or
# the writer's, or its name) and a ``z`` axis in m ``positive: "down"`` (the base frame's convention);
# datasets of COMPRESS_MIN_ELEMENTS or more elements are chunked (about CHUNK_BYTES per chunk, whole trailing
# axes first) and gzip-compressed with the shuffle filter, which every HDF5/netCDF reader decodes:
# reachability masks shrink ~50-100x, index fields several-fold. :func:`groups` lists a file's groups, and
# :func:`load`/:func:`open_xarray` name them when asked for a missing one.
__all__ += ["groups", "ResultsGroupError"]

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


class ResultsGroupError(KeyError):
    """A group that the results file does not have; the message lists the groups it has."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


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
        block = _userblock_size(self._record_size_bound())
        f = h5py.File(f"deltajax-image-{os.getpid()}-{next(_IMAGE_IDS)}", "w", driver="core",
                      backing_store=False, block_size=1 << 22, userblock_size=block)
        try:
            for k, v in self.attrs.items():
                f.attrs[k] = _attr_value(v)
            for gname, variables in self._groups.items():
                g = f.require_group(gname)
                for k, v in self._group_attrs.get(gname, {}).items():
                    g.attrs[k] = _attr_value(v)
                self._write_group(g, variables)
                for n, v in variables.items():
                    g[n].attrs["checksum"] = checksum(v.data)
            for gname, gattrs in self._group_attrs.items():
                if gname not in self._groups:
                    g = f.require_group(gname)
                    for k, v in gattrs.items():
                        g.attrs[k] = _attr_value(v)
            f.flush()
            record = _integrity_record(f)
            if len(record) > block:
                raise RuntimeError(f"{self.path}: integrity record of {len(record)} bytes exceeds the user block "
                                   f"({block} bytes)")  # a bug in _record_size_bound, never the user's input
            # the core driver's image starts at the superblock: the user block goes in front of it
            return record.ljust(block, b"\0") + f.id.get_file_image()
        finally:
            f.close()

    def _record_size_bound(self) -> int:
        """An upper bound on the size of the integrity record (:func:`_integrity_record`) of this file."""
        names = {""}
        for g in list(self._groups) + list(self._group_attrs):
            parts = g.strip("/").split("/")
            names.update("/".join(parts[:i]) for i in range(1, len(parts) + 1))
        keys = (list(self.attrs) + [k for a in self._group_attrs.values() for k in a]
                + [k for v in self._groups.values() for k in v] + [n.rpartition("/")[2] for n in names])
        return (len(INTEGRITY_MAGIC) + 64 + sum(len(json.dumps(n)) + 64 for n in names)
                + sum(len(json.dumps(str(k))) + 2 * _HASH_CHARS for k in keys))

    @staticmethod
    def _write_group(g: h5py.Group, variables: dict[str, _Var]) -> None:
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


_IMAGE_IDS = itertools.count()


class ResultsWriteError(OSError):
    """A results file could not be written (disk full, I/O error); the previous file at the path is intact."""

    def __str__(self) -> str:  # one line, without OSError's "[Errno N]" prefix
        return str(self.strerror)


class ChecksumError(ValueError):
    """A stored dataset does not match its checksum (damaged or edited file)."""


def checksum(data: Any) -> str:
    """``"sha256:<hex>"`` of an array's dtype, shape and bytes (strings: their UTF-8 text)."""
    arr = np.asarray(data)
    h = hashlib.sha256()
    if arr.dtype.kind in "OUS":
        h.update(f"str{arr.shape}".encode())
        for item in arr.reshape(-1):
            h.update((item.decode() if isinstance(item, bytes) else str(item)).encode() + b"\0")
    else:
        arr = np.ascontiguousarray(arr)
        h.update(f"{arr.dtype.str}{arr.shape}".encode())
        h.update(memoryview(arr.reshape(-1)).cast("B"))
    return "sha256:" + h.hexdigest()


def read_checked(dset: "h5py.Dataset") -> np.ndarray:
    """Read a whole dataset and verify it against its ``checksum`` attribute.

    Raises:
        ChecksumError: the attribute is missing or does not match (the message names file and dataset).
    """
    data = dset[()]
    _verify(dset, data)
    return data


def _verify(dset: "h5py.Dataset", data: Any) -> None:
    want = dset.attrs.get("checksum")
    want = want.decode() if isinstance(want, bytes) else want
    where = f"{dset.file.filename}:{dset.name}"
    if not want:
        raise ChecksumError(f"{where} has no checksum (not written by this deltajax version, or edited)")
    if checksum(data) != want:
        raise ChecksumError(f"{where} does not match its checksum (the file is damaged or was edited)")


#: first bytes of the integrity record in a results file's HDF5 user block (followed by JSON, then NUL padding)
INTEGRITY_MAGIC = b"deltajax-integrity-record 1\n"
_HASH_CHARS = 16  # hex characters kept of each sha256 in the record (it detects damage and edits, not attacks)
#: attributes HDF5 uses to wire dimension scales: references whose bytes change with the layout, left out of the
#: record (the scales themselves are members and are recorded)
_LAYOUT_ATTRS = ("CLASS", "NAME", "REFERENCE_LIST", "DIMENSION_LIST", "DIMENSION_LABELS")


def _userblock_size(n: int) -> int:
    """The HDF5 user block size (a power of two, at least 512) that holds ``n`` bytes."""
    size = 512
    while size < n:
        size *= 2
    return size


def _attr_hash(value: Any) -> str:
    return checksum(np.asarray(to_python(value)))[7:7 + _HASH_CHARS]


def _member_hash(item) -> str:
    """Checksum of a group's member: "group" for a subgroup; a dataset's attributes (units, checksum, ...; not
    the dimension-scale wiring) for a dataset."""
    if isinstance(item, h5py.Group):
        return "group"
    h = hashlib.sha256()
    for k in sorted(item.attrs):
        if k not in _LAYOUT_ATTRS:
            h.update(f"{k}={_attr_hash(item.attrs[k])}\0".encode())
    return h.hexdigest()[:_HASH_CHARS]


def _group_record(g: "h5py.Group") -> dict:
    return {"attrs": {k: _attr_hash(g.attrs[k]) for k in sorted(g.attrs)},
            "members": {k: _member_hash(g[k]) for k in sorted(g)}}


def _integrity_record(f: "h5py.File") -> bytes:
    """The integrity record of an open file: per group ("" for the root) its attributes' and members' checksums."""
    groups = {"": _group_record(f)}
    f.visititems(lambda name, item: groups.__setitem__(name, _group_record(item))
                 if isinstance(item, h5py.Group) else None)
    return INTEGRITY_MAGIC + json.dumps({"groups": groups}, sort_keys=True, separators=(",", ":")).encode() + b"\n"


def _stored_record(f: "h5py.File") -> dict:
    """The integrity record in the user block of an open file. Raises :class:`ChecksumError` when it has none."""
    block = f.userblock_size
    raw = b""
    if block:
        with open(f.filename, "rb") as fh:
            raw = fh.read(block)
    if not raw.startswith(INTEGRITY_MAGIC):
        raise ChecksumError(f"{f.filename} has no integrity record (written by an older deltajax, or rewritten by "
                            "another tool)")
    try:
        return json.loads(raw[len(INTEGRITY_MAGIC):].rstrip(b"\0"))["groups"]
    except (ValueError, KeyError, TypeError):
        raise ChecksumError(f"{f.filename}: its integrity record is damaged") from None


def _verify_group(f: "h5py.File", record: dict, name: str, g: "h5py.Group") -> None:
    """Check a group's attributes and members against the file's integrity record (:class:`ChecksumError`)."""
    where = f"{f.filename}:/{name}" if name else f"{f.filename}:/ (root)"
    want = record.get(name)
    if not isinstance(want, dict):
        raise ChecksumError(f"{where} is not in the file's integrity record (a group added after it was written)")
    have = _group_record(g)
    for kind, what in (("attrs", "attribute"), ("members", "member")):
        a, b = have[kind], want.get(kind, {})
        for k in sorted(set(a) | set(b)):
            item = f"{what} {k!r}" if kind == "attrs" else f"{'group' if a.get(k) == 'group' else 'dataset'} {k!r}"
            if k not in a:
                raise ChecksumError(f"{where}: its {item} was removed after the file was written (it was edited)")
            if k not in b:
                raise ChecksumError(f"{where}: its {item} was added after the file was written (it was edited)")
            if a[k] != b[k]:
                detail = "does not match its checksum" if kind == "attrs" else "has attributes that do not match " \
                                                                               "their checksum"
                raise ChecksumError(f"{where}: its {item} {detail} (the file is damaged or was edited)")


def verify_file(path: os.PathLike) -> None:
    """Verify a whole results file: every dataset against its checksum, every attribute and group against the
    integrity record (the reads a resume or a rerun of a finished run trusts).

    Raises:
        FileNotFoundError: no file at ``path``.
        OSError: HDF5 cannot open it (truncated, not HDF5).
        ChecksumError: damaged or edited (the message names the file, the item and what is wrong).
    """
    read(path, verify=True)


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


# -- the one reader ---------------------------------------------------------------------------------------------
#: attributes HDF5 and netCDF use to wire dimension scales (not data attributes; ``units`` is kept apart)
_WIRING_ATTRS = ("CLASS", "NAME", "REFERENCE_LIST", "DIMENSION_LIST", "DIMENSION_LABELS", "_Netcdf4Dimid",
                 "_Netcdf4Coordinates", "units")


@dataclasses.dataclass(frozen=True, eq=False)
class Variable:
    """One dataset as stored: its data, ``units`` (None when it has none), dimension names (its dimension
    scales; ``<name>_dim<i>`` for an axis without one), other attributes, and whether it is an axis."""

    data: Any
    units: Optional[str]
    dims: tuple
    attrs: dict
    is_axis: bool


@dataclasses.dataclass(frozen=True, eq=False)
class Contents:
    """What :func:`read` returns: root attributes, and per group (full path, ``""`` for the root) its attributes
    and its datasets. ``top`` is the group that was asked for (``""``: the whole file)."""

    attrs: dict
    group_attrs: dict
    variables: dict
    top: str = ""


def read(path: os.PathLike, group: Optional[str] = None, *, max_elements: Optional[int] = None,
         verify: bool = False) -> Contents:
    """Read a results file, or the groups at and below ``group``, keeping dimensions, units and attributes.

    The one HDF5 reader of deltajax: :func:`load` (plain dicts), :func:`open_xarray` (an xarray Dataset), the
    shard merge and the sweep summaries (:mod:`deltajax.sweeps`) are views of what it returns.

    Args:
        path: the results file.
        group: a group name ("a/b"); ``None``: the whole file.
        max_elements: read only datasets of at most this many elements (a scalar has 1; 0 reads attributes
            only); the others are left out of ``variables``. ``None``: every dataset.
        verify: check every dataset read against its checksum, and the attributes and members of every group
            read (and the root's attributes) against the file's integrity record.

    Raises:
        FileNotFoundError: no file at ``path``.
        ResultsGroupError: ``group`` is not in the file; the message lists the groups it has.
        ChecksumError: with ``verify``, a dataset does not match its checksum (or has none), or an attribute or
            the members of a group read (and the root's attributes) differ from the file's integrity record (or
            the file has none).
    """
    with _open(path) as f:
        top = "" if group is None else group.strip("/")
        g = f.get(top or "/")
        if not isinstance(g, h5py.Group):
            raise _no_group(path, str(group))
        record = _stored_record(f) if verify else {}
        root = {k: to_python(v) for k, v in f.attrs.items()}
        group_attrs: dict[str, dict] = {}
        variables: dict[str, dict[str, Variable]] = {}

        def walk(name: str, grp: h5py.Group) -> None:
            group_attrs[name] = {k: to_python(v) for k, v in grp.attrs.items()}
            own = variables.setdefault(name, {})
            for key, item in grp.items():
                if isinstance(item, h5py.Group):
                    walk(f"{name}/{key}" if name else key, item)
                elif max_elements is None or item.size <= max_elements:
                    own[key] = _variable(key, item, verify)
                elif verify and "checksum" not in item.attrs:
                    _verify(item, None)  # not read, but a dataset without its checksum is refused all the same
            if verify:  # after the datasets: a removed checksum attribute is named as such
                _verify_group(f, record, name, grp)

        walk(top, g)
        if verify and top:
            _verify_group(f, record, "", f)  # the root's attributes (returned too) and its members
    return Contents(attrs=root, group_attrs=group_attrs, variables=variables, top=top)


def _variable(name: str, dset: "h5py.Dataset", verify: bool = False) -> Variable:
    if dset.dtype.kind == "O" or h5py.check_string_dtype(dset.dtype) is not None:
        data = dset.asstr()[()]
    else:
        data = dset[()]
    if verify:
        _verify(dset, data)
    is_axis = to_python(dset.attrs.get("CLASS", "")) == "DIMENSION_SCALE"
    if is_axis:
        dims: tuple = (name,)
    else:
        dims = tuple((to_python(next(iter(d.keys()))) if len(d) else f"{name}_dim{i}")
                     for i, d in enumerate(dset.dims))
    units = to_python(dset.attrs["units"]) if "units" in dset.attrs else None
    attrs = {k: to_python(v) for k, v in dset.attrs.items() if k not in _WIRING_ATTRS}
    return Variable(data=data, units=units, dims=dims, attrs=attrs, is_axis=is_axis)


def to_python(v: Any) -> Any:
    """An HDF5 attribute or scalar as plain Python (bytes -> str, NumPy scalars -> int/float/bool)."""
    if isinstance(v, bytes):
        return v.decode()
    if isinstance(v, np.generic):
        return v.item()
    return v


def groups(path: os.PathLike) -> list[str]:
    """Names ("a/b") of the groups of a results file that hold datasets, in file order."""
    out: list[str] = []

    def visit(name, item):
        if isinstance(item, h5py.Group) and any(isinstance(v, h5py.Dataset) for v in item.values()):
            out.append(name)

    with _open(path) as f:
        if any(isinstance(v, h5py.Dataset) for v in f.values()):
            out.append("/")
        f.visititems(visit)
    return out


def _open(path: os.PathLike) -> h5py.File:
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"no results file at {p} (a run writes <run dir>/results.h5)")
    return h5py.File(p, "r")


def _no_group(path: os.PathLike, group: str) -> ResultsGroupError:
    have = groups(path)
    return ResultsGroupError(f"{path} has no group {group!r}; its groups with data: {', '.join(have) or 'none'}")


def load(path: os.PathLike, group: Optional[str] = None, *, verify: bool = True) -> dict[str, Any]:
    """Load a results file (or one group of it) as plain Python/NumPy: a view of :func:`read`.

    Args:
        path: the results file.
        group: a group name ("a/b"); ``None`` loads the whole file.
        verify: check what is read against its checksums and the file's integrity record (:func:`read`);
            ``False`` reads a damaged, edited or older file as it is (to inspect it).

    Returns:
        A dict with ``"attrs"`` (root attributes; ``attrs["config"]`` is the resolved YAML), ``"units"`` and
        one dict per group, each holding its datasets as NumPy arrays, its own ``"attrs"`` and ``"units"``
        (dataset name -> units string), and nested groups as dicts. With ``group``: that group's dict.

    Raises:
        FileNotFoundError: no file at ``path``.
        ResultsGroupError: ``group`` is not in the file; the message lists the groups it has.
        ChecksumError: with ``verify``, the file is damaged or was edited, or has no integrity record.
    """
    contents = read(path, group, verify=verify)
    top = contents.top
    nested: dict[str, dict[str, Any]] = {}
    for name in sorted(contents.group_attrs, key=lambda n: (n.count("/") if n else -1, n)):
        node: dict[str, Any] = {"attrs": dict(contents.group_attrs[name]), "units": {}}
        for vname, v in contents.variables.get(name, {}).items():
            node[vname] = v.data
            if v.units is not None:
                node["units"][vname] = v.units
        nested[name] = node
        if name != top:
            parent = name.rpartition("/")[0] if "/" in name else ""
            nested[parent][name.rpartition("/")[2]] = node
    return nested[top]


def open_xarray(path: os.PathLike, group: str, *, verify: bool = True):
    """Open one group of a results file as an in-memory :class:`xarray.Dataset` (SPEC §5): a view of :func:`read`.

    Gridded datasets come with their named dimensions and coordinate axes (the HDF5 dimension scales), each
    variable with its ``units``, ``long_name`` and other attributes; scalars are 0-d variables; the group's
    attributes are the dataset's. The same file also opens with ``xarray.open_dataset(path, group=...,
    engine="h5netcdf")``.

    Example::

        ws = open_xarray(run_dir / "results.h5", "workspace")
        area_vs_z = ws.reachable.sum(("x", "y")) * float(ws.attrs["h"]) ** 2      # m^2 per z level

    ``verify`` (default): the group is checked against its checksums and the file's integrity record, as by
    :func:`load`; ``False`` reads a damaged, edited or older file as it is.

    Raises:
        FileNotFoundError: no file at ``path``.
        ResultsGroupError: ``group`` is not in the file; the message lists the groups it has.
        ChecksumError: with ``verify``, the file is damaged or was edited, or has no integrity record.
    """
    import xarray as xr

    contents = read(path, group, verify=verify)
    variables = contents.variables.get(contents.top, {})

    def attrs(v: Variable) -> dict[str, Any]:
        return {"units": v.units, **v.attrs} if v.units is not None else dict(v.attrs)

    coords = {n: xr.Variable(v.dims, v.data, attrs(v)) for n, v in variables.items() if v.is_axis}
    data = {n: xr.Variable(v.dims, v.data, attrs(v)) for n, v in variables.items() if not v.is_axis}
    return xr.Dataset(data, coords=coords, attrs=dict(contents.group_attrs[contents.top]))


__all__ += ["open_xarray", "to_python"]


#: attributes that differ between two runs of the same computation: when, where and by which commit it ran, and
#: how long it took (everything else in a results file is a function of the code, the config and the seed)
RUN_ATTRS = ("start_time", "end_time", "git_commit", "wall_time_s", "host", "hostname", "checksum")


def differences(path_a: os.PathLike, path_b: os.PathLike, *, ignore: Sequence[str] = (),
                rtol: float = 0.0, exact: Sequence[str] = (), group: Optional[str] = None,
                verify: bool = True) -> list[str]:
    """What differs between two results files: every group, dataset and attribute present in one only, every
    dataset whose dtype, shape or values differ (NaN equals NaN; ``rtol`` > 0 compares floats to that relative
    tolerance, 0: bit for bit), and every attribute whose value differs. One line per difference, ``[]`` when
    the files hold the same results.

    Attributes named in :data:`RUN_ATTRS` (time, commit, wall time, the checksums that follow the values) and the
    datasets, groups or attributes matching a pattern of ``ignore`` (``fnmatch`` on ``group/name`` and on
    ``group@attribute``; e.g. ``"*/timing*"``, ``"*@*_s"``) are not compared. Datasets matching a pattern of
    ``exact`` are compared bit for bit whatever ``rtol`` (a selection, a mask). ``group``: only that group and
    its subgroups (the file's root attributes left out). Both files are read verified (``verify=False``: as they
    are, e.g. to compare a file edited outside deltajax).
    """
    import fnmatch

    a, b = read(path_a, verify=verify), read(path_b, verify=verify)

    def skip(name: str) -> bool:
        return any(fnmatch.fnmatchcase(name, pat) for pat in ignore)

    def same(x, y, name: str = "") -> bool:
        x, y = np.asarray(x), np.asarray(y)
        if x.dtype != y.dtype or x.shape != y.shape:
            return False
        if x.dtype.kind in "fc":
            if rtol > 0 and not any(fnmatch.fnmatchcase(name, pat) for pat in exact):
                return bool(np.allclose(x, y, rtol=rtol, atol=0.0, equal_nan=True))
            return bool(np.array_equal(x, y, equal_nan=True))
        return bool(np.array_equal(x, y))

    def attrs_diff(where: str, ax: Mapping, bx: Mapping) -> list[str]:
        out = []
        for k in sorted(set(ax) | set(bx)):
            if k in RUN_ATTRS or skip(f"{where}@{k}"):
                continue
            if k not in bx or k not in ax:
                out.append(f"{where}@{k}: only in {'a' if k in ax else 'b'}")
            elif not same(ax[k], bx[k]):
                out.append(f"{where}@{k}: {ax[k]!r} != {bx[k]!r}"[:300])
        return out

    out = attrs_diff("/", a.attrs, b.attrs) if group is None else []
    for g in sorted(set(a.group_attrs) | set(b.group_attrs)):
        if (g and skip(g)) or (group is not None and g != group and not g.startswith(group + "/")):
            continue
        if g not in a.group_attrs or g not in b.group_attrs:
            out.append(f"{g}/: group only in {'a' if g in a.group_attrs else 'b'}")
            continue
        if g:
            out += attrs_diff(g, a.group_attrs[g], b.group_attrs[g])
        va, vb = a.variables.get(g, {}), b.variables.get(g, {})
        for n in sorted(set(va) | set(vb)):
            name = f"{g}/{n}" if g else n
            if skip(name):
                continue
            if n not in va or n not in vb:
                out.append(f"{name}: dataset only in {'a' if n in va else 'b'}")
                continue
            x, y = np.asarray(va[n].data), np.asarray(vb[n].data)
            if x.dtype != y.dtype or x.shape != y.shape:
                out.append(f"{name}: {x.dtype}{list(x.shape)} != {y.dtype}{list(y.shape)}")
            elif not same(x, y, name):
                if x.dtype.kind in "fc":
                    d = np.abs(x.astype(complex) - y.astype(complex))
                    d = np.where(np.isnan(x) & np.isnan(y), 0.0, d)
                    out.append(f"{name}: values differ at {int(np.count_nonzero(d))} of {x.size} elements "
                               f"(largest difference {np.nanmax(d):.3g})")
                else:
                    out.append(f"{name}: values differ at {int(np.count_nonzero(x != y))} of {x.size} elements")
            out += attrs_diff(name, va[n].attrs, vb[n].attrs)
    return out


__all__ += ["differences", "RUN_ATTRS"]
