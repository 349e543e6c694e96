"""Writing and reading a results file: today's :mod:`deltajax.io` against an earlier version, in one process.

    python experiments/bench_io.py --old-ref 6915047                  # a toy main-job run's results.h5
    python experiments/bench_io.py --old-ref 6915047 --file outputs/ga_reconfig/<run>/results.h5 --rounds 7

Every run of a job flushes its results file after each stage (the whole file, atomically: the main job ~16 times)
and its later stages read it back (``load``, verified against the integrity record), so the same file is written
and read many times per run. This stages ``--file``'s contents (default: a toy main-job run made here, the suite's
sizes) in a :class:`deltajax.io.ResultsFile` of each version and times, in interleaved rounds, one flush and one
verified load: median CPU and wall seconds per call, and the ratios old / new. Both versions must write the same
bytes and read the same contents (checked; a difference is an error, not a figure). The earlier version is
``deltajax/io/`` as ``git show <old-ref>``, loaded as its own package beside today's.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def load_old(ref: str) -> types.ModuleType:
    """``deltajax/io`` as of git ``ref``, as the package ``deltajax._bench_old_io``."""
    name = "deltajax._bench_old_io"
    pkg = types.ModuleType(name)
    pkg.__path__ = []
    pkg.__package__ = name
    sys.modules[name] = pkg

    def show(path: str) -> str:
        return subprocess.run(["git", "show", f"{ref}:{path}"], cwd=ROOT, check=True, capture_output=True,
                              text=True).stdout

    for sub in ("integrity", "reader"):
        mod = types.ModuleType(f"{name}.{sub}")
        mod.__package__ = name
        sys.modules[mod.__name__] = mod
        exec(compile(show(f"deltajax/io/{sub}.py"), f"<{mod.__name__}>", "exec"), mod.__dict__)
        setattr(pkg, sub, mod)
    exec(compile(show("deltajax/io/__init__.py"), f"<{name}>", "exec"), pkg.__dict__)
    return pkg


def toy_results(folder: Path) -> Path:
    """A toy main-job run's results file (the suite's sizes, tests/toy_jobs.py)."""
    sys.path.insert(0, str(ROOT / "tests"))
    from toy_jobs import COMMON, TOY

    from deltajax.run import run_experiment

    run_experiment("ga_reconfig", [*COMMON, *TOY["ga_reconfig"], "plots=false"], run_dir=folder / "run")
    return folder / "run" / "results.h5"


def staged(io, contents, path: Path):
    """A ResultsFile of module ``io`` at ``path`` holding ``contents`` (:func:`deltajax.io.read`'s)."""
    res = io.ResultsFile(path, attrs=contents.attrs)
    for g, variables in contents.variables.items():
        if variables:
            res.put_variables(g, variables)
    for g, attrs in contents.group_attrs.items():
        if g and attrs:
            res.set_attrs(g, **attrs)
    return res


def _same(a, b, where="") -> list:
    """Where two nested results (``load``'s dicts) differ."""
    import numpy as np

    if isinstance(a, dict) and isinstance(b, dict):
        out = [f"{where}: keys {sorted(set(a) ^ set(b))}"] if set(a) != set(b) else []
        for k in set(a) & set(b):
            out += _same(a[k], b[k], f"{where}/{k}")
        return out
    a, b = np.asarray(a), np.asarray(b)
    ok = a.dtype == b.dtype and a.shape == b.shape and (a.tobytes() == b.tobytes() if a.dtype != object
                                                          else a.tolist() == b.tolist())
    return [] if ok else [where]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--old-ref", required=True, help="git ref of the earlier deltajax/io")
    ap.add_argument("--file", type=Path, default=None, help="a results file (default: a toy main-job run's)")
    ap.add_argument("--rounds", type=int, default=5)
    a = ap.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import deltajax.io as new

    old = load_old(a.old_ref)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        src = a.file or toy_results(tmp)
        contents = new.read(src, verify=True)
        n_sets = sum(len(v) for v in contents.variables.values())
        files = {"old": staged(old, contents, tmp / "old.h5"), "new": staged(new, contents, tmp / "new.h5")}
        times = {k: {"flush": [], "load": []} for k in files}
        for _ in range(a.rounds):
            for k, io in (("old", old), ("new", new)):
                for what, call in (("flush", files[k].flush), ("load", lambda: io.load(files[k].path))):
                    c, w = time.process_time(), time.perf_counter()
                    call()
                    times[k][what].append((time.process_time() - c, time.perf_counter() - w))
        a_bytes, b_bytes = files["old"].path.read_bytes(), files["new"].path.read_bytes()
        if a_bytes != b_bytes:
            raise SystemExit("the two versions wrote different bytes")
        diff = _same(old.load(files["new"].path), new.load(files["old"].path))
        if diff:
            raise SystemExit(f"the two versions read different contents: {diff[:5]}")
        print(f"{src.name}: {n_sets} datasets in {len(contents.variables)} groups, {len(a_bytes) / 1e6:.2f} MB; "
              f"old = {a.old_ref}; {a.rounds} interleaved rounds, median; load {os.getloadavg()[0]:.1f}")
        for what in ("flush", "load"):
            med = {k: [statistics.median(t[i] for t in times[k][what]) for i in (0, 1)] for k in files}
            print(f"  {what:5s}: old {med['old'][0]:.3f} CPU-s ({med['old'][1]:.3f} s wall), new {med['new'][0]:.3f} "
                  f"CPU-s ({med['new'][1]:.3f} s wall): {med['old'][0] / med['new'][0]:.2f}x CPU, "
                  f"{med['old'][1] / med['new'][1]:.2f}x wall")
        print("  the same bytes written and the same contents read by both versions")
    return 0


if __name__ == "__main__":
    sys.exit(main())
