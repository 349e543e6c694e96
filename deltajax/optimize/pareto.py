"""Multi-objective Pareto fronts: pymoo's NSGA-II (ask/tell) fed with JAX-batched evaluations.

evosax has no multi-objective algorithm, so we drive pymoo's maintained NSGA-II (Deb et al. 2002) through its
ask/tell interface: pymoo proposes a population in the unit box, our compiled, vmapped JAX function evaluates
it in one call (padded to a fixed batch so it compiles once), pymoo selects. Constraints go in as pymoo's
inequality constraints G <= 0 (its constrained domination: feasible first, then by violation), the same
feasibility-first rule as the single-objective GA. Validated on ZDT1 and ZDT2 against their known fronts
(tests).

Everything here is host-side NumPy (pymoo is NumPy); only ``eval_fn`` runs JAX.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Optional

import numpy as np
import jax
import jax.numpy as jnp

__all__ = ["ParetoResult", "nsga2", "hypervolume", "non_dominated", "zdt", "zdt_front", "padded_batch"]


@dataclasses.dataclass
class ParetoResult:
    """A Pareto front.

    Attributes:
        X: decision vectors of the non-dominated feasible designs (n, d) (genes in [0, 1]).
        F: their objective vectors (n, m) (all minimised).
        G: their constraint values (n, c) (<= 0: feasible), or an empty (n, 0) array.
        history_hv: hypervolume of the current front after each generation (``ref`` given) else empty.
        n_evals: number of evaluations.
        pop_X, pop_F, pop_G: the final population (feasible or not, dominated or not), e.g. to re-verify more
            candidates than the front on a finer model.
    """

    X: np.ndarray
    F: np.ndarray
    G: np.ndarray
    history_hv: np.ndarray
    n_evals: int
    pop_X: Optional[np.ndarray] = None
    pop_F: Optional[np.ndarray] = None
    pop_G: Optional[np.ndarray] = None


def hypervolume(F: np.ndarray, ref: np.ndarray) -> float:
    """Hypervolume dominated by the points ``F`` (minimisation) and bounded by ``ref`` (pymoo's exact HV).

    Points that do not strictly dominate ``ref`` contribute nothing.
    """
    from pymoo.indicators.hv import HV

    F = np.asarray(F, float).reshape(-1, len(ref))
    keep = np.all(F < np.asarray(ref), axis=1) & np.all(np.isfinite(F), axis=1)
    if not np.any(keep):
        return 0.0
    return float(HV(ref_point=np.asarray(ref, float))(F[keep]))


def non_dominated(F: np.ndarray) -> np.ndarray:
    """Indices of the non-dominated rows of ``F`` (minimisation)."""
    from pymoo.util.nds.non_dominated_sorting import NonDominatedSorting

    F = np.asarray(F, float)
    if len(F) == 0:
        return np.zeros((0,), int)
    return np.asarray(NonDominatedSorting().do(F, only_non_dominated_front=True), int)


def padded_batch(fn: Callable[[np.ndarray], Any], batch: int) -> Callable[[np.ndarray], Any]:
    """Wrap a jitted batch function so that it always sees ``batch`` rows (compile once), padding with the
    first row and cutting the outputs (a pytree of arrays with leading axis) back to the true size."""
    def call(X):
        X = np.asarray(X)
        n = len(X)
        outs = []
        for s in range(0, n, batch):
            part = X[s:s + batch]
            m = len(part)
            if m < batch:
                part = np.concatenate([part, np.repeat(part[:1], batch - m, axis=0)])
            out = fn(part)
            outs.append(jax.tree_util.tree_map(lambda a: np.asarray(a)[:m], out))
        return jax.tree_util.tree_map(lambda *a: np.concatenate(a), *outs)

    return call


def nsga2(eval_fn: Callable[[np.ndarray], tuple[np.ndarray, Optional[np.ndarray]]], n_var: int, n_obj: int, *,
          n_constr: int = 0, pop_size: int = 40, n_gen: int = 50, seed: int = 0,
          initial: Optional[np.ndarray] = None, ref: Optional[np.ndarray] = None,
          progress: Optional[Callable[[int], Any]] = None) -> ParetoResult:
    """NSGA-II over the unit box [0, 1]^n_var with pymoo's ask/tell.

    Args:
        eval_fn: ``X (n, n_var) -> (F (n, n_obj), G (n, n_constr) or None)``, all minimised, G <= 0 feasible.
        n_var, n_obj, n_constr: problem sizes.
        pop_size: population (and offspring) size.
        n_gen: generations.
        seed: pymoo's seed (NumPy RNG): the run is reproducible.
        initial: optional (k, n_var) designs to put into the initial population (e.g. the baseline, GA winners).
        ref: reference point for the hypervolume history (optional).
        progress: called with 1 after each generation.

    Returns:
        :class:`ParetoResult` with the feasible non-dominated set of the final population.
    """
    from pymoo.algorithms.moo.nsga2 import NSGA2
    from pymoo.core.evaluator import Evaluator
    from pymoo.core.problem import Problem
    from pymoo.operators.sampling.rnd import FloatRandomSampling
    from pymoo.problems.static import StaticProblem

    problem = Problem(n_var=n_var, n_obj=n_obj, n_ieq_constr=n_constr, xl=np.zeros(n_var), xu=np.ones(n_var))
    sampling: Any = FloatRandomSampling()
    if initial is not None:
        rng = np.random.default_rng(seed)
        init = np.clip(np.asarray(initial, float).reshape(-1, n_var), 0.0, 1.0)[:pop_size]
        rest = rng.random((pop_size - len(init), n_var))
        sampling = np.concatenate([init, rest])
    algorithm = NSGA2(pop_size=pop_size, sampling=sampling, eliminate_duplicates=True)
    algorithm.setup(problem, termination=("n_gen", n_gen), seed=seed, verbose=False)
    hv_hist = []
    n_evals = 0
    while algorithm.has_next():
        pop = algorithm.ask()
        X = pop.get("X")
        F, G = eval_fn(X)
        F = np.asarray(F, float).reshape(len(X), n_obj)
        F = np.where(np.isfinite(F), F, 1e12)
        kw = {"F": F}
        if n_constr:
            kw["G"] = np.asarray(G, float).reshape(len(X), n_constr)
        Evaluator().eval(StaticProblem(problem, **kw), pop)
        algorithm.tell(infills=pop)
        n_evals += len(X)
        if ref is not None:
            opt = algorithm.opt
            Fo = opt.get("F") if opt is not None and len(opt) else np.zeros((0, n_obj))
            if n_constr and opt is not None and len(opt):
                Fo = Fo[np.all(opt.get("G") <= 0, axis=1)]
            hv_hist.append(hypervolume(Fo, np.asarray(ref)))
        if progress is not None:
            progress(1)
    opt = algorithm.opt
    X, F = opt.get("X"), opt.get("F")
    G = opt.get("G") if n_constr else np.zeros((len(X), 0))
    if n_constr:
        feas = np.all(G <= 0, axis=1)
        X, F, G = X[feas], F[feas], G[feas]
    order = np.lexsort(F.T[::-1]) if len(F) else np.zeros((0,), int)
    pop = algorithm.pop
    pG = pop.get("G") if n_constr else np.zeros((len(pop), 0))
    return ParetoResult(X=X[order], F=F[order], G=G[order], history_hv=np.asarray(hv_hist), n_evals=n_evals,
                        pop_X=np.asarray(pop.get("X")), pop_F=np.asarray(pop.get("F")), pop_G=np.asarray(pG))


# -- ZDT test problems (Zitzler, Deb, Thiele 2000), in JAX, for validation -----------------------------------

def zdt(name: str):
    """The ZDT1 / ZDT2 objective function ``x (n, d) in [0,1]^d -> F (n, 2)`` (JAX, vmapped)."""
    if name not in ("zdt1", "zdt2"):
        raise ValueError(f"zdt name must be 'zdt1' or 'zdt2', got {name!r}")

    def f(x):
        x = jnp.asarray(x)
        f1 = x[:, 0]
        g = 1.0 + 9.0 * jnp.mean(x[:, 1:], axis=1)
        h = 1.0 - jnp.sqrt(f1 / g) if name == "zdt1" else 1.0 - (f1 / g) ** 2
        return jnp.stack([f1, g * h], axis=1)

    return f


def zdt_front(name: str, n: int = 2001) -> np.ndarray:
    """The analytic Pareto front of ZDT1 (f2 = 1 - sqrt f1) or ZDT2 (f2 = 1 - f1^2), f1 in [0, 1]."""
    f1 = np.linspace(0.0, 1.0, n)
    f2 = 1.0 - np.sqrt(f1) if name == "zdt1" else 1.0 - f1 ** 2
    return np.stack([f1, f2], axis=1)
