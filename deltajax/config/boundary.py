"""Reads ``experiment.*`` of ``experiment=boundary_search`` (m, deg) into :class:`BoundarySearchSettings`; the search
centre (and each swept centre) must lie in the robot's workspace.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from .readers import ConfigError, read_choice, read_field, read_vector

__all__ = ["BoundarySearchSettings", "boundary_search_spec"]


def _search_centre(path: str, v: Any, centre: list, robot) -> None:
    """A boundary search starts from its centre: outside the workspace it would measure nothing (a NaN sector
    volume); refused unless the inverse kinematics of ``centre`` succeeds within the joint limits."""
    if robot is None:
        return
    from ..workspace.grid import reachable_point

    if not bool(reachable_point(robot, centre)):
        raise ConfigError(f"{path}={v!r} m puts the search centre {centre!r} m outside the robot's workspace (no "
                          f"inverse kinematics within the joint limits there); choose a reachable centre")


@dataclasses.dataclass(frozen=True)
class BoundarySearchSettings:
    """``experiment=boundary_search`` (m, deg): the search centre, bisection tolerance and ray length, angular
    steps, predictor, half space, volume rule, profile samples, the reference grid (spacing, box), the centre sweep
    and the timing repeats."""

    eps: float
    rho_max: float
    grid_h: float
    sweep_step_deg: float
    centre: list
    steps_deg: list
    predictor: str
    volume_rule: str
    profile_samples: int
    grid_box: list
    centre_sweep_z: list
    half_space: bool
    timing_repeats: int


def boundary_search_spec(e, cfg=None, robot=None, recon=None) -> BoundarySearchSettings:
    """``experiment.*`` of boundary_search (m, deg)."""
    from ..workspace import boundary as B

    pos = lambda k, unit: read_field(f"experiment.{k}", e.get(k), lo=0, lo_open=True, unit=unit)  # noqa: E731
    out = dict(eps=pos("eps", "m"), rho_max=pos("rho_max", "m"), grid_h=pos("grid_h", "m"),
               sweep_step_deg=pos("sweep_step_deg", "deg"),
               centre=read_vector("experiment.centre", e.get("centre"), 3))
    _search_centre("experiment.centre", out["centre"], out["centre"], robot)
    if out["rho_max"] <= out["eps"]:
        raise ConfigError(f"experiment.rho_max must exceed experiment.eps, got {out['rho_max']} m <= {out['eps']} m")
    steps = [read_field(f"experiment.steps_deg[{i}]", s, lo=0, lo_open=True, unit="deg")
             for i, s in enumerate(e.get("steps_deg") or [])]
    if not steps:
        raise ConfigError("experiment.steps_deg must list at least one angular step (deg)")
    for s in steps:
        try:
            B.angle_grid(s)
        except (ValueError, TypeError) as err:
            raise ConfigError(f"experiment.steps_deg: {err}") from None
    out["steps_deg"] = steps
    out["predictor"] = read_choice("experiment.predictor", e.get("predictor"), B.PREDICTORS)
    out["volume_rule"] = read_choice("experiment.volume_rule", e.get("volume_rule"), B.VOLUME_RULES)
    out["profile_samples"] = read_field("experiment.profile_samples", e.get("profile_samples"), kind="int", lo=2)
    box = e.get("grid_box")
    if not hasattr(box, "__len__") or len(box) != 3:
        raise ConfigError(f"experiment.grid_box must be [[x0, x1], [y0, y1], [z0, z1]] (m), got {box!r}")
    box = [read_vector(f"experiment.grid_box[{i}]", b, 2) for i, b in enumerate(box)]
    for (a, b), name in zip(box, "xyz"):
        if not b > a:
            raise ConfigError(f"experiment.grid_box {name} side must have lo < hi (m), got {[a, b]!r}")
        k = (b - a) / out["grid_h"]
        if abs(k - round(k)) > 1e-6 * k:
            raise ConfigError(f"experiment.grid_box {name} side ({a}, {b}) m is not a whole number of "
                              f"experiment.grid_h = {out['grid_h']} m")
    out["grid_box"] = box
    out["centre_sweep_z"] = [read_field(f"experiment.centre_sweep_z[{i}]", z, unit="m")
                             for i, z in enumerate(e.get("centre_sweep_z") or [])]
    for i, z in enumerate(out["centre_sweep_z"]):  # each swept centre starts a search as the centre does
        _search_centre(f"experiment.centre_sweep_z[{i}]", z, [out["centre"][0], out["centre"][1], z], robot)
    out["half_space"] = read_field("experiment.half_space", e.get("half_space", True), kind="bool")
    out["timing_repeats"] = read_field("experiment.timing_repeats", e.get("timing_repeats", 3), kind="int", lo=1)
    return BoundarySearchSettings(**out)
