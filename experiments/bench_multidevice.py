"""Speed-up from sharding a workspace-grid chunk over several JAX host devices of one machine.

    python experiments/bench_multidevice.py                     # 1 device vs one per CPU, 10^6 points, f64
    python experiments/bench_multidevice.py --devices 1,2,4 --points 2000000 --precision float32

The device count of the CPU backend is fixed when JAX starts (``--xla_force_host_platform_device_count``),
so each configuration runs in its own subprocess that sets it before importing JAX; every subprocess has
the same XLA thread pool (``PJRT_NPROC`` = the CPUs given). Each evaluates the same chunk of the franco2026
paper grid (x-planes from x = -0.2 m, the full y-z planes) with the kernel of ``experiment=workspace_grid``
(:func:`deltajax.experiments.workspace_grid.make_evaluator`: reachability + every index), reports compile
time separately from the warm time (best of ``--reps``), and a hash of the outputs. Configurations are run
in alternating rounds (1, n, 1, n, ...) so that load from other processes hits them alike; the ratio uses
the median over rounds of each configuration's best time. Also checks that the outputs are bit-identical
for every device count. ``--numba`` adds ``experiment.backend=numba`` (the workspace engine's parallel Numba
kernel with ``--threads`` threads, which also halves the work by the robot's y -> -y symmetry).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time


def _cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover
        return os.cpu_count() or 1


def child(args) -> None:
    flags = os.environ.get("XLA_FLAGS", "")
    os.environ["XLA_FLAGS"] = f"{flags} --xla_force_host_platform_device_count={args.n_devices}".strip()
    os.environ["PJRT_NPROC"] = str(args.threads)
    os.environ["NUMBA_NUM_THREADS"] = str(args.threads)
    import hashlib

    import jax

    jax.config.update("jax_enable_x64", args.precision == "float64")
    import numpy as np

    import deltajax as dj
    from deltajax.experiments.workspace_grid import make_evaluator
    from deltajax.workspace import franco2026_grid

    assert jax.local_device_count() == args.n_devices, jax.devices()
    grid = franco2026_grid(0.002)
    nx, ny, nz = grid.shape
    plane = ny * nz
    planes = max(1, args.points // plane)
    i0 = int(np.searchsorted(grid.x, -0.2))
    n = planes * plane
    n_pad = -(-n // args.n_devices) * args.n_devices
    idx = np.arange(i0 * plane, i0 * plane + n_pad, dtype=np.int64)
    dtype = np.float64 if args.precision == "float64" else np.float32
    pts = grid.points_at(idx).astype(dtype)
    robot = dj.presets.franco2026(fixed_R=0.2)
    if args.precision == "float32":
        robot = jax.tree_util.tree_map(lambda a: a.astype(np.float32) if hasattr(a, "astype") else a, robot)
    if args.numba:  # the workspace engine's Numba kernel on the same planes (mirror halving included)
        from deltajax.experiments.workspace_grid import make_numba_evaluator

        ev_nb = make_numba_evaluator(grid, b_v=2.0, b_f=4.2, beta=0.5)

        def call():
            return ev_nb(robot, i0, i0 + planes)
    else:
        evaluate = make_evaluator(args.n_devices, b_v=2.0, b_f=4.2, beta=0.5)

        def call():
            return jax.block_until_ready(evaluate(robot, pts))
    t0 = time.perf_counter()
    ok, vals = call()
    compile_s = time.perf_counter() - t0
    times = []
    for _ in range(args.reps):
        t0 = time.perf_counter()
        ok, vals = call()
        times.append(time.perf_counter() - t0)
    ok, vals = np.asarray(ok)[:n], np.asarray(vals)[:n]
    digest = hashlib.sha256(ok.tobytes() + vals.tobytes()).hexdigest()[:16]
    print(json.dumps({"devices": "numba" if args.numba else args.n_devices, "points": n, "compile_s": compile_s, "best_s": min(times),
                      "median_s": statistics.median(times), "reachable": int(ok.sum()), "hash": digest}))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--devices", default=None, help="comma-separated device counts (default: 1,<CPUs>)")
    ap.add_argument("--points", type=int, default=1_000_000, help="points per evaluation (whole y-z planes)")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=2, help="alternating rounds over the configurations")
    ap.add_argument("--threads", type=int, default=_cpus(), help="XLA threads (PJRT_NPROC) in every run")
    ap.add_argument("--precision", choices=("float64", "float32"), default="float64")
    ap.add_argument("--numba", action="store_true",
                    help="also time experiment.backend=numba (the workspace engine's Numba kernel, --threads threads)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--n-devices", type=int, default=1, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(args)
        return 0
    counts: list = [int(c) for c in (args.devices or f"1,{max(2, _cpus())}").split(",")]
    if args.numba:
        counts.append("numba")
    env = dict(os.environ)
    env.pop("XLA_FLAGS", None)
    env.pop("JAX_NUM_CPU_DEVICES", None)
    results: dict[int, list[dict]] = {c: [] for c in counts}
    for r in range(args.rounds):
        for c in counts:
            cmd = [sys.executable, os.path.abspath(__file__), "--child", "--n-devices", str(1 if c == "numba" else c),
                   "--points", str(args.points), "--reps", str(args.reps), "--threads", str(args.threads),
                   "--precision", args.precision] + (["--numba"] if c == "numba" else [])
            out = subprocess.run(cmd, env=env, capture_output=True, text=True)
            if out.returncode != 0:
                print(out.stdout, out.stderr, file=sys.stderr)
                return 1
            res = json.loads(out.stdout.strip().splitlines()[-1])
            results[c].append(res)
            print(f"round {r}: {c} device(s): compile {res['compile_s']:.2f} s, best {res['best_s']:.3f} s "
                  f"({res['points'] / res['best_s'] / 1e6:.2f} M points/s)", flush=True)
    base = statistics.median(r["best_s"] for r in results[counts[0]])
    n = results[counts[0]][0]["points"]
    print(f"\n{n} points ({args.precision}, franco2026 grid chunk), {args.threads} XLA threads, "
          f"{_cpus()} CPUs; median over {args.rounds} rounds of the best of {args.reps}")
    print("| devices | warm time (s) | M points/s | speed-up vs 1st | compile (s) |")
    print("|---|---|---|---|---|")
    for c in counts:
        t = statistics.median(r["best_s"] for r in results[c])
        comp = statistics.median(r["compile_s"] for r in results[c])
        print(f"| {c} | {t:.3f} | {n / t / 1e6:.2f} | {base / t:.2f}x | {comp:.1f} |")
    hashes = {r["hash"] for c, rs in results.items() if c != "numba" for r in rs}
    print(f"JAX outputs bit-identical across device counts: {len(hashes) == 1} ({', '.join(sorted(hashes))})")
    if args.numba:
        same = {r["reachable"] for rs in results.values() for r in rs}
        print(f"numba: same reachable count as JAX: {len(same) == 1} (numba evaluates the y >= 0 half and "
              f"mirrors it; its values agree with JAX to rounding, not bit for bit)")
    return 0 if len(hashes) == 1 else 2


if __name__ == "__main__":
    sys.exit(main())
