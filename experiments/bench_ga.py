"""Benchmark of the design optimiser: design evaluations per second and a full GA run, on the main job's problem.

    python experiments/bench_ga.py                                  # defaults below
    python experiments/bench_ga.py --population 256 --generations 200 --out bench_ga.h5

Measures, in one process (compile time reported separately from warm time):

1. *Kernel throughput*: one population of reconfigurable designs evaluated on the regular-workspace search grid:
   designs x grid points x R samples (IK within joint limits) per second, and the same for the fixed-R
   reachability (designs x points) as the in-process baseline (ratio printed).
2. *Design throughput* of the main job's GA fitness (:func:`deltajax.optimize.workflow.ga_fitness` of the
   default ``experiment=ga_reconfig`` problem on its search grids: picks/min with every constraint, feasibility
   first; ``--regular`` adds the regular workspace, the NSGA-II evaluator's extra cost): designs per second.
3. *A full GA run*: population x generations with that fitness (``run_ga``; checkpoints off), wall time
   including compilation, and warm time of a second identical run (compiled chunks are cached).

Writes the numbers to an HDF5 file (group ``bench``) when ``--out`` is given.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from deltajax.optimize import GAConfig, run_ga  # noqa: E402
from deltajax.workspace import reachable_mask, reconfigurable_reachable  # noqa: E402


def designer_problem(n_R: int):
    """(settings, design space, search problem) of the default main job with ``n_R`` R samples per design."""
    from hydra import compose, initialize_config_dir

    from deltajax.config import ga_reconfig_build, robot_from_config
    from deltajax.run import CONFIG_DIR

    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(config_name="config", overrides=["experiment=ga_reconfig", f"experiment.design.n_R={n_R}"])
    robot, recon = robot_from_config(cfg.robot)
    s, space, pb, _ = ga_reconfig_build(cfg.experiment, robot, recon)
    return s, space, pb


def timed(fn, *args, repeat=3):
    t0 = time.perf_counter()
    jax.block_until_ready(fn(*args))
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    for _ in range(repeat):
        jax.block_until_ready(fn(*args))
    return first, (time.perf_counter() - t0) / repeat


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--population", type=int, default=256)
    ap.add_argument("--generations", type=int, default=200)
    ap.add_argument("--n-R", type=int, default=8, help="R samples per design (the main job: 8)")
    ap.add_argument("--regular", action="store_true", help="the fitness with the regular workspace (all objectives)")
    ap.add_argument("--checkpoint-every", type=int, default=50)
    ap.add_argument("--skip-run", action="store_true", help="only the throughput measurements")
    ap.add_argument("--out", default=None, help="write results to this HDF5 file (group bench)")
    a = ap.parse_args(argv)

    from deltajax.optimize.designer import DESIGN_SENSE
    from deltajax.optimize.workflow import batch_evaluator, ga_fitness

    s_, space, pb = designer_problem(a.n_R)
    P = a.population
    pts = jnp.asarray(pb.rw_points).reshape(-1, 3)
    N = int(pts.shape[0])
    genes = jax.random.uniform(jax.random.PRNGKey(0), (P, space.dim))
    designs = jax.vmap(space.decode)(genes)
    out = {}
    print(f"device: {jax.devices()[0]} x{jax.device_count()}, population {P}, {N} regular-workspace grid points, "
          f"n_R {a.n_R}, {len(pb.task_points)} task samples, {pb.cycle.n_samples} cycle samples")

    # 1. kernel throughput: reconfigurable reachability vs the fixed-R baseline
    f_fixed = jax.jit(jax.vmap(lambda d: jnp.sum(reachable_mask(d.robot, pts))))
    f_recon = jax.jit(jax.vmap(lambda d: jnp.sum(reconfigurable_reachable(d, pts))))
    c_fixed, w_fixed = timed(f_fixed, designs)
    c_recon, w_recon = timed(f_recon, designs)
    ev_fixed = P * N / w_fixed
    ev_recon = P * N * a.n_R / w_recon
    print(f"fixed-R volume:          {ev_fixed / 1e6:8.2f} M (design x point) evals/s  (compile {c_fixed:.1f} s)")
    print(f"reconfigurable volume:   {ev_recon / 1e6:8.2f} M (design x point x R) evals/s  (compile {c_recon:.1f} s)"
          f"  ratio to fixed-R: {ev_recon / ev_fixed:.2f}")
    out.update(evals_per_s_fixed=ev_fixed, evals_per_s_reconfigurable=ev_recon, compile_s_fixed=c_fixed,
               compile_s_reconfigurable=c_recon)

    # 2. design throughput of the main job's GA fitness (picks/min, feasibility first)
    objs = list(s_.objectives) if a.regular else [s_.primary]
    base = {k: v[0] for k, v in batch_evaluator(pb, space, 2)(space.baseline_genes()[None]).items()}
    scale = np.asarray([DESIGN_SENSE[o] / abs(float(base[o])) for o in objs])
    fit = ga_fitness(pb, space, objs, scale)
    c_fit, w_fit = timed(jax.jit(fit), genes)
    what = " + ".join(objs)
    print(f"GA fitness ({what}, every constraint): {P / w_fit:8.1f} designs/s "
          f"({w_fit * 1e3:.1f} ms per population; compile {c_fit:.1f} s)")
    out.update(designs_per_s_fitness=P / w_fit, compile_s_fitness=c_fit)

    # 3. the full GA run
    if not a.skip_run:
        ga = GAConfig(algorithm="simple_ga", population_size=P, generations=a.generations,
                      checkpoint_every=a.checkpoint_every, sigma=0.08, seed=0)
        t0 = time.perf_counter()
        r1 = run_ga(fit, space.dim, ga, init_genes=space.baseline_genes())
        cold = time.perf_counter() - t0
        t0 = time.perf_counter()
        r2 = run_ga(fit, space.dim, ga, init_genes=space.baseline_genes())
        warm = time.perf_counter() - t0
        assert np.array_equal(r1.best_genes, r2.best_genes)
        n_designs = P * (a.generations + 1)
        print(f"GA run {P} x {a.generations}: {cold:.1f} s including compilation, {warm:.1f} s warm "
              f"({n_designs / warm:.0f} designs/s); best fitness {r1.best_fitness:.4f} (the baseline's is -1 "
              "by construction when feasible)")
        out.update(ga_run_cold_s=cold, ga_run_warm_s=warm, ga_best_fitness=r1.best_fitness,
                   ga_population=P, ga_generations=a.generations)
    if a.out:
        from deltajax.io import ResultsFile

        res = ResultsFile(a.out, attrs={"benchmark": "bench_ga", "device": str(jax.devices()[0])})
        for k, v in out.items():
            unit = "1/s" if "per_s" in k else ("s" if k.endswith("_s") else "1")
            res.put("bench", k, v, units=unit)
        res.set_attrs("bench", population=P, rw_points=N, n_R=a.n_R, objectives=",".join(objs))
        res.flush(final=True)
        print(f"wrote {a.out}")
    return out


if __name__ == "__main__":
    main()
