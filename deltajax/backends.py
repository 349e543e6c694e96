"""The kernel's declared backends: one row per kernel function, JAX the definition, Numba and NumPy its twins.

JAX (:mod:`deltajax.kinematics`, :mod:`deltajax.jacobian`, :mod:`deltajax.indices`, :mod:`deltajax.eigen3`) is
the definition of the per-point kernel. Two other backends compute the same functions:

* ``numba``: :mod:`deltajax.workspace.numba_kernel`, the scalar mirror the host drivers are built from (name
  for name with the JAX definition; a second Numba function of one row is a variant the drivers need, e.g. an
  early exit, that computes the same thing);
* ``reference``: :mod:`deltajax.reference`, an independent NumPy reimplementation (vectorised over points,
  LAPACK for the singular values), the oracle of the other two.

:data:`KERNELS` is the table ``tests/test_backend_conformance.py`` runs: every function of every backend on the
same points (valid ones over the franco2026 box and invalid ones), compared output by output within the row's
tolerances. A backend without a twin says why in ``why_none``. Adding an index means adding its JAX definition
and its row here (with its twins, or the reason there are none); the coverage test fails while a public
function of the Numba mirror or of the reference is in no row.

Functions are named by string (``"module:function"`` for JAX, a name in the backend's module otherwise):
the core does not import the engine wing (the Numba mirror lives in ``workspace/``) nor Numba itself;
:func:`resolve` imports a row's function when a caller asks for it.

Not kernel functions, hence in no row (:data:`EXCLUDED`): the Numba module's compile options and constants
(``OPTS``, ``INLINE``, ``N_IDX``, ``CRITERION``, ``JACOBI``, ``FAST``, ``CUBIC``, ``SV_METHODS``), its
argument packers (``kt_tuple``: (a_v, b_v, a_f, b_f) from b_v, b_f, beta; ``as_tuple4``: an array's first four
entries as loop-invariant scalars) and the reference's ``INDEX_NAMES`` (a constant, checked equal to the
core's by the coverage test); private helpers (``_jacobi_rotate``, ``_eig_top2_fast``, ...) are the inside of
one row's function and are tested through it.
"""

from __future__ import annotations

import importlib
from typing import Callable, NamedTuple, Optional

__all__ = ["Kernel", "KERNELS", "BACKENDS", "MODULES", "EXCLUDED", "kernel", "resolve"]

#: the backends, the definition first
BACKENDS = ("jax", "numba", "reference")
#: the module that holds each non-JAX backend's functions
MODULES = {"numba": "deltajax.workspace.numba_kernel", "reference": "deltajax.reference"}
#: public names of the backend modules that are not kernel functions (see the module docstring)
EXCLUDED = {
    "numba": frozenset({"OPTS", "INLINE", "N_IDX", "CRITERION", "JACOBI", "FAST", "CUBIC", "SV_METHODS", "kt_tuple",
                        "as_tuple4"}),
    "reference": frozenset({"INDEX_NAMES"}),
}


class Kernel(NamedTuple):
    """One kernel function and its twins.

    Attributes:
        name: the JAX definition's name.
        jax: ``"module:function"`` of the definition.
        numba: names in :mod:`deltajax.workspace.numba_kernel` that compute it (the first of the same name where
            there is one), () where the mirror has none.
        reference: names in :mod:`deltajax.reference`, () where it has none.
        why_none: one line per missing twin: why that backend deliberately has no function of its own.
        numba_rtol: relative tolerance of the Numba twin against the definition.
        reference_rtol: relative tolerance of the reference against the definition.
        why_rtol: why these tolerances.
    """

    name: str
    jax: str
    numba: tuple = ()
    reference: tuple = ()
    why_none: str = ""
    numba_rtol: float = 1e-13
    reference_rtol: float = 1e-12
    why_rtol: str = "the same expressions in the same order (Numba) / an independent formula (reference): rounding"


_SAME = "the same expressions in the same order: rounding only (the JAX kernel's cheap-op reciprocal, ~1 ulp)"
_FMA = "the same products in the same order; XLA contracts a*b + c into one FMA (1 ulp)"
_REF_BLOCKS = "the reference forms the three Jx rows and d together (its jacobian_blocks row)"
_SVD = ("the reference takes LAPACK's SVD of M = Jx^-1 diag(d) (no eigenproblem, no closed form); "
        "singular_values is the row that meets it")

#: the conformance table, in the kernel's order (point -> chains -> Jacobian blocks -> singular values -> indices)
KERNELS: tuple[Kernel, ...] = (
    Kernel("limit_terms", "deltajax.kinematics:limit_terms", numba=("limits_tuple",),
           why_none="reference: tests theta itself against [theta_min, theta_max] (arctan2), no cos/sin form",
           numba_rtol=1e-15, why_rtol="the same cos/sin of the same mid and half width"),
    Kernel("chain_local", "deltajax.kinematics:chain_local", numba=("chain_local",), reference=("chain_local",),
           numba_rtol=1e-15, reference_rtol=1e-14,
           why_rtol="Numba: the same products (XLA contracts a*b + c into one FMA: 1 ulp); reference: the rotation "
                    "by cos/sin of 2 pi i / 3 itself"),
    Kernel("loop_closure", "deltajax.kinematics:loop_closure", numba=("loop_closure",), reference=("loop_closure",),
           numba_rtol=1e-13, reference_rtol=1e-11,
           why_rtol="Numba: the same algebra, IEEE divide and sqrt for the fast ones; reference: the same "
                    "equation with a divide by rho^2 and the limits tested on arctan2(sin, cos)"),
    Kernel("loop_vectors", "deltajax.kinematics:loop_vectors", numba=("loop_vectors",), reference=("loop_vectors",),
           numba_rtol=1e-15, reference_rtol=1e-14, why_rtol="times 1/L2 versus a divide by L2: 1 ulp"),
    Kernel("jx_row", "deltajax.jacobian:jx_row", numba=("jx_row",), why_none=f"reference: {_REF_BLOCKS}",
           numba_rtol=1e-15, why_rtol=_FMA),
    Kernel("jq_theta", "deltajax.jacobian:jq_theta", numba=("jq_theta",), why_none=f"reference: {_REF_BLOCKS}",
           numba_rtol=1e-15, why_rtol=_FMA),
    Kernel("jx_det", "deltajax.jacobian:jx_det", numba=("jx_det",),
           why_none="reference: never forms det Jx alone (LAPACK's solve; numpy.linalg.det is the test's oracle)",
           numba_rtol=1e-15, why_rtol=_FMA),
    Kernel("chain", "deltajax.jacobian:chain", numba=("chain", "chain_ok"),
           why_none="reference: runs the three chains at once (its jacobian_blocks row)", numba_rtol=1e-13,
           why_rtol=_SAME),
    Kernel("jacobian_blocks", "deltajax.jacobian:jacobian_blocks", numba=("jacobian_blocks",),
           reference=("jacobian_blocks",), numba_rtol=1e-13, reference_rtol=1e-11,
           why_rtol="Numba: " + _SAME + "; reference: its own loop closure (divides, arctan2 limits)"),
    Kernel("ik_cos_sin", "deltajax.kinematics:ik_cos_sin", numba=("ik_ok", "ik_ok_all"),
           why_none="numba: only the reachability decision (cos/sin are jacobian_blocks' business); reference: "
                    "point_indices' ok and cos/sin (point_kernel row)",
           numba_rtol=0.0, why_rtol="a decision: equal exactly"),
    Kernel("sv_matrix", "deltajax.indices:sv_matrix", numba=("sv_matrix",), why_none=f"reference: {_SVD}",
           numba_rtol=1e-14, why_rtol="the same products in the same order (1 ulp from XLA's reassociation)"),
    Kernel("sym3_top2", "deltajax.eigen3:sym3_top2", numba=("sym3_top2",),
           why_none=f"reference: {_SVD}; numpy.linalg.eigvalsh is the test's oracle", numba_rtol=1e-12,
           why_rtol="the same sweeps / cubic with IEEE divide and sqrt instead of the JAX kernel's cheap-op ones"),
    Kernel("singular_values_from_eig", "deltajax.indices:singular_values_from_eig",
           numba=("singular_values_from_eig",), why_none=f"reference: {_SVD}", numba_rtol=1e-14,
           why_rtol="three reciprocals and products (JAX) versus three divides (Numba): a few ulp"),
    Kernel("singular_values", "deltajax.indices:singular_values", numba=("singular_values",),
           reference=("singular_values",), numba_rtol=1e-11, reference_rtol=1e-7,
           why_rtol="Numba: the same closed form; reference: LAPACK's SVD, against which the fast cubic splits a "
                    "nearly repeated pair by ~sqrt(eps) near the z axis (indices.singular_values' accuracy)"),
    Kernel("sigma_tilde", "deltajax.indices:sigma_tilde", numba=("sigma_tilde",), reference=("sigma_tilde",),
           numba_rtol=1e-15, reference_rtol=1e-13,
           why_rtol="u (2 - u) and reciprocal breakpoints versus the paper's 1 - ((s - a) / a)^2"),
    Kernel("k_tilde", "deltajax.indices:k_tilde", numba=("k_tilde",), reference=("k_tilde",), numba_rtol=1e-15,
           reference_rtol=1e-13, why_rtol="a product of two sigma_tilde (their tolerances)"),
    Kernel("indices_from_sv", "deltajax.indices:indices_from_sv", numba=("indices_from_sv",),
           reference=("indices_from_sv",), numba_rtol=1e-14, reference_rtol=1e-13,
           why_rtol="products and reciprocals of the same singular values"),
    Kernel("point_kernel", "deltajax.indices:point_kernel", numba=("point_kernel",), reference=("point_indices",),
           numba_rtol=1e-11, reference_rtol=1e-7,
           why_rtol="the singular_values row's tolerances carried through the indices"),
    Kernel("criterion_of", "deltajax.indices:criterion_of", numba=("criterion_of",),
           why_none="reference: a dict lookup in point_indices' result (point_value row)", numba_rtol=0.0,
           why_rtol="a selection: the value itself"),
    Kernel("point_value", "deltajax.indices:point_value", numba=("point_value",), reference=("point_indices",),
           numba_rtol=1e-11, reference_rtol=1e-7, why_rtol="the point_kernel row's tolerances"),
)


def kernel(name: str) -> Kernel:
    """The row of :data:`KERNELS` named ``name`` (the JAX definition's name)."""
    for k in KERNELS:
        if k.name == name:
            return k
    raise KeyError(f"no kernel {name!r} in deltajax.backends.KERNELS")


def resolve(row: Kernel, backend: str) -> tuple[Callable, ...]:
    """The functions of ``backend`` (one of :data:`BACKENDS`) for ``row``, imported now: one for ``"jax"``, the
    row's twins (possibly none) otherwise. Raises ``AttributeError`` for a name the module does not have."""
    if backend == "jax":
        module, _, name = row.jax.partition(":")
        return (getattr(importlib.import_module(module), name),)
    if backend not in MODULES:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    mod = importlib.import_module(MODULES[backend])
    names: Optional[tuple] = getattr(row, backend)
    return tuple(getattr(mod, n) for n in names)
