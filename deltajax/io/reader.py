"""The one reader of results files (docs/results.md): :func:`read` and its views.

:func:`read` returns a file (or the groups at and below one group) as :class:`Contents`, keeping every
dataset's dimensions, units and attributes as a :class:`Variable`; with ``verify=True`` it checks what it reads
against the checksums and the integrity record (:mod:`deltajax.io.integrity`), and :func:`verify_file` reads a
whole file so. :func:`load` (plain Python/NumPy), :func:`open_xarray` (xarray) and :func:`differences` (two files
compared, :data:`RUN_ATTRS` left out) are views of what it returns; :func:`groups` lists a file's groups, and a
missing one raises :class:`ResultsGroupError` naming them. Host-side only; imports nothing of deltajax outside
:mod:`deltajax.io`.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any, Mapping, Optional, Sequence
import fnmatch

import h5py
import numpy as np

from .integrity import dataset_hash, recorded_attrs, stored_record, to_python, verify_dataset, verify_group

__all__ = ["Variable", "Contents", "ResultsGroupError", "read", "load", "load_groups", "groups", "open_xarray",
           "differences", "RUN_ATTRS", "verify_file"]


class ResultsGroupError(KeyError):
    """A group that the results file does not have; the message lists the groups it has."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


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
        record = stored_record(f) if verify else {}
        root = {k: to_python(v) for k, v in f.attrs.items()}
        group_attrs: dict[str, dict] = {}
        variables: dict[str, dict[str, Variable]] = {}

        def walk(name: str, grp: h5py.Group) -> None:
            group_attrs[name] = {k: to_python(v) for k, v in grp.attrs.items()}
            own = variables.setdefault(name, {})
            known = {}   # the record's checksums of the datasets read (their attributes are read once)
            for key, item in grp.items():
                if isinstance(item, h5py.Group):
                    walk(f"{name}/{key}" if name else key, item)
                elif max_elements is None or item.size <= max_elements:
                    raw = recorded_attrs(item, keep=("CLASS",))
                    own[key] = _variable(key, item, raw, verify)
                    if verify:
                        known[key] = dataset_hash(raw)
                elif verify and "checksum" not in item.attrs:
                    verify_dataset(item, None)  # not read, but a dataset without its checksum is refused all the same
            if verify:  # after the datasets: a removed checksum attribute is named as such
                verify_group(f, record, name, grp, known)

        walk(top, g)
        if verify and top:
            verify_group(f, record, "", f)  # the root's attributes (returned too) and its members
    return Contents(attrs=root, group_attrs=group_attrs, variables=variables, top=top)


def _variable(name: str, dset: "h5py.Dataset", raw: dict, verify: bool = False) -> Variable:
    """A dataset as a :class:`Variable`; ``raw``: its attributes as read (:func:`recorded_attrs` and ``CLASS``)."""
    if dset.dtype.kind == "O" or h5py.check_string_dtype(dset.dtype) is not None:
        data = dset.asstr()[()]
    else:
        data = dset[()]
    if verify:
        verify_dataset(dset, data, raw)
    is_axis = to_python(raw.get("CLASS", "")) == "DIMENSION_SCALE"
    if is_axis:
        dims: tuple = (name,)
    else:
        dims = tuple((to_python(next(iter(d.keys()))) if len(d) else f"{name}_dim{i}")
                     for i, d in enumerate(dset.dims))
    units = to_python(raw["units"]) if "units" in raw else None
    attrs = {k: to_python(v) for k, v in raw.items() if k not in _WIRING_ATTRS}
    return Variable(data=data, units=units, dims=dims, attrs=attrs, is_axis=is_axis)


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


def load_groups(path: os.PathLike, names: Sequence[str], *, verify: bool = True) -> dict[str, dict[str, Any]]:
    """The groups ``names`` of a results file that it holds, each as :func:`load` returns it (a missing group is
    left out): what a job's later stage reads back of its own file, without reading (and checking) the rest."""
    out = {}
    for name in names:
        try:
            out[name] = load(path, name, verify=verify)
        except ResultsGroupError:
            continue
    return out


def open_xarray(path: os.PathLike, group: str, *, verify: bool = True):
    """Open one group of a results file as an in-memory :class:`xarray.Dataset`: a view of :func:`read`.

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


def verify_file(path: os.PathLike) -> None:
    """Verify a whole results file: every dataset against its checksum, every attribute and group against the
    integrity record (the reads a resume or a rerun of a finished run trusts).

    Raises:
        FileNotFoundError: no file at ``path``.
        OSError: HDF5 cannot open it (truncated, not HDF5).
        ChecksumError: damaged or edited (the message names the file, the item and what is wrong).
    """
    read(path, verify=True)
