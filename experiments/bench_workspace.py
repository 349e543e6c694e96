"""Benchmark of the full Table-6 job (Franco-López 2026): ODR fields + RDR redundancy resolution + statistics.

    python experiments/bench_workspace.py                 # 2 mm paper grid, fast mode; exact mode on a subset
    python experiments/bench_workspace.py --h 0.004       # coarser grid
    python experiments/bench_workspace.py --exact-fraction 1.0   # full exact run (slow)

The job: (1) fixed robot R = 0.200 over the whole grid (mask + every index), (2) the reconfigurable robot's
k~-optimal R* at every ODR workspace point (358 samples), (3) min/max/mean of every index for both. Fast
mode: mirror half of the grid, closed-form reach range per point, IK pre-test before the Jacobian work.
Exact mode: every point, every sample (the paper's sweep), timed on ``--exact-fraction`` of the ODR points
(a random subset; the rate is extrapolated to all points and the same subset is checked for identical
selection against the fast answer). Prints wall times, evaluations/s and the fast/exact ratio.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--h", type=float, default=0.002)
    ap.add_argument("--beta", type=float, default=0.5)
    ap.add_argument("--exact-fraction", type=float, default=0.01)
    args = ap.parse_args()
    import deltajax as dj
    from deltajax import workspace as ws

    rec = dj.presets.franco2026()
    fixed = dj.presets.franco2026(fixed_R=0.2)
    grid = ws.franco2026_grid(args.h)
    print(f"grid {grid.shape}: {grid.n_points} points x {rec.n_R} R samples; CPUs {len(os.sched_getaffinity(0))}; "
          f"load {os.getloadavg()}")
    # warm-up (Numba compile, cached on disk) on a tiny grid
    small = ws.franco2026_grid(0.05)
    f0 = ws.fixed_workspace(fixed, small)
    ws.redundancy_grid(rec, small, mask=f0.ok)
    ws.resolve_redundancy_host(rec, small.points()[:100], mode="exact")

    t0 = time.perf_counter()
    odr = ws.fixed_workspace(fixed, grid, fields=True, field_dtype=np.float32, beta=args.beta)
    t1 = time.perf_counter()
    work: dict = {}
    rdr = ws.redundancy_grid(rec, grid, mask=odr.ok, mode="fast", beta=args.beta, field_dtype=np.float32, work=work)
    t2 = time.perf_counter()
    s_rdr = ws.index_stats(rdr.fields, odr.ok)
    s_odr = ws.index_stats(odr.fields, odr.ok)
    t3 = time.perf_counter()
    n_odr = int(odr.ok.sum())
    fast_total = t3 - t0
    print(f"FAST  total {fast_total:.1f} s  (ODR fields {t1 - t0:.1f} s, RDR {t2 - t1:.1f} s, stats {t3 - t2:.1f} s)")
    print(f"      ODR points {n_odr}; RDR solved {work['points']} mirror-unique points, {work['samples']} IK tests, "
          f"{work['full']} full kernels; {n_odr * rec.n_R / (t2 - t1) / 1e6:.1f} M (point, R) pairs/s equivalent")

    # exact mode on a random subset of ODR points
    idx = np.flatnonzero(odr.ok.reshape(-1))
    rng = np.random.default_rng(0)
    sub = np.sort(rng.choice(idx, max(1, int(args.exact_fraction * len(idx))), replace=False))
    pts = grid.points_at(sub)
    t4 = time.perf_counter()
    ex, wex = ws.resolve_redundancy_host(rec, pts, "k_tilde", mode="exact", beta=args.beta, return_indices=True)
    t5 = time.perf_counter()
    same = np.array_equal(ex.k, rdr.fields["k_star"].reshape(-1)[sub])
    rate = len(sub) / (t5 - t4)
    exact_rdr = n_odr / rate
    exact_total = (t1 - t0) * (grid.n_points / max(1, grid.n_points)) * 2 + exact_rdr + (t3 - t2)
    print(f"EXACT subset {len(sub)} points in {t5 - t4:.1f} s ({rate:.0f} points/s, {wex['samples'] / (t5 - t4) / 1e6:.1f} M "
          f"IK tests/s, {wex['full']} full kernels); identical selection on the subset: {same}")
    print(f"      extrapolated exact RDR {exact_rdr:.1f} s; exact job (ODR on the full grid, no mirror) ~{exact_total:.1f} s")
    print(f"RATIO exact/fast (whole job) ~{exact_total / fast_total:.2f}; RDR part {exact_rdr / (t2 - t1):.2f}")
    print(f"Table 6 check (beta {args.beta}): RDR omega_v mean {s_rdr['omega_v']['mean']:.4f}, ODR {s_odr['omega_v']['mean']:.4f}")


if __name__ == "__main__":
    main()
