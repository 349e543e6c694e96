"""Boundary-search paper: workspace boundary of its Table 1 robot by Conti et al.'s bisection and the paper's
continuation variant, Test-Pose call counts, pyramid-sector volumes, a dense check of every ray for
re-entry (the workspace is not star-shaped from the centre) and an independent Cartesian grid volume.

Writes group ``boundary``:

* ``boundary`` attrs: centre, eps, rho_max, grid volume / centroid / step, the paper's numbers.
* ``boundary/step_<s>deg/<method>`` (method ``conti`` or ``continuation``): axes ``azimuth`` and ``polar``
  (rad, dimension scales), ``radius_in`` / ``radius_out`` / ``radius`` (m, the bracket and its midpoint),
  ``calls`` (Test-Pose calls per ray), ``ok``, the dense-sampling results ``n_exits``, ``first_exit``,
  ``last_exit``; attrs: total calls, warm/compile time, sector volumes for every rule, ray-integrated volume,
  volume in doubt.
* ``boundary/centre_sweep``: axis ``centre_z`` (m): sector volume and calls of both methods per centre.

Plots: ``boundary_slice.png`` (the plane y = 0: reachable region, centre, both boundaries, re-entering rays)
and ``boundary_surface.png`` (3-D boundary points, non-star rays highlighted).
"""

from __future__ import annotations

import functools
import time

import jax
import jax.numpy as jnp
import numpy as np

from ..papers import BOUNDARY_SEARCH as PAPER
from ..workspace import boundary as B
from .stages import Runner, Stage, State
from .. import plots

__all__ = ["run"]

G0 = "boundary"  # the job's group


def _timed_search(robot, p, step, method, reps):
    """Run one search: first call (compile + run) and the best of ``reps`` warm calls (s)."""
    def go():
        return B.boundary_search(robot, p.centre, step_deg=step, eps=p.eps, rho_max=p.rho_max,
                                 method=method, predictor=p.predictor, half_space=p.half_space)

    t0 = time.perf_counter()
    res = jax.block_until_ready(go())
    first = time.perf_counter() - t0
    warm = []
    for _ in range(reps):
        t0 = time.perf_counter()
        res = jax.block_until_ready(go())
        warm.append(time.perf_counter() - t0)
    return res, min(warm), first - min(warm)


def _volumes(res, prof, polar, azimuth, rule):
    """Sector volumes of the bracket ends and midpoint, and the dense-sampling volumes (m^3)."""
    w = B.vertex_weights(polar, azimuth)
    r_in, r_out, r_mid = (np.asarray(x) for x in (res.radius_in, res.radius_out, res.radius))
    vols = {f"volume_{rl}_{which}": B.sector_volume(r, polar, azimuth, rl)
            for rl in B.VOLUME_RULES for which, r in (("in", r_in), ("mid", r_mid), ("out", r_out))}
    vols["volume_sector"] = vols[f"volume_{rule}_mid"]
    vols["volume_ray_integral"] = float(np.sum(w * np.asarray(prof.vol_integrand)))
    vols["volume_missed"] = float(np.sum(w * np.asarray(prof.vol_missed)))
    vols["volume_false"] = float(np.sum(w * np.asarray(prof.vol_false)))
    vols["volume_first_exit"] = B.sector_volume(np.asarray(prof.first_exit), polar, azimuth, rule)
    vols["volume_last_exit"] = B.sector_volume(np.asarray(prof.last_exit), polar, azimuth, rule)
    return vols


def run(ctx) -> None:
    """The boundary job: settings read once, then its stages on the stage engine: ``setup`` (the settings and the
    paper's numbers stored), ``grid_volume`` (the independent check), one ``step_<s>deg`` per angular step (both
    methods), ``centre_sweep`` and ``plots``."""
    p = ctx.settings                                   # checked before the run (config.boundary_search_spec)
    st = State(ctx=ctx, res=ctx.results, p=p, robot=ctx.robot, keep={})
    steps = [Stage(f"step_{step:g}deg", functools.partial(_step, step=step)) for step in p.steps_deg]
    Runner(ctx, "boundary_search", resumable=False).run(
        (Stage("setup", _store_setup), Stage("grid_volume", _grid_volume), *steps,
         Stage("centre_sweep", _centre_sweep, when=lambda st: bool(st.p.centre_sweep_z)),
         Stage("plots", _plots, when=lambda st: st.ctx.plots)), st)


def _store_setup(st: State) -> None:
    """Group ``boundary``'s attributes: the search's settings (m) and the paper's numbers."""
    p = st.p
    st.res.set_attrs(G0, centre=np.asarray(p.centre), centre_units="m", eps=p.eps, eps_units="m",
                     rho_max=p.rho_max, rho_max_units="m", predictor=p.predictor,
                     half_space=p.half_space, volume_rule=p.volume_rule,
                     bisection_calls_per_ray=B.bisection_calls(p.rho_max, p.eps),
                     **{f"paper_{k}": v for k, v in PAPER.items()})
    st.ctx.log(f"centre {p.centre} m, eps {p.eps} m, rho_max {p.rho_max} m "
               f"({B.bisection_calls(p.rho_max, p.eps)} bisection calls per ray)")


def _grid_volume(st: State) -> None:
    """The independent check: the workspace volume (m^3) and centroid on a cell-centred Cartesian grid (z > 0)."""
    ctx, p = st.ctx, st.p
    t0 = time.perf_counter()
    gv = B.grid_volume(st.robot, p.grid_h, p.grid_box, half_space=p.half_space,
                       progress=lambda it, total: ctx.progress(it, total=total, desc="grid volume"))
    st.res.set_attrs(G0, grid_volume=gv.volume, grid_volume_units="m^3", grid_count=gv.count, grid_h=gv.h,
                     grid_shape=np.asarray(gv.shape), grid_centroid=gv.centroid,
                     grid_time_s=time.perf_counter() - t0)
    ctx.log(f"grid volume (h = {gv.h} m, {gv.shape}): {gv.volume:.4f} m^3, centroid {np.round(gv.centroid, 4)} m")
    st.res.flush()


def _step(st: State, step: float) -> None:
    """One angular step (deg): each method's search (timed warm and with compilation), the dense check of every
    ray and the volumes, stored in ``boundary/step_<s>deg/<method>`` (flushed) and kept for the plots."""
    ctx, p = st.ctx, st.p
    for method in B.METHODS:
        res, warm, compile_s = _timed_search(st.robot, p, step, method, p.timing_repeats)
        prof = B.ray_profiles(st.robot, res, rho_max=p.rho_max, n_samples=p.profile_samples,
                              half_space=p.half_space)
        polar, azimuth = np.asarray(res.polar), np.asarray(res.azimuth)
        vols = _volumes(res, prof, polar, azimuth, p.volume_rule)
        stats = _store_step(st.res, f"{G0}/step_{step:g}deg/{method}", res, prof, warm, compile_s, vols)
        st.keep[(step, method)] = (res, prof)
        ctx.log(f"{step:g} deg {method:12s}: {stats['calls_total']} calls "
                f"({stats['calls_per_ray_mean']:.3f}/ray), warm {warm * 1e3:.1f} ms, compile {compile_s:.2f} s; "
                f"sector V = {vols['volume_sector']:.4f} m^3 ({p.volume_rule}, midpoint), "
                f"ray-integral V = {vols['volume_ray_integral']:.4f}; non-star rays {stats['n_rays_non_star']}; "
                f"in doubt: +{vols['volume_false']:.4f} (unreachable inside), -{vols['volume_missed']:.4f} "
                f"(reachable outside)")
    st.res.flush()


def _store_step(res_file, g, res, prof, warm, compile_s, vols) -> dict:
    """One search's group ``g``: the rays' brackets (m), calls, dense-sampling results and its statistics
    (attributes: calls, times in s, volumes in m^3); returns the statistics."""
    polar, azimuth, calls = np.asarray(res.polar), np.asarray(res.azimuth), np.asarray(res.calls)
    res_file.put_axis(g, "azimuth", azimuth, units="rad",
                      attrs={"description": "azimuth theta from +x (the paper's theta), inclusive 0..360 deg"})
    res_file.put_axis(g, "polar", polar, units="rad",
                      attrs={"description": "polar angle phi from +z (down, into the workspace; the paper's "
                                            "phi); elevation above the horizontal = 90 deg - phi"})
    dims = ("azimuth", "polar")
    res_file.put(g, "radius_in", res.radius_in, units="m", dims=dims,
                 attrs={"description": "last radius tested reachable"})
    res_file.put(g, "radius_out", res.radius_out, units="m", dims=dims,
                 attrs={"description": "first radius tested unreachable"})
    res_file.put(g, "radius", res.radius, units="m", dims=dims, attrs={"description": "bracket midpoint"})
    res_file.put(g, "calls", calls, units="1", dims=dims, attrs={"description": "Test-Pose calls per ray"})
    res_file.put(g, "ok", np.asarray(res.ok), units="1", dims=dims)
    res_file.put(g, "n_exits", np.asarray(prof.n_exits), units="1", dims=dims,
                 attrs={"description": "inside->outside transitions along the densely sampled ray"})
    res_file.put(g, "first_exit", np.asarray(prof.first_exit), units="m", dims=dims)
    res_file.put(g, "last_exit", np.asarray(prof.last_exit), units="m", dims=dims)
    non_star = np.asarray(prof.n_exits) > 1
    stats = dict(calls_total=int(calls.sum()), calls_per_ray_mean=float(calls.mean()),
                 calls_per_ray_max=int(calls.max()), n_rays=int(calls.size),
                 all_ok=bool(np.all(np.asarray(res.ok))), time_warm_s=warm, time_compile_s=compile_s,
                 n_rays_non_star=int(non_star.sum()),
                 n_rays_reentry_beyond=int(np.asarray(prof.reentry_beyond).sum()),
                 n_rays_hole_before=int(np.asarray(prof.hole_before).sum()), **vols)
    res_file.set_attrs(g, **stats, volume_units="m^3")
    return stats


def _centre_sweep(st: State) -> None:
    """Sector volume (m^3) and calls of both methods for a sweep of centres on the axis (the paper's centre is
    unknown): group ``boundary/centre_sweep``."""
    ctx, p, res_file = st.ctx, st.p, st.res
    zs = np.asarray(p.centre_sweep_z)
    rows = {m: ([], []) for m in B.METHODS}
    for z in ctx.progress(zs, total=len(zs), desc="centre sweep"):
        c = (p.centre[0], p.centre[1], float(z))
        for m in B.METHODS:
            r = B.boundary_search(st.robot, c, step_deg=p.sweep_step_deg, eps=p.eps, rho_max=p.rho_max,
                                  method=m, predictor=p.predictor, half_space=p.half_space)
            ok = bool(np.all(np.asarray(r.ok)))
            rows[m][0].append(B.sector_volume(np.asarray(r.radius_in), np.asarray(r.polar),
                                              np.asarray(r.azimuth), p.volume_rule) if ok else np.nan)
            rows[m][1].append(int(np.asarray(r.calls).sum()))
    gs = f"{G0}/centre_sweep"
    res_file.put_axis(gs, "centre_z", zs, units="m")
    for m in B.METHODS:
        res_file.put(gs, f"volume_{m}", np.asarray(rows[m][0]), units="m^3", dims=("centre_z",),
                     attrs={"description": f"{p.volume_rule} sector volume of radius_in"})
        res_file.put(gs, f"calls_{m}", np.asarray(rows[m][1]), units="1", dims=("centre_z",))
    res_file.set_attrs(gs, step_deg=p.sweep_step_deg)
    for z, vc, cc, vn, cn in zip(zs, *rows["conti"], *rows["continuation"]):
        ctx.log(f"centre z = {z:.3f}: conti V = {vc:.4f} ({cc} calls), continuation V = {vn:.4f} ({cn} calls)")


def _plots(st: State) -> None:
    """The figures of the finest step: the slice y = 0 and the 3-D boundary (:func:`_plot`)."""
    step = min(st.p.steps_deg)
    _plot(st.ctx, st.robot, st.p, st.keep[(step, "conti")], st.keep[(step, "continuation")], step)


def _plot(ctx, robot, p, conti, cont, step):
    res_c, prof_c = conti
    res_n, _ = cont
    polar, azimuth = np.asarray(res_c.polar), np.asarray(res_c.azimuth)
    centre = np.asarray(p.centre)
    # Slice y = 0 through the centre: the azimuths 0 (x > 0) and 180 deg (x < 0).
    xs = np.linspace(-3.0, 3.0, 301)
    zs = np.linspace(-0.5, 4.5, 251)
    X, Z = np.meshgrid(xs, zs, indexing="xy")
    pts = np.stack([X.ravel(), np.full(X.size, centre[1]), Z.ravel()], -1)
    mask = np.asarray(jax.jit(jax.vmap(lambda q: B.test_pose(robot, q, p.half_space)))(jnp.asarray(pts)))
    ctx.savefig(plots.boundary_slice(X, Z, mask, centre, float(robot.base_radius), polar, azimuth, conti, cont, step),
                "boundary_slice")

    d = np.asarray(B.ray_directions(polar, azimuth))
    q = centre + np.asarray(res_n.radius)[..., None] * d
    ns = np.asarray(prof_c.n_exits) > 1
    ctx.savefig(plots.boundary_surface(q, ns), "boundary_surface")
