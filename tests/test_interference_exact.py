"""Exact link-plate geometry of deltajax.constraints.interference against an independent dense sampling
(1e5 points per segment of the signed point-disc distance), including forearms that cross the plate plane."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

import deltajax as dj
from deltajax import constraints as C

ROBOT = dj.presets.franco2026(fixed_R=0.2)
N_DENSE = 100_001
SEG_DISC = jax.jit(jax.vmap(C.segment_disc_distance))


def _dense_plate(q0, q1, radius, n=N_DENSE):
    """min over n points of the segment of the signed point-disc distance: z over the disc (< 0 above the
    plate), the distance to the rim beside it."""
    s = np.linspace(0.0, 1.0, n)[:, None]
    q = q0[None] + s * (q1 - q0)[None]
    rho = np.hypot(q[:, 0], q[:, 1])
    return float(np.where(rho > radius, np.hypot(rho - radius, q[:, 2]), q[:, 2]).min())


def _assert_exact(d, q0, q1, radius):
    dense = np.array([_dense_plate(a, b, r) for a, b, r in zip(q0, q1, radius)])
    step = np.linalg.norm(q1 - q0, axis=1) / (N_DENSE - 1)
    assert np.all(d <= dense + 1e-12)            # the exact minimum is never above a sampled one
    assert np.all(d >= dense - step - 1e-12)     # and below it by at most the sample spacing


@pytest.mark.slow
def test_segment_disc_distance_against_dense_sampling():
    rng = np.random.default_rng(7)
    n = 120
    q0 = rng.uniform(-0.5, 0.5, (n, 3))
    q1 = rng.uniform(-0.5, 0.5, (n, 3))
    q1[:20, :2] = q0[:20, :2]                                  # vertical segments
    q0[20:40, 2], q1[20:40, 2] = -0.1, 0.2                    # crossing the plate plane
    q1[40:50] = q0[40:50]                                     # points
    radius = rng.uniform(0.0, 0.4, n)
    d = np.asarray(SEG_DISC(jnp.asarray(q0), jnp.asarray(q1), jnp.asarray(radius)))
    _assert_exact(d, q0, q1, radius)
    assert np.any(d[20:40] < 0) and np.any(d[20:40] > 0)      # both kinds of crossing occur


def _forearms(p, theta):
    B = np.asarray(dj.elbows(ROBOT, jnp.asarray(theta)))
    ang = np.array([0.0, 2 * np.pi / 3, 4 * np.pi / 3])
    return B, np.asarray(p)[None] + 0.065 * np.stack([np.cos(ang), np.sin(ang), np.zeros(3)], 1)


def test_forearm_crossing_the_plate_plane_through_the_disc():
    """Arms raised (theta = -0.6 rad) with the platform 5 cm below the plate: each forearm runs from above the
    plate beside the disc to below it, crossing the plate plane inside the disc."""
    links = C.LinkModel(forearm_radius=0.02, plate_overhang=0.03)
    p, theta = np.array([0.0, 0.0, 0.05]), np.full(3, -0.6)
    out = C.interference(ROBOT, jnp.asarray(p), jnp.asarray(theta), links)
    B, Cp = _forearms(p, theta)
    dense = min(_dense_plate(B[i], Cp[i], 0.23) for i in range(3))
    step = np.linalg.norm(Cp - B, axis=1).max() / (N_DENSE - 1)
    assert dense - step - 1e-12 <= float(out.base_plate) + 0.02 <= dense + 1e-12
    assert float(out.base_plate) < -0.02 and float(out.margin) < 0


@pytest.mark.slow
def test_interference_plate_clearance_exact_over_random_configurations():
    rng = np.random.default_rng(3)
    n = 60
    p = np.stack([rng.uniform(-0.25, 0.25, n), rng.uniform(-0.25, 0.25, n), rng.uniform(0.05, 0.5, n)], 1)
    theta = rng.uniform(-1.0, 1.5, (n, 3))
    links = C.LinkModel(forearm_radius=0.0, plate_overhang=0.03)
    f = jax.jit(jax.vmap(lambda p_, t_: C.interference(ROBOT, p_, t_, links).base_plate))
    bp = np.asarray(f(jnp.asarray(p), jnp.asarray(theta)))
    for i in range(n):
        B, Cp = _forearms(p[i], theta[i])
        dense = min(min(_dense_plate(B[k], Cp[k], 0.23) for k in range(3)), p[i, 2])
        step = np.linalg.norm(Cp - B, axis=1).max() / (N_DENSE - 1)
        assert dense - step - 1e-12 <= bp[i] <= dense + 1e-12, (i, bp[i], dense)


@pytest.mark.slow
def test_plate_clearance_gradient_matches_finite_differences():
    # a forearm passing beside the rim: the nearest point is inside the segment (envelope-theorem derivative)
    q0 = jnp.asarray([0.30, 0.02, -0.05])
    q1 = jnp.asarray([0.10, -0.03, 0.30])
    check_grads(lambda a, b, r: C.segment_disc_distance(a, b, r), (q0, q1, jnp.asarray(0.23)), order=1,
                modes=("rev", "fwd"), eps=1e-6)
    links = C.LinkModel(forearm_radius=0.02, plate_overhang=0.03)
    th = jnp.asarray([0.1, -0.2, 0.3])
    check_grads(lambda p: C.interference(ROBOT, p, th, links).base_plate, (jnp.asarray([0.05, 0.02, 0.35]),),
                order=1, modes=("rev",), eps=1e-6)
    assert math.isfinite(float(C.interference(ROBOT, jnp.asarray([0.05, 0.02, 0.35]), th, links).base_plate))


def _bisected_plate(q0, q1, radius, steps=60):
    """Unsigned segment-disc distance by plain bisection on the sign of h'(t) over [0, 1] (h convex), numpy,
    vectorised over rows; ends taken where h' points outward there. Independent of the Newton search."""
    d = q1 - q0

    def parts(t):
        q = q0 + t[:, None] * d
        rho = np.hypot(q[:, 0], q[:, 1])
        ex = np.maximum(rho - radius, 0.0)
        rp = np.where(rho > radius, (q[:, 0] * d[:, 0] + q[:, 1] * d[:, 1]) / np.where(rho > 0, rho, 1.0), 0.0)
        return ex * rp + q[:, 2] * d[:, 2], ex * ex + q[:, 2] ** 2

    lo, hi = np.zeros(len(q0)), np.ones(len(q0))
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        up = parts(mid)[0] > 0
        lo, hi = np.where(up, lo, mid), np.where(up, mid, hi)
    h = np.minimum(np.minimum(parts(0.5 * (lo + hi))[1], parts(np.zeros(len(q0)))[1]), parts(np.ones(len(q0)))[1])
    return np.sqrt(h)


@pytest.mark.slow
def test_segment_disc_distance_equals_a_full_bisection_on_grazing_segments():
    """The Newton search (closed-form pieces, PLATE_NEWTON_STEPS steps) reaches the minimum of a 60-step bisection
    to 1e-13 m on segments that graze the rim nearly in the plate plane (where Newton from a far start crawls)
    and on random ones; rows that pass over the disc above the plate (signed, closed form) are left out."""
    rng = np.random.default_rng(11)
    n = 20_000
    radius = rng.uniform(0.05, 0.4, n)
    ang = rng.uniform(0.0, 2 * np.pi, n)
    rr = radius + rng.normal(0.0, 0.01, n)
    mid = np.stack([rr * np.cos(ang), rr * np.sin(ang), rng.normal(0.0, 0.01, n)], 1)
    u = rng.normal(size=(n, 3))
    u[: n // 2, 2] *= 0.02                                        # nearly in the plate plane
    u /= np.linalg.norm(u, axis=1)[:, None]
    length = rng.uniform(0.01, 0.6, (n, 1))
    q0 = mid - length * u * rng.uniform(0.0, 1.0, (n, 1))
    q1 = q0 + length * u
    q0 = np.concatenate([q0, rng.uniform(-0.5, 0.5, (n, 3))])
    q1 = np.concatenate([q1, rng.uniform(-0.5, 0.5, (n, 3))])
    radius = np.concatenate([radius, rng.uniform(0.0, 0.4, n)])
    d = np.asarray(SEG_DISC(jnp.asarray(q0), jnp.asarray(q1), jnp.asarray(radius)))
    ref = _bisected_plate(q0, q1, radius)
    unsigned = d >= 0
    assert unsigned.sum() > n
    assert np.max(np.abs(d[unsigned] - ref[unsigned])) <= 1e-13


@pytest.mark.slow
def test_plate_blocks_only_where_the_exact_plate_clearance_fails():
    """constraints.plate_blocks (closed form; the search's necessary condition good_point_possible rules a point
    out with it) is True only where the exact clearance of some forearm to the plate is below forearm_radius +
    clearance, and catches most such configurations; plate radii placed near each forearm's closest approach to
    the axis, so that forearms graze the rim."""
    rng = np.random.default_rng(11)
    n = 4000
    links = C.LinkModel(forearm_radius=0.012, clearance=0.005)
    P = np.stack([rng.uniform(-0.25, 0.25, n), rng.uniform(-0.25, 0.25, n), rng.uniform(-0.05, 0.6, n)], 1)
    TH = rng.uniform(-1.2, 1.4, (n, 3))
    B = np.asarray(jax.vmap(lambda t: dj.elbows(ROBOT, t))(jnp.asarray(TH)))
    ang = np.array([0.0, 2 * np.pi / 3, 4 * np.pi / 3])
    Cp = P[:, None] + float(ROBOT.platform_radius) * np.stack([np.cos(ang), np.sin(ang), np.zeros(3)], 1)[None]
    # per configuration a plate radius at a forearm's closest approach to the axis (+- 2 cm): rim grazing
    s = np.linspace(0.0, 1.0, 201)[None, :, None]
    rho_min = np.hypot(*(B[:, 0, None, :2] + s * (Cp[:, 0, None, :2] - B[:, 0, None, :2])).transpose(2, 0, 1)).min(1)
    Rp = np.clip(rho_min + rng.uniform(-0.02, 0.02, n), 0.0, None)
    blocked = np.asarray(jax.jit(jax.vmap(lambda p, t, r: C.plate_blocks(ROBOT, p, jnp.cos(t), jnp.sin(t), links, r)))(
        jnp.asarray(P), jnp.asarray(TH), jnp.asarray(Rp)))
    exact = np.asarray(SEG_DISC(jnp.asarray(B.reshape(-1, 3)), jnp.asarray(Cp.reshape(-1, 3)),
                                jnp.asarray(np.repeat(Rp, 3)))).reshape(n, 3).min(1)
    fails = exact - float(links.forearm_radius) < float(links.clearance)
    assert not np.any(blocked & ~fails)                            # sufficient: never blocks a clear plate
    assert blocked.sum() > 0.8 * fails.sum() > 100                 # and not vacuous
    near = np.abs(exact - float(links.forearm_radius + links.clearance)) < 2e-3
    assert near.sum() > 20 and np.any(blocked & near)             # the boundary itself is exercised
