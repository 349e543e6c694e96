"""Compare two ``reconfig_indices`` results files: is the new run's output the same as the reference's?

    python experiments/check_reconfig_indices.py REF/results.h5 NEW/results.h5

What "the same" means, per stored quantity of group ``workspace`` (read with :func:`deltajax.io.read`):

* the selection -- ``R_star`` (every grid point, NaN outside the ODR workspace) and ``slices/R_star`` -- and
  the mask ``reachable_fixed``, the axes and the counts: **bitwise equal** (NaN where NaN);
* every stored index field (``*_odr``, ``*_rdr``, ``slices/*``) and ``stats``: equal to ``--rtol`` relative
  (default 0: bitwise; NaN where NaN). The job stores fields as float32, so any tolerance below 6e-8 means
  bitwise equality of the stored numbers;
* ``paper_stats`` and the job's attributes other than timings and work counters: equal.

Exit status 0 when everything matches, 1 otherwise (one line per difference).
"""

from __future__ import annotations

import argparse
import sys

from deltajax.io import differences

#: attributes that legitimately differ between two runs of the same job
VOLATILE = {"time_odr_s", "time_rdr_s", "time_stats_s", "rdr_ik_tests", "rdr_full_kernels"}
#: datasets compared bitwise whatever the tolerance (the selection and the masks)
EXACT = {"R_star", "reachable_fixed", "count_odr", "face_count_odr", "x", "y", "z", "robot", "index", "stat",
         "paper_stats"}


def compare(ref_path, new_path, rtol: float = 0.0, ignore_attrs=()) -> list[str]:
    """Differences between two results files (empty: the same, in the sense of the module docstring), by
    :func:`deltajax.io.differences` on group ``workspace``; ``ignore_attrs``: group attributes not compared
    besides :data:`VOLATILE` (e.g. ``mode``). The files are read as they are (not verified)."""
    return differences(ref_path, new_path, group="workspace", rtol=rtol, verify=False,
                       exact=[f"workspace/{n}" for n in EXACT] + [f"workspace/*/{n}" for n in EXACT],
                       ignore=[f"workspace@{k}" for k in (*VOLATILE, *ignore_attrs)])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("ref")
    ap.add_argument("new")
    ap.add_argument("--rtol", type=float, default=0.0, help="relative tolerance of index fields and stats")
    args = ap.parse_args(argv)
    diffs = compare(args.ref, args.new, args.rtol)
    for d in diffs:
        print(d)
    print("SAME" if not diffs else f"{len(diffs)} differences")
    return 0 if not diffs else 1


if __name__ == "__main__":
    sys.exit(main())
