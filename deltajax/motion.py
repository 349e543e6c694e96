"""Path-level redundancy resolution of the reconfigurable Delta: the best base radius R(t) along a trajectory.

Pointwise resolution (:func:`deltajax.workspace.resolve_redundancy`) picks R* = argmax of an index at every
point independently; along a path R* jumps between branches of the index landscape and nothing checks what the
R drive can do. Here the whole sequence R_0..R_{K-1} at the K samples t_j = j dt of a Cartesian cycle is chosen
at once:

    maximise    Phi = sum_j w_j v(p_j, R_j)           (aggregate "integral": trapezoid weights w_j, dt included;
                                                        ties broken by the minimum)
             or Phi = min_j v(p_j, R_j)               (aggregate "min"; ties broken by the integral: the order is
                                                        lexicographic, best minimum first, then the largest
                                                        integral among the paths with that minimum)
    subject to  R_j = R_min + k_j dR (the R samples of the robot), p_j reachable and non-singular at R_j,
                |R_{j+1} - R_j| <= Rdot_max dt,  |R_{j+1} - 2 R_j + R_{j-1}| <= Rddot_max dt^2,
                |F_R(p_j, R_j, Rdot_j, Rddot_j)| <= F_max at every sample,

where v is any index of :data:`deltajax.INDEX_NAMES` (computed by :func:`deltajax.point_indices`) and F_R the
R actuator force of the inverse dynamics with moving R (:func:`deltajax.cycle_profile`), the discrete motion's
rates being the finite differences (interior samples: central Rdot_j = (R_{j+1} - R_{j-1}) / (2 dt),
Rddot_j = (R_{j+1} - 2 R_j + R_{j-1}) / dt^2; end samples: the one-sided difference and the neighbour's
second difference).

**Exact method (dynamic programming).** With integer samples the limits are bands: |k_{j+1} - k_j| <= w =
floor(Rdot_max dt / dR) and |second difference| <= a = floor(Rddot_max dt^2 / dR). The acceleration limit and
the force (which needs Rddot_j, i.e. k_{j-1}, k_j, k_{j+1}) enter *exactly* by making the DP state the pair
(k_j, d_j = k_j - k_{j-1}) (n_R x (2w + 1) states); a transition to (k_{j+1}, d_{j+1}) is allowed when
|d_{j+1} - d_j| <= a and the force at sample j holds. One ``lax.scan`` step per sample evaluates all
n_R (2w + 1) (2a + 1) transitions vectorised and stores one small back-pointer per state, so memory is
O(K n_R w). The force is exactly a quadratic polynomial in Rdot and linear in Rddot at fixed (p, pdot, pddot,
R) (the joint rates are affine in Rdot, the joint accelerations quadratic in Rdot and affine in Rddot, and
the efforts linear in the accelerations and quadratic in the rates), so four dynamics evaluations per
(sample, R) give its coefficients (:func:`path_tables`; tested against direct evaluation). For aggregate "min"
the DP runs twice (the optimal minimum m*, then the best integral with every cell >= m*; ``path_dp`` says why one
pass is not exact). The optimum is exact for the discretised problem (tested against brute force) and never
worse than the best fixed R (a constant sequence is feasible for the DP whenever it is feasible at all).

Boundary conditions: ``"free"``; ``"rest"`` (Rdot = 0 at both ends: k_1 = k_0, k_{K-1} = k_{K-2}); ``"closed"``
(rest and R_{K-1} = R_0, so that a closed cycle repeats with continuous R, Rdot and zero wrap-around
acceleration; solved exactly by one DP per start sample, values only, then once with back-pointers).

Quantisation: the smallest non-zero speed and acceleration of the discrete motion are dR / dt and
dR / dt^2; choose the path's sample count and the R step so that w >= 1 and a >= 1 (``PathResult.bands``
reports them; w = 0 leaves only fixed R).

For optimisers, :func:`path_optimum` returns the DP's optimal score as a pure function (jit/vmap over a
population of designs; bands from :func:`path_bands`).

**Smooth refinement** (a cubic B-spline R(t) improved by optax, accepted only when it beats the DP's exact
criterion): :func:`deltajax.motion_refine.refine_path`, whose module docstring gives the method.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple, Optional

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .cycle import cycle_profile
from .fields import check_range, float_leaf
from .geometry import ReconfigurableDelta
from .indices import INDEX_NAMES, point_indices
from .trajectory import Cycle, task_path, trapezoid_weights, with_R

__all__ = [
    "AGGREGATES",
    "BOUNDARIES",
    "RDriveLimits",
    "PathTables",
    "PathResult",
    "path_tables",
    "resolve_path",
    "resolve_tables",
    "path_bands",
    "path_optimum",
    "pointwise_path",
    "fixed_path",
    "path_score",
    "discrete_rates",
    "path_constraints_ok",
    "task_path",
    "with_R",
    "path_dp",
]

AGGREGATES = ("integral", "min")
BOUNDARIES = ("free", "rest", "closed")


class RDriveLimits(eqx.Module):
    """Limits of the reconfiguration (R) drive, at the R joint.

    Attributes:
        speed: |Rdot| limit (m/s); ``inf`` for none.
        acceleration: |Rddot| limit (m/s^2); ``inf`` for none.
        force: |F_R| limit, the total radial force of the R actuator (N); ``inf`` for none.
    """

    speed: jax.Array = eqx.field(converter=float_leaf, default=float("inf"))
    acceleration: jax.Array = eqx.field(converter=float_leaf, default=float("inf"))
    force: jax.Array = eqx.field(converter=float_leaf, default=float("inf"))

    def __check_init__(self):
        for name, unit in (("speed", "m/s"), ("acceleration", "m/s^2"), ("force", "N")):
            v = getattr(self, name)
            if not isinstance(v, jax.core.Tracer) and np.ndim(v) != 0:
                raise ValueError(f"RDriveLimits.{name} must be a scalar (one R drive), got shape {np.shape(v)}")
            check_range("RDriveLimits", name, v, unit=unit, allow_inf=True)


class PathTables(NamedTuple):
    """Everything the DP needs, per (sample j, R sample k).

    Attributes:
        t: (K,) sample times (s).
        R: (n_R,) the R samples (m).
        value: (K, n_R) criterion value; NaN where infeasible.
        feasible: (K, n_R) reachable (IK within limits), criterion finite and dynamics non-singular.
        force_coef: (K, n_R, 4) F_R = c0 + c1 Rdot + c2 Rdot^2 + c3 Rddot (N; Rdot in m/s, Rddot in m/s^2).
        weights: (K,) trapezoid weights of the time integral (s).
        R_step: spacing of the R samples (m).
    """

    t: Float[Array, "K"]
    R: Float[Array, "n"]
    value: Float[Array, "K n"]
    feasible: Bool[Array, "K n"]
    force_coef: Float[Array, "K n 4"]
    weights: Float[Array, "K"]
    R_step: Float[Array, ""]


class PathResult(NamedTuple):
    """A path R(t) on the R samples and its evaluation (host NumPy arrays).

    Attributes:
        k: (K,) R sample index per path sample (-1 where the problem has no feasible path).
        R, R_dot, R_ddot: (K,) base radius (m) and its discrete rates (m/s, m/s^2), see :func:`discrete_rates`.
        value: (K,) criterion along the path.
        force_R: (K,) R actuator force at the discrete rates (N).
        score: (primary, secondary): (integral, min) for aggregate "integral", (min, integral) for "min".
        ok: a feasible path exists (and ``k`` is one).
        bands: (w, a) the speed and acceleration bands in R samples.
    """

    k: np.ndarray
    R: np.ndarray
    R_dot: np.ndarray
    R_ddot: np.ndarray
    value: np.ndarray
    force_R: np.ndarray
    score: tuple
    ok: bool
    bands: tuple


def check_path_args(criterion: str, aggregate: str, boundary: str = "free") -> None:
    if criterion not in INDEX_NAMES:
        raise ValueError(f"criterion must be one of {INDEX_NAMES}, got {criterion!r}")
    if aggregate not in AGGREGATES:
        raise ValueError(f"aggregate must be one of {AGGREGATES}, got {aggregate!r}")
    if boundary not in BOUNDARIES:
        raise ValueError(f"boundary must be one of {BOUNDARIES}, got {boundary!r}")


def _check_cycle(cycle: Cycle) -> None:
    if cycle.space != "cartesian":
        raise ValueError(f"path resolution needs a Cartesian cycle, got cycle.space={cycle.space!r}")
    if cycle.n_samples < 3:
        raise ValueError(f"the cycle needs >= 3 samples, got {cycle.n_samples}")


def criterion_at(robot, p, R, criterion, b_v, b_f, beta):
    """(feasible, value) of one point at base radius R (m): the public kernel :func:`deltajax.point_indices`."""
    cs, ind = point_indices(robot.with_base_radius(R), p, b_v=b_v, b_f=b_f, beta=beta)
    v = getattr(ind, criterion)
    ok = jnp.all(cs.ok) & jnp.isfinite(v)
    return ok, jnp.where(ok, v, jnp.nan)


def path_forces(robot, cycle: Cycle, p, pd, pdd, R, R_dot, R_ddot):
    """F_R (N) at arbitrary samples (flat arrays) via the public :func:`deltajax.cycle_profile` at T = 1 s."""
    n = p.shape[0]
    probe = Cycle(u=jnp.linspace(0.0, 1.0, n, dtype=p.dtype), x=p, dx=pd, ddx=pdd, duration=1.0,
                  R=R, dR=R_dot, ddR=R_ddot, space="cartesian")
    prof = cycle_profile(robot, probe)
    return prof.force_R, prof.tau, prof.ok


def path_tables(recon: ReconfigurableDelta, cycle: Cycle, criterion: str = "k_tilde", *, b_v: float = 2.0,
                b_f: float = 4.2, beta: float = 0.5) -> PathTables:
    """Criterion, feasibility and R-force coefficients at every (path sample, R sample) (pure; jit-able).

    Args:
        recon: reconfigurable robot with a mass model (``recon.robot.mass``).
        cycle: Cartesian :class:`deltajax.trajectory.Cycle` at its nominal duration.
        criterion: index name in :data:`deltajax.INDEX_NAMES`.
        b_v, b_f, beta: k~ parameters.
    """
    _check_cycle(cycle)
    robot = recon.robot
    x, xd, xdd = cycle.rates()
    dtype = x.dtype
    R = recon.R_samples().astype(dtype)
    K, n = x.shape[0], R.shape[0]
    feas, val = jax.vmap(jax.vmap(lambda p, r: criterion_at(robot, p, r, criterion, b_v, b_f, beta),
                                  in_axes=(None, 0)), in_axes=(0, None))(x, R)
    # four probes (Rdot, Rddot) = (0, 0), (1, 0), (-1, 0), (0, 1) give the exact quadratic/affine coefficients
    probes = jnp.asarray([[0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 1.0]], dtype)
    rep = lambda a: jnp.broadcast_to(a[:, None, None, :], (K, n, 4, 3)).reshape(-1, 3)  # noqa: E731
    RR = jnp.broadcast_to(R[None, :, None], (K, n, 4)).reshape(-1)
    vd = jnp.broadcast_to(probes[None, None, :, 0], (K, n, 4)).reshape(-1)
    vdd = jnp.broadcast_to(probes[None, None, :, 1], (K, n, 4)).reshape(-1)
    F, _, ok = path_forces(robot, cycle, rep(x), rep(xd), rep(xdd), RR, vd, vdd)
    F = F.reshape(K, n, 4)
    ok = jnp.all(ok.reshape(K, n, 4), axis=-1)
    c0 = F[..., 0]
    c1 = 0.5 * (F[..., 1] - F[..., 2])
    c2 = 0.5 * (F[..., 1] + F[..., 2]) - c0
    c3 = F[..., 3] - c0
    coef = jnp.stack([c0, c1, c2, c3], axis=-1)
    feasible = feas & ok & jnp.all(jnp.isfinite(coef), axis=-1)
    dt = cycle.duration / (K - 1)
    return PathTables(t=cycle.time(), R=R, value=jnp.where(feasible, val, jnp.nan), feasible=feasible,
                      force_coef=jnp.where(feasible[..., None], coef, jnp.nan),
                      weights=trapezoid_weights(K, dt, dtype), R_step=jnp.asarray(recon.R_step, dtype))


def _force_eval(coef, v, acc):
    return coef[..., 0] + v * (coef[..., 1] + v * coef[..., 2]) + acc * coef[..., 3]


def path_bands(recon: ReconfigurableDelta, cycle: Cycle, limits: RDriveLimits) -> tuple[int, int]:
    """(w, a): the speed and acceleration bands in R samples for this robot's R step and the cycle's dt (host)."""
    dR = float(recon.R_step)
    dt = float(cycle.duration) / (cycle.n_samples - 1)
    n = recon.n_R
    sp, ac = float(limits.speed), float(limits.acceleration)
    # 1e-9 relative slack: a limit that is exactly a whole number of samples keeps that band
    w = n - 1 if not math.isfinite(sp) else min(n - 1, int(math.floor(sp * dt / dR * (1 + 1e-9))))
    a = 2 * w if not math.isfinite(ac) else min(2 * w, int(math.floor(ac * dt * dt / dR * (1 + 1e-9))))
    return w, a


# -- the DP ------------------------------------------------------------------------------------------------

def lex_better(p1, s1, p2, s2):
    return (p1 > p2) | ((p1 == p2) & (s1 > s2))


def _lex_argmax(P, S, axis):
    best_p = jnp.max(P, axis=axis, keepdims=True)
    S_m = jnp.where(P == best_p, S, -jnp.inf)
    idx = jnp.argmax(S_m, axis=axis)
    take = lambda X: jnp.take_along_axis(X, jnp.expand_dims(idx, axis), axis=axis).squeeze(axis)  # noqa: E731
    return idx, take(P), take(S)


def path_dp(value, feasible, coef, weights, dR, dt, fmax, k0, *, w: int, a: int, primary_min: bool, boundary: str,
        backtrack: bool, speed=math.inf, accel=math.inf):
    """Viterbi over states (k_j, d_j = k_j - k_{j-1}); returns (P, S, path k (K,) or None).

    ``k0`` (traced int) fixes the start sample for ``boundary="closed"`` (ignored otherwise). ``speed`` (m/s) and
    ``accel`` (m/s^2) are traced limits applied inside the static bands w, a (for a population whose R step
    differs per design: bands from the smallest step, limits per design); ``inf`` leaves the bands alone.

    ``primary_min``: the lexicographic order (min, then integral) in two exact passes. One (min, integral) pair
    per DP state is not exact: which of two partial paths continues better depends on the minimum still to come
    (a partial path with the higher running minimum but the lower integral loses once a later cell drags both
    minima to the same value). Both single criteria are exact per state (min and sum are monotone in the
    running value), so pass 1 finds the optimal minimum m* (the bottleneck DP) and pass 2 maximises the integral
    over the paths whose every cell is >= m* (cells below m* infeasible): each such path has minimum exactly m*.
    """
    if not primary_min:
        return _dp_pass(value, feasible, coef, weights, dR, dt, fmax, k0, w=w, a=a, primary_min=False,
                        boundary=boundary, backtrack=backtrack, speed=speed, accel=accel)
    m_star, _, _ = _dp_pass(value, feasible, coef, weights, dR, dt, fmax, k0, w=w, a=a, primary_min=True,
                            boundary=boundary, backtrack=False, speed=speed, accel=accel)
    at_least = feasible & (value >= m_star)         # NaN (infeasible) compares False; m* = -inf: no path either way
    integral, _, path = _dp_pass(value, at_least, coef, weights, dR, dt, fmax, k0, w=w, a=a, primary_min=False,
                                 boundary=boundary, backtrack=backtrack, speed=speed, accel=accel)
    return m_star, integral, path


def _dp_pass(value, feasible, coef, weights, dR, dt, fmax, k0, *, w: int, a: int, primary_min: bool, boundary: str,
             backtrack: bool, speed=math.inf, accel=math.inf):
    """One Viterbi pass of :func:`path_dp` with one lexicographic (P, S) pair per state: exact for (integral, min),
    and for the primary alone when ``primary_min`` (the bottleneck); :func:`path_dp` composes the exact (min,
    integral) order from two passes."""
    K, n = value.shape
    D, A = 2 * w + 1, 2 * a + 1
    neg = -jnp.inf
    dtype = value.dtype
    v = jnp.where(feasible, value, neg)
    wv = jnp.where(feasible, weights[:, None] * value, neg)

    def node(P, S, j_val, j_wv):
        # primary/secondary update by one more sample's contribution
        if primary_min:
            return jnp.minimum(P, j_val), S + j_wv
        return P + j_wv, jnp.minimum(S, j_val)

    ks = jnp.arange(n)
    ds = jnp.arange(D) - w
    # init at sample 1: state (k1, d) with k0' = k1 - d
    k0s = ks[:, None] - ds[None, :]
    valid0 = (k0s >= 0) & (k0s < n)
    k0c = jnp.clip(k0s, 0, n - 1)
    if primary_min:
        P = jnp.minimum(v[0][k0c], v[1][:, None])
        S = wv[0][k0c] + wv[1][:, None]
    else:
        P = wv[0][k0c] + wv[1][:, None]
        S = jnp.minimum(v[0][k0c], v[1][:, None])
    slack = 1.0 + 1e-9   # as path_bands: a limit that is exactly a whole number of samples keeps that band
    init_ok = valid0 & (jnp.abs(ds)[None, :] * dR <= speed * dt * slack)
    if boundary in ("rest", "closed"):
        init_ok = init_ok & (ds[None, :] == 0)
    if boundary == "closed":
        init_ok = init_ok & (ks[:, None] == k0)
    P = jnp.where(init_ok, P, neg)
    S = jnp.where(init_ok, S, neg)

    kn = ks[:, None, None]
    dn = ds[None, :, None]
    delta = (jnp.arange(A) - a)[None, None, :]
    d_prev = dn - delta
    cur = kn - dn
    prev = cur - d_prev
    valid = (jnp.abs(d_prev) <= w) & (cur >= 0) & (cur < n)
    valid = valid & (jnp.abs(dn) * dR <= speed * dt * slack) & (jnp.abs(delta) * dR <= accel * dt * dt * slack)
    cur_c = jnp.clip(cur, 0, n - 1)
    dprev_c = jnp.clip(d_prev + w, 0, D - 1)
    prev_c = jnp.clip(prev, 0, n - 1)
    acc = (delta * dR / (dt * dt)).astype(dtype)
    v_mid = ((d_prev + dn) * dR / (2 * dt)).astype(dtype)
    v_first = (d_prev * dR / dt).astype(dtype)
    v_last = (dn * dR / dt).astype(dtype)

    def step(carry, j):
        P, S = carry
        Pg = jnp.where(valid, P[cur_c, dprev_c], neg)
        Sg = jnp.where(valid, S[cur_c, dprev_c], neg)
        ok = jnp.abs(_force_eval(coef[j][cur_c], v_mid, acc)) <= fmax
        ok0 = jnp.abs(_force_eval(coef[0][prev_c], v_first, acc)) <= fmax
        okl = jnp.abs(_force_eval(coef[K - 1][jnp.broadcast_to(kn, cur.shape)], v_last, acc)) <= fmax
        ok = ok & ((j != 1) | ok0) & ((j != K - 2) | okl)
        Pg = jnp.where(ok, Pg, neg)
        Sg = jnp.where(ok, Sg, neg)
        idx, Pb, Sb = _lex_argmax(Pg, Sg, axis=2)
        Pn, Sn = node(Pb, Sb, v[j + 1][:, None], wv[j + 1][:, None])
        Pn = jnp.where(Pb > neg, Pn, neg)
        Sn = jnp.where(Pb > neg, Sn, neg)
        return (Pn, Sn), (idx.astype(jnp.int16) if backtrack else None)

    (P, S), bps = jax.lax.scan(step, (P, S), jnp.arange(1, K - 1))
    fin_ok = jnp.ones((n, D), bool)
    if boundary in ("rest", "closed"):
        fin_ok = fin_ok & (ds[None, :] == 0)
    if boundary == "closed":
        fin_ok = fin_ok & (ks[:, None] == k0)
    P = jnp.where(fin_ok, P, neg)
    S = jnp.where(fin_ok, S, neg)
    flat = jnp.argmax(jnp.where(P.reshape(-1) == jnp.max(P), S.reshape(-1), neg))
    Pbest, Sbest = P.reshape(-1)[flat], S.reshape(-1)[flat]
    if not backtrack:
        return Pbest, Sbest, None
    kL, dL = flat // D, flat % D - w

    def back(state, bp):
        k, d = state
        dl = bp[k, d + w] - a          # delta = d_{j+1} - d_j
        return (k - d, d - dl), k

    (k1, d1), ks_rev = jax.lax.scan(back, (kL, dL), bps, reverse=True)
    path = jnp.concatenate([jnp.stack([k1 - d1, k1]), ks_rev])
    return Pbest, Sbest, path


path_dp_jit = jax.jit(path_dp, static_argnames=("w", "a", "primary_min", "boundary", "backtrack"))


def _closed_starts(value, feasible, coef, weights, dR, dt, fmax, starts, *, w, a, primary_min, batch):
    one = lambda k0: path_dp(value, feasible, coef, weights, dR, dt, fmax, k0, w=w, a=a,  # noqa: E731
                         primary_min=primary_min, boundary="closed", backtrack=False)[:2]
    P, S = jax.lax.map(one, starts, batch_size=batch)
    flat = jnp.argmax(jnp.where(P == jnp.max(P), S, -jnp.inf))
    return starts[flat]


_closed_jit = jax.jit(_closed_starts, static_argnames=("w", "a", "primary_min", "batch"))


def discrete_rates(R: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(Rdot, Rddot) of a sampled R sequence: central differences inside, one-sided / neighbour's at the ends."""
    R = np.asarray(R, float)
    v = np.empty_like(R)
    acc = np.empty_like(R)
    v[1:-1] = (R[2:] - R[:-2]) / (2 * dt)
    v[0] = (R[1] - R[0]) / dt
    v[-1] = (R[-1] - R[-2]) / dt
    acc[1:-1] = (R[2:] - 2 * R[1:-1] + R[:-2]) / (dt * dt)
    acc[0], acc[-1] = acc[1], acc[-2]
    return v, acc


def _int_rates(k: np.ndarray, dR: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`discrete_rates` of R = R_min + k dR from the integer differences (the DP's own arithmetic)."""
    k = np.asarray(k, np.int64)
    v = np.empty(k.shape, float)
    acc = np.empty(k.shape, float)
    v[1:-1] = (k[2:] - k[:-2]) * dR / (2 * dt)
    v[0] = (k[1] - k[0]) * dR / dt
    v[-1] = (k[-1] - k[-2]) * dR / dt
    acc[1:-1] = (k[2:] - 2 * k[1:-1] + k[:-2]) * dR / (dt * dt)
    acc[0], acc[-1] = acc[1], acc[-2]
    return v, acc


def path_score(tables: PathTables, k: np.ndarray, aggregate: str = "integral") -> tuple[float, float]:
    """(primary, secondary) of a sample path k (K,): (integral, min) or (min, integral); -inf if infeasible."""
    val = np.asarray(tables.value)
    fe = np.asarray(tables.feasible)
    k = np.asarray(k)
    j = np.arange(val.shape[0])
    if np.any(k < 0) or not np.all(fe[j, k]):
        return -math.inf, -math.inf
    vv = val[j, k]
    integral = float(np.sum(np.asarray(tables.weights) * vv))
    mn = float(np.min(vv))
    return (integral, mn) if aggregate == "integral" else (mn, integral)


def _evaluate(tables: PathTables, k, aggregate, dt, bands, ok) -> PathResult:
    K = tables.value.shape[0]
    if not ok:
        nanK = np.full(K, np.nan)
        return PathResult(k=np.full(K, -1), R=nanK, R_dot=nanK, R_ddot=nanK, value=nanK, force_R=nanK,
                          score=(-math.inf, -math.inf), ok=False, bands=bands)
    k = np.asarray(k, int)
    R = np.asarray(tables.R)[k]
    v, acc = _int_rates(k, float(tables.R_step), dt)
    coef = np.asarray(tables.force_coef)[np.arange(K), k]
    F = _force_eval(coef, v, acc)
    val = np.asarray(tables.value)[np.arange(K), k]
    return PathResult(k=k, R=R, R_dot=v, R_ddot=acc, value=val, force_R=F, score=path_score(tables, k, aggregate),
                      ok=True, bands=bands)


def path_constraints_ok(res: PathResult, limits: RDriveLimits, dt: float, R_step: float, rtol: float = 1e-9) -> bool:
    """Do a discrete path's samples respect the rate, acceleration and force limits (with slack ``rtol``)?"""
    R = np.asarray(res.R)
    d1 = np.abs(np.diff(R)) / dt
    d2 = np.abs(np.diff(R, 2)) / (dt * dt)
    tol = rtol + 1e-9 * R_step / dt  # rounding of R_min + k dR
    return bool(np.all(d1 <= float(limits.speed) * (1 + rtol) + tol)
                and np.all(d2 <= float(limits.acceleration) * (1 + rtol) + tol / dt)
                and np.all(np.abs(res.force_R) <= float(limits.force) * (1 + rtol)))


def resolve_path(recon: ReconfigurableDelta, cycle: Cycle, criterion: str = "k_tilde", *,
                 limits: Optional[RDriveLimits] = None, aggregate: str = "integral", boundary: str = "free",
                 b_v: float = 2.0, b_f: float = 4.2, beta: float = 0.5, tables: Optional[PathTables] = None,
                 start_batch: int = 16) -> PathResult:
    """Exact path-optimal R(t) on the R samples (dynamic programming; see the module docstring).

    Args:
        recon: reconfigurable robot with a mass model.
        cycle: Cartesian cycle; its K samples are the DP's time grid (dt = T / (K - 1)).
        criterion: index to maximise (:data:`deltajax.INDEX_NAMES`).
        limits: :class:`RDriveLimits` of the R drive.
        aggregate: ``"integral"`` (time integral of the index) or ``"min"`` (its minimum along the path).
        boundary: ``"free"``, ``"rest"`` or ``"closed"``.
        b_v, b_f, beta: k~ parameters.
        tables: precomputed :func:`path_tables` (same robot, cycle and criterion).
        start_batch: starts solved together for ``boundary="closed"`` (memory vs speed).

    Returns:
        :class:`PathResult` (``ok=False`` and NaN arrays when no sample path satisfies every constraint).
    """
    limits = RDriveLimits() if limits is None else limits  # built at call time: the caller's precision
    check_path_args(criterion, aggregate, boundary)
    _check_cycle(cycle)
    if tables is None:
        tables = jax.jit(path_tables, static_argnames=("criterion",))(recon, cycle, criterion, b_v=b_v, b_f=b_f,
                                                                      beta=beta)
    w, a = path_bands(recon, cycle, limits)
    dt = float(cycle.duration) / (cycle.n_samples - 1)
    return resolve_tables(tables, dt, w, a, float(limits.force), aggregate=aggregate, boundary=boundary,
                          start_batch=start_batch)


def resolve_tables(tables: PathTables, dt: float, w: int, a: int, force_limit: float = math.inf, *,
                   aggregate: str = "integral", boundary: str = "free", start_batch: int = 16) -> PathResult:
    """The DP of :func:`resolve_path` on given tables and integer bands (w: speed, a: acceleration, in samples).

    Args:
        tables: :class:`PathTables` (any source; the DP only reads value, feasible, force_coef, weights, R_step).
        dt: sample spacing (s).
        w, a: |k_{j+1} - k_j| <= w, |k_{j+1} - 2 k_j + k_{j-1}| <= a (a is capped at 2 w, where it stops binding).
        force_limit: |F_R| limit (N).
    """
    if aggregate not in AGGREGATES or boundary not in BOUNDARIES:
        check_path_args(INDEX_NAMES[0], aggregate, boundary)
    n = tables.value.shape[1]
    w = int(min(max(w, 0), n - 1))
    a = int(min(max(a, 0), 2 * w))
    args = (tables.value, tables.feasible, tables.force_coef, tables.weights, float(tables.R_step), float(dt),
            float(force_limit))
    pm = aggregate == "min"
    k0 = 0
    if boundary == "closed":
        # only samples feasible at both ends can start a closed path (host filter; padded to limit retraces)
        fe = np.asarray(tables.feasible)
        starts = np.flatnonzero(fe[0] & fe[-1])
        if starts.size == 0:
            return _evaluate(tables, None, aggregate, float(dt), (w, a), False)
        pad = -(-starts.size // start_batch) * start_batch
        starts = np.concatenate([starts, np.full(pad - starts.size, starts[0])]).astype(np.int32)
        k0 = int(_closed_jit(*args, jnp.asarray(starts), w=w, a=a, primary_min=pm, batch=int(start_batch)))
    P, S, path = path_dp_jit(*args, k0, w=w, a=a, primary_min=pm, boundary=boundary, backtrack=True)
    ok = bool(np.isfinite(float(P)))
    return _evaluate(tables, np.asarray(path), aggregate, float(dt), (w, a), ok)


def path_optimum(recon: ReconfigurableDelta, cycle: Cycle, criterion: str = "k_tilde", *, w: int, a: int,
                 force_limit: Any = math.inf, aggregate: str = "integral", boundary: str = "free",
                 b_v: float = 2.0, b_f: float = 4.2, beta: float = 0.5, start_batch: int = 16,
                 speed_limit: Any = math.inf, accel_limit: Any = math.inf
                 ) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """The DP's optimal (primary, secondary) score, pure and jit/vmap-able over designs (no path returned).

    What an optimiser needs to score a design in the "R(t) along the cycle" mode: the same DP as
    :func:`resolve_path` (``-inf`` where no path meets the limits). The bands are static: compute them once with
    :func:`path_bands` (they depend only on the R step and dt, shared by a population);
    ``jax.vmap(lambda r: path_optimum(r, cycle, w=w, a=a))(population)``. For ``boundary="closed"`` every start
    sample is tried (no host filter), ``start_batch`` at a time. ``speed_limit`` (m/s) / ``accel_limit`` (m/s^2):
    traced per-design limits inside the static bands (a population with different R steps: static bands from
    the smallest step, or w = n_R - 1, a = 2 w, and the limits here).
    """
    check_path_args(criterion, aggregate, boundary)
    tab = path_tables(recon, cycle, criterion, b_v=b_v, b_f=b_f, beta=beta)
    dt = cycle.duration / (cycle.n_samples - 1)
    n = tab.value.shape[1]
    w = int(min(max(w, 0), n - 1))
    a = int(min(max(a, 0), 2 * w))
    args = (tab.value, tab.feasible, tab.force_coef, tab.weights, tab.R_step, dt, force_limit)
    pm = aggregate == "min"
    lim = dict(speed=speed_limit, accel=accel_limit)
    if boundary != "closed":
        P, S, _ = path_dp(*args, 0, w=w, a=a, primary_min=pm, boundary=boundary, backtrack=False, **lim)
        return P, S
    one = lambda k0: path_dp(*args, k0, w=w, a=a, primary_min=pm, boundary="closed", backtrack=False,  # noqa: E731
                         **lim)[:2]
    P, S = jax.lax.map(one, jnp.arange(n), batch_size=start_batch)
    best = jnp.argmax(jnp.where(P == jnp.max(P), S, -jnp.inf))
    return P[best], S[best]


def pointwise_path(tables: PathTables, aggregate: str = "integral", dt: float = 1.0) -> PathResult:
    """Pointwise resolution along the path: k_j = argmax_k value[j, k] (ties: smallest R); no drive limits.

    Samples with no feasible R make the whole path infeasible (``ok=False``) but ``k`` still holds -1 there.
    """
    val = np.where(np.asarray(tables.feasible), np.asarray(tables.value), -np.inf)
    k = np.argmax(val, axis=1)
    has = np.isfinite(val[np.arange(val.shape[0]), k])
    if not np.all(has):
        res = _evaluate(tables, None, aggregate, dt, (None, None), False)
        return res._replace(k=np.where(has, k, -1))
    return _evaluate(tables, k, aggregate, dt, (None, None), True)


def fixed_path(tables: PathTables, limits: RDriveLimits, aggregate: str = "integral", dt: float = 1.0) -> PathResult:
    """Best fixed R on the path: every sample feasible and the static-R force within the limit (R at rest)."""
    fe = np.asarray(tables.feasible)
    F0 = np.abs(np.asarray(tables.force_coef)[..., 0])
    ok_k = np.all(fe, axis=0) & np.all(np.where(fe, F0, np.inf) <= float(limits.force), axis=0)
    best, best_score = -1, (-math.inf, -math.inf)
    K = fe.shape[0]
    for k in np.flatnonzero(ok_k):
        s = path_score(tables, np.full(K, k), aggregate)
        if s > best_score:   # lexicographic; ties keep the smaller R
            best, best_score = int(k), s
    if best < 0:
        return _evaluate(tables, None, aggregate, dt, (0, 0), False)
    return _evaluate(tables, np.full(K, best), aggregate, dt, (0, 0), True)
