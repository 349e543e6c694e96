"""The regular workspace: the largest cylinder on the z axis, with a given height/diameter ratio, inside a set of
good points, on a polar sample grid (:func:`regular_workspace`, :func:`largest_cylinder`) and refined to
a continuous measure (:func:`refine_cylinder`: golden-section search of the centre height around the grid's answer,
bisection on the diameter with the good test on a fixed set of samples scaled with the cylinder), so that the value
moves continuously with the design instead of stepping between the grid's levels and rings.

Pure geometry over a good-point predicate: what "good" means (reachable, index, passive joints, interference) is
:func:`deltajax.constraints.good_point`, which re-exports these names as the designer's constraints.
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

__all__ = ["polar_grid", "RegularWorkspace", "largest_cylinder", "regular_workspace", "cylinder_samples",
           "refine_cylinder", "REFINE_SAMPLES", "REFINE_BISECT", "REFINE_GOLDEN"]


def polar_grid(r_max: float, z_min: float, z_max: float, n_r: int, n_phi: int, n_z: int):
    """Samples for :func:`regular_workspace`: rings r_j = r_max j / (n_r - 1) (j = 0: the axis) x angles
    phi in [0, 60 deg] (both ends; the three-fold + mirror symmetry makes this wedge enough) x levels
    z_k = z_min .. z_max. Returns (points (n_z, n_r, n_phi, 3), r (n_r,), z (n_z,))."""
    r = np.linspace(0.0, r_max, n_r)
    phi = np.linspace(0.0, math.pi / 3, n_phi)
    z = np.linspace(z_min, z_max, n_z)
    Z, Rr, P = np.meshgrid(z, r, phi, indexing="ij")
    pts = np.stack([Rr * np.cos(P), Rr * np.sin(P), Z], axis=-1)
    return pts, r, z


class RegularWorkspace(NamedTuple):
    """Largest axis-centred cylinder with the given H/D inside the good set: volume (m^3), diameter (m),
    height (m), z_top (m, z down; the cylinder spans [z_top, z_top + height])."""

    volume: Float[Array, ""]
    diameter: Float[Array, ""]
    height: Float[Array, ""]
    z_top: Float[Array, ""]


def largest_cylinder(good: Bool[Array, "nz nr"], r: Float[Array, "nr"], z: Float[Array, "nz"],
                     hd_ratio: float) -> RegularWorkspace:
    """Largest cylinder on the z axis, height = hd_ratio x diameter, whose sampled levels and rings are all good.

    ``good[k, j]``: every sample of ring j at level z_k is good (ring 0 is the axis point). A disc of radius
    r_j at level k is good if rings 0..j are; a cylinder over levels a..b (uniform spacing) has height
    z_b - z_a and radius <= the smallest good disc radius over those levels; with D <= 2 r and
    hd_ratio D <= z_b - z_a the largest volume is pi D^2 / 4 x hd_ratio D. Zero when nothing fits.
    """
    good = jnp.asarray(good)
    r = jnp.asarray(r)
    z = jnp.asarray(z)
    nz, nr = good.shape
    prefix = jnp.cumprod(good.astype(jnp.int32), axis=1).astype(bool)    # rings 0..j all good
    r_disc = jnp.max(jnp.where(prefix, r[None, :], -1.0), axis=1)          # (nz,) -1: axis not good
    ia = jnp.arange(nz)
    inside = (ia[None, None, :] >= ia[:, None, None]) & (ia[None, None, :] <= ia[None, :, None])  # [a, b, k]
    r_win = jnp.min(jnp.where(inside, r_disc[None, None, :], jnp.inf), axis=2)                    # (nz, nz)
    H = z[None, :] - z[:, None]
    valid = (ia[None, :] >= ia[:, None]) & (r_win >= 0)
    D = jnp.minimum(2.0 * jnp.maximum(r_win, 0.0), H / hd_ratio)
    D = jnp.where(valid, D, 0.0)
    vol = math.pi / 4.0 * D * D * hd_ratio * D
    k = jnp.argmax(vol.reshape(-1))
    a, b = k // nz, k % nz
    Db = D.reshape(-1)[k]
    del b
    return RegularWorkspace(volume=vol.reshape(-1)[k], diameter=Db, height=hd_ratio * Db, z_top=z[a])


def regular_workspace(good_fn: Callable[[Array], Array], points, r, z, hd_ratio: float, *,
                      refine: bool = False) -> RegularWorkspace:
    """Regular workspace from a per-point good test ``good_fn(p) -> bool`` on a :func:`polar_grid`.

    ``good_fn`` is e.g. ``lambda p: good_point(robot, p, spec).good`` (R frozen) or, for a reconfigurable
    design with R chosen per point, the ``any`` over its R samples. ``refine=True``: the grid's answer refined to
    the continuous measure of :func:`refine_cylinder`.
    """
    pts = jnp.asarray(points)
    nz, nr, nphi, _ = pts.shape
    g = jax.vmap(good_fn)(pts.reshape(-1, 3)).reshape(nz, nr, nphi)
    out = largest_cylinder(jnp.all(g, axis=2), r, z, hd_ratio)
    return refine_cylinder(good_fn, out, r, z, hd_ratio) if refine else out


#: Samples of the unit cylinder used by :func:`refine_cylinder` (rings, angles over the 60 deg wedge, levels).
REFINE_SAMPLES = (4, 3, 5)
#: Bisection steps on the diameter and golden-section steps on the centre height of :func:`refine_cylinder`.
REFINE_BISECT, REFINE_GOLDEN = 12, 14


def cylinder_samples(hd_ratio: float, n_r: int = REFINE_SAMPLES[0], n_phi: int = REFINE_SAMPLES[1],
                     n_z: int = REFINE_SAMPLES[2]) -> np.ndarray:
    """Samples of the cylinder of diameter 1 and height ``hd_ratio`` centred at the origin: rings
    rho = 0.5 j / (n_r - 1) (j = 0: the axis) x angles in [0, 60 deg] (the Delta's three-fold + mirror symmetry,
    as :func:`polar_grid`) x levels u in [-hd_ratio/2, hd_ratio/2] (both end discs). (n, 3); a cylinder of
    diameter D centred at c has the samples c + D x these (so they move continuously with D and c)."""
    rho = np.linspace(0.0, 0.5, n_r)
    phi = np.linspace(0.0, math.pi / 3, n_phi)
    u = np.linspace(-hd_ratio / 2.0, hd_ratio / 2.0, n_z)
    U, Rr, P = np.meshgrid(u, rho, phi, indexing="ij")
    return np.stack([Rr * np.cos(P), Rr * np.sin(P), U], axis=-1).reshape(-1, 3)


def _distinct_offsets(unit, dt):
    """The samples of :func:`refine_cylinder` other than the centre, each point once: a concrete ``unit`` loses its
    exact repeats and its zero offsets (the axis ring repeats one point per angle, and the axis point of the middle
    level is the centre, which :func:`refine_cylinder` tests on its own). A repeated point gives the same answer of
    the pure good test, so the cylinder's test (all samples good) is unchanged and costs fewer good tests
    (3 x 2 x 3 samples: 15 distinct points instead of 18 plus the centre). A traced ``unit`` is used as given."""
    try:
        u = np.asarray(unit, dtype=np.dtype(dt))
    except Exception:   # traced: no repeats removed (a repeated point is only extra work)
        return jnp.asarray(unit, dt)
    keep, seen = [], set()
    for i, row in enumerate(u.reshape(-1, 3)):
        key = tuple(float(x) + 0.0 for x in row)   # + 0.0: -0.0 and 0.0 are one point
        if key in seen or key == (0.0, 0.0, 0.0):
            continue
        seen.add(key)
        keep.append(i)
    return jnp.asarray(u.reshape(-1, 3)[keep], dt)


def refine_cylinder(good_fn: Callable[[Array], Array], start: RegularWorkspace, r, z, hd_ratio: float, *,
                    unit=None, n_bisect: int = REFINE_BISECT, n_golden: int = REFINE_GOLDEN,
                    all_good: Optional[Callable[[Array], Array]] = None) -> RegularWorkspace:
    """Continuous regular-workspace measure, started from the grid's answer ``start`` (:func:`largest_cylinder`
    on the grid ``r``, ``z``).

    A cylinder of diameter D (height ``hd_ratio`` D) centred on the axis at height c is *good* when
    ``good_fn`` holds at every sample of :func:`cylinder_samples` scaled by D and moved to c (``unit``: other
    samples, (n, 3) for D = 1). D*(c), the largest good D at c, is found by bisection on D in [0, D_hi] with
    D_hi = D_grid + 2 (2 dr + dz / hd_ratio) (dr, dz: the grid's ring and level spacing): ``n_bisect`` steps,
    error <= D_hi / 2^n_bisect, from below (0 when the centre itself is not good). The centre c maximising D*(c)
    is searched by golden section on [c_grid - 2 dz, c_grid + 2 dz] (``n_golden`` steps, final bracket
    4 dz x 0.618^n_golden = 0.07 mm on the fine verification grid; the best of the last two centres and the
    grid's own centre is kept). With the defaults (12 / 14) on the fine verification grid (dz = 15 mm,
    dr = 12.9 mm, D ~ 0.4 m, hd_ratio 0.5: D_hi ~ 0.5 m): D error <= D_hi / 4096 ~ 0.12 mm from the bisection,
    and a centre within 0.07 mm of the bracket's optimum costs at most 2 x 0.07 mm / hd_ratio = 0.3 mm in D where
    the height binds: in all, <= ~0.1 % in D, <= ~0.3 % in volume. The samples (4 rings x 3 angles 0/30/60 deg x
    5 levels by default) are
    what is checked: like any sampled test, a bad region thinner than the sample spacing can slip between them.
    Each distinct sample is tested once per step (the axis ring's repeats dropped: ``_distinct_offsets``; without
    ``all_good`` the centre once per centre), which changes the cost, not the answer.
    ``all_good(points (n, 3)) -> bool``: the same answer as ``all(good_fn(p) for p in points)``, computed
    another way (e.g. stopping at the first bad point: :func:`deltajax.optimize.designer.evaluate_designer`);
    it is then the only test called: the centre joins every step's samples, so a compiled program holds one copy
    of the good test (the centre's own call was a second one).
    Every step is a continuous function of the good set's boundary, so the measure moves continuously with
    the design (the grid's answer only places the brackets). Pure, vmappable; returns a
    :class:`RegularWorkspace`.
    """
    r = jnp.asarray(r)
    z = jnp.asarray(z)
    dt = z.dtype
    unit = _distinct_offsets(cylinder_samples(hd_ratio) if unit is None else unit, dt)
    dr = (r[-1] - r[0]) / max(r.shape[0] - 1, 1)
    dz = (z[-1] - z[0]) / max(z.shape[0] - 1, 1)
    d_hi = start.diameter + 2.0 * (2.0 * dr + dz / hd_ratio)
    c0 = start.z_top + start.height / 2.0

    test_all = all_good if all_good is not None else (lambda P: jnp.all(jax.vmap(good_fn)(P)))

    def d_at(c):
        centre = jnp.stack([jnp.zeros((), dt), jnp.zeros((), dt), c])
        if all_good is None:
            # the centre itself (offset 0, the same point at every D) tested once per centre, not at every step:
            # D = 0 when it is not good
            centre_ok = good_fn(centre)
            samples = lambda mid: centre[None, :] + mid * unit  # noqa: E731
        else:
            # with ``all_good`` the centre joins every step's samples (the same answer: all of them good, or D = 0
            # when the centre is not): one call of ``all_good`` at one shape, so the program holds one copy of the
            # good test, not a second one for the centre
            centre_ok = True
            samples = lambda mid: jnp.concatenate([centre[None, :], centre[None, :] + mid * unit])  # noqa: E731

        def body(_, lh):
            lo, hi = lh
            mid = 0.5 * (lo + hi)
            ok = centre_ok & test_all(samples(mid))
            return jnp.where(ok, mid, lo), jnp.where(ok, hi, mid)

        lo, _ = jax.lax.fori_loop(0, n_bisect, body, (0.0 * d_hi, d_hi))
        return lo

    g = (math.sqrt(5.0) - 1.0) / 2.0
    a, b = c0 - 2.0 * dz, c0 + 2.0 * dz
    c, d = b - g * (b - a), a + g * (b - a)
    nan = c0 * jnp.nan

    # one loop, one call of d_at (one compiled copy of the good test): steps 0-2 evaluate c, d and the grid's
    # centre c0; then golden-section steps
    def step(i, st):
        a, b, c, d, fc, fd, f0 = st
        left = fc >= fd                                  # the maximum lies in [a, d]
        a2, b2 = jnp.where(left, a, c), jnp.where(left, d, b)
        xg = jnp.where(left, b2 - g * (b2 - a2), a2 + g * (b2 - a2))
        x = jnp.where(i == 0, c, jnp.where(i == 1, d, jnp.where(i == 2, c0, xg)))
        fx = d_at(x)
        gs = i >= 3
        return (jnp.where(gs, a2, a), jnp.where(gs, b2, b),
                jnp.where(gs, jnp.where(left, x, d), c), jnp.where(gs, jnp.where(left, c, x), d),
                jnp.where(gs, jnp.where(left, fx, fd), jnp.where(i == 0, fx, fc)),
                jnp.where(gs, jnp.where(left, fc, fx), jnp.where(i == 1, fx, fd)),
                jnp.where(i == 2, fx, f0))

    a, b, c, d, fc, fd, f0 = jax.lax.fori_loop(0, 3 + n_golden, step, (a, b, c, d, nan, nan, nan))
    cs, fs = jnp.stack([c, d, c0]), jnp.stack([fc, fd, f0])
    k = jnp.argmax(fs)
    D, cb = fs[k], cs[k]
    H = hd_ratio * D
    return RegularWorkspace(volume=math.pi / 4.0 * D * D * H, diameter=D, height=H, z_top=cb - H / 2.0)
