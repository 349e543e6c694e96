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

from typing import Callable, Mapping, Sequence

import numpy as np
import jax

from ..tracing import PROGRAMS, content_key, shared_program, stable_key
from .designer import evaluate_designer
from .pareto import padded_batch

# the content-keyed program store lives in deltajax.tracing (certify uses it too without importing the designer)
__all__ = ["design_metrics", "batch_evaluator", "objective_matrix", "shared_program", "content_key", "stable_key",
           "PROGRAMS"]


def design_metrics(pb, space, *, regular: bool = True) -> Callable:
    """``genes (d,) -> {metric: ()}`` of one design (:func:`deltajax.optimize.designer.evaluate_designer`), jitted,
    one function per (content of ``pb`` and ``space``, ``regular``) in this process. Called inside another
    program (vmapped, differentiated), JAX reuses its traced jaxpr and only transforms it, so the evaluators, the
    GA's fitness and the refine descent trace the designer once. ``inline=True``: the jaxpr is inlined into each
    caller, so every compiled program computes exactly what it did with the designer traced in place (a nested,
    not inlined call inside the GA's scan changed its fitness history in the last bit)."""
    def build():
        return jax.jit(lambda g: evaluate_designer(pb, space.decode(g), regular=regular), inline=True)

    return shared_program("design_metrics", pb, space, (bool(regular),), build)


def batch_evaluator(pb, space, batch: int, *, regular: bool = True) -> Callable[[np.ndarray], dict]:
    """``genes (n, d) -> {metric: (n,)}`` host arrays, compiled once for ``batch`` rows (and shared by every
    evaluator of the same problem, space and settings in this process)."""
    def build():
        f = shared_program("batch_program", pb, space, (bool(regular),),
                           lambda: jax.jit(jax.vmap(design_metrics(pb, space, regular=regular))), persist=True)
        call = padded_batch(f, batch)
        return lambda X: {k: np.asarray(v) for k, v in call(np.asarray(X)).items()}

    return shared_program("batch_evaluator", pb, space, (int(batch), bool(regular)), build)


def objective_matrix(m: Mapping[str, np.ndarray], objs: Sequence[str], scale: np.ndarray) -> np.ndarray:
    """Minimised, normalised objectives (n, k): sense x metric / |baseline metric|."""
    return np.stack([np.asarray(m[o], float) for o in objs], axis=1) * scale
