"""Worst cases found, not sampled: the regular workspace by rays, the worst points of the task cylinder and the
cycle, with a convergence check at doubled density, and every constraint's margin in units (issue 28).

* :func:`ray_cylinders` / :func:`ray_cylinder`: the regular workspace (largest axis-centred cylinder with a given
  H/D inside a good set) from *rays*: a ray (phi, z) of the 60 deg wedge (the Delta's three-fold + mirror
  symmetry) gives the first bad radius rho*(phi, z) (dense samples along the ray, then the first bad interval
  searched again, ``n_levels`` times: a bad island between the old grid's rings, e.g. where a forearm passes
  through the base plate, is found, not skipped). The profile rho(z) = min over phi of rho* is refined in passes
  of ``n_z`` x ``n_phi`` rays each, every pass placed where the previous one left the answer uncertain: (0) a
  coarse grid over the whole z range; (1) a grid of levels zoomed onto the cylinder found so far; (2, 3) the
  same levels with the phi rays zoomed twice onto each level's smallest radius (a dip between two phi rays is
  found, not interpolated); (4, 5) the levels next to the cylinder's two ends, zoomed twice onto the end
  brackets (where the height binds the ends set the volume); (6) a final check of the winning cylinder: rays at
  phi midway between the grid's, at ``n_z`` levels from its top disc to its bottom disc, and the diameter shrunk
  to twice the smallest radius found there. Between passes the cylinder is the largest one over the profile,
  counting every profile sample that its span touches plus the nearest sample beyond each end (so the answer
  never leans on an unsampled gap). All passes run in one loop with one call of the good test: one traced copy
  per compiled program, and the searches of several good sets (e.g. "any of the design's R samples" and "the
  operating R") share it.
* :func:`worst_in_cylinder`: the minimum of a scalar field over a task cylinder: dense samples, then a
  coordinate-wise golden section in (rho, phi, z) from the worst samples.
* :func:`certify_design`: one design on one problem: the regular workspace (rays), the task cylinder's worst index,
  joint margin and clearance, the cycle's worst joint margin and clearance and the motors' peak and RMS
  utilisation, at a density and at twice it; the figures are those of the denser evaluation, with the change
  doubling made (``*_change``) against the stated tolerances (:data:`TOLERANCES`).
* :func:`design_margins`: every constraint's margin in units from a design's metrics (numpy, any batch shape).
* :func:`grid_cylinder_bounds`: an independent brute-force check on a dense point grid (no rays).
* :func:`overlay`: a results file's ``verify`` group with the certified figures in place (what the summary, the
  plots, the report and the tolerance stage read).

Pure JAX, float64, vmappable (the good test is :func:`deltajax.constraints.good_point`).
"""

from __future__ import annotations

import math
from typing import Callable, Mapping, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ..regular import RegularWorkspace

__all__ = ["TOLERANCES", "RAY_DENSITY", "RAY_PASSES", "RayDensity", "ray_cylinders", "ray_cylinder",
           "worst_in_cylinder", "certify_design", "certified_program", "design_margins", "MARGIN_UNITS", "cycle_at",
           "grid_cylinder_bounds", "CERTIFIED_METRICS", "CYCLE_METRICS", "feasible_certified", "overlay"]

#: Stated accuracy of a certified figure: doubling the density moves it by no more than this.
#: regular_volume: relative; joint margin: deg; clearance: m; utilisations: ratio (relative to 1).
TOLERANCES = {"regular_volume": 0.005, "joint_margin_deg": 0.05, "interference_margin": 1e-4,
              "rms_utilisation": 1e-4, "peak_utilisation": 1e-4, "task_index_min": 1e-3}

_GOLD = (math.sqrt(5.0) - 1.0) / 2.0

#: The passes of :func:`ray_cylinders`, in order (module docstring).
RAY_PASSES = ("coarse", "zoom_z", "zoom_z", "zoom_z") + ("zoom_phi",) * 6 + ("check",)


class RayDensity(NamedTuple):
    """Density of :func:`ray_cylinders`: per pass ``n_z`` levels x ``n_phi`` rays (over the 60 deg wedge, both
    ends), ``n_along`` samples along a ray in each of ``n_levels`` nested searches (resolution
    r_max / (n_along - 1)^n_levels)."""

    n_phi: int = 7
    n_z: int = 16
    n_along: int = 9
    n_levels: int = 4

    def doubled(self) -> "RayDensity":
        """Twice the density in phi, z and along the rays (same end points: 2 n - 1 samples)."""
        return self._replace(n_phi=2 * self.n_phi - 1, n_z=2 * self.n_z - 1, n_along=2 * self.n_along - 1)


#: The verification's density (the fine evaluator, :func:`deltajax.optimize.designer.evaluate_designer`).
RAY_DENSITY = RayDensity()


def _golden_min(f, a, b, n):
    """Golden-section search for a minimum of f on [a, b] (n steps); returns (x, f(x)) of the best point seen
    (the two interior points; the ends are not evaluated). One f per step (single traced copy)."""
    dt = jnp.result_type(a)
    c, d = b - _GOLD * (b - a), a + _GOLD * (b - a)
    inf = jnp.asarray(jnp.inf, dt)

    def step(i, st):
        a, b, c, d, fc, fd, xb, fb = st
        left = fc <= fd                                   # the minimum lies in [a, d]
        a2, b2 = jnp.where(left, a, c), jnp.where(left, d, b)
        xg = jnp.where(left, b2 - _GOLD * (b2 - a2), a2 + _GOLD * (b2 - a2))
        x = jnp.where(i == 0, c, jnp.where(i == 1, d, xg))
        fx = f(x)
        fx_ = jnp.where(jnp.isnan(fx), -inf, fx)          # NaN (unreachable) is the worst
        better = fx_ < fb
        xb, fb = jnp.where(better, x, xb), jnp.where(better, fx_, fb)
        gs = i >= 2
        return (jnp.where(gs, a2, a), jnp.where(gs, b2, b),
                jnp.where(gs, jnp.where(left, x, d), c), jnp.where(gs, jnp.where(left, c, x), d),
                jnp.where(gs, jnp.where(left, fx_, fd), jnp.where(i == 0, fx_, fc)),
                jnp.where(gs, jnp.where(left, fc, fx_), jnp.where(i == 1, fx_, fd)), xb, fb)

    st = jax.lax.fori_loop(0, 2 + n, step, (a, b, c, d, inf, inf, a, inf))
    return st[6], st[7]


# -- the regular workspace by rays ------------------------------------------------------------------------------

def _first_bad(good_R: Callable, R_sets, phi, z, r_hi, n_along: int, n_levels: int):
    """First bad radius along each ray, for each good set j (a point is good for set j when ``good_R(R, p)`` holds
    at any R of ``R_sets[j]``): ``phi[j]``, ``z[j]``, ``r_hi[j]`` (N,) per set; returns a list of (N,). ``n_along``
    samples in [0, r_hi], then the first bad interval searched again with ``n_along`` samples, ``n_levels`` times
    in all (every level a dense search, so an island inside the interval is found too). The value is the last good
    sample before the first bad one (never over-stated by the search), ``r_hi`` when every sample is good and 0
    when the axis point is bad. Every (R, point) pair of every set goes through one vmapped call of ``good_R``."""
    dt = jnp.result_type(z[0])
    u = jnp.linspace(0.0, 1.0, n_along, dtype=dt)
    cs = [(jnp.cos(ph), jnp.sin(ph)) for ph in phi]
    sizes = [ph.shape[0] * n_along * Rj.shape[0] for ph, Rj in zip(phi, R_sets)]

    def level(i, st):
        rows = []
        for j, (lo, hi, _, _) in enumerate(st):
            s = lo[:, None] + u[None, :] * (hi - lo)[:, None]                          # (N, n_along)
            p = jnp.stack([s * cs[j][0][:, None], s * cs[j][1][:, None], jnp.broadcast_to(z[j][:, None], s.shape)],
                          axis=-1)
            nR = R_sets[j].shape[0]
            rows.append((jnp.broadcast_to(R_sets[j], s.shape + (nR,)).reshape(-1),
                         jnp.broadcast_to(p[:, :, None, :], s.shape + (nR, 3)).reshape(-1, 3)))
        Rf = jnp.concatenate([r for r, _ in rows])
        Pf = jnp.concatenate([p for _, p in rows])
        gf = jax.vmap(good_R)(Rf, Pf)                                                   # the one call
        out, k = [], 0
        for j, (lo, hi, done, axis_bad) in enumerate(st):
            g = jnp.any(gf[k:k + sizes[j]].reshape(lo.shape[0], n_along, -1), axis=2)   # (N, n_along)
            k += sizes[j]
            s = lo[:, None] + u[None, :] * (hi - lo)[:, None]
            jb = jnp.argmin(g, axis=1)
            all_good = jnp.all(g, axis=1)
            axis_bad = axis_bad | ((i == 0) & ~g[:, 0])
            take = lambda idx: jnp.take_along_axis(s, idx[:, None], axis=1)[:, 0]  # noqa: E731
            new_lo = jnp.where(all_good, hi, take(jnp.maximum(jb - 1, 0)))
            new_hi = jnp.where(all_good, hi, take(jb))
            out.append((jnp.where(done, lo, new_lo), jnp.where(done, hi, new_hi), done | all_good, axis_bad))
        return out

    init = [(jnp.zeros_like(zj), jnp.asarray(rh, dt) * jnp.ones_like(zj), jnp.zeros(zj.shape, bool),
             jnp.zeros(zj.shape, bool)) for zj, rh in zip(z, r_hi)]
    st = jax.lax.fori_loop(0, n_levels, level, init)
    return [jnp.where(axis_bad, 0.0, lo) for lo, _, _, axis_bad in st]


def _window_min(pz, pr, lo, hi):
    """The smallest radius of the profile over [lo, hi]: the samples inside and the profile linearly interpolated
    at both ends (samples ``pz``, ``pr``; empty slots have ``pr`` = inf); -1 when [lo, hi] leaves the sampled
    range. Between two samples the profile is taken as linear: where the smallest radius changes rays (a kink of
    a minimum over phi) that is below the true profile."""
    fin = jnp.isfinite(pr)
    inside = (pz >= lo) & (pz <= hi) & fin
    m = jnp.min(jnp.where(inside, pr, jnp.inf))

    def at(e):
        below, above = fin & (pz <= e), fin & (pz >= e)
        zb = jnp.max(jnp.where(below, pz, -jnp.inf))
        za = jnp.min(jnp.where(above, pz, jnp.inf))
        rb = jnp.min(jnp.where(below & (pz == zb), pr, jnp.inf))
        ra = jnp.min(jnp.where(above & (pz == za), pr, jnp.inf))
        w = jnp.where(za > zb, (e - zb) / jnp.where(za > zb, za - zb, 1.0), 0.0)
        return jnp.where(za > zb, rb + w * (ra - rb), jnp.minimum(ra, rb))

    ok = (lo >= jnp.min(jnp.where(fin, pz, jnp.inf))) & (hi <= jnp.max(jnp.where(fin, pz, -jnp.inf)))
    return jnp.where(ok, jnp.minimum(m, jnp.minimum(at(lo), at(hi))), -1.0)


def _diameter_at(pz, pr, c, hd_ratio, d_max, n_iter: int = 48):
    """Largest D with D <= 2 x :func:`_window_min` over [c - hd D / 2, c + hd D / 2] (the span shrinks with D, so
    the test is monotone: bisection)."""
    def body(_, lh):
        lo, hi = lh
        mid = 0.5 * (lo + hi)
        ok = 2.0 * _window_min(pz, pr, c - hd_ratio * mid / 2.0, c + hd_ratio * mid / 2.0) >= mid
        return jnp.where(ok, mid, lo), jnp.where(ok, hi, mid)

    lo, _ = jax.lax.fori_loop(0, n_iter, body, (jnp.zeros_like(c), jnp.asarray(d_max, c.dtype)))
    return lo


def _profile_cylinder(pz, pr, z_min, z_max, hd_ratio, d_max, n_c: int, n_golden: int = 24):
    """(centre, D) of the largest cylinder over the profile samples (pz, pr): ``n_c`` centres over [z_min, z_max],
    then a golden section around the best (no good test: cheap)."""
    dt = pz.dtype
    cs = jnp.linspace(z_min, z_max, n_c, dtype=dt)
    Ds = jax.vmap(lambda c: _diameter_at(pz, pr, c, hd_ratio, d_max))(cs)
    j = jnp.argmax(Ds)
    dcs = cs[1] - cs[0]
    c_g, negD = _golden_min(lambda c: -_diameter_at(pz, pr, c, hd_ratio, d_max), cs[j] - dcs, cs[j] + dcs, n_golden)
    better = -negD > Ds[j]
    return jnp.where(better, c_g, cs[j]), jnp.where(better, -negD, Ds[j])


def ray_cylinders(good_R: Callable, R_sets: Sequence, r_max: float, z_min: float, z_max: float, hd_ratio: float,
                  density: RayDensity = RAY_DENSITY, dtype=None) -> list:
    """The regular workspace from rays (module docstring) of each good set: a point is good for set j when
    ``good_R(R, p)`` (R scalar, p (3,) m, z down) holds at any R of ``R_sets[j]`` (an (n_j,) array: e.g. the
    design's R samples, R chosen per point; or the operating R alone). The largest cylinder on the z axis with
    height = ``hd_ratio`` x diameter inside [z_min, z_max] and radius <= ``r_max``. Pure, vmappable; returns one
    :class:`deltajax.constraints.RegularWorkspace` per set (zeros when nothing fits). The passes of
    :data:`RAY_PASSES` run in one loop, and every pass's rays of every set go through one call of ``good_R``.

    Each profile sample is a *level*: its z, the smallest first-bad radius of its rays, the phi of that ray and the
    phi span around it still unsearched. After the coarse pass, rays search [0, min(r_max, 0.65 D)] only (D: the
    cylinder so far; a radius beyond that cannot bind), so the same samples give a finer radius."""
    dt = jnp.result_type(float) if dtype is None else dtype
    n = density
    nz, nphi = n.n_z, n.n_phi
    m = len(R_sets)
    R_sets = [jnp.asarray(Rj, dt).reshape(-1) for Rj in R_sets]
    nzoom = RAY_PASSES.count("zoom_z")
    kinds, sub, seen = [], [], {}
    for k in RAY_PASSES:
        kinds.append(("coarse", "zoom_z", "zoom_phi", "check").index(k))
        base = "zoom_z" if k == "zoom_phi" else k
        sub.append(seen.get(base + k, 0) % max(nzoom, 1))
        seen[base + k] = seen.get(base + k, 0) + 1
    T = nz * (1 + nzoom)                       # the coarse levels, then each zoom_z pass's
    wedge = math.pi / 3.0
    d_max = 2.0 * r_max
    phi0 = jnp.linspace(0.0, wedge, nphi, dtype=dt)
    phi_mid = (jnp.arange(nphi, dtype=dt) + 0.5) / nphi * wedge       # the check's rays: between the grid's
    dphi0 = wedge / (nphi - 1)
    zg = jnp.linspace(z_min, z_max, nz, dtype=dt)
    dz0 = (z_max - z_min) / (nz - 1)
    ui = jnp.linspace(-1.0, 1.0, nphi, dtype=dt)
    jz = jnp.arange(nz)
    n_c = 4 * nz
    inf = jnp.asarray(jnp.inf, dt)
    kind_of, sub_of = jnp.asarray(kinds), jnp.asarray(sub)

    def layout(i, st):
        """Pass i's rays of one set: z (nz, nphi), phi (nz, nphi), r_hi (), the level slots it writes (nz,), the
        phi half-width of its rays (nz,) and the zoomed range (lo, hi)."""
        c, D = st["c"], st["D"]
        top, bot = c - hd_ratio * D / 2.0, c + hd_ratio * D / 2.0
        kind, k = kind_of[i], sub_of[i]
        # zoom_z: the range is fixed by the first zoom_z pass (over the cylinder so far and 1.5 coarse spacings
        # beyond each end); pass k takes every nzoom-th of nzoom x nz uniform levels from offset k
        first = (kind == 1) & (k == 0)
        lo = jnp.where(first, jnp.maximum(top - 1.5 * dz0, z_min), st["lo"])
        hi = jnp.where(first, jnp.minimum(bot + 1.5 * dz0, z_max), st["hi"])
        zz = lo + (nzoom * jz + k) * (hi - lo) / (nzoom * nz - 1)
        slots = jnp.where(kind == 0, jz, (1 + k) * nz + jz)
        z_ck = jnp.linspace(top, bot, nz)                                # check: top disc to bottom disc
        zs = jnp.select([kind == 0, kind == 1, kind == 2], [zg, zz, st["z"][slots]], z_ck)
        width = jnp.where(kind == 2, st["span"][slots], 0.0)
        ps = jnp.select([kind <= 1, kind == 3], [jnp.broadcast_to(phi0, (nz, nphi)),
                                                  jnp.broadcast_to(phi_mid, (nz, nphi))],
                        jnp.clip(st["phi"][slots][:, None] + width[:, None] * ui[None, :], 0.0, wedge))
        r_hi = jnp.where(kind == 3, D / 2.0, jnp.where((kind == 0) | (D <= 0), r_max, jnp.minimum(r_max, 0.65 * D)))
        return jnp.broadcast_to(zs[:, None], (nz, nphi)), ps, r_hi, slots, width, lo, hi

    def update(i, st, zs, ps, slots, width, lo, hi, rho):
        """One set's state after pass i gave the radii ``rho`` (nz, nphi) of its rays."""
        kind = kind_of[i]
        row_r = jnp.min(rho, axis=1)
        row_phi = ps[jz, jnp.argmin(rho, axis=1)]
        add, zoom, chk = kind <= 1, kind == 2, kind == 3
        old_r = st["r"][slots]
        better = row_r < old_r
        z = st["z"].at[slots].set(jnp.where(add, zs[:, 0], st["z"][slots]))
        r = st["r"].at[slots].set(jnp.where(add, row_r, jnp.where(zoom, jnp.minimum(row_r, old_r), old_r)))
        phi = st["phi"].at[slots].set(jnp.where(add | (zoom & better), row_phi, st["phi"][slots]))
        span = st["span"].at[slots].set(jnp.where(add, dphi0, jnp.where(zoom, 2.0 * width / (nphi - 1),
                                                                        st["span"][slots])))
        c_new, D_new = _profile_cylinder(z, r, z_min, z_max, hd_ratio, d_max, n_c)
        return dict(z=z, r=r, phi=phi, span=span, c=jnp.where(chk, st["c"], c_new), D=jnp.where(chk, st["D"], D_new),
                    check=jnp.where(chk, jnp.min(row_r), st["check"]), lo=lo, hi=hi)

    def one_pass(i, sts):
        lay = [layout(i, st) for st in sts]
        radii = _first_bad(good_R, R_sets, [a[1].reshape(-1) for a in lay], [a[0].reshape(-1) for a in lay],
                           [jnp.broadcast_to(a[2], (nz * nphi,)) for a in lay], n.n_along, n.n_levels)
        return [update(i, st, *a[:2], *a[3:], r.reshape(nz, nphi)) for st, a, r in zip(sts, lay, radii)]

    st0 = dict(z=jnp.full((T,), inf), r=jnp.full((T,), inf), phi=jnp.zeros((T,), dt), span=jnp.full((T,), dphi0, dt),
               c=jnp.asarray(0.5 * (z_min + z_max), dt), D=jnp.zeros((), dt), check=inf,
               lo=jnp.asarray(z_min, dt), hi=jnp.asarray(z_max, dt))
    sts = jax.lax.fori_loop(0, len(RAY_PASSES), one_pass, [dict(st0) for _ in range(m)])
    out = []
    for st in sts:
        D = jnp.maximum(jnp.minimum(st["D"], 2.0 * st["check"]), 0.0)
        H = hd_ratio * D
        out.append(RegularWorkspace(volume=math.pi / 4.0 * D * D * H, diameter=D, height=H, z_top=st["c"] - H / 2.0))
    return out


def ray_cylinder(good_fn: Callable, r_max: float, z_min: float, z_max: float, hd_ratio: float,
                 density: RayDensity = RAY_DENSITY, dtype=None) -> RegularWorkspace:
    """:func:`ray_cylinders` of one good set given as ``good_fn(p) -> bool`` (p (3,), m, z down)."""
    dt = jnp.result_type(float) if dtype is None else dtype
    return ray_cylinders(lambda R, p: good_fn(p), [jnp.zeros((1,), dt)], r_max, z_min, z_max, hd_ratio, density,
                         dt)[0]


# -- worst points of a task cylinder ------------------------------------------------------------------------------

def worst_in_cylinder(f: Callable, diameter: float, height: float, z_top: float, n_r: int, n_phi: int, n_z: int,
                      *, n_golden: int = 10, n_start: int = 2, sweeps: int = 2):
    """Minimum of the field ``f(p)`` (a scalar or an (m,) vector of fields, each minimised on its own; NaN:
    unreachable, the worst) over the cylinder of ``diameter`` and ``height`` on the z axis from ``z_top`` (z down),
    using the 60 deg wedge (the Delta's symmetry): samples rho in [0, D/2] (``n_r``) x phi in [0, 60 deg]
    (``n_phi``) x z (``n_z``), then from the ``n_start`` worst samples of each field a coordinate-wise golden
    section (``sweeps`` sweeps over rho, phi, z, each in +-1 sample spacing, clipped to the cylinder). Returns
    (minimum, point (3,)), each with a leading (m,) axis for a vector field. Two call sites of ``f`` (the samples
    and the search), so it is traced twice."""
    rr = jnp.linspace(0.0, diameter / 2.0, n_r)
    pp = jnp.linspace(0.0, math.pi / 3.0, n_phi)
    zz = jnp.linspace(z_top, z_top + height, n_z)
    Z, Rr, P = jnp.meshgrid(zz, rr, pp, indexing="ij")
    q = jnp.stack([Rr.reshape(-1), P.reshape(-1), Z.reshape(-1)], axis=1)     # (rho, phi, z)

    def at(x):
        return jnp.stack([x[0] * jnp.cos(x[1]), x[0] * jnp.sin(x[1]), x[2]])

    def fv(p):
        return jnp.atleast_1d(f(p))

    V = jax.vmap(lambda x: fv(at(x)))(q)                                      # (n, m)
    V = jnp.where(jnp.isnan(V), -jnp.inf, V)
    lo = jnp.asarray([0.0, 0.0, z_top])
    hi = jnp.asarray([diameter / 2.0, math.pi / 3.0, z_top + height])
    step = jnp.asarray([diameter / 2.0 / max(n_r - 1, 1), math.pi / 3.0 / max(n_phi - 1, 1),
                        height / max(n_z - 1, 1)])
    ns = min(n_start, q.shape[0])

    def field(v, c):
        _, idx = jax.lax.top_k(-v, ns)

        def search(x0, f0):
            def coord(i, st):
                x, fx = st
                d = i % 3
                a = jnp.clip(x[d] - step[d], lo[d], hi[d])
                b = jnp.clip(x[d] + step[d], lo[d], hi[d])
                t, ft = _golden_min(lambda t: fv(at(x.at[d].set(t)))[c], a, b, n_golden)
                better = ft < fx
                return jnp.where(better, x.at[d].set(t), x), jnp.where(better, ft, fx)

            return jax.lax.fori_loop(0, 3 * sweeps, coord, (x0, f0))

        xs, fs = jax.vmap(search)(q[idx], v[idx])
        j = jnp.argmin(fs)
        best = jnp.minimum(fs[j], jnp.min(v))
        return jnp.where(jnp.isinf(best) & (best < 0), jnp.nan, best), at(xs[j])

    best, pts = jax.vmap(field, in_axes=(1, 0))(V, jnp.arange(V.shape[1]))
    scalar = jnp.ndim(jax.eval_shape(f, jnp.zeros(3, q.dtype))) == 0
    return (best[0], pts[0]) if scalar else (best, pts)


# -- one design, certified ------------------------------------------------------------------------------------------

def cycle_at(pb, n_samples: int):
    """The problem's cycle resampled with ``n_samples`` (same path, law and duration)."""
    from ..trajectory import adept_cycle

    cyc = pb.settings["cycle"]
    return adept_cycle(pb.settings["cycle_centre"], duration=float(cyc["duration"]), n_samples=int(n_samples),
                       law=str(cyc["law"]))


def _certified_once(pb, design, R_op, density: RayDensity, task_n, cycle_n: int):
    """Every certified figure at one density (traced; ``R_op``: the operating R)."""
    from .. import constraints as C
    from ..geometry import ReconfigurableDelta

    recon = isinstance(design, ReconfigurableDelta)
    robot0 = design.robot if recon else design
    dt = robot0.upper_arm.dtype
    if recon:
        plate = design.R_max + pb.links.plate_overhang
        at, Rs = design.at, design.R_samples()
    else:
        plate = robot0.base_radius + pb.links.plate_overhang
        at, Rs = robot0.with_base_radius, robot0.base_radius[None]

    def chk(R, p):
        return C.good_point(at(R), p, pb.good, plate_radius=plate)

    reg_s = pb.settings["regular"]
    sets = [Rs, jnp.asarray(R_op, dt)[None]] if recon else [Rs]
    cyl = ray_cylinders(lambda R, p: chk(R, p).good, sets, float(reg_s["r_max"]), float(reg_s["z_min"]),
                        float(reg_s["z_max"]), pb.hd_ratio, density, dt)
    reg, regf = cyl[0], cyl[-1]
    t = pb.settings["task"]
    task = (float(t["diameter"]), float(t["height"]), float(t["z_top"])) + tuple(task_n)
    worst, _ = worst_in_cylinder(lambda p: jnp.stack([(c := chk(R_op, p)).index, c.joint_margin,
                                                      c.interference_margin]), *task)
    idx, jm_t, im_t = worst[0], worst[1], worst[2]
    cyc = cycle_at(pb, cycle_n)
    cc = jax.vmap(lambda p: chk(R_op, p))(cyc.x.astype(dt))

    def nanmin(a):
        return jnp.where(jnp.any(jnp.isnan(a)), jnp.nan, jnp.min(a))

    rate = C.cycle_rate(at(R_op), cyc, pb.motor, robot0.mass.gear_ratio, dwell=pb.dwell, payload_mass=pb.payload)
    return {"regular_volume": reg.volume, "regular_diameter": reg.diameter, "regular_height": reg.height,
            "regular_z_top": reg.z_top, "regular_volume_fixed": regf.volume, "regular_diameter_fixed": regf.diameter,
            "task_index_min": idx,
            "joint_margin_deg": jnp.rad2deg(jnp.minimum(jm_t, nanmin(cc.joint_margin))),
            "interference_margin": jnp.minimum(im_t, nanmin(cc.interference_margin)),
            "picks_per_min": rate.picks_per_min, "cycle_time": rate.cycle_time,
            "peak_utilisation": rate.loads.peak_utilisation, "rms_utilisation": rate.loads.rms_utilisation,
            "speed_utilisation": rate.loads.speed_utilisation}


def _densities(pb, density, task_samples, cycle_samples):
    """The verification's densities (rays, task samples, cycle samples) of ``pb`` where not given."""
    if density is None:
        density = RAY_DENSITY if pb.rw_rays is None else RayDensity(*pb.rw_rays)
    if task_samples is None:
        t = pb.settings["task"]
        task_samples = (int(t["n_r"]) + 1, 2 * int(t["n_phi"]) - 1, int(t["n_z"]) + 2)
    if cycle_samples is None:    # the peak converges as the square of the spacing: 8x the verification's
        cycle_samples = 8 * (int(pb.cycle.n_samples) - 1) + 1
    return RayDensity(*density), tuple(int(n) for n in task_samples), int(cycle_samples)


def certified_program(pb, density: RayDensity, task_samples: tuple, cycle_samples: int) -> Callable:
    """``(design, R_operating) -> {figure: ()}`` at one density, jitted, one program per (content of ``pb``,
    densities) in this process (:func:`deltajax.optimize.programs.shared_program`): the baseline and the
    recommendation (and any design re-derived later) share one compilation."""
    from .programs import shared_program

    key = (tuple(density), tuple(task_samples), int(cycle_samples))

    def build():
        return jax.jit(lambda d, R: _certified_once(pb, d, R, RayDensity(*key[0]), key[1], key[2]))

    return shared_program("certified", pb, None, key, build, persist=True)


def certify_design(pb, design, R_operating=None, *, density=None, task_samples=None,
                   cycle_samples=None, reference: Mapping[str, float] = None) -> dict:
    """Certified figures of one design (a :class:`deltajax.Delta` or :class:`deltajax.ReconfigurableDelta`) on
    the designer's problem ``pb`` (:class:`deltajax.optimize.designer.DesignerProblem`) at its operating R
    (``R_operating``; None: the one :func:`deltajax.optimize.designer.evaluate_designer` chooses): every figure
    evaluated at a density and at twice it (rays: ``density``, default the problem's ``rw_rays`` or
    :data:`RAY_DENSITY`; task cylinder samples (rings, angles, levels): ``task_samples``, default one ring, angles
    doubled and two levels more than the problem's task grid; cycle samples: ``cycle_samples``, default eight times
    the problem's: the peak of a sampled torque converges as the square of the spacing). The returned figures are
    the denser ones, ``<name>_first`` the first density's, ``<name>_change`` the change doubling made (relative for
    the volume, in the figure's units otherwise), ``<name>_tolerance`` and ``converged`` (every change within
    :data:`TOLERANCES`). The cycle is evaluated at its fastest feasible duration at each density. ``reference``:
    the figures already evaluated at the first density (e.g. by an earlier call): then only the doubled
    evaluation runs. Host function (numpy floats); jitted inside."""
    dt = (design.robot if hasattr(design, "robot") else design).upper_arm.dtype
    if R_operating is None:
        from .designer import evaluate_designer
        R_operating = jax.jit(lambda d: evaluate_designer(pb, d, regular=False)["R_operating"])(design)
    R_op = jnp.asarray(R_operating, dt)
    d1, t1, c1 = _densities(pb, density, task_samples, cycle_samples)
    a = (dict(reference) if reference is not None
         else {k: float(v) for k, v in certified_program(pb, d1, t1, c1)(design, R_op).items()})
    b = certified_program(pb, d1.doubled(), tuple(2 * n - 1 for n in t1), 2 * c1 - 1)(design, R_op)
    out = {k: float(v) for k, v in b.items()}
    out.update({f"{k}_first": float(a[k]) for k in TOLERANCES})
    ok = True
    for k, tol in TOLERANCES.items():
        x, y = float(a[k]), float(b[k])
        ch = abs(y / x - 1.0) if k == "regular_volume" and x > 0 else abs(y - x)
        out[f"{k}_change"] = ch
        out[f"{k}_tolerance"] = tol
        ok = ok and bool(ch <= tol)
    out["converged"] = ok
    out["R_operating"] = float(R_op)
    return out


# -- margins ---------------------------------------------------------------------------------------------------

#: Units of :func:`design_margins`' entries.
MARGIN_UNITS = {"task_index_margin": "1", "joint_margin_deg": "deg", "interference_clearance_mm": "mm",
                "peak_headroom": "1", "rms_headroom": "1", "speed_headroom": "1", "picks_over_min": "1/min",
                "size_budget_margin_mm": "mm", "regular_volume_over_floor": "m^3"}


def design_margins(m: Mapping[str, np.ndarray], *, threshold: float, min_picks: float, max_arm_sum,
                   volume_floor=None) -> dict:
    """Every constraint's margin in units (positive: met by that much) from metrics ``m`` (any batch shape):
    task index margin = worst index - threshold; joint margin (deg, the smaller of both joints' cone margins
    over the task and the cycle); interference clearance (mm, beyond the required clearance); peak, RMS and
    speed headroom 1 - utilisation; picks/min over the required rate; size budget margin (mm, max L1 + L2 -
    (L1 + L2); NaN without a budget); regular volume over the floor rule's floor (m^3; NaN without a floor: the
    rule's threshold, not a constraint)."""
    f = lambda k: np.asarray(m[k], float)  # noqa: E731
    return {"task_index_margin": f("task_index_min") - threshold,
            "joint_margin_deg": f("joint_margin_deg"),
            "interference_clearance_mm": 1e3 * f("interference_margin"),
            "peak_headroom": 1.0 - f("peak_utilisation"), "rms_headroom": 1.0 - f("rms_utilisation"),
            "speed_headroom": 1.0 - f("speed_utilisation"), "picks_over_min": f("picks_per_min") - min_picks,
            "size_budget_margin_mm": (1e3 * (max_arm_sum - f("arm_sum")) if max_arm_sum is not None
                                      else np.full_like(f("arm_sum"), np.nan)),
            "regular_volume_over_floor": (f("regular_volume") - volume_floor if volume_floor is not None
                                          else np.full_like(f("regular_volume"), np.nan))}


# -- an independent check: a dense point grid and every window of levels ---------------------------------------------

def grid_cylinder_bounds(good: np.ndarray, r: np.ndarray, z: np.ndarray, hd_ratio: float) -> dict:
    """Brute-force bounds on the regular workspace from good flags on a dense polar grid (a method independent
    of :func:`ray_cylinders`: no rays, no bisection, no local search): ``good`` (n_z, n_r, n_phi) on rings ``r``
    (r[0] = 0), levels ``z`` (uniform) and angles over the wedge. Per level, the last good ring before the first
    bad one (lower) and the first bad ring (upper, r_max + dr when none); every window of levels [a, b] scanned:
    lower volume with height z_b - z_a and the lower radii, upper volume with height z_(b+1) - z_(a-1) and the
    upper radii, and a mid estimate (midpoints). Returns volumes (m^3) ``lower``, ``mid``, ``upper``."""
    good = np.asarray(good, bool)
    nz, nr, _ = good.shape
    dr, dz = r[1] - r[0], z[1] - z[0]
    prefix = np.cumprod(good, axis=1).astype(bool)                     # rings 0..j all good, per angle
    n_good = prefix.sum(axis=1)                                         # (nz, nphi) good rings from the axis
    last = np.where(n_good > 0, r[np.maximum(n_good - 1, 0)], -1.0)     # radius of the last good ring
    first_bad = np.where(n_good < nr, r[np.minimum(n_good, nr - 1)], r[-1] + dr)
    lo_k = np.min(last, axis=1)
    hi_k = np.where(np.min(n_good, axis=1) > 0, np.min(first_bad, axis=1), 0.0)
    out = {}
    for name, rad, extra in (("lower", lo_k, 0.0), ("mid", 0.5 * (lo_k + np.maximum(hi_k, 0.0)), 1.0),
                             ("upper", hi_k, 2.0)):
        best = 0.0
        for a in range(nz):
            mm = np.inf
            for b in range(a, nz):
                mm = min(mm, rad[b])
                if mm <= 0:
                    break
                H = z[b] - z[a] + extra * dz
                D = min(2.0 * mm, H / hd_ratio)
                best = max(best, math.pi / 4.0 * D * D * hd_ratio * D)
        out[name] = best
    return out


# -- the certified figures in place of the verified ones ---------------------------------------------------------------

#: Certified metrics of the cycle run at the operating R: with ``experiment.reconfig.mode=path`` (R(t) along the
#: cycle) they certify the fixed-R variant (``<metric>_fixed``), not the path's figures.
CYCLE_METRICS = ("picks_per_min", "cycle_time", "peak_utilisation", "rms_utilisation", "speed_utilisation",
                 "joint_margin_deg", "interference_margin")

#: Metrics :func:`certify_design` returns that replace the verification's values of a certified design.
CERTIFIED_METRICS = ("regular_volume", "regular_diameter", "regular_height", "regular_z_top", "regular_volume_fixed",
                     "regular_diameter_fixed", "task_index_min", "joint_margin_deg", "interference_margin",
                     "picks_per_min", "cycle_time", "peak_utilisation", "rms_utilisation", "speed_utilisation")


def feasible_certified(m: Mapping[str, np.ndarray], pb) -> np.ndarray:
    """Every enabled constraint met by the metrics ``m`` (certified figures: the worst index instead of the good
    fraction; NaN: not met), up to :data:`deltajax.optimize.designer.FEASIBILITY_TOL`."""
    from .designer import FEASIBILITY_TOL

    ok = np.ones(np.shape(m["picks_per_min"]), bool)
    en = set(pb.enabled)
    with np.errstate(invalid="ignore"):
        if "task_in_good_workspace" in en:
            ok &= (m["task_index_min"] >= pb.good.threshold - FEASIBILITY_TOL)
        if "task_in_good_workspace" in en or "passive_joints" in en:
            ok &= m["joint_margin_deg"] >= -FEASIBILITY_TOL
        if "task_in_good_workspace" in en or "interference" in en:
            ok &= m["interference_margin"] >= -FEASIBILITY_TOL
        ok &= np.isfinite(m["picks_per_min"]) & (m["picks_per_min"] > 0)
        ok &= m["picks_per_min"] >= pb.min_picks - FEASIBILITY_TOL
        if pb.max_arm_sum is not None:
            ok &= m["arm_sum"] <= pb.max_arm_sum * (1.0 + FEASIBILITY_TOL)
    return ok


def overlay(data: Mapping) -> dict:
    """The ``verify`` group of a loaded results file with the certified designs' figures (group ``certify``) in
    place of the verified ones, ``feasible`` and ``front`` as certified, ``F`` recomputed (normalised by the
    certified baseline) and ``margins`` (``{name: ((n,), units)}``); the ``verify`` group itself when there is no
    ``certify`` group. The recommendation (attribute ``recommended``) is the one the certify stage wrote into
    ``verify`` (and a robust tolerance stage after it)."""
    V = data.get("verify")
    Cg = data.get("certify")
    if V is None or not Cg or "row" not in Cg:
        return V
    out = dict(V)
    rows = np.asarray(Cg["row"], int).reshape(-1)
    path = Cg.get("attrs", {}).get("cycle_variant") == "fixed_R"     # mode=path: the cycle figures are the fixed R's
    for k in CERTIFIED_METRICS + ("feasible",):
        if path and k in CYCLE_METRICS and f"{k}_fixed" in V:
            b = np.array(V[f"{k}_fixed"], dtype=float, copy=True).reshape(-1)
            b[rows] = np.asarray(Cg[k], float).reshape(-1)
            out[f"{k}_fixed"] = b
            continue
        if k in V and k in Cg:
            a = np.array(V[k], dtype=float, copy=True).reshape(-1)
            kf = f"{k}_fixed"       # the fixed-R variant's cycle figures: the same where R does not move (per_task)
            if kf in V and kf not in CERTIFIED_METRICS and np.array_equal(
                    np.asarray(V[kf], float).reshape(-1)[rows], a[rows], equal_nan=True):
                b = np.array(V[kf], dtype=float, copy=True).reshape(-1)
                b[rows] = np.asarray(Cg[k], float).reshape(-1)
                out[kf] = b
            a[rows] = np.asarray(Cg[k], float).reshape(-1)
            out[k] = a
    if "feasible" in Cg:
        out["feasible"] = out["feasible"].astype(np.uint8)
    if "front" in Cg:
        out["front"] = np.asarray(Cg["front"], int)
    if "F" in Cg:
        out["F"] = np.asarray(Cg["F"], float)
    out["margins"] = {k: (np.asarray(Cg[f"margin_{k}"], float).reshape(-1), u) for k, u in MARGIN_UNITS.items()
                      if f"margin_{k}" in Cg}
    return out
