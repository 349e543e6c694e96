"""Benchmark: torque-profile evaluations per second over a population of designs.

One evaluation = one (design, trajectory sample): IK, joint rates and accelerations, inverse dynamics.
Compares in the same process (the machine is shared, ratios are what we report; CPU-seconds from
``time.process_time`` and wall seconds, best of ``--repeats``):

* ``numpy``: a vectorised NumPy implementation of the same maths over (designs x samples) arrays
  (written independently here, incl. the rigid-rod forearm term; also checks the JAX torques to 1e-9);
* ``jax_old``: the pre-issue-9 JAX form kept here as the second baseline (per-point (3,) vectors and (3, 3)
  Jacobians under two vmaps, theta by atan2 and cos/sin again); point-split forearms only;
* ``jax_torque``: ``vmap(designs) o vmap(samples)`` of the library's flat form (``cycle_profile``'s sample
  function: scalars per chain from the core's loop_closure / loop_vectors / jq_theta / jx_det), jitted;
* ``jax_point_api``: the per-point public API (``joint_motion`` + ``inverse_dynamics_motion``) under two vmaps;
* ``jax_metrics``: the full ``cycle_metrics`` (profile, peaks, RMS and closed-form cycle time in one variadic
  reduction), what a GA fitness calls; reported as designs/s and sample evaluations/s.

Usage: ``python experiments/bench_dynamics.py [--designs 2000] [--samples 201] [--repeats 3]
[--forearm-model point_split|rigid_rod] [--json out.json]``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import deltajax as dj  # noqa: E402
from deltajax import cycle as cy  # noqa: E402
from deltajax import dynamics as dyn  # noqa: E402
from deltajax import reference as ref  # noqa: E402
from deltajax import trajectory as tr  # noqa: E402

CHAIN = [2.0 * math.pi * i / 3.0 for i in range(3)]


def population(n, seed=0, dtype=jnp.float64, forearm_model="point_split"):
    """n franco2026-like designs: L1, L2, R, r and the upper-arm mass perturbed (all reach the cycle)."""
    rng = np.random.default_rng(seed)
    base = dj.presets.franco2026(fixed_R=0.2, with_mass=True)
    base = eqx.tree_at(lambda x: x.mass, base, base.mass.with_forearm_model(forearm_model))
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
    """Torques (P, K, 3) of P designs along K samples, fixed R, NumPy (independent implementation).

    Rigid-rod forearms (``mm["J"]`` > 0): kinetic energy of the point split minus J/2 |w'|^2 per chain, which
    adds J L1 (cos th w_z'' - sin th w_x'') to the arm and -J w'' to the platform force.
    """
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
    J = mm["J"]
    F_rod = np.zeros((P, K, 3))
    for i, a in enumerate(CHAIN):
        ca, sa = math.cos(a), math.sin(a)
        rot = lambda v: (ca * v[:, 0] + sa * v[:, 1], -sa * v[:, 0] + ca * v[:, 1], v[:, 2])  # noqa: E731
        px, py, pz = (x[None, :] for x in rot(p))
        vx, vy, vz = (x[None, :] for x in rot(pd))
        ax, ay, az = (x[None, :] for x in rot(pdd))
        dx = px + r - R
        c, s = ref.loop_closure(dx, py, pz, L1, L2)[:2]       # the one NumPy loop closure (deltajax.reference)
        ux, uy, uz = ref.loop_vectors(dx, py, pz, c, s, L1, L2)
        dd = L1 * (uz * c - ux * s)
        thd = (ux * vx + uy * vy + uz * vz) / dd
        wx, wy, wz = vx + L1 * s * thd, vy, vz - L1 * c * thd
        thdd = (ux * ax + uy * ay + uz * az + (wx * wx + wy * wy + wz * wz) / L2
                + L1 * thd * thd * (ux * c + uz * s)) / dd
        tau_arm[:, :, i] = I_arm * thdd - g * s_arm * c
        if J:
            bx = -L1 * (c * thd * thd + s * thdd)
            bz = L1 * (c * thdd - s * thd * thd)
            wx, wy, wz = ax - bx, ay, az - bz                   # loop-vector acceleration, chain frame
            tau_arm[:, :, i] += J * L1 * (c * wz - s * wx)
            F_rod[..., 0] -= J * (ca * wx - sa * wy)
            F_rod[..., 1] -= J * (sa * wx + ca * wy)
            F_rod[..., 2] -= J * wz
        dcol[:, :, i] = dd
        u_base[:, :, i, 0] = ca * ux - sa * uy
        u_base[:, :, i, 1] = sa * ux + ca * uy
        u_base[:, :, i, 2] = uz
    F = M * (pdd - np.array([0.0, 0.0, g])) + F_rod            # (P, K, 3)
    y = np.linalg.solve(np.swapaxes(u_base, -1, -2), np.broadcast_to(F, (P, K, 3))[..., None])[..., 0]
    return tau_arm + dcol * y


def old_jax_torque(robot, p, pd, pdd):
    """The pre-issue-9 JAX form (copied from deltajax/dynamics.py at 9f54c88, point-split forearms): per-point
    (3,) vectors and (3, 3) matrices, theta by atan2 and cos/sin again, Jacobians from ``dj.jacobians``."""
    from deltajax.kinematics import from_chain_frames, to_chain_frames

    def cross_rows(A):
        C = jnp.stack([jnp.cross(A[1], A[2]), jnp.cross(A[2], A[0]), jnp.cross(A[0], A[1])])
        return jnp.dot(A[0], C[0]), C

    def one(p_, pd_, pdd_):
        L1, mm = robot.upper_arm, robot.mass
        cs = dj.ik_cos_sin(robot, p_)
        ik_ok = jnp.all(cs.ok)
        c, s = jnp.where(ik_ok, cs.cos, 1.0), jnp.where(ik_ok, cs.sin, 0.0)
        theta = jnp.arctan2(s, c)
        c, s = jnp.cos(theta), jnp.sin(theta)
        loc = to_chain_frames(p_)
        w = jnp.stack([loc[:, 0] + robot.platform_radius - robot.base_radius - L1 * c, loc[:, 1],
                       loc[:, 2] - L1 * s], axis=-1)
        u = w / robot.forearm
        d = L1 * (u[:, 2] * c - u[:, 0] * s)
        det_jx, _ = cross_rows(from_chain_frames(u))
        ok = ik_ok & (jnp.abs(det_jx) > 1e-9) & jnp.all(jnp.abs(d) > 1e-9 * L1)
        d_safe = jnp.where(jnp.abs(d) > 0, d, 1.0)
        pd_loc, pdd_loc = to_chain_frames(pd_), to_chain_frames(pdd_)
        thd = jnp.sum(u * pd_loc, axis=-1) / d_safe
        zero = jnp.zeros_like(thd)
        b_dot = jnp.stack([-L1 * s * thd, zero, L1 * c * thd], axis=-1)
        w_dot = pd_loc - b_dot
        thdd = (jnp.sum(u * pdd_loc, axis=-1) + jnp.sum(w_dot * w_dot, axis=-1) / robot.forearm
                + L1 * thd ** 2 * (u[:, 0] * c + u[:, 2] * s)) / d_safe
        th = jnp.where(ok, theta, jnp.nan)
        c, s = jnp.cos(th), jnp.sin(th)
        g = mm.gravity
        tau = (mm.upper_arm_inertia_factor * mm.upper_arm_mass * L1 * L1 + mm.gear_ratio ** 2 * mm.rotor_inertia) * thdd
        for mass, arm in ((mm.upper_arm_mass, mm.upper_arm_com_fraction * L1), (mm.elbow_point_mass(), L1)):
            ax = -arm * (c * thd ** 2 + s * thdd)
            az = arm * (-s * thd ** 2 + c * thdd)
            tau = tau + mass * (-arm * s * ax + arm * c * az) - mass * g * arm * c
        jac = dj.jacobians(robot, p_, th)
        det, C = cross_rows(jac.Jx)
        det = jnp.where(det != 0, det, 1.0)
        M = mm.moving_mass()
        Q = jac.Jq.T @ (C @ (M * pdd_ - M * g * jnp.asarray([0.0, 0.0, 1.0], pdd_.dtype))) / det
        return jnp.where(ok, tau + Q[1:], jnp.nan)

    return jax.vmap(one)(p, pd, pdd)


def timed(fn, repeats):
    """(best wall s, best CPU s, output) over ``repeats`` calls, outputs blocked on."""
    best_w, best_c = math.inf, math.inf
    out = None
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        out = jax.block_until_ready(fn())
        best_w = min(best_w, time.perf_counter() - t0)
        best_c = min(best_c, time.process_time() - c0)
    return best_w, best_c, out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--designs", type=int, default=2000)
    ap.add_argument("--samples", type=int, default=201)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--forearm-model", default="point_split", choices=["point_split", "rigid_rod"])
    ap.add_argument("--json", type=str, default="")
    args = ap.parse_args()
    P, K = args.designs, args.samples
    pop, d = population(P, forearm_model=args.forearm_model)
    cycle = tr.adept_cycle((0.0, 0.0, 0.4), duration=0.5, n_samples=K)
    x, xd, xdd = cycle.rates()
    mass = dj.presets.franco2026_mass().with_forearm_model(args.forearm_model)
    mm = dict(g=float(mass.gravity), elbow=float(mass.elbow_mass), split=float(mass.forearm_elbow_fraction),
              forearm=float(mass.forearm_mass), platform=float(mass.platform_mass), payload=float(mass.payload_mass),
              com=float(mass.upper_arm_com_fraction), kI=float(mass.upper_arm_inertia_factor),
              n=float(mass.gear_ratio), rotor=float(mass.rotor_inertia), J=float(mass.forearm_rotation_deficit()))
    xn, xdn, xddn = (np.asarray(a) for a in (x, xd, xdd))

    def point_api(robot, p, pd, pdd):
        def one(p_, pd_, pdd_):
            return dyn.inverse_dynamics_motion(robot, dyn.joint_motion(robot, p_, pd_, pdd_)).tau
        return jax.vmap(one)(p, pd, pdd)

    limits = cy.Limits(torque=20.0, speed=10.0)
    fns = {
        "jax_torque": jax.jit(jax.vmap(lambda rob: cy.cycle_profile(rob, cycle).tau)),
        "jax_point_api": jax.jit(jax.vmap(point_api, in_axes=(0, None, None, None))),
        "jax_metrics": jax.jit(jax.vmap(cy.cycle_metrics, in_axes=(0, None, None))),
    }
    calls = {"jax_torque": lambda f: f(pop), "jax_point_api": lambda f: f(pop, x, xd, xdd),
             "jax_metrics": lambda f: f(pop, cycle, limits)}
    if args.forearm_model == "point_split":
        fns["jax_old"] = jax.jit(jax.vmap(old_jax_torque, in_axes=(0, None, None, None)))
        calls["jax_old"] = lambda f: f(pop, x, xd, xdd)
    compile_s, out = {}, {}
    for name, f in fns.items():
        t0 = time.perf_counter()
        out[name] = jax.block_until_ready(calls[name](f))
        compile_s[name] = time.perf_counter() - t0
    load = os.getloadavg()
    res = dict(designs=P, samples=K, evaluations=P * K, forearm_model=args.forearm_model, device=str(jax.devices()[0]),
               load_before=load)
    t_np, c_np, tau_np = timed(lambda: numpy_torques(d, mm, xn, xdn, xddn), args.repeats)
    timings = {"numpy": (t_np, c_np)}
    for name, f in fns.items():
        tw, tc, out[name] = timed(lambda: calls[name](f), args.repeats)
        timings[name] = (tw, tc)
    res["load_after"] = os.getloadavg()
    errs = {k: float(np.max(np.abs(np.asarray(out[k]) - tau_np))) for k in ("jax_torque", "jax_point_api", "jax_old")
            if k in out}
    n_eval = P * K
    print(f"{P} designs x {K} samples = {n_eval} torque evaluations (float64, {res['device']}, forearms "
          f"{args.forearm_model}); load {load[0]:.1f} -> {res['load_after'][0]:.1f}")
    print(f"  {'method':22s} {'wall s':>8s} {'CPU s':>8s} {'M eval/CPU-s':>13s} {'x numpy (CPU)':>14s} "
          f"{'x numpy (wall)':>15s} {'compile s':>10s}")
    for name, (tw, tc) in timings.items():
        res[f"{name}_wall_s"], res[f"{name}_cpu_s"] = tw, tc
        res[f"{name}_eval_per_cpu_s"] = n_eval / tc
        res[f"ratio_{name}_vs_numpy_cpu"], res[f"ratio_{name}_vs_numpy_wall"] = c_np / tc, t_np / tw
        print(f"  {name:22s} {tw:8.4f} {tc:8.4f} {n_eval / tc / 1e6:13.3f} {c_np / tc:14.2f} {t_np / tw:15.2f} "
              f"{compile_s.get(name, 0.0):10.1f}")
    if "jax_old" in timings:
        for name in ("jax_torque", "jax_metrics"):
            res[f"ratio_{name}_vs_jax_old_cpu"] = timings["jax_old"][1] / timings[name][1]
            print(f"  {name} vs jax_old: {res[f'ratio_{name}_vs_jax_old_cpu']:.2f}x (CPU-s)")
    res["jax_metrics_designs_per_cpu_s"] = P / timings["jax_metrics"][1]
    res["max_abs_diff_numpy_jax_Nm"] = errs
    res["all_ok"] = bool(np.all(np.asarray(out["jax_metrics"].ok)))
    res["compile_s"] = compile_s
    print(f"  cycle_metrics: {res['jax_metrics_designs_per_cpu_s']:.0f} designs per CPU-s; all designs ok: "
          f"{res['all_ok']}; max |tau_numpy - tau_jax| = "
          + ", ".join(f"{k} {v:.1e}" for k, v in errs.items()) + " N m")
    assert all(v < 1e-9 for v in errs.values()), "NumPy and JAX torques disagree"
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=2)


if __name__ == "__main__":
    main()
