"""Mass model of a (reconfigurable) Delta robot, as a frozen pytree carried by ``Delta.mass``.

Lumped-parameter model (per chain; the three chains are identical), frame z down (docs/CONVENTIONS.md), so gravity
acts along +z and the potential energy of a mass m at height z is ``V = -m g z``:

* **Upper arm** A_i B_i, a rigid body rotating about the motor axis (the chain's local y axis): mass
  ``upper_arm_mass``, centre of mass at ``upper_arm_com_fraction * L1`` from A_i along the arm, inertia about
  its centre of mass ``upper_arm_inertia_factor * m * L1**2`` (1/12 for a uniform slender rod). Fractions
  (not metres) keep the model meaningful when an optimiser changes L1.
* **Motor/gearbox**: rotor inertia ``rotor_inertia`` on the motor side and ``gear_ratio`` n (motor speed =
  n * arm speed), reflected to the arm as n**2 * rotor_inertia. Torques and speeds are reported at the arm
  (gearbox output); divide the torque by n (and multiply the speed by n) for motor-side values.
* **Forearm** (the parallelogram, both rods, as one link of mass ``forearm_mass``). Its *static* description
  is the share s = ``forearm_elbow_fraction`` of its weight carried at the elbow B_i, i.e. its centre of mass
  lies at (1 - s) L2 from B_i (s = 1/2 for symmetric rods). Two models of its motion, ``forearm_model``:

  - ``"rigid_rod"`` (**default**): each parallelogram moves as rigid slender rods, kinetic energy
    ``m/2 |v_c|^2 + I_c/2 |omega|^2`` with v_c the centre-of-mass velocity, omega = u x u' the rotation rate of
    the rod direction u = (C_i - B_i) / L2 (the two rods of a parallelogram stay parallel, so they share u and
    omega; spin about the rod's own axis is not defined by the kinematics and carries no inertia for a slender
    rod) and ``I_c = forearm_inertia_factor * m * L2**2`` about the centre of mass (1/12: uniform rods, both
    rods together). It holds for any mass distribution along the rods given (s, factor); the factor cannot
    exceed s (1 - s) (all mass at the two ends; Bhatia-Davis bound on the variance).
  - ``"point_split"``: s m lumped at the elbow and (1 - s) m at the platform. It keeps the mass and the centre
    of mass (so the gravity torques are exact) and the translational energy, and equals ``rigid_rod`` with
    factor s (1 - s): for uniform rods (s = 1/2) that is 1/4 instead of 1/12, three times the rod's rotational
    inertia (m/8 |v_C - v_B|^2 instead of m/24 |v_C - v_B|^2). The GA paper (§2.6) and Codourey's simplified
    model use it; it is the model of deltajax <= this change.

  Why ``rigid_rod`` is the default: it is the physics of the part (point_split is its special case with the
  inertia of two end masses), it costs one extra term per chain, and the gravity (static) torques of the two
  models are identical by construction, so only the inertial part changes. The error of point_split grows
  with the forearm's share of the moving mass: on the standard cycle it overestimates the peak torque by about
  1 % for franco2026 (41 g forearms) and about 7 % for ``industrial`` (300 g forearms); see
  docs/REPRODUCTION.md §4 for the table. Select ``point_split`` for the paper's (and Codourey's) lumped model.
* ``elbow_mass``: extra point mass at each elbow (joint hardware), kg.
* **Platform** (travelling plate) ``platform_mass`` plus ``payload_mass``, a translating point mass at P.
* **Reconfiguration carriage** ``carriage_mass`` per chain: everything the R actuator moves radially that does
  not rotate with the arm (motor and gearbox housing, slider, the share of the R drive reflected as a
  translating mass). The upper arm, elbow mass and forearm share move radially too (their kinetic energy
  contains Rdot); this mass only adds m_c Rdot^2 / 2 per chain. Irrelevant when R is fixed.
* ``gravity``: g (m/s^2), along +z (downward).

The R actuator moves the three A_i together (one scalar R; its generalised force is the total radial force).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Optional

import equinox as eqx
import jax
import jax.numpy as jnp

from .fields import float_leaf

__all__ = ["MassModel", "MassError", "check_field", "MASS_FIELDS", "STANDARD_GRAVITY", "FOREARM_MODELS",
           "DEFAULT_FOREARM_MODEL"]

STANDARD_GRAVITY = 9.80665

#: Forearm models (see the module docstring); the default and why: ``rigid_rod``, exact for slender rods.
FOREARM_MODELS = ("rigid_rod", "point_split")
DEFAULT_FOREARM_MODEL = "rigid_rod"

#: (field, unit, lower bound kind) for validation and config parsing. "pos" > 0, "nonneg" >= 0, "frac" in [0,1],
#: "ratio" >= 1 ... see check_field.
MASS_FIELDS = (
    ("upper_arm_mass", "kg", "nonneg"),
    ("upper_arm_com_fraction", "1", "frac"),
    ("upper_arm_inertia_factor", "1", "nonneg"),
    ("rotor_inertia", "kg m^2", "nonneg"),
    ("gear_ratio", "1", "pos"),
    ("elbow_mass", "kg", "nonneg"),
    ("forearm_mass", "kg", "nonneg"),
    ("forearm_elbow_fraction", "1", "frac"),
    ("forearm_inertia_factor", "1", "nonneg"),
    ("platform_mass", "kg", "nonneg"),
    ("payload_mass", "kg", "nonneg"),
    ("carriage_mass", "kg", "nonneg"),
    ("gravity", "m/s^2", "nonneg"),
)



def check_field(name: str, kind: str, value: Any) -> Optional[str]:
    """Return an error message if a concrete scalar ``value`` is invalid for ``kind``, else None."""
    if isinstance(value, jax.core.Tracer):
        return None
    arr = jnp.asarray(value)
    if arr.ndim != 0:
        return None  # batched designs: validated by whoever built the batch
    v = float(arr)
    if not math.isfinite(v):
        return f"{name} must be a finite number, got {v!r}"
    if kind == "nonneg" and v < 0:
        return f"{name} must be >= 0, got {v!r}"
    if kind == "pos" and not v > 0:
        return f"{name} must be > 0, got {v!r}"
    if kind == "frac" and not 0.0 <= v <= 1.0:
        return f"{name} must be in [0, 1], got {v!r}"
    return None


class MassError(ValueError):
    """Invalid mass model; the message names the field and the value."""


class MassModel(eqx.Module):
    """Lumped mass model of a Delta robot (see the module docstring for the modelling choices).

    Attributes (all array leaves, SI units):
        upper_arm_mass: kg, per arm.
        upper_arm_com_fraction: centre of mass of the upper arm from A_i, as a fraction of L1.
        upper_arm_inertia_factor: inertia about the centre of mass / (m L1^2) (1/12: uniform rod).
        rotor_inertia: motor rotor (+ gearbox input) inertia, motor side, kg m^2.
        gear_ratio: n = motor speed / arm speed (1: direct drive).
        elbow_mass: extra lumped mass at each elbow, kg.
        forearm_mass: one forearm (both parallelogram rods), kg.
        forearm_elbow_fraction: s, share of the forearm weight carried at the elbow: the forearm's centre of mass
            is at (1 - s) L2 from the elbow (``point_split`` lumps s m at the elbow and the rest at the platform).
        forearm_inertia_factor: ``rigid_rod`` only: forearm inertia about its centre of mass, perpendicular to the
            rods, / (m L2^2) (1/12: uniform rods); at most s (1 - s).
        platform_mass: travelling plate, kg.
        payload_mass: payload carried by the platform, kg.
        carriage_mass: per chain, mass moved radially by the R actuator that does not rotate with the arm, kg.
        gravity: g along +z (down), m/s^2.
        forearm_model: ``"rigid_rod"`` (default) or ``"point_split"`` (static: it selects the equations, so a
            batch of designs shares it).
    """

    upper_arm_mass: jax.Array = eqx.field(converter=float_leaf)
    upper_arm_com_fraction: jax.Array = eqx.field(converter=float_leaf, default=0.5)
    upper_arm_inertia_factor: jax.Array = eqx.field(converter=float_leaf, default=1.0 / 12.0)
    rotor_inertia: jax.Array = eqx.field(converter=float_leaf, default=0.0)
    gear_ratio: jax.Array = eqx.field(converter=float_leaf, default=1.0)
    elbow_mass: jax.Array = eqx.field(converter=float_leaf, default=0.0)
    forearm_mass: jax.Array = eqx.field(converter=float_leaf, default=0.0)
    forearm_elbow_fraction: jax.Array = eqx.field(converter=float_leaf, default=0.5)
    forearm_inertia_factor: jax.Array = eqx.field(converter=float_leaf, default=1.0 / 12.0)
    platform_mass: jax.Array = eqx.field(converter=float_leaf, default=0.0)
    payload_mass: jax.Array = eqx.field(converter=float_leaf, default=0.0)
    carriage_mass: jax.Array = eqx.field(converter=float_leaf, default=0.0)
    gravity: jax.Array = eqx.field(converter=float_leaf, default=STANDARD_GRAVITY)
    forearm_model: str = eqx.field(static=True, default=DEFAULT_FOREARM_MODEL)

    def __check_init__(self):
        if self.forearm_model not in FOREARM_MODELS:
            raise MassError(f"forearm_model must be one of {FOREARM_MODELS}, got {self.forearm_model!r}")
        for name, _unit, kind in MASS_FIELDS:
            msg = check_field(name, kind, getattr(self, name))
            if msg is not None:
                raise MassError(msg)
        if self.forearm_model == "rigid_rod":
            k, s = self.forearm_inertia_factor, self.forearm_elbow_fraction
            if not any(isinstance(v, jax.core.Tracer) or jnp.ndim(v) for v in (k, s)):
                bound = float(s) * (1.0 - float(s))
                if float(k) > bound * (1.0 + 1e-12):
                    raise MassError(f"forearm_inertia_factor must be <= s (1 - s) = {bound!r} for rods between "
                                    f"elbow and platform (s = forearm_elbow_fraction = {float(s)!r}), got {float(k)!r}")

    # -- lumped quantities used by the dynamics (per chain) -------------------------------------------------
    def elbow_point_mass(self) -> jax.Array:
        """Point mass at each elbow: elbow hardware + the elbow share of the forearm (kg)."""
        return self.elbow_mass + self.forearm_elbow_fraction * self.forearm_mass

    def moving_mass(self) -> jax.Array:
        """Translating point mass at the platform centre P: plate + payload + 3 forearm shares (kg)."""
        return self.platform_mass + self.payload_mass + 3.0 * (1.0 - self.forearm_elbow_fraction) * self.forearm_mass

    def arm_inertia(self, L1: jax.Array) -> jax.Array:
        """Inertia of one chain's rotating parts about the motor axis, reflected rotor included (kg m^2)."""
        c = self.upper_arm_com_fraction * L1
        m = self.upper_arm_mass
        return (self.upper_arm_inertia_factor * m * L1 * L1 + m * c * c + self.elbow_point_mass() * L1 * L1
                + self.gear_ratio * self.gear_ratio * self.rotor_inertia)

    def arm_first_moment(self, L1: jax.Array) -> jax.Array:
        """First moment of the rotating point masses about the motor axis, m_a c + m_e L1 (kg m)."""
        return self.upper_arm_mass * self.upper_arm_com_fraction * L1 + self.elbow_point_mass() * L1

    def forearm_rotation_deficit(self) -> jax.Array:
        """J (kg) with T_forearm = T_point_split - J/2 |v_C - v_B|^2: the rod's inertia below two end masses.

        For ``rigid_rod``, m (s (1 - s) - factor) >= 0 (uniform rods, s = 1/2: m / 6); for ``point_split``
        exactly 0 (and the dynamics skip the term). The elbow and platform lumps (:meth:`elbow_point_mass`,
        :meth:`moving_mass`) are the same in both models: they carry the weight and the translation.
        """
        if self.forearm_model == "point_split":
            return jnp.zeros_like(self.forearm_mass)
        s = self.forearm_elbow_fraction
        return self.forearm_mass * (s * (1.0 - s) - self.forearm_inertia_factor)

    def forearm_inertia(self, L2: jax.Array) -> jax.Array:
        """Inertia of one forearm about its centre of mass, perpendicular to the rods (kg m^2), per model."""
        s = self.forearm_elbow_fraction
        k = s * (1.0 - s) if self.forearm_model == "point_split" else self.forearm_inertia_factor
        return k * self.forearm_mass * L2 * L2

    def radial_mass(self) -> jax.Array:
        """Mass per chain moved radially by the R actuator: arm + elbow share + carriage (kg)."""
        return self.upper_arm_mass + self.elbow_point_mass() + self.carriage_mass

    def with_forearm_model(self, forearm_model: str) -> "MassModel":
        """The same masses with the other forearm model (``"rigid_rod"`` or ``"point_split"``).

        A static field, so ``eqx.tree_at`` cannot set it; this validates the combination again (e.g. a
        ``forearm_inertia_factor`` above s (1 - s) is rejected for ``rigid_rod``).
        """
        return dataclasses.replace(self, forearm_model=forearm_model)

    def with_payload(self, payload_mass: Any) -> "MassModel":
        """The same model carrying ``payload_mass`` (kg)."""
        return eqx.tree_at(lambda m: m.payload_mass, self, float_leaf(payload_mass))
