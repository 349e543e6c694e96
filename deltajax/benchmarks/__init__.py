"""Benchmark-only code: the yardsticks the benchmarks measure against, not part of the library.

* :mod:`deltajax.benchmarks.frozen_kernel`: a frozen copy of an earlier JAX kernel (the baseline of the
  ``bench_kernel`` job); never fixed, never shared with the library.
* :mod:`deltajax.benchmarks.numba_loops`: the Numba kernel's throughput and the minimal tight loop of the same
  algorithm (the ceiling the kernel is compared with).

Imported only by the ``bench_kernel`` job, ``experiments/bench_*`` and their tests; nothing in the library imports
it.
"""

__all__: list[str] = []
