"""Merging the shards of one job into the file a single process would have written.

Sharded results (the contract an experiment follows to be mergeable): a group carrying the attributes
``shard_axis`` (name of the dimension split between shards), ``shard``, ``n_shards``, ``shard_start``,
``shard_stop`` (the shard's half-open index range along that axis) and optionally ``shard_reduce``: the NAME
of a reducer in :data:`deltajax.sweeps.reducers.REDUCERS` (files written before the registry carry a
``"module:function"`` string, which is mapped to its registered name, never imported). Datasets that have the
shard axis among their dimensions are concatenated; the reducer recomputes every other dataset and attribute
that depends on the whole axis; anything else must be identical in all shards.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any, Mapping, Optional, Sequence

import numpy as np

from ..io import ChecksumError, ResultsFile, Variable, read
from .layout import find_runs, label, override_dict, run_overrides
from .reducers import ShardError, get_reducer

__all__ = ["merge_shards", "merge_sweep", "ShardError", "SHARD_ATTRS"]

log = logging.getLogger(__name__)

#: group attributes that describe a shard (rewritten to the single-run values by :func:`merge_shards`)
SHARD_ATTRS = ("shard", "n_shards", "shard_start", "shard_stop")


def _same(a: Any, b: Any) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    if a.dtype.kind in "fc":
        return bool(np.array_equal(a, b, equal_nan=True))
    return bool(np.array_equal(a, b))


def _config_without_shard(config_yaml: str) -> tuple[str, Any]:
    """(config YAML of the equivalent single run, shard index) from a run's ``config`` attribute."""
    from omegaconf import OmegaConf

    cfg = OmegaConf.create(config_yaml or "{}")
    shard = cfg.get("shard", None)
    if "shard" in cfg:
        cfg.shard = 0
    if "n_shards" in cfg:
        cfg.n_shards = 1
    return OmegaConf.to_yaml(cfg), shard


def _tree(path: Path) -> tuple[dict, dict[str, dict], dict[str, dict[str, Variable]]]:
    """(root attrs, {group: attrs}, {group: {name: Variable}}) of a results file (groups by full path), verified:
    a damaged or edited shard is never merged into a file with fresh checksums."""
    try:
        c = read(path, verify=True)
    except ChecksumError as e:
        raise ShardError(f"{e}; rerun that shard (fresh=true in its run directory)") from None
    return c.attrs, {g: a for g, a in c.group_attrs.items() if g}, c.variables


def merge_shards(paths: Sequence[os.PathLike], out: Optional[os.PathLike] = None) -> Path:
    """Merge the ``results.h5`` files of the shards of one job into one file.

    The merged datasets, units, dimensions and group attributes are identical to those a single process
    (``n_shards=1``) writes: gridded datasets are concatenated along the shard axis in index order and
    everything derived from the whole axis is recomputed by the group's ``shard_reduce`` function from the
    merged arrays. Root attributes are the first shard's, with ``config`` rewritten to the single-run config
    (``shard=0``, ``n_shards=1``), ``start_time``/``end_time`` spanning all shards, ``wall_time_s`` summed,
    ``merged_from`` listing the inputs (one per line), and root attributes that differ between shards (e.g.
    throughput) stored as one value per shard.

    Args:
        paths: the shards' results files, in any order; all ``n_shards`` of them.
        out: output path (default: ``merged_results.h5`` beside the first input).

    Returns:
        The written path.

    Raises:
        ShardError: shards missing, duplicated, overlapping, from different configurations, or a dataset
            that is not along the shard axis differs between shards and no reducer recomputes it.
    """
    paths = [Path(p) for p in paths]
    if not paths:
        raise ShardError("merge_shards: no input files")
    trees = [_tree(p) for p in paths]
    # -- same job? --------------------------------------------------------------------------------------
    single_cfgs = [_config_without_shard(str(t[0].get("config", ""))) for t in trees]
    for (cfg, _), p in zip(single_cfgs[1:], paths[1:]):
        if cfg != single_cfgs[0][0]:
            raise ShardError(f"{p} is not a shard of the same job as {paths[0]} (configs differ beyond 'shard')")
    sharded = {g: a for g, a in trees[0][1].items() if "shard_axis" in a}
    if not sharded:
        raise ShardError(f"{paths[0]}: no group has a 'shard_axis' attribute: not a sharded result")
    # -- order and coverage -----------------------------------------------------------------------------
    gname0 = next(iter(sharded))
    infos = []
    for t, p in zip(trees, paths):
        a = t[1].get(gname0)
        if a is None:
            raise ShardError(f"{p}: group {gname0!r} missing")
        infos.append((int(a["shard_start"]), int(a["shard_stop"]), int(a["shard"]), int(a["n_shards"]), p))
    n_shards = infos[0][3]
    if any(i[3] != n_shards for i in infos):
        raise ShardError(f"shards disagree on n_shards: {[i[3] for i in infos]}")
    shards = sorted(i[2] for i in infos)
    if shards != list(range(n_shards)):
        missing = sorted(set(range(n_shards)) - set(shards))
        dup = sorted({s for s in shards if shards.count(s) > 1})
        raise ShardError(f"need shards 0..{n_shards - 1} exactly once: missing {missing}, duplicated {dup}")
    order = sorted(range(len(paths)), key=lambda i: infos[i][0])
    trees = [trees[i] for i in order]
    paths = [paths[i] for i in order]
    # -- merge group by group ---------------------------------------------------------------------------
    root0 = trees[0][0]
    res = ResultsFile(out if out is not None else paths[0].with_name("merged_results.h5"))
    res.attrs = {}
    all_groups = list(trees[0][2].keys() | trees[0][1].keys())
    for g in sorted(all_groups):
        if g == "":
            continue
        per_shard = [t[2].get(g, {}) for t in trees]
        attrs = [t[1].get(g, {}) for t in trees]
        if g in sharded:
            datasets, gattrs = _merge_group(g, per_shard, attrs, paths)
        else:
            datasets, gattrs = _check_identical_group(g, per_shard, attrs, paths)
        res.put_variables(g, datasets)
        if gattrs:
            res.set_attrs(g, **gattrs)
    # -- root attributes --------------------------------------------------------------------------------
    root = dict(root0)
    root["config"] = single_cfgs[0][0] if "config" in root0 else ""
    starts = [str(t[0].get("start_time", "")) for t in trees if t[0].get("start_time")]
    ends = [str(t[0].get("end_time", "")) for t in trees if t[0].get("end_time")]
    if starts:
        root["start_time"] = min(starts)
    if ends:
        root["end_time"] = max(ends)
    walls = [t[0].get("wall_time_s") for t in trees]
    if all(isinstance(w, (int, float)) for w in walls):
        root["wall_time_s"] = float(sum(walls))
    for key in root0:  # per-shard figures (throughput, worker settings): one value per shard, in order
        if key in ("config", "start_time", "end_time", "wall_time_s"):
            continue
        values = [t[0].get(key) for t in trees]
        if not all(_same(v, values[0]) for v in values[1:]):
            if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
                root[key] = np.asarray(values)
            else:
                root[key] = "\n".join(str(v) for v in values)
    root["merged_from"] = "\n".join(str(p.resolve()) for p in paths)  # one path per line
    root["merged_n_shards"] = n_shards
    res.attrs.update(root)
    return res.flush()


def _merge_group(g, per_shard, attrs, paths):
    a0 = attrs[0]
    axis = str(a0["shard_axis"])
    size = None
    merged: dict[str, Variable] = {}
    names = set(per_shard[0])
    for p, d in zip(paths[1:], per_shard[1:]):
        if set(d) != names:
            raise ShardError(f"{p}: group {g!r} has datasets {sorted(d)}, first shard has {sorted(names)}")
    expected = 0
    for a, p in zip(attrs, paths):
        if int(a["shard_start"]) != expected:
            raise ShardError(f"{p}: shard covers {axis}[{a['shard_start']}:{a['shard_stop']}], expected to start "
                             f"at {expected} (shards overlap or one is missing)")
        expected = int(a["shard_stop"])
    size = expected
    for name in sorted(names):
        d0 = per_shard[0][name]
        if axis in d0.dims:
            k = d0.dims.index(axis)
            data = np.concatenate([d[name].data for d in per_shard], axis=k)
            if data.shape[k] != size:
                raise ShardError(f"group {g!r}: {name} has {data.shape[k]} entries along {axis!r}, expected {size}")
            merged[name] = Variable(data, d0.units, d0.dims, d0.attrs, d0.is_axis)
        else:
            merged[name] = d0
    gattrs = dict(a0)
    gattrs.update(shard=0, n_shards=1, shard_start=0, shard_stop=size)
    recomputed: set[str] = set()
    recomputed_attrs: set[str] = set()
    if a0.get("shard_reduce"):
        reducer = get_reducer(str(a0["shard_reduce"]))
        new_data, new_attrs = reducer({k: v.data for k, v in merged.items()}, [dict(a) for a in attrs])
        for k, v in new_data.items():
            if k not in merged:
                raise ShardError(f"shard_reduce of {g!r} returned {k!r}, which the shards do not have")
            old = merged[k]
            merged[k] = Variable(np.asarray(v), old.units, old.dims, old.attrs, old.is_axis)
            recomputed.add(k)
        gattrs.update(new_attrs)
        recomputed_attrs = set(new_attrs)
    for name in sorted(names):
        d0 = per_shard[0][name]
        if axis in d0.dims or name in recomputed:
            continue
        for d, p in zip(per_shard[1:], paths[1:]):
            if not _same(d[name].data, d0.data):
                raise ShardError(f"group {g!r}: {name} differs between shards ({p}) and is not along "
                                 f"{axis!r} nor recomputed by shard_reduce")
    skip = set(SHARD_ATTRS) | recomputed_attrs
    for key in a0:
        if key in skip:
            continue
        for a, p in zip(attrs[1:], paths[1:]):
            if not _same(a.get(key), a0[key]):
                raise ShardError(f"group {g!r}: attribute {key!r} differs between shards ({p})")
    return merged, gattrs


def _check_identical_group(g, per_shard, attrs, paths):
    d0, a0 = per_shard[0], attrs[0]
    for d, a, p in zip(per_shard[1:], attrs[1:], paths[1:]):
        if set(d) != set(d0) or any(not _same(d[k].data, d0[k].data) for k in d0):
            raise ShardError(f"group {g!r} (not sharded) differs between shards ({p})")
        if set(a) != set(a0) or any(not _same(a[k], a0[k]) for k in a0):
            raise ShardError(f"group {g!r} (not sharded): attributes differ between shards ({p})")
    return d0, a0


def merge_sweep(sweep_dir: os.PathLike) -> list[Path]:
    """Merge every sharded job of a sweep: runs with ``n_shards > 1`` whose configs differ only in ``shard``.

    Writes ``<sweep>/merged/<label>/results.h5`` for each complete set of shards, ``<label>`` being the
    overrides that vary across the sweep (without ``shard``), or the experiment name; sets with missing or
    inconsistent shards are skipped with a message. Returns the written paths.
    """
    sweep_dir = Path(sweep_dir)
    groups: dict[str, list[tuple[Path, dict]]] = {}
    all_overrides = []
    for run in find_runs(sweep_dir):
        ov = override_dict(run_overrides(run))
        all_overrides.append(ov)
        f = run / "results.h5"
        if not f.exists():
            continue
        head = read(f, max_elements=0)  # attributes only
        cfg_yaml = head.attrs.get("config", "")
        name = str(head.attrs.get("experiment", "run"))
        is_sharded = any("shard_axis" in a and int(a.get("n_shards", 1)) > 1 for g, a in head.group_attrs.items()
                         if g and "/" not in g)
        if not is_sharded:
            continue
        single, _ = _config_without_shard(str(cfg_yaml))
        groups.setdefault(single, []).append((f, {**ov, "__name__": name}))
    keys = sorted({k for ov in all_overrides for k in ov})
    varying = [k for k in keys if k != "shard" and len({ov.get(k) for ov in all_overrides}) > 1]
    written = []
    for members in groups.values():
        files = [m[0] for m in members]
        ov = members[0][1]
        tag = label({k: ov[k] for k in varying if k in ov}) if varying else label({}).replace("all", ov["__name__"])
        out = sweep_dir / "merged" / tag / "results.h5"
        try:
            written.append(merge_shards(files, out))
        except ShardError as e:
            log.warning("not merged (%s): %s", ", ".join(map(str, files)), e)
            print(f"[deltajax] not merged: {e}", flush=True)
    return written
