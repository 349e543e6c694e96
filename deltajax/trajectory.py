"""Motion laws and trajectories (pick-and-place cycles, the GA paper's test motion), sampled for dynamics.

A :class:`Cycle` is a path sampled at K points of *normalised time* u in [0, 1] with its first and second
derivatives with respect to u, plus a nominal duration T. For a duration T the physical rates are
``x_dot = x' / T`` and ``x_ddot = x'' / T^2``: the geometric path stays the same and only the time scale
changes, which is what makes the minimum cycle time under torque and speed limits a 1-D problem
(:func:`deltajax.cycle.cycle_metrics`). Cycles are pytrees: stack them (``jax.tree.map(jnp.stack, ...)``)
and ``jax.vmap`` over trajectories as over designs.

Frame: base frame, z down (docs/CONVENTIONS.md); "up" is -z.
"""

from __future__ import annotations

import math
from typing import Any, Callable, Optional, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .fields import float_leaf

__all__ = [
    "MOTION_LAWS",
    "motion_law",
    "poly5",
    "cycloidal",
    "modified_trapezoid",
    "Cycle",
    "adept_cycle",
    "adept_path",
    "point_to_point",
    "ga_paper_motion",
    "with_R_profile",
    "with_R",
    "task_path",
    "trapezoid_weights",
    "ADEPT_HEIGHT",
    "ADEPT_WIDTH",
]

ADEPT_HEIGHT = 0.025  #: m, the standard cycle's vertical stroke
ADEPT_WIDTH = 0.305   #: m, the standard cycle's horizontal stroke


def _clip01(t):
    return jnp.clip(t, 0.0, 1.0)


def poly5(t: Float[Array, "..."]) -> tuple[Array, Array, Array]:
    """5th-order polynomial (3-4-5) rest-to-rest law: s = 10 t^3 - 15 t^4 + 6 t^5 on [0, 1].

    Returns (s, s', s'') (zero-order hold outside [0, 1]: s = 0 or 1, derivatives 0). Peak s'' = 10/sqrt(3).
    """
    inside = (t >= 0.0) & (t <= 1.0)
    x = _clip01(t)
    s = x ** 3 * (10.0 - 15.0 * x + 6.0 * x * x)
    ds = 30.0 * x * x * (1.0 - x) ** 2
    dds = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x)
    return s, jnp.where(inside, ds, 0.0), jnp.where(inside, dds, 0.0)


def cycloidal(t: Float[Array, "..."]) -> tuple[Array, Array, Array]:
    """Cycloidal law s = t - sin(2 pi t) / (2 pi): zero acceleration at both ends. Peak s'' = 2 pi."""
    inside = (t >= 0.0) & (t <= 1.0)
    x = _clip01(t)
    w = 2.0 * math.pi
    s = x - jnp.sin(w * x) / w
    ds = 1.0 - jnp.cos(w * x)
    dds = w * jnp.sin(w * x)
    return s, jnp.where(inside, ds, 0.0), jnp.where(inside, dds, 0.0)


_W_MT = 4.0 * math.pi
#: Peak acceleration coefficient of the modified trapezoid (so that s(1) = 1); the classic value 4.888.
MT_PEAK = 0.5 / ((0.125 - 1.0 / _W_MT) / _W_MT + 1.0 / (4.0 * _W_MT) + 1.0 / 32.0 + (1.0 / _W_MT + 0.25) / 8.0
                 + 1.0 / _W_MT ** 2)


def _mt_half(x):
    """Modified trapezoid on the first half, x in [0, 1/2]: sine ramp (0-1/8), constant (1/8-3/8), cosine (3/8-1/2)."""
    A, w = MT_PEAK, _W_MT
    x1 = jnp.minimum(x, 0.125)
    s1 = A * (x1 - jnp.sin(w * x1) / w) / w
    v1 = A * (1.0 - jnp.cos(w * x1)) / w
    a1 = A * jnp.sin(w * x1)
    v1e, s1e = A / w, A * (0.125 - 1.0 / w) / w
    x2 = jnp.clip(x - 0.125, 0.0, 0.25)
    s2 = s1e + v1e * x2 + 0.5 * A * x2 * x2
    v2 = v1e + A * x2
    v2e, s2e = v1e + 0.25 * A, s1e + 0.25 * v1e + A / 32.0
    x3 = jnp.clip(x - 0.375, 0.0, 0.125)
    s3 = s2e + v2e * x3 + A * (1.0 - jnp.cos(w * x3)) / (w * w)
    v3 = v2e + A * jnp.sin(w * x3) / w
    a3 = A * jnp.cos(w * x3)
    seg1, seg2 = x <= 0.125, x <= 0.375
    s = jnp.where(seg1, s1, jnp.where(seg2, s2, s3))
    v = jnp.where(seg1, v1, jnp.where(seg2, v2, v3))
    a = jnp.where(seg1, a1, jnp.where(seg2, A, a3))
    return s, v, a


def modified_trapezoid(t: Float[Array, "..."]) -> tuple[Array, Array, Array]:
    """Modified trapezoidal acceleration law (sine ramps, constant plateaus; peak s'' = 4.888)."""
    inside = (t >= 0.0) & (t <= 1.0)
    x = _clip01(t)
    first = x <= 0.5
    sa, va, aa = _mt_half(jnp.where(first, x, 0.5))
    sb, vb, ab = _mt_half(jnp.where(first, 0.5, 1.0 - x))
    s = jnp.where(first, sa, 1.0 - sb)
    v = jnp.where(first, va, vb)
    a = jnp.where(first, aa, -ab)
    return s, jnp.where(inside, v, 0.0), jnp.where(inside, a, 0.0)


MOTION_LAWS: dict[str, Callable] = {"poly5": poly5, "cycloidal": cycloidal, "modified_trapezoid": modified_trapezoid}


def motion_law(name: str) -> Callable:
    """Look a motion law up by name (``poly5``, ``cycloidal``, ``modified_trapezoid``)."""
    try:
        return MOTION_LAWS[name]
    except KeyError:
        raise ValueError(f"unknown motion law {name!r}; known: {sorted(MOTION_LAWS)}") from None



class Cycle(eqx.Module):
    """A trajectory sampled in normalised time u in [0, 1] (K samples, uniform, both ends included).

    Attributes:
        u: (K,) normalised time.
        x, dx, ddx: (K, 3) the path and its u-derivatives: the platform centre (m, base frame) if
            ``space == "cartesian"``, the actuated angles (rad) if ``space == "joint"``.
        duration: nominal duration T (s); physical rates are dx / T, ddx / T^2.
        R, dR, ddR: optional (K,) base radius along the path (m) and its u-derivatives (reconfigurable
            robot); ``None`` keeps the robot's base radius fixed.
        space: ``"cartesian"`` or ``"joint"`` (static).
    """

    u: jax.Array
    x: jax.Array
    dx: jax.Array
    ddx: jax.Array
    duration: jax.Array = eqx.field(converter=float_leaf)
    R: Optional[jax.Array] = None
    dR: Optional[jax.Array] = None
    ddR: Optional[jax.Array] = None
    space: str = eqx.field(static=True, default="cartesian")

    def __check_init__(self):
        if self.space not in ("cartesian", "joint"):
            raise ValueError(f"Cycle.space must be 'cartesian' or 'joint', got {self.space!r}")

    @property
    def n_samples(self) -> int:
        return self.u.shape[-1]

    def at_duration(self, duration: Any) -> "Cycle":
        """The same path with nominal duration ``duration`` (s)."""
        return eqx.tree_at(lambda c: c.duration, self, float_leaf(duration))

    def time(self) -> jax.Array:
        """Sample times u * T (s)."""
        return self.u * self.duration

    def rates(self, duration: Any = None):
        """(x, xdot, xddot) at ``duration`` (default: the nominal one), SI units per second."""
        T = self.duration if duration is None else duration
        return self.x, self.dx / T, self.ddx / (T * T)


def _check_positive(name, value):
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return v


def _uniform(n_samples: int, dtype):
    if not isinstance(n_samples, int) or n_samples < 3:
        raise ValueError(f"n_samples must be an integer >= 3, got {n_samples!r}")
    return jnp.arange(n_samples, dtype=dtype) / (n_samples - 1)


def _segment(law, tau, t0, t1):
    """Law over the normalised-time window [t0, t1]: (s, ds/dtau, d2s/dtau2)."""
    span = t1 - t0
    s, ds, dds = law((tau - t0) / span)
    return s, ds / span, dds / (span * span)


def _adept_fraction(width: float, height: float, blend: float, vertical_fraction: Optional[float]) -> float:
    """f_v of :func:`adept_path` (validated): the default gives the vertical and horizontal moves the same peak
    acceleration."""
    if vertical_fraction is None:
        return 1.0 / (math.sqrt(width / height) + 2.0 * (1.0 - blend))
    f_v = float(vertical_fraction)
    if not 0.0 < f_v < 0.5:
        raise ValueError(f"vertical_fraction must be in (0, 0.5), got {vertical_fraction!r}")
    return f_v


def adept_path(u: Any, centre: Any = (0.0, 0.0, 0.4), *, heading: float = 0.0, height: float = ADEPT_HEIGHT,
               width: float = ADEPT_WIDTH, law: str = "poly5", blend: float = 0.5,
               vertical_fraction: Optional[float] = None, dtype=None) -> tuple[Array, Array, Array]:
    """The standard pick-and-place path of :func:`adept_cycle` at any normalised times ``u`` (any values in
    [0, 1], shape (k,)): (x, x', x'') each (k, 3), the platform centre (m, base frame) and its u-derivatives.
    Pure and elementwise in ``u`` (jit / vmap / differentiate freely): :func:`adept_cycle` is this at uniform
    samples, and a search between the samples (:mod:`deltajax.optimize.cycle_worst`) evaluates the same path.
    Arguments as :func:`adept_cycle`."""
    fn = motion_law(law)
    height = _check_positive("height", height)
    width = _check_positive("width", width)
    blend = float(blend)
    if not 0.0 <= blend < 1.0:
        raise ValueError(f"blend must be in [0, 1), got {blend!r}")
    f_v = _adept_fraction(width, height, blend, vertical_fraction)
    dtype = jnp.result_type(float) if dtype is None else dtype
    centre = jnp.asarray(centre, dtype)
    if centre.shape != (3,):
        raise ValueError(f"centre must be a 3-vector (m), got shape {centre.shape}")
    u = jnp.asarray(u, dtype)
    go = u <= 0.5
    tau = jnp.where(go, 2.0 * u, 2.0 - 2.0 * u)        # the return half retraces the go half
    dtau = jnp.where(go, 2.0, -2.0)
    up, dup, ddup = _segment(fn, tau, 0.0, f_v)
    down, ddown, dddown = _segment(fn, tau, 1.0 - f_v, 1.0)
    h0 = f_v * (1.0 - blend)
    sx, dsx, ddsx = _segment(fn, tau, h0, 1.0 - h0)
    z = -height * (up - down)                         # up is -z
    dz = -height * (dup - ddown)
    ddz = -height * (ddup - dddown)
    along = width * (sx - 0.5)
    e = jnp.asarray([math.cos(heading), math.sin(heading), 0.0], dtype)
    ez = jnp.asarray([0.0, 0.0, 1.0], dtype)
    e, ez, centre = e[None, :], ez[None, :], centre[None, :]
    x = centre + along[:, None] * e + z[:, None] * ez
    dx = (dtau * width * dsx)[:, None] * e + (dtau * dz)[:, None] * ez
    ddx = (4.0 * width * ddsx)[:, None] * e + (4.0 * ddz)[:, None] * ez
    return x, dx, ddx


def adept_cycle(centre: Any = (0.0, 0.0, 0.4), *, heading: float = 0.0, duration: float = 0.5,
                height: float = ADEPT_HEIGHT, width: float = ADEPT_WIDTH, law: str = "poly5",
                blend: float = 0.5, vertical_fraction: Optional[float] = None, n_samples: int = 201,
                dtype=None) -> Cycle:
    """The standard pick-and-place ("Adept") cycle: ``height`` up, ``width`` across, ``height`` down, and back.

    The go half (u in [0, 1/2]) lifts from the pick point, crosses, and lowers onto the place point; the return
    half retraces it backwards in time. Within a half (normalised tau in [0, 1]) the lift runs over
    [0, f_v], the descent over [1 - f_v, 1] and the horizontal move over [f_v (1 - blend), 1 - f_v (1 - blend)],
    each with the rest-to-rest ``law``. ``blend = 0`` stops at the corners; ``blend > 0`` overlaps the moves
    (rounded corners, as controllers do). By default f_v = 1 / (sqrt(width / height) + 2 (1 - blend)), which
    gives the vertical and horizontal moves the same peak acceleration. The path at ``n_samples`` uniform
    samples of :func:`adept_path` (which evaluates it at any u).

    Args:
        centre: midpoint of the pick-place line (m, base frame, z down: the pick/place height).
        heading: direction of the horizontal move in the xy plane (rad from +x).
        duration: nominal cycle time T for the full go-and-back cycle (s).
        height, width: strokes (m); the standard cycle is 0.025 / 0.305.
        law: ``"poly5"``, ``"cycloidal"`` or ``"modified_trapezoid"``.
        blend: overlap in [0, 1).
        vertical_fraction: f_v, override of the default.
        n_samples: K samples over the whole cycle (>= 3).
        dtype: float dtype (default: JAX's default float).

    Returns:
        A Cartesian :class:`Cycle`.
    """
    duration = _check_positive("duration", duration)
    dtype = jnp.result_type(float) if dtype is None else dtype
    u = _uniform(n_samples, dtype)
    x, dx, ddx = adept_path(u, centre, heading=heading, height=height, width=width, law=law, blend=blend,
                            vertical_fraction=vertical_fraction, dtype=dtype)
    return Cycle(u=u, x=x, dx=dx, ddx=ddx, duration=duration, space="cartesian")


def point_to_point(start: Any, end: Any, *, duration: float = 0.5, law: str = "poly5", n_samples: int = 101,
                   dtype=None) -> Cycle:
    """A straight rest-to-rest move from ``start`` to ``end`` (m, base frame) with the given law."""
    fn = motion_law(law)
    duration = _check_positive("duration", duration)
    dtype = jnp.result_type(float) if dtype is None else dtype
    a, b = jnp.asarray(start, dtype), jnp.asarray(end, dtype)
    u = _uniform(n_samples, dtype)
    s, ds, dds = fn(u)
    d = (b - a)[None, :]
    return Cycle(u=u, x=a[None, :] + s[:, None] * d, dx=ds[:, None] * d, ddx=dds[:, None] * d, duration=duration,
                 space="cartesian")


def ga_paper_motion(*, amplitude: float = 0.25, duration: float = 2.0 * math.pi, n_samples: int = 201,
                    dtype=None) -> Cycle:
    """The GA paper's test motion (Hasanlu 2025, before Eq. 56), in joint space.

    Its actuated angles ("alpha_i", rad) are alpha_1 = alpha_3 = 0.25 sin t, alpha_2 = 0.25 cos t, and the
    platform position follows from the direct kinematics. We take t in [0, 2 pi] s (one period; the paper
    gives no interval), i.e. u = t / T with T = 2 pi s by default; other durations time-scale the same path.
    """
    duration = _check_positive("duration", duration)
    dtype = jnp.result_type(float) if dtype is None else dtype
    u = _uniform(n_samples, dtype)
    w = 2.0 * math.pi
    ph = w * u
    s, c = jnp.sin(ph), jnp.cos(ph)
    A = float(amplitude)
    x = A * jnp.stack([s, c, s], axis=-1)
    dx = A * w * jnp.stack([c, -s, c], axis=-1)
    ddx = -A * w * w * jnp.stack([s, c, s], axis=-1)
    return Cycle(u=u, x=x, dx=dx, ddx=ddx, duration=duration, space="joint")


def with_R_profile(cycle: Cycle, R_start: float, R_end: Optional[float] = None, *, amplitude: float = 0.0,
                   law: str = "poly5") -> Cycle:
    """Attach a base-radius profile to a cycle (reconfigurable robot).

    R(u) = R_start + (R_end - R_start) s(u) + amplitude sin(2 pi u) with the rest-to-rest ``law`` s; the
    sine term (period = the cycle) makes R move during a closed cycle (R_end = R_start).
    """
    R_end = R_start if R_end is None else R_end
    u = cycle.u
    s, ds, dds = motion_law(law)(u)
    w = 2.0 * math.pi
    dR_total = float(R_end) - float(R_start)
    R = R_start + dR_total * s + amplitude * jnp.sin(w * u)
    dR = dR_total * ds + amplitude * w * jnp.cos(w * u)
    ddR = dR_total * dds - amplitude * w * w * jnp.sin(w * u)
    return eqx.tree_at(lambda c: (c.R, c.dR, c.ddR), cycle, (R, dR, ddR), is_leaf=lambda x: x is None)


def with_R(cycle: Cycle, R, R_dot, R_ddot) -> Cycle:
    """The cycle carrying the base-radius profile R(t) (m) with physical rates Rdot (m/s), Rddot (m/s^2)."""
    T = cycle.duration
    return eqx.tree_at(lambda c: (c.R, c.dR, c.ddR), cycle,
                       (jnp.asarray(R), jnp.asarray(R_dot) * T, jnp.asarray(R_ddot) * T * T),
                       is_leaf=lambda x: x is None)


def task_path(points: Sequence[Sequence[float]], *, segment_duration: float = 0.5, law: str = "poly5",
              samples_per_segment: int = 25, closed: bool = False, dtype=None) -> Cycle:
    """A rest-to-rest path through task points (m, base frame): straight moves with the given law.

    Consecutive moves share their end sample; with ``closed=True`` the path returns to the first point.

    Returns:
        A Cartesian :class:`Cycle` of n_seg (samples_per_segment - 1) + 1 samples and duration
        n_seg * segment_duration.
    """
    pts = [list(map(float, p)) for p in points]
    if len(pts) < 2 or any(len(p) != 3 for p in pts):
        raise ValueError(f"task points must be >= 2 points of 3 coordinates (m), got {points!r}")
    if closed:
        pts = pts + [pts[0]]
    segs = [point_to_point(a, b, duration=segment_duration, law=law, n_samples=samples_per_segment, dtype=dtype)
            for a, b in zip(pts[:-1], pts[1:])]
    n_seg = len(segs)
    cat = lambda f: jnp.concatenate([f(s)[:-1] for s in segs] + [f(segs[-1])[-1:]], axis=0)  # noqa: E731
    x = cat(lambda s: s.x)
    dx = cat(lambda s: s.dx) * n_seg            # u-derivatives of the whole path: d/du = n_seg d/du_seg
    ddx = cat(lambda s: s.ddx) * n_seg ** 2
    K = x.shape[0]
    u = jnp.arange(K, dtype=x.dtype) / (K - 1)
    return Cycle(u=u, x=x, dx=dx, ddx=ddx, duration=segment_duration * n_seg, space="cartesian")


def trapezoid_weights(K: int, dt, dtype) -> jax.Array:
    """Trapezoidal-rule weights of K equally spaced samples dt apart: sum_j w_j f_j ~ integral of f."""
    return (jnp.ones((K,), dtype).at[0].set(0.5).at[-1].set(0.5)) * dt
