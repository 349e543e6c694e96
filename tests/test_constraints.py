"""Designer constraints (deltajax.constraints), each against an independent computation."""

import itertools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import deltajax as dj
from deltajax import constraints as C
from deltajax.indices import point_kernel

from _programs import kept

ROBOT = dj.presets.franco2026(fixed_R=0.2, with_mass=True)
POINTS = np.array([[0.0, 0.0, 0.45], [0.15, 0.0, 0.4], [0.0, 0.15, 0.5], [-0.12, 0.07, 0.42], [0.05, -0.1, 0.3]])
MOTOR = C.Motor(peak_torque=3.8, rated_torque=1.27, max_speed=628.0, corner_speed=400.0, rotor_inertia=3.4e-5,
                efficiency=0.9)


def _thetas():
    return np.stack([np.asarray(dj.ik(ROBOT, jnp.asarray(p)).theta) for p in POINTS])


@pytest.mark.slow
def test_ball_joint_cones_match_the_passive_angles():
    jm = C.JointModel(limit=math.radians(50), elbow_neutral=math.radians(80), platform_neutral=math.radians(35))
    f = jax.jit(jax.vmap(lambda p, t: C.joint_angles(ROBOT, p, t, jm)))
    th = _thetas()
    a = f(jnp.asarray(POINTS), jnp.asarray(th))
    for i, p in enumerate(POINTS):
        t2, t3 = (np.asarray(x) for x in dj.passive_angles(ROBOT, jnp.asarray(p), jnp.asarray(th[i])))
        t12 = th[i] + t2
        # u = (sin t3 cos t12, cos t3, sin t3 sin t12) in the chain frame (paper §2.1)
        np.testing.assert_allclose(np.cos(a.elbow[i]), np.sin(t3) * np.cos(t2 - math.radians(80)), atol=1e-12)
        np.testing.assert_allclose(np.cos(a.platform[i]), np.sin(t3) * np.sin(t12 - math.radians(35)), atol=1e-12)
    m = C.joint_margin(ROBOT, jnp.asarray(POINTS[2]), jnp.asarray(th[2]), jm)
    np.testing.assert_allclose(float(m), math.radians(50) - max(np.max(a.elbow[2]), np.max(a.platform[2])))


def test_universal_joint_angles():
    jm = C.JointModel(limit=math.pi / 2, elbow_neutral=math.radians(90), platform_neutral=0.0, kind="universal")
    th = _thetas()
    for i, p in enumerate(POINTS):
        a = C.joint_angles(ROBOT, jnp.asarray(p), jnp.asarray(th[i]), jm)
        t2, t3 = (np.asarray(x) for x in dj.passive_angles(ROBOT, jnp.asarray(p), jnp.asarray(th[i])))
        tilt = np.abs(t3 - np.pi / 2)
        inplane = np.abs((t2 - np.pi / 2 + np.pi) % (2 * np.pi) - np.pi)
        np.testing.assert_allclose(np.asarray(a.elbow), np.maximum(inplane, tilt), atol=1e-12)
    with pytest.raises(C.ConstraintError, match="JointModel.kind"):
        C.JointModel(limit=1.0, kind="hinge")
    with pytest.raises(C.ConstraintError, match="JointModel.limit"):
        C.JointModel(limit=float("nan"))


def _brute_seg(p0, p1, q0, q1, n=801):
    s = np.linspace(0, 1, n)
    P = p0[None] + s[:, None] * (p1 - p0)[None]
    Q = q0[None] + s[:, None] * (q1 - q0)[None]
    return np.min(np.linalg.norm(P[:, None] - Q[None], axis=-1))


SEG = jax.jit(C.segment_distance)


@settings(deadline=None, max_examples=25)
@given(st.lists(st.floats(-1, 1), min_size=12, max_size=12), st.booleans())
@pytest.mark.slow
def test_segment_distance_against_dense_sampling(v, parallel):
    p0, p1, q0, q1 = (np.asarray(v[3 * i:3 * i + 3]) for i in range(4))
    if parallel:
        q1 = q0 + 0.7 * (p1 - p0)
    d = float(SEG(*(jnp.asarray(x) for x in (p0, p1, q0, q1))))
    b = _brute_seg(p0, p1, q0, q1)
    seg_len = max(np.linalg.norm(p1 - p0), np.linalg.norm(q1 - q0))
    assert d <= b + 1e-12
    assert b <= d + 2 * seg_len / 800 + 1e-12


@pytest.mark.slow
def test_interference_against_brute_force_capsules():
    links = C.LinkModel(forearm_radius=0.02, upper_arm_radius=0.025, clearance=0.005, plate_overhang=0.03)
    th = _thetas()
    f = jax.jit(jax.vmap(lambda p, t: C.interference(ROBOT, p, t, links)))
    out = f(jnp.asarray(POINTS), jnp.asarray(th))
    for i, p in enumerate(POINTS):
        B = np.asarray(dj.elbows(ROBOT, jnp.asarray(th[i])))
        ang = np.array([0, 2 * np.pi / 3, 4 * np.pi / 3])
        e = np.stack([np.cos(ang), np.sin(ang), np.zeros(3)], 1)
        Cp = p[None] + 0.065 * e
        A = 0.2 * e
        ff = min(_brute_seg(B[a], Cp[a], B[b], Cp[b]) for a, b in itertools.combinations(range(3), 2)) - 0.04
        fu = min(_brute_seg(B[a], Cp[a], A[b], B[b]) for a in range(3) for b in range(3) if a != b) - 0.045
        np.testing.assert_allclose(float(out.forearm_forearm[i]), ff, atol=2e-3)
        np.testing.assert_allclose(float(out.forearm_upper_arm[i]), fu, atol=2e-3)
        # base plate (disc z = 0, radius 0.23): signed distance of the forearm axes, sampled finely
        s = np.linspace(0, 1, 2001)
        pts = (B[:, None] + s[None, :, None] * (Cp - B)[:, None]).reshape(-1, 3)
        rho = np.hypot(pts[:, 0], pts[:, 1])
        dist = np.where(rho > 0.23, np.hypot(np.maximum(rho - 0.23, 0), pts[:, 2]), pts[:, 2])
        bp = min(dist.min() - 0.02, p[2])
        # exact segment-disc clearance: never above the sampled one, below it by at most the sample spacing
        assert float(out.base_plate[i]) <= bp + 1e-12
        assert float(out.base_plate[i]) >= bp - np.linalg.norm(Cp - B, axis=1).max() / 2000
        np.testing.assert_allclose(float(out.margin[i]), min(float(out.forearm_forearm[i]),
                                                             float(out.forearm_upper_arm[i]),
                                                             float(out.base_plate[i])) - 0.005, atol=1e-15)
    # an arm raised through the base plate is caught
    high = C.interference(ROBOT, jnp.asarray([0.0, 0.0, 0.05]), jnp.asarray([-0.6, -0.6, -0.6]),
                          C.LinkModel(plate_overhang=0.3))
    assert float(high.base_plate) < 0


def _numpy_loads(n, T, dwell, payload):
    """Independent: arm torques from cycle_profile of a robot whose MassModel was rebuilt by hand."""
    import equinox as eqx

    m = ROBOT.mass
    m2 = dj.MassModel(upper_arm_mass=m.upper_arm_mass, forearm_mass=m.forearm_mass, platform_mass=m.platform_mass,
                      payload_mass=payload, gear_ratio=n, rotor_inertia=3.4e-5)
    rob = eqx.tree_at(lambda d: d.mass, ROBOT, m2)
    cyc = dj.adept_cycle((0, 0, 0.4), n_samples=61, duration=T)
    pr = dj.cycle_profile(rob, cyc)
    tau = np.asarray(pr.tau) / (n * 0.9)
    om = np.asarray(pr.theta_dot) * n
    t = np.asarray(pr.t)
    w = np.abs(om)
    env = np.where(w >= 628, 0.0, 3.8 * np.clip((628 - w) / (628 - 400), 0, 1))
    peak = np.max(np.abs(tau) / env)
    g = np.asarray(pr.tau_gravity) / (n * 0.9)
    integ = np.trapezoid(tau ** 2, t, axis=0) + dwell * (g[0] ** 2 + g[30] ** 2)
    rms = np.sqrt(integ / (T + 2 * dwell))
    # reflected rotor inertia: the torque difference to a rotor-less model is n^2 J thetaddot exactly
    m0 = eqx.tree_at(lambda q: q.rotor_inertia, m2, jnp.asarray(0.0))
    pr0 = dj.cycle_profile(eqx.tree_at(lambda d: d.mass, ROBOT, m0), cyc)
    np.testing.assert_allclose(np.asarray(pr.tau) - np.asarray(pr0.tau), n * n * 3.4e-5 * np.asarray(pr.theta_ddot),
                               atol=1e-10)
    return peak, rms.max() / 1.27, w.max() / 628, cyc


@pytest.mark.parametrize("n, T, dwell, payload", [(20.0, 0.4, 0.0, 0.0), (12.0, 0.6, 0.1, 1.0)])
@pytest.mark.slow
def test_drive_loads_against_an_independent_computation(n, T, dwell, payload):
    peak, rms, spd, cyc = _numpy_loads(n, T, dwell, payload)
    L = C.drive_loads(ROBOT, cyc, MOTOR, n, dwell=dwell, payload_mass=payload)
    np.testing.assert_allclose(float(L.peak_utilisation), peak, rtol=1e-10)
    np.testing.assert_allclose(float(L.rms_utilisation), rms, rtol=1e-10)
    np.testing.assert_allclose(float(L.speed_utilisation), spd, rtol=1e-10)


@pytest.mark.slow
def test_min_cycle_time_is_the_feasibility_edge():
    cyc = dj.adept_cycle((0, 0, 0.4), n_samples=61)
    rate = jax.jit(lambda n, dwell, payload: C.cycle_rate(ROBOT, cyc, MOTOR, n, dwell=dwell, payload_mass=payload))
    loads = jax.jit(lambda T, n, dwell, payload: C.drive_loads(ROBOT, cyc, MOTOR, n, duration=T, dwell=dwell,
                                                               payload_mass=payload))
    for n, dwell, payload in [(20.0, 0.0, 0.5), (8.0, 0.2, 2.0)]:
        r = rate(n, dwell, payload)
        T = float(r.cycle_time)
        assert 0.05 < T < 5

        def util(TT):
            L = loads(TT, n, dwell, payload)
            return max(float(L.peak_utilisation), float(L.rms_utilisation))

        assert util(T) <= 1.0 + 1e-9 < util(0.995 * T)  # exp(log T) rounding
        np.testing.assert_allclose(float(r.picks_per_min), 60.0 / (T + 2 * dwell), rtol=1e-12)
    weak = C.Motor(peak_torque=0.05, rated_torque=0.01, max_speed=600.0, corner_speed=600.0)
    assert float(C.picks_per_minute(ROBOT, cyc, weak, 5.0)) == 0.0  # cannot even hold the arm
    far = dj.adept_cycle((0, 0, 0.9), n_samples=11)
    assert math.isnan(float(C.picks_per_minute(ROBOT, far, MOTOR, 10.0)))  # unreachable: NaN, not a number


def _brute_cylinder(good, r, z, lam):
    best = (0.0, 0.0, 0.0)
    nz, nr = good.shape
    for a in range(nz):
        for b in range(a, nz):
            rr = None
            for k in range(a, b + 1):
                j = 0
                while j < nr and good[k, j]:
                    j += 1
                rk = r[j - 1] if j > 0 else -1
                rr = rk if rr is None else min(rr, rk)
            if rr < 0:
                continue
            D = min(2 * rr, (z[b] - z[a]) / lam)
            v = math.pi / 4 * D * D * lam * D
            if v > best[0] + 1e-15:
                best = (v, D, z[a])
    return best


@settings(deadline=None, max_examples=15)
@given(st.integers(0, 2 ** 31 - 1), st.floats(0.2, 2.0))
def test_largest_cylinder_against_brute_force(seed, lam):
    rng = np.random.default_rng(seed)
    nz, nr = 7, 5
    good = rng.random((nz, nr)) < 0.8
    r = np.linspace(0, 0.2, nr)
    z = np.linspace(0.2, 0.5, nz)
    out = C.largest_cylinder(jnp.asarray(good), jnp.asarray(r), jnp.asarray(z), lam)
    v, D, zt = _brute_cylinder(good, r, z, lam)
    np.testing.assert_allclose(float(out.volume), v, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(float(out.diameter), D, rtol=1e-12, atol=1e-15)


@pytest.mark.slow
def test_regular_workspace_of_a_known_good_set():
    # good set: the cylinder r <= 0.15, 0.3 <= z <= 0.45: with H/D = 0.5 the answer is D = 0.3, H = 0.15
    pts, r, z = C.polar_grid(0.3, 0.2, 0.6, 31, 4, 41)
    good = lambda p: (jnp.hypot(p[0], p[1]) <= 0.15 + 1e-9) & (p[2] >= 0.3 - 1e-9) & (p[2] <= 0.45 + 1e-9)  # noqa
    out = C.regular_workspace(good, pts, r, z, 0.5)
    np.testing.assert_allclose([float(out.diameter), float(out.height), float(out.z_top)], [0.3, 0.15, 0.3],
                               atol=1e-12)
    np.testing.assert_allclose(float(out.volume), math.pi * 0.15 ** 2 * 0.15, rtol=1e-12)


@pytest.mark.slow
def test_good_point_combines_the_margins():
    spec = C.GoodSpec(joints=C.JointModel(limit=math.radians(50), platform_neutral=math.radians(40)),
                      links=C.LinkModel(), threshold=0.3)
    f = jax.jit(jax.vmap(lambda p: C.good_point(ROBOT, p, spec)))
    pts = np.concatenate([POINTS, [[0.0, 0.0, 0.95]]])
    out = f(jnp.asarray(pts))
    for i, p in enumerate(pts):
        sol = dj.ik(ROBOT, jnp.asarray(p))
        if not bool(sol.ok):
            assert not bool(out.good[i]) and math.isnan(float(out.joint_margin[i]))
            continue
        k = float(dj.indices(ROBOT, jnp.asarray(p), sol.theta).k_tilde)
        np.testing.assert_allclose(float(out.index[i]), k, rtol=1e-8)
        jm = float(C.joint_margin(ROBOT, jnp.asarray(p), sol.theta, spec.joints))
        im = float(C.interference(ROBOT, jnp.asarray(p), sol.theta, spec.links).margin)
        assert bool(out.good[i]) == (k >= 0.3 and jm >= 0 and im >= 0)


@pytest.mark.slow
def test_cycle_rate_gradient_is_the_implicit_derivative_of_the_bisection():
    """d T_min / d(gear ratio, payload, upper arm) by autodiff (implicit function theorem at the binding limit)
    against central differences of the bisection itself (value unchanged by the gradient path)."""
    import equinox as eqx

    cyc = dj.adept_cycle((0, 0, 0.4), n_samples=31)

    def T(x):
        rob = eqx.tree_at(lambda r: r.upper_arm, ROBOT, x[2])
        return C.cycle_rate(rob, cyc, MOTOR, x[0], payload_mass=x[1], n_iter=80).cycle_time

    f = jax.jit(T)
    x0 = jnp.asarray([20.0, 0.5, float(ROBOT.upper_arm)])
    g = np.asarray(jax.jit(jax.grad(T))(x0))
    h = np.asarray([1e-4, 1e-5, 1e-6])
    cd = [(float(f(x0.at[i].add(h[i]))) - float(f(x0.at[i].add(-h[i])))) / (2 * h[i]) for i in range(3)]
    assert np.all(np.isfinite(g)) and np.all(np.abs(g) > 0)
    np.testing.assert_allclose(g, cd, rtol=2e-4)
    # forward mode (the refine descent's) gives the same derivative; at T_low (not interior) it is zero
    np.testing.assert_allclose(np.asarray(jax.jit(jax.jacfwd(T))(x0)), g, rtol=1e-12)
    fast = jax.jit(jax.value_and_grad(lambda x: C.cycle_rate(ROBOT, cyc, MOTOR, x, T_low=1.0).cycle_time))
    assert tuple(map(float, fast(20.0))) == (1.0, 0.0)  # T_low binds


# -- continuous regular-workspace measure (a grid's levels would quantise the volume) --------------------------

def _ball(c, rho):
    return lambda p: jnp.sum((p - jnp.asarray([0.0, 0.0, c])) ** 2) <= rho * rho


@pytest.mark.slow
def test_refined_cylinder_in_a_ball_and_a_cone_against_closed_forms():
    # independent closed forms: a ball of radius rho holds the cylinder with (D/2)^2 + (H/2)^2 = rho^2, H = lam D;
    # the frustum r <= a + b (z - z0), z <= z2 (radius growing downward) the one touching z2 and the top rim:
    # D / 2 = a + b (z2 - lam D - z0)
    lam = 0.5
    pts, r, z = C.polar_grid(0.3, 0.2, 0.7, 16, 3, 22)
    f = jax.jit(lambda rho: C.regular_workspace(_ball(0.45, rho), pts, r, z, lam, refine=True))
    grid = jax.jit(lambda rho: C.regular_workspace(_ball(0.45, rho), pts, r, z, lam))
    rhos = np.linspace(0.17, 0.19, 5)
    D = np.asarray([float(f(rho).diameter) for rho in rhos])
    # within the stated bound, from below: bisection D_hi / 2^12 (D_hi = D_grid + 2 (2 dr + dz / lam) < 0.55 m)
    # plus the centre's golden-section bracket 4 dz 0.618^14, which costs at most 2 x that / lam in D
    dz = float(z[1] - z[0])
    tol = 0.55 / 2 ** C.REFINE_BISECT + 2 * 4 * dz * 0.618 ** C.REFINE_GOLDEN / lam
    d_exact = 2 * rhos / math.sqrt(1 + lam ** 2)
    assert np.all(D <= d_exact + 1e-12) and np.all(D >= d_exact - tol)
    # continuous: equal steps in rho give equal steps in D, where the grid's answer moves in level/ring steps
    np.testing.assert_allclose(np.diff(D), np.diff(d_exact), atol=2 * tol)
    Dg = np.asarray([float(grid(rho).diameter) for rho in rhos])
    assert np.max(np.abs(Dg - 2 * rhos / math.sqrt(1 + lam ** 2))) > 10 * np.max(np.abs(D - 2 * rhos / math.sqrt(1 + lam ** 2)))
    out = f(0.18)
    np.testing.assert_allclose(float(out.z_top), 0.45 - lam * float(out.diameter) / 2, atol=2e-4)
    np.testing.assert_allclose(float(out.volume), math.pi / 4 * float(out.diameter) ** 3 * lam, rtol=1e-12)
    a, b, z0, z2 = 0.05, 0.5, 0.3, 0.6
    cone = lambda p: (jnp.hypot(p[0], p[1]) <= a + b * (p[2] - z0)) & (p[2] >= z0) & (p[2] <= z2)  # noqa: E731
    oc = C.regular_workspace(cone, pts, r, z, lam, refine=True)
    d_cone = 2 * (a + b * (z2 - z0)) / (1 + 2 * b * lam)
    assert d_cone - tol <= float(oc.diameter) <= d_cone + 1e-12
    np.testing.assert_allclose(float(oc.z_top) + float(oc.height), z2, atol=tol)


def test_search_settings_of_the_refined_cylinder_against_closed_forms():
    # the main job's search uses the continuous measure with fewer steps and samples (experiment.regular_workspace.
    # search_refine: 10 bisection / 8 golden-section steps, 3 x 2 x 3 samples) on the search grid; checked against
    # the ball's closed form like the verification settings: from below, within the stated bound, and moving in
    # equal steps where the grid's answer jumps between levels
    lam = 0.5
    pts, r, z = C.polar_grid(0.40, 0.15, 0.78, 16, 3, 22)            # the job's search grid
    unit = C.cylinder_samples(lam, 3, 2, 3)

    @jax.jit
    def f(rho):
        good = _ball(0.45, rho)
        g = jax.vmap(good)(jnp.asarray(pts).reshape(-1, 3)).reshape(pts.shape[:3])
        start = C.largest_cylinder(jnp.all(g, axis=2), r, z, lam)
        return C.refine_cylinder(good, start, r, z, lam, unit=unit, n_bisect=10, n_golden=8), start

    rhos = np.linspace(0.17, 0.19, 5)
    outs = [f(rho) for rho in rhos]
    D = np.asarray([float(o[0].diameter) for o in outs])
    Dg = np.asarray([float(o[1].diameter) for o in outs])
    dz, dr = float(z[1] - z[0]), float(r[1] - r[0])
    d_hi = Dg.max() + 2 * (2 * dr + dz / lam)
    tol = d_hi / 2 ** 10 + 2 * 4 * dz * 0.618 ** 8 / lam            # stated bound (the centre's bracket dominates)
    d_exact = 2 * rhos / math.sqrt(1 + lam ** 2)
    assert np.all(D <= d_exact + 1e-12) and np.all(D >= d_exact - tol)
    err = d_exact - D
    assert np.max(err) < 2e-3                                        # measured: well inside the bound (~1 mm)
    np.testing.assert_allclose(np.diff(D), np.diff(d_exact), atol=2e-3)
    assert np.max(np.abs(Dg - d_exact)) > 5 * np.max(err)           # the grid's answer alone is much coarser


@pytest.mark.slow
def test_refine_cylinder_each_distinct_sample_once_and_all_good_give_the_same_answer():
    # refine_cylinder tests the centre once per centre and drops repeated samples (the axis ring repeats one point
    # per angle): the answer must be that of the samples as given, repeats and all; an ``all_good`` computing the
    # same all() another way (here: the samples in reverse order) must not change it either, and is then the only
    # test the refinement calls (the centre too: one copy of the good test in the program, not two)
    lam = 0.5
    pts, r, z = C.polar_grid(0.40, 0.15, 0.78, 16, 3, 22)
    unit = C.cylinder_samples(lam, 3, 2, 3)
    def run(u, good_fn=None, **kw):
        good = _ball(0.45, 0.18)
        g = jax.vmap(good)(jnp.asarray(pts).reshape(-1, 3)).reshape(pts.shape[:3])
        start = C.largest_cylinder(jnp.all(g, axis=2), r, z, lam)
        return C.refine_cylinder(good_fn or good, start, r, z, lam, unit=u, n_bisect=10, n_golden=8, **kw)

    base = run(unit)
    doubled = run(np.concatenate([unit, unit, np.zeros((2, 3))]))       # repeats and extra centres
    calls = []

    def good_counted(p):
        calls.append(p.shape)
        return _ball(0.45, 0.18)(p)

    rev = run(unit, good_fn=good_counted, all_good=lambda P: jnp.all(jax.vmap(_ball(0.45, 0.18))(P[::-1])))
    assert calls == []
    for o in (doubled, rev):
        for a, b in zip(base, o):
            assert float(a) == float(b)


@pytest.mark.slow
def test_good_point_possible_is_necessary():
    # a point where good_point_possible is False is never good (the search evaluator skips the full test there)
    spec = C.GoodSpec(joints=C.JointModel(limit=math.radians(50), platform_neutral=math.radians(40)),
                      links=C.LinkModel(), threshold=0.3)
    pts, _, _ = C.polar_grid(0.45, 0.1, 0.9, 12, 3, 12)
    P = jnp.asarray(pts).reshape(-1, 3)
    for plate in (None, 0.33):       # the plate's closed-form test (plate_blocks) rules points out too
        # both tests in one program, kept across sessions (tests/_programs.py)
        good, maybe = kept(jax.jit(jax.vmap(lambda p: (C.good_point(ROBOT, p, spec, plate_radius=plate).good,
                                                      C.good_point_possible(ROBOT, p, spec, plate_radius=plate)))),
                           f"good_point_possible_{plate}", __file__)(P)
        assert np.all(np.asarray(maybe) | ~np.asarray(good))
        assert 0 < int(np.sum(good)) and int(np.sum(maybe)) < P.shape[0]   # neither test trivial on this grid
    reach = jax.jit(jax.vmap(lambda p: (k := point_kernel(ROBOT, p, beta=spec.beta)).ok
                             & (k.indices.k_tilde >= spec.threshold - 1e-9)))(P)
    assert int(np.sum(maybe)) < int(np.sum(reach))     # the plate test ruled out points that reach and index allow


@pytest.mark.slow
def test_good_point_decided_is_the_full_test_wherever_it_decides_and_its_state_settles_the_rest():
    # the closed-form plate tests settle all but the forearms that pass near the rim at the required clearance;
    # plate radii swept so that some do (those must come back undecided), and wherever it decides, the flag is
    # good_point's, bit for bit; good_point_settle of the state it solved is good_point's flag at every point
    # (unreachable and NaN points included)
    # (ball joints: a sign test instead of the cone angles; universal joints: their exact margin)
    pts, _, _ = C.polar_grid(0.4, 0.1, 0.8, 8, 3, 10)
    P = jnp.concatenate([jnp.asarray(pts).reshape(-1, 3), jnp.asarray([[jnp.nan, 0.0, 0.5], [0.0, 0.0, 5.0]])])
    plates = jnp.linspace(0.2, 0.45, 26)
    for kind, limit in (("ball", 50), ("universal", 40)):
        spec = C.GoodSpec(joints=C.JointModel(limit=math.radians(limit), platform_neutral=math.radians(40), kind=kind),
                          links=C.LinkModel(forearm_radius=0.012, clearance=0.005), threshold=0.2)

        def both(P, Rp, spec=spec):
            check = jax.vmap(lambda p: C.good_point(ROBOT, p, spec, plate_radius=Rp))(P)
            g, dec, state = jax.vmap(lambda p: C.good_point_decided(ROBOT, p, spec, plate_radius=Rp, state=True))(P)
            return check.good, g, dec, check.joint_margin, jax.vmap(lambda s: C.good_point_settle(s, spec))(state)

        program = kept(jax.jit(jax.vmap(lambda r: both(P, r))), f"good_point_decided_{kind}", __file__)
        full, g, dec, jm, settled = (np.asarray(a) for a in program(plates))
        assert np.array_equal(g[dec], full[dec])
        assert np.array_equal(settled, full) and not full[:, -2:].any()
        assert 0 < int((~dec).sum()) < 0.05 * dec.size          # some undecided (rim grazing), few
        assert full.any() and not full.all()
        assert np.any(jm < 0) and np.any(jm > 0)                # the joints' limit is crossed on this grid
