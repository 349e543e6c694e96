"""Design space: a gene vector in [0, 1]^d  <->  a (fixed or reconfigurable) Delta robot.

evosax does not keep genes inside bounds and its default mutation std is 1.0, so every gene is a
*normalised* coordinate: 0 is the lower and 1 the upper bound of its parameter. Offspring that leave
[0, 1] are *repaired* by reflection at the walls (:func:`reflect_unit`) before they are evaluated **and**
before they are told to the optimiser, so the optimiser's population, every evaluated design and every
reported design stay inside their bounds (tested).

Free parameters (any subset; the others stay at the baseline robot's value):

======================  ==================================================  ======
name                    meaning                                             units
======================  ==================================================  ======
``base_radius``         R of a fixed design                                  m
``R_min``, ``R_max``    reconfiguration range of a reconfigurable design    m
``platform_radius``     r                                                    m
``upper_arm``           L1                                                   m
``forearm``             L2                                                   m
``theta_min_deg``       lower joint limit                                    deg
``theta_max_deg``       upper joint limit                                    deg
``gear_ratio``          gearbox ratio n (motor speed / arm speed)            1
======================  ==================================================  ======

Bounds are validated when the space is built (outside jit): lo < hi, positive lengths, and ranges that
cannot invert (R_min's upper bound below R_max's lower bound; theta_min's below theta_max's), so every
gene vector decodes to a valid robot. Masses (when the baseline carries a :class:`deltajax.mass.MassModel`):
the upper arm and the forearms are rods of unchanged cross-section, so their masses scale with L1 / L1_0 and
L2 / L2_0; the model's centre-of-mass and inertia *fractions* of L1 then scale the arm inertia as m L1^2
by themselves. Platform, payload, rotor and carriage masses are kept (they do not depend on the lengths).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping, Optional, Sequence, Union

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float
import equinox as eqx

from ..geometry import Delta, GeometryError, ReconfigurableDelta

__all__ = ["DesignSpace", "reflect_unit", "PARAMETERS", "DesignSpaceError"]

#: Every parameter a gene can control, with its unit.
PARAMETERS = {
    "base_radius": "m",
    "R_min": "m",
    "R_max": "m",
    "platform_radius": "m",
    "upper_arm": "m",
    "forearm": "m",
    "theta_min_deg": "deg",
    "theta_max_deg": "deg",
    "gear_ratio": "1",
}
_LENGTHS = ("base_radius", "R_min", "R_max", "upper_arm", "forearm")


class DesignSpaceError(ValueError):
    """Invalid design-space configuration; the message names the field and the value."""


def _scale_mass(mass: Any, s_upper: Any, s_fore: Any) -> Any:
    """Rod masses scaled with their lengths (see the module docstring); ``None`` stays ``None``."""
    if mass is None or not hasattr(mass, "upper_arm_mass"):
        return mass

    return eqx.tree_at(lambda m: (m.upper_arm_mass, m.forearm_mass), mass,
                       (mass.upper_arm_mass * s_upper, mass.forearm_mass * s_fore))


def reflect_unit(g: Array) -> Array:
    """Fold any real number into [0, 1] by reflection at the walls (a triangle wave of period 2).

    Reflection (rather than clipping) keeps mutated offspring spread inside the box instead of piling them
    up on its faces. Non-finite genes become 0.5 (the centre), never NaN.
    """
    g = jnp.where(jnp.isfinite(g), g, 0.5)
    m = jnp.mod(g, 2.0)
    return jnp.clip(jnp.where(m > 1.0, 2.0 - m, m), 0.0, 1.0)


@dataclasses.dataclass(frozen=True)
class DesignSpace:
    """Normalised genes <-> robots around a baseline design.

    Attributes:
        baseline: the baseline robot (a :class:`Delta` for ``mode="fixed"``, a :class:`ReconfigurableDelta`
            for ``mode="reconfigurable"``); parameters that are not free keep its values.
        names: the free parameters, in gene order.
        lower, upper: their bounds (SI units except ``*_deg``, in degrees).
        n_R: number of R samples of a reconfigurable design (static; R_step follows from the range).
    """

    baseline: Union[Delta, ReconfigurableDelta]
    names: tuple[str, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    n_R: int = 16

    # -- construction ----------------------------------------------------------------------------------------
    @staticmethod
    def from_bounds(baseline: Union[Delta, ReconfigurableDelta], bounds: Mapping[str, Sequence[float]],
                    *, n_R: Optional[int] = None, prefix: str = "design.bounds") -> "DesignSpace":
        """Build and validate a design space.

        Args:
            baseline: baseline robot; reconfigurable -> reconfigurable designs.
            bounds: ``{parameter: [lo, hi]}`` for the free parameters (see module docstring).
            n_R: R samples per reconfigurable design (default: the baseline's, capped at 16 for speed).
            prefix: config path used in error messages.

        Raises:
            DesignSpaceError: unknown parameter, bad bound, a range that could invert, a parameter that does
                not fit the mode (``R_min`` for a fixed design, ``base_radius`` for a reconfigurable one).
        """
        recon = isinstance(baseline, ReconfigurableDelta)
        if not bounds:
            raise DesignSpaceError(f"{prefix} is empty: give at least one free parameter {sorted(PARAMETERS)}")
        names, lo, hi = [], [], []
        for name, b in bounds.items():
            name = str(name)
            if name not in PARAMETERS:
                raise DesignSpaceError(f"{prefix}.{name}: unknown design parameter; known: {sorted(PARAMETERS)}")
            if recon and name == "base_radius":
                raise DesignSpaceError(f"{prefix}.base_radius: a reconfigurable design has R_min/R_max instead")
            if not recon and name in ("R_min", "R_max"):
                raise DesignSpaceError(f"{prefix}.{name}: a fixed design has base_radius instead")
            try:
                a, c = (float(v) for v in b)
            except (TypeError, ValueError):
                raise DesignSpaceError(f"{prefix}.{name} must be [lo, hi], got {b!r}") from None
            if not (math.isfinite(a) and math.isfinite(c) and a < c):
                raise DesignSpaceError(f"{prefix}.{name} must be finite with lo < hi, got [{a!r}, {c!r}]")
            if name in _LENGTHS and a <= 0:
                raise DesignSpaceError(f"{prefix}.{name}: lengths must be > 0 m, got lower bound {a!r}")
            if name == "gear_ratio" and a <= 0:
                raise DesignSpaceError(f"{prefix}.{name}: must be > 0, got lower bound {a!r}")
            if name == "gear_ratio" and getattr(baseline.robot if recon else baseline, "mass", None) is None:
                raise DesignSpaceError(f"{prefix}.gear_ratio: the baseline robot has no mass model (robot.mass)")
            if name == "platform_radius" and a < 0:
                raise DesignSpaceError(f"{prefix}.{name}: must be >= 0 m, got lower bound {a!r}")
            names.append(name)
            lo.append(a)
            hi.append(c)
        space = DesignSpace(baseline=baseline, names=tuple(names), lower=tuple(lo), upper=tuple(hi),
                            n_R=int(n_R if n_R is not None else (min(baseline.n_R, 16) if recon else 1)))
        if recon and space.n_R < 2:
            raise DesignSpaceError(f"design.n_R must be >= 2 for a reconfigurable design, got {space.n_R}")
        # Ranges that could invert: check the worst case (upper bound of the low end vs lower of the high end).
        lo_d, hi_d = space._range("R_min"), space._range("R_max")
        if recon and not lo_d[1] < hi_d[0]:
            raise DesignSpaceError(f"{prefix}: R_min can reach {lo_d[1]!r} m but R_max can be as low as "
                                   f"{hi_d[0]!r} m; make the bounds disjoint so R_min < R_max for every design")
        tlo, thi = space._range("theta_min_deg"), space._range("theta_max_deg")
        if not tlo[1] < thi[0]:
            raise DesignSpaceError(f"{prefix}: theta_min_deg can reach {tlo[1]!r} deg but theta_max_deg can be "
                                   f"as low as {thi[0]!r} deg; make the bounds disjoint")
        if thi[1] - tlo[0] >= 360.0:
            raise DesignSpaceError(f"{prefix}: joint range up to {thi[1] - tlo[0]!r} deg must stay < 360 deg")
        # Every corner of the box must be a valid robot (validation of the extreme designs).
        for corner in (np.zeros(space.dim), np.ones(space.dim)):
            try:
                space.decode(jnp.asarray(corner, dtype=jnp.result_type(float)))
            except GeometryError as e:
                raise DesignSpaceError(f"{prefix}: the design at the {'lower' if corner[0] == 0 else 'upper'} "
                                       f"bounds is invalid: {e}") from None
        return space

    # -- helpers ---------------------------------------------------------------------------------------------
    @property
    def dim(self) -> int:
        """Number of genes."""
        return len(self.names)

    @property
    def reconfigurable(self) -> bool:
        return isinstance(self.baseline, ReconfigurableDelta)

    def _base_robot(self) -> Delta:
        return self.baseline.robot if self.reconfigurable else self.baseline

    def baseline_value(self, name: str) -> float:
        """Value of parameter ``name`` in the baseline design (its units)."""
        b = self._base_robot()
        if name == "R_min":
            return float(self.baseline.R_min)
        if name == "R_max":
            return float(self.baseline.R_max)
        if name == "gear_ratio":
            return float(b.mass.gear_ratio)
        if name.endswith("_deg"):
            return math.degrees(float(getattr(b, name[:-4])))
        return float(getattr(b, name))

    def _range(self, name: str) -> tuple[float, float]:
        if name in self.names:
            i = self.names.index(name)
            return self.lower[i], self.upper[i]
        if name in ("R_min", "R_max") and not self.reconfigurable:
            return (math.nan, math.nan)
        v = self.baseline_value(name)
        return v, v

    def units(self, name: str) -> str:
        return PARAMETERS[name]

    # -- genes <-> physical parameters ----------------------------------------------------------------------
    def to_params(self, genes: Float[Array, "d"]) -> Float[Array, "d"]:
        """Physical values (SI, degrees for ``*_deg``) of the free parameters of a (repaired) gene vector."""
        g = reflect_unit(jnp.asarray(genes))
        lo = jnp.asarray(self.lower, dtype=g.dtype)
        hi = jnp.asarray(self.upper, dtype=g.dtype)
        return lo + g * (hi - lo)

    def from_params(self, params: Sequence[float]) -> np.ndarray:
        """Genes of physical parameter values (no repair; values outside the bounds give genes outside [0,1])."""
        p = np.asarray(params, dtype=float)
        lo, hi = np.asarray(self.lower), np.asarray(self.upper)
        return (p - lo) / (hi - lo)

    def baseline_genes(self) -> np.ndarray:
        """Genes of the baseline design, clipped into [0, 1] (exact when the baseline is inside the bounds)."""
        return np.clip(self.from_params([self.baseline_value(n) for n in self.names]), 0.0, 1.0)

    def baseline_inside(self) -> bool:
        g = self.from_params([self.baseline_value(n) for n in self.names])
        return bool(np.all((g >= 0) & (g <= 1)))

    def decode(self, genes: Float[Array, "d"]) -> Union[Delta, ReconfigurableDelta]:
        """The robot of one gene vector (repaired into [0, 1] first). Pure; vmap it over a population."""
        values = self.to_params(genes)
        v = {n: values[i] for i, n in enumerate(self.names)}
        b = self._base_robot()
        dt = values.dtype

        def get(name):
            return v[name] if name in v else jnp.asarray(self.baseline_value(name), dt)

        kw = dict(platform_radius=get("platform_radius"), upper_arm=get("upper_arm"), forearm=get("forearm"),
                  theta_min=jnp.deg2rad(get("theta_min_deg")) if "theta_min_deg" in v else b.theta_min.astype(dt),
                  theta_max=jnp.deg2rad(get("theta_max_deg")) if "theta_max_deg" in v else b.theta_max.astype(dt))
        mass = _scale_mass(b.mass, kw["upper_arm"] / b.upper_arm, kw["forearm"] / b.forearm)
        if "gear_ratio" in v:
            mass = eqx.tree_at(lambda m: m.gear_ratio, mass, v["gear_ratio"])
        if not self.reconfigurable:
            R = get("base_radius")
            return Delta(base_radius=R, mass=mass, **kw)
        R_lo, R_hi = get("R_min"), get("R_max")
        R_lo, R_hi = jnp.minimum(R_lo, R_hi), jnp.maximum(R_lo, R_hi)
        R_nom = jnp.clip(self.baseline.robot.base_radius.astype(dt), R_lo, R_hi)
        robot = Delta(base_radius=R_nom, mass=mass, **kw)
        return ReconfigurableDelta(robot=robot, R_min=R_lo, R_step=(R_hi - R_lo) / (self.n_R - 1), n_R=self.n_R)

    def describe(self, genes: Any) -> dict[str, float]:
        """``{parameter: value}`` of one gene vector (host side, for reports)."""
        vals = np.asarray(self.to_params(jnp.asarray(genes)))
        out = {n: float(x) for n, x in zip(self.names, vals)}
        if "R_min" in out and "R_max" in out and out["R_min"] > out["R_max"]:
            out["R_min"], out["R_max"] = out["R_max"], out["R_min"]
        return out
