"""The run report of a main-job run: ``python -m deltajax.report <run dir> [-o report.html]``.

Writes the self-contained HTML report (:func:`deltajax.runreport.write_report`) of a finished
``experiment=ga_reconfig`` run; ``experiment=ga_reconfig`` itself writes it as its last stage. Default output:
``<run dir>/report.html``. Float64 is switched on when the run was a float64 run (as the CLI does for the run).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from .runreport import ReportError, write_report

__all__ = ["main", "write_report", "ReportError"]


def _run_precision(path: Path) -> str:
    import h5py

    try:
        with h5py.File(path, "r") as f:
            p = f.attrs.get("precision", "")
    except OSError as err:
        raise ReportError(f"{path} cannot be read as a results file ({err})") from None
    return p.decode() if isinstance(p, bytes) else str(p)


def main(argv=None) -> int:
    """The command line (exit 0: written; 2: bad input, one line on stderr)."""
    ap = argparse.ArgumentParser(prog="python -m deltajax.report", description=__doc__.splitlines()[0])
    ap.add_argument("run", help="the run directory of a finished ga_reconfig run (or its results.h5)")
    ap.add_argument("-o", "--out", help="output file (default: report.html in the run directory)")
    args = ap.parse_args(argv)
    path = Path(args.run)
    path = path / "results.h5" if path.is_dir() else path
    if not path.is_file():
        print(f"python -m deltajax.report: {args.run} holds no results.h5", file=sys.stderr)
        return 2
    try:
        precision = _run_precision(path)
        import jax

        jax.config.update("jax_enable_x64", precision == "float64")   # before any array is built
        cache = os.environ.get("DELTAJAX_JAX_CACHE", "~/.cache/deltajax/jax")  # the CLI's default cache
        jax.config.update("jax_compilation_cache_dir", os.path.expanduser(cache))
        out = write_report(path, args.out)
    except ReportError as err:
        print(f"python -m deltajax.report: {err}", file=sys.stderr)
        return 2
    print(f"report -> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
