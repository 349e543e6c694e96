"""Redundancy resolution of the reconfigurable Delta: the best base radius R per point (docs/CONVENTIONS.md).

For each point the candidates are the R samples ``R_min + k R_step`` (k = 0..n_R-1). A sample is *feasible*
when the IK succeeds for all chains within the joint limits and Jx is not exactly singular (det Jx != 0) and
the criterion is not NaN. The selected sample maximises the criterion (any name in
:data:`deltajax.INDEX_NAMES`, k~ by default); ties go to the smallest R. Points with no feasible sample
get ``ok=False``, ``k=-1`` and NaN values.

Two implementations return the identical selection (tested):

* **exact** -- every sample is evaluated, like the paper. :func:`resolve_redundancy` (pure JAX, jit/vmap-able:
  a ``lax.scan`` over the samples keeps memory O(N); what a GA calls) and the host driver
  ``resolve_redundancy_host(..., mode="exact")`` (Numba).
* **fast** -- ``resolve_redundancy_host(..., mode="fast")``. The savings, none of which changes the answer:

  1. *Closed-form reach interval.* For chain i with P in its local frame, d_x = p_x,i + r - R and
     L2' = sqrt(L2^2 - p_y,i^2), the loop closes iff rho = sqrt(d_x^2 + p_z^2) lies in [|L2' - L1|, L2' + L1]
     (the loop-closure condition (d_x^2 + p_z^2 + p_y^2 + L1^2 - L2^2)^2 <= 4 L1^2 (d_x^2 + p_z^2) is
     a quadratic in d_x^2 whose roots are exactly these). Hence R must lie in
     [p_x,i + r - sqrt((L2'+L1)^2 - p_z^2), p_x,i + r + sqrt((L2'+L1)^2 - p_z^2)] for every chain; the
     intersection (widened by one sample for rounding) bounds the sample range of each point.
  2. *IK pre-test.* Inside that range each sample first runs the cheap IK test (joint limits included);
     the Jacobian and singular-value work runs only where it passes (the Numba kernel in :mod:`.numba_fields`).
  3. *Screen and verify* (``screen=True``, the default). A vectorised Numba loop over the window
     (:func:`.numba_fields.screen_window`) evaluates every sample with the same IK, Jacobian and matrix S or T as the
     exact kernel (the same floating-point expressions, hence the same feasibility decisions and the same
     matrix), but takes the eigenvalues from the trigonometric Cardano formula instead of 4 Jacobi sweeps,
     written without inverse trigonometry (lambda_max = q + p (1 + t), lambda_mid = q + p (t' - t), where
     t^2 (t + 3) = 2 (1 + r) and t'^2 (t' + 3) = 2 (1 - r) are solved by a polynomial guess and one Halley
     step). Each sample gets an interval [lo, hi] that contains the exact kernel's value:

     * eigenvalues: |lambda_screen - lambda_Jacobi| <= e_lam = 512 eps (|q| + 2 p) + p (dt + dt'), where
       512 eps (|q| + 2 p) >= 512 eps ||A|| covers the rounding of both solvers and dt, dt' bound how far
       the roots t, t' move when r carries its rounding error dr = 512 eps (1 + |q| / p): dt <=
       min(sqrt(2 dr / 3), 2 dr / f'(t - sqrt(2 dr / 3)), 1) (f = t^2 (t + 3) is convex with f >= 3 t^2; the
       square-root branch is the sqrt(eps) loss near repeated eigenvalues, e.g. on the robot's axis);
     * singular values: relative errors 2 e_lam / lambda_max (from lambda_max), 2 e_lam / lambda_mid (from
       lambda_mid) and twice their sum (from the determinant; first order x 2, refused above 5 %);
     * k~ = s~_v(s3) s~_f(1/s1) with both factors in [0, 1] and slopes <= 2 / min(a, b - a), so
       |dk~| <= 2 / min(a_v, b_v - a_v) |ds3| + 2 / min(a_f, b_f - a_f) |d(1/s1)| + 16 eps; the other
       criteria get the corresponding relative bound (omega_v, omega_f, manipulability, imi do not depend on
       the eigenvalues at all: s1 s2 s3 = |prod d| / |det Jx|, 64 eps);
     * plus ``screen_margin`` (default :data:`SCREEN_MARGIN` = 1e-6 absolute), NaN or unbounded -> (-inf, inf).

     Measured on every sample of the 10 mm job: max |k~_screen - k~_exact| <= 2.6e-8 for beta 0.25-0.75
     (1.1e-7 on the axis), at most 0.4 % of the bound (``tests/test_workspace_screen.py``,
     ``numba_fields.screen_audit``). With T the largest lower end over the feasible samples, a sample with hi < T
     has a value below T <= the value of the sample that defines T, so it can be neither the maximum nor a
     tie: only the candidates (hi >= T, ~1.15 per point) run the exact kernel, in increasing k with the
     exact mode's strict comparison. The result is then certified: if the best exact candidate value is
     >= T every other sample is strictly smaller; otherwise (a bound failed, e.g. a NaN exact value) the
     point is swept exactly (``work["fallback"]``, 0 in all our runs). Before screening, the window is
     trimmed to its first and last IK-feasible samples.
  4. *Mirror symmetry.* The kernel evaluates every point at (x, |y|, z) (see :mod:`.grid`), so a point and
     its mirror image have bit-identical answers; the host driver solves each mirror pair once.
     The three-fold rotation maps the Cartesian grid onto itself only for a few points (120 deg rotations
     of grid points are not grid points), so it is not used.

Exact-singular Jx is detected by det Jx == 0 exactly (rank tolerance zero), as docs/CONVENTIONS.md says.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ..geometry import ReconfigurableDelta
from ..indices import INDEX_NAMES, Indices, point_kernel
from ..kinematics import ik_cos_sin, to_chain_frames
from .grid import canonical_point

#: default extra absolute margin of the fast mode's screen (on top of its per-sample error bound)
SCREEN_MARGIN = 1e-6

__all__ = [
    "SCREEN_MARGIN",
    "Redundancy",
    "resolve_redundancy",
    "resolve_redundancy_host",
    "reconfigurable_reachable",
    "reach_interval",
    "sample_value",
]


class Redundancy(NamedTuple):
    """Result of redundancy resolution for N points.

    Attributes:
        k: index of the selected R sample (-1 where none is feasible).
        R: selected base radius R* = R_min + k R_step (m; NaN where none).
        value: criterion value at R* (NaN where none).
        ok: some R sample is feasible.
        indices: every index at R* (:class:`deltajax.indices.Indices`, each field of shape (N,), singular values (N, 3)).
    """

    k: Int[Array, "n"]
    R: Float[Array, "n"]
    value: Float[Array, "n"]
    ok: Bool[Array, "n"]
    indices: Indices


def _check_criterion(criterion: str) -> None:
    if criterion not in INDEX_NAMES:
        raise ValueError(f"criterion must be one of {INDEX_NAMES}, got {criterion!r}")


def _sample_R(recon: ReconfigurableDelta, k):
    return recon.R_min + jnp.asarray(k, recon.R_min.dtype) * recon.R_step


def _kernel(recon: ReconfigurableDelta, p, k, b_v, b_f, beta):
    """(feasible, indices) of canonical point ``p`` at sample ``k``: the core :func:`deltajax.indices.point_kernel`.

    The exact (Jacobi) singular values: this is the selection the host driver certifies against, so it uses
    the same exact form as the Numba kernel. Feasible = IK ok within limits and det Jx != 0 exactly.
    """
    out = point_kernel(recon.at(_sample_R(recon, k)), p, sv_method="jacobi", b_v=b_v, b_f=b_f, beta=beta)
    return out.ok & (out.det_jx != 0.0), out.indices


def sample_value(recon: ReconfigurableDelta, p: Float[Array, "3"], k: Int[Array, ""], *,
                 criterion: str = "k_tilde", b_v: float = 2.0, b_f: float = 4.2, beta: float = 0.5
                 ) -> tuple[Bool[Array, ""], Float[Array, ""]]:
    """(feasible, criterion value) of one point at R sample ``k``; the value is -inf where not feasible."""
    _check_criterion(criterion)
    feas, ind = _kernel(recon, canonical_point(jnp.asarray(p)), k, b_v, b_f, beta)
    v = getattr(ind, criterion)
    feas = feas & ~jnp.isnan(v)
    return feas, jnp.where(feas, v, -jnp.inf)


def _nan_indices(ind: Indices, ok) -> Indices:
    return Indices(*(jnp.where(ok if v.ndim == ok.ndim else ok[..., None], v, jnp.nan) for v in ind))


def _finish(recon, pts, best_k, best_v, b_v, b_f, beta) -> Redundancy:
    ok = best_k >= 0
    k_safe = jnp.where(ok, best_k, 0)
    _, ind = jax.vmap(lambda q, kk: _kernel(recon, canonical_point(q), kk, b_v, b_f, beta))(pts, k_safe)
    R = jnp.where(ok, _sample_R(recon, k_safe), jnp.nan)
    return Redundancy(k=best_k, R=R, value=jnp.where(ok, best_v, jnp.nan), ok=ok, indices=_nan_indices(ind, ok))


def resolve_redundancy(recon: ReconfigurableDelta, points: Float[Array, "n 3"], criterion: str = "k_tilde", *,
                       b_v: float = 2.0, b_f: float = 4.2, beta: float = 0.5) -> Redundancy:
    """Exact redundancy resolution: sweep every R sample (pure; jit/vmap-able, memory O(N)).

    Args:
        recon: the reconfigurable robot (``n_R`` static).
        points: (N, 3) platform positions (m, base frame).
        criterion: index to maximise, a name in :data:`deltajax.INDEX_NAMES` (default ``"k_tilde"``).
        b_v, b_f, beta: parameters of k~ (may be traced).

    Returns:
        :class:`Redundancy` (ties -> smallest R; ``ok=False`` where no sample is feasible).
    """
    _check_criterion(criterion)
    pts = jnp.asarray(points)
    dtype = jnp.result_type(pts.dtype, recon.R_min.dtype)
    pts = pts.astype(dtype)
    n = pts.shape[0]
    value = jax.vmap(lambda q, kk: sample_value(recon, q, kk, criterion=criterion, b_v=b_v, b_f=b_f, beta=beta),
                     in_axes=(0, None))

    def step(carry, k):
        best_k, best_v = carry
        feas, v = value(pts, k)
        better = feas & (v > best_v)  # strictly greater: ties keep the smaller R
        return (jnp.where(better, k, best_k), jnp.where(better, v, best_v)), None

    init = (jnp.full((n,), -1, jnp.int32), jnp.full((n,), -jnp.inf, dtype))
    (best_k, best_v), _ = jax.lax.scan(step, init, jnp.arange(recon.n_R, dtype=jnp.int32))
    return _finish(recon, pts, best_k, best_v, b_v, b_f, beta)


def reconfigurable_reachable(recon: ReconfigurableDelta, points: Float[Array, "n 3"]) -> Bool[Array, "n"]:
    """Whether some R sample reaches each point (IK within limits for all chains); pure, memory O(N).

    Vmap over designs: ``jax.vmap(reconfigurable_reachable, in_axes=(0, None))``.
    """
    pts = jnp.asarray(points)
    canon = jax.vmap(canonical_point)(pts)

    def step(acc, k):
        robot = recon.at(_sample_R(recon, k))
        ok = jax.vmap(lambda q: jnp.all(ik_cos_sin(robot, q).ok))(canon)
        return acc | ok, None

    acc, _ = jax.lax.scan(step, jnp.zeros(pts.shape[:1], bool), jnp.arange(recon.n_R, dtype=jnp.int32))
    return acc


# -- fast mode -----------------------------------------------------------------------------------------------

def reach_interval(recon: ReconfigurableDelta, p: Float[Array, "3"]) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """Closed-form interval [R_lo, R_hi] (m) outside which some chain cannot close its loop (any R).

    Necessary condition only (joint limits and the inner hole |d_x| >= sqrt((L2' - L1)^2 - p_z^2) are not
    used); empty (R_lo > R_hi) when no R reaches the point.
    """
    robot = recon.robot
    loc = to_chain_frames(canonical_point(jnp.asarray(p)))
    L1, L2, r = robot.upper_arm, robot.forearm, robot.platform_radius
    py2 = loc[:, 1] ** 2
    l2p2 = L2 * L2 - py2
    l2p = jnp.sqrt(jnp.where(l2p2 >= 0, l2p2, 0.0))
    hi2 = (l2p + L1) ** 2 - loc[:, 2] ** 2
    reach = (l2p2 >= 0) & (hi2 >= 0)
    half = jnp.sqrt(jnp.where(reach, hi2, 0.0))
    c = loc[:, 0] + r
    lo = jnp.max(jnp.where(reach, c - half, jnp.inf))
    hi = jnp.min(jnp.where(reach, c + half, -jnp.inf))
    return lo, hi


def _reach_k_range(recon, p):
    lo, hi = reach_interval(recon, p)
    # one extra sample on each side absorbs rounding of the closed form against the IK's own test
    k_lo = jnp.ceil((lo - recon.R_min) / recon.R_step) - 1.0
    k_hi = jnp.floor((hi - recon.R_min) / recon.R_step) + 1.0
    k_lo = jnp.clip(jnp.where(jnp.isfinite(k_lo), k_lo, recon.n_R), 0, recon.n_R)
    k_hi = jnp.clip(jnp.where(jnp.isfinite(k_hi), k_hi, -1), -1, recon.n_R - 1)
    return k_lo.astype(jnp.int32), k_hi.astype(jnp.int32)


def nb_params(recon: ReconfigurableDelta):
    from . import numba_fields

    rb = recon.robot
    f = lambda v: float(np.asarray(v))  # noqa: E731
    return dict(R_min=f(recon.R_min), R_step=f(recon.R_step), r=f(rb.platform_radius), L1=f(rb.upper_arm),
                L2=f(rb.forearm), lim=numba_fields.limits_tuple(f(rb.theta_min), f(rb.theta_max)))


def reach_k_range_host(recon: ReconfigurableDelta, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form sample range [k_lo, k_stop) per point (host, NumPy); see :func:`reach_interval`."""
    from . import numba_fields

    q = nb_params(recon)
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    k_lo = np.empty(pts.shape[0], np.int64)
    k_stop = np.empty(pts.shape[0], np.int64)
    numba_fields.parallel(lambda a, b: numba_fields.reach_k_range(pts[a:b], q["R_min"], q["R_step"], recon.n_R, q["r"], q["L1"], q["L2"],
                                                k_lo[a:b], k_stop[a:b]), pts.shape[0])
    return k_lo, k_stop


def resolve_redundancy_host(recon: ReconfigurableDelta, points: np.ndarray, criterion: str = "k_tilde", *,
                            mode: str = "fast", b_v: float = 2.0, b_f: float = 4.2, beta: float = 0.5,
                            mirror: bool = True, return_indices: bool = True, screen: bool = True,
                            screen_margin: float = SCREEN_MARGIN) -> tuple[Redundancy, dict]:
    """Redundancy resolution on the host (Numba kernel, see :mod:`.numba_fields`), NumPy in and out.

    Args:
        recon: the reconfigurable robot (concrete values).
        points: (N, 3) positions (m).
        criterion, b_v, b_f, beta: as in :func:`resolve_redundancy`.
        mode: ``"fast"`` (closed-form reach range, screen-and-verify, mirror pairs solved once) or ``"exact"``
            (every sample of every point, the paper's sweep; the IK pre-test still skips the Jacobian work
            of unreachable samples). Both return the identical selection (same compiled exact kernel).
        mirror: solve each mirror pair (x, +-y, z) once (fast mode only).
        return_indices: also return every index at R*.
        screen: fast mode only: screen every sample with the vectorised approximate kernel and run the exact
            kernel only on the samples that can still be the argmax (see the module docstring); ``False``
            runs the exact kernel on every IK-feasible sample of the reach range (the previous fast mode).
        screen_margin: extra absolute margin added to the screen's per-sample error bound (>= 0).

    Returns:
        (:class:`Redundancy` of NumPy arrays, work counters: "samples" (window samples), "full" (exact
        kernels), "points", "screened" (samples screened), "fallback" (points whose screen could not be
        certified and were swept exactly)).
    """
    from . import numba_fields

    _check_criterion(criterion)
    if mode not in ("fast", "exact"):
        raise ValueError(f"mode must be 'fast' or 'exact', got {mode!r}")
    screen_margin = float(screen_margin)
    if not (screen_margin >= 0.0 and np.isfinite(screen_margin)):
        raise ValueError(f"screen_margin must be a finite number >= 0, got {screen_margin!r}")
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    n_all = pts.shape[0]
    q = nb_params(recon)
    if mode == "fast" and mirror and n_all:
        keyed = np.stack([pts[:, 0], np.abs(pts[:, 1]), pts[:, 2]], axis=-1)
        uniq, inverse = np.unique(keyed, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
    else:
        uniq, inverse = pts, None
    n = uniq.shape[0]
    if mode == "exact":
        k_lo = np.zeros(n, np.int64)
        k_stop = np.full(n, recon.n_R, np.int64)
    else:
        k_lo, k_stop = reach_k_range_host(recon, uniq)
    best_k = np.empty(n, np.int64)
    best_v = np.empty(n, np.float64)
    n_full = np.empty(n, np.int64)
    n_fb = np.zeros(n, np.int64)
    kt = numba_fields.kt_tuple(b_v, b_f, beta)
    crit = INDEX_NAMES.index(criterion)
    use_screen = mode == "fast" and screen
    if use_screen:
        numba_fields.parallel(lambda a, b: numba_fields.resolve_screened(
            uniq[a:b], k_lo[a:b], k_stop[a:b], q["R_min"], q["R_step"], q["r"], q["L1"], q["L2"], q["lim"], kt,
            crit, screen_margin, best_k[a:b], best_v[a:b], n_full[a:b], n_fb[a:b]), n)
    else:
        numba_fields.parallel(lambda a, b: numba_fields.resolve(uniq[a:b], k_lo[a:b], k_stop[a:b], q["R_min"], q["R_step"], q["r"],
                                              q["L1"], q["L2"], q["lim"], kt, crit, best_k[a:b], best_v[a:b],
                                              n_full[a:b]), n)
    n_samples = int(np.sum(k_stop - k_lo))
    work = {"samples": n_samples, "full": int(n_full.sum()), "points": int(n),
            "screened": n_samples if use_screen else 0, "fallback": int(n_fb.sum())}
    if inverse is not None:
        best_k, best_v = best_k[inverse], best_v[inverse]
    ok = best_k >= 0
    R = np.where(ok, q["R_min"] + np.maximum(best_k, 0) * q["R_step"], np.nan)
    if return_indices:
        ind = indices_at_host(recon, pts, best_k, b_v=b_v, b_f=b_f, beta=beta)
    else:
        ind = None
    return Redundancy(k=best_k.astype(np.int32), R=R, value=np.where(ok, best_v, np.nan), ok=ok,
                      indices=ind), work


def indices_at_host(recon: ReconfigurableDelta, points: np.ndarray, k: np.ndarray, *, b_v: float = 2.0,
                    b_f: float = 4.2, beta: float = 0.5) -> np.ndarray:
    """Every index (columns in :data:`deltajax.INDEX_NAMES` order) at sample ``k`` per point, (N, 8); NaN where k < 0."""
    from . import numba_fields

    q = nb_params(recon)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    x, y, z = (np.ascontiguousarray(pts[:, i]) for i in range(3))
    out = np.empty((numba_fields.N_IDX, pts.shape[0]))  # structure of arrays: the kernel loop vectorises
    k = np.ascontiguousarray(k, np.int64)
    kt = numba_fields.kt_tuple(b_v, b_f, beta)
    numba_fields.parallel(lambda a, b: numba_fields.fields_at(x[a:b], y[a:b], z[a:b], k[a:b], q["R_min"], q["R_step"], q["r"], q["L1"],
                                            q["L2"], q["lim"], kt, numba_fields.rows(out, a, b)), pts.shape[0])
    return out.T
