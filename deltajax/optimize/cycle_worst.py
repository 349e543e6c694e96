"""Worst cases along a cycle found, not only sampled: dense samples in normalised time u, then a golden section in
u from the worst samples, for the joint margin and the link clearance along the path and for the motors' peak
torque utilisation (the figure that sets the fastest feasible cycle time of :func:`deltajax.constraints.cycle_rate`).

* :func:`worst_along`: the minimum of fields f(u) over [0, 1] from their samples: from the ``n_start`` worst
  samples of each field a golden section within one sample spacing either side.
* :func:`cycle_worst`: a design's cycle: the worst joint margin and clearance along the path, and the cycle rate
  with the peak utilisation refined (the fastest cycle time at which the refined peak still holds, and the RMS).

The path is evaluated at any u by a pure function (e.g. :func:`deltajax.trajectory.adept_path`, the one
:func:`deltajax.trajectory.adept_cycle` samples). The RMS torque is an integral over the cycle, not a worst point:
it stays the trapezoidal rule on the dense samples, and doubling the density is its check
(:func:`deltajax.optimize.certify.certify_design`). Pure JAX, one traced copy of each searched field.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp

from .. import constraints as C
from ..cycle import log_bisect
from ..trajectory import Cycle
from .rays import _golden_min

__all__ = ["worst_along", "CycleWorst", "cycle_worst"]


def worst_along(f: Callable, u, V, *, n_start: int = 3, n_golden: int = 14):
    """Minimum of each of the fields ``f(t) -> (m,)`` over t in [0, 1] from their values ``V`` (K, m) at the
    uniform samples ``u`` (K,): from the ``n_start`` worst samples of each field a golden section (``n_golden``
    steps) on [u_k - h, u_k + h] (h: the sample spacing, clipped to [0, 1]). NaN (e.g. unreachable) is the worst;
    a NaN sample or a NaN point found gives NaN. Returns (minimum (m,), its t (m,)); the minimum is never above the
    samples' (the search can only find worse points)."""
    K = u.shape[0]
    h = 1.0 / (K - 1)
    Vw = jnp.where(jnp.isnan(V), -jnp.inf, V)
    ns = min(int(n_start), K)

    def field(v, c):
        _, idx = jax.lax.top_k(-v, ns)

        def search(t0):
            return _golden_min(lambda t: f(t)[c], jnp.clip(t0 - h, 0.0, 1.0), jnp.clip(t0 + h, 0.0, 1.0), n_golden)

        ts, fs = jax.vmap(search)(u[idx])
        j = jnp.argmin(fs)
        k = jnp.argmin(v)
        better = fs[j] < v[k]
        best = jnp.where(better, fs[j], v[k])
        return jnp.where(jnp.isneginf(best), jnp.nan, best), jnp.where(better, ts[j], u[k])

    return jax.vmap(field, in_axes=(1, 0))(Vw, jnp.arange(V.shape[1]))


class CycleWorst(NamedTuple):
    """A design's cycle, worst cases refined (:func:`cycle_worst`).

    Attributes:
        joint_margin, interference_margin: the fields' minima along the path (units of ``point_fields``).
        rate: :class:`deltajax.constraints.CycleRate` with the refined peak: the fastest cycle time at which the
            peak utilisation holds at the dense samples and at the refined worst points, and the loads there
            (peak torque and utilisation over both; RMS and speed from the dense samples).
        sampled: the same figures on the dense samples alone (a dict: ``joint_margin``, ``interference_margin``,
            ``cycle_time``, ``peak_utilisation``).
        t_worst: (3,) the normalised times of the joint margin's, the clearance's and the peak's worst points.
    """

    joint_margin: jax.Array
    interference_margin: jax.Array
    rate: C.CycleRate
    sampled: dict
    t_worst: jax.Array


def cycle_worst(robot, path: Callable, n_samples: int, duration, point_fields: Callable, motor, gear_ratio, *,
                dwell=0.0, payload_mass=None, n_start: int = 3, n_golden: int = 14, T_low: float = 1e-3,
                T_high: float = 60.0, n_iter: int = 60) -> CycleWorst:
    """The worst joint margin, clearance and peak utilisation along a cycle, found by :func:`worst_along` from
    ``n_samples`` uniform samples, and the cycle rate that the refined peak allows.

    Args:
        robot: :class:`deltajax.Delta` with a mass model (R frozen).
        path: ``u (k,) -> (x, x', x'')`` each (k, 3): the cycle's path at any normalised times (m, base frame).
        n_samples: K dense samples (>= 3).
        duration: the cycle's nominal duration (s; loads where no duration meets the limits).
        point_fields: ``p (3,) -> (joint margin, interference margin)`` at a point of the path (NaN: unreachable).
        motor, gear_ratio, dwell, payload_mass, T_low, T_high, n_iter: as :func:`deltajax.constraints.cycle_rate`.

    The peak: at the dense samples' fastest time T0 (exactly :func:`deltajax.constraints.cycle_rate` on the
    samples) the peak utilisation max over actuators of |tau_m| / envelope(omega_m) is maximised in u from the
    worst samples; the cycle time is then the smallest T at which the dense samples (peak and RMS) and the refined
    points (peak) all hold, never below T0. The refined points are found at T0; the time they move T by is far
    below the doubling check's tolerance, so they are not searched again at the new T. NaN everywhere (as
    ``cycle_rate``) where a sample or a refined point is unreachable.
    """
    u = jnp.arange(n_samples, dtype=jnp.result_type(float)) / (n_samples - 1)
    x, dx, ddx = path(u)
    dt = x.dtype
    u = u.astype(dt)
    cyc = Cycle(u=u, x=x, dx=dx, ddx=ddx, duration=duration, space="cartesian")

    def fields_at(t):
        return jnp.stack(point_fields(path(jnp.reshape(t, (1,)))[0][0]))

    def nanmin(a):
        return jnp.where(jnp.any(jnp.isnan(a)), jnp.nan, jnp.min(a))

    Vm = jax.vmap(lambda p: jnp.stack(point_fields(p)))(x)                              # (K, 2)
    margins, t_m = worst_along(fields_at, u, Vm, n_start=n_start, n_golden=n_golden)
    any_nan = jnp.any(jnp.isnan(Vm), axis=0)
    margins = jnp.where(any_nan, jnp.nan, margins)

    # the cycle rate on the dense samples (cycle_rate's algebra), then the peak refined at its time
    m, n, drive = C._guarded_drive(motor, gear_ratio)
    r = C.with_drive(robot, m, n, payload_mass)
    a, g, thd, ok = C._unit_profile(r, cyc)
    ok = ok & drive
    dw = jnp.asarray(dwell, dt)
    T0 = jnp.where(ok, C._bisect_time(a, g, thd, m, n, dw, T_low, T_high, n_iter), jnp.nan)
    T0l = jnp.where(jnp.isfinite(T0), T0, cyc.duration)

    def unit_at(t):
        tt = jnp.reshape(t, (1,))
        xt, dxt, ddxt = path(tt)
        a1, g1, thd1, ok1 = C._unit_profile(r, Cycle(u=tt, x=xt, dx=dxt, ddx=ddxt, duration=duration,
                                                     space="cartesian"))
        return a1[0], g1[0], thd1[0], ok1

    def neg_peak(t, T):
        a1, g1, thd1, ok1 = unit_at(t)
        return jnp.where(ok1, -jnp.max(C._peak_ratio(a1, g1, thd1, T, m, n)[2]), jnp.nan)

    Vp = -jnp.max(C._peak_ratio(a, g, thd, T0l, m, n)[2], axis=1)                       # (K,)
    _, t_p = worst_along(lambda t: neg_peak(t, T0l)[None], u, Vp[:, None], n_start=n_start, n_golden=n_golden)
    a1, g1, thd1, ok1 = unit_at(t_p[0])
    ok = ok & ok1

    def feasible(T):
        L = C._loads_from_unit(a, g, thd, T, dw, m, n, jnp.asarray(True))
        pk = jnp.max(C._peak_ratio(a1[None], g1[None], thd1[None], T, m, n)[2])
        return (L.peak_utilisation <= 1.0) & (L.rms_utilisation <= 1.0) & (pk <= 1.0)

    T = jnp.where(ok, jnp.maximum(T0, log_bisect(feasible, T_low, T_high, dt, n_iter)), jnp.nan)
    ppm = jnp.where(jnp.isfinite(T), 60.0 / (T + 2.0 * dw), jnp.where(jnp.isnan(T), jnp.nan, 0.0))
    Tl = jnp.where(jnp.isfinite(T), T, cyc.duration)
    L = C._loads_from_unit(a, g, thd, Tl, dw, m, n, ok)
    tau1, _, ratio1 = C._peak_ratio(a1[None], g1[None], thd1[None], Tl, m, n)
    nan = jnp.asarray(jnp.nan, dt)
    L = L._replace(peak_torque=jnp.where(ok, jnp.maximum(L.peak_torque, jnp.abs(tau1[0])), nan),
                   peak_utilisation=jnp.where(ok, jnp.maximum(L.peak_utilisation, jnp.max(ratio1)), nan))
    L0 = C._loads_from_unit(a, g, thd, T0l, dw, m, n, ok)
    sampled = {"joint_margin": nanmin(Vm[:, 0]), "interference_margin": nanmin(Vm[:, 1]),
               "cycle_time": T0, "peak_utilisation": L0.peak_utilisation}
    return CycleWorst(joint_margin=margins[0], interference_margin=margins[1],
                      rate=C.CycleRate(cycle_time=T, picks_per_min=ppm, loads=L), sampled=sampled,
                      t_worst=jnp.concatenate([t_m, t_p]))
