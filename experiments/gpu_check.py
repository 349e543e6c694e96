"""GPU readiness check: every job's JAX path on the default accelerator, checked against the
CPU and timed, then the main job end to end. Run it first whenever a GPU is available and record the figures
in docs/BENCHMARKS.md.

    python experiments/gpu_check.py --scale 64      # fills an H100/H200-class device (kernel N = 64 x 2^16)
    python experiments/gpu_check.py --scale 1       # tiny: what tests/test_gpu_check.py runs on CPU
    python experiments/gpu_check.py --no-job        # the paths only (not the main job)

Paths (float64): kernel ``jit(vmap(dj.point_indices))``; workspace index fields (``index_fields``) and JAX
redundancy resolution (``resolve_redundancy``); GA fitness (``workflow.ga_fitness`` of the default ga_reconfig
problem); dynamics profiles over designs x cycles (``dj.cycle_profile`` via the public API); boundary search
(``boundary_search`` on boundary2d); the designer's search evaluator with the regular workspace
(``deltajax.optimize.workflow.batch_evaluator`` of the main job's problem, what its NSGA-II stage calls); the
Table-6 JAX path (``reconfig_indices``: the fixed robot's workspace on the paper's grid by ``index_fields``, then
``resolve_redundancy`` with k~ over it; its selection must also equal the job's Numba path,
``resolve_redundancy_host``). Each runs on ``jax.devices()[0]`` and on ``jax.devices("cpu")[0]``; results must
agree (rtol 1e-9 on finite values, identical masks / selections); prints warm throughput. Where the default
device is the CPU (the test suite), each path runs once and prints its throughput: there is nothing to compare.

Then the main job (``experiment=ga_reconfig``; at ``--scale 1`` the test suite's toy size, tests/toy_jobs.py,
otherwise its defaults) runs once in this process on the default device: its per-stage wall times (the
``[stage: N s]`` figures, stored as ``time_<stage>_s`` on the results' ``ga_reconfig`` group), its total wall and
CPU-s. Exit status 1 if any check fails.
"""

from __future__ import annotations

import argparse
import re
import resource
import sys
import tempfile
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import deltajax as dj  # noqa: E402
from deltajax.workspace import boundary as B  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
ROOT = Path(__file__).resolve().parents[1]


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
    fit = ga_fitness(pb, space, [s.objectives.primary], [-1.0 / 195.0])   # picks/min, feasibility first
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
    ev, genes = _search_evaluator(scale)
    yield "designer batch_evaluator", len(genes), "designs (regular ws)", lambda: ev(genes), ()
    pts6 = _table6_points(recon, scale)
    yield ("Table-6 resolve_redundancy", len(pts6) * recon.n_R, "(point, R) pairs",
           lambda p: dj.workspace.resolve_redundancy(recon, p), (jnp.asarray(pts6),))


def _job_overrides(scale: int) -> list:
    """The main job's overrides: the suite's toy size at scale 1 (tests/toy_jobs.py), else its defaults."""
    if scale > 1:
        return []
    sys.path.insert(0, str(ROOT / "tests"))
    from toy_jobs import TOY

    return list(TOY["ga_reconfig"])


def _search_evaluator(scale: int):
    """(the main job's search evaluator with the regular workspace, its batch of designs: 4 x scale)."""
    from hydra import compose, initialize_config_dir

    from deltajax.config import ga_reconfig_build, robot_from_config
    from deltajax.optimize.workflow import batch_evaluator
    from deltajax.run import CONFIG_DIR

    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(config_name="config", overrides=["experiment=ga_reconfig", *_job_overrides(scale)])
    robot, recon = robot_from_config(cfg.robot)
    _, space, pb, _ = ga_reconfig_build(cfg.experiment, robot, recon)
    n = 4 * scale
    genes = np.random.default_rng(2).random((n, space.dim))
    genes[0] = space.baseline_genes()
    return batch_evaluator(pb, space, n), genes


def _table6_points(recon, scale: int) -> np.ndarray:
    """Points of the fixed robot's workspace (R = robot.base_radius, the job's ODR mask) on the paper's grid at
    h = 40 mm / scale^(1/3) (10 mm at scale 64), by the JAX index_fields."""
    g = dj.workspace.franco2026_grid(round(0.04 / scale ** (1 / 3), 4))
    pts = np.asarray(g.points()).reshape(-1, 3)
    ok, _ = jax.jit(lambda p: dj.workspace.index_fields(recon.robot, p))(jnp.asarray(pts))
    return pts[np.asarray(ok)]


def table6_matches_numba(recon, scale: int) -> bool:
    """The JAX selection of :func:`_table6_points` equals the job's Numba path (fast mode) exactly."""
    from deltajax.workspace.redundancy import resolve_redundancy_host

    pts = _table6_points(recon, scale)
    red = dj.workspace.resolve_redundancy(recon, jnp.asarray(pts))
    host, _ = resolve_redundancy_host(recon, pts, return_indices=False)
    return bool(np.array_equal(np.asarray(red.k), host.k))


def run_main_job(scale: int) -> dict:
    """The main job end to end in this process: {stage: wall s} (its ``[stage: N s]`` log lines; the stored
    ``time_<stage>_s`` attributes where the log is missing) plus "total wall s" and "total CPU-s"."""
    import h5py

    from deltajax.run import run_experiment

    with tempfile.TemporaryDirectory() as d:
        c0, t0 = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
        path = run_experiment("ga_reconfig", ["plots=false", "progress=false", *_job_overrides(scale)],
                              run_dir=Path(d) / "job")
        wall, c1 = time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_SELF)
        log = path.parent / "run.log"
        out = {m[1]: float(m[2]) for m in re.finditer(r"\[(\w+): ([0-9.]+) s\]", log.read_text())} if log.exists() else {}
        if not out:
            with h5py.File(path, "r") as f:
                out = {k[5:-2]: float(v) for k, v in f["ga_reconfig"].attrs.items()
                       if k.startswith("time_") and k.endswith("_s")}
    out["total wall s"] = wall
    out["total CPU-s"] = (c1.ru_utime + c1.ru_stime) - (c0.ru_utime + c0.ru_stime)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scale", type=int, default=64, help="size multiplier (1 = tiny CPU test)")
    ap.add_argument("--no-job", action="store_true", help="skip the main job end to end")
    a = ap.parse_args(argv)
    dev, cpu = jax.devices()[0], jax.devices("cpu")[0]
    print(f"device: {dev} (platform {dev.platform}); reference: {cpu}; scale {a.scale}")
    failed = []
    for name, n, unit, fn, args in checks(a.scale):
        out_d, t_d = _on(dev, fn, *args)
        if dev == cpu:   # no accelerator: the path runs once, there is nothing to compare it with
            print(f"{name:32s} {n:>10d} {unit:22s} cpu {n / t_d:12.4g}/s  ran (the device is the CPU)", flush=True)
            continue
        out_c, t_c = _on(cpu, fn, *args)
        good = _agree(out_d, out_c)
        failed += [] if good else [name]
        print(f"{name:32s} {n:>10d} {unit:22s} device {n / t_d:12.4g}/s  cpu {n / t_c:12.4g}/s  "
              f"x{t_c / t_d:6.2f}  {'agree' if good else 'DISAGREE'}", flush=True)
    t6 = table6_matches_numba(dj.presets.franco2026(), a.scale)
    failed += [] if t6 else ["Table-6 JAX vs Numba"]
    print(f"{'Table-6 JAX vs Numba selection':32s} {'identical' if t6 else 'DIFFERENT'}", flush=True)
    if not a.no_job:
        t0 = time.perf_counter()
        stages = run_main_job(a.scale)
        print(f"main job ga_reconfig ({'toy size' if a.scale == 1 else 'defaults'}) on {dev.platform}: "
              f"{time.perf_counter() - t0:.1f} s", flush=True)
        for k, v in stages.items():
            print(f"  {k:24s} {v:9.1f}" + ("" if k.startswith("total") else " s"))
    if failed:
        print("FAILED: " + ", ".join(failed))
        return 1
    print("all paths ran (no device other than the CPU)" if dev == cpu else "all paths agree with the CPU")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
