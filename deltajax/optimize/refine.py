"""Gradient refinement with optax on a differentiable relaxation, verified on the true objective.

The true fitness is piecewise constant in the design (a workspace volume counts grid cells; coverage counts
task points; the operating R is an argmin), so its gradient is useless. :func:`evaluate_design` with
``smooth=tau`` replaces each indicator by a sigmoid of a signed margin (IK discriminant and joint-limit
margins for workspace membership, index minus threshold for coverage) and the argmin by softmin weights;
torque, speed and indices are already differentiable almost everywhere. Adam (optax) descends that
surrogate in gene space, projected onto the box [0, 1]^d after each step (``optax.projections``), for all
designs at once (vmapped, one ``lax.scan``).

Every refined design is then re-evaluated with the **true** metrics; :class:`RefineResult` reports before and
after for each design, and ``accepted`` marks those whose true objective improved (and stayed feasible): only
those replace their starting design.
"""

from __future__ import annotations

import dataclasses
from typing import Callable, Mapping, Optional

import jax
import jax.numpy as jnp
import numpy as np

from .objectives import SENSE, Problem, evaluate_design, fitness_from_metrics

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


def _objective(pb: Problem, m, direction: Optional[Mapping[str, float]]):
    """Weighted fitness (``direction=None``) or a direction sum of normalised, minimised objectives."""
    if direction is None:
        return fitness_from_metrics(pb, m)
    f = 0.0
    for name, wgt in direction.items():
        f = f + wgt * SENSE[name] * m[name] / abs(pb.baseline[name])
    return f


def surrogate_loss(pb: Problem, space, genes, *, tau: float, direction=None, penalty: float = 10.0):
    """Relaxed objective of one gene vector: the relaxed weighted objective plus ``penalty`` x the relaxed
    constraint violation (a smooth exterior penalty; feasibility-first needs a step function)."""
    m = evaluate_design(pb, space.decode(genes), smooth=tau)
    if direction is None:
        f = 0.0
        for name, wgt in pb.weights.items():
            f = f + wgt * SENSE[name] * m[name] / abs(pb.baseline[name])
    else:
        f = _objective(pb, m, direction)
    return f + penalty * m["violation"]


def refine(pb: Problem, space, genes: np.ndarray, *, steps: int = 30, learning_rate: float = 0.01,
           tau: float = 0.05, direction: Optional[Mapping[str, float]] = None, penalty: float = 10.0,
           true_fn: Optional[Callable] = None) -> RefineResult:
    """Refine designs by projected Adam on the relaxed objective; verify on the true one.

    Args:
        pb: problem (with baseline set).
        space: design space.
        genes: (n, d) starting genes in [0, 1].
        steps: Adam steps.
        learning_rate: Adam step size in gene units.
        tau: relaxation temperature (see :func:`deltajax.optimize.evaluate_design`).
        direction: ``None`` refines the GA's weighted fitness; a mapping ``{metric: weight}`` refines the
            weighted sum of those normalised objectives instead (used for Pareto points).
        penalty: weight of the relaxed constraint violation.
        true_fn: optional jitted ``genes (n, d) -> metrics`` (reuses a compiled evaluator).

    Returns:
        :class:`RefineResult`.
    """
    import optax
    from optax import projections

    genes = jnp.asarray(np.clip(np.asarray(genes, float), 0.0, 1.0))
    opt = optax.adam(learning_rate)
    loss = lambda g: surrogate_loss(pb, space, g, tau=tau, direction=direction, penalty=penalty)  # noqa: E731
    vg = jax.value_and_grad(loss)

    @jax.jit
    def descend(g0):
        def one(g0):
            def body(carry, _):
                g, st = carry
                val, grad = vg(g)
                grad = jnp.where(jnp.isfinite(grad), grad, 0.0)
                upd, st = opt.update(grad, st, g)
                g = projections.projection_box(optax.apply_updates(g, upd), 0.0, 1.0)
                return (g, st), val
            (g, _), hist = jax.lax.scan(body, (g0, opt.init(g0)), None, length=steps)
            return g, hist, loss(g0), loss(g)
        return jax.vmap(one)(g0)

    after, hist, s_before, s_after = descend(genes)
    if true_fn is None:
        true_fn = jax.jit(lambda G: jax.vmap(lambda g: evaluate_design(pb, space.decode(g)))(G))
    mb = {k: np.asarray(v) for k, v in true_fn(genes).items()}
    ma = {k: np.asarray(v) for k, v in true_fn(after).items()}
    tb = np.asarray(jax.vmap(lambda i: _objective(pb, {k: jnp.asarray(v)[i] for k, v in mb.items()}, direction))(
        jnp.arange(len(genes))))
    ta = np.asarray(jax.vmap(lambda i: _objective(pb, {k: jnp.asarray(v)[i] for k, v in ma.items()}, direction))(
        jnp.arange(len(genes))))
    accepted = (ta < tb) & ma["feasible"].astype(bool)
    return RefineResult(genes_before=np.asarray(genes), genes_after=np.asarray(after), true_before=tb,
                        true_after=ta, surrogate_before=np.asarray(s_before), surrogate_after=np.asarray(s_after),
                        metrics_before=mb, metrics_after=ma, accepted=accepted, loss_history=np.asarray(hist).T)
