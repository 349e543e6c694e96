"""Merge sharded runs: ``python -m deltajax.merge <sweep dir>`` or ``python -m deltajax.merge a.h5 b.h5 -o out.h5``.

The same command as ``python -m deltajax.sweeps`` (:mod:`deltajax.sweeps.__main__`), kept under this name.
"""

from __future__ import annotations

import sys

from .sweeps.__main__ import main as _main

__all__ = ["main"]


def main(argv=None) -> int:
    """``python -m deltajax.merge``: see :func:`deltajax.sweeps.__main__.main`."""
    return _main(argv, prog="python -m deltajax.merge")


if __name__ == "__main__":
    sys.exit(main())
