"""Benchmark of the full Table-6 job (Franco-López 2026): ODR fields + RDR redundancy resolution + statistics.

    python experiments/bench_workspace.py --h 0.01 --exact-fraction 0.2   # 10 mm grid, exact on 20 % of points
    python experiments/bench_workspace.py                 # 2 mm paper grid, fast mode; baselines on a subset
    python experiments/bench_workspace.py --audit         # also check the screen's error bound on the subset
    python experiments/bench_workspace.py --backends 0.004 0.002   # workspace_grid job: JAX (new, old) vs Numba path
    python experiments/bench_workspace.py --versus 6b6bd19         # Numba kernel + Table-6 parts: old vs new

The job: (1) fixed robot R = 0.200 over the whole grid (mask + every index), (2) the reconfigurable robot's
k~-optimal R* at every ODR workspace point (358 samples), (3) min/max/mean of every index for both.

Modes compared in the same process (the machine is shared: ratios are what we report, and CPU seconds,
summed over threads, next to wall seconds):

* FAST: mirror half of the grid, closed-form reach range per point, screen-and-verify (vectorised
  approximate kernel with error bounds on every sample, exact kernel on the ~1 candidate per point);
* FAST-noscreen (the previous fast mode): the exact kernel on every IK-feasible sample of the reach range;
* EXACT: every sample of every point (the paper's sweep).

The baselines run on a random subset of the ODR points (``--exact-fraction``, the same subset for both);
their rates are extrapolated to all ODR points and their selections are checked against the fast answer.
``--extrapolate-h`` rescales the measured times to another grid by the number of ODR points (h^-3).
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

# like the CLI's worker setup on this machine: one JAX host device per CPU (set before JAX starts)
os.environ.setdefault("XLA_FLAGS", f"--xla_force_host_platform_device_count={len(os.sched_getaffinity(0))}")


class _Clock:
    def __init__(self):
        self.w = time.perf_counter()
        self.c = time.process_time()

    def lap(self):
        w, c = time.perf_counter(), time.process_time()
        out = (w - self.w, c - self.c)
        self.w, self.c = w, c
        return out


def old_jax_evaluator(grid, n_devices: int, *, planes: int, b_v: float, b_f: float, beta: float, dtype=np.float64):
    """The ``workspace_grid`` JAX path before stop 20, kept as this benchmark's baseline: every point of every
    chunk (built on the host) through :func:`deltajax.workspace.evaluators.make_evaluator`, no mirror half, no
    compaction. Same call as :func:`deltajax.workspace.evaluators.make_grid_evaluator`."""
    from deltajax.workspace.evaluators import make_evaluator

    evaluate_points = make_evaluator(n_devices, b_v=b_v, b_f=b_f, beta=beta)
    plane = grid.shape[1] * grid.shape[2]
    chunk_len = -(-planes * plane // n_devices) * n_devices

    def evaluate(robot, a: int, b: int):
        idx = np.arange(a * plane, b * plane, dtype=np.int64)
        pad = np.full(chunk_len - idx.size, idx[0], np.int64)
        return evaluate_points(robot, grid.points_at(np.concatenate([idx, pad])).astype(dtype))

    return evaluate


def compare_backends(hs, old_jax: bool = True) -> None:
    """The ``workspace_grid`` job (reachability + every index + statistics, results.h5) through the JAX path, the
    old JAX path (:func:`old_jax_evaluator`, with ``old_jax``) and the Numba path, in this process, on the same
    grid: CPU s (all threads), wall s, their ratios, and the load.

    Each JAX path runs twice (the first run includes compilation; the second is the warm figure); Numba's
    machine code is cached on disk (warmed on a tiny grid first). The results must agree: the same reachable
    set and index statistics to rounding (JAX's fast singular values vs Numba's Jacobi ones), and the new JAX
    path's stored k~ field equal to the old one's to the old path's own rounding (its in-jit stack of the
    outputs compiles the kernel differently; tests/test_workspace_grid_jax.py checks the new path bit for bit
    against the kernel)."""
    import tempfile
    from pathlib import Path

    import h5py

    from deltajax.jobs import workspace_grid as wg
    from deltajax.run import run_experiment

    tmp = Path(tempfile.mkdtemp(prefix="bench_ws_"))
    common = ["plots=false", "progress=false", "experiment.resume=false"]

    def grid(h):  # the paper's grid at spacing h: z = 0, h, ..., below 0.6 m (h = 0.002: 300 planes)
        return [f"experiment.grid.h={h}", f"experiment.grid.z=[0.0,{round(round(0.6 / h - 1) * h, 9)}]"]

    run_experiment("workspace_grid", [*common, *grid(0.05), "experiment.backend=numba"], tmp / "warm")
    runs = [("jax (cold)", "jax"), ("jax", "jax"), ("numba", "numba")]
    if old_jax:
        runs = [("old jax (cold)", "old"), ("old jax", "old")] + runs
    new_evaluator = wg.make_grid_evaluator
    for h in hs:
        over = [*common, *grid(h)]
        res = {}
        for label, backend in runs:
            wg.make_grid_evaluator = old_jax_evaluator if backend == "old" else new_evaluator
            try:
                load = os.getloadavg()[0]
                clk = _Clock()
                path = run_experiment("workspace_grid", [*over, f"experiment.backend={backend.replace('old', 'jax')}"],
                                      tmp / f"{h}_{label}")
                wall, cpu = clk.lap()
            finally:
                wg.make_grid_evaluator = new_evaluator
            res[label] = (wall, cpu, path, load)
            print(f"h = {h} m  {label:14s}: {cpu:8.2f} CPU s  {wall:8.2f} s wall  (load {load:.1f})", flush=True)
        with h5py.File(res["jax"][2], "r") as a, h5py.File(res["numba"][2], "r") as b:
            same = bool(np.array_equal(a["workspace/reachable"][()], b["workspace/reachable"][()]))
            n = int(b["workspace/count"][()])
            d = max(abs(float(a[f"workspace/{k}_mean"][()]) / float(b[f"workspace/{k}_mean"][()]) - 1.0)
                    for k in ("inv_cond", "sigma_min_v", "k_tilde", "omega_v"))
        print(f"h = {h} m  RATIO jax/numba: {res['jax'][1] / res['numba'][1]:.2f}x CPU s, "
              f"{res['jax'][0] / res['numba'][0]:.2f}x wall "
              f"(cold jax {res['jax (cold)'][1] / res['numba'][1]:.2f}x CPU); "
              f"reachable sets identical: {same} ({n} points), index means agree to {d:.1e}")
        if old_jax:
            with h5py.File(res["jax"][2], "r") as a, h5py.File(res["old jax"][2], "r") as b:
                same_old = bool(np.array_equal(a["workspace/reachable"][()], b["workspace/reachable"][()]))
                ka, kb = a["workspace/k_tilde"][()], b["workspace/k_tilde"][()]
                nan_same = bool(np.array_equal(np.isnan(ka), np.isnan(kb)))
                fin = np.isfinite(kb)
                bits = int(np.count_nonzero(ka[fin].view(np.uint64) == kb[fin].view(np.uint64)))
                rel = float(np.max(np.abs(ka[fin] - kb[fin]) / np.maximum(np.abs(kb[fin]), np.finfo(kb.dtype).tiny),
                                   initial=0.0))
            print(f"h = {h} m  RATIO old jax/numba: {res['old jax'][1] / res['numba'][1]:.2f}x CPU s, "
                  f"{res['old jax'][0] / res['numba'][0]:.2f}x wall; new/old jax {res['jax'][1] / res['old jax'][1]:.2f}x "
                  f"CPU s, {res['jax'][0] / res['old jax'][0]:.2f}x wall; reachable sets identical: {same_old}, NaN "
                  f"pattern of k~ identical: {nan_same}, k~ bit-equal on {bits} of {int(fin.sum())} points, "
                  f"max relative difference {rel:.1e}")


def import_baseline(rev: str):
    """The deltajax package of git revision ``rev`` of this repository, importable as ``deltajax_<rev>``
    next to the working tree's (for old-vs-new ratios in one process; its Numba cache is kept in
    ~/.cache/deltajax_bench so that the old kernels compile once)."""
    import importlib
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).resolve().parents[1]
    rev = subprocess.run(["git", "rev-parse", "--short", rev], cwd=repo, check=True, capture_output=True,
                         text=True).stdout.strip()
    name = f"deltajax_{rev}"
    root = Path.home() / ".cache" / "deltajax_bench" / rev
    if not (root / name / "__init__.py").exists():
        root.mkdir(parents=True, exist_ok=True)
        tar = subprocess.run(["git", "archive", rev, "deltajax"], cwd=repo, check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(root)], input=tar, check=True)
        (root / "deltajax").rename(root / name)
    sys.path.insert(0, str(root))
    return importlib.import_module(name), rev


def versus(rev: str, n_points: int, h: float, repeats: int) -> None:
    """Old (git ``rev``) vs new Numba code in this process, same inputs: the kernel rates of
    :func:`deltajax.benchmarks.numba_loops.bench_kernel_rates` (M eval per CPU-s; single thread) and the two Numba
    parts of the Table-6 job on the ``h`` grid: ODR fields (``fixed_workspace``, every index) and the RDR
    redundancy resolution (fast mode, screen-and-verify) of the mirror-unique ODR points, CPU s (all threads)
    and wall s; the selections must be identical."""
    import importlib

    import deltajax as dj

    old, rev = import_baseline(rev)
    try:   # where the old revision keeps its Numba benchmark hooks (moved out of the library)
        nb_old = importlib.import_module(f"{old.__name__}.benchmarks.numba_loops")
    except ModuleNotFoundError:
        nb_old = importlib.import_module(f"{old.__name__}.workspace._nb_bench")
    from deltajax.benchmarks import numba_loops as nb_new

    rng = np.random.default_rng(0)
    pts = rng.uniform([-0.45, -0.45, 0.0], [0.45, 0.45, 0.6], (n_points, 3))
    geo = [0.2, 0.065, 0.2, 0.4, float(dj.presets.franco2026().robot.theta_min),
           float(dj.presets.franco2026().robot.theta_max)]
    print(f"old = {rev}, new = working tree; CPUs {len(os.sched_getaffinity(0))}; load {os.getloadavg()}")
    nb_old.bench_kernel_rates(pts[:1000], geo, 1), nb_new.bench_kernel_rates(pts[:1000], geo, 1)  # compile
    a = nb_old.bench_kernel_rates(pts, geo, repeats)
    b = nb_new.bench_kernel_rates(pts, geo, repeats)
    print(f"KERNEL (Numba, 1 thread, best of {repeats}; {n_points} random points, load {os.getloadavg()[0]:.1f})")
    print(f"  {'label':34s} {'old M/CPU-s':>12s} {'new M/CPU-s':>12s} {'new/old':>8s}   (new wall s)")
    for label in b:
        ra = a[label][0] / a[label][2] / 1e6 if label in a else float("nan")
        rb = b[label][0] / b[label][2] / 1e6
        print(f"  {label:34s} {ra:12.1f} {rb:12.1f} {rb / ra:8.2f}x   ({b[label][1]:.3f})")

    res = {}
    for tag, pkg in (("old", old), ("new", dj)):
        wsp = pkg.workspace
        rec, fixed = pkg.presets.franco2026(), pkg.presets.franco2026(fixed_R=0.2)
        small = wsp.franco2026_grid(0.05)
        wsp.redundancy_grid(rec, small, mask=wsp.fixed_workspace(fixed, small).ok)  # compile
        grid = wsp.franco2026_grid(h)
        load = os.getloadavg()[0]
        clk = _Clock()
        odr = wsp.fixed_workspace(fixed, grid, fields=True, field_dtype=np.float32)
        t_odr = clk.lap()
        pts_odr = grid.points_at(np.flatnonzero(odr.ok.reshape(-1)))
        clk.lap()
        red, work = wsp.resolve_redundancy_host(rec, pts_odr, "k_tilde", mode="fast", return_indices=False)
        t_rdr = clk.lap()
        res[tag] = (t_odr, t_rdr, red, work, load, odr)
    (o_odr, o_rdr, o_red, o_w, o_load, o_f), (n_odr, n_rdr, n_red, n_w, n_load, n_f) = res["old"], res["new"]
    same = bool(np.array_equal(o_red.k, n_red.k) and np.array_equal(o_f.ok, n_f.ok))
    ok = n_red.ok
    dv = float(np.max(np.abs(n_red.value[ok] / o_red.value[ok] - 1.0), initial=0.0))
    print(f"TABLE-6 PARTS (h = {h} m, {len(o_red.k)} ODR points, {o_w['points']} solved; load old {o_load:.1f}, "
          f"new {n_load:.1f})")
    for name, a_, b_ in (("ODR fields", o_odr, n_odr), ("RDR resolve", o_rdr, n_rdr)):
        print(f"  {name:12s} old {a_[1]:7.2f} CPU-s {a_[0]:7.2f} s wall | new {b_[1]:7.2f} CPU-s {b_[0]:7.2f} s wall | "
              f"old/new {a_[1] / b_[1]:.2f}x CPU, {a_[0] / b_[0]:.2f}x wall")
    print(f"  RDR screened samples {o_w['screened']} -> {n_w['screened']}, exact kernels {o_w['full']} -> "
          f"{n_w['full']}, fallbacks {n_w['fallback']}; identical reachable set and R*: {same}; k~ at R* agrees to "
          f"{dv:.1e} (the exact kernel's rounding)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--h", type=float, default=0.002)
    ap.add_argument("--beta", type=float, default=0.5)
    ap.add_argument("--exact-fraction", type=float, default=0.01)
    ap.add_argument("--extrapolate-h", type=float, default=0.002)
    ap.add_argument("--audit", action="store_true", help="check the screen's bound on every subset sample")
    ap.add_argument("--backends", type=float, nargs="+", metavar="H",
                    help="only compare the workspace_grid job's JAX and Numba paths on grids of these spacings (m)")
    ap.add_argument("--no-old-jax", action="store_true", help="--backends: leave out the old JAX path (baseline)")
    ap.add_argument("--versus", metavar="REV", help="old (git REV) vs new Numba code: kernel rates and the "
                    "Table-6 job's ODR/RDR parts on the --h grid, in this process")
    ap.add_argument("--points", type=int, default=400_000, help="--versus: random points of the kernel rates")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    if args.versus:
        versus(args.versus, args.points, args.h, args.repeats)
        return
    if args.backends:
        compare_backends(args.backends, old_jax=not args.no_old_jax)
        return
    import deltajax as dj
    from deltajax import workspace as ws
    from deltajax.workspace import numba_fields
    from deltajax.workspace.redundancy import nb_params

    rec = dj.presets.franco2026()
    fixed = dj.presets.franco2026(fixed_R=0.2)
    grid = ws.franco2026_grid(args.h)
    print(f"grid {grid.shape}: {grid.n_points} points x {rec.n_R} R samples; CPUs {len(os.sched_getaffinity(0))}; "
          f"load {os.getloadavg()}")
    # warm-up (Numba compile, cached on disk) on a tiny grid
    small = ws.franco2026_grid(0.05)
    f0 = ws.fixed_workspace(fixed, small)
    ws.redundancy_grid(rec, small, mask=f0.ok)
    ws.redundancy_grid(rec, small, mask=f0.ok, screen=False)
    ws.resolve_redundancy_host(rec, small.points()[:100], mode="exact")

    clk = _Clock()
    odr = ws.fixed_workspace(fixed, grid, fields=True, field_dtype=np.float32, beta=args.beta)
    t_odr = clk.lap()
    work: dict = {}
    rdr = ws.redundancy_grid(rec, grid, mask=odr.ok, mode="fast", beta=args.beta, field_dtype=np.float32, work=work)
    t_rdr = clk.lap()
    s_rdr = ws.index_stats(rdr.fields, odr.ok)
    s_odr = ws.index_stats(odr.fields, odr.ok)
    t_st = clk.lap()
    n_odr = int(odr.ok.sum())
    fast = [a + b + c for a, b, c in zip(t_odr, t_rdr, t_st)]
    print(f"FAST  total {fast[0]:.2f} s wall / {fast[1]:.2f} s CPU  (ODR fields {t_odr[0]:.2f}, RDR {t_rdr[0]:.2f}, "
          f"stats {t_st[0]:.2f} s wall)")
    print(f"      ODR points {n_odr}; RDR solved {work['points']} mirror-unique points: {work['screened']} samples "
          f"screened ({work['screened'] / t_rdr[1] / 1e6:.1f} M/s per CPU-s), {work['full']} exact kernels "
          f"({work['full'] / max(1, work['points']):.3f} per point), {work['fallback']} fallbacks; "
          f"{n_odr * rec.n_R / t_rdr[0] / 1e6:.0f} M (point, R) pairs/s equivalent")

    # baselines on a random subset of ODR points
    idx = np.flatnonzero(odr.ok.reshape(-1))
    rng = np.random.default_rng(0)
    sub = np.sort(rng.choice(idx, max(1, int(args.exact_fraction * len(idx))), replace=False))
    pts = grid.points_at(sub)
    frac = len(sub) / n_odr
    ref_k = rdr.fields["k_star"].reshape(-1)[sub]
    ref_v = rdr.fields["k_tilde"].reshape(-1)[sub]
    clk.lap()
    fs, wfs = ws.resolve_redundancy_host(rec, pts, "k_tilde", mode="fast", beta=args.beta, return_indices=True)
    t_fs = clk.lap()
    ns, wns = ws.resolve_redundancy_host(rec, pts, "k_tilde", mode="fast", beta=args.beta, screen=False,
                                         return_indices=True)
    t_ns = clk.lap()
    ex, wex = ws.resolve_redundancy_host(rec, pts, "k_tilde", mode="exact", beta=args.beta, return_indices=True)
    t_ex = clk.lap()
    same = (np.array_equal(ex.k, ref_k) and np.array_equal(ns.k, ref_k) and np.array_equal(fs.k, ref_k)
            and np.array_equal(ex.value, ns.value) and np.array_equal(ex.value, fs.value)
            and np.array_equal(ex.indices, fs.indices)
            and np.array_equal(ex.indices[:, 5].astype(np.float32), ref_v))
    print(f"SUBSET {len(sub)} ODR points ({100 * frac:.1f} %), same points for all modes; identical k, values and "
          f"indices (and = the grid job's): {same}")
    for name, t, w in (("fast", t_fs, wfs), ("noscreen", t_ns, wns), ("exact", t_ex, wex)):
        print(f"      {name:9s} {t[0]:7.2f} s wall {t[1]:7.2f} s CPU  {len(sub) / t[1]:9.0f} points/CPU-s  "
              f"exact kernels {w['full']:10d} ({w['full'] / max(1, w['points']):7.2f} per solved point)"
              + (f"  screened {w['screened'] / t[1] / 1e6:.1f} M samples/CPU-s" if w["screened"] else ""))
    r_ns = t_ns[1] / t_fs[1]
    r_ex = t_ex[1] / t_fs[1]
    print(f"RATIO (CPU, subset, RDR part): noscreen/fast {r_ns:.1f}x, exact/fast {r_ex:.1f}x "
          f"(exact/noscreen {t_ex[1] / t_ns[1]:.2f}x)")
    # the whole job: ODR + stats as measured, RDR of the baselines extrapolated from the subset: the previous
    # fast mode solves the mirror-unique ODR points (as the grid job above), the exact mode every ODR point
    rdr_ns = t_ns[1] / len(sub) * work["points"]
    rdr_ex = t_ex[1] / len(sub) * n_odr
    other = t_odr[1] + t_st[1]
    print(f"JOB (CPU s, h = {args.h}): fast {fast[1]:.1f} (RDR {t_rdr[1]:.1f}); noscreen ~{other + rdr_ns:.1f} "
          f"(RDR {rdr_ns:.1f}); exact ~{other + rdr_ex:.1f} (RDR {rdr_ex:.1f}); ODR {t_odr[1]:.1f} + stats "
          f"{t_st[1]:.1f} in each. Ratios RDR part: noscreen/fast {rdr_ns / t_rdr[1]:.1f}x, exact/fast "
          f"{rdr_ex / t_rdr[1]:.1f}x; whole job: noscreen/fast {(other + rdr_ns) / fast[1]:.1f}x, exact/fast "
          f"{(other + rdr_ex) / fast[1]:.1f}x")
    scale = (args.h / args.extrapolate_h) ** 3
    ncpu = len(os.sched_getaffinity(0))
    print(f"EXTRAPOLATED to h = {args.extrapolate_h} (x{scale:.0f} points), CPU s / {ncpu} cores as ideal wall s: "
          f"fast {fast[1] * scale:.0f} / {fast[1] * scale / ncpu:.0f}; noscreen {(other + rdr_ns) * scale:.0f} / "
          f"{(other + rdr_ns) * scale / ncpu:.0f}; exact {(other + rdr_ex) * scale:.0f} / "
          f"{(other + rdr_ex) * scale / ncpu:.0f}")
    if args.audit:
        q = nb_params(rec)
        uniq = np.ascontiguousarray(pts)
        k_lo, k_stop = ws.reach_k_range_host(rec, uniq)
        out = np.empty((len(uniq), 4))
        numba_fields.screen_audit(uniq, k_lo, k_stop, q["R_min"], q["R_step"], q["r"], q["L1"], q["L2"], q["lim"],
                         numba_fields.kt_tuple(2.0, 4.2, args.beta), numba_fields.CRITERION["k_tilde"], out)
        print(f"AUDIT {int(out[:, 3].sum())} feasible samples: max |k~ screen - exact| {out[:, 0].max():.3g}, "
              f"max error / bound {out[:, 1].max():.3g}, violations {int(out[:, 2].sum())}")
    print(f"Table 6 check (beta {args.beta}): RDR omega_v mean {s_rdr['omega_v']['mean']:.4f}, "
          f"ODR {s_odr['omega_v']['mean']:.4f}")


if __name__ == "__main__":
    main()
