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

from ..indices import INDEX_NAMES
from .stages import Runner, Stage, State
from ..workspace import fixed_workspace, redundancy_grid
from ..workspace.driver import computed_points, face_count
from ..papers import FRANCO2026_INDEX_STATS as PAPER_TABLES
from ..workspace.redundancy import resolve_redundancy_host
from .. import plots

__all__ = ["run", "STATS"]

STATS = ("min", "max", "mean")


def run(ctx) -> None:
    """The paper's tables and Fig 8: settings read once, then the fixed robot's workspace (``odr``), R* over it
    (``rdr``), the statistics against the paper (``store``), the Fig 8 planes (``slices``) and their figure."""
    st = State(ctx=ctx, res=ctx.results, **_settings(ctx))
    Runner(ctx, "reconfig_indices", resumable=False).run(STAGES, st)


def _settings(ctx) -> dict:
    """What the stages read: the job's settings ``s`` (checked before the run: config.reconfig_indices_settings;
    read as ``st.s``), the checkpoint directory and the k~ parameters as keyword arguments."""
    s = ctx.settings
    return dict(s=s, ck=ctx.run_dir / "checkpoint" if s.checkpoint else None,
                kw=dict(b_v=s.b_v, b_f=s.b_f, beta=s.beta), plots=ctx.plots)


def _odr(st: State) -> None:
    """The fixed robot's workspace and indices on the grid (only the stored and sliced fields kept; statistics
    accumulated chunk by chunk; checkpointed under ``<run_dir>/checkpoint/odr``)."""
    s = st.s
    st.t0 = time.perf_counter()
    with st.ctx.progress(total=computed_points(s.grid), desc="ODR fields") as bar:
        # only the fields written below are kept on the grid; the statistics accumulate chunk by chunk
        st.odr = fixed_workspace(st.ctx.robot, s.grid, fields=True, field_dtype=np.float32, chunk_size=1 << 20,
                                 keep=sorted(set(s.store_fields) | {s.slice_index}), stats=True, progress=bar.update,
                                 checkpoint_dir=None if st.ck is None else st.ck / "odr", **st.kw)
    st.t1 = time.perf_counter()


def _rdr(st: State) -> None:
    """R* (the sample maximising ``experiment.criterion``) over the fixed robot's workspace, and the indices there;
    the statistics of both robots over that workspace."""
    s = st.s
    st.work = {}
    with st.ctx.progress(total=computed_points(s.grid, s.mode == "fast"), desc=f"RDR R* ({s.mode})") as bar:
        st.rdr = redundancy_grid(st.ctx.recon, s.grid, mask=st.odr.ok, criterion=s.criterion, mode=s.mode,
                                 field_dtype=np.float32, chunk_size=s.chunk_points, keep=["R_star", *s.store_fields],
                                 stats=True, R_dtype=np.float32, progress=bar.update, work=st.work,
                                 checkpoint_dir=None if st.ck is None else st.ck / f"rdr_{s.mode}", **st.kw)
    st.t2 = time.perf_counter()
    st.s_odr = st.odr.stats
    st.s_rdr = st.rdr.stats  # over the ODR workspace: the mask of the redundancy job
    st.t3 = time.perf_counter()


def _store(st: State) -> None:
    """Group ``workspace``: the fields, the statistics table of both robots and the paper's (NaN where it has no
    value), the workspace's count and its points on the box faces (warned: the statistics then miss part of
    it); the table logged against the paper."""
    ctx, res, grid, odr, rdr, s_odr, s_rdr = st.ctx, st.res, st.s.grid, st.odr, st.rdr, st.s_odr, st.s_rdr
    g = "workspace"
    for name, ax in (("x", grid.x), ("y", grid.y), ("z", grid.z)):
        res.put_axis(g, name, ax, units="m")
    res.put(g, "reachable_fixed", odr.ok.astype(np.uint8), units="1", dims=("x", "y", "z"))
    res.put(g, "R_star", rdr.fields["R_star"].astype(np.float32, copy=False), units="m", dims=("x", "y", "z"))
    for n in st.s.store_fields:
        res.put(g, f"{n}_rdr", rdr.fields[n], units="1", dims=("x", "y", "z"))
        res.put(g, f"{n}_odr", odr.fields[n], units="1", dims=("x", "y", "z"))
    res.put_axis(g, "robot", np.array(["RDR", "ODR"], dtype=object), units="1")
    res.put_axis(g, "index", np.array(list(INDEX_NAMES), dtype=object), units="1")
    res.put_axis(g, "stat", np.array(list(STATS), dtype=object), units="1")
    table = np.array([[[s[n][st_] for st_ in STATS] for n in INDEX_NAMES] for s in (s_rdr, s_odr)])
    res.put(g, "stats", table, units="1", dims=("robot", "index", "stat"))
    paper = PAPER_TABLES.get(st.s.beta)
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
    t0, t1, t2, t3 = st.t0, st.t1, st.t2, st.t3
    res.set_attrs(g, beta=st.s.beta, b_v=st.s.b_v, b_f=st.s.b_f, criterion=st.s.criterion, mode=st.s.mode,
                  h=grid.h, time_odr_s=t1 - t0, time_rdr_s=t2 - t1, time_stats_s=t3 - t2,
                  rdr_ik_tests=st.work.get("samples", 0), rdr_full_kernels=st.work.get("full", 0))
    ctx.log(f"ODR {t1 - t0:.1f} s, RDR {t2 - t1:.1f} s ({st.work}), stats {t3 - t2:.1f} s")
    for n in ("inv_cond", "omega_v", "omega_f", "sigma_min_v", "sigma_min_f", "k_tilde"):
        for rob, s in (("RDR", s_rdr), ("ODR", s_odr)):
            p = "" if paper is None or n not in paper[rob] else f"   paper {paper[rob][n]}"
            ctx.log(f"{n:12s} {rob}: min {s[n]['min']:.6g} max {s[n]['max']:.6g} mean {s[n]['mean']:.6g}{p}")


def _slices(st: State) -> None:
    """Fig 8's data, group ``workspace/slices``: ``experiment.slice_index`` and R* on whole planes z (the RDR
    solved on the whole plane: it reaches beyond the ODR workspace) beside the fixed robot's."""
    ctx, res, grid = st.ctx, st.res, st.s.grid
    zs = [float(v) for v in st.s.slices_z]
    st.kz = kz = [int(np.argmin(np.abs(grid.z - v))) for v in zs]
    nx, ny, _ = grid.shape
    X, Y = np.meshgrid(grid.x, grid.y, indexing="ij")
    st.sl_rdr, st.sl_odr, sl_R = [], [], []
    col = INDEX_NAMES.index(st.s.slice_index)
    for k in ctx.progress(kz, total=len(kz), desc="Fig 8 planes (RDR R*)"):
        pts = np.stack([X.ravel(), Y.ravel(), np.full(X.size, grid.z[k])], axis=-1)
        red, _ = resolve_redundancy_host(ctx.recon, pts, st.s.criterion, mode="fast", **st.kw)
        st.sl_rdr.append(red.indices[:, col].reshape(nx, ny))
        sl_R.append(red.R.reshape(nx, ny))
        st.sl_odr.append(st.odr.fields[st.s.slice_index][:, :, k].astype(np.float64))
    gs = "workspace/slices"
    res.put_axis(gs, "x", grid.x, units="m")
    res.put_axis(gs, "y", grid.y, units="m")
    res.put_axis(gs, "z", grid.z[kz], units="m")
    res.put(gs, f"{st.s.slice_index}_rdr", np.stack(st.sl_rdr, -1), units="1", dims=("x", "y", "z"))
    res.put(gs, f"{st.s.slice_index}_odr", np.stack(st.sl_odr, -1), units="1", dims=("x", "y", "z"))
    res.put(gs, "R_star", np.stack(sl_R, -1), units="m", dims=("x", "y", "z"))


def _plots(st: State) -> None:
    """Figure ``fig8_<index>_slices``: the slices of both robots."""
    grid = st.s.grid
    fig = plots.index_slices(grid.x, grid.y, grid.z[st.kz],
                             {"RDR (R* by " + st.s.criterion + ")": st.sl_rdr,
                              f"ODR (R = {float(st.ctx.robot.base_radius):.3f} m)": st.sl_odr},
                             label=st.s.slice_index, units="1")
    st.ctx.savefig(fig, f"fig8_{st.s.slice_index}_slices")


STAGES = (
    Stage("odr", _odr),
    Stage("rdr", _rdr),
    Stage("store", _store),
    Stage("slices", _slices),
    Stage("plots", _plots, when=lambda st: st.plots),
)
