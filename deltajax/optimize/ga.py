"""Single-objective GA with evosax: compiled generation loop, checkpoints, bit-identical resume.

The loop is ``jax.lax.scan`` over a *chunk* of generations (ask -> repair -> evaluate -> tell); between
chunks the host writes a checkpoint (optimiser state, PRNG key, history so far). Chunk boundaries are fixed
multiples of ``checkpoint_every`` counted from generation 0, so an uninterrupted run and a run that was
killed and resumed execute the very same compiled chunks on the very same inputs, and end bit-identical
(tested). Carries cross the host at every boundary in both cases (NumPy round trip), so the resumed run does
not even differ in weak-type flags.

evosax minimises; NaN fitness means a failed evaluation. Genes are normalised to [0, 1] and repaired by
reflection (:func:`deltajax.optimize.design.reflect_unit`) before evaluation *and* before ``tell``, so the
optimiser's population never leaves the box.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, Callable, Mapping, Optional

import jax
import jax.numpy as jnp
import numpy as np

from .design import reflect_unit
from ..tracing import persistent

__all__ = ["GAConfig", "GAResult", "ALGORITHMS", "make_strategy", "run_ga", "GAError", "state_to_arrays",
           "arrays_to_state"]

#: Selectable evosax GAs (name in config -> evosax class name).
ALGORITHMS = {
    "simple_ga": "SimpleGA",
    "mr15_ga": "MR15_GA",
    "samr_ga": "SAMR_GA",
    "gesmr_ga": "GESMR_GA",
    "de": "DifferentialEvolution",
}


class GAError(ValueError):
    """Invalid GA configuration or an unusable checkpoint (names the field / the mismatch)."""


@dataclasses.dataclass(frozen=True)
class GAConfig:
    """GA settings (all static).

    Attributes:
        algorithm: one of :data:`ALGORITHMS`.
        population_size: designs per generation.
        generations: number of generations (each evaluates one population).
        sigma: mutation std in gene units (genes live in [0, 1]; evosax's default of 1.0 would be a uniform
            restart).
        crossover_rate: SimpleGA's per-gene crossover probability.
        elite_ratio: fraction of the population that parents the next one (SimpleGA/MR15/SAMR/GESMR).
        checkpoint_every: generations per compiled chunk / between checkpoints.
        seed: PRNG seed.
        init: ``"uniform"`` (uniform in the box, member 0 = the given initial genes if any) or ``"around"``
            (normal around the initial genes with std ``sigma``).
    """

    algorithm: str = "simple_ga"
    population_size: int = 32
    generations: int = 40
    sigma: float = 0.1
    crossover_rate: float = 0.5
    elite_ratio: float = 0.25
    checkpoint_every: int = 10
    seed: int = 0
    init: str = "uniform"

    def validate(self, prefix: str = "GAConfig") -> "GAConfig":
        """Check the invariants (raises :class:`GAError` naming ``<prefix>.<field>`` and the value); returns self."""
        if self.algorithm not in ALGORITHMS:
            raise GAError(f"{prefix}.algorithm must be one of {sorted(ALGORITHMS)}, got {self.algorithm!r}")
        for name in ("population_size", "generations", "checkpoint_every"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise GAError(f"{prefix}.{name} must be an integer >= 1, got {v!r}")
        if self.population_size < 4:
            raise GAError(f"{prefix}.population_size must be >= 4, got {self.population_size}")
        if not (0.0 < float(self.sigma) <= 1.0):
            raise GAError(f"{prefix}.sigma (gene units, genes in [0,1]) must be in (0, 1], got {self.sigma!r}")
        if not (0.0 <= float(self.crossover_rate) <= 1.0):
            raise GAError(f"{prefix}.crossover_rate must be in [0, 1], got {self.crossover_rate!r}")
        if not (0.0 < float(self.elite_ratio) <= 1.0):
            raise GAError(f"{prefix}.elite_ratio must be in (0, 1], got {self.elite_ratio!r}")
        if self.init not in ("uniform", "around"):
            raise GAError(f"{prefix}.init must be 'uniform' or 'around', got {self.init!r}")
        if self.algorithm == "gesmr_ga" and (self.population_size - 1) % 4:
            raise GAError(f"{prefix}.population_size - 1 must be divisible by 4 for gesmr_ga (4 std groups), "
                          f"got {self.population_size}")
        return self


def make_strategy(cfg: GAConfig, num_dims: int):
    """The evosax strategy and its params for ``cfg`` (mutation std set to ``cfg.sigma``)."""
    import evosax.algorithms as ea
    import optax

    cls = getattr(ea, ALGORITHMS[cfg.algorithm])
    dummy = jnp.zeros((num_dims,))
    if cfg.algorithm == "simple_ga":
        strat = cls(population_size=cfg.population_size, solution=dummy,
                    std_schedule=optax.constant_schedule(float(cfg.sigma)))
        params = strat.default_params.replace(crossover_rate=float(cfg.crossover_rate))
    elif cfg.algorithm == "gesmr_ga":
        strat = cls(population_size=cfg.population_size, solution=dummy, num_groups=4)
        params = strat.default_params.replace(std_init=float(cfg.sigma), std_max=0.5)
    elif cfg.algorithm == "de":
        strat = cls(population_size=cfg.population_size, solution=dummy)
        params = strat.default_params
    else:
        strat = cls(population_size=cfg.population_size, solution=dummy)
        params = strat.default_params.replace(std_init=float(cfg.sigma), std_max=0.5)
    if hasattr(strat, "elite_ratio") and cfg.algorithm != "de":
        strat.elite_ratio = float(cfg.elite_ratio)
    return strat, params


@dataclasses.dataclass
class GAResult:
    """Outcome of :func:`run_ga` (host NumPy arrays).

    Attributes:
        best_genes: best (repaired) genes ever evaluated, (d,).
        best_fitness: its fitness (evosax minimises).
        history: per generation: ``best_fitness`` (best so far), ``gen_best_fitness``, ``gen_mean_fitness``
            (over finite values), ``gen_feasible_fraction``, ``gen_best_genes`` (G, d), plus every aux metric
            of the generation's best design (``aux/<name>``).
        generations_done: generations completed (< ``cfg.generations`` when stopped early).
        resumed_from: generation the run resumed from (0 for a fresh start).
        final_population: last evaluated population (P, d) and its fitness (P,).
    """

    best_genes: np.ndarray
    best_fitness: float
    history: dict[str, np.ndarray]
    generations_done: int
    resumed_from: int
    final_population: np.ndarray
    final_fitness: np.ndarray


def state_to_arrays(tree: Any) -> dict[str, np.ndarray]:
    """Flatten a pytree into ``{'leaf_000': array, ...}`` (host copies) for a checkpoint."""
    leaves = jax.tree_util.tree_leaves(tree)
    return {f"leaf_{i:03d}": np.asarray(x) for i, x in enumerate(leaves)}


def arrays_to_state(template: Any, arrays: Mapping[str, np.ndarray]) -> Any:
    """Inverse of :func:`state_to_arrays`, checking shapes and dtypes against a freshly built template."""
    leaves, treedef = jax.tree_util.tree_flatten(template)
    if len([k for k in arrays if k.startswith("leaf_")]) != len(leaves):
        raise GAError(f"checkpoint has {len(arrays)} state leaves, the optimiser has {len(leaves)}")
    out = []
    for i, ref in enumerate(leaves):
        a = np.asarray(arrays[f"leaf_{i:03d}"])
        if a.shape != tuple(ref.shape) or a.dtype != np.dtype(ref.dtype):
            raise GAError(f"checkpoint leaf {i} is {a.dtype}{a.shape}, expected {ref.dtype}{ref.shape}")
        out.append(jnp.asarray(a))
    return jax.tree_util.tree_unflatten(treedef, out)


def _host(tree):
    """NumPy round trip: identical carries (values, dtypes, weak types) on fresh and resumed paths."""
    return jax.tree_util.tree_map(lambda x: jnp.asarray(np.asarray(x)), tree)


@functools.lru_cache(maxsize=16)   # like deltajax.optimize.workflow's programs: bounded in a long process
def _engine(fitness_fn, d: int, cfg: GAConfig, program_key: Optional[str] = None):
    """Compiled init and chunk functions, cached per (fitness function, settings) so that repeated runs
    (resume, tests, sweeps in one process) reuse compilations. Seed and seed genes are arguments.
    ``program_key`` (the content of ``fitness_fn``): the programs are also kept across processes
    (:func:`deltajax.tracing.persistent`)."""
    strat, params = make_strategy(cfg, d)
    P = cfg.population_size

    def evaluate(genes):
        genes = jax.vmap(reflect_unit)(genes)
        fit, aux = fitness_fn(genes)
        fit = jnp.where(jnp.isfinite(fit), fit, jnp.nan)  # evosax: NaN = failed evaluation
        return genes, fit, aux

    @jax.jit
    def init_fn(key, seed_genes):
        # seed_genes (P, d): rows with every gene finite replace those members (NaN rows: no seed)
        k_init, k_pop, k_run = jax.random.split(key, 3)
        has_seed = jnp.all(jnp.isfinite(seed_genes), axis=1)
        if cfg.init == "uniform":
            pop = jax.random.uniform(k_pop, (P, d))
        else:
            base = jnp.where(has_seed[0], seed_genes[0], 0.5)
            pop = base[None, :] + cfg.sigma * jax.random.normal(k_pop, (P, d))
        pop = jnp.where(has_seed[:, None], seed_genes, pop)
        pop, fit, aux = evaluate(pop)
        state = strat.init(k_init, pop, fit, params)
        return state, k_run, pop, fit

    def one_generation(carry, _):
        state, key = carry
        key, k_ask, k_tell = jax.random.split(key, 3)
        pop, state = strat.ask(k_ask, state, params)
        pop, fit, aux = evaluate(pop)
        state, _metrics = strat.tell(k_tell, pop, fit, state, params)
        safe = jnp.where(jnp.isnan(fit), jnp.inf, fit)
        i = jnp.argmin(safe)
        finite = jnp.isfinite(fit)
        feas = aux.get("feasible", finite)
        rec = {
            "best_fitness": state.best_fitness,
            "gen_best_fitness": safe[i],
            "gen_mean_fitness": jnp.sum(jnp.where(finite, fit, 0.0)) / jnp.maximum(jnp.sum(finite), 1),
            "gen_feasible_fraction": jnp.mean(feas.astype(fit.dtype)),
            "gen_best_genes": pop[i],
        }
        for k, v in aux.items():
            rec[f"aux/{k}"] = v[i]
        return (state, key), (rec, pop, fit)

    chunk_cache: dict[int, Callable] = {}
    kept = None if program_key is None else f"{program_key}|{cfg!r}|{d}"
    if kept is not None:
        init_fn = persistent(init_fn, "ga_init", kept)

    def chunk(n):
        if n not in chunk_cache:
            @jax.jit
            def run_chunk(state, key):
                (state, key), (recs, pops, fits) = jax.lax.scan(one_generation, (state, key), None, length=n)
                return state, key, recs, pops[-1], fits[-1]
            chunk_cache[n] = run_chunk if kept is None else persistent(run_chunk, "ga_chunk", f"{kept}|{n}")
        return chunk_cache[n]

    return init_fn, chunk


def run_ga(fitness_fn: Callable[[jax.Array], tuple[jax.Array, Mapping[str, jax.Array]]], num_dims: int,
           cfg: GAConfig, *, init_genes: Optional[np.ndarray] = None,
           checkpoint: Optional[Mapping[str, Any]] = None,
           save_checkpoint: Optional[Callable[[dict[str, Any]], None]] = None,
           stop_after: Optional[int] = None, progress: Optional[Callable[[int], Any]] = None, program_key: Optional[str] = None) -> GAResult:
    """Run (or resume) a GA.

    Args:
        fitness_fn: ``genes (P, d) in [0,1] -> (fitness (P,), aux {name: (P,)})``, jit-able; evosax minimises.
            ``aux`` must contain ``feasible`` (bool) for the feasible-fraction history (optional otherwise).
        num_dims: number of genes d.
        cfg: GA settings.
        init_genes: genes (d,) of a design to seed the initial population with (member 0), e.g. the baseline, or
            (k, d) designs for members 0..k-1 (e.g. the baseline and the best of a quasi-random screen).
        checkpoint: a previous checkpoint (as passed to ``save_checkpoint``) to resume from, of this very run: the
            caller owns its identity (the CLI's stage engine, :class:`deltajax.jobs.stages.Checkpoint`, refuses
            another run's); a state that does not fit these settings' optimiser is a :class:`GAError`.
        save_checkpoint: called on the host with a dict of NumPy arrays and attributes after every chunk.
        stop_after: stop (as if killed) after this many generations in total (for kill-and-resume tests).
        progress: called with the number of generations completed by each chunk (e.g. a tqdm ``update``).
        program_key: a string naming everything ``fitness_fn`` computes (e.g.
            :func:`deltajax.optimize.workflow.ga_fitness_key`): the GA's programs are then kept across processes
            (:func:`deltajax.tracing.persistent`), so a warm process does not trace the fitness again.

    Returns:
        :class:`GAResult`.
    """
    cfg.validate()
    G = cfg.generations
    init_fn, chunk = _engine(fitness_fn, num_dims, dataclasses.replace(cfg, seed=0, generations=1,
                                                                          checkpoint_every=1), program_key)
    seed_genes = np.full((cfg.population_size, num_dims), np.nan)
    if init_genes is not None:
        ig = np.asarray(init_genes, float).reshape(-1, num_dims)[:cfg.population_size]
        seed_genes[:len(ig)] = ig
    seed_genes = jnp.asarray(seed_genes)

    if checkpoint is not None:
        template_state, template_key, _, _ = jax.eval_shape(init_fn, jax.random.PRNGKey(cfg.seed), seed_genes)
        state = arrays_to_state(template_state, checkpoint["state"])
        key = jnp.asarray(np.asarray(checkpoint["key"]))
        history = {k: list(np.asarray(v)) for k, v in checkpoint["history"].items()}
        done = int(checkpoint["generations_done"])
        last_pop = np.asarray(checkpoint["population"])
        last_fit = np.asarray(checkpoint["fitness"])
        resumed_from = done
    else:
        state, key, pop0, fit0 = init_fn(jax.random.PRNGKey(cfg.seed), seed_genes)
        history, done, resumed_from = {}, 0, 0
        last_pop, last_fit = np.asarray(pop0), np.asarray(fit0)
    state, key = _host(state), _host(key)

    limit = G if stop_after is None else min(G, int(stop_after))
    while done < limit:
        n = min(cfg.checkpoint_every - done % cfg.checkpoint_every, G - done)
        state, key, recs, pop, fit = chunk(n)(state, key)
        state, key = _host(state), _host(key)
        for k, v in recs.items():
            history.setdefault(k, []).extend(list(np.asarray(v)))
        last_pop, last_fit = np.asarray(pop), np.asarray(fit)
        done += n
        if progress is not None:
            progress(n)
        if save_checkpoint is not None:
            save_checkpoint({
                "generations_done": done, "state": state_to_arrays(state),
                "key": np.asarray(key), "history": {k: np.asarray(v) for k, v in history.items()},
                "population": last_pop, "fitness": last_fit,
            })

    hist = {k: np.asarray(v) for k, v in history.items()}
    best_genes = np.asarray(state.best_solution)
    return GAResult(best_genes=best_genes, best_fitness=float(state.best_fitness), history=hist,
                    generations_done=done, resumed_from=resumed_from, final_population=last_pop,
                    final_fitness=last_fit)
