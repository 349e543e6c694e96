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

import numpy as np

from deltajax.io import read

#: attributes that legitimately differ between two runs of the same job
VOLATILE = {"time_odr_s", "time_rdr_s", "time_stats_s", "rdr_ik_tests", "rdr_full_kernels"}
#: datasets compared bitwise whatever the tolerance (the selection and the masks)
EXACT = {"R_star", "reachable_fixed", "count_odr", "face_count_odr", "x", "y", "z", "robot", "index", "stat",
         "paper_stats"}


def compare(ref_path, new_path, rtol: float = 0.0, ignore_attrs=()) -> list[str]:
    """Differences between two results files (empty: the same, in the sense of the module docstring);
    ``ignore_attrs``: group attributes not compared besides :data:`VOLATILE` (e.g. ``mode``)."""
    a, b = read(ref_path, "workspace"), read(new_path, "workspace")
    out = []
    for grp in sorted(set(a.variables) | set(b.variables)):
        va, vb = a.variables.get(grp, {}), b.variables.get(grp, {})
        for name in sorted(set(va) | set(vb)):
            where = f"{grp}/{name}"
            if name not in va or name not in vb:
                out.append(f"{where}: only in {'the reference' if name in va else 'the new file'}")
                continue
            x, y = np.asarray(va[name].data), np.asarray(vb[name].data)
            if x.shape != y.shape or x.dtype != y.dtype:
                out.append(f"{where}: shape/dtype {x.shape} {x.dtype} vs {y.shape} {y.dtype}")
                continue
            if x.dtype.kind not in "fc":
                if not np.array_equal(x, y):
                    out.append(f"{where}: {int(np.sum(x != y))} entries differ")
                continue
            nan_x, nan_y = np.isnan(x), np.isnan(y)
            if not np.array_equal(nan_x, nan_y):
                out.append(f"{where}: NaN pattern differs at {int(np.sum(nan_x != nan_y))} entries")
                continue
            fx, fy = x[~nan_x].astype(np.float64), y[~nan_y].astype(np.float64)
            tol = 0.0 if name in EXACT else rtol
            bad = np.abs(fx - fy) > tol * np.abs(fx)
            if np.any(bad):
                rel = np.max(np.abs(fx - fy)[bad] / np.maximum(np.abs(fx[bad]), 1e-300))
                out.append(f"{where}: {int(bad.sum())} of {fx.size} entries differ (largest relative {rel:.3g}, "
                           f"allowed {tol:g})")
    for grp in sorted(set(a.group_attrs) | set(b.group_attrs)):
        ga, gb = a.group_attrs.get(grp, {}), b.group_attrs.get(grp, {})
        for k in sorted((set(ga) | set(gb)) - VOLATILE - set(ignore_attrs)):
            if k not in ga or k not in gb or not np.array_equal(np.asarray(ga[k]), np.asarray(gb[k])):
                out.append(f"{grp} attribute {k}: {ga.get(k)!r} vs {gb.get(k)!r}")
    return out


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
