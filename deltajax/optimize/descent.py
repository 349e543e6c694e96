"""The refine descent: projected Adam (optax) on the designer's primary objective plus a constraint penalty,
and the refinement stage built on it (:func:`refine_designs`); the floor step
(:func:`deltajax.optimize.floor.solve_floor`) runs the same compiled descent.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Optional, Sequence

import numpy as np
import jax
import jax.numpy as jnp

from .programs import batch_evaluator, design_metrics, objective_matrix, shared_program
from .designer import FEASIBILITY_TOL
from .pareto import padded_batch

__all__ = ["DESCENT_ROWS", "RefineOutcome", "descent_paths", "refine_designs"]


# -- optax refinement --------------------------------------------------------------------------------------------

DESCENT_ROWS = 8   # rows of one compiled refine descent (the job's REFINE_MAX winners)


@dataclasses.dataclass
class RefineOutcome:
    """Refinement of each winner (rows): ``genes_before/after``, ``F_before/after`` (normalised minimised
    objectives on the search grids), ``accepted`` (an iterate was feasible, no objective worse and the primary
    strictly better), ``step`` (which iterate, 0 = the start), ``loss_history`` (steps, n)."""

    genes_before: np.ndarray
    genes_after: np.ndarray
    F_before: np.ndarray
    F_after: np.ndarray
    accepted: np.ndarray
    step: np.ndarray
    loss_history: np.ndarray


def descent_paths(pb, space, genes: np.ndarray, objs: Sequence[str], scale: np.ndarray, primary: str, *,
                  steps: int = 20, learning_rate: float = 0.01, penalty: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """Projected Adam (optax) on ``scale_primary x primary + penalty x sum(max(g, 0))`` from each row of ``genes``
    (the gene box [0, 1]^d): ``(loss history (n, steps), iterates (n, steps + 1, d), the start first)``.

    One compiled program per (problem, space, settings), run in padded batches of :data:`DESCENT_ROWS` rows (the
    refinement and :func:`deltajax.optimize.floor.solve_floor` share it). Raises ``FloatingPointError`` on any
    non-finite gradient (never zeroed)."""
    import optax
    from optax import projections

    genes = np.clip(np.asarray(genes, float).reshape(-1, space.dim), 0.0, 1.0)
    sp = float(scale[list(objs).index(primary)])
    reg = primary.startswith("regular")

    def build():
        one = design_metrics(pb, space, regular=reg)   # the evaluators' traced program, differentiated

        def loss(g):
            m = one(g)
            return sp * m[primary] + penalty * jnp.sum(jnp.maximum(m["g"] - FEASIBILITY_TOL, 0.0))

        def value_and_loss(g):
            v = loss(g)
            return v, v                                 # the value once (it was traced twice)

        opt = optax.adam(learning_rate)
        # forward mode: 6 genes, and it compiles faster than reverse mode through the kernel (26 vs 34 CPU-s)
        vg = jax.jacfwd(value_and_loss, has_aux=True)

        @jax.jit
        def descend(G0):
            def one(g0):
                def body(carry, _):
                    g, st = carry
                    grad, val = vg(g)
                    upd, st = opt.update(grad, st, g)
                    g = projections.projection_box(optax.apply_updates(g, upd), 0.0, 1.0)
                    return (g, st), (val, g, jnp.all(jnp.isfinite(grad)))
                _, (hist, path, fin) = jax.lax.scan(body, (g0, opt.init(g0)), None, length=steps)
                return hist, path, fin
            return jax.vmap(one)(G0)
        return descend

    settings = (primary, repr(sp), reg, int(steps), repr(float(learning_rate)), repr(float(penalty)))
    descend = shared_program("refine_descent", pb, space, settings, build, persist=True)
    # in batches of DESCENT_ROWS rows (padded): one compiled descent for any number of starts (the job refines
    # at most 8; a stage with fewer, e.g. without a Pareto front, reuses it)
    hist, path, fin = padded_batch(descend, DESCENT_ROWS)(genes)
    if not fin.all():
        i, k = (int(v[0]) for v in np.nonzero(~fin))
        raise FloatingPointError(f"refine: non-finite gradient of the designer's loss for design {i} at step {k} "
                                 f"(genes {path[i, max(k - 1, 0)].tolist() if k else genes[i].tolist()}); "
                                 "the refinement never zeroes a broken gradient")
    return np.asarray(hist), np.concatenate([genes[:, None, :], np.asarray(path)], axis=1)


def refine_designs(pb, space, genes: np.ndarray, objs: Sequence[str], scale: np.ndarray, primary: str, *,
                   steps: int = 20, learning_rate: float = 0.01, penalty: float = 10.0, top: int = 3,
                   evaluate: Optional[Callable] = None, evaluate_cheap: Optional[Callable] = None,
                   progress: Optional[Callable[[int], Any]] = None) -> RefineOutcome:
    """:func:`descent_paths` from each row of ``genes``, then an acceptance rule on the true constraints.

    The cycle rate carries implicit-function derivatives (:func:`deltajax.constraints.cycle_rate`); the task
    coverage is a step function (zero derivative), so the true constraints decide: every iterate is evaluated
    without the regular workspace, the ``top`` best feasible iterates that improve the primary are evaluated
    with it, and the best of those with no objective worse than the start is kept. Raises
    ``FloatingPointError`` on any non-finite gradient (never zeroed).
    """
    genes = np.clip(np.asarray(genes, float).reshape(-1, space.dim), 0.0, 1.0)
    n, d = genes.shape
    jp = list(objs).index(primary)
    sp = float(scale[jp])
    hist, cand = descent_paths(pb, space, genes, objs, scale, primary, steps=steps, learning_rate=learning_rate,
                               penalty=penalty)
    if progress is not None:
        progress(1)
    evaluate_cheap = evaluate_cheap or batch_evaluator(pb, space, 64, regular=False)
    evaluate = evaluate or batch_evaluator(pb, space, 16)
    cheap = evaluate_cheap(cand.reshape(-1, d))
    P = np.asarray(cheap[primary], float).reshape(n, steps + 1) * sp                # minimised
    ok = cheap["feasible"].astype(bool).reshape(n, steps + 1) & np.isfinite(P)
    better = ok & (P < P[:, :1])
    better[:, 0] = False
    picks = []
    for i in range(n):
        idx = np.flatnonzero(better[i])
        picks.append([0] + list(idx[np.argsort(P[i, idx], kind="stable")][:top]))
    rows = [(i, k) for i in range(n) for k in picks[i]]
    full = evaluate(np.stack([cand[i, k] for i, k in rows]))
    F = objective_matrix(full, objs, scale)
    feas = full["feasible"].astype(bool)
    if progress is not None:
        progress(1)
    F_before, F_after = np.zeros((n, len(objs))), np.zeros((n, len(objs)))
    after, step, acc = genes.copy(), np.zeros(n, int), np.zeros(n, bool)
    r = 0
    for i in range(n):
        k_rows = list(range(r, r + len(picks[i])))
        r += len(picks[i])
        F0 = F[k_rows[0]]
        F_before[i] = F_after[i] = F0
        for j, k in zip(k_rows[1:], picks[i][1:]):          # best primary first
            if feas[j] and np.all(F[j] <= F0 + 1e-12) and F[j][jp] < F0[jp]:
                after[i], step[i], acc[i], F_after[i] = cand[i, k], k, True, F[j]
                break
    return RefineOutcome(genes_before=genes, genes_after=after, F_before=F_before, F_after=F_after, accepted=acc,
                         step=step, loss_history=hist.T)
