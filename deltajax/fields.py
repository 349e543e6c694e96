"""Leaf converter and invariant check shared by the model pytrees (geometry, mass, mechanism, limits, constraints).

Library models take plain values and check only their invariants here, in the model's own words
(``ScrewLinkage.pitch must be ...``); configuration paths and user units belong to :mod:`deltajax.config`.
"""

from __future__ import annotations

import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["float_leaf", "check_range", "ConstraintError"]


class ConstraintError(ValueError):
    """Invalid constraint model: motor, joints, links, good-workspace spec (names the field and the value)."""


def float_leaf(x: Any) -> jax.Array:
    """A model field as an array of JAX's default float dtype (float64 when x64 is on)."""
    return jnp.asarray(x, dtype=jnp.result_type(float))


def check_range(owner: str, name: str, value: Any, *, lo: float = 0.0, strict: bool = True, hi: float = math.inf,
                unit: str = "", error: type = ValueError, skip_batches: bool = False, allow_inf: bool = False) -> None:
    """Raise ``error`` unless every entry of ``value`` is finite (or +inf, "no limit", with ``allow_inf``),
    above ``lo`` (or equal, when not ``strict``) and at most ``hi``. Traced values are skipped (checked where they were concrete); with ``skip_batches``
    so are arrays of more than one dimension-0 value (a population, checked per instance by its builder).

    The message names ``owner.name``, the admissible range with ``unit`` and the value.
    """
    if isinstance(value, jax.core.Tracer):
        return
    a = np.asarray(value, dtype=float)
    if skip_batches and a.ndim != 0:
        return
    finite = ~np.isnan(a) & (a != -np.inf) if allow_inf else np.isfinite(a)
    bad = (not np.all(finite)) or np.any(a < lo) or (strict and np.any(a == lo)) or np.any(a > hi)
    if not bad:
        return
    low = f"{'>' if strict else '>='} {lo:g}"
    rng = low if hi == math.inf else f"in {'(' if strict else '['}{lo:g}, {hi:g}]"
    shown = float(a) if a.ndim == 0 else a.tolist()
    what = "a number" if allow_inf else "a finite number"
    raise error(f"{owner}.{name} must be {what} {rng}{' ' + unit if unit else ''}{' (inf: none)' if allow_inf else ''}, got {shown!r}")
