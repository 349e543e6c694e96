"""Per-point arithmetic written for XLA:CPU's fusion rules: cheap-op reciprocal and square root, one-loop outputs.

Why (measured): XLA:CPU never duplicates a divide or square root into two consumers, and it gives every
output of a ``jit(vmap(kernel))`` its own loop. A kernel with a few dozen shared divides and ~10 outputs therefore
becomes ~60-90 loops that store their intermediates to memory and recompute the cheap algebra between them.
Two small tools remove both causes, so that the whole per-point kernel compiles to ONE loop:

* :func:`recip`, :func:`rsqrt`, :func:`sqrt0`: 1/x, 1/sqrt(x) and sqrt(max(x, 0)) from integer bit tricks and
  Newton steps (multiplies and adds only, which XLA fuses freely), accurate to ~1 ulp for positive normal
  inputs, with custom JVPs (finite derivatives, no bit tricks under differentiation);
* :func:`fuse_outputs`: returns its pytree unchanged, routed through one variadic reduce over a 2-lane axis
  (lane 0 the value, lane 1 zero). XLA then emits every output in one multi-output loop in which shared values
  are computed once (plain outputs would each get a loop that recomputes its whole cone). Outputs a caller
  does not use are removed by XLA.

Scalars that do not depend on the point (design lengths) keep ordinary divides: they are computed once.
The implementations live in :mod:`deltajax.eigen3` (the ground-floor module of the kernel's arithmetic, which
imports nothing from deltajax); this module is their public face.
"""

from .eigen3 import fuse_outputs, recip, rsqrt, sqrt0

__all__ = ["recip", "rsqrt", "sqrt0", "fuse_outputs"]
