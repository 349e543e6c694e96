"""Reads the robot block (``robot.*``, ``configs/robot/*.yaml``) into library objects; no settings class:

- :func:`robot_from_config`: the fixed robot (:class:`deltajax.Delta`) and, with ``robot.R_range``, the
  reconfigurable one (:class:`deltajax.ReconfigurableDelta`);
- :func:`mass_from_config`: ``robot.mass`` as a :class:`deltajax.mass.MassModel`;
- :func:`check_reach_over_range`: something is reachable at both ends of ``robot.R_range``.

Every error names the field (``robot.<field>``) and the value.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Optional, Tuple

from ..geometry import Delta, GeometryError, ReconfigurableDelta
from ..mass import FOREARM_MODELS, MASS_FIELDS, MassError, MassModel
from .readers import ConfigError, check_fits, read_choice, read_field

__all__ = ["robot_from_config", "mass_from_config", "check_reach_over_range", "n_steps"]


def robot_from_config(cfg: Mapping[str, Any], prefix: str = "robot") -> Tuple[Delta, Optional[ReconfigurableDelta]]:
    """Build the robot described by a ``configs/robot/*.yaml`` entry.

    Fields: ``base_radius``, ``platform_radius``, ``upper_arm``, ``forearm`` (m), ``theta_min_deg``,
    ``theta_max_deg`` (deg, ``null`` = unlimited), optional ``R_range: {min, max, step}`` (m) for a
    reconfigurable robot and optional ``mass`` (used by the dynamics).

    Returns:
        (fixed robot, reconfigurable robot or ``None``). The fixed robot has R = ``base_radius``.

    Raises:
        ConfigError: a missing or invalid field; the message names ``robot.<field>`` and the value.
    """
    kw = {key: read_field(f"{prefix}.{key}", cfg.get(key), unit="m")
          for key in ("base_radius", "platform_radius", "upper_arm", "forearm")}
    lo = read_field(f"{prefix}.theta_min_deg", cfg.get("theta_min_deg"), none=True, unit="deg")
    hi = read_field(f"{prefix}.theta_max_deg", cfg.get("theta_max_deg"), none=True, unit="deg")
    mass_cfg = cfg.get("mass") if hasattr(cfg, "get") else None
    mass = None
    if mass_cfg is not None:
        mass = mass_from_config(mass_cfg, kw, prefix=f"{prefix}.mass")
    try:
        robot = Delta.from_degrees(theta_min_deg=lo, theta_max_deg=hi, mass=mass, **kw)
    except GeometryError as e:
        raise ConfigError(f"{prefix}: {e}") from None
    rng = cfg.get("R_range") if hasattr(cfg, "get") else None
    if rng is None:
        return robot, None
    p = f"{prefix}.R_range"
    r_min, r_max, r_step = (read_field(f"{p}.{k}", rng.get(k), unit="m") for k in ("min", "max", "step"))
    if r_step > 0 and r_max >= r_min:  # the R samples (one float64 each at least), before anything holds them
        check_fits(f"{p}.step", r_step, 8.0 * n_steps(r_min, r_max, r_step), "the R samples", unit="m")
    try:
        recon = ReconfigurableDelta.from_range(robot, r_min, r_max, r_step)
    except GeometryError as e:
        raise ConfigError(f"{p}: {e}") from None
    return robot, recon


def n_steps(lo: float, hi: float, step: float) -> int:
    """Samples of the inclusive range [lo, hi] every ``step`` (an estimate: no array is built); the R
    samples of a range, before any array holds them."""
    return math.floor((hi - lo) / step + 1e-6) + 1


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
    """Build a :class:`MassModel` from a ``mass:`` config block, validating every field first.

    Fields: those of :class:`MassModel` (``upper_arm_mass`` required, the others default as documented;
    ``forearm_model`` is ``rigid_rod`` or ``point_split``) plus,
    instead of ``upper_arm_inertia_factor``, an absolute ``upper_arm_inertia`` (kg m^2 about the upper arm's
    centre of mass), converted with the config's ``upper_arm`` length L1 (taken from ``geometry_kwargs``).

    Args:
        mass_cfg: mapping (OmegaConf or dict).
        geometry_kwargs: the robot's geometry (``upper_arm`` in m) for the inertia conversion.
        prefix: dotted path used in error messages.

    Raises:
        ConfigError: unknown, missing, non-numeric or out-of-range field; the message names
            ``<prefix>.<field>`` and the value.
    """
    known = {name for name, _u, _k in MASS_FIELDS} | {"upper_arm_inertia", "forearm_model"}
    keys = list(mass_cfg.keys())
    for k in keys:
        if k not in known:
            raise ConfigError(f"{prefix}.{k} is not a mass-model field; valid keys: {', '.join(sorted(known))}")
    ranges = {"nonneg": dict(lo=0), "pos": dict(lo=0, lo_open=True), "frac": dict(lo=0, hi=1)}
    kinds = {name: kind for name, _u, kind in MASS_FIELDS}
    units = {name: u for name, u, _k in MASS_FIELDS if u != "1"} | {"upper_arm_inertia": "kg m^2"}
    values: dict[str, Any] = {}
    for k in keys:
        v = mass_cfg[k]
        if v is None:
            continue
        if k == "forearm_model":
            values[k] = str(read_choice(f"{prefix}.forearm_model", v, FOREARM_MODELS))
        else:
            values[k] = read_field(f"{prefix}.{k}", v, unit=units.get(k, ""), **ranges[kinds.get(k, "nonneg")])
    if values.get("forearm_model") == "point_split" and "forearm_inertia_factor" in values:
        raise ConfigError(f"{prefix}.forearm_inertia_factor={values['forearm_inertia_factor']!r} applies to "
                          "forearm_model: rigid_rod only (point_split's inertia is that of its two end masses)")
    if "upper_arm_mass" not in values:
        raise ConfigError(f"{prefix}.upper_arm_mass is required")
    if "upper_arm_inertia" in values:
        if "upper_arm_inertia_factor" in values:
            raise ConfigError(f"{prefix}: give upper_arm_inertia or upper_arm_inertia_factor, not both")
        inertia = values.pop("upper_arm_inertia")
        L1 = None if geometry_kwargs is None else geometry_kwargs.get("upper_arm")
        m = values["upper_arm_mass"]
        if L1 is None or not float(L1) > 0:
            raise ConfigError(f"{prefix}.upper_arm_inertia needs the robot's upper_arm length, got {L1!r}")
        if inertia > 0 and m == 0:
            raise ConfigError(f"{prefix}.upper_arm_inertia={inertia!r} kg m^2 needs upper_arm_mass > 0")
        values["upper_arm_inertia_factor"] = 0.0 if m == 0 else inertia / (m * float(L1) ** 2)
    try:
        return MassModel(**values)
    except MassError as e:  # the rigid-rod inertia bound couples two fields; the message names them
        raise ConfigError(f"{prefix}.{e}") from None
