"""Kernel benchmark (IK + Jacobian + all indices): python experiments/bench_kernel.py [hydra overrides]

Equivalent to ``python -m deltajax.run experiment=bench_kernel``; prints M eval/s for float32 and float64,
compile time, and ratios against NumPy and the naive JAX kernel measured in the same process.
"""

import sys

from deltajax.run import main

if __name__ == "__main__":
    sys.argv = [sys.argv[0], "experiment=bench_kernel", *sys.argv[1:]]
    main()
