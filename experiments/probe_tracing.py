"""What a run of the main job traces, lowers and compiles, run after run in one process (jax.monitoring).

    python experiments/probe_tracing.py            # the suite's toy size (tests/toy_jobs.py), two runs
    python experiments/probe_tracing.py --runs 3 --defaults

Per run: wall, CPU-s, and the totals of JAX's monitoring events (jaxpr tracing, lowering to MLIR, backend
compilation, persistent-cache hits and retrieval time), then the programs whose tracing took longest
(``jax_log_compiles``). The first run of a process with a warm persistent cache shows what every new process
pays; the second, what a warm process still re-traces.

``--reads N``: every executable read back from the persistent compilation cache, timed (wall, and the process's
CPU-s, which also count what other threads do meanwhile; the reading itself runs on a PJRT thread, so the
caller's thread time does not see it): the total per stage, and the N slowest reads with their stage,
serialised size and number of compiled kernels (XLA:CPU rebuilds the optimised HLO module and its buffer
assignment from the serialised proto and links each kernel's object code: the cost follows the program's size).
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
    ap.add_argument("--reads", type=int, default=0, metavar="N", help="list the N slowest executable reads")
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

    reads = _time_reads() if a.reads else None
    jax.config.update("jax_log_compiles", True)
    lg = logging.getLogger("jax")
    lg.addHandler(Traces())
    lg.propagate = False  # the compile log goes to the handler only
    extra = [] if a.defaults else TOY["ga_reconfig"]
    for i in range(a.runs):
        events.clear()
        traces.clear()
        if reads is not None:
            reads.clear()
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
        if reads is not None:
            _print_reads(reads, a.reads)
    return 0


def _time_reads() -> list:
    """Records each persistent-cache read as [wall s, process CPU-s, serialised bytes, kernels, stage] (the stage
    filled in when the stage engine marks it done)."""
    from jax._src import compilation_cache as cc

    from deltajax.jobs import stages

    reads: list = []
    last = {}
    get, extract, mark = cc.get_executable_and_time, cc.extract_executable_and_time, stages.Runner.mark

    def extract_sized(data):
        out = extract(data)
        last["size"], last["kernels"] = len(out[0]), out[0].count(b"\x7fELF")
        return out

    def timed_get(*args, **kwargs):
        last.clear()
        t0, c0 = time.perf_counter(), time.process_time()
        out = get(*args, **kwargs)
        if out[0] is not None:
            reads.append([time.perf_counter() - t0, time.process_time() - c0, last.get("size", 0),
                          last.get("kernels", 0), None])
        return out

    def marking(self, name, *args, **kwargs):
        for r in reads:
            r[4] = r[4] or name
        return mark(self, name, *args, **kwargs)

    cc.extract_executable_and_time = extract_sized
    cc.get_executable_and_time = timed_get       # jax's compiler calls it through this module
    stages.Runner.mark = marking
    return reads


def _print_reads(reads: list, n: int) -> None:
    where = [stage or "after the last stage" for *_, stage in reads]
    by_stage = collections.defaultdict(lambda: [0, 0.0])
    for (t, *_), w in zip(reads, where):
        by_stage[w][0] += 1
        by_stage[w][1] += t
    print(f"  executables read: {len(reads)}, {sum(r[0] for r in reads):.2f} s wall, "
          f"{sum(r[1] for r in reads):.2f} CPU-s; wall by stage (reads): "
          + ", ".join(f"{k} {s:.2f} ({c})" for k, (c, s) in by_stage.items()))
    for (t, c, size, kernels, _), w in sorted(zip(reads, where), key=lambda rw: -rw[0][0])[:n]:
        print(f"  read {t:6.2f} s {c:6.2f} CPU-s {size / 1e6:6.1f} MB {kernels:5d} kernels ({w})")


if __name__ == "__main__":
    raise SystemExit(main())
