"""Speed-up from sharding a workspace-grid chunk over several JAX host devices of one machine.

    python experiments/bench_multidevice.py                      # 1 device vs one per CPU, 10^6 points, f64
    python experiments/bench_multidevice.py --devices 1,2,4 --points 2000000 --precision float32 --numba

The CPU backend's device count is fixed when JAX starts (``--xla_force_host_platform_device_count``), so the
benchmark re-runs itself in a subprocess that sets it (to the largest count asked for) before importing JAX,
with an XLA thread pool of ``--threads`` threads (``PJRT_NPROC``). There it builds the kernel of
``experiment=workspace_grid`` (:func:`deltajax.jobs.workspace_grid.make_evaluator`: reachability + every
index) once per device count, sharded over a mesh of the first k devices, and evaluates the same chunk of
the franco2026 paper grid (whole y-z planes from x = -0.2 m). Compile time is reported apart from warm time;
the warm repetitions of all configurations are interleaved (1, n, 1, n, ...) so that load from other
processes on a shared machine hits them alike, and the speed-up is the ratio of the median times (best
times also shown). The outputs must be bit-identical for every device count. ``--numba`` adds
``experiment.backend=numba`` (the workspace engine's parallel Numba kernel with ``--threads`` threads, which
also halves the work by the robot's y -> -y symmetry).
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
    counts = [int(c) for c in args.devices.split(",")]
    flags = os.environ.get("XLA_FLAGS", "")
    os.environ["XLA_FLAGS"] = f"{flags} --xla_force_host_platform_device_count={max(counts)}".strip()
    os.environ["PJRT_NPROC"] = str(args.threads)
    os.environ["NUMBA_NUM_THREADS"] = str(args.threads)
    import hashlib

    import jax

    jax.config.update("jax_enable_x64", args.precision == "float64")
    import numpy as np

    import deltajax as dj
    from deltajax.jobs.workspace_grid import make_evaluator, make_numba_evaluator
    from deltajax.workspace import franco2026_grid

    assert jax.local_device_count() == max(counts), jax.devices()
    grid = franco2026_grid(0.002)
    nx, ny, nz = grid.shape
    plane = ny * nz
    planes = max(1, args.points // plane)
    i0 = int(np.searchsorted(grid.x, -0.2))
    n = planes * plane
    dtype = np.float64 if args.precision == "float64" else np.float32
    robot = dj.presets.franco2026(fixed_R=0.2)
    if args.precision == "float32":
        robot = jax.tree_util.tree_map(lambda a: a.astype(np.float32) if hasattr(a, "astype") else a, robot)
    calls = {}
    for c in counts:
        n_pad = -(-n // c) * c
        pts = grid.points_at(np.arange(i0 * plane, i0 * plane + n_pad, dtype=np.int64)).astype(dtype)
        ev = make_evaluator(c, b_v=2.0, b_f=4.2, beta=0.5)
        calls[str(c)] = (lambda ev=ev, pts=pts: jax.block_until_ready(ev(robot, pts)))
    if args.numba:
        ev_nb = make_numba_evaluator(grid, b_v=2.0, b_f=4.2, beta=0.5)
        calls["numba"] = lambda: ev_nb(robot, i0, i0 + planes)
    res = {}
    for name, call in calls.items():
        t0 = time.perf_counter()
        ok, vals = call()
        ok, vals = np.asarray(ok)[:n], np.asarray(vals)[:n]
        res[name] = {"compile_s": time.perf_counter() - t0, "times": [], "reachable": int(ok.sum()),
                     "hash": hashlib.sha256(ok.tobytes() + vals.astype(dtype).tobytes()).hexdigest()[:16]}
    for _ in range(args.reps):
        for name, call in calls.items():
            t0 = time.perf_counter()
            call()
            res[name]["times"].append(time.perf_counter() - t0)
    print(json.dumps({"points": n, "results": res}))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--devices", default=None, help="comma-separated device counts (default: 1,<CPUs>)")
    ap.add_argument("--points", type=int, default=1_000_000, help="points per evaluation (whole y-z planes)")
    ap.add_argument("--reps", type=int, default=10, help="interleaved warm repetitions of each configuration")
    ap.add_argument("--threads", type=int, default=_cpus(), help="XLA (and Numba) threads in every configuration")
    ap.add_argument("--precision", choices=("float64", "float32"), default="float64")
    ap.add_argument("--numba", action="store_true", help="also time experiment.backend=numba")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    args.devices = args.devices or f"1,{max(2, _cpus())}"
    if args.child:
        child(args)
        return 0
    env = dict(os.environ)
    env.pop("XLA_FLAGS", None)
    env.pop("JAX_NUM_CPU_DEVICES", None)
    cmd = [sys.executable, os.path.abspath(__file__), "--child", *sys.argv[1:]] if argv is None else \
        [sys.executable, os.path.abspath(__file__), "--child", *argv]
    if "--devices" not in cmd:
        cmd += ["--devices", args.devices]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if out.returncode != 0:
        print(out.stdout, out.stderr, file=sys.stderr)
        return 1
    data = json.loads(out.stdout.strip().splitlines()[-1])
    res, n = data["results"], data["points"]
    names = list(res)
    base_med = statistics.median(res[names[0]]["times"])
    base_best = min(res[names[0]]["times"])
    try:
        load = os.getloadavg()[0]
    except OSError:  # pragma: no cover
        load = float("nan")
    print(f"{n} points ({args.precision}, franco2026 2 mm grid, x-planes from -0.2 m), {args.threads} threads, "
          f"{_cpus()} CPUs, load average {load:.1f}; {args.reps} interleaved warm repetitions each")
    print("| configuration | median (s) | best (s) | M points/s (median) | speed-up (median / best) | compile (s) |")
    print("|---|---|---|---|---|---|")
    for name in names:
        t = res[name]["times"]
        med, best = statistics.median(t), min(t)
        label = f"JAX, {name} device(s)" if name != "numba" else f"Numba, {args.threads} threads"
        print(f"| {label} | {med:.3f} | {best:.3f} | {n / med / 1e6:.2f} | {base_med / med:.2f}x / "
              f"{base_best / best:.2f}x | {res[name]['compile_s']:.1f} |")
    hashes = {res[k]["hash"] for k in names if k != "numba"}
    print(f"JAX outputs bit-identical across device counts: {len(hashes) == 1} ({', '.join(sorted(hashes))})")
    if "numba" in res:
        same = len({res[k]["reachable"] for k in names}) == 1
        print(f"Numba finds the same reachable points count: {same} (its index values agree with JAX to "
              f"rounding, not bit for bit)")
    return 0 if len(hashes) == 1 else 2


if __name__ == "__main__":
    sys.exit(main())
