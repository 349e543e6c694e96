"""Shard reducers, looked up by NAME: what recomputes a sharded group's whole-axis figures when shards merge.

A sharded group names its reducer in its ``shard_reduce`` attribute (see :mod:`deltajax.sweeps.merge`). A
reducer is ``f(data, shard_attrs) -> (datasets, attributes)``: ``data`` maps every dataset name of the merged
group to its merged array, ``shard_attrs`` is the list of the shards' group attributes in axis order; it
returns the datasets it recomputes (each must exist in the shards) and the group attributes it recomputes.

The registry holds deltajax's own reducers under fixed names; :func:`register_reducer` adds others. A name
read from a file is only ever looked up here: no code named by a file is imported. Files written before the
registry carry a ``"module:function"`` string; :data:`LEGACY` maps the strings deltajax wrote to their names.
"""

from __future__ import annotations

from typing import Any, Callable, Mapping, Sequence

from ..workspace.chunks import reduce_plane_shards

__all__ = ["ShardError", "REDUCERS", "LEGACY", "register_reducer", "get_reducer"]

Reducer = Callable[[Mapping[str, Any], Sequence[Mapping[str, Any]]], tuple]


class ShardError(ValueError):
    """Shards that cannot be merged (missing, overlapping, or from different jobs); the message says which."""


#: reducer name -> function (deltajax's own are added on first use, see :func:`get_reducer`)
REDUCERS: dict[str, Reducer] = {}

#: ``"module:function"`` strings in files written before the registry -> the registered name
LEGACY = {
    "deltajax.jobs.workspace_grid:reduce_shards": "workspace_planes",
    "deltajax.experiments.workspace_grid:reduce_shards": "workspace_planes",
}


def register_reducer(name: str, fn: Reducer) -> Reducer:
    """Register ``fn`` as the reducer called ``name`` (the value a sharded group stores in ``shard_reduce``).

    Raises:
        ValueError: ``name`` is empty, contains ':' (the old string form) or is taken by another function.
    """
    if not name or ":" in name:
        raise ValueError(f"reducer name must be a non-empty word without ':', got {name!r}")
    if REDUCERS.get(name, fn) is not fn:
        raise ValueError(f"reducer name {name!r} is already registered to {REDUCERS[name]!r}")
    REDUCERS[name] = fn
    return fn


def _register_builtin() -> None:
    REDUCERS.setdefault("workspace_planes", reduce_plane_shards)


def get_reducer(name: str) -> Reducer:
    """The reducer registered as ``name`` (or the name :data:`LEGACY` gives an old ``"module:function"``).

    Raises:
        ShardError: no reducer has that name; the message lists the registered ones.
    """
    _register_builtin()
    key = LEGACY.get(name, name)
    if key not in REDUCERS:
        raise ShardError(f"shard_reduce {name!r} is not a registered reducer; registered: {sorted(REDUCERS)} "
                         f"(deltajax.sweeps.register_reducer adds one)")
    return REDUCERS[key]
