"""Checksums and the integrity record of a results file (docs/results.md): what :func:`deltajax.io.read` checks with
``verify=True``.

Every dataset carries a ``checksum`` attribute (:func:`checksum`, ``sha256:<hex>`` of its dtype, shape and data),
checked by :func:`verify_dataset` (and :func:`read_checked`). The file's HDF5 user block holds the integrity record
(:data:`INTEGRITY_MAGIC`, then JSON, :func:`integrity_record`): per group a checksum of every attribute and of each
member (datasets, subgroups and the datasets' attributes). The writer (:class:`deltajax.io.ResultsFile`) sizes the
user block with :func:`record_size_bound` and :func:`userblock_size` and stores the record there; the reader
(:mod:`deltajax.io.reader`) loads it with :func:`stored_record` and checks each group read with
:func:`verify_group`. Any mismatch, a missing checksum or a missing record raises :class:`ChecksumError`.
Host-side only; imports nothing else of deltajax.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any, Iterable, Mapping, Optional

import h5py
import numpy as np

__all__ = ["ChecksumError", "checksum", "read_checked", "verify_dataset", "INTEGRITY_MAGIC", "userblock_size",
           "record_size_bound", "integrity_record", "dataset_hash", "recorded_attrs", "stored_record", "verify_group",
           "to_python"]


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
    verify_dataset(dset, data)
    return data


def verify_dataset(dset: "h5py.Dataset", data: Any, attrs: Optional[Mapping[str, Any]] = None) -> None:
    """Check ``data`` (as read from ``dset``; ``None`` when not read) against the dataset's ``checksum`` attribute
    (``attrs``: the dataset's attributes, when the caller has read them already).

    Raises:
        ChecksumError: the attribute is missing or does not match (the message names file and dataset).
    """
    want = (dset.attrs if attrs is None else attrs).get("checksum")
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


def userblock_size(n: int) -> int:
    """The HDF5 user block size (a power of two, at least 512) that holds ``n`` bytes."""
    size = 512
    while size < n:
        size *= 2
    return size


def record_size_bound(names: Iterable[str], keys: Iterable[Any]) -> int:
    """An upper bound on the size of the integrity record (:func:`integrity_record`) of a file whose groups are
    ``names`` (full paths, ``""`` for the root) and whose attributes and members are named by ``keys``."""
    return (len(INTEGRITY_MAGIC) + 64 + sum(len(json.dumps(n)) + 64 for n in names)
            + sum(len(json.dumps(str(k))) + 2 * _HASH_CHARS for k in keys))


def _attr_hash(value: Any) -> str:
    return checksum(np.asarray(to_python(value)))[7:7 + _HASH_CHARS]


def dataset_hash(attrs: Mapping[str, Any]) -> str:
    """The record's checksum of a dataset from its attributes as read from the file (``{name: dset.attrs[name]}``,
    every name; the dimension-scale wiring is left out): units, checksum and the others."""
    h = hashlib.sha256()
    for k in sorted(attrs):
        if k not in _LAYOUT_ATTRS:
            h.update(f"{k}={_attr_hash(attrs[k])}\0".encode())
    return h.hexdigest()[:_HASH_CHARS]


def _member_hash(item) -> str:
    """Checksum of a group's member: "group" for a subgroup; a dataset's attributes (units, checksum, ...; not
    the dimension-scale wiring) for a dataset (:func:`dataset_hash`)."""
    if isinstance(item, h5py.Group):
        return "group"
    return dataset_hash(recorded_attrs(item))


def recorded_attrs(dset: "h5py.Dataset", keep: tuple = ()) -> dict:
    """A dataset's attributes as read from the file, but the dimension-scale wiring (slow to read, and left out
    of the record) other than the names in ``keep``."""
    return {k: dset.attrs[k] for k in dset.attrs if k not in _LAYOUT_ATTRS or k in keep}


def _group_record(g: "h5py.Group", known: Optional[Mapping[str, str]] = None) -> dict:
    """A group's entry of the record; ``known``: member name -> :func:`dataset_hash` of datasets whose attributes
    the caller has already read from this file (the others are read here)."""
    known = known or {}
    return {"attrs": {k: _attr_hash(g.attrs[k]) for k in sorted(g.attrs)},
            "members": {k: known[k] if k in known else _member_hash(g[k]) for k in sorted(g)}}


def integrity_record(f: "h5py.File", known: Optional[Mapping[str, Mapping[str, str]]] = None,
                     names: Optional[Iterable[str]] = None) -> bytes:
    """The integrity record of an open file: per group ("" for the root) its attributes' and members' checksums.
    ``known``: group name -> {member name: its checksum ("group" for a subgroup, :func:`dataset_hash` for a
    dataset)} already known from what was written; ``names``: every group of the file, when the writer knows them
    (else the file is walked)."""
    known = known or {}
    if names is not None:
        groups = {n: _group_record(f[n] if n else f, known.get(n)) for n in names}
    else:
        groups = {"": _group_record(f, known.get(""))}
        f.visititems(lambda name, item: groups.__setitem__(name, _group_record(item, known.get(name)))
                     if isinstance(item, h5py.Group) else None)
    return INTEGRITY_MAGIC + json.dumps({"groups": groups}, sort_keys=True, separators=(",", ":")).encode() + b"\n"


def stored_record(f: "h5py.File") -> dict:
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


def verify_group(f: "h5py.File", record: dict, name: str, g: "h5py.Group",
                 known: Optional[Mapping[str, str]] = None) -> None:
    """Check a group's attributes and members against the file's integrity record (:class:`ChecksumError`).
    ``known``: dataset name -> :func:`dataset_hash` of members whose attributes the caller has read already."""
    where = f"{f.filename}:/{name}" if name else f"{f.filename}:/ (root)"
    want = record.get(name)
    if not isinstance(want, dict):
        raise ChecksumError(f"{where} is not in the file's integrity record (a group added after it was written)")
    have = _group_record(g, known)
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


def to_python(v: Any) -> Any:
    """An HDF5 attribute or scalar as plain Python (bytes -> str, NumPy scalars -> int/float/bool)."""
    if isinstance(v, bytes):
        return v.decode()
    if isinstance(v, np.generic):
        return v.item()
    return v
