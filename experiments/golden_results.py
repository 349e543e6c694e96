"""Every CLI job's toy-size results, run before and after a change, compared dataset by dataset.

    python experiments/golden_results.py run golden/before          # on the old tree
    python experiments/golden_results.py run golden/after           # on the new tree
    python experiments/golden_results.py compare golden/before golden/after

``run`` runs each job of :data:`deltajax.jobs.JOBS` through the command line (``python -m deltajax.run``, a fresh
process each) at the suite's toy size (``tests/toy_jobs.py``) into ``DIR/<job>/``. ``compare`` reports, per job,
every difference :func:`deltajax.io.differences` finds between the two results files (bit for bit; ``--rtol``
for a tolerance), leaving out what legitimately changes between two runs of the same code: run time, commit and
the measured timings (:data:`VOLATILE`, found by running the same tree twice). Exit status 1 when anything
differs. A refactoring that moves code without changing what it computes must compare clean.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: what differs between two runs of the same tree (every job at toy size, run twice): wall and CPU timings
#: (attributes ending in _s), the kernel benchmark's measured rates and compile times, and its printed report
VOLATILE = ("*@*_s", "bench@report", "bench/*rate_*", "bench/*compile_time")


def run(out: Path, jobs: list[str]) -> int:
    sys.path.insert(0, str(ROOT / "tests"))
    from toy_jobs import overrides

    out.mkdir(parents=True, exist_ok=True)
    failed = 0
    for name in jobs:
        d = out / name
        if (d / "results.h5").exists():
            print(f"{name}: kept {d / 'results.h5'}")
            continue
        t0 = time.perf_counter()
        cmd = [sys.executable, "-m", "deltajax.run", f"experiment={name}", *overrides(name), "plots=false",
               f"hydra.run.dir={d}"]
        r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env=os.environ.copy())
        print(f"{name}: rc {r.returncode}, {time.perf_counter() - t0:.0f} s", flush=True)
        if r.returncode:
            failed += 1
            print(r.stdout[-2000:], r.stderr[-2000:], sep="\n")
    return 1 if failed else 0


def compare(a: Path, b: Path, jobs: list[str], rtol: float) -> int:
    from deltajax.io import differences

    bad = 0
    for name in jobs:
        fa, fb = a / name / "results.h5", b / name / "results.h5"
        if not (fa.exists() and fb.exists()):
            print(f"{name}: missing {fa if not fa.exists() else fb}")
            bad += 1
            continue
        diff = differences(fa, fb, ignore=VOLATILE, rtol=rtol)
        print(f"{name}: {'same' if not diff else f'{len(diff)} differences'}")
        for line in diff[:40]:
            print("   ", line)
        bad += bool(diff)
    return 1 if bad else 0


def main(argv=None) -> int:
    from deltajax.jobs import JOBS

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("action", choices=("run", "compare"))
    ap.add_argument("dirs", nargs="+", type=Path)
    ap.add_argument("--jobs", nargs="*", default=sorted(JOBS))
    ap.add_argument("--rtol", type=float, default=0.0)
    a = ap.parse_args(argv)
    if a.action == "run":
        return run(a.dirs[0], a.jobs)
    if len(a.dirs) != 2:
        ap.error("compare needs two directories")
    return compare(a.dirs[0], a.dirs[1], a.jobs, a.rtol)


if __name__ == "__main__":
    raise SystemExit(main())
