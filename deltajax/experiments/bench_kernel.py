"""Kernel benchmark: IK + Jacobian + all indices, evaluations per second (warm), compile time separately.

Compared in the same process against (a) a vectorised NumPy implementation of the same algebra and (b) the
naive JAX kernel (atan2/acos IK, indices from ``jnp.linalg.svd``). Ratios are what we report: absolute rates
depend on the machine and its load. The fast kernel is checked against the SVD reference before timing.
"""

from __future__ import annotations

import math
import time

import jax
import jax.numpy as jnp
import numpy as np

from ..config import ConfigError
from ..geometry import CHAIN_ANGLES
from ..indices import indices, point_indices
from ..kinematics import ik


def _sample_points(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lo, hi = np.array([-0.35, -0.35, 0.05]), np.array([0.35, 0.35, 0.6])
    return lo + (hi - lo) * rng.random((n, 3))


def numpy_kernel(R, r, L1, L2, lo, hi, p: np.ndarray) -> dict:
    """The fast kernel's maths in vectorised NumPy (algebraic IK, Jacobi eigenvalues, determinant)."""
    ca = np.cos(np.asarray(CHAIN_ANGLES))
    sa = np.sin(np.asarray(CHAIN_ANGLES))
    px = p[:, :1] * ca + p[:, 1:2] * sa
    py = -p[:, :1] * sa + p[:, 1:2] * ca
    pz = np.broadcast_to(p[:, 2:3], px.shape)
    dx = px + r - R
    rho2 = dx * dx + pz * pz
    m = (rho2 + py * py + L1 * L1 - L2 * L2) / (2 * L1)
    disc = rho2 - m * m
    reach = disc >= 0
    w = np.sqrt(np.where(reach, disc, 1.0))
    c = (dx * m + pz * w) / rho2
    s = (pz * m - dx * w) / rho2
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    ok = (reach & (c * math.cos(mid) + s * math.sin(mid) >= math.cos(half))).all(axis=1)
    ux = (dx - L1 * c) / L2
    uy = py / L2
    uz = (pz - L1 * s) / L2
    Jx = np.stack([ux * ca - uy * sa, ux * sa + uy * ca, uz], axis=-1)  # (n, 3 chains, 3)
    d = uz * c - ux * s
    G = np.einsum("nik,njk->nij", Jx, Jx)
    det_jx = np.abs(np.linalg.det(Jx))
    prod_d = np.abs(d.prod(axis=1))
    adjG = np.empty_like(G)
    for i in range(3):
        for j in range(3):
            a, b = [k for k in range(3) if k != i], [k for k in range(3) if k != j]
            adjG[:, j, i] = (-1) ** (i + j) * (G[:, a[0], b[0]] * G[:, a[1], b[1]] - G[:, a[0], b[1]] * G[:, a[1], b[0]])
    adj_d = np.stack([d[:, 1] * d[:, 2], d[:, 0] * d[:, 2], d[:, 0] * d[:, 1]], axis=1)
    jx_side = det_jx < prod_d
    S = np.where(jx_side[:, None, None], adj_d[:, :, None] * G * adj_d[:, None, :], d[:, :, None] * adjG * d[:, None, :])
    ev = np.linalg.eigvalsh(S)  # ascending; LAPACK's symmetric solver stands in for the Jacobi sweeps
    r1, r2 = np.sqrt(np.maximum(ev[:, 2], 0)), np.sqrt(np.maximum(ev[:, 1], 0))
    with np.errstate(divide="ignore", invalid="ignore"):
        a1, a2 = r1 / det_jx, r2 / det_jx
        a3 = prod_d / (det_jx * a1 * a2)
        b3, b2 = prod_d / r1, prod_d / r2
        b1 = prod_d / (det_jx * b2 * b3)
        s1 = np.where(jx_side, b1, a1)
        s3 = np.where(jx_side, b3, a3)
        s2 = np.where(jx_side, b2, a2)
        s1, s2, s3 = (np.where(ok, v, np.nan) for v in (s1, s2, s3))
        return {"ok": ok, "inv_cond": s3 / s1, "sigma_min_v": s3, "sigma_min_f": 1 / s1, "omega_v": s1 * s2 * s3}


def _best(fn, repeats: int) -> float:
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def run(ctx) -> None:
    e = ctx.cfg.experiment
    for key in ("n_points", "n_baseline", "repeats"):
        if int(e[key]) < 1:
            raise ConfigError(f"experiment.{key} must be >= 1, got {e[key]!r}")
    for dt in e.dtypes:
        if dt not in ("float32", "float64"):
            raise ConfigError(f"experiment.dtypes entries must be float32/float64, got {dt!r}")
    if ctx.cfg.precision != "float64" and "float64" in e.dtypes:
        raise ConfigError("bench_kernel with float64 in experiment.dtypes needs precision=float64")
    robot64 = ctx.robot.with_base_radius(float(e.R))
    n, nb, reps = int(e.n_points), int(e.n_baseline), int(e.repeats)
    pts = _sample_points(n, int(ctx.cfg.seed))
    res = ctx.results
    lines = []

    block = int(e.get("block", 1000))
    if n % block:
        raise ConfigError(f"experiment.n_points={n} must be a multiple of experiment.block={block}")

    devices = jax.local_devices()
    mesh = jax.sharding.Mesh(np.asarray(devices), ("d",))
    spec = jax.sharding.PartitionSpec("d")
    if n % (block * len(devices)):
        raise ConfigError(f"experiment.n_points={n} must be a multiple of block x devices = {block * len(devices)}")

    def fast(robot, p):
        # cache blocking: XLA:CPU splits the kernel into ~85 fusions with intermediates in memory between them;
        # lax.map over blocks of ~1000 points keeps those intermediates in L1/L2 (measured ~1.5-2x). The
        # blocks are split over all local devices (one per CPU under the CLI's worker settings).
        def local(robot, p):
            def blk(c):
                return jax.vmap(lambda q: point_indices(robot, q)[1])(c)
            out = jax.lax.map(blk, p.reshape(-1, block, 3))
            return jax.tree_util.tree_map(lambda x: x.reshape((-1,) + x.shape[2:]), out)
        return jax.shard_map(local, mesh=mesh, in_specs=(jax.sharding.PartitionSpec(), spec), out_specs=spec)(robot, p)

    def naive(robot, p):
        def one(q):
            sol = ik(robot, q)
            return indices(robot, q, sol.theta, sv_method="svd")
        return jax.vmap(one)(p)

    # NumPy baseline (float64), same maths
    geo = [float(x) for x in (robot64.base_radius, robot64.platform_radius, robot64.upper_arm, robot64.forearm,
                              robot64.theta_min, robot64.theta_max)]
    t_np = _best(lambda: numpy_kernel(*geo, pts[:nb]), reps)
    rate_np = nb / t_np
    res.put("bench", "numpy_rate", rate_np, units="1/s")
    lines.append(f"numpy (same algebra, f64)      : {rate_np / 1e6:8.2f} M eval/s")

    ref_np = numpy_kernel(*geo, pts[:nb])
    for dt_name in e.dtypes:
        dt = jnp.float32 if dt_name == "float32" else jnp.float64
        robot = jax.tree_util.tree_map(lambda x: x.astype(dt), robot64)
        p = jnp.asarray(pts, dt)
        t0 = time.perf_counter()
        compiled = jax.jit(fast).lower(robot, p).compile()
        t_compile = time.perf_counter() - t0
        out = jax.block_until_ready(compiled(robot, p))
        t_warm = _best(lambda: jax.block_until_ready(compiled(robot, p)), reps)
        rate = n / t_warm
        # correctness against the NumPy reference (float64 only: f32 loses digits near singular poses)
        got = np.asarray(out.sigma_min_v[:nb], np.float64)
        okm = ref_np["ok"] & np.isfinite(ref_np["sigma_min_v"]) & (ref_np["inv_cond"] > 1e-3)
        err = float(np.max(np.abs(got[okm] - ref_np["sigma_min_v"][okm]) / ref_np["sigma_min_v"][okm]))
        p_b = p[:nb]
        naive_c = jax.jit(naive).lower(robot, p_b).compile()
        jax.block_until_ready(naive_c(robot, p_b))
        t_naive = _best(lambda: jax.block_until_ready(naive_c(robot, p_b)), reps)
        rate_naive = nb / t_naive
        g = f"bench/{dt_name}"
        res.put(g, "rate", rate, units="1/s")
        res.put(g, "compile_time", t_compile, units="s")
        res.put(g, "naive_rate", rate_naive, units="1/s")
        res.put(g, "max_rel_err_sigma_min_v_vs_numpy", err, units="1")
        lines.append(f"jax fast kernel {dt_name}        : {rate / 1e6:8.2f} M eval/s (N={n}, {len(devices)} device(s), "
                     f"compile {t_compile:.2f} s)"
                     f"  x{rate / rate_np:.1f} vs numpy, x{rate / rate_naive:.1f} vs naive jax; "
                     f"max rel err sigma_min_v vs numpy {err:.1e}")
        lines.append(f"jax naive kernel {dt_name}       : {rate_naive / 1e6:8.2f} M eval/s (trig IK + linalg.svd)")
    res.put("bench", "n_points", n, units="1")
    res.set_attrs("bench", device=str(jax.devices()[0]), report="\n".join(lines))
    for line in lines:
        ctx.log(line)
    if ctx.cfg.get("plots", True):
        from ..plots import bench_rates_from_results

        ctx.savefig(bench_rates_from_results(res, f"kernel throughput (IK + Jacobian + indices), {n} points, "
                                                  f"{len(devices)} {jax.default_backend()} device(s)"),
                    "bench_kernel")
