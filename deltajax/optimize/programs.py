"""The designer's compiled per-design programs, shared by content (the workflow's stages, the floor step and the
refine descent all evaluate designs through them), and the objective matrix they feed.

:func:`design_metrics` is one design's metrics as a jitted function; :func:`batch_evaluator` (the screen, NSGA-II,
the verification), :func:`deltajax.optimize.workflow.ga_fitness` (the GA) and
:func:`deltajax.optimize.descent.descent_paths` (forward-mode derivatives) call it inside their own programs, so
JAX traces the designer's Python once per (problem, space, ``regular``) and only transforms (vmap, jvp) the traced
program for each use: tracing, not XLA compilation, was most of a toy run's CPU time (the persistent XLA cache
holds the compiled programs; tracing happens in every process).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Mapping, Sequence

import numpy as np

__all__ = ["design_metrics", "batch_evaluator", "objective_matrix", "shared_program", "content_key", "stable_key"]


# -- compiled per-design programs, shared by value -----------------------------------------------------------------
# Every run builds its problem and design space afresh, and a jitted closure over a fresh object is traced and
# compiled again (a toy run traces its stages for ~40 CPU-s before any compile). The stages' programs are kept
# here under the *content* of the problem and space they close over, so a resumed run, a rerun or another run
# with the same grids in the same process reuses them: the same content gives the same program, hence the same
# numbers as compiling it afresh.
_PROGRAMS: dict = {}
_PROGRAMS_MAX = 24


def content_key(x) -> Any:
    """A hashable value of everything ``x`` holds (dataclasses and equinox modules field by field, arrays by
    dtype, shape and bytes); an object it cannot see into is keyed by identity (never a false match: the cached
    program keeps it alive)."""
    if isinstance(x, (np.ndarray, np.generic)) or type(x).__module__.startswith("jax"):
        try:
            a = np.asarray(x)
        except Exception:  # noqa: BLE001 - not an array after all (e.g. a tracer): identity
            return ("id", id(x))
        if a.dtype != object:
            return ("array", a.dtype.str, a.shape, a.tobytes())
        return ("objects", a.shape, tuple(content_key(v) for v in a.reshape(-1)))
    if x is None or isinstance(x, (bool, int, float, complex, str, bytes)):
        return (type(x).__name__, repr(x))
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return (type(x).__module__, type(x).__qualname__,
                tuple((f.name, content_key(getattr(x, f.name))) for f in dataclasses.fields(x)))
    if isinstance(x, (tuple, list)):
        return (type(x).__qualname__, tuple(content_key(v) for v in x))
    if isinstance(x, Mapping):
        return ("mapping", tuple(sorted((repr(k), content_key(v)) for k, v in x.items())))
    return ("id", id(x))


def stable_key(*objs) -> Any:
    """A string naming the content of ``objs`` in every process (:func:`content_key`'s value, hashed), or None
    when part of it is only known by identity (such a program is not kept across processes)."""
    import hashlib

    def by_value(k) -> bool:
        if isinstance(k, tuple):
            if len(k) == 2 and k[0] == "id":
                return False
            return all(by_value(v) for v in k)
        return True

    k = tuple(content_key(o) for o in objs)
    return hashlib.sha256(repr(k).encode()).hexdigest() if by_value(k) else None


def shared_program(kind: str, pb, space, settings: tuple, build: Callable[[], Any], *,
                   persist: bool = False) -> Any:
    """The program ``build()`` for (``kind``, the content of ``pb`` and ``space``, ``settings``), built once per
    process (least recently used dropped beyond ``_PROGRAMS_MAX``). ``persist``: ``build()`` is a jitted function
    of arrays whose lowered program is also kept across processes (:func:`deltajax.tracing.persistent`), when the
    content is known by value (:func:`stable_key`)."""
    if persist:
        inner = build

        def build():
            from ..tracing import persistent

            key = stable_key(pb, space, settings)
            return inner() if key is None else persistent(inner(), kind, key)

    key = (kind, content_key(pb), content_key(space), settings)
    if key in _PROGRAMS:
        _PROGRAMS[key] = _PROGRAMS.pop(key)          # most recently used last
    else:
        _PROGRAMS[key] = build()
        while len(_PROGRAMS) > _PROGRAMS_MAX:
            _PROGRAMS.pop(next(iter(_PROGRAMS)))
    return _PROGRAMS[key]


def design_metrics(pb, space, *, regular: bool = True) -> Callable:
    """``genes (d,) -> {metric: ()}`` of one design (:func:`deltajax.optimize.designer.evaluate_designer`), jitted,
    one function per (content of ``pb`` and ``space``, ``regular``) in this process. Called inside another
    program (vmapped, differentiated), JAX reuses its traced jaxpr and only transforms it, so the evaluators, the
    GA's fitness and the refine descent trace the designer once. ``inline=True``: the jaxpr is inlined into each
    caller, so every compiled program computes exactly what it did with the designer traced in place (a nested,
    not inlined call inside the GA's scan changed its fitness history in the last bit)."""
    def build():
        import jax

        from .designer import evaluate_designer

        return jax.jit(lambda g: evaluate_designer(pb, space.decode(g), regular=regular), inline=True)

    return shared_program("design_metrics", pb, space, (bool(regular),), build)


def batch_evaluator(pb, space, batch: int, *, regular: bool = True) -> Callable[[np.ndarray], dict]:
    """``genes (n, d) -> {metric: (n,)}`` host arrays, compiled once for ``batch`` rows (and shared by every
    evaluator of the same problem, space and settings in this process)."""
    def build():
        import jax

        from .pareto import padded_batch

        f = shared_program("batch_program", pb, space, (bool(regular),),
                           lambda: jax.jit(jax.vmap(design_metrics(pb, space, regular=regular))), persist=True)
        call = padded_batch(f, batch)
        return lambda X: {k: np.asarray(v) for k, v in call(np.asarray(X)).items()}

    return shared_program("batch_evaluator", pb, space, (int(batch), bool(regular)), build)


def objective_matrix(m: Mapping[str, np.ndarray], objs: Sequence[str], scale: np.ndarray) -> np.ndarray:
    """Minimised, normalised objectives (n, k): sense x metric / |baseline metric|."""
    return np.stack([np.asarray(m[o], float) for o in objs], axis=1) * scale
