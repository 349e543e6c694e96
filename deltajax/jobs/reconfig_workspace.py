"""Experiment ``reconfig_workspace``: fixed vs reconfigurable workspace volume (Franco-López 2026 §6.1, Fig 7).

Writes group ``workspace``: axes x, y, z (m), ``reachable_fixed`` and ``reachable_reconfigurable`` (uint8
on the grid), scalars ``count_*``, ``volume_count_*`` (count h^3), ``volume_box_*`` (the paper's count / N
V_box), ``increase_percent`` (from the box volumes), and the paper's numbers as attributes. Figure
``fig7_workspace.png``.
"""

from __future__ import annotations

import numpy as np

from ..papers import FRANCO2026_VOLUMES as PAPER
from .. import plots
from ..workspace import fixed_workspace, reconfigurable_workspace
from ..workspace.driver import computed_points, face_count

__all__ = ["run"]


def run(ctx) -> None:
    s = ctx.settings                                   # checked before the run (config.paper_grid_settings)
    grid, h, chunk = s.grid, s.grid.h, s.chunk_points
    ck = ctx.run_dir / "checkpoint" if s.checkpoint else None
    ctx.log(f"grid {grid.shape} = {grid.n_points} points, h = {h} m")
    with ctx.progress(total=computed_points(grid), desc="fixed") as bar:
        fixed = fixed_workspace(ctx.robot, grid, fields=False, chunk_size=chunk, progress=bar.update,
                                checkpoint_dir=None if ck is None else ck / "fixed")
    with ctx.progress(total=computed_points(grid), desc="reconfigurable") as bar:
        recon = reconfigurable_workspace(ctx.recon, grid, chunk_size=chunk, progress=bar.update,
                                         checkpoint_dir=None if ck is None else ck / "reconf")
    res = ctx.results
    g = "workspace"
    for name, ax in (("x", grid.x), ("y", grid.y), ("z", grid.z)):
        res.put_axis(g, name, ax, units="m")
    out = {}
    for tag, job in (("fixed", fixed), ("reconfigurable", recon)):
        c = int(job.ok.sum())
        out[tag] = (c, grid.volume_count(c), grid.volume_box(c))
        res.put(g, f"reachable_{tag}", job.ok.astype(np.uint8), units="1", dims=("x", "y", "z"))
        res.put(g, f"count_{tag}", c, units="1", dims=())
        res.put(g, f"volume_count_{tag}", out[tag][1], units="m^3", dims=())
        res.put(g, f"volume_box_{tag}", out[tag][2], units="m^3", dims=())
        faces = face_count(job.ok)  # reachable points on the box faces: the volume is then a lower bound
        res.put(g, f"face_count_{tag}", faces, units="1", dims=())
        if faces:
            ctx.log(f"WARNING: {faces} points reachable by the {tag} robot lie on the faces of the grid box: its "
                    f"workspace continues outside the box, so its volume is a lower bound")
    inc = 100.0 * (out["reconfigurable"][0] / out["fixed"][0] - 1.0)
    res.put(g, "increase_percent", inc, units="%", dims=())
    res.set_attrs(g, h=h, n_points=grid.n_points, box_volume=grid.box_volume, fixed_R=float(ctx.robot.base_radius),
                  paper_volume_fixed=PAPER["volume_fixed"], paper_volume_reconfigurable=PAPER["volume_reconfigurable"],
                  paper_increase_percent=PAPER["increase_percent"])
    ctx.log(f"fixed: {out['fixed'][0]} points, {out['fixed'][1]:.5f} m^3 (count h^3), {out['fixed'][2]:.5f} m^3 "
            f"(count/N V_box); reconfigurable: {out['reconfigurable'][0]} points, {out['reconfigurable'][1]:.5f} / "
            f"{out['reconfigurable'][2]:.5f} m^3; increase {inc:.1f} % (paper 0.075 / 0.137 m^3, +82 %)")
    if ctx.plots:
        fig = plots.workspace_3d(grid.x, grid.y, grid.z, {"(a) reconfigurable": recon.ok,
                                                          f"(b) fixed R = {float(ctx.robot.base_radius):.3f} m": fixed.ok})
        ctx.savefig(fig, "fig7_workspace")
