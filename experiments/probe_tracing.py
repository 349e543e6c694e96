"""What a run of the main job traces, lowers and compiles, run after run in one process (jax.monitoring).

    python experiments/probe_tracing.py            # the suite's toy size (tests/toy_jobs.py), two runs
    python experiments/probe_tracing.py --runs 3 --defaults

Per run: wall, CPU-s, and the totals of JAX's monitoring events (jaxpr tracing, lowering to MLIR, backend
compilation, persistent-cache hits and retrieval time), then the programs whose tracing took longest
(``jax_log_compiles``). The first run of a process with a warm persistent cache shows what every new process
pays; the second, what a warm process still re-traces.
"""

from __future__ import annotations

import argparse
import collections
import logging
import re
import resource
import sys
import tempfile
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.monitoring as mon  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--defaults", action="store_true", help="the job's default size instead of the toy size")
    a = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT / "tests"))
    from toy_jobs import COMMON, TOY

    from deltajax.run import run_experiment

    events = collections.defaultdict(lambda: [0, 0.0])
    traces = []

    def on_duration(name, secs, **kw):
        events[name][0] += 1
        events[name][1] += secs

    def on_event(name, **kw):
        events[name][0] += 1

    mon.register_event_duration_secs_listener(on_duration)
    mon.register_event_listener(on_event)

    class Traces(logging.Handler):
        def emit(self, rec):
            m = re.search(r"Finished tracing (\S+) for jit in ([0-9.e-]+) sec", rec.getMessage())
            if m:
                traces.append((m[1], float(m[2])))

    jax.config.update("jax_log_compiles", True)
    lg = logging.getLogger("jax")
    lg.addHandler(Traces())
    lg.propagate = False  # the compile log goes to the handler only
    extra = [] if a.defaults else TOY["ga_reconfig"]
    for i in range(a.runs):
        events.clear()
        traces.clear()
        c0, t0 = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
        with tempfile.TemporaryDirectory() as d:
            run_experiment("ga_reconfig", [*COMMON, "plots=false", *extra], run_dir=Path(d) / "run")
        c1 = resource.getrusage(resource.RUSAGE_SELF)
        print(f"=== run {i + 1}: {time.perf_counter() - t0:.1f} s wall, "
              f"{c1.ru_utime + c1.ru_stime - c0.ru_utime - c0.ru_stime:.1f} CPU-s", flush=True)
        for k, (n, s) in sorted(events.items()):
            print(f"  {k:60s} n={n:5d}" + (f" {s:8.2f} s" if s else ""))
        top = collections.defaultdict(lambda: [0, 0.0])
        for name, s in traces:
            top[name][0] += 1
            top[name][1] += s
        for name, (n, s) in sorted(top.items(), key=lambda kv: -kv[1][1])[:8]:
            print(f"  traced {name:30s} x{n:3d} {s:7.2f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
