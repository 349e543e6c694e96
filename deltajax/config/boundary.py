"""Reads ``experiment.*`` of ``experiment=boundary_search`` (m, deg) into :class:`BoundarySearchSettings`, declared
once (each field's range, unit and choices as metadata, read by :func:`deltajax.config.readers.read_settings`); the
search centre (and each swept centre) must lie in the robot's workspace.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from .readers import ConfigError, read_box, read_field, read_settings, read_vector, setting
from ..workspace.grid import reachable_point
from ..workspace import boundary as B
from ..workspace.boundary import PREDICTORS, VOLUME_RULES

__all__ = ["BoundarySearchSettings", "boundary_search_spec"]


def _search_centre(path: str, v: Any, centre: list, robot) -> None:
    """A boundary search starts from its centre: outside the workspace it would measure nothing (a NaN sector
    volume); refused unless the inverse kinematics of ``centre`` succeeds within the joint limits."""
    if robot is None:
        return

    if not bool(reachable_point(robot, centre)):
        raise ConfigError(f"{path}={v!r} m puts the search centre {centre!r} m outside the robot's workspace (no "
                          f"inverse kinematics within the joint limits there); choose a reachable centre")


def _centre(path: str, v: Any) -> list:
    return read_vector(path, v, 3)


def _steps_deg(path: str, v: Any) -> list:
    steps = [read_field(f"{path}[{i}]", s, lo=0, lo_open=True, unit="deg") for i, s in enumerate(v or [])]
    if not steps:
        raise ConfigError(f"{path} must list at least one angular step (deg)")
    for s in steps:
        try:
            B.angle_grid(s)
        except (ValueError, TypeError) as err:
            raise ConfigError(f"{path}: {err}") from None
    return steps


def _heights(path: str, v: Any) -> tuple:
    return tuple(read_field(f"{path}[{i}]", z, unit="m") for i, z in enumerate(v or []))


def _predictors():
    return PREDICTORS


def _volume_rules():
    return VOLUME_RULES


@dataclasses.dataclass(frozen=True, kw_only=True)
class BoundarySearchSettings:
    """``experiment=boundary_search`` (m, deg): the search centre, bisection tolerance, angular steps, ray length,
    predictor, half space, volume rule, profile samples, the reference grid (spacing, box), the centre sweep and
    the timing repeats."""

    name: str = setting("boundary_search")
    centre: list = setting(read=_centre)
    eps: float = setting(lo=0, lo_open=True, unit="m")
    steps_deg: list = setting(read=_steps_deg)
    rho_max: float = setting(lo=0, lo_open=True, unit="m")
    predictor: str = setting(choices=_predictors)
    half_space: bool = setting(True)
    volume_rule: str = setting(choices=_volume_rules)
    profile_samples: int = setting(lo=2)
    grid_h: float = setting(lo=0, lo_open=True, unit="m")
    grid_box: list = setting(read=read_box)
    centre_sweep_z: tuple = setting((), read=_heights)
    sweep_step_deg: float = setting(lo=0, lo_open=True, unit="deg")
    timing_repeats: int = setting(3, lo=1)

    def _check(self, path: str) -> None:
        if self.rho_max <= self.eps:
            raise ConfigError(f"{path}.rho_max must exceed {path}.eps, got {self.rho_max} m <= {self.eps} m")
        for (a, b), name in zip(self.grid_box, "xyz"):
            k = (b - a) / self.grid_h
            if abs(k - round(k)) > 1e-6 * k:
                raise ConfigError(f"{path}.grid_box {name} side ({a}, {b}) m is not a whole number of "
                                  f"{path}.grid_h = {self.grid_h} m")


def boundary_search_spec(e, cfg=None, robot=None, recon=None) -> BoundarySearchSettings:
    """``experiment.*`` of boundary_search (m, deg); the search centre and each swept centre in the workspace of
    ``robot``."""
    s = read_settings(BoundarySearchSettings, e, "experiment")
    _search_centre("experiment.centre", s.centre, s.centre, robot)
    for i, z in enumerate(s.centre_sweep_z):  # each swept centre starts a search as the centre does
        _search_centre(f"experiment.centre_sweep_z[{i}]", z, [s.centre[0], s.centre[1], z], robot)
    return s
