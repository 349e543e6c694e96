"""Delta and reconfigurable-Delta robot models as frozen pytrees, with validation.

Frame (docs/CONVENTIONS.md): origin at the centre of the fixed platform, **z pointing down** toward the workspace.
Chain i (i = 0, 1, 2) lies in the vertical plane at angle alpha_i = 2*pi*i/3 about z.

Every geometric number is an array leaf, so that `jax.vmap` over a population of designs (a GA) works on
the same functions as a single robot. Validation runs when a robot is built from concrete values (user
input, configs, presets); it is skipped for traced values (inside jit/vmap), where failure is data.
"""

from __future__ import annotations

import math
from typing import Any, Optional

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._precision import warn_if_float32
from .fields import float_leaf

__all__ = [
    "Delta",
    "ReconfigurableDelta",
    "GeometryError",
    "CHAIN_ANGLES",
    "to_z_up",
    "from_z_up",
]

#: Angles alpha_i of the three chains about the base z axis (rad).
CHAIN_ANGLES = (0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0)


class GeometryError(ValueError):
    """Invalid robot geometry; the message names the field and the value."""


def _is_concrete(x: Any) -> bool:
    return not isinstance(x, jax.core.Tracer)


def _concrete_float(name: str, value: Any) -> Optional[float]:
    """Return ``value`` as a Python float when it is a concrete scalar, ``None`` when traced or batched."""
    if not _is_concrete(value):
        return None
    arr = np.asarray(value)
    if arr.ndim != 0:
        return None  # a batch of designs (e.g. a GA population): checked per design by the caller
    v = float(arr)
    if not math.isfinite(v):
        raise GeometryError(f"{name} must be a finite number, got {v!r}")
    return v


def _cos_range(lo: float, hi: float) -> tuple[float, float]:
    """(min, max) of cos(theta) over theta in [lo, hi] (rad)."""
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi - lo >= 2 * math.pi:
        return -1.0, 1.0
    ends = (math.cos(lo), math.cos(hi))
    def contains(angle: float) -> bool:  # is angle + 2 pi k inside [lo, hi] for some k
        k = math.ceil((lo - angle) / (2 * math.pi))
        return angle + 2 * math.pi * k <= hi
    return (-1.0 if contains(math.pi) else min(ends)), (1.0 if contains(0.0) else max(ends))


#: a joint range of at least FULL_TURN_MIN (rad) is a full revolution (no limit; [-pi, pi] and radians(+-180)
#: with their rounding); more than FULL_TURN_MAX is rejected as more than one turn
FULL_TURN_MIN = 2 * math.pi * (1 - 1e-12)
FULL_TURN_MAX = 2 * math.pi * (1 + 1e-12)



class Delta(eqx.Module):
    """A (fixed-geometry) Delta robot.

    Attributes:
        base_radius: R, centre of the fixed platform to the actuated joint A_i (m).
        platform_radius: r, platform centre P to the distal joint C_i (m).
        upper_arm: L1, length A_i B_i (m).
        forearm: L2, length B_i C_i of the parallelogram, modelled as one rod (m).
        theta_min: lower limit of the actuated angles (rad, positive downward), inclusive.
        theta_max: upper limit of the actuated angles (rad), inclusive. Use +-inf for no limits.
        mass: optional mass model used by the dynamics (``None`` for kinematics only).
    """

    base_radius: jax.Array = eqx.field(converter=float_leaf)
    platform_radius: jax.Array = eqx.field(converter=float_leaf)
    upper_arm: jax.Array = eqx.field(converter=float_leaf)
    forearm: jax.Array = eqx.field(converter=float_leaf)
    theta_min: jax.Array = eqx.field(converter=float_leaf, default=-math.inf)
    theta_max: jax.Array = eqx.field(converter=float_leaf, default=math.inf)
    mass: Any = None

    def __check_init__(self):
        warn_if_float32(self.base_radius.dtype, "deltajax.Delta")
        R = _concrete_float("base_radius", self.base_radius)
        r = _concrete_float("platform_radius", self.platform_radius)
        L1 = _concrete_float("upper_arm", self.upper_arm)
        L2 = _concrete_float("forearm", self.forearm)
        lo = self.theta_min
        hi = self.theta_max
        for name, v in (("base_radius", R), ("upper_arm", L1), ("forearm", L2)):
            if v is not None and not v > 0:
                raise GeometryError(f"{name} must be > 0 m, got {v!r}")
        if r is not None and r < 0:
            raise GeometryError(f"platform_radius must be >= 0 m, got {r!r}")
        if _is_concrete(lo) and _is_concrete(hi) and np.ndim(lo) == 0 and np.ndim(hi) == 0:
            lo_f, hi_f = float(lo), float(hi)
            if math.isnan(lo_f) or math.isnan(hi_f):
                raise GeometryError(f"theta_min/theta_max must not be NaN, got ({lo_f!r}, {hi_f!r})")
            if not lo_f < hi_f:
                raise GeometryError(
                    f"joint limits inverted or empty: theta_min={lo_f!r} rad must be < theta_max={hi_f!r} rad"
                )
            # [-pi, pi] (a full revolution) is the common way to write "no limit"; more than one turn is an error
            if math.isfinite(lo_f) and math.isfinite(hi_f) and hi_f - lo_f > FULL_TURN_MAX:
                raise GeometryError(
                    f"joint range theta_max - theta_min = {hi_f - lo_f:.6g} rad must be <= 2*pi "
                    "(a full revolution, e.g. [-pi, pi]; or theta_min=-inf, theta_max=inf)"
                )
        if None not in (R, r, L1, L2) and _is_concrete(lo) and _is_concrete(hi) and np.ndim(lo) == 0:
            # With sphere centres c_i = rho_i e_i + z_i (rho_i = R - r + L1 cos theta_i) the three forearm
            # spheres of radius L2 can only meet if some rho_i is within [-L2, L2]: if all rho_i > L2, a
            # common point Q would need Q.e_i > 0 for all i, impossible since sum(e_i) = 0.
            c_lo, c_hi = _cos_range(float(lo), float(hi))
            rho_lo, rho_hi = R - r + L1 * c_lo, R - r + L1 * c_hi
            if rho_lo > L2 or rho_hi < -L2:
                raise GeometryError(
                    f"geometry can reach nothing: forearm={L2!r} m is shorter than every horizontal offset "
                    f"R - r + L1 cos(theta) in [{rho_lo!r}, {rho_hi!r}] m allowed by the joint limits "
                    f"(base_radius={R!r}, platform_radius={r!r}, upper_arm={L1!r})"
                )

    # -- convenience -------------------------------------------------------------------------------------
    @property
    def R_minus_r(self) -> jax.Array:
        """R - r, the only radius combination that enters the kinematics (m)."""
        return self.base_radius - self.platform_radius

    def with_base_radius(self, R: Any) -> "Delta":
        """The same robot with base radius ``R`` (a traced value is fine)."""
        return eqx.tree_at(lambda d: d.base_radius, self, float_leaf(R))

    @staticmethod
    def from_degrees(*, base_radius, platform_radius, upper_arm, forearm, theta_min_deg=None,
                     theta_max_deg=None, mass=None) -> "Delta":
        """Build a Delta with joint limits given in degrees (``None`` = unlimited; [-180, 180] = a full turn).

        Limit errors are reported in degrees, the units they were given in.
        """
        lo_d = None if theta_min_deg is None else float(theta_min_deg)
        hi_d = None if theta_max_deg is None else float(theta_max_deg)
        if lo_d is not None and hi_d is not None and not (math.isnan(lo_d) or math.isnan(hi_d)):
            if not lo_d < hi_d:
                raise GeometryError(f"joint limits inverted or empty: theta_min_deg={lo_d:g} deg must be < "
                                    f"theta_max_deg={hi_d:g} deg")
            if hi_d - lo_d > 360.0 * (1 + 1e-12):
                raise GeometryError(f"joint range theta_max_deg - theta_min_deg = {hi_d - lo_d:g} deg must be <= "
                                    "360 deg (a full revolution, e.g. [-180, 180]; or null for no limit)")
        lo = -math.inf if lo_d is None else math.radians(lo_d)
        hi = math.inf if hi_d is None else math.radians(hi_d)
        return Delta(base_radius=base_radius, platform_radius=platform_radius, upper_arm=upper_arm,
                     forearm=forearm, theta_min=lo, theta_max=hi, mass=mass)


class ReconfigurableDelta(eqx.Module):
    """A Delta whose base radius R is a fourth actuated joint with range [R_min, R_max].

    The R samples used by redundancy resolution are ``R_min + k * R_step``, k = 0..n_R-1 (integer k, no
    accumulated floating-point ``arange``). ``n_R`` fixes array shapes and is therefore static.

    Attributes:
        robot: the nominal robot; its ``base_radius`` is the fixed-R variant used for comparisons (m).
        R_min: smallest base radius (m).
        R_step: spacing of the R samples (m).
        n_R: number of R samples (static).
    """

    robot: Delta
    R_min: jax.Array = eqx.field(converter=float_leaf)
    R_step: jax.Array = eqx.field(converter=float_leaf)
    n_R: int = eqx.field(static=True)

    def __check_init__(self):
        if not isinstance(self.n_R, int) or self.n_R < 1:
            raise GeometryError(f"n_R (number of R samples) must be an integer >= 1, got {self.n_R!r}")
        lo = _concrete_float("R_min", self.R_min)
        step = _concrete_float("R_step", self.R_step)
        if lo is not None and not lo > 0:
            raise GeometryError(f"R_min must be > 0 m, got {lo!r}")
        if step is not None and self.n_R > 1 and not step > 0:
            raise GeometryError(f"R_step must be > 0 m, got {step!r}")

    @staticmethod
    def from_range(robot: Delta, R_min: float, R_max: float, R_step: float) -> "ReconfigurableDelta":
        """Build from an inclusive range [R_min, R_max] sampled every R_step (validated).

        Raises:
            GeometryError: empty or inverted range, non-positive step, or a range that is not a whole
                number of steps (to 1e-9 relative).
        """
        R_min, R_max, R_step = float(R_min), float(R_max), float(R_step)
        for name, v in (("R_min", R_min), ("R_max", R_max), ("R_step", R_step)):
            if not math.isfinite(v):
                raise GeometryError(f"{name} must be finite, got {v!r}")
        if not R_min > 0:
            raise GeometryError(f"R_min must be > 0 m, got {R_min!r}")
        if not R_max >= R_min:
            raise GeometryError(f"empty R range: R_max={R_max!r} m < R_min={R_min!r} m")
        if not R_step > 0:
            raise GeometryError(f"R_step must be > 0 m, got {R_step!r}")
        n_float = (R_max - R_min) / R_step
        n_steps = round(n_float)
        if abs(n_float - n_steps) > 1e-6 * max(1.0, n_float):
            raise GeometryError(
                f"R range [{R_min!r}, {R_max!r}] m is not a whole number of R_step={R_step!r} m steps "
                f"({n_float:.6f})"
            )
        return ReconfigurableDelta(robot=robot, R_min=R_min, R_step=R_step, n_R=int(n_steps) + 1)

    @property
    def R_max(self) -> jax.Array:
        """Largest base radius sample, R_min + (n_R - 1) R_step (m)."""
        return self.R_min + (self.n_R - 1) * self.R_step

    @property
    def fixed(self) -> Delta:
        """The fixed-R variant (the nominal robot)."""
        return self.robot

    def R_samples(self) -> jax.Array:
        """The n_R base radii R_min + k R_step, k = 0..n_R-1 (m)."""
        k = jnp.arange(self.n_R, dtype=self.R_min.dtype)
        return self.R_min + k * self.R_step

    def at(self, R: Any) -> Delta:
        """The robot frozen at base radius ``R`` (m); works with traced R inside jit/vmap.

        Raises:
            GeometryError: a concrete scalar ``R`` that is not a finite number > 0 (traced or batched values are
                not checked here: failure is data inside batches).
        """
        v = _concrete_float("R", R)
        if v is not None and not v > 0:
            raise GeometryError(f"R must be > 0 m, got {v!r}")
        return self.robot.with_base_radius(R)


def to_z_up(p: Any) -> jax.Array:
    """Convert a point from the library frame (z down) to a z-up frame.

    The z-up frame is the library frame rotated by pi about x: (x, y, z) -> (x, -y, -z). It stays
    right-handed, so chain 0 stays on +x. Apply to the last axis of any batch.
    """
    p = jnp.asarray(p)
    return jnp.concatenate([p[..., :1], -p[..., 1:]], axis=-1)


def from_z_up(p: Any) -> jax.Array:
    """Inverse of :func:`to_z_up` (the map is an involution)."""
    return to_z_up(p)
