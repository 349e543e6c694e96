"""Workspace engine: grids, reachable volumes, index fields, redundancy resolution, statistics.

Pure, jit/vmap-able functions (one robot; vmap over designs with ``in_axes=(0, None)``)::

    make_grid(x, y, z, h) -> Grid                      # host object; grid.points(start, stop) -> (n, 3)
    reachable_mask(robot, points) -> bool[N]
    reachable_fraction(robot, points) -> float
    reconfigurable_reachable(recon, points) -> bool[N] # some R sample reaches
    index_fields(robot, points, b_v=, b_f=, beta=) -> (ok[N], {index name: float[N]})   NaN outside
    resolve_redundancy(recon, points, criterion="k_tilde", b_v=, b_f=, beta=) -> Redundancy(k, R, value, ok, indices)

One call for any robot (box sized from its reach bound, truncation flagged)::

    volume(robot, h=0.005, stats=False) -> WorkspaceVolume(volume, count, h, box, truncated, grid, mask, stats)

Host drivers (NumPy in/out, chunked, progress, checkpoint/resume)::

    resolve_redundancy_host(recon, points, criterion, mode="fast" | "exact", ...)
    fixed_workspace(robot, grid, ...), reconfigurable_workspace(recon, grid, ...), redundancy_grid(recon, grid, ...)
    index_stats(fields, mask) -> {name: {min, max, mean, count}}
"""

from .grid import (FIELD_NAMES, Grid, franco2026_grid, index_fields, make_grid, mirrored_point_indices, point_indices,
                   reachable_fraction, reachable_mask)
from .redundancy import (Redundancy, indices_at_host, reach_interval, reach_k_range_host,
                         reconfigurable_reachable, resolve_redundancy, resolve_redundancy_host, sample_value)
from .driver import CheckpointMismatch, GridJob, fixed_workspace, reconfigurable_workspace, redundancy_grid, run_chunks
from .stats import index_stats
from . import boundary

from .measure import WorkspaceVolume, reach_box, volume  # one-call volume of any robot


__all__ = ["FIELD_NAMES", "Grid", "franco2026_grid", "index_fields", "make_grid", "mirrored_point_indices",
           "point_indices", "reachable_fraction", "reachable_mask", "Redundancy", "indices_at_host", "reach_interval",
           "reach_k_range_host", "reconfigurable_reachable", "resolve_redundancy", "resolve_redundancy_host",
           "sample_value", "CheckpointMismatch", "GridJob", "fixed_workspace", "reconfigurable_workspace",
           "redundancy_grid", "run_chunks", "index_stats", "boundary", "WorkspaceVolume", "reach_box", "volume"]
