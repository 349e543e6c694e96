"""GPU readiness check (issue 9 item 7): every job's JAX path on the default accelerator, checked against the
CPU and timed. Run it first whenever a GPU is available and record the figures in docs/BENCHMARKS.md.

    python experiments/gpu_check.py --scale 64      # fills an H100/H200-class device (kernel N = 64 x 2^16)
    python experiments/gpu_check.py --scale 1       # tiny: what tests/test_gpu_check.py runs on CPU

Paths (float64): kernel ``jit(vmap(dj.point_indices))``; workspace index fields (``index_fields``) and JAX
redundancy resolution (``resolve_redundancy``); GA fitness (``workflow.ga_fitness`` of the default ga_reconfig
problem); dynamics profiles over designs x cycles (``dj.cycle_profile`` via the public API); boundary search
(``boundary_search`` on boundary2d). Each runs on ``jax.devices()[0]`` and on ``jax.devices("cpu")[0]``;
results must agree (rtol 1e-9 on finite values, identical masks / selections); prints warm throughput.
Exit status 1 if any check fails.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import deltajax as dj  # noqa: E402
from deltajax.workspace import boundary as B  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))


def _on(device, fn, *args):
    """(outputs as NumPy, warm seconds) of ``jit(fn)(*args)`` on ``device``; ``args=()`` calls ``fn()`` as is
    (a host driver that jits internally) under ``jax.default_device``."""
    with jax.default_device(device):
        args = jax.device_put(args, device)
        f = jax.jit(fn) if args else fn
        jax.block_until_ready(f(*args))
        t0 = time.perf_counter()
        out = jax.block_until_ready(f(*args))
    return jax.tree_util.tree_map(np.asarray, out), time.perf_counter() - t0


def _agree(a, b, rtol=1e-9):
    ok = True
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)):
        x, y = np.asarray(x), np.asarray(y)
        if x.dtype == bool or np.issubdtype(x.dtype, np.integer):
            ok &= bool(np.array_equal(x, y))
            continue
        fx, fy = np.isfinite(x), np.isfinite(y)
        ok &= bool(np.array_equal(fx, fy))
        if fx.any():
            ok &= bool(np.allclose(x[fx], y[fx], rtol=rtol, atol=1e-12 * max(1.0, float(np.abs(y[fy]).max()))))
    return ok


def checks(scale: int):
    rng = np.random.default_rng(0)
    recon = dj.presets.franco2026()
    robot = recon.at(0.3)
    n_kernel = 65536 * scale
    pts = jnp.asarray(np.array([-0.35, -0.35, 0.05]) + np.array([0.7, 0.7, 0.55]) * rng.random((n_kernel, 3)))
    yield "kernel point_indices", n_kernel, "points", lambda p: jax.vmap(lambda q: dj.point_indices(robot, q)[1])(p), (pts,)
    n_ws = 16384 * scale
    yield ("workspace index_fields", n_ws, "points", lambda p: dj.workspace.index_fields(robot, p), (pts[:n_ws],))
    n_red = 256 * scale
    yield ("redundancy resolve_redundancy", n_red * recon.n_R, "(point, R) pairs",
           lambda p: dj.workspace.resolve_redundancy(recon, p), (pts[:n_red],))
    import bench_ga

    from deltajax.optimize.workflow import ga_fitness

    s, space, pb = bench_ga.designer_problem(8)
    P = 64 * scale
    genes = jax.random.uniform(jax.random.PRNGKey(1), (P, space.dim), dtype=jnp.float64)
    fit = ga_fitness(pb, space, [s.primary], [-1.0 / 195.0])   # picks/min, feasibility first
    yield "GA fitness", P, "designs", lambda g: fit(g)[0], (genes,)
    rm = dj.presets.franco2026(fixed_R=0.3, with_mass=True)
    n_d = 64 * scale
    L2 = jnp.linspace(0.38, 0.42, n_d)
    cyc = dj.adept_cycle((0.0, 0.0, 0.45), n_samples=201)

    def profiles(L2):
        return jax.vmap(lambda l2: dj.cycle_profile(rm.__class__(
            base_radius=rm.base_radius, platform_radius=rm.platform_radius, upper_arm=rm.upper_arm, forearm=l2,
            theta_min=rm.theta_min, theta_max=rm.theta_max, mass=rm.mass), cyc).tau)(L2)
    yield "dynamics cycle_profile", n_d * 201, "(design, sample) pairs", profiles, (L2,)
    rb = dj.presets.boundary2d()
    step = 10.0 if scale < 4 else 5.0 if scale < 16 else 2.0 if scale < 64 else 1.0  # divides 180 and 360
    polar, azimuth = B.angle_grid(step)
    centre = (0.0, 0.0, 2.0)
    rho_max = B.reach_bound(rb, centre)
    yield ("boundary continuation_rays", polar.size * azimuth.size, "rays",
           lambda: B.continuation_rays(rb, centre, polar, azimuth, eps=0.01, rho_max=rho_max).radius_in, ())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scale", type=int, default=64, help="size multiplier (1 = tiny CPU test)")
    a = ap.parse_args(argv)
    dev, cpu = jax.devices()[0], jax.devices("cpu")[0]
    print(f"device: {dev} (platform {dev.platform}); reference: {cpu}; scale {a.scale}")
    failed = []
    for name, n, unit, fn, args in checks(a.scale):
        out_d, t_d = _on(dev, fn, *args)
        out_c, t_c = _on(cpu, fn, *args)
        good = _agree(out_d, out_c)
        failed += [] if good else [name]
        print(f"{name:32s} {n:>10d} {unit:22s} device {n / t_d:12.4g}/s  cpu {n / t_c:12.4g}/s  "
              f"x{t_c / t_d:6.2f}  {'agree' if good else 'DISAGREE'}", flush=True)
    if failed:
        print("FAILED: " + ", ".join(failed))
        return 1
    print("all paths agree with the CPU")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
