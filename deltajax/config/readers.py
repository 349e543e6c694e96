"""The one set of field readers of the configuration (every value goes through these) and :class:`ConfigError`."""

from __future__ import annotations

import math
import copy
import dataclasses
import typing
from typing import Any, Callable, Mapping, Optional
import os


__all__ = ["ConfigError", "read_field", "read_choice", "read_names", "read_vector", "read_box", "memory_bytes", "check_fits",
           "setting", "read_settings", "plain", "schema_of"]


class ConfigError(ValueError):
    """Invalid configuration; the message names the field (dotted path) and the value."""


# ---- the one set of field readers: every value of the configuration goes through these ----
def read_field(path: str, v: Any, *, kind: str = "float", lo: Optional[float] = None, hi: Optional[float] = None,
           lo_open: bool = False, hi_open: bool = False, none: bool = False, unit: str = "") -> Any:
    """Check one value; ``kind`` is "float" (finite number), "int" or "bool". Returns it as a Python value.
    ``unit`` (the unit the user writes it in: "m", "deg", "s", ...) follows every bound and value in the message."""
    u = f" {unit}" if unit else ""
    if v is None:
        if none:
            return None
        raise ConfigError(f"{path} is required, got null")
    if kind == "bool":
        if not isinstance(v, bool):
            raise ConfigError(f"{path} must be true or false, got {v!r}")
        return v
    if isinstance(v, bool):
        raise ConfigError(f"{path} must be {'an integer' if kind == 'int' else 'a number'}, got {v!r}")
    if kind == "int":
        if isinstance(v, float) and v.is_integer():
            v = int(v)
        if not isinstance(v, int):
            raise ConfigError(f"{path} must be an integer, got {v!r}")
    else:
        try:
            v = float(v)
        except (TypeError, ValueError):
            raise ConfigError(f"{path} must be a number{u and f' ({unit})'}, got {v!r}") from None
        if not math.isfinite(v):
            raise ConfigError(f"{path} must be a finite number{u and f' ({unit})'}, got {v!r}")
    bad_lo = lo is not None and (v <= lo if lo_open else v < lo)
    bad_hi = hi is not None and (v >= hi if hi_open else v > hi)
    if bad_lo or bad_hi:
        g = str if kind == "int" and all(isinstance(b, int) for b in (lo, hi) if b is not None) else \
            (lambda b: f"{b:g}")  # integer bounds in full (a seed's 4294967295, not 4.29497e+09)
        left = "" if lo is None else ("(" if lo_open else "[") + g(lo)
        right = "" if hi is None else g(hi) + (")" if hi_open else "]")
        if lo is not None and hi is None:
            rng = f"{'>' if lo_open else '>='} {g(lo)}{u}"
        elif hi is not None and lo is None:
            rng = f"{'<' if hi_open else '<='} {g(hi)}{u}"
        else:
            rng = f"in {left}, {right}{u}"
        raise ConfigError(f"{path} must be {rng}, got {v!r}{u}")
    return v


def read_choice(path: str, v: Any, options) -> str:
    if v not in tuple(options):
        raise ConfigError(f"{path} must be one of {', '.join(map(str, sorted(options)))}, got {v!r}")
    return v


def read_names(path: str, v: Any, options, *, min_len: int = 0) -> list:
    items = list(v or [])
    for x in items:
        read_choice(f"{path} entry", x, options)
    if len(items) < min_len:
        raise ConfigError(f"{path} must list at least {min_len} of {', '.join(map(str, sorted(options)))}, "
                          f"got {items!r}")
    return items


def read_vector(path: str, v: Any, n: int, unit: str = "m") -> list:
    u = f" ({unit})" if unit else ""
    try:
        items = [float(t) for t in v]
    except (TypeError, ValueError):
        raise ConfigError(f"{path} must be a list of {n} numbers{u}, got {v!r}") from None
    if len(items) != n or not all(math.isfinite(t) for t in items):
        raise ConfigError(f"{path} must be a list of {n} finite numbers{u}, got {v!r}")
    return items




def read_box(path: str, v: Any, *, optional: bool = False) -> list:
    """A box ``[[x0, x1], [y0, y1], [z0, z1]]`` (m), each side of positive width, as three ``[lo, hi]`` lists
    (``optional``: the setting may be null, which the message says)."""
    if not hasattr(v, "__len__") or len(v) != 3:
        raise ConfigError(f"{path} must be {'null or ' if optional else ''}[[x0,x1],[y0,y1],[z0,z1]] (m), "
                          f"got {v!r}")
    box = [read_vector(f"{path}[{i}]", b, 2) for i, b in enumerate(v)]
    for (lo, hi), k in zip(box, "xyz"):
        if not hi > lo:
            raise ConfigError(f"{path} ({k}) must have lo < hi (m), got {[lo, hi]!r}")
    return box

# ---- settings declared once: a frozen dataclass per block, each field's range, unit and choices as metadata ----
@dataclasses.dataclass(frozen=True)
class _Spec:
    unit: str = ""
    lo: Optional[float] = None
    hi: Optional[float] = None
    lo_open: bool = False
    hi_open: bool = False
    choices: Any = None          # a tuple of allowed values, or a zero-argument callable returning one (lazy)
    read: Optional[Callable[[str, Any], Any]] = None   # a field's own reader (path, value) -> value


def setting(default: Any = dataclasses.MISSING, *, unit: str = "", lo: Optional[float] = None,
            hi: Optional[float] = None, lo_open: bool = False, hi_open: bool = False, choices: Any = None,
            read: Optional[Callable[[str, Any], Any]] = None) -> Any:
    """A field of a settings dataclass with what :func:`read_settings` checks it by: the range ``[lo, hi]``
    (``lo_open``/``hi_open``: strict), its ``unit`` (in every message), its ``choices`` (a string field), or its own
    ``read(path, value)`` (lists, mappings, values with a library reader). No ``default``: the key is required; a
    nested settings dataclass with a default may be absent as a whole. The type comes from the annotation
    (``bool``, ``int``, ``float``, ``str``, ``Optional[...]``: null allowed, or a settings dataclass)."""
    md = {"deltajax": _Spec(unit, lo, hi, lo_open, hi_open, choices, read)}
    if default is dataclasses.MISSING:
        return dataclasses.field(metadata=md)
    if isinstance(default, (dict, list)):           # a fresh copy per instance, never one shared mutable default
        return dataclasses.field(default_factory=lambda d=default: copy.deepcopy(d), metadata=md)
    if dataclasses.is_dataclass(default):           # a frozen block: one instance may serve every default
        return dataclasses.field(default_factory=lambda d=default: d, metadata=md)
    return dataclasses.field(default=default, metadata=md)


def plain(x: Any) -> Any:
    """A composed (OmegaConf) value as plain Python containers; anything else unchanged."""
    if hasattr(x, "_metadata") and hasattr(x, "_get_node"):   # DictConfig / ListConfig, without importing omegaconf
        from omegaconf import OmegaConf

        return OmegaConf.to_container(x, resolve=True)
    return x


def _optional(tp) -> tuple:
    if typing.get_origin(tp) is typing.Union and type(None) in typing.get_args(tp):
        inner = [a for a in typing.get_args(tp) if a is not type(None)]
        return (inner[0] if len(inner) == 1 else Any), True
    return tp, False


def _read_value(path: str, v: Any, tp, spec: _Spec) -> Any:
    tp, none = _optional(tp)
    if spec.read is not None:
        return None if (v is None and none) else spec.read(path, v)
    if dataclasses.is_dataclass(tp):
        return read_settings(tp, v, path)
    if tp is bool:
        return read_field(path, v, kind="bool", none=none)
    if tp in (int, float):
        return read_field(path, v, kind="int" if tp is int else "float", lo=spec.lo, hi=spec.hi,
                          lo_open=spec.lo_open, hi_open=spec.hi_open, none=none, unit=spec.unit)
    if v is None and none:
        return None
    if spec.choices is not None:
        return read_choice(path, v, spec.choices() if callable(spec.choices) else spec.choices)
    if tp is str and not isinstance(v, str):
        raise ConfigError(f"{path} must be a string, got {v!r}")
    return v


def read_settings(cls, block: Any, path: str):
    """The settings dataclass ``cls`` of the config block at dotted ``path``, every field checked by its metadata
    (:func:`setting`), nested blocks read the same way, then the block's own cross-field rules (its ``_check(path)``
    method, if it has one; what it returns, if not None, is the result: a block with derived fields filled in, i.e.
    fields declared without :func:`setting`, which are no config keys). Unknown keys and missing required keys are
    refused, each as one line naming the block; a bad value as one line naming the field and the value in its
    unit. A value left ``???`` (OmegaConf's MISSING: a required field of the schema that the YAML does not give)
    is a missing key."""
    block = plain(block)
    if not isinstance(block, Mapping):
        raise ConfigError(f"{path} must be a mapping, got {block!r}")
    block = {k: v for k, v in block.items() if not (isinstance(v, str) and v == "???")}
    # a field declared without setting() is derived (no config key: it keeps its default unless _check fills it)
    fields = [f for f in dataclasses.fields(cls) if "deltajax" in f.metadata]
    names = [f.name for f in fields]
    extra = sorted(set(block) - set(names), key=str)
    if extra:
        raise ConfigError(f"{path}: unknown keys {', '.join(map(str, extra))}; valid keys: {', '.join(sorted(names))}")
    required = [f.name for f in fields if f.default is dataclasses.MISSING
                and f.default_factory is dataclasses.MISSING]
    missing = sorted(set(required) - set(block))
    if missing:
        raise ConfigError(f"{path}: missing keys {', '.join(missing)}")
    hints = typing.get_type_hints(cls)
    # a block given as null where it has a default: absent (a structured config holds absent optional blocks as null)
    given = {f.name for f in fields if f.name in block and not (
        block[f.name] is None and dataclasses.is_dataclass(_optional(hints[f.name])[0])
        and (f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING))}
    out = {f.name: _read_value(f"{path}.{f.name}", block[f.name], hints[f.name], f.metadata["deltajax"])
           for f in fields if f.name in given}
    obj = cls(**out)
    check = getattr(obj, "_check", None)
    return obj if check is None else (check(path) or obj)



def schema_of(cls, name: Optional[str] = None):
    """The Hydra structured-config schema of settings dataclass ``cls`` (registered in the ConfigStore): its config
    fields, nested blocks as nested schemas, each typed as declared (``bool``, ``int``, ``float``, ``str``,
    ``Optional[...]``; ``Any`` where the field has its own reader: lists, mappings, paths) and required (``???``)
    unless the field has a default (a block with a default: ``Optional``, absent as null). So the keys and types
    Hydra composes against come from the same declaration as the ranges :func:`read_settings` checks."""
    from omegaconf import MISSING

    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        spec = f.metadata.get("deltajax")
        if spec is None:
            continue
        tp, none = _optional(hints[f.name])
        has_default = f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING
        if dataclasses.is_dataclass(tp) and spec.read is None:
            sub = schema_of(tp)
            out.append((f.name, Optional[sub], dataclasses.field(default=None)) if has_default or none else
                       (f.name, sub, dataclasses.field(default_factory=sub)))
            continue
        if spec.read is not None or tp not in (bool, int, float, str):
            tp, none = Any, False
        default = f.default if f.default is not dataclasses.MISSING else (None if has_default else MISSING)
        out.append((f.name, Optional[tp] if none or default is None else tp, dataclasses.field(default=default)))
    return dataclasses.make_dataclass(name or f"{cls.__name__}Schema", out)



# ---- memory: sizes are refused up front when even a lower bound of what they hold exceeds the machine ----
def memory_bytes() -> int:
    """Memory this process may use (bytes): the machine's physical memory, or the cgroup's limit where lower (a
    container, a SLURM allocation). The cap that a grid, a population or a batch must fit in."""
    cap = int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    for f in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = open(f).read().strip()
        except OSError:
            continue
        if text.isdigit():
            cap = min(cap, int(text))
    return cap


def _gib(n: float) -> str:
    return f"{n / 2 ** 30:.3g} GiB"


def check_fits(path: str, v: Any, n_bytes: float, what: str, unit: str = "") -> None:
    """Refuse ``path=v`` when ``what`` needs at least ``n_bytes`` (a lower bound) and the machine has less."""
    cap = memory_bytes()
    if n_bytes > cap:
        u = f" {unit}" if unit else ""
        raise ConfigError(f"{path}={v!r}{u} needs at least {_gib(n_bytes)} of memory for {what}, more than the "
                          f"{_gib(cap)} this machine has")
