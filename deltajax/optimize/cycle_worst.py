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
from ..trajectory import Cycle
from .rays import golden_min, padded_linspace

__all__ = ["worst_along", "CycleWorst", "cycle_worst"]


def worst_along(f: Callable, u, V, *, n_start: int = 3, n_golden: int = 14, n_valid=None):
    """Minimum of each of the fields ``f(t) -> (m,)`` over t in [0, 1] from their values ``V`` (K, m) at the
    uniform samples ``u`` (K,): from the ``n_start`` worst samples of each field a golden section (``n_golden``
    steps) on [u_k - h, u_k + h] (h: the sample spacing, clipped to [0, 1]). NaN (e.g. unreachable) is the worst;
    a NaN sample or a NaN point found gives NaN. Returns (minimum (m,), its t (m,)); the minimum is never above the
    samples' (the search can only find worse points). ``n_valid`` (traced, optional): only the first n_valid
    samples count (the rest padding, never chosen; the spacing 1 / (n_valid - 1))."""
    K = u.shape[0]
    h = 1.0 / (K - 1) if n_valid is None else 1.0 / jnp.asarray(n_valid - 1, u.dtype)
    Vw = jnp.where(jnp.isnan(V), -jnp.inf, V)
    if n_valid is not None:
        Vw = jnp.where((jnp.arange(K) < n_valid)[:, None], Vw, jnp.inf)
    ns = min(int(n_start), K)

    def field(v, c):
        _, idx = jax.lax.top_k(-v, ns)

        def search(t0):
            return golden_min(lambda t: f(t)[c], jnp.clip(t0 - h, 0.0, 1.0), jnp.clip(t0 + h, 0.0, 1.0), n_golden)

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
        t_worst: (2,) the normalised times of the joint margin's and the clearance's worst points.
    """

    joint_margin: jax.Array
    interference_margin: jax.Array
    rate: C.CycleRate
    sampled: dict
    t_worst: jax.Array


def cycle_worst(robot, path: Callable, n_samples: int, duration, point_fields: Callable, motor, gear_ratio, *,
                dwell=0.0, payload_mass=None, n_start: int = 3, n_golden: int = 14, T_low: float = 1e-3,
                T_high: float = 60.0, n_iter: int = 60, n_valid=None) -> CycleWorst:
    """The worst joint margin, clearance and peak utilisation along a cycle, found by :func:`worst_along` from
    ``n_samples`` uniform samples, and the cycle rate that the refined peak allows.

    Args:
        robot: :class:`deltajax.Delta` with a mass model (R frozen).
        path: ``u (k,) -> (x, x', x'')`` each (k, 3): the cycle's path at any normalised times (m, base frame).
        n_samples: K dense samples (>= 3).
        duration: the cycle's nominal duration (s; loads where no duration meets the limits).
        point_fields: ``p (3,) -> (joint margin, interference margin)`` at a point of the path (NaN: unreachable).
        motor, gear_ratio, dwell, payload_mass, T_low, T_high, n_iter: as :func:`deltajax.constraints.cycle_rate`.
        n_valid: (traced, optional) the samples' count, at most ``n_samples`` (then the array size): the same
            figures as with ``n_samples=n_valid``, one compiled program for every count up to the size.

    The peak (:func:`deltajax.constraints.cycle_rate_refined`): at the dense samples' fastest time T0 (exactly
    :func:`deltajax.constraints.cycle_rate` on the samples) the peak utilisation max over actuators of |tau_m| /
    envelope(omega_m) is maximised in u from the worst samples; the cycle time is then the smallest T at which the
    dense samples (peak and RMS) and the refined point (peak) all hold, never below T0. The point is found at T0;
    the time it moves T by is far below the doubling check's tolerance, so it is not searched again at the new T.
    NaN everywhere (as ``cycle_rate``) where a sample or the refined point is unreachable.
    """
    if n_valid is None:
        u = jnp.arange(n_samples, dtype=jnp.result_type(float)) / (n_samples - 1)
    else:       # the padding repeats the last sample (u = 1)
        u = padded_linspace(0.0, 1.0, n_valid, n_samples)
    x, dx, ddx = path(u)
    dt = x.dtype
    u = u.astype(dt)
    cyc = Cycle(u=u, x=x, dx=dx, ddx=ddx, duration=duration, space="cartesian")

    def fields_at(t):
        return jnp.stack(point_fields(path(jnp.reshape(t, (1,)))[0][0]))

    def nanmin(a):
        return jnp.where(jnp.any(jnp.isnan(a)), jnp.nan, jnp.min(a))

    Vm = jax.vmap(lambda p: jnp.stack(point_fields(p)))(x)                              # (K, 2)
    margins, t_m = worst_along(fields_at, u, Vm, n_start=n_start, n_golden=n_golden, n_valid=n_valid)
    any_nan = jnp.any(jnp.isnan(Vm), axis=0)
    margins = jnp.where(any_nan, jnp.nan, margins)

    rate, T0, peak0 = C.cycle_rate_refined(
        robot, cyc, path,
        lambda f, uu, V: worst_along(f, uu, V, n_start=n_start, n_golden=n_golden, n_valid=n_valid)[1][0], motor,
        gear_ratio, dwell=dwell, payload_mass=payload_mass, T_low=T_low, T_high=T_high, n_iter=n_iter,
        n_valid=n_valid)
    sampled = {"joint_margin": nanmin(Vm[:, 0]), "interference_margin": nanmin(Vm[:, 1]),
               "cycle_time": T0, "peak_utilisation": peak0}
    return CycleWorst(joint_margin=margins[0], interference_margin=margins[1], rate=rate, sampled=sampled,
                      t_worst=t_m)
