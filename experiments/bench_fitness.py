"""GA-fitness benchmark (issue 9): population 256 of the weighted-sum ``ga_reconfig`` problem of 2026-12-01
(``experiments/bench_fitness_problem.yaml``, :class:`deltajax.optimize.Problem`), split by term,
new core kernel vs the frozen pre-issue-9 kernel (:mod:`deltajax.benchmarks.frozen_kernel`) in the same
process; fitness values must agree to 1e-12.

    python experiments/bench_fitness.py [--population 256] [--repeats 3]

Prints, per metric term and for the whole fitness: warm CPU-s and wall per population evaluation, old and
new, and the speed-up (CPU-s ratio). Record ``uptime`` next to the figures (shared machine).

old: the frozen kernel with the per-design R sweeps (``screen=False``) and the frozen peak-speed term
(the fitness as it was); new: the core kernel with the population-level task coverage and reachability
(:func:`deltajax.optimize.screens.task_cover`, :func:`~deltajax.optimize.screens.reach_cover`) and the
flat peak-speed term. The middle column ("new exact") is the core kernel with the per-design sweeps
(``screen=False``), to separate the kernel's share from the screens'. Exits non-zero unless the fitness
values agree to 1e-12 (absolute; they are O(1) or 1e3 + violation), the NaN patterns are identical and the
task coverage and volume are identical. Also prints how many exact evaluations the screens ran.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from omegaconf import OmegaConf  # noqa: E402

import deltajax as dj  # noqa: E402
from deltajax.benchmarks import frozen_kernel as _kernel_baseline  # noqa: E402
from deltajax.optimize import DesignSpace, Problem, evaluate_design, evaluate_population, make_fitness  # noqa: E402
from deltajax.optimize import objectives as _objectives  # noqa: E402
from deltajax.optimize.screens import TASK_CHUNK, reach_cover, task_cover  # noqa: E402

#: the main job's problem before it became the designer's problem (issue 12): the kernel's baseline workload
CONFIG = Path(__file__).resolve().parent / "bench_fitness_problem.yaml"


def _old_ee_speed(robot, pts, motor_speed):
    """Frozen copy of ``objectives._ee_speed`` before 2026-12-01 (ik with its atan2, cos/sin of theta again,
    a batched LAPACK solve per point): the baseline side of the peak_speed term."""
    from deltajax.jacobian import jacobian
    from deltajax.kinematics import ik
    from deltajax.optimize.objectives import speed_vertices

    def one(p):
        sol = ik(robot, p)
        theta = jnp.where(sol.ok, sol.theta, 0.0)
        J = jacobian(robot, p, theta)[:, 1:]
        v = jnp.asarray(speed_vertices, J.dtype) @ J.T
        return jnp.max(jnp.sqrt(jnp.sum(v * v, axis=-1))) * motor_speed, sol.ok
    s, ok = jax.vmap(one)(pts)
    n = jnp.sum(ok)
    return jnp.where(n > 0, jnp.sum(jnp.where(ok, s, 0.0)) / jnp.maximum(n, 1), 0.0)


@contextlib.contextmanager
def _old_fitness():
    """The fitness as it was: the frozen kernel (:func:`deltajax.benchmarks.frozen_kernel.patch_old_kernel`) and the
    frozen peak-speed term; the per-design sweeps are selected by ``screen=False``. Must wrap tracing."""
    saved = _objectives._ee_speed
    try:
        _objectives._ee_speed = _old_ee_speed
        with _kernel_baseline.patch_old_kernel():
            yield
    finally:
        _objectives._ee_speed = saved


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

    def build_fns(screen):
        fns = {t: jax.jit(lambda G, t=t: evaluate_population(pb, space, G, (t,), screen=screen)[t])
               for t in terms}
        fns["fitness (all terms)"] = jax.jit(lambda G: make_fitness(pb, space, screen=screen)(G)[0])
        return fns

    new, new_exact = build_fns(True), build_fns(False)
    with _old_fitness():
        old = build_fns(False)
        f_old = np.asarray(old["fitness (all terms)"](genes))  # traced inside the patch
        cov_old = np.asarray(old["task_coverage"](genes))
        vol_old = np.asarray(old["volume"](genes))
        for f in old.values():
            jax.block_until_ready(f(genes))
    f_new = np.asarray(new["fitness (all terms)"](genes))
    cov_new = np.asarray(new["task_coverage"](genes))
    vol_new = np.asarray(new["volume"](genes))
    both = np.isfinite(f_old) & np.isfinite(f_new)
    diff = float(np.max(np.abs(f_old[both] - f_new[both]))) if both.any() else 0.0
    same_nan = np.array_equal(np.isnan(f_old), np.isnan(f_new))
    same_cov = np.array_equal(cov_old, cov_new) and np.array_equal(vol_old, vol_new)
    cover = jax.jit(lambda G: task_cover(pb, jax.vmap(space.decode)(G)))(genes)
    reach = jax.jit(lambda G: reach_cover(jax.vmap(space.decode)(G), pb.ws_points))(genes)
    print(f"population {a.population}, terms {terms}; load {os.getloadavg()[0]:.1f}")
    print(f"fitness old vs new: max |diff| {diff:.2e} (must be <= 1e-12), NaN pattern "
          f"{'identical' if same_nan else 'DIFFERENT'}; task coverage and volume "
          f"{'identical' if same_cov else 'DIFFERENT'}")
    print(f"task_cover: exact evaluations {int(cover.n_first)} (first pass) + {int(cover.n_rest)} (rest of the "
          f"uncovered points) = {int(cover.n_first) + int(cover.n_rest)} of the sweep's {cover.n_sweep} "
          f"({(int(cover.n_first) + int(cover.n_rest)) / cover.n_sweep:.1%}); chunks of {TASK_CHUNK}: "
          f"{-(-int(cover.n_rest) // TASK_CHUNK)}")
    n_pairs = reach.reachable.size
    print(f"reach_cover: of {n_pairs} (design, point) pairs {int(reach.n_excluded)} excluded by the closed form, "
          f"{n_pairs - int(reach.n_excluded)} one IK sample, {int(reach.n_rest)} swept: "
          f"{n_pairs - int(reach.n_excluded) + int(reach.n_rest) * space.n_R} IK evaluations of the sweep's "
          f"{reach.n_sweep} ({(n_pairs - int(reach.n_excluded) + int(reach.n_rest) * space.n_R) / reach.n_sweep:.1%})")
    print(f"{'term':24s} {'old CPU-s':>10s} {'new exact':>10s} {'new CPU-s':>10s} {'old wall':>9s} {'new wall':>9s}"
          f"  speed-up CPU (wall)")
    for name in new:
        co, wo = _timed(old[name], genes, a.repeats)
        ce, _ = _timed(new_exact[name], genes, a.repeats)
        cn, wn = _timed(new[name], genes, a.repeats)
        print(f"{name:24s} {co:10.4f} {ce:10.4f} {cn:10.4f} {wo:9.4f} {wn:9.4f}  x{co / max(cn, 1e-9):.2f} "
              f"(x{wo / max(wn, 1e-9):.2f})")
    if not (same_nan and same_cov):
        raise SystemExit("NaN pattern, task coverage or volume differ between old and new")
    if not diff <= 1e-12:
        raise SystemExit(f"fitness values differ by {diff:.2e} > 1e-12")


if __name__ == "__main__":
    main()
