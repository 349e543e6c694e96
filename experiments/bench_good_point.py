"""Cost of the good-point test and of the designer's search evaluator, as ratios to the index kernel alone.

    python experiments/bench_good_point.py                 # default main-job problem (experiment=ga_reconfig)
    python experiments/bench_good_point.py --reps 7 --designs 64

On a shared machine absolute times drift with the load; the ratios against a baseline measured in the same
process, interleaved with the measured programs, do not. Programs measured (each jitted, compiled before timing):

* ``kernel``: ``jax.vmap(point_indices)`` (the IK and every index, no constraint) over the job's regular-workspace
  grid, task cylinder and cycle samples at every R of the baseline design: the same (R, point) pairs the search
  evaluator tests;
* ``good_point``: :func:`deltajax.constraints.good_point` over the same pairs (IK, index, passive joints, links);
* ``good_decided``: :func:`deltajax.constraints.good_point_decided` (the ray searches' test) over the same pairs;
* ``evaluator`` / ``evaluator_cheap``: the search evaluator (:func:`deltajax.optimize.workflow.batch_evaluator`)
  on ``--designs`` Sobol designs, with and without the regular workspace (the NSGA-II stage and the screen).

For each: CPU-seconds and wall per call (median over ``--reps`` interleaved rounds), and the ratio to ``kernel``;
plus the number of HLO instructions of the optimised good-point program (one point) as a size figure, and the
kernels (fusions) of the two batched good-test programs with how many of them XLA:CPU runs as library calls. Runs at
any commit that has these functions (it was used to compare the main job before and after the exact plate
clearance; docs/BENCHMARKS.md).
"""

from __future__ import annotations

import argparse
import os
import resource
import time

import numpy as np


def _cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _timed(fn, *args):
    c0, t0 = _cpu(), time.perf_counter()
    out = fn(*args)
    import jax

    jax.block_until_ready(out)
    return _cpu() - c0, time.perf_counter() - t0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reps", type=int, default=5, help="interleaved rounds (median reported)")
    ap.add_argument("--designs", type=int, default=32, help="designs per evaluator call")
    ap.add_argument("--no-evaluator", action="store_true", help="only the point programs")
    args = ap.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    from hydra import compose, initialize_config_dir
    from scipy.stats import qmc

    from deltajax import constraints as C
    from deltajax.config import ga_reconfig_build, robot_from_config
    from deltajax.indices import point_indices
    from deltajax.optimize.workflow import batch_evaluator
    from deltajax.run import CONFIG_DIR

    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(config_name="config", overrides=["experiment=ga_reconfig"])
    robot, recon = robot_from_config(cfg.robot)
    s, space, pb, _ = ga_reconfig_build(cfg.experiment, robot, recon)
    design = space.decode(jnp.asarray(space.baseline_genes()))
    Rs = jnp.concatenate([design.R_samples(), jnp.linspace(design.R_min, design.R_max, pb.n_R_operating)])
    pts = jnp.concatenate([jnp.asarray(pb.rw_points).reshape(-1, 3), jnp.asarray(pb.task_points),
                           jnp.asarray(pb.cycle.x)])
    plate = design.R_max + pb.links.plate_overhang
    n_pairs = int(Rs.shape[0] * pts.shape[0])

    def over_pairs(one):
        return jax.jit(lambda d, P: jax.vmap(lambda R: jax.vmap(lambda p: one(d.at(R), p))(P))(Rs))

    kernel = over_pairs(lambda r, p: point_indices(r, p, beta=pb.good.beta)[1].k_tilde)
    good = over_pairs(lambda r, p: C.good_point(r, p, pb.good, plate_radius=plate))
    decided = over_pairs(lambda r, p: C.good_point_decided(r, p, pb.good, plate_radius=plate))
    progs = {"kernel": (kernel, (design, pts)), "good_point": (good, (design, pts)),
             "good_decided": (decided, (design, pts))}
    if not args.no_evaluator:
        X = qmc.Sobol(d=space.dim, scramble=True, seed=7).random(args.designs)
        progs["evaluator"] = (batch_evaluator(pb, space, args.designs), (X,))
        progs["evaluator_cheap"] = (batch_evaluator(pb, space, args.designs, regular=False), (X,))

    compile_cost = {}
    for name, (f, a) in progs.items():
        compile_cost[name] = _timed(f, *a)
    one = jax.jit(lambda p: C.good_point(design.at(Rs[0]), p, pb.good, plate_radius=plate))
    hlo = one.lower(pts[0]).compile().as_text()
    n_hlo = sum(1 for line in hlo.splitlines() if " = " in line and not line.lstrip().startswith("//"))
    kernels = {}  # the batched programs' kernels (fusions), and how many of them are library calls (YNNPACK)
    for name in ("good_point", "good_decided"):
        text = progs[name][0].lower(*progs[name][1]).compile().as_text()
        kernels[name] = (text.count(" fusion("), text.count('"__ynn_fusion"'))

    rows = {k: [] for k in progs}
    for _ in range(args.reps):
        for name, (f, a) in progs.items():
            rows[name].append(_timed(f, *a))
    med = {k: np.median(np.asarray(v), axis=0) for k, v in rows.items()}
    print(f"deltajax {__import__('deltajax').__file__}; load {os.getloadavg()[0]:.1f}; "
          f"{n_pairs} (R, point) pairs; {args.designs} designs per evaluator call; median of {args.reps}")
    print(f"{'program':18s} {'CPU-s':>9s} {'wall s':>9s} {'x kernel CPU':>13s} {'x kernel wall':>14s}  first call")
    kc, kw = med["kernel"]
    for name, (c, w) in med.items():
        per = f"  ({c / n_pairs * 1e9:.0f} CPU-ns/pair)" if name in ("kernel", "good_point", "good_decided") else \
            f"  ({c / args.designs * 1e3:.1f} CPU-ms/design)"
        print(f"{name:18s} {c:9.4f} {w:9.4f} {c / kc:13.2f} {w / kw:14.2f}  {compile_cost[name][0]:.1f} CPU-s{per}")
    print(f"good_point optimised HLO instructions (one point): {n_hlo}")
    for name, (nk, ny) in kernels.items():
        print(f"{name} batched program: {nk} kernels (fusions), {ny} of them library calls (YNNPACK)")
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20:.2f} GB")


if __name__ == "__main__":
    main()
