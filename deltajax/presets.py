"""Robots shipped with deltajax (SPEC §2). Each function returns a validated robot.

Numbers and their sources:

* ``franco2026``: Franco-López et al. 2026, Table 1 and §5.1: R in [0.138, 0.495] m sampled every 1 mm
  (358 samples; the paper's "385" is a digit swap), r = 0.065 m, L1 = 0.200 m, L2 = 0.400 m,
  theta in [-40 deg, 110 deg]; the fixed (non-reconfigurable) variant has R = 0.200 m.
* ``boundary2d``: the boundary-search paper's Table 1: L1 = 1.73, L2 = 2.66, R - r = 1.74 (we put r = 0),
  no joint limits; the workspace is taken on one side of the base plate (z > 0).
"""

from __future__ import annotations

import math
from typing import Optional, Union

from .geometry import Delta, ReconfigurableDelta

__all__ = ["franco2026", "boundary2d", "PRESETS", "get"]

FRANCO2026_R_RANGE = (0.138, 0.495, 0.001)


def franco2026(fixed_R: Optional[float] = None, *, R_step: float = FRANCO2026_R_RANGE[2]
               ) -> Union[Delta, ReconfigurableDelta]:
    """The reconfigurable Delta of Franco-López et al. 2026.

    Args:
        fixed_R: if given, return the fixed-geometry robot with this base radius (m) (the paper's
            comparison robot is ``fixed_R=0.200``); if ``None``, the reconfigurable robot.
        R_step: spacing of the R samples for redundancy resolution (m).
    """
    base = Delta.from_degrees(base_radius=0.200 if fixed_R is None else fixed_R, platform_radius=0.065,
                              upper_arm=0.200, forearm=0.400, theta_min_deg=-40.0, theta_max_deg=110.0)
    if fixed_R is not None:
        return base
    return ReconfigurableDelta.from_range(base, FRANCO2026_R_RANGE[0], FRANCO2026_R_RANGE[1], R_step)


def boundary2d() -> Delta:
    """The robot of the boundary-search paper (its Table 1): L1 = 1.73, L2 = 2.66, R - r = 1.74, no limits."""
    return Delta(base_radius=1.74, platform_radius=0.0, upper_arm=1.73, forearm=2.66,
                 theta_min=-math.inf, theta_max=math.inf)


PRESETS = {"franco2026": franco2026, "boundary2d": boundary2d}


def get(name: str, **kwargs):
    """Look a preset up by name; raises ``KeyError`` listing the known names."""
    try:
        fn = PRESETS[name]
    except KeyError:
        raise KeyError(f"unknown robot preset {name!r}; known: {sorted(PRESETS)}") from None
    return fn(**kwargs)
