"""Build library objects from (Hydra/OmegaConf or plain dict) configuration, validating first.

Every error raised here names the config field and the value, before anything is compiled.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Optional, Tuple

from .geometry import Delta, GeometryError, ReconfigurableDelta

__all__ = ["ConfigError", "robot_from_config"]


class ConfigError(ValueError):
    """Invalid configuration; the message names the field (dotted path) and the value."""


def _get(cfg: Mapping[str, Any], key: str, prefix: str, default: Any = ...):
    if key in cfg and cfg[key] is not None:
        return cfg[key]
    if default is ...:
        raise ConfigError(f"{prefix}.{key} is required")
    return default


def _number(cfg: Mapping[str, Any], key: str, prefix: str, default: Any = ...) -> Optional[float]:
    v = _get(cfg, key, prefix, default)
    if v is None:
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ConfigError(f"{prefix}.{key} must be a number, got {v!r}") from None
    if math.isnan(f):
        raise ConfigError(f"{prefix}.{key} must not be NaN")
    return f


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
    kw = {}
    for key in ("base_radius", "platform_radius", "upper_arm", "forearm"):
        kw[key] = _number(cfg, key, prefix)
    lo = _number(cfg, "theta_min_deg", prefix, None)
    hi = _number(cfg, "theta_max_deg", prefix, None)
    mass_cfg = cfg.get("mass") if hasattr(cfg, "get") else None
    mass = None
    if mass_cfg is not None:
        try:
            from .mass import mass_from_config  # provided by the dynamics module
        except ImportError:  # pragma: no cover - dynamics not installed
            mass = None
        else:
            mass = mass_from_config(mass_cfg, kw, prefix=f"{prefix}.mass")
    try:
        robot = Delta.from_degrees(theta_min_deg=lo, theta_max_deg=hi, mass=mass, **kw)
    except GeometryError as e:
        raise ConfigError(f"{prefix}: {e}") from None
    rng = cfg.get("R_range") if hasattr(cfg, "get") else None
    if rng is None:
        return robot, None
    p = f"{prefix}.R_range"
    r_min, r_max, r_step = _number(rng, "min", p), _number(rng, "max", p), _number(rng, "step", p)
    try:
        recon = ReconfigurableDelta.from_range(robot, r_min, r_max, r_step)
    except GeometryError as e:
        raise ConfigError(f"{p}: {e}") from None
    return robot, recon
