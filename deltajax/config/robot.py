"""Reads the robot block (``robot.*``, ``configs/robot/*.yaml``) into library objects. Its settings are declared
once, like every experiment's (:func:`deltajax.config.readers.setting`), checked by the one generic reader
(:func:`deltajax.config.readers.read_settings`), and its Hydra schema is generated from them
(:func:`deltajax.config.readers.schema_of`, registered as ``schema/robot``):

- :class:`RobotSettings`: the block, with :class:`RRangeBlock` (``robot.R_range``) and :class:`MassBlock`
  (``robot.mass``, one field per :data:`deltajax.mass.MASS_FIELDS`, generated from it);
- :func:`robot_from_config`: the fixed robot (:class:`deltajax.Delta`) and, with ``robot.R_range``, the
  reconfigurable one (:class:`deltajax.ReconfigurableDelta`);
- :func:`mass_from_config`: a ``mass`` block as a :class:`deltajax.mass.MassModel`;
- :func:`check_reach_over_range`: something is reachable at both ends of ``robot.R_range``.

Every error names the field (``robot.<field>``) and the value.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping, Optional, Tuple

from ..geometry import Delta, GeometryError, ReconfigurableDelta
from ..mass import FOREARM_MODELS, MASS_FIELDS, MassError, MassModel
from .readers import ConfigError, check_fits, read_settings, setting

__all__ = ["RobotSettings", "RRangeBlock", "MassBlock", "robot_from_config", "mass_from_config",
           "check_reach_over_range", "n_steps"]


def n_steps(lo: float, hi: float, step: float) -> int:
    """Samples of the inclusive range [lo, hi] every ``step`` (an estimate: no array is built); the R
    samples of a range, before any array holds them."""
    return math.floor((hi - lo) / step + 1e-6) + 1


@dataclasses.dataclass(frozen=True, kw_only=True)
class RRangeBlock:
    """``robot.R_range`` (m): the reconfiguration joint's samples R = min + k * step, k = 0, 1, ... up to max (an
    empty range, max < min, and a step that does not divide it are the geometry's refusals,
    :meth:`deltajax.ReconfigurableDelta.from_range`)."""
    min: float = setting(lo=0, lo_open=True, unit="m")
    max: float = setting(lo=0, lo_open=True, unit="m")
    step: float = setting(lo=0, lo_open=True, unit="m")

    def _check(self, path: str) -> None:
        if self.max >= self.min:  # the R samples (one float64 each at least), before anything holds them
            check_fits(f"{path}.step", self.step, 8.0 * n_steps(self.min, self.max, self.step), "the R samples",
                       unit="m")


# ---- robot.mass: one field per MassModel field (deltajax.mass.MASS_FIELDS), each null = MassModel's default ----
_MASS_RANGES = {"nonneg": dict(lo=0), "pos": dict(lo=0, lo_open=True), "frac": dict(lo=0, hi=1)}


def _mass_fields() -> list:
    """The fields of :class:`MassBlock`: each of :data:`deltajax.mass.MASS_FIELDS` (its unit, its range by its
    kind), plus ``upper_arm_inertia`` (kg m^2, instead of the factor) after the factor and ``forearm_model`` before
    the forearm's inertia factor (the YAML's order)."""
    out = []
    for name, unit, kind in MASS_FIELDS:
        if name == "forearm_inertia_factor":
            out.append(("forearm_model", Optional[str], setting(None, choices=FOREARM_MODELS)))
        out.append((name, Optional[float], setting(None, unit="" if unit == "1" else unit, **_MASS_RANGES[kind])))
        if name == "upper_arm_inertia_factor":
            out.append(("upper_arm_inertia", Optional[float], setting(None, lo=0, unit="kg m^2")))
    return out


class _MassRules:
    """The cross-field rules of ``robot.mass`` and its conversion to a :class:`MassModel` (the methods of
    :class:`MassBlock`, whose fields are generated from :data:`deltajax.mass.MASS_FIELDS`)."""

    def _check(self, path: str) -> None:
        if self.forearm_model == "point_split" and self.forearm_inertia_factor is not None:
            raise ConfigError(f"{path}.forearm_inertia_factor={self.forearm_inertia_factor!r} applies to "
                              "forearm_model: rigid_rod only (point_split's inertia is that of its two end masses)")
        if self.upper_arm_mass is None:
            raise ConfigError(f"{path}.upper_arm_mass is required")
        if self.upper_arm_inertia is not None:
            if self.upper_arm_inertia_factor is not None:
                raise ConfigError(f"{path}: give upper_arm_inertia or upper_arm_inertia_factor, not both")
            if self.upper_arm_inertia > 0 and self.upper_arm_mass == 0:
                raise ConfigError(f"{path}.upper_arm_inertia={self.upper_arm_inertia!r} kg m^2 needs "
                                  "upper_arm_mass > 0")

    def with_upper_arm(self, upper_arm: Optional[float], path: str):
        """This block with ``upper_arm_inertia`` (kg m^2 about the upper arm's centre of mass) converted to
        ``upper_arm_inertia_factor`` with the robot's upper arm length L1 (m); unchanged without one."""
        if self.upper_arm_inertia is None:
            return self
        if upper_arm is None or not float(upper_arm) > 0:
            raise ConfigError(f"{path}.upper_arm_inertia needs the robot's upper_arm length, got {upper_arm!r}")
        m = self.upper_arm_mass
        factor = 0.0 if m == 0 else self.upper_arm_inertia / (m * float(upper_arm) ** 2)
        return dataclasses.replace(self, upper_arm_inertia_factor=factor)

    def model(self, path: str) -> MassModel:
        """The :class:`MassModel` of this block (after :meth:`with_upper_arm`): the fields given, the others
        MassModel's defaults."""
        values = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                  if f.name != "upper_arm_inertia" and getattr(self, f.name) is not None}
        try:
            return MassModel(**values)
        except MassError as e:  # the rigid-rod inertia bound couples two fields; the message names them
            raise ConfigError(f"{path}.{e}") from None


MassBlock = dataclasses.make_dataclass("MassBlock", _mass_fields(), bases=(_MassRules,), frozen=True,
                                       kw_only=True)
MassBlock.__module__ = __name__
MassBlock.__doc__ = (
    """``robot.mass``: the fields of :class:`deltajax.mass.MassModel` (:data:`deltajax.mass.MASS_FIELDS`, their units
    and ranges; null or absent: MassModel's default; ``upper_arm_mass`` required; ``forearm_model`` one of
    :data:`deltajax.mass.FOREARM_MODELS`, ``forearm_inertia_factor`` for ``rigid_rod`` only) plus, instead of
    ``upper_arm_inertia_factor``, an absolute ``upper_arm_inertia`` (kg m^2 about the upper arm's centre of mass),
    converted with the robot's ``upper_arm`` length (:meth:`with_upper_arm`).""")


@dataclasses.dataclass(frozen=True, kw_only=True)
class RobotSettings:
    """``robot`` (``configs/robot/*.yaml``): the geometry (m), the joint limits (deg, null: unlimited; their order
    and span are the geometry's rules, :meth:`deltajax.Delta.from_degrees`), the reconfiguration range (null: a
    fixed robot) and the mass model (null: none; the dynamics jobs need one)."""
    name: str = setting("custom")
    base_radius: float = setting(lo=0, lo_open=True, unit="m")
    platform_radius: float = setting(lo=0, unit="m")
    upper_arm: float = setting(lo=0, lo_open=True, unit="m")
    forearm: float = setting(lo=0, lo_open=True, unit="m")
    theta_min_deg: Optional[float] = setting(None, unit="deg")
    theta_max_deg: Optional[float] = setting(None, unit="deg")
    R_range: Optional[RRangeBlock] = setting(None)
    mass: Optional[MassBlock] = setting(None)

    def _check(self, path: str) -> Optional["RobotSettings"]:
        if self.mass is None:
            return None
        return dataclasses.replace(self, mass=self.mass.with_upper_arm(self.upper_arm, f"{path}.mass"))


def robot_from_config(cfg: Mapping[str, Any], prefix: str = "robot") -> Tuple[Delta, Optional[ReconfigurableDelta]]:
    """Build the robot described by a ``configs/robot/*.yaml`` entry (:class:`RobotSettings`).

    Fields: ``base_radius``, ``platform_radius``, ``upper_arm``, ``forearm`` (m), ``theta_min_deg``,
    ``theta_max_deg`` (deg, ``null`` = unlimited), optional ``R_range: {min, max, step}`` (m) for a
    reconfigurable robot and optional ``mass`` (used by the dynamics).

    Returns:
        (fixed robot, reconfigurable robot or ``None``). The fixed robot has R = ``base_radius``.

    Raises:
        ConfigError: a missing or invalid field; the message names ``robot.<field>`` and the value.
    """
    s = read_settings(RobotSettings, cfg, prefix)
    mass = None if s.mass is None else s.mass.model(f"{prefix}.mass")
    try:
        robot = Delta.from_degrees(theta_min_deg=s.theta_min_deg, theta_max_deg=s.theta_max_deg, mass=mass,
                                   base_radius=s.base_radius, platform_radius=s.platform_radius,
                                   upper_arm=s.upper_arm, forearm=s.forearm)
    except GeometryError as e:
        raise ConfigError(f"{prefix}: {e}") from None
    if s.R_range is None:
        return robot, None
    try:
        recon = ReconfigurableDelta.from_range(robot, s.R_range.min, s.R_range.max, s.R_range.step)
    except GeometryError as e:
        raise ConfigError(f"{prefix}.R_range: {e}") from None
    return robot, recon


def check_reach_over_range(cfg: Mapping[str, Any], recon: ReconfigurableDelta, prefix: str = "robot") -> None:
    """Something must be reachable at every R of ``robot.R_range`` (for jobs that use the range).

    The "can reach nothing" test of :class:`deltajax.Delta` is monotone in R, so both ends suffice.
    """
    rb, rng = recon.robot, cfg.get("R_range")
    for end, R in (("min", float(recon.R_min)), ("max", float(recon.R_max))):
        try:
            Delta(base_radius=R, platform_radius=rb.platform_radius, upper_arm=rb.upper_arm, forearm=rb.forearm,
                  theta_min=rb.theta_min, theta_max=rb.theta_max, mass=rb.mass)
        except GeometryError as e:
            raise ConfigError(f"{prefix}.R_range.{end}={rng.get(end)!r} m: at R = {R:g} m the {e}") from None


def mass_from_config(mass_cfg: Mapping[str, Any], geometry_kwargs: Optional[Mapping[str, Any]] = None,
                     prefix: str = "robot.mass") -> MassModel:
    """Build a :class:`MassModel` from a ``mass:`` config block (:class:`MassBlock`), validating every field first.

    Args:
        mass_cfg: mapping (OmegaConf or dict).
        geometry_kwargs: the robot's geometry (``upper_arm`` in m) for the conversion of ``upper_arm_inertia``.
        prefix: dotted path used in error messages.

    Raises:
        ConfigError: unknown, missing, non-numeric or out-of-range field; the message names
            ``<prefix>.<field>`` and the value.
    """
    block = read_settings(MassBlock, mass_cfg, prefix)
    upper_arm = None if geometry_kwargs is None else geometry_kwargs.get("upper_arm")
    return block.with_upper_arm(upper_arm, prefix).model(prefix)
