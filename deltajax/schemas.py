"""Hydra structured-config schemas: their registration, and the walkers that name an unknown key with the valid ones.

Registered in the ConfigStore by :func:`register_schemas` (``deltajax.run`` calls it at import). A mistyped key,
a wrong type or an unknown ``+key`` is rejected at composition (``configs/config.yaml`` puts
``schema/robot`` before the robot group and ``schema/experiment/<name>`` before the experiment group). Every
schema is generated from its settings dataclass (:data:`deltajax.config.ROBOT_SCHEMA`,
:data:`deltajax.config.EXPERIMENT_SCHEMAS`, :func:`deltajax.config.readers.schema_of`), where ranges, units, choices
and cross-field rules are declared too. Values live in the YAML files. Imports nothing from deltajax.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Dict, List, Optional
import typing

__all__ = ["register_schemas", "unknown_key", "schema_keys"]


def register_schemas(robot: Any, experiments: Dict[str, Any]) -> None:
    """Register the ``robot`` schema (``schema/robot``, name ``delta``) and ``experiments`` (name -> schema,
    ``schema/experiment``) in Hydra's ConfigStore, both generated from their settings
    (:data:`deltajax.config.ROBOT_SCHEMA`, :data:`deltajax.config.EXPERIMENT_SCHEMAS`); idempotent (run.py calls it
    at import, through :func:`deltajax.config.register_schemas`)."""
    from hydra.core.config_store import ConfigStore

    cs = ConfigStore.instance()
    cs.store(group="schema/robot", name="delta", node=robot)
    for name, node in experiments.items():
        cs.store(group="schema/experiment", name=name, node=node)


# ---- walking the schemas (deltajax.config turns the answers into ConfigError lines) ----
def _schema_fields(schema) -> dict:
    hints = typing.get_type_hints(schema)
    return {f.name: hints[f.name] for f in dataclasses.fields(schema)}


def _unwrap(tp):
    """The dataclass inside Optional[...] / Dict[str, ...] annotations: (dataclass or None, is_dict)."""
    args = typing.get_args(tp)
    origin = typing.get_origin(tp)
    if origin is typing.Union:
        inner = [a for a in args if a is not type(None)]
        return _unwrap(inner[0]) if len(inner) == 1 else (None, False)
    if origin in (dict, Dict) and len(args) == 2 and dataclasses.is_dataclass(args[1]):
        return args[1], True
    if dataclasses.is_dataclass(tp):
        return tp, False
    return None, False


def unknown_key(node: Any, schema, path: str) -> Optional[str]:
    """The first key of ``node`` (a mapping at dotted ``path``) that ``schema`` does not know, as a message that
    lists the valid keys of that block; ``None`` when every key is known (nested blocks included)."""
    if not hasattr(node, "keys"):
        return None
    fields = _schema_fields(schema)
    for k in node.keys():
        if k not in fields:
            return f"{path}.{k} is not a setting of {path}; valid keys: {', '.join(sorted(fields))}"
        sub, is_dict = _unwrap(fields[k])
        v = node.get(k)
        if sub is None or v is None:
            continue
        for sub_path, sub_node in ([(f"{path}.{k}.{n}", v.get(n)) for n in v.keys()] if is_dict
                                   else [(f"{path}.{k}", v)]):
            msg = unknown_key(sub_node, sub, sub_path)
            if msg is not None:
                return msg
    return None


def schema_keys(schema, inner: List[str]) -> Optional[list]:
    """The sorted keys of the block reached from ``schema`` through the field names ``inner``; ``None`` when
    that is not a (non-dict) schema block."""
    for name in inner:
        fields = _schema_fields(schema)
        if name not in fields:
            return None
        sub, is_dict = _unwrap(fields[name])
        if sub is None or is_dict:
            return None
        schema = sub
    return sorted(_schema_fields(schema))
