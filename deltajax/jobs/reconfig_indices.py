"""Experiment ``reconfig_indices``: Franco-López 2026 Tables 6-8 and Fig 8.

Over the fixed robot's workspace (ODR, R = robot.base_radius) on the grid, the indices of the fixed robot
and of the reconfigurable robot at R* (the sample maximising ``experiment.criterion``, k~ by default, with
``beta``) are reduced to min / max / mean. ``beta=0.5/0.75/0.25`` gives Tables 6/7/8.

Writes group ``workspace``: axes x, y, z; ``reachable_fixed`` (uint8); ``R_star`` and the fields of
``experiment.store_fields`` for both robots (float32, NaN outside the ODR workspace); ``stats`` (robot x
index x stat: min, max, mean) with the paper's table as ``paper_stats`` (NaN where the paper has no value);
group ``workspace/slices``: the Fig 8 heat-map data on the planes ``experiment.slices_z`` (RDR solved on
the whole plane, not only the ODR workspace). Figure ``fig8_<index>_slices.png``.
"""

from __future__ import annotations

import time

import numpy as np

from ..config import ConfigError, paper_grid_from_config
from ..indices import INDEX_NAMES

__all__ = ["run", "STATS"]

STATS = ("min", "max", "mean")


def run(ctx) -> None:
    from .. import plots
    from ..papers import FRANCO2026_INDEX_STATS as PAPER_TABLES
    from ..workspace import fixed_workspace, redundancy_grid
    from ..workspace.driver import computed_points, face_count
    from ..workspace.redundancy import resolve_redundancy_host

    cfg = ctx.cfg.experiment
    if ctx.recon is None:
        raise ConfigError("reconfig_indices needs a reconfigurable robot: robot.R_range is null")
    beta = float(ctx.cfg.get("beta", cfg.get("beta", 0.5)))
    if not 0.0 < beta < 1.0:
        raise ConfigError(f"beta must be in (0, 1), got {beta!r}")
    b_v, b_f = float(cfg.get("b_v", 2.0)), float(cfg.get("b_f", 4.2))
    for k, v in (("b_v", b_v), ("b_f", b_f)):
        if not v > 0:
            raise ConfigError(f"experiment.{k} must be > 0, got {v!r}")
    criterion = str(cfg.get("criterion", "k_tilde"))
    if criterion not in INDEX_NAMES:
        raise ConfigError(f"experiment.criterion must be one of {INDEX_NAMES}, got {criterion!r}")
    mode = str(cfg.get("mode", "fast"))
    if mode not in ("fast", "exact"):
        raise ConfigError(f"experiment.mode must be 'fast' or 'exact', got {mode!r}")
    slice_index = str(cfg.get("slice_index", "omega_v"))
    if slice_index not in INDEX_NAMES:
        raise ConfigError(f"experiment.slice_index must be one of {INDEX_NAMES}, got {slice_index!r}")
    store = list(cfg.get("store_fields", []) or [])
    for n in store:
        if n not in INDEX_NAMES:
            raise ConfigError(f"experiment.store_fields: {n!r} is not one of {INDEX_NAMES}")
    grid = paper_grid_from_config(cfg)
    h = grid.h
    chunk = int(cfg.get("chunk_points", 1 << 18))
    ck = ctx.run_dir / "checkpoint" if cfg.get("checkpoint", True) else None
    kw = dict(b_v=b_v, b_f=b_f, beta=beta)

    t0 = time.perf_counter()
    with ctx.progress(total=computed_points(grid), desc="ODR fields") as bar:
        # only the fields written below are kept on the grid; the statistics accumulate chunk by chunk
        odr = fixed_workspace(ctx.robot, grid, fields=True, field_dtype=np.float32, chunk_size=1 << 20,
                              keep=sorted(set(store) | {slice_index}), stats=True, progress=bar.update, checkpoint_dir=None if ck is None else ck / "odr", **kw)
    t1 = time.perf_counter()
    work: dict = {}
    with ctx.progress(total=computed_points(grid, mode == "fast"), desc=f"RDR R* ({mode})") as bar:
        rdr = redundancy_grid(ctx.recon, grid, mask=odr.ok, criterion=criterion, mode=mode, field_dtype=np.float32,
                              chunk_size=chunk, keep=["R_star", *store], stats=True, R_dtype=np.float32,
                              progress=bar.update, work=work,
                              checkpoint_dir=None if ck is None else ck / f"rdr_{mode}", **kw)
    t2 = time.perf_counter()
    s_odr = odr.stats
    s_rdr = rdr.stats  # over the ODR workspace: the mask of the redundancy job
    t3 = time.perf_counter()

    res = ctx.results
    g = "workspace"
    for name, ax in (("x", grid.x), ("y", grid.y), ("z", grid.z)):
        res.put_axis(g, name, ax, units="m")
    res.put(g, "reachable_fixed", odr.ok.astype(np.uint8), units="1", dims=("x", "y", "z"))
    res.put(g, "R_star", rdr.fields["R_star"].astype(np.float32, copy=False), units="m", dims=("x", "y", "z"))
    for n in store:
        res.put(g, f"{n}_rdr", rdr.fields[n], units="1", dims=("x", "y", "z"))
        res.put(g, f"{n}_odr", odr.fields[n], units="1", dims=("x", "y", "z"))
    res.put_axis(g, "robot", np.array(["RDR", "ODR"], dtype=object), units="1")
    res.put_axis(g, "index", np.array(list(INDEX_NAMES), dtype=object), units="1")
    res.put_axis(g, "stat", np.array(list(STATS), dtype=object), units="1")
    table = np.array([[[s[n][st] for st in STATS] for n in INDEX_NAMES] for s in (s_rdr, s_odr)])
    res.put(g, "stats", table, units="1", dims=("robot", "index", "stat"))
    paper = PAPER_TABLES.get(beta)
    ptab = np.full_like(table, np.nan)
    if paper is not None:
        for r, rob in enumerate(("RDR", "ODR")):
            for i, n in enumerate(INDEX_NAMES):
                if n in paper[rob]:
                    ptab[r, i] = paper[rob][n]
    res.put(g, "paper_stats", ptab, units="1", dims=("robot", "index", "stat"),
            attrs={"source": "Franco-Lopez 2026 Tables 6 (beta 0.5), 7 (0.75), 8 (0.25)"})
    res.put(g, "count_odr", int(odr.ok.sum()), units="1", dims=())
    faces = face_count(odr.ok)  # ODR points on the box faces: the statistics then miss part of the workspace
    res.put(g, "face_count_odr", faces, units="1", dims=())
    if faces:
        ctx.log(f"WARNING: {faces} points of the fixed robot's workspace lie on the faces of the grid box: the "
                f"statistics cover only the part inside the box")
    res.set_attrs(g, beta=beta, b_v=b_v, b_f=b_f, criterion=criterion, mode=mode, h=h,
                  time_odr_s=t1 - t0, time_rdr_s=t2 - t1, time_stats_s=t3 - t2,
                  rdr_ik_tests=work.get("samples", 0), rdr_full_kernels=work.get("full", 0))
    ctx.log(f"ODR {t1 - t0:.1f} s, RDR {t2 - t1:.1f} s ({work}), stats {t3 - t2:.1f} s")
    for n in ("inv_cond", "omega_v", "omega_f", "sigma_min_v", "sigma_min_f", "k_tilde"):
        for rob, s in (("RDR", s_rdr), ("ODR", s_odr)):
            p = "" if paper is None or n not in paper[rob] else f"   paper {paper[rob][n]}"
            ctx.log(f"{n:12s} {rob}: min {s[n]['min']:.6g} max {s[n]['max']:.6g} mean {s[n]['mean']:.6g}{p}")

    # Fig 8: whole planes (the RDR reaches beyond the ODR workspace)
    zs = [float(v) for v in cfg.get("slices_z", [0.3, 0.4, 0.5])]
    kz = [int(np.argmin(np.abs(grid.z - v))) for v in zs]
    nx, ny, _ = grid.shape
    X, Y = np.meshgrid(grid.x, grid.y, indexing="ij")
    sl_rdr, sl_odr, sl_R = [], [], []
    col = INDEX_NAMES.index(slice_index)
    for k in ctx.progress(kz, total=len(kz), desc="Fig 8 planes (RDR R*)"):
        pts = np.stack([X.ravel(), Y.ravel(), np.full(X.size, grid.z[k])], axis=-1)
        red, _ = resolve_redundancy_host(ctx.recon, pts, criterion, mode="fast", **kw)
        sl_rdr.append(red.indices[:, col].reshape(nx, ny))
        sl_R.append(red.R.reshape(nx, ny))
        sl_odr.append(odr.fields[slice_index][:, :, k].astype(np.float64))
    gs = f"{g}/slices"
    res.put_axis(gs, "x", grid.x, units="m")
    res.put_axis(gs, "y", grid.y, units="m")
    res.put_axis(gs, "z", grid.z[kz], units="m")
    res.put(gs, f"{slice_index}_rdr", np.stack(sl_rdr, -1), units="1", dims=("x", "y", "z"))
    res.put(gs, f"{slice_index}_odr", np.stack(sl_odr, -1), units="1", dims=("x", "y", "z"))
    res.put(gs, "R_star", np.stack(sl_R, -1), units="m", dims=("x", "y", "z"))
    if ctx.cfg.get("plots", True):
        fig = plots.index_slices(grid.x, grid.y, grid.z[kz], {"RDR (R* by " + criterion + ")": sl_rdr,
                                                              f"ODR (R = {float(ctx.robot.base_radius):.3f} m)": sl_odr},
                                 label=slice_index, units="1")
        ctx.savefig(fig, f"fig8_{slice_index}_slices")
