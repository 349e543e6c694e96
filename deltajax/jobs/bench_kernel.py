"""Kernel benchmark: IK + Jacobian + all indices, evaluations per CPU-second and per wall-second (warm).

Measured in the same process (ratios are what we report; absolute rates depend on the machine and its load):
(a) the new core kernel ``point_indices`` as one plain ``jit(vmap(...))`` (the whole kernel is one XLA:CPU loop,
:mod:`deltajax.fastmath`; fast closed form and exact Jacobi form) and in blocks
(:func:`deltajax.indices.map_points`, the previous form), f64 and f32; (b) the frozen pre-issue-9 kernel (:mod:`deltajax.benchmarks.frozen_kernel`, main 9f54c88) as the baseline; (c) the
independent NumPy reference (:mod:`deltajax.reference`); (d) Numba (exact kernel + minimal loop ceiling),
:func:`deltajax.benchmarks.numba_loops.bench_kernel_rates`.
Every JAX result is checked against the NumPy reference before timing; XLA fusion counts are printed.
"""

from __future__ import annotations

import math
import re
import time

import jax
import jax.numpy as jnp
import numpy as np

from .. import reference
from ..indices import map_points, point_indices
from ..benchmarks import frozen_kernel as _kernel_baseline
from ..plots import bench_rates_from_results

__all__ = ["run", "fusion_count"]


def _sample_points(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lo, hi = np.array([-0.35, -0.35, 0.05]), np.array([0.35, 0.35, 0.6])
    return lo + (hi - lo) * rng.random((n, 3))


def _timed(fn, repeats: int) -> tuple[float, float]:
    """(best wall s, CPU s of that run) over ``repeats`` calls."""
    best = (math.inf, math.inf)
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        w, c = time.perf_counter() - t0, time.process_time() - c0
        if w < best[0]:
            best = (w, c)
    return best


def fusion_count(compiled) -> int:
    """Number of XLA fusions in a compiled executable's HLO text."""
    return len(re.findall(r"^\s*(?:ROOT )?\S+ = (?:\S+|\([^)]*\)) fusion\(", compiled.as_text(), flags=re.M))


def _numba_rates(points: np.ndarray, geo: list, repeats: int):
    """Numba figures, ``deltajax.benchmarks.numba_loops.bench_kernel_rates(points, geo, repeats)`` -> {label: (n, wall s, CPU s)}."""
    from ..benchmarks.numba_loops import bench_kernel_rates

    return bench_kernel_rates(points, geo, repeats)


def run(ctx) -> None:
    e = ctx.settings                                   # checked before the run (config.bench_kernel_settings)
    block = e.block
    robot64 = ctx.robot.with_base_radius(e.R)
    n, nb, reps = e.n_points, e.n_baseline, e.repeats
    pts = _sample_points(n, ctx.seed)
    res = ctx.results
    lines = []

    geo = [float(x) for x in (robot64.base_radius, robot64.platform_radius, robot64.upper_arm, robot64.forearm,
                              robot64.theta_min, robot64.theta_max)]

    def row(label, n_eval, wall, cpu, base=None):
        rate_c, rate_w = n_eval / max(cpu, 1e-9), n_eval / wall
        extra = f"  x{rate_c / base:.2f} vs old kernel" if base else ""
        lines.append(f"{label:34s}: {rate_c / 1e6:8.2f} M eval/CPU-s {rate_w / 1e6:8.2f} M eval/s wall{extra}")
        return rate_c

    wall, cpu = _timed(lambda: reference.point_indices(*geo, pts[:nb]), reps)
    res.put("bench", "numpy_rate_cpu", nb / max(cpu, 1e-9), units="1/s")
    row("numpy reference (f64, LAPACK svd)", nb, wall, cpu)
    ref_np = reference.point_indices(*geo, pts[:nb])

    for dt_name in e.dtypes:
        dt = jnp.float32 if dt_name == "float32" else jnp.float64
        robot = jax.tree_util.tree_map(lambda x: x.astype(dt), robot64)
        p = jnp.asarray(pts, dt)
        variants = {
            "old kernel (main 9f54c88)": lambda rb, q: jax.vmap(lambda x: _kernel_baseline.point_indices(rb, x)[1])(q),
            "new kernel fast, one vmap": lambda rb, q: jax.vmap(lambda x: point_indices(rb, x)[1])(q),
            f"new kernel fast (blocks of {block})": lambda rb, q: map_points(lambda x: point_indices(rb, x)[1], q,
                                                                              block=block),
            "new kernel exact (jacobi)": lambda rb, q: jax.vmap(lambda x: point_indices(rb, x,
                                                                                      sv_method="jacobi")[1])(q),
        }
        base = None
        for label, fn in variants.items():
            t0 = time.perf_counter()
            compiled = jax.jit(fn).lower(robot, p).compile()
            t_compile = time.perf_counter() - t0
            out = jax.block_until_ready(compiled(robot, p))
            wall, cpu = _timed(lambda: jax.block_until_ready(compiled(robot, p)), reps)
            got = np.asarray(out.sigma_min_v[:nb], np.float64)
            okm = ref_np["ok"] & (ref_np["inv_cond"] > 1e-3)
            err = float(np.max(np.abs(got[okm] - ref_np["sigma_min_v"][okm]) / ref_np["sigma_min_v"][okm]))
            same_mask = bool(np.array_equal(np.isfinite(got), ref_np["ok"]))
            rate = row(f"{label} {dt_name}", n, wall, cpu, base)
            base = base or rate
            nf = fusion_count(compiled)
            lines.append(f"{'':34s}  compile {t_compile:.2f} s, {nf} fusions, max rel err sigma_min_v vs numpy "
                         f"{err:.1e}, ok mask {'identical' if same_mask else 'DIFFERENT'}")
            g = f"bench/{dt_name}/{label.split(' (')[0].replace(',', '').replace(' ', '_')}"
            res.put(g, "rate_cpu", rate, units="1/s")
            res.put(g, "rate_wall", n / wall, units="1/s")
            res.put(g, "compile_time", t_compile, units="s")
            res.put(g, "fusions", nf, units="1")
            res.put(g, "max_rel_err_sigma_min_v_vs_numpy", err, units="1")
    for label, (n_eval, wall, cpu) in _numba_rates(pts, geo, reps).items():
        row(f"numba {label}", n_eval, wall, cpu)
    res.put("bench", "n_points", n, units="1")
    res.set_attrs("bench", device=str(jax.devices()[0]), report="\n".join(lines))
    for line in lines:
        ctx.log(line)
    if ctx.plots:
        ctx.savefig(bench_rates_from_results(res, f"kernel throughput (IK + Jacobian + indices), {n} points, "
                                                  f"{jax.device_count()} {jax.default_backend()} device(s)"),
                    "bench_kernel")
