"""GA-fitness benchmark (issue 9): population 256 of the weighted-sum ``ga_reconfig`` problem of 2026-12-01
(``experiments/bench_fitness_problem.yaml``, :class:`deltajax.optimize.Problem`), split by term,
new core kernel vs the frozen pre-issue-9 kernel (:mod:`deltajax.baseline_kernel`) in the same
process; fitness values must agree to 1e-12.

    python experiments/bench_fitness.py [--population 256] [--repeats 3]

Prints, per metric term and for the whole fitness: warm CPU-s and wall per population evaluation, old and
new, and the speed-up (CPU-s ratio). Record ``uptime`` next to the figures (shared machine).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from omegaconf import OmegaConf  # noqa: E402

import deltajax as dj  # noqa: E402
from deltajax import baseline_kernel as _kernel_baseline  # noqa: E402
from deltajax.optimize import DesignSpace, Problem, evaluate_design, make_fitness  # noqa: E402

#: the main job's problem before it became the designer's problem (issue 12): the kernel's baseline workload
CONFIG = Path(__file__).resolve().parent / "bench_fitness_problem.yaml"


def _timed(fn, arg, repeats):
    jax.block_until_ready(fn(arg))
    best = (np.inf, np.inf)
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        jax.block_until_ready(fn(arg))
        w, c = time.perf_counter() - t0, time.process_time() - c0
        best = min(best, (c, w))
    return best


def problem():
    """(space, problem with baseline) of the benchmark's weighted-sum problem on franco2026 (with masses)."""
    e = OmegaConf.to_container(OmegaConf.load(CONFIG)["experiment"], resolve=True)
    recon = dj.presets.franco2026(with_mass=True)
    space = DesignSpace.from_bounds(recon, e["design"]["bounds"], n_R=e["design"]["n_R"],
                                    prefix="experiment.design.bounds")
    ws = dict(e["workspace"])
    hi = {n: space._range(n)[1] for n in ("R_max", "upper_arm", "forearm")}
    r_max = ws.pop("r_max", None) or hi["R_max"] - space._range("platform_radius")[0] + hi["upper_arm"] + hi["forearm"]
    z_max = ws.pop("z_max", None) or hi["upper_arm"] + hi["forearm"]
    pb = Problem.from_config({**e, "workspace": ws}, r_max=float(r_max), z_max=float(z_max))
    base = jax.jit(lambda g: evaluate_design(pb, space.decode(g)))(jnp.asarray(space.baseline_genes()))
    return space, pb.with_baseline({k: float(v) for k, v in base.items()})


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--population", type=int, default=256)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args(argv)
    space, pb = problem()
    genes = jax.random.uniform(jax.random.PRNGKey(0), (a.population, space.dim), dtype=jnp.float64)
    terms = sorted(pb.needed | {"peak_torque"})

    def build_fns():
        fns = {t: jax.jit(jax.vmap(lambda g, t=t: evaluate_design(pb, space.decode(g), (t,))[t])) for t in terms}
        fns["fitness (all terms)"] = jax.jit(lambda G: make_fitness(pb, space)(G)[0])
        return fns

    new = build_fns()
    with _kernel_baseline.patch_old_kernel():
        old = build_fns()
        f_old = np.asarray(old["fitness (all terms)"](genes))  # traced inside the patch
        for f in old.values():
            jax.block_until_ready(f(genes))
    f_new = np.asarray(new["fitness (all terms)"](genes))
    both = np.isfinite(f_old) & np.isfinite(f_new)
    diff = float(np.max(np.abs(f_old[both] - f_new[both]))) if both.any() else 0.0
    print(f"population {a.population}, terms {terms}; load {os.getloadavg()[0]:.1f}")
    print(f"fitness old vs new: max |diff| {diff:.2e} (must be <= 1e-12), NaN pattern "
          f"{'identical' if np.array_equal(np.isnan(f_old), np.isnan(f_new)) else 'DIFFERENT'}")
    print(f"{'term':24s} {'old CPU-s':>10s} {'new CPU-s':>10s} {'old wall':>9s} {'new wall':>9s}  speed-up (CPU)")
    for name in new:
        co, wo = _timed(old[name], genes, a.repeats)
        cn, wn = _timed(new[name], genes, a.repeats)
        print(f"{name:24s} {co:10.4f} {cn:10.4f} {wo:9.4f} {wn:9.4f}  x{co / max(cn, 1e-9):.2f}")
    if not diff <= 1e-12:
        raise SystemExit(f"fitness values differ by {diff:.2e} > 1e-12")


if __name__ == "__main__":
    main()
