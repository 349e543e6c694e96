"""Merge sharded runs: ``python -m deltajax.sweeps <sweep dir>`` or ``python -m deltajax.sweeps a.h5 b.h5 -o out.h5``.

With a sweep directory, every set of runs that differ only in ``shard`` (and have ``n_shards > 1``) is merged
into ``<sweep>/merged/<label>/results.h5`` and the sweep's ``summary.csv``/``summary.json`` are rewritten.
With files, they are merged into ``-o`` (default ``merged_results.h5`` beside the first). The merged datasets
are identical to those of a single-process run (:func:`deltajax.sweeps.merge_shards`). ``python -m deltajax.merge``
is the same command.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .layout import find_runs
from .merge import ShardError, merge_shards, merge_sweep
from .summary import summarize_sweep
from ..rundir import MANIFEST

__all__ = ["main"]


def _not_a_sweep(path: Path, prog: str):
    """Why ``path`` is not a sweep directory (a single run's directory, or no runs at all), or None."""
    own = [n for n in (MANIFEST, "results.h5") if (path / n).exists()]
    if own:
        return (f"{path} is a run directory (it holds {' and '.join(own)}), not a sweep directory; merge shard "
                f"files with: {prog} a.h5 b.h5 -o out.h5")
    if not find_runs(path):
        return f"{path} holds no runs of a sweep (<sweep>/<job number>/ with results.h5)"
    return None


def main(argv=None, prog: str = "python -m deltajax.sweeps") -> int:
    """The command line: merge a sweep directory (and rewrite its summary), or merge shard files."""
    ap = argparse.ArgumentParser(prog=prog, description=__doc__.splitlines()[0])
    ap.add_argument("inputs", nargs="+", help="a sweep directory, or the shards' results.h5 files")
    ap.add_argument("-o", "--out", help="output file when merging files")
    args = ap.parse_args(argv)
    paths = [Path(p) for p in args.inputs]
    try:
        if len(paths) == 1 and paths[0].is_dir():
            problem = _not_a_sweep(paths[0], prog)
            if problem is not None:  # refused before anything is written into it
                print(f"error: {problem}", file=sys.stderr)
                return 2
            written = merge_sweep(paths[0])
            for w in written:
                print(f"merged -> {w}")
            if not written:
                print(f"no complete set of shards (n_shards > 1) in {paths[0]}")
            summary = summarize_sweep(paths[0])
            print(f"summary -> {summary['csv']}")
            return 0
        missing = [str(p) for p in paths if not p.is_file()]
        if missing:
            ap.error(f"not a file: {', '.join(missing)}")
        print(f"merged -> {merge_shards(paths, args.out)}")
    except ShardError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
