"""The one set of field readers of the configuration (every value goes through these) and :class:`ConfigError`."""

from __future__ import annotations

import math
from typing import Any, Optional


__all__ = ["ConfigError", "read_field", "read_choice", "read_names", "read_vector", "memory_bytes", "check_fits"]


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




# ---- memory: sizes are refused up front when even a lower bound of what they hold exceeds the machine ----
def memory_bytes() -> int:
    """Memory this process may use (bytes): the machine's physical memory, or the cgroup's limit where lower (a
    container, a SLURM allocation). The cap that a grid, a population or a batch must fit in."""
    import os

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
