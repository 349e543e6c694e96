"""Benchmark: torque-profile evaluations per second over a population of designs (issue 4).

One evaluation = one (design, trajectory sample): IK, joint rates and accelerations, inverse dynamics.
Compares in the same process (the machine is shared, ratios are what we report):

* ``numpy``: a vectorised NumPy implementation of the same maths over (designs x samples) arrays
  (written independently here; also checks the JAX torques to 1e-9);
* ``jax_torque``: ``vmap(designs) o vmap(samples)`` of ``joint_motion`` + ``inverse_dynamics_motion``, jitted;
* ``jax_metrics``: the full ``cycle_metrics`` (profile + static profile + peaks + closed-form cycle time),
  what a GA fitness calls; reported as designs/s and sample evaluations/s.

Usage: ``python experiments/bench_dynamics.py [--designs 2000] [--samples 201] [--repeats 3] [--float32]``.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import deltajax as dj  # noqa: E402
from deltajax import dynamics as dyn  # noqa: E402
from deltajax import trajectory as tr  # noqa: E402

CHAIN = [2.0 * math.pi * i / 3.0 for i in range(3)]


def population(n, seed=0, dtype=jnp.float64):
    """n franco2026-like designs: L1, L2, R, r and the upper-arm mass perturbed (all reach the cycle)."""
    rng = np.random.default_rng(seed)
    base = dj.presets.franco2026(fixed_R=0.2, with_mass=True)
    L1 = rng.uniform(0.19, 0.23, n)
    L2 = rng.uniform(0.39, 0.44, n)
    R = rng.uniform(0.18, 0.22, n)
    r = rng.uniform(0.055, 0.07, n)
    m_arm = rng.uniform(1.0, 2.0, n)
    pop = jax.vmap(lambda a, b, c, d, e: eqx.tree_at(
        lambda x: (x.upper_arm, x.forearm, x.base_radius, x.platform_radius, x.mass.upper_arm_mass), base,
        (a, b, c, d, e)))(*(jnp.asarray(v, dtype) for v in (L1, L2, R, r, m_arm)))
    return pop, dict(L1=L1, L2=L2, R=R, r=r, m_arm=m_arm)


def numpy_torques(d, mm, p, pd, pdd):
    """Torques (P, K, 3) of P designs along K samples, fixed R, NumPy (independent implementation)."""
    L1, L2, R, r = (d[k][:, None] for k in ("L1", "L2", "R", "r"))
    m_arm = d["m_arm"][:, None]
    g = mm["g"]
    m_e = mm["elbow"] + mm["split"] * mm["forearm"]
    M = mm["platform"] + mm["payload"] + 3 * (1 - mm["split"]) * mm["forearm"]
    c_arm = mm["com"] * L1
    I_arm = mm["kI"] * m_arm * L1 ** 2 + m_arm * c_arm ** 2 + m_e * L1 ** 2 + mm["n"] ** 2 * mm["rotor"]
    s_arm = m_arm * c_arm + m_e * L1
    P, K = L1.shape[0], p.shape[0]
    u_base = np.empty((P, K, 3, 3))
    dcol = np.empty((P, K, 3))
    tau_arm = np.empty((P, K, 3))
    for i, a in enumerate(CHAIN):
        ca, sa = math.cos(a), math.sin(a)
        rot = lambda v: (ca * v[:, 0] + sa * v[:, 1], -sa * v[:, 0] + ca * v[:, 1], v[:, 2])  # noqa: E731
        px, py, pz = (x[None, :] for x in rot(p))
        vx, vy, vz = (x[None, :] for x in rot(pd))
        ax, ay, az = (x[None, :] for x in rot(pdd))
        dx = px + r - R
        rho2 = dx * dx + pz * pz
        m = (rho2 + py * py + L1 * L1 - L2 * L2) / (2 * L1)
        w = np.sqrt(rho2 - m * m)
        c = (dx * m + pz * w) / rho2
        s = (pz * m - dx * w) / rho2
        ux, uy, uz = (dx - L1 * c) / L2, py / L2, (pz - L1 * s) / L2
        dd = L1 * (uz * c - ux * s)
        thd = (ux * vx + uy * vy + uz * vz) / dd
        wx, wy, wz = vx + L1 * s * thd, vy, vz - L1 * c * thd
        thdd = (ux * ax + uy * ay + uz * az + (wx * wx + wy * wy + wz * wz) / L2
                + L1 * thd * thd * (ux * c + uz * s)) / dd
        tau_arm[:, :, i] = I_arm * thdd - g * s_arm * c
        dcol[:, :, i] = dd
        u_base[:, :, i, 0] = ca * ux - sa * uy
        u_base[:, :, i, 1] = sa * ux + ca * uy
        u_base[:, :, i, 2] = uz
    F = M * (pdd - np.array([0.0, 0.0, g]))                      # (K, 3)
    y = np.linalg.solve(np.swapaxes(u_base, -1, -2), np.broadcast_to(F, (P, K, 3))[..., None])[..., 0]
    return tau_arm + dcol * y


def timed(fn, repeats):
    best = math.inf
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn())
        best = min(best, time.perf_counter() - t0)
    return best, out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--designs", type=int, default=2000)
    ap.add_argument("--samples", type=int, default=201)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", type=str, default="")
    args = ap.parse_args()
    P, K = args.designs, args.samples
    pop, d = population(P)
    cycle = tr.adept_cycle((0.0, 0.0, 0.4), duration=0.5, n_samples=K)
    x, xd, xdd = cycle.rates()
    mass = dj.presets.franco2026_mass()
    mm = dict(g=float(mass.gravity), elbow=float(mass.elbow_mass), split=float(mass.forearm_elbow_fraction),
              forearm=float(mass.forearm_mass), platform=float(mass.platform_mass), payload=float(mass.payload_mass),
              com=float(mass.upper_arm_com_fraction), kI=float(mass.upper_arm_inertia_factor),
              n=float(mass.gear_ratio), rotor=float(mass.rotor_inertia))
    xn, xdn, xddn = (np.asarray(a) for a in (x, xd, xdd))

    def jax_torque(robot, p, pd, pdd):
        def one(p_, pd_, pdd_):
            return dyn.inverse_dynamics_motion(robot, dyn.joint_motion(robot, p_, pd_, pdd_)).tau
        return jax.vmap(one)(p, pd, pdd)

    torque_pop = jax.jit(jax.vmap(jax_torque, in_axes=(0, None, None, None)))
    limits = dyn.Limits(torque=20.0, speed=10.0)
    metrics_pop = jax.jit(jax.vmap(dyn.cycle_metrics, in_axes=(0, None, None)))

    t0 = time.perf_counter()
    jax.block_until_ready(torque_pop(pop, x, xd, xdd))
    c_torque = time.perf_counter() - t0
    t0 = time.perf_counter()
    jax.block_until_ready(metrics_pop(pop, cycle, limits))
    c_metrics = time.perf_counter() - t0

    t_np, tau_np = timed(lambda: numpy_torques(d, mm, xn, xdn, xddn), args.repeats)
    t_jt, tau_j = timed(lambda: torque_pop(pop, x, xd, xdd), args.repeats)
    t_jm, met = timed(lambda: metrics_pop(pop, cycle, limits), args.repeats)
    err = float(np.max(np.abs(np.asarray(tau_j) - tau_np)))
    n_eval = P * K
    res = dict(designs=P, samples=K, evaluations=n_eval, max_abs_diff_numpy_jax_Nm=err,
               numpy_eval_per_s=n_eval / t_np, jax_torque_eval_per_s=n_eval / t_jt,
               jax_metrics_designs_per_s=P / t_jm, jax_metrics_eval_per_s=n_eval / t_jm,
               ratio_jax_torque_vs_numpy=t_np / t_jt, ratio_jax_metrics_vs_numpy=t_np / t_jm,
               compile_s_torque=c_torque, compile_s_metrics=c_metrics, all_ok=bool(np.all(np.asarray(met.ok))),
               device=str(jax.devices()[0]))
    print(f"{P} designs x {K} samples = {n_eval} torque evaluations (float64, {res['device']})")
    print(f"  numpy (vectorised)         {res['numpy_eval_per_s'] / 1e6:8.3f} M eval/s  (1.00x)")
    print(f"  jax torque profile (jit)   {res['jax_torque_eval_per_s'] / 1e6:8.3f} M eval/s  "
          f"({res['ratio_jax_torque_vs_numpy']:.2f}x numpy; compile {c_torque:.1f} s)")
    print(f"  jax cycle_metrics (jit)    {res['jax_metrics_eval_per_s'] / 1e6:8.3f} M eval/s = "
          f"{res['jax_metrics_designs_per_s']:.0f} designs/s ({res['ratio_jax_metrics_vs_numpy']:.2f}x numpy "
          f"torque-only; compile {c_metrics:.1f} s)")
    print(f"  max |tau_numpy - tau_jax| = {err:.2e} N m; all designs ok: {res['all_ok']}")
    assert err < 1e-9, "NumPy and JAX torques disagree"
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=2)


if __name__ == "__main__":
    main()
