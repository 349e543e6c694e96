"""Benchmark: boundary search of the boundary-search paper's robot at 1 deg steps, eps = 0.01.

Times both JAX searches (compile separately from warm) and a NumPy baseline measured in the same process:
the paper's algorithms written as per-ray Python loops with a NumPy Test-Pose (the same reachability
condition as ``dj.ik_cos_sin(robot, p).ok.all()``, evaluated chain-vectorised for one point), run on a subset
of rays and extrapolated to all rays. Prints the ratios and the paper's MATLAB times (589.1 s Conti,
246.6 s improved, Core i5 2.4 GHz) for reference, and checks that the baseline finds the same brackets.

    python experiments/bench_boundary.py                     # 1 deg, eps 0.01 (the issue's target: <= 1 s warm)
    python experiments/bench_boundary.py --step 2 --subset 0.05
"""

from __future__ import annotations

import argparse
import math
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import deltajax as dj  # noqa: E402
from deltajax.workspace import boundary as B  # noqa: E402

from deltajax.papers import BOUNDARY_SEARCH  # noqa: E402

PAPER_S = {"conti": BOUNDARY_SEARCH["time_conti_1deg_s"], "continuation": BOUNDARY_SEARCH["time_continuation_1deg_s"]}


# -- NumPy baseline (one point at a time, like the paper's MATLAB loops) ----------------------------------------
def make_test_pose_numpy(robot, half_space=True):
    """Test-Pose for one point with NumPy: the three chains' loop closure of the independent NumPy reference
    (:func:`deltajax.reference.loop_closure`, the IK of docs/CONVENTIONS.md)."""
    from deltajax import reference

    R, r = float(robot.base_radius), float(robot.platform_radius)
    L1, L2 = float(robot.upper_arm), float(robot.forearm)
    assert not np.isfinite(float(robot.theta_min)), "the baseline covers robots without joint limits only"

    def test(p):
        x, y, z = reference.chain_local(np.asarray(p)[None, :])
        reach = reference.loop_closure(x + r - R, y, z, L1, L2)[3]
        ok = bool(np.all(reach))
        return ok and (p[2] > 0.0) if half_space else ok

    return test


def conti_numpy(test, centre, d, eps, rho_max):
    """Bisection on one ray; returns (radius_in, radius_out, calls)."""
    lo, hi, calls = 0.0, rho_max, 0
    for _ in range(B.bisection_calls(rho_max, eps)):
        mid = 0.5 * (lo + hi)
        calls += 1
        if test(centre + mid * d):
            lo = mid
        else:
            hi = mid
    return lo, hi, calls


def continuation_numpy(test, centre, dirs_az, polar, eps, rho_max):
    """The paper's continuation along one azimuth (tangent predictor); returns arrays (in, out, calls)."""
    n = len(polar)
    r_in, r_out, calls = np.zeros(n), np.zeros(n), np.zeros(n, np.int64)
    r_in[0], r_out[0], calls[0] = conti_numpy(test, centre, dirs_az[0], eps, rho_max)
    for i in range(1, n):
        rho0 = min(max(r_in[i - 1] / math.cos(polar[i] - polar[i - 1]), 0.0), rho_max)
        d = dirs_az[i]
        t0 = test(centre + rho0 * d)
        c, k = 1, 0
        sgn = 1.0 if t0 else -1.0
        while True:
            k += 1
            rk = min(max(rho0 + sgn * k * eps, 0.0), rho_max)
            c += 1
            if test(centre + rk * d) != t0 or rk in (0.0, rho_max):
                break
        prev = min(max(rho0 + sgn * (k - 1) * eps, 0.0), rho_max)
        r_in[i], r_out[i] = (prev, rk) if t0 else (rk, prev)
        calls[i] = c
    return r_in, r_out, calls


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--step", type=float, default=1.0, help="angular step (deg)")
    ap.add_argument("--eps", type=float, default=0.01, help="tolerance (m)")
    ap.add_argument("--rho-max", type=float, default=5.12, help="bisection interval (m)")
    ap.add_argument("--centre", type=float, nargs=3, default=(0.0, 0.0, 1.62), help="search centre (m)")
    ap.add_argument("--repeats", type=int, default=5, help="warm repetitions (best is reported)")
    ap.add_argument("--subset", type=float, default=0.03, help="fraction of rays / azimuths for the NumPy baseline")
    a = ap.parse_args()

    robot = dj.presets.boundary2d()
    centre = np.asarray(a.centre)
    print(f"device {jax.devices()[0]}, step {a.step} deg, eps {a.eps} m, rho_max {a.rho_max} m, centre {centre}")
    results = {}
    for method in B.METHODS:
        def go():
            return B.boundary_search(robot, centre, step_deg=a.step, eps=a.eps, rho_max=a.rho_max, method=method)

        t0 = time.perf_counter()
        res = jax.block_until_ready(go())
        first = time.perf_counter() - t0
        warm = []
        for _ in range(a.repeats):
            t0 = time.perf_counter()
            res = jax.block_until_ready(go())
            warm.append(time.perf_counter() - t0)
        results[method] = (res, min(warm), first - min(warm))

    polar, azimuth = (np.asarray(x) for x in B.angle_grid(a.step))
    dirs = np.asarray(B.ray_directions(polar, azimuth))
    n_rays = dirs.shape[0] * dirs.shape[1]
    test = make_test_pose_numpy(robot)

    # NumPy baseline, Conti: every k-th ray.
    flat = dirs.reshape(-1, 3)
    k = max(1, int(round(1.0 / a.subset)))
    idx = np.arange(0, n_rays, k)
    t0 = time.perf_counter()
    base = np.array([conti_numpy(test, centre, flat[i], a.eps, a.rho_max) for i in idx])
    t_conti_np = (time.perf_counter() - t0) / idx.size * n_rays
    jr = results["conti"][0]
    same_c = np.allclose(base[:, 0], np.asarray(jr.radius_in).reshape(-1)[idx], atol=1e-12)

    # NumPy baseline, continuation: every k-th azimuth, whole polar sweep.
    jdx = np.arange(0, azimuth.size, k)
    t0 = time.perf_counter()
    bc = [continuation_numpy(test, centre, dirs[j], polar, a.eps, a.rho_max) for j in jdx]
    t_cont_np = (time.perf_counter() - t0) / jdx.size * azimuth.size
    jn = results["continuation"][0]
    same_n = all(np.array_equal(c, np.asarray(jn.calls)[j]) for (_, _, c), j in zip(bc, jdx))
    diff_n = max(float(np.max(np.abs(ri - np.asarray(jn.radius_in)[j]))) for (ri, _, _), j in zip(bc, jdx))

    print(f"\nrays: {polar.size} polar x {azimuth.size} azimuth = {n_rays}")
    print(f"{'method':13s} {'calls':>8s} {'JAX warm':>10s} {'compile':>9s} {'NumPy loop (extrap.)':>21s} "
          f"{'ratio':>7s} {'paper MATLAB':>13s} {'paper/JAX':>10s}")
    for method, t_np, same in (("conti", t_conti_np, same_c), ("continuation", t_cont_np, same_n)):
        res, warm, comp = results[method]
        calls = int(np.asarray(res.calls).sum())
        paper = PAPER_S[method] if a.step == 1.0 and a.eps == 0.01 else float("nan")
        print(f"{method:13s} {calls:8d} {warm * 1e3:8.1f}ms {comp:8.2f}s {t_np:19.2f} s {t_np / warm:7.0f}x "
              f"{paper:11.1f} s {paper / warm:9.0f}x   baseline agrees: {same}")
    print(f"continuation baseline max |radius_in diff| vs JAX: {diff_n:.3g} m")
    n_calls = {m: int(np.asarray(results[m][0].calls).sum()) for m in B.METHODS}
    print(f"continuation / conti: calls {n_calls['continuation'] / n_calls['conti']:.3f}, "
          f"JAX time {results['continuation'][1] / results['conti'][1]:.2f}, NumPy time {t_cont_np / t_conti_np:.2f} "
          f"(paper: time {PAPER_S['continuation'] / PAPER_S['conti']:.3f} at 1 deg, "
          f"calls {BOUNDARY_SEARCH['calls_continuation_2deg']}/{BOUNDARY_SEARCH['calls_conti_2deg']} = "
          f"{BOUNDARY_SEARCH['calls_continuation_2deg'] / BOUNDARY_SEARCH['calls_conti_2deg']:.3f} at 2 deg)")


if __name__ == "__main__":
    main()
