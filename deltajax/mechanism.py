"""Reconfiguration mechanisms: what turns the R drive's motor into the base radius R (pluggable pytrees).

Every mechanism maps its input coordinate q (the drive's own coordinate) to R and back, gives the transmission
ratio dR/dq, flags its own singular positions as data and converts the R actuator force F_R (N, the total
radial force from :func:`deltajax.cycle_profile` / :func:`deltajax.inverse_dynamics`) into the motor-side
effort of the drive. Single configuration; ``jax.vmap`` for profiles.

* :class:`DirectRadial` -- a linear actuator moves the three A_i radially: R = q (m), dR/dq = 1, effort in N.
* :class:`ScrewLinkage` -- the GA paper's screw-driven linkage (Hasanlu 2025 §2.7; its Eqs. 43-46 are garbled,
  the model below is derived from its loop equation 43 only). In each chain's vertical plane (first coordinate
  radial, second along the screw axis):

  - the *rocker* F-A' of length ``R_r`` pivots at F = (R_f, 0) at angle alpha4: A' = (R_f + R_r cos a4, R_r sin a4);
  - the *screw* (axis parallel to the second coordinate, at radial position ``d3``) carries a nut point
    D = (d3, d1 + p phi): screw angle phi (rad), ``pitch`` p = lead / (2 pi) (m/rad), offset ``d1``;
  - the *coupler* D-A' has length ``d2``:  (R_f + R_r cos a4 - d3)^2 + (d1 + p phi - R_r sin a4)^2 = d2^2  (Eq. 43);
  - the actuated joint A_i rides on a radial carriage driven by the rocker tip through a slot parallel to the
    screw axis, so R = R_f + R_r cos a4 (the paper writes R = R_f + R_r at a4 = 0). The slot is our reading:
    the library's kinematics keep A_i in the base plane (docs/CONVENTIONS.md), which a pinned rocker tip would leave.

  With a = R_f - d3, b = d1 + p phi, X = a + R_r cos a4, Y = b - R_r sin a4 (the coupler's components), Eq. 43
  is k1 sin a4 + k2 cos a4 = k3 with k1 = -2 R_r b, k2 = 2 R_r a, k3 = d2^2 - a^2 - b^2 - R_r^2 (the paper's
  Eq. 45 constants), so a4 = psi + beta acos(k3 / rho), rho = sqrt(k1^2 + k2^2), psi = atan2(k1, k2), with the
  two assembly branches beta = +-1 = sign(X sin a4 + Y cos a4) (the side of the coupler relative to the rocker);
  no assembly where |k3| > rho. Implicit differentiation of G = X^2 + Y^2 - d2^2:
  dG/da4 = -2 R_r (X sin a4 + Y cos a4), dG/dphi = 2 p Y, hence

      dR/dphi = -R_r sin a4 * da4/dphi = -p Y sin a4 / (X sin a4 + Y cos a4).

  Singular positions (flags, with relative tolerance ``tol``):
  ``dead_centre``: rocker and coupler aligned, X sin a4 + Y cos a4 = 0 -> dR/dphi infinite: the screw can
  neither drive nor hold R (the two assembly branches meet); ``coupler_normal``: the coupler perpendicular to the
  screw, Y = 0 -> dR/dphi = 0 (the nut moves, R does not); ``rocker_radial``: sin a4 = 0, R at its extreme
  R_f +- R_r -> dR/dphi = 0. :meth:`ScrewLinkage.singular_positions` lists every such phi in closed form.

  Screw torque by virtual work: the ideal torque is tau = F_R dR/dphi (all three chains' linkages driven by one
  motor through a common transmission, so F_R is the total radial force; one chain's screw carries a third).
  Losses: when the motor delivers power (tau_ideal phidot >= 0, and at rest) tau = tau_ideal / ``efficiency``;
  when the load back-drives it, tau = tau_ideal * ``back_efficiency``. The motor side divides by ``gear_ratio``
  (motor angle = gear_ratio * phi). Linkage and screw inertias are not modelled (light links; the moving
  carriage mass is in :class:`deltajax.MassModel`, ``carriage_mass``).

**Example parameters** (:func:`example_screw_linkage`, for franco2026's R range [0.138, 0.495] m):
R_f = 0.3165 m (the middle of the range) and R_r = 0.357 / (2 cos 45 deg) = 0.2524 m, so R_min .. R_max is
alpha4 = 135 deg .. 45 deg: the rocker stays 45 deg away from its rocker_radial singularities, where dR/dphi -> 0
and the screw would need unbounded speed. The screw axis d3 = 0.07 m, coupler d2 = 0.46 m, nut side Y < 0,
assembly beta = +1 came from a grid search (d3 in [-0.4, 0.8] m, d2 in [0.1, 0.8] m, both nut sides; rocker
sweeps 60-100 deg) for the largest worst-case transmission quality over the range, min(|sin| of the
rocker-coupler angle, |Y| / d2) = 0.383 (no transmission angle below 22.5 deg): sweeping 80 deg would give 0.42
with a 0.28 m rocker, 120 deg only 0.26. Lead 10 mm (pitch 0.01 / 2 pi m/rad), d1 puts phi = 0 at R = R_min;
the range is then phi = 0 .. 175.3 rad (27.9 screw turns), dR/dphi = 1.12 .. 2.51 mm/rad, no singular position
inside (:meth:`ScrewLinkage.check_range`). Efficiency 0.9 driving / 0.8 back-driven (a ball screw).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .cycle import cycle_profile
from .fields import check_range, float_leaf

__all__ = [
    "MechanismState",
    "Mechanism",
    "DirectRadial",
    "ScrewLinkage",
    "example_screw_linkage",
    "MECHANISMS",
    "DriveProfile",
    "drive_profile",
    "reconfiguration_drive",
]



class MechanismState(NamedTuple):
    """Position-level state of a reconfiguration mechanism at input q.

    Attributes:
        R: base radius (m); NaN where ``ok`` is False.
        ratio: dR/dq (m per unit of q); NaN where not ``ok``.
        ok: assembled (and inside the input range, if any).
        dead_centre: dR/dq infinite (input cannot drive or hold R).
        coupler_normal: dR/dq = 0 because the coupler is perpendicular to the input's motion.
        rocker_radial: dR/dq = 0 because R is at an extreme of the rocker's sweep.
        angle: the mechanism's internal angle (rad; alpha4 of the screw linkage, 0 for direct actuation).
    """

    R: Float[Array, ""]
    ratio: Float[Array, ""]
    ok: Bool[Array, ""]
    dead_centre: Bool[Array, ""]
    coupler_normal: Bool[Array, ""]
    rocker_radial: Bool[Array, ""]
    angle: Float[Array, ""]

    @property
    def singular(self):
        return self.dead_centre | self.coupler_normal | self.rocker_radial


class Mechanism(eqx.Module):
    """Interface of a reconfiguration mechanism (input q -> R).

    Subclasses are equinox modules with array fields ``efficiency``, ``back_efficiency`` (in (0, 1]) and
    ``gear_ratio`` (> 0), and implement :meth:`state`, :meth:`inverse`, ``input_unit`` and ``effort_unit``.
    """

    def state(self, q) -> MechanismState:  # pragma: no cover - interface
        raise NotImplementedError

    def inverse(self, R) -> tuple[Float[Array, ""], Bool[Array, ""]]:  # pragma: no cover - interface
        """Input q giving base radius R (m) on the working branch, and whether it exists."""
        raise NotImplementedError

    @property
    def input_unit(self) -> str:  # pragma: no cover - interface
        raise NotImplementedError

    @property
    def effort_unit(self) -> str:  # pragma: no cover - interface
        raise NotImplementedError

    def position(self, q) -> Float[Array, ""]:
        """R (m) at input q."""
        return self.state(q).R

    def ratio(self, q) -> Float[Array, ""]:
        """Transmission ratio dR/dq at input q."""
        return self.state(q).ratio

    def effort(self, q, q_dot, force_R) -> Float[Array, ""]:
        """Motor-side effort of the drive for R actuator force ``force_R`` (N) at input q moving at q_dot.

        Virtual work tau_ideal = F_R dR/dq; divided by ``efficiency`` when the motor delivers power
        (tau_ideal q_dot >= 0, rest included), multiplied by ``back_efficiency`` when the load back-drives it;
        then divided by ``gear_ratio``.
        """
        ideal = force_R * self.ratio(q)
        driving = ideal * q_dot >= 0
        return jnp.where(driving, ideal / self.efficiency, ideal * self.back_efficiency) / self.gear_ratio

    def motor_speed(self, q_dot) -> Float[Array, ""]:
        """Motor speed for input rate q_dot (the input's unit per second times ``gear_ratio``)."""
        return q_dot * self.gear_ratio


class DirectRadial(Mechanism):
    """Direct radial actuation: a linear drive whose stroke is R itself (q = R, m; effort = force, N).

    Attributes:
        efficiency, back_efficiency: in (0, 1]; gear_ratio: > 0 (1 for a direct linear motor).
    """

    efficiency: jax.Array = eqx.field(converter=float_leaf, default=1.0)
    back_efficiency: jax.Array = eqx.field(converter=float_leaf, default=1.0)
    gear_ratio: jax.Array = eqx.field(converter=float_leaf, default=1.0)

    def __check_init__(self):
        check_range("DirectRadial", "efficiency", self.efficiency, hi=1.0, skip_batches=True)
        check_range("DirectRadial", "back_efficiency", self.back_efficiency, hi=1.0, skip_batches=True)
        check_range("DirectRadial", "gear_ratio", self.gear_ratio, skip_batches=True)

    input_unit = "m"
    effort_unit = "N"

    def state(self, q) -> MechanismState:
        q = jnp.asarray(q, jnp.result_type(float))
        f = jnp.zeros((), bool)
        return MechanismState(R=q, ratio=jnp.ones_like(q), ok=jnp.ones((), bool), dead_centre=f, coupler_normal=f,
                              rocker_radial=f, angle=jnp.zeros_like(q))

    def inverse(self, R):
        R = jnp.asarray(R, jnp.result_type(float))
        return R, jnp.isfinite(R)


class ScrewLinkage(Mechanism):
    """The screw-driven rocker linkage (see the module docstring for the geometry and the derivation).

    Attributes:
        R_f: radial position of the rocker pivot F (m).
        R_r: rocker length F-A' (m).
        d1: nut offset along the screw axis at phi = 0 (m).
        d2: coupler length D-A' (m).
        d3: radial position of the screw axis (m).
        pitch: p, nut travel per radian of screw (m/rad) = lead / (2 pi).
        efficiency, back_efficiency: screw efficiency driving / back-driven, in (0, 1].
        gear_ratio: motor angle per screw angle (> 0).
        assembly: working assembly branch beta = +1 or -1 (static).
        nut_side: sign of Y = d1 + p phi - R_r sin alpha4 on the working range (static; used by the inverse).
        tol: relative tolerance of the singular-position flags (static).
    """

    R_f: jax.Array = eqx.field(converter=float_leaf)
    R_r: jax.Array = eqx.field(converter=float_leaf)
    d1: jax.Array = eqx.field(converter=float_leaf)
    d2: jax.Array = eqx.field(converter=float_leaf)
    d3: jax.Array = eqx.field(converter=float_leaf)
    pitch: jax.Array = eqx.field(converter=float_leaf)
    efficiency: jax.Array = eqx.field(converter=float_leaf, default=0.9)
    back_efficiency: jax.Array = eqx.field(converter=float_leaf, default=0.8)
    gear_ratio: jax.Array = eqx.field(converter=float_leaf, default=1.0)
    assembly: int = eqx.field(static=True, default=1)
    nut_side: int = eqx.field(static=True, default=-1)
    tol: float = eqx.field(static=True, default=1e-6)

    input_unit = "rad"
    effort_unit = "N m"

    def __check_init__(self):
        for name in ("R_f", "R_r", "d2", "pitch"):
            check_range("ScrewLinkage", name, getattr(self, name), unit="m/rad" if name == "pitch" else "m",
                        skip_batches=True)
        for name in ("d1", "d3"):
            v = getattr(self, name)
            if not isinstance(v, jax.core.Tracer) and np.ndim(v) == 0 and not math.isfinite(float(v)):
                raise ValueError(f"ScrewLinkage.{name} must be a finite number (m), got {float(v)!r}")
        check_range("ScrewLinkage", "efficiency", self.efficiency, hi=1.0, skip_batches=True)
        check_range("ScrewLinkage", "back_efficiency", self.back_efficiency, hi=1.0, skip_batches=True)
        check_range("ScrewLinkage", "gear_ratio", self.gear_ratio, skip_batches=True)
        for name in ("assembly", "nut_side"):
            if getattr(self, name) not in (1, -1):
                raise ValueError(f"ScrewLinkage.{name} must be +1 or -1, got {getattr(self, name)!r}")
        if not (isinstance(self.tol, float) and 0 < self.tol < 1):
            raise ValueError(f"ScrewLinkage.tol must be a float in (0, 1), got {self.tol!r}")

    def angles(self, phi) -> tuple[Float[Array, "2"], Bool[Array, ""]]:
        """Both assembly solutions alpha4 (rad) for screw angle phi: ([beta=+1, beta=-1], assembled)."""
        phi = jnp.asarray(phi, jnp.result_type(float))
        a = self.R_f - self.d3
        b = self.d1 + self.pitch * phi
        k1 = -2.0 * self.R_r * b
        k2 = 2.0 * self.R_r * a
        k3 = self.d2 ** 2 - a * a - b * b - self.R_r ** 2
        rho = jnp.sqrt(k1 * k1 + k2 * k2)
        ok = jnp.abs(k3) <= rho
        c = jnp.where(ok, k3 / jnp.where(rho > 0, rho, 1.0), 0.0)
        gamma = jnp.arccos(jnp.clip(c, -1.0, 1.0))
        psi = jnp.arctan2(k1, k2)
        both = jnp.stack([psi + gamma, psi - gamma])
        return jnp.where(ok, both, jnp.nan), ok

    def state(self, phi) -> MechanismState:
        """Position, transmission ratio dR/dphi (m/rad) and singularity flags on the working branch."""
        phi = jnp.asarray(phi, jnp.result_type(float))
        both, ok = self.angles(phi)
        alpha = both[0] if self.assembly == 1 else both[1]
        alpha = jnp.where(ok, alpha, jnp.pi / 2)
        s, c = jnp.sin(alpha), jnp.cos(alpha)
        X = self.R_f - self.d3 + self.R_r * c
        Y = self.d1 + self.pitch * phi - self.R_r * s
        den = X * s + Y * c
        dead = ok & (jnp.abs(den) <= self.tol * self.d2)
        normal = ok & (jnp.abs(Y) <= self.tol * self.d2)
        radial = ok & (jnp.abs(s) <= self.tol)
        ratio = -self.pitch * Y * s / jnp.where(jnp.abs(den) > 0, den, 1.0)
        nan = jnp.asarray(jnp.nan, phi.dtype)
        R = self.R_f + self.R_r * c
        return MechanismState(R=jnp.where(ok, R, nan), ratio=jnp.where(ok & ~dead, ratio, nan), ok=ok,
                              dead_centre=dead, coupler_normal=normal, rocker_radial=radial,
                              angle=jnp.where(ok, alpha, nan))

    def inverse(self, R):
        """Screw angle phi (rad) giving R on the working branch, and whether it exists.

        The rocker side is sin alpha4 >= 0 and the nut side is the sign of Y = ``nut_side``:
        cos alpha4 = (R - R_f) / R_r, Y = nut_side sqrt(d2^2 - X^2), phi = (R_r sin alpha4 + Y - d1) / p;
        ``ok`` is False where R is out of the rocker's reach or the solution is not on assembly ``assembly``.
        """
        R = jnp.asarray(R, jnp.result_type(float))
        c = (R - self.R_f) / self.R_r
        in_rng = jnp.abs(c) <= 1.0
        c = jnp.clip(c, -1.0, 1.0)
        s = jnp.sqrt(1.0 - c * c)
        X = self.R_f - self.d3 + self.R_r * c
        y2 = self.d2 ** 2 - X * X
        reach = in_rng & (y2 >= 0)
        Y = self.nut_side * jnp.sqrt(jnp.where(reach, y2, 0.0))
        ok = reach & (jnp.sign(X * s + Y * c) == self.assembly)
        phi = (self.R_r * s + Y - self.d1) / self.pitch
        return jnp.where(ok, phi, jnp.nan), ok

    def singular_positions(self) -> dict[str, np.ndarray]:
        """Every screw angle phi (rad) where the linkage is singular, closed form (host, NumPy).

        Returns:
            {type: (n, 2) array of rows (phi, beta)}, beta the assembly branch on which the position lies
            (0 for dead centres, where both branches meet), sorted by phi. Types:
            ``"dead_centre"`` (|F - D| = d2 +- R_r, rocker and coupler aligned), ``"coupler_normal"`` (Y = 0),
            ``"rocker_radial"`` (sin alpha4 = 0).
        """
        Rf, Rr, d1, d2, d3, p = (float(np.asarray(v)) for v in (self.R_f, self.R_r, self.d1, self.d2, self.d3,
                                                                 self.pitch))
        a = Rf - d3
        dead = []
        for L in (d2 + Rr, abs(d2 - Rr)):
            if L * L >= a * a:
                r = math.sqrt(L * L - a * a)
                dead += [((r - d1) / p, 0.0), ((-r - d1) / p, 0.0)]
        normal = []
        for X in (d2, -d2):
            c = (X - a) / Rr
            if abs(c) <= 1:
                for s in (math.sqrt(1 - c * c), -math.sqrt(1 - c * c)):
                    normal.append(((Rr * s - d1) / p, float(np.sign(X * s))))
        radial = []
        for c in (1.0, -1.0):
            X = a + Rr * c
            if X * X <= d2 * d2:
                for Y in (math.sqrt(d2 * d2 - X * X), -math.sqrt(d2 * d2 - X * X)):
                    radial.append(((Y - d1) / p, float(np.sign(Y * c))))

        def table(rows):
            arr = np.asarray(rows, float).reshape(-1, 2)
            return arr[np.argsort(arr[:, 0], kind="stable")]

        return {"dead_centre": table(dead), "coupler_normal": table(normal), "rocker_radial": table(radial)}

    def check_range(self, R_min: float, R_max: float, n: int = 2001) -> dict:
        """Verify the working branch over [R_min, R_max] m: assembled, consistent, monotone, no singular position.

        Raises:
            ValueError: naming the first R (m) where the linkage fails and why.

        Returns:
            {"phi_min", "phi_max" (rad), "min_transmission" (smallest of |sin| of the rocker-coupler angle and
            |Y| / d2 over the range), "ratio_min", "ratio_max" (m/rad)}.
        """
        Rs = np.linspace(float(R_min), float(R_max), int(n))
        phi, ok = jax.vmap(self.inverse)(jnp.asarray(Rs))
        phi, ok = np.asarray(phi), np.asarray(ok)
        if not ok.all():
            raise ValueError(f"ScrewLinkage cannot reach R = {float(Rs[~ok][0])!r} m on assembly {self.assembly} with "
                             f"nut_side {self.nut_side} (out of the rocker's reach, or the working branch ends at a "
                             "singular position before it)")
        st = jax.vmap(self.state)(jnp.asarray(phi))
        R_back = np.asarray(st.R)
        bad = ~np.isclose(R_back, Rs, rtol=0, atol=1e-9)
        if bad.any():
            raise ValueError(f"ScrewLinkage: phi(R) at R = {float(Rs[bad][0])!r} m is not on assembly {self.assembly} "
                             f"(forward position {R_back[bad][0]!r} m)")
        sing = np.asarray(st.singular)
        if sing.any():
            raise ValueError(f"ScrewLinkage is singular at R = {float(Rs[sing][0])!r} m inside [{R_min}, {R_max}] m")
        dphi = np.diff(phi)
        if not (np.all(dphi > 0) or np.all(dphi < 0)):
            raise ValueError(f"ScrewLinkage: phi(R) is not monotone over [{R_min}, {R_max}] m")
        alpha = np.asarray(st.angle)
        s, c = np.sin(alpha), np.cos(alpha)
        Rf, Rr, d1, d2, d3, p = (float(np.asarray(v)) for v in (self.R_f, self.R_r, self.d1, self.d2, self.d3,
                                                                 self.pitch))
        X = Rf - d3 + Rr * c
        Y = d1 + p * phi - Rr * s
        trans = np.minimum(np.abs(X * s + Y * c) / d2, np.abs(Y) / d2)
        ratio = np.asarray(st.ratio)
        return {"phi_min": float(phi.min()), "phi_max": float(phi.max()), "min_transmission": float(trans.min()),
                "ratio_min": float(np.abs(ratio).min()), "ratio_max": float(np.abs(ratio).max())}


def example_screw_linkage(R_min: float = 0.138, R_max: float = 0.495, *, sweep_deg: float = 45.0, d3: float = 0.07,
                          d2: float = 0.46, lead: float = 0.010, assembly: int = 1, nut_side: int = -1,
                          efficiency: float = 0.9,
                          back_efficiency: float = 0.8, gear_ratio: float = 1.0) -> ScrewLinkage:
    """The documented example linkage for an R range [R_min, R_max] m (see the module docstring).

    R_f is the middle of the range and R_r such that the rocker sweeps alpha4 = 180 - sweep_deg .. sweep_deg;
    d1 puts phi = 0 at R = R_min.
    """
    Rf = 0.5 * (R_min + R_max)
    Rr = 0.5 * (R_max - R_min) / math.cos(math.radians(sweep_deg))
    p = lead / (2 * math.pi)
    probe = ScrewLinkage(R_f=Rf, R_r=Rr, d1=0.0, d2=d2, d3=d3, pitch=p, efficiency=efficiency,
                         back_efficiency=back_efficiency, gear_ratio=gear_ratio, assembly=assembly, nut_side=nut_side)
    phi0, ok = probe.inverse(R_min)
    if not bool(ok):
        raise ValueError(f"example_screw_linkage: no assembly at R_min={R_min!r} m with d2={d2!r} m, d3={d3!r} m")
    return ScrewLinkage(R_f=Rf, R_r=Rr, d1=float(p * phi0), d2=d2, d3=d3, pitch=p, efficiency=efficiency,
                        back_efficiency=back_efficiency, gear_ratio=gear_ratio, assembly=assembly, nut_side=nut_side)


#: registry of mechanism constructors by config name
MECHANISMS = {"direct": DirectRadial, "screw_linkage": example_screw_linkage}


class DriveProfile(NamedTuple):
    """The reconfiguration drive along R(t) (arrays over samples)."""

    q: Float[Array, "K"]
    q_dot: Float[Array, "K"]
    ratio: Float[Array, "K"]
    effort: Float[Array, "K"]
    motor_speed: Float[Array, "K"]
    ok: Bool[Array, "K"]
    singular: Bool[Array, "K"]


def drive_profile(mech: Mechanism, R, R_dot, force_R) -> DriveProfile:
    """Input angle/stroke, its rate, dR/dq and the motor-side effort along R(t) (vmapped over samples).

    Args:
        mech: the mechanism.
        R, R_dot: (K,) base radius (m) and rate (m/s).
        force_R: (K,) R actuator force (N), e.g. ``cycle_profile(...).force_R``.
    """
    def one(r, rd, f):
        q, ok = mech.inverse(r)
        st = mech.state(q)
        q_dot = rd / st.ratio
        eff = mech.effort(q, q_dot, f)
        return q, q_dot, st.ratio, eff, mech.motor_speed(q_dot), ok & st.ok & ~st.singular, st.singular

    return DriveProfile(*jax.vmap(one)(jnp.asarray(R), jnp.asarray(R_dot), jnp.asarray(force_R)))


def reconfiguration_drive(robot, cycle, mech: Mechanism, duration=None) -> tuple[Any, DriveProfile]:
    """Inverse dynamics along a cycle that carries R(t) and the drive's motor-side effort: (profile, drive).

    Args:
        robot: robot with a mass model.
        cycle: :class:`deltajax.trajectory.Cycle` with an R profile (``cycle.R`` not None).
        mech: the reconfiguration mechanism.
        duration: cycle time (s); default the cycle's nominal one.

    Returns:
        (:class:`deltajax.cycle.CycleProfile`, :class:`DriveProfile`).
    """
    if cycle.R is None:
        raise ValueError("reconfiguration_drive needs a cycle with an R profile (cycle.R is None)")
    prof = cycle_profile(robot, cycle, duration)
    return prof, drive_profile(mech, prof.R, prof.R_dot, prof.force_R)
