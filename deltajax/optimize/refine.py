"""Gradient refinement with optax on a differentiable relaxation, verified on the true objective.

The true fitness is piecewise constant in the design (a workspace volume counts grid cells; coverage counts
task points; the operating R is an argmin), so its gradient is useless. :func:`evaluate_design` with
``smooth=tau`` replaces each indicator by a sigmoid of a signed margin (IK discriminant and joint-limit
margins for workspace membership, index minus threshold for coverage) and the argmin by softmin weights;
torque, speed and indices are already differentiable almost everywhere. Adam (optax) descends that
surrogate in gene space, projected onto the box [0, 1]^d after each step (``optax.projections``), for all
designs at once (vmapped, one ``lax.scan``).

Every iterate of the descent is then re-evaluated with the **true** metrics and the best feasible one by the
true objective is kept (a line search on the truth along the surrogate's path); :class:`RefineResult` reports
before and after for each design, and ``accepted`` marks those whose true objective strictly improved (and
stayed feasible): only those replace their starting design.
"""

from __future__ import annotations

import dataclasses
from typing import Callable, Mapping, Optional, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from .objectives import METRICS, SENSE, Problem, evaluate_design

__all__ = ["RefineResult", "refine", "surrogate_loss"]


@dataclasses.dataclass
class RefineResult:
    """Before/after of every refined design (host arrays, one row per design).

    Attributes:
        genes_before, genes_after: (n, d).
        true_before, true_after: true objective (the quantity refined, minimised) of each design.
        surrogate_before, surrogate_after: the relaxed objective.
        metrics_before, metrics_after: every true metric, {name: (n,)}.
        accepted: true objective improved and the design is feasible after refinement.
        loss_history: (steps, n) surrogate loss along the descent.
    """

    genes_before: np.ndarray
    genes_after: np.ndarray
    true_before: np.ndarray
    true_after: np.ndarray
    surrogate_before: np.ndarray
    surrogate_after: np.ndarray
    metrics_before: dict
    metrics_after: dict
    accepted: np.ndarray
    loss_history: np.ndarray


def _direction_vector(pb: Problem, direction: Optional[Mapping[str, float]]) -> np.ndarray:
    """Weights over :data:`METRICS` (sense and baseline normalisation folded in)."""
    d = dict(pb.weights) if direction is None else dict(direction)
    for k in d:
        if k not in METRICS:
            raise ValueError(f"refine direction: unknown metric {k!r}; known: {list(METRICS)}")
    return np.asarray([d.get(k, 0.0) * SENSE[k] / abs(pb.baseline[k]) if d.get(k, 0.0) else 0.0
                       for k in METRICS])


def _weighted(m, wvec):
    # only the metrics that were computed (a NaN metric with weight 0 must not reach the gradient)
    return sum(wvec[i] * m[k] for i, k in enumerate(METRICS) if k in m)


def surrogate_loss(pb: Problem, space, genes, wvec, *, tau: float, penalty: float = 10.0,
                   needed: Optional[Sequence[str]] = None):
    """Relaxed objective of one gene vector: the relaxed weighted objective (``wvec`` over
    :data:`METRICS`, see :func:`_direction_vector`) plus ``penalty`` x the relaxed constraint violation (a smooth
    exterior penalty: feasibility-first needs a step function)."""
    m = evaluate_design(pb, space.decode(genes), needed, smooth=tau)
    if needed is not None:
        m = {k: v for k, v in m.items() if k in needed or k == "violation"}
    return _weighted(m, wvec) + penalty * m["violation"]


def refine(pb: Problem, space, genes: np.ndarray, *, steps: int = 30, learning_rate: float = 0.01,
           tau: float = 0.05, directions: Optional[Sequence[Optional[Mapping[str, float]]]] = None,
           penalty: float = 10.0, true_fn: Optional[Callable] = None) -> RefineResult:
    """Refine designs by projected Adam on the relaxed objective; verify on the true one.

    Args:
        pb: problem (with baseline set).
        space: design space.
        genes: (n, d) starting genes in [0, 1].
        steps: Adam steps.
        learning_rate: Adam step size in gene units.
        tau: relaxation temperature (see :func:`deltajax.optimize.evaluate_design`).
        directions: per design, ``None`` (refine the GA's weighted objective, ``pb.weights``) or a mapping
            ``{metric: weight}`` (refine that weighted sum of baseline-normalised objectives, e.g. for Pareto
            points). Default: ``None`` for every design. One compilation serves all of them.
        penalty: weight of the relaxed constraint violation.
        true_fn: optional ``genes (n, d) -> metrics`` (reuses a compiled evaluator).

    Returns:
        :class:`RefineResult`; ``true_*`` are the chosen objective (without constraints) on the true metrics.
    """
    import optax
    from optax import projections

    genes = jnp.asarray(np.clip(np.asarray(genes, float), 0.0, 1.0))
    n = genes.shape[0]
    directions = [None] * n if directions is None else list(directions)
    if len(directions) != n:
        raise ValueError(f"refine: {len(directions)} directions for {n} designs")
    W = jnp.asarray(np.stack([_direction_vector(pb, d) for d in directions]))
    opt = optax.adam(learning_rate)

    needed = tuple(sorted({k for j, k in enumerate(METRICS) if np.any(np.asarray(W)[:, j] != 0)}))

    def loss(g, w):
        return surrogate_loss(pb, space, g, w, tau=tau, penalty=penalty, needed=needed)

    vg = jax.value_and_grad(loss)

    @jax.jit
    def descend(G0, W):
        def one(g0, w):
            def body(carry, _):
                g, st = carry
                val, grad = vg(g, w)
                upd, st = opt.update(grad, st, g)
                g = projections.projection_box(optax.apply_updates(g, upd), 0.0, 1.0)
                return (g, st), (val, g, jnp.isfinite(grad))
            (g, _), (hist, path, fin) = jax.lax.scan(body, (g0, opt.init(g0)), None, length=steps)
            return path, hist, hist[0], loss(g, w), fin
        return jax.vmap(one)(G0, W)

    path, hist, s_before, s_after, finite = descend(genes, W)  # path: (n, steps, d) iterates after each step
    finite = np.asarray(finite)  # (n, steps, d)
    if not finite.all():
        # Never hide a broken gradient (a NaN entry zeroed would silently freeze that gene): fail loudly.
        i, k, j = (int(v[0]) for v in np.nonzero(~finite))
        raise FloatingPointError(
            f"refine: non-finite surrogate gradient for design {i} (gene {j}, step {k}) at genes "
            f"{np.asarray(genes)[i].tolist()}; the relaxation must be differentiable everywhere (tau={tau!r})")
    if true_fn is None:
        true_fn = jax.jit(lambda G: jax.vmap(lambda g: evaluate_design(pb, space.decode(g)))(G))
    Wn = np.asarray(W)
    d = genes.shape[1]
    # Verify on the truth along the whole descent: every iterate is evaluated with the true metrics and the
    # best feasible one (true objective) is kept; the start itself is a candidate, so "accepted" means a
    # strict improvement of the true objective.
    cand = np.concatenate([np.asarray(genes)[:, None, :], np.asarray(path)], axis=1)  # (n, steps + 1, d)
    mc = {k: np.array(v).reshape(n, steps + 1) for k, v in true_fn(cand.reshape(-1, d)).items()}
    tc = sum(Wn[:, j, None] * mc[k] for j, k in enumerate(METRICS) if np.any(Wn[:, j]))
    feas = mc["feasible"].astype(bool)
    score = np.where(feas | (np.arange(steps + 1)[None, :] == 0), tc, np.inf)
    score = np.where(np.isfinite(score), score, np.inf)
    pick = np.argmin(score, axis=1)
    rows = np.arange(n)
    after = cand[rows, pick]
    mb = {k: v[:, 0] for k, v in mc.items()}
    ma = {k: v[rows, pick] for k, v in mc.items()}
    tb, ta = tc[:, 0], tc[rows, pick]
    accepted = (pick > 0) & (ta < tb) & ma["feasible"].astype(bool)
    s_after = np.asarray(jax.jit(jax.vmap(loss))(jnp.asarray(after), W))
    return RefineResult(genes_before=np.array(genes), genes_after=np.array(after), true_before=tb, true_after=ta,
                        surrogate_before=np.array(s_before), surrogate_after=np.array(s_after),
                        metrics_before=mb, metrics_after=ma, accepted=np.array(accepted),
                        loss_history=np.array(hist))
