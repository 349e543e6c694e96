"""One-call workspace volume and index statistics of any robot, on a box sized from its reach bound.

    res = dj.workspace.volume(robot, h=0.005)          # Delta or ReconfigurableDelta
    res.volume, res.count, res.box, res.truncated      # m^3, points, ((x0, x1), (y0, y1), (z0, z1)) m, bool
    dj.workspace.volume(robot, h=0.005, stats=True).stats["k_tilde"]["mean"]

The box needs no guess: it is the robot's closed-form reach bound (:func:`deltajax.workspace.driver.reach_box`,
the same bound the grid jobs use for null axes; over the whole R range for a reconfigurable robot), widened
to whole grid steps plus one. ``truncated`` is the check that nothing was cut off anyway: a reachable point on
a face of the box.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Optional, Union

import numpy as np

from ..geometry import Delta, ReconfigurableDelta
from .driver import fixed_workspace, reach_box as driver_reach_box, reconfigurable_workspace
from .grid import Grid, make_grid
from .stats import index_stats

__all__ = ["WorkspaceVolume", "volume", "reach_box", "MAX_POINTS"]

#: grids larger than this are refused (about 4 GB of working memory with index statistics); raise h instead
MAX_POINTS = 400_000_000


@dataclasses.dataclass(frozen=True, eq=False)
class WorkspaceVolume:
    """Result of :func:`volume`.

    Attributes:
        volume: reachable volume, count * h^3 (m^3).
        count: reachable grid points.
        h: grid spacing (m).
        box: the evaluated box ((x0, x1), (y0, y1), (z0, z1)) (m, base frame, z down).
        truncated: True when a reachable point lies on a face of the box (the box cut the workspace off, so
            ``volume`` is a lower bound); False is the normal case.
        grid: the evaluated :class:`Grid`.
        mask: bool (nx, ny, nz) reachable mask on ``grid``.
        stats: with ``stats=True``: index name -> {"min", "max", "mean", "count"} over the reachable points
            (dimensionless indices, homogenised theta-block); else ``None``.
        reconfigurable: whether the robot was a :class:`~deltajax.ReconfigurableDelta` (reachable at some R).
    """

    volume: float
    count: int
    h: float
    box: tuple
    truncated: bool
    grid: Grid
    mask: np.ndarray
    stats: Optional[dict] = None
    reconfigurable: bool = False

    def __repr__(self) -> str:
        return (f"WorkspaceVolume(volume={self.volume:.6g} m^3, count={self.count}, h={self.h} m, "
                f"box={self.box}, truncated={self.truncated}, reconfigurable={self.reconfigurable})")


def reach_box(robot: Union[Delta, ReconfigurableDelta]) -> tuple:
    """Bounding box ((x0, x1), (y0, y1), (z0, z1)) (m, z down) of every platform position the robot can reach
    within its joint limits (over its whole R range for a :class:`~deltajax.ReconfigurableDelta`): the one
    reach bound, :func:`deltajax.workspace.driver.reach_box` (the grid jobs size null axes with it too)."""
    if isinstance(robot, ReconfigurableDelta):
        return driver_reach_box(robot.robot.with_base_radius(robot.R_min), R_max=float(robot.R_max))
    return driver_reach_box(robot)


def volume(robot: Union[Delta, ReconfigurableDelta], h: float = 0.005, *, stats: bool = False,
           b_v: float = 2.0, b_f: float = 4.2, beta: float = 0.5, chunk_size: int = 1 << 20,
           progress=None) -> WorkspaceVolume:
    """Workspace volume (and, optionally, index statistics) of ``robot`` in one call.

    Args:
        robot: a :class:`~deltajax.Delta` (reachable: IK within joint limits) or a
            :class:`~deltajax.ReconfigurableDelta` (reachable at some R sample).
        h: grid spacing (m); the error of count * h^3 shrinks like h.
        stats: also compute min / max / mean of every index over the workspace (fixed robots only).
        b_v, b_f, beta: parameters of k~ (for ``stats``).
        chunk_size: points per chunk (bounded memory).
        progress: callable(n) called with the points finished per chunk (e.g. ``tqdm(...).update``).

    Returns:
        :class:`WorkspaceVolume`.

    Raises:
        ValueError: h not a positive number, a grid of more than :data:`MAX_POINTS` points, or ``stats`` for
            a reconfigurable robot (use :func:`deltajax.workspace.redundancy_grid`).
    """
    h = float(h)
    if not (math.isfinite(h) and h > 0):
        raise ValueError(f"h must be a positive grid spacing in m, got {h!r}")
    recon = isinstance(robot, ReconfigurableDelta)
    if not recon and not isinstance(robot, Delta):
        raise TypeError(f"robot must be a deltajax.Delta or ReconfigurableDelta, got {type(robot).__name__}")
    if recon and stats:
        raise ValueError("stats=True needs a redundancy resolution for a reconfigurable robot: use "
                         "deltajax.workspace.redundancy_grid (or pass recon.at(R) for one R)")
    # whole steps on a lattice through the origin, one step of padding: the faces lie outside the reach bound
    # and y is exactly symmetric (mirror halving applies)
    (x0, x1), (y0, y1), (z0, z1) = reach_box(robot)
    y = max(-y0, y1)
    ix = (math.floor(x0 / h) - 1, math.ceil(x1 / h) + 1)
    iy = math.ceil(y / h) + 1
    iz = (math.floor(z0 / h) - 1, math.ceil(z1 / h) + 1)
    n = (ix[1] - ix[0] + 1) * (2 * iy + 1) * (iz[1] - iz[0] + 1)
    if n > MAX_POINTS:
        raise ValueError(f"h={h!r} m needs a grid of {n:,} points (> {MAX_POINTS:,}); use a larger h")
    grid = make_grid((ix[0] * h, ix[1] * h), (-iy * h, iy * h), (iz[0] * h, iz[1] * h), h)
    if recon:
        job = reconfigurable_workspace(robot, grid, chunk_size=chunk_size, progress=progress)
    else:
        job = fixed_workspace(robot, grid, fields=stats, b_v=b_v, b_f=b_f, beta=beta, chunk_size=chunk_size,
                              progress=progress)
    ok = job.ok
    faces = (ok[0].any() or ok[-1].any() or ok[:, 0].any() or ok[:, -1].any() or ok[:, :, 0].any()
             or ok[:, :, -1].any())
    count = job.count
    return WorkspaceVolume(volume=grid.volume_count(count), count=count, h=h, box=grid.bounds,
                           truncated=bool(faces), grid=grid, mask=ok,
                           stats=index_stats(job.fields, ok) if stats else None, reconfigurable=recon)
