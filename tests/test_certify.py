"""Worst cases found, not sampled (deltajax.optimize.certify): the regular workspace by rays against a brute-force
grid scan and against the old sampled measure where a bad region slips between its samples, converged when the
density doubles, with one traced copy of the good test; the worst point of a task cylinder against a dense scan;
the margins in units."""

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from deltajax import constraints as C
from deltajax.optimize import certify as CE

from _programs import kept

# a good set with a known shape: a barrel on the axis (radius 0.25 - 1.2 (z - 0.45)^2 for z in [0.2, 0.7]) minus a
# bad island at 38-52 deg, rho >= 0.15, z in [0.35, 0.55] -- between the 0/30/60 deg samples of the old measure,
# like the forearm that crosses the base plate in the default problem's baseline
R_MAX, Z0, Z1, HD = 0.4, 0.15, 0.78, 0.5


def _good(p):
    rho = jnp.hypot(p[0], p[1])
    phi = jnp.degrees(jnp.arctan2(p[1], p[0]))
    barrel = (p[2] >= 0.2) & (p[2] <= 0.7) & (rho <= 0.25 - 1.2 * (p[2] - 0.45) ** 2)
    island = (phi >= 38.0) & (phi <= 52.0) & (rho >= 0.15) & (p[2] >= 0.35) & (p[2] <= 0.55)
    return barrel & ~island


# a second set whose smallest radius moves in phi as z moves (a boundary sweeping across the wedge, as the
# recommendation's limiting rays do) and whose ends are where the profile crosses D / 2
def _sweep(p):
    rho = jnp.hypot(p[0], p[1])
    phi = jnp.arctan2(p[1], p[0])
    centre = math.radians(10.0) + 4.0 * (p[2] - 0.3)                     # the dip's phi moves with z
    dip = 0.03 * jnp.exp(-((phi - centre) / math.radians(4.0)) ** 2)
    return (p[2] >= 0.2) & (p[2] <= 0.7) & (rho <= 0.26 - 1.5 * (p[2] - 0.45) ** 2 - dip)


def _brute(good, n_r, n_phi, n_z, r_max=R_MAX):
    pts, r, z = C.polar_grid(r_max, Z0, Z1, n_r, n_phi, n_z)
    g = np.asarray(jax.jit(jax.vmap(good))(jnp.asarray(pts.reshape(-1, 3)))).reshape(pts.shape[:3])
    return CE.grid_cylinder_bounds(g, r, z, HD)


def _rays(good, dens):
    return jax.jit(lambda: CE.ray_cylinder(good, R_MAX, Z0, Z1, HD, dens))()


@pytest.fixture(scope="module")
def synthetic():
    dens = CE.RAY_DENSITY
    return dens, _rays(_good, dens), _rays(_good, dens.doubled())


def _samples(d):
    return len(CE.RAY_PASSES) * d.n_phi * d.n_z * (d.n_along + (d.n_levels - 1) * d.refine)


def test_doubling_the_ray_density_halves_every_spacing():
    d = CE.RAY_DENSITY
    res = lambda d: (d.n_along - 1) * (d.refine - 1) ** (d.n_levels - 1)  # noqa: E731  (intervals at the end)
    for _ in range(2):
        e = d.doubled()
        assert (e.n_phi - 1, e.n_z - 1, e.n_along - 1) == (2 * (d.n_phi - 1), 2 * (d.n_z - 1), 2 * (d.n_along - 1))
        assert res(e) == 2 * res(d) and e.refine == d.refine == CE.RAY_DENSITY.n_along and e.n_levels == d.n_levels
        d = e
    assert CE.RayDensity(n_along=5).refine == 5 and CE.RayDensity(n_along=5, n_refine=3).refine == 3


def _nested_first_bad(good, r_hi, n0, n1, levels):
    """The first bad radius along one ray by the nested search, in numpy (the reference of rays._first_bad)."""
    lo, hi, done, axis_bad = 0.0, r_hi, False, False
    for level in range(levels):
        s = lo + np.linspace(0.0, 1.0, n0 if level == 0 else n1) * (hi - lo)
        g = good(s)
        axis_bad |= level == 0 and not g[0]
        if done:
            continue
        if g.all():
            lo, done = hi, True
        else:
            jb = int(np.argmin(g))
            lo, hi = s[max(jb - 1, 0)], s[jb]
    return 0.0 if axis_bad else lo


@settings(max_examples=25, deadline=None)
@given(st.floats(0.02, 0.4), st.lists(st.tuples(st.floats(0.0, 0.4), st.floats(1e-4, 0.05)), min_size=3, max_size=3),
       st.booleans())
@pytest.mark.slow
def test_first_bad_with_nested_searches_of_their_own_size_is_the_nested_search(edge, islands, possible):
    # a first level of 17 samples, then two nested searches of 5 (the doubled density's shape): every ray's first
    # bad radius is the reference's, through the full test or the necessary-condition path
    isl = np.asarray([(a, a + w) for a, w in islands])

    def good_np(r):
        return (r <= edge) & ~np.any((r[:, None] >= isl[:, 0]) & (r[:, None] <= isl[:, 1]), axis=1)

    out = _first_bad_program(possible)(edge, jnp.asarray(isl))
    ref = _nested_first_bad(good_np, R_MAX, 17, 5, 3)
    np.testing.assert_allclose(np.asarray(out), ref, rtol=1e-12, atol=1e-15)


@pytest.mark.slow
def test_nested_searches_test_neither_a_brackets_ends_nor_a_finished_ray():
    # three rays: one with its first bad radius at 0.23, one good to r_hi (finished after the first level), one
    # whose axis point is bad (finished too); good at R = 1 only, so every point is asked at both R (R = 0 first).
    # The reference's answers, and after the first level only the inside samples of the bracket are asked
    from deltajax.optimize import rays as RY

    edges = {0.4: 0.23, 0.5: 1.0, 0.6: -1.0}
    asked = []

    def good(R, p):
        jax.debug.callback(lambda q, r: asked.append((round(float(q[2]), 6), round(float(np.hypot(q[0], q[1])), 9),
                                                      float(r))), p, R)
        edge = jnp.select([p[2] < 0.45, p[2] < 0.55], [edges[0.4], edges[0.5]], edges[0.6])
        return (jnp.hypot(p[0], p[1]) <= edge) & (R > 0.5)

    z = jnp.asarray(list(edges))
    out = RY._first_bad(good, [jnp.asarray([0.0, 1.0])], [jnp.full((3,), 0.3)], [z], [R_MAX], 17, 3,
                        lambda R, p: jnp.bool_(True), 5)[0]
    jax.effects_barrier()
    ref = [_nested_first_bad(lambda r, e=e: r <= e, R_MAX, 17, 5, 3) for e in edges.values()]
    np.testing.assert_allclose(np.asarray(out), ref, rtol=1e-12)
    by_z = {zz: [(r, R) for q, r, R in asked if q == zz] for zz in edges}
    assert len(by_z[0.5]) == 2 * 17 and len(by_z[0.6]) == 2 * 17            # the first level only
    s0 = np.linspace(0.0, R_MAX, 17)
    lo, hi = s0[int(np.argmin(s0 <= 0.23)) - 1], s0[int(np.argmin(s0 <= 0.23))]
    at_1 = [r for r, R in by_z[0.4] if R == 1.0]           # (a padding lane repeats the first pair, at R = 0)
    later = [r for r in at_1 if r not in np.round(s0, 9)]
    assert len(at_1) == 17 + 2 * 3 and len(later) == 2 * 3 and all(lo < r < hi for r in later)


_FIRST_BAD = {}


def _first_bad_program(possible):
    if possible not in _FIRST_BAD:
        from deltajax.optimize import rays as RY

        def good(p, edge, isl):
            r = jnp.hypot(p[0], p[1])
            return (r <= edge) & ~jnp.any((r >= isl[:, 0]) & (r <= isl[:, 1]))

        phi, z = jnp.asarray([0.1, 0.7, 1.0]), jnp.full((3,), 0.4)

        def run(edge, isl):
            g = lambda R, p: good(p, edge, isl)  # noqa: E731
            pos = (lambda R, p: jnp.hypot(p[0], p[1]) <= edge) if possible else None
            return RY._first_bad(g, [jnp.zeros((2,))], [phi], [z], [R_MAX], 17, 3, pos, 5)[0]

        _FIRST_BAD[possible] = jax.jit(run)
    return _FIRST_BAD[possible]


@pytest.mark.slow
def test_ray_cylinder_agrees_with_a_brute_force_grid_scan_at_more_than_10x_the_density(synthetic):
    dens, one, two = synthetic
    n = (241, 31, 253)                      # 1.9 M points
    assert np.prod(n) >= 10 * _samples(dens)
    bf = _brute(_good, *n)
    assert bf["lower"] <= bf["mid"] <= bf["upper"]
    assert float(one.volume) == pytest.approx(bf["mid"], rel=0.01)
    assert bf["lower"] * 0.995 <= float(one.volume) <= bf["upper"]
    assert abs(float(two.volume) / float(one.volume) - 1.0) <= CE.TOLERANCES["regular_volume"]   # converged
    # the island binds: without it the cylinder is larger (a brute force that ignores it would say so)
    assert float(one.diameter) / 2.0 <= 0.15 + 1e-3


@pytest.mark.slow
def test_a_limiting_dip_that_moves_in_phi_with_z_is_found_and_converges():
    dens = CE.RAY_DENSITY
    one, two = _rays(_sweep, dens), _rays(_sweep, dens.doubled())
    bf = _brute(_sweep, 161, 61, 321, r_max=0.28)
    assert abs(float(two.volume) / float(one.volume) - 1.0) <= CE.TOLERANCES["regular_volume"]
    assert float(one.volume) == pytest.approx(bf["mid"], rel=0.01)
    assert float(one.volume) <= bf["upper"]


@pytest.mark.slow
def test_old_sampled_measure_overstates_where_a_bad_island_slips_between_its_samples(synthetic):
    _, one, _ = synthetic
    pts_old, r_old, z_old = C.polar_grid(R_MAX, Z0, Z1, 32, 3, 43)
    old = jax.jit(lambda: C.regular_workspace(_good, pts_old, r_old, z_old, HD, refine=True))()
    bf = _brute(_good, 241, 31, 253)
    assert float(old.volume) > 1.1 * bf["upper"]                 # the island is not seen: >10 % over-stated
    assert float(one.volume) <= bf["upper"]


def test_ray_cylinder_is_zero_when_the_axis_is_bad():
    out = _rays(lambda p: jnp.hypot(p[0], p[1]) > 0.05, CE.RayDensity(n_phi=3, n_z=6, n_along=5, n_levels=2))
    assert float(out.volume) == 0.0


@pytest.mark.slow
def test_one_traced_good_test_serves_every_pass_and_both_good_sets():
    calls = []

    def good_R(R, p):
        calls.append(1)                                      # once per trace, not per evaluation
        return jnp.hypot(p[0], p[1]) <= 0.15 + R - 0.4 * (p[2] - 0.45) ** 2

    dens = CE.RayDensity(n_phi=3, n_z=6, n_along=5, n_levels=2)
    f = jax.jit(lambda: CE.ray_cylinders(good_R, [jnp.asarray([0.0, 0.05]), jnp.asarray([0.02])], R_MAX, Z0, Z1,
                                         HD, dens))
    both = f()
    assert len(calls) == 1
    # a doubled density's first samples along a ray outnumber its nested searches': a second traced copy, no more
    jax.jit(lambda: CE.ray_cylinders(good_R, [jnp.asarray([0.0, 0.05])], R_MAX, Z0, Z1, HD, dens.doubled()))()
    assert len(calls) == 3
    # each set as if alone: R per point (any of 0 and 0.05: the larger) and the single R
    alone = [_rays(lambda p, R=R: good_R(jnp.asarray(R), p), dens) for R in (0.05, 0.02)]
    for a, b in zip(both, alone):
        np.testing.assert_allclose(float(a.volume), float(b.volume), rtol=1e-12)
    assert float(both[1].volume) < float(both[0].volume)


def test_worst_in_cylinder_finds_a_minimum_between_the_samples():
    p0 = jnp.asarray([0.1 * math.cos(math.radians(7.0)), 0.1 * math.sin(math.radians(7.0)), 0.437])

    def f(p):                                  # a narrow well at phi = 7 deg, between the 0 and 15 deg samples
        return 1.0 - jnp.exp(-jnp.sum((p - p0) ** 2) / 0.01 ** 2)

    best, at = jax.jit(lambda: CE.worst_in_cylinder(f, 0.3, 0.1, 0.4, 3, 5, 5))()
    sampled = jax.vmap(f)(jnp.asarray(C.polar_grid(0.15, 0.4, 0.5, 3, 5, 5)[0].reshape(-1, 3))).min()
    assert float(sampled) > 0.5                                   # the samples miss the well
    assert float(best) < 1e-4 and float(jnp.linalg.norm(at - p0)) < 2e-3


@pytest.mark.slow
def test_worst_in_cylinder_at_traced_counts_is_the_search_at_those_counts_bit_for_bit():
    # one program sized for the densest samples serves every sparser count (the certify stage's first density and
    # its doubling): the same samples, the same worst starts, the same golden sections
    p0 = jnp.asarray([0.06, 0.02, 0.43])
    corner = jnp.asarray([0.15 * math.cos(math.pi / 3), 0.15 * math.sin(math.pi / 3), 0.5])   # the last sample
    well = math.radians(37.5)       # at 3 x 5 x 5 samples: between the 2nd and 3rd angle from 60 deg

    def f(p):
        # third field: a sharp dip at the grid's last sample (its copies in the padding tie with it) and a valley
        # in phi between two sample angles, deeper than the dip: found only from a start next to the valley
        phi = jnp.arctan2(p[1], p[0])
        third = (-0.5 * jnp.exp(-jnp.sum((p - corner) ** 2) / 1e-3 ** 2)
                 - jnp.exp(-((phi - well) / math.radians(6.0)) ** 2))
        return jnp.stack([1.0 - jnp.exp(-jnp.sum((p - p0) ** 2) / 0.02 ** 2), jnp.cos(9.0 * p[0]) * p[2] + p[1],
                          third])

    padded = jax.jit(lambda n: CE.worst_in_cylinder(f, 0.3, 0.1, 0.4, 7, 9, 9, counts=n))
    for n in ((2, 2, 2), (3, 5, 5), (4, 9, 7), (7, 9, 9)):
        want = jax.jit(lambda n=n: CE.worst_in_cylinder(f, 0.3, 0.1, 0.4, *n))()
        got = padded(jnp.asarray(n))
        for a, b in zip(want, got):
            np.testing.assert_array_equal(np.asarray(b), np.asarray(a), err_msg=str(n))
        if n == (3, 5, 5):
            assert float(want[0][2]) < -0.9          # the valley, from the second start (not the dip's copies)
    assert padded._cache_size() == 1


def test_worst_in_cylinder_reports_nan_where_a_point_is_unreachable():
    best, _ = jax.jit(lambda: CE.worst_in_cylinder(lambda p: jnp.where(p[2] > 0.49, jnp.nan, p[2]), 0.3, 0.1, 0.4,
                                                   2, 3, 3))()
    assert np.isnan(float(best))


def test_design_margins_in_units():
    m = {"task_index_min": np.asarray([0.35, np.nan]), "joint_margin_deg": np.asarray([3.0, 1.0]),
         "interference_margin": np.asarray([0.0029, -0.001]), "peak_utilisation": np.asarray([0.8, 1.0]),
         "rms_utilisation": np.asarray([1.0, 0.5]), "speed_utilisation": np.asarray([0.5, 0.5]),
         "picks_per_min": np.asarray([200.0, 100.0]), "arm_sum": np.asarray([0.59, 0.6]),
         "regular_volume": np.asarray([0.03, 0.02])}
    out = CE.design_margins(m, threshold=0.3, min_picks=150.0, max_arm_sum=0.6, volume_floor=0.025)
    np.testing.assert_allclose(out["task_index_margin"][0], 0.05)
    assert np.isnan(out["task_index_margin"][1])                 # unreachable: NaN, never a number
    np.testing.assert_allclose(out["interference_clearance_mm"], [2.9, -1.0])
    np.testing.assert_allclose(out["rms_headroom"], [0.0, 0.5])
    np.testing.assert_allclose(out["picks_over_min"], [50.0, -50.0])
    np.testing.assert_allclose(out["size_budget_margin_mm"], [10.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(out["regular_volume_over_floor"], [0.005, -0.005])
    assert set(out) == set(CE.MARGIN_UNITS)


def test_overlay_puts_the_certified_figures_in_place():
    V = {"design_name": np.asarray(["baseline", "a", "b"], dtype=object), "regular_volume": np.asarray([1.0, 2, 3]),
         "picks_per_min": np.asarray([10.0, 20, 30]), "picks_per_min_fixed": np.asarray([10.0, 20, 30]),
         "feasible": np.asarray([1, 1, 1], np.uint8), "front": np.asarray([1, 2]), "attrs": {"recommended": 2}}
    Cg = {"row": np.asarray([0, 2]), "regular_volume": np.asarray([0.9, 2.5]), "picks_per_min": np.asarray([10.0, 29]),
          "feasible": np.asarray([1, 0], np.uint8), "front": np.asarray([1]), "margin_joint_margin_deg":
          np.asarray([1.0, 2.0, -0.5]), "attrs": {"recommended": 1}}
    out = CE.overlay({"verify": V, "certify": Cg})
    np.testing.assert_array_equal(out["regular_volume"], [0.9, 2, 2.5])
    np.testing.assert_array_equal(out["picks_per_min_fixed"], [10.0, 20, 29])    # the same where R does not move
    np.testing.assert_array_equal(out["feasible"], [1, 1, 0])
    np.testing.assert_array_equal(out["front"], [1])
    assert out["margins"]["joint_margin_deg"][1] == "deg"
    np.testing.assert_array_equal(V["regular_volume"], [1.0, 2, 3])             # the verify group untouched
    assert CE.overlay({"verify": V}) is V


def test_overlay_in_path_mode_certifies_the_fixed_R_cycle_only():
    V = {"picks_per_min": np.asarray([10.0, 20]), "picks_per_min_fixed": np.asarray([9.0, 19]),
         "regular_volume": np.asarray([1.0, 2]), "attrs": {"recommended": 1}}
    Cg = {"row": np.asarray([1]), "picks_per_min": np.asarray([18.5]), "regular_volume": np.asarray([1.9]),
          "attrs": {"recommended": 1, "cycle_variant": "fixed_R"}}
    out = CE.overlay({"verify": V, "certify": Cg})
    np.testing.assert_array_equal(out["picks_per_min"], [10.0, 20])             # R(t) along the cycle: as verified
    np.testing.assert_array_equal(out["picks_per_min_fixed"], [9.0, 18.5])
    np.testing.assert_array_equal(out["regular_volume"], [1.0, 1.9])


@pytest.fixture(scope="module")
def default_problem():
    from hydra import compose, initialize_config_dir

    from deltajax.config import ga_reconfig_build, robot_from_config
    from deltajax.optimize import workflow as W
    from deltajax.run import CONFIG_DIR

    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(config_name="config", overrides=["experiment=ga_reconfig"])
    robot, recon = robot_from_config(cfg.robot)
    s, space, _, _ = ga_reconfig_build(cfg.experiment, robot, recon)
    return s, space, W.designer_problem(s, fine=True)


@pytest.mark.slow
def test_task_worst_joint_margin_within_tolerance_of_a_dense_scan(default_problem):
    s, space, pb = default_problem
    d = space.decode(jnp.asarray(space.baseline_genes()))
    plate = d.R_max + pb.links.plate_overhang
    R = jnp.asarray(0.16)
    t = s.task

    def jm(p):
        return jnp.rad2deg(C.good_point(d.at(R), p, pb.good, plate_radius=plate).joint_margin)

    def im(p):
        return C.good_point(d.at(R), p, pb.good, plate_radius=plate).interference_margin

    args = (t.diameter, t.height, t.z_top, 4, 9, 7)
    pts = C.polar_grid(t.diameter / 2, t.z_top, t.z_top + t.height, 31, 121, 41)[0].reshape(-1, 3)

    def worst_and_dense(pts):       # one program, kept across sessions (tests/_programs.py)
        return (CE.worst_in_cylinder(jm, *args)[0], CE.worst_in_cylinder(im, *args)[0],
                jnp.min(jax.vmap(jm)(pts)), jnp.min(jax.vmap(im)(pts)))

    found_j, found_i, dense_j, dense_i = (float(v) for v in kept(jax.jit(worst_and_dense), "task_worst", __file__,
                                                                   s, space, pb)(jnp.asarray(pts)))
    assert float(found_j) <= dense_j + CE.TOLERANCES["joint_margin_deg"]
    assert float(found_j) >= dense_j - 0.5                       # a real point of the cylinder, not a bound
    assert float(found_i) <= dense_i + CE.TOLERANCES["interference_margin"]


@pytest.mark.slow
def test_cycle_peak_and_rms_converge_at_the_certification_density(default_problem):
    _, space, pb = default_problem
    d = space.decode(jnp.asarray(space.baseline_genes()))
    rob = d.at(jnp.asarray(0.16))
    n0 = pb.cycle.n_samples - 1
    dense = CE.cycle_at(pb, 64 * n0 + 1)

    def figures():          # one program, kept across sessions (tests/_programs.py)
        out = []
        for n in (8 * n0 + 1, 16 * n0 + 1):       # certify_design's first density and its double
            r = C.cycle_rate(rob, CE.cycle_at(pb, n), pb.motor, rob.mass.gear_ratio, dwell=pb.dwell,
                             payload_mass=pb.payload)
            ld = C.drive_loads(rob, dense, pb.motor, rob.mass.gear_ratio, duration=r.cycle_time, dwell=pb.dwell,
                               payload_mass=pb.payload)
            out.append(jnp.stack([r.loads.peak_utilisation, ld.peak_utilisation, ld.rms_utilisation]))
        return jnp.stack(out)

    out = np.asarray(kept(jax.jit(figures), "cycle_peak_rms", __file__, space, pb)()).tolist()
    # the sampled peak is within the tolerance of the dense one at both densities, and so is the RMS
    for peak, peak_dense, rms_dense in out:
        assert abs(peak - peak_dense) <= CE.TOLERANCES["peak_utilisation"]
        assert rms_dense <= 1.0 + CE.TOLERANCES["rms_utilisation"]      # the rating holds on the dense cycle


# -- worst cases along the cycle: a golden section in t from the worst samples --------------------------------------

def test_worst_along_finds_a_minimum_between_the_samples_and_is_never_above_the_samples():
    from deltajax.optimize.cycle_worst import worst_along

    t0, t1 = 0.3137, 0.8261                            # neither on the 11-sample grid

    def f(t):
        return jnp.stack([(t - t0) ** 2 - 1.0, jnp.cos(40.0 * (t - t1))])

    u = jnp.linspace(0.0, 1.0, 11)
    V = jax.vmap(f)(u)
    best, at = jax.jit(lambda: worst_along(f, u, V))()
    np.testing.assert_allclose(best, [-1.0, -1.0], atol=1e-6)             # the analytic minima
    np.testing.assert_allclose(at[0], t0, atol=1e-3)
    assert np.all(np.asarray(best) <= np.min(np.asarray(V), axis=0))
    assert float(np.min(np.asarray(V)[:, 1])) > -1.0 + 1e-2               # the samples alone miss it


def test_worst_along_skips_the_padding_beyond_its_sample_count():
    # samples padded with copies of the last one (the worst): the copies must not crowd out the second and third
    # worst samples as search starts, or the well between them (deeper than every sample) is missed
    from deltajax.optimize.cycle_worst import worst_along

    n, h = 11, 0.1
    tw = 1.0 - 1.5 * h                                 # between the second and third worst samples

    def f(t):
        return (jnp.where(t > 1.0 - h / 2, 0.0, 0.1 + (1.0 - t)) - 1.1 * jnp.exp(-((t - tw) / (h / 20)) ** 2))[None]

    u = jnp.linspace(0.0, 1.0, n)
    want = jax.jit(lambda: worst_along(f, u, jax.vmap(f)(u)))()
    up = jnp.concatenate([u, jnp.ones(n - 1)])         # padded to 2 n - 1 with the last sample
    got = jax.jit(lambda k: worst_along(f, up, jax.vmap(f)(up), n_valid=k))(jnp.asarray(n))
    assert float(want[0][0]) < -0.5                     # the well is found from the second or third start
    for a, b in zip(want, got):
        np.testing.assert_array_equal(np.asarray(b), np.asarray(a))


def test_worst_along_reports_nan_where_a_point_between_the_samples_is_unreachable():
    from deltajax.optimize.cycle_worst import worst_along

    def f(t):   # the margin falls toward 0.43, unreachable on (0.42, 0.44): between the worst samples 0.4, 0.5
        return jnp.where((t > 0.42) & (t < 0.44), jnp.nan, jnp.abs(t - 0.43))[None]

    u = jnp.linspace(0.0, 1.0, 11)
    V = jax.vmap(f)(u)
    assert np.all(np.isfinite(np.asarray(V)))
    best, _ = jax.jit(lambda: worst_along(f, u, V, n_golden=20))()
    assert np.isnan(float(best[0]))


def test_adept_path_is_the_cycle_at_its_samples_and_its_derivatives_are_the_paths():
    from deltajax.trajectory import adept_cycle, adept_path

    c = (0.01, -0.02, 0.45)
    cyc = adept_cycle(c, law="cycloidal", n_samples=41)
    x, dx, ddx = adept_path(cyc.u, c, law="cycloidal")
    for a, b in ((x, cyc.x), (dx, cyc.dx), (ddx, cyc.ddx)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    t = jnp.asarray([0.1234, 0.3711, 0.6172, 0.9001])   # between the samples: central differences of the path
    eps = 1e-6
    xp, dxp, _ = adept_path(t + eps, c, law="cycloidal")
    xm, dxm, _ = adept_path(t - eps, c, law="cycloidal")
    _, dx0, ddx0 = adept_path(t, c, law="cycloidal")
    np.testing.assert_allclose((xp - xm) / (2 * eps), dx0, atol=1e-6)
    np.testing.assert_allclose((dxp - dxm) / (2 * eps), ddx0, atol=1e-4)


@pytest.mark.slow
def test_cycle_worst_at_a_traced_sample_count_is_the_one_at_that_count(default_problem):
    # the certify stage's first density and its doublings share one program sized for a later density: the samples
    # beyond the count repeat the last one, never chosen, never weighted (the RMS integral, the place dwell)
    from deltajax.optimize.cycle_worst import cycle_worst

    _, space, pb = default_problem
    rob = space.decode(jnp.asarray(space.baseline_genes())).at(jnp.asarray(0.16))
    p0 = jnp.asarray([0.1, -0.05, 0.42])

    def fields(p):          # the joint margin and the clearance's stand-ins: one well on the path, one slope
        return jnp.sum((p - p0) ** 2) - 1e-3, p[2] - 0.4 + 0.1 * p[0]

    kw = dict(dwell=0.1, payload_mass=pb.payload)      # a dwell: the place point's static load enters the RMS
    dur = float(pb.settings["cycle"]["duration"])
    path, n = CE.cycle_path(pb), rob.mass.gear_ratio
    K = 2 * (pb.cycle.n_samples - 1) + 1
    k = pb.cycle.n_samples           # the first density's count in the doubling's size
    # both programs kept across sessions (tests/_programs.py)
    want = kept(jax.jit(lambda: cycle_worst(rob, path, k, dur, fields, pb.motor, n, **kw)), "cycle_worst_at_count",
                __file__, space, pb)()
    got = kept(jax.jit(lambda k: cycle_worst(rob, path, K, dur, fields, pb.motor, n, n_valid=k, **kw)),
               "cycle_worst_traced_count", __file__, space, pb)(jnp.asarray(k))
    for a, b in zip(jax.tree_util.tree_leaves(want), jax.tree_util.tree_leaves(got)):
        # the RMS integral sums the same terms in another order (padding zeros): its last bit may move
        np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-13, atol=0)
    for a, b in ((want.joint_margin, got.joint_margin), (want.interference_margin, got.interference_margin),
                 (want.t_worst, got.t_worst), (want.sampled["joint_margin"], got.sampled["joint_margin"])):
        np.testing.assert_array_equal(np.asarray(b), np.asarray(a))      # the searches: exact


@pytest.mark.slow
def test_cycle_worst_agrees_with_a_64x_denser_scan_and_is_never_better_than_its_samples(default_problem):
    """The refined worst joint margin, clearance and peak utilisation of the baseline's cycle at the problem's own
    samples against a brute-force scan at 64x the density (cycle_rate on 64x the samples: a different method), with
    rated = peak torque so that the peak, not the RMS, sets the cycle time."""
    import equinox as eqx

    from deltajax.optimize.cycle_worst import cycle_worst

    _, space, pb = default_problem
    d = space.decode(jnp.asarray(space.baseline_genes()))
    plate = d.R_max + pb.links.plate_overhang
    rob = d.at(jnp.asarray(0.16))
    motor = eqx.tree_at(lambda m: m.rated_torque, pb.motor, pb.motor.peak_torque)
    n = rob.mass.gear_ratio
    kw = dict(dwell=pb.dwell, payload_mass=pb.payload)

    def fields(p):
        c = C.good_point(rob, p, pb.good, plate_radius=plate)
        return c.joint_margin, c.interference_margin

    K = pb.cycle.n_samples
    dur = float(pb.settings["cycle"]["duration"])
    dense = CE.cycle_at(pb, 64 * (K - 1) + 1)

    def refined_and_dense(x):       # one program, kept across sessions (tests/_programs.py): figures only
        cw = cycle_worst(rob, CE.cycle_path(pb), K, dur, fields, motor, n, **kw)
        f64 = jax.vmap(fields)(x)
        return ({"joint_margin": cw.joint_margin, "interference_margin": cw.interference_margin,
                 "cycle_time": cw.rate.cycle_time, "peak_utilisation": cw.rate.loads.peak_utilisation},
                dict(cw.sampled), C.cycle_rate(rob, dense, motor, n, **kw).cycle_time, jnp.min(f64[0]),
                jnp.min(f64[1]))

    cw, s, T64, jm64, im64 = jax.tree_util.tree_map(
        float, kept(jax.jit(refined_and_dense), "cycle_worst", __file__, space, pb)(dense.x))
    # never better than the samples
    assert cw["joint_margin"] <= float(s["joint_margin"])
    assert cw["interference_margin"] <= float(s["interference_margin"])
    assert cw["cycle_time"] >= float(s["cycle_time"])
    assert cw["peak_utilisation"] >= float(s["peak_utilisation"]) - 1e-12
    # the refined figures at 1x agree with the 64x scan within the stated tolerances (and are at least as bad)
    assert abs(np.rad2deg(cw["joint_margin"]) - np.rad2deg(jm64)) <= CE.TOLERANCES["joint_margin_deg"]
    assert cw["joint_margin"] <= jm64 + 1e-12
    assert abs(cw["interference_margin"] - im64) <= CE.TOLERANCES["interference_margin"]
    assert cw["interference_margin"] <= im64 + 1e-12
    assert cw["cycle_time"] >= T64 * (1.0 - 1e-9)
    assert cw["cycle_time"] <= T64 * (1.0 + CE.TOLERANCES["peak_utilisation"])
    # the samples alone are faster than the 64x scan allows; the refined time is not
    assert float(s["cycle_time"]) < T64


def _fake_programs(monkeypatch, volume_at, sizes=None):
    """certify_design with its jitted program replaced by figures that depend on the cycle samples only; ``sizes``
    (a list): each evaluation's task-and-cycle program size (``padded_to``) appended."""
    calls = []

    def program(pb, density, task_samples, cycle_samples, rays=True, padded_to=None):
        def run(design, R):
            calls.append(cycle_samples if rays else -cycle_samples)     # negative: without the ray searches
            if sizes is not None:
                sizes.append(padded_to)
            out = {k: 0.5 for k in CE.CERTIFIED_METRICS}
            out["regular_volume"] = volume_at(cycle_samples) if rays else float("nan")
            return out
        return run

    monkeypatch.setattr(CE, "certified_program", program)
    return calls


class _Design:
    upper_arm = jnp.zeros(3)


@pytest.mark.parametrize("volumes, doublings, converged", [
    ((1.0, 1.001), 1, True),                                 # settled at the first doubling: two evaluations
    ((1.0, 1.02, 1.03, 1.032), 3, True),                     # settled at the third
    ((1.0, 1.02, 1.04, 1.06), 3, False),                     # never: capped at 1 + 2 doublings
    ((float("nan"),) * 4, 1, False),                         # NaN at both densities: doubling again cannot help
])
def test_certify_design_doubles_the_density_again_until_every_figure_settles(monkeypatch, volumes, doublings,
                                                                            converged):
    dens, task = CE.RAY_DENSITY, (3, 5, 7)
    seq = {c: v for c, v in zip((9, 17, 33, 65), volumes)}
    sizes = []
    calls = _fake_programs(monkeypatch, lambda c: seq[c], sizes)
    out = CE.certify_design(None, _Design(), 0.2, density=dens, task_samples=task, cycle_samples=9)
    assert out["doublings"] == doublings and out["converged"] is converged
    assert calls == [9, 17, 33, 65][:doublings + 1]
    # the first density and its first two doublings share one task-and-cycle program (the second doubling's size);
    # later ones their own
    assert CE.SHARED_DOUBLINGS == 2
    assert sizes == [((9, 17, 25), 33)] * min(doublings + 1, 3) + [None] * max(doublings - 2, 0)
    assert out["cycle_samples"] == calls[-1]
    np.testing.assert_equal(out["regular_volume"], volumes[doublings])
    np.testing.assert_equal(out["regular_volume_first"], volumes[0])
    with pytest.raises(ValueError, match="max_extra_doublings"):
        CE.certify_design(None, _Design(), 0.2, density=dens, task_samples=task, cycle_samples=9,
                          max_extra_doublings=-1)
    sizes.clear()       # no further doubling allowed: the program is sized for the first doubling only
    CE.certify_design(None, _Design(), 0.2, density=dens, task_samples=task, cycle_samples=9, max_extra_doublings=0)
    assert sizes == [((5, 9, 13), 17)] * 2


class _Problem:
    rw_rays = tuple(CE.RAY_DENSITY)


def test_certify_design_takes_the_first_densitys_regular_workspace_from_the_verification(monkeypatch):
    # the verification searched the same rays at the first density: its figures are used, the first program runs
    # without the ray searches, and the doublings run with them
    calls = _fake_programs(monkeypatch, {9: 1.0, 17: 1.02, 33: 1.021}.get)
    first = {k: 0.25 for k in CE.REGULAR_FIGURES}
    first["regular_volume"] = 1.0
    out = CE.certify_design(_Problem(), _Design(), 0.2, task_samples=(3, 5, 7), cycle_samples=9, regular_first=first)
    assert calls == [-9, 17, 33] and out["doublings"] == 2
    assert out["regular_volume_first"] == 1.0 and out["regular_volume"] == 1.021 and out["regular_certified"]
    # regular=False: no ray search at any density; the doublings settle the task and cycle figures alone and the
    # regular figures are the verification's, their change NaN (the certify stage's first step for a design)
    calls.clear()
    out = CE.certify_design(_Problem(), _Design(), 0.2, task_samples=(3, 5, 7), cycle_samples=9, regular_first=first,
                            regular=False)
    assert calls == [-9, -17] and out["doublings"] == 1 and out["converged"] and not out["regular_certified"]
    assert all(out[k] == first[k] for k in CE.REGULAR_FIGURES) and np.isnan(out["regular_volume_change"])
    assert "regular_volume 1 (the verification's, not certified)" in CE.describe(out)
    with pytest.raises(ValueError, match="regular=False takes the regular-workspace figures from regular_first"):
        CE.certify_design(_Problem(), _Design(), 0.2, task_samples=(3, 5, 7), cycle_samples=9, regular=False)
    with pytest.raises(ValueError, match="regular_first lacks regular_diameter, .*regular_diameter_fixed"):
        CE.certify_design(_Problem(), _Design(), 0.2, regular_first={"regular_volume": 1.0}, cycle_samples=9,
                          task_samples=(3, 5, 7))
    with pytest.raises(ValueError, match="the problem's own rays"):   # another first density: not the same search
        CE.certify_design(_Problem(), _Design(), 0.2, density=CE.RAY_DENSITY, regular_first=first, cycle_samples=9,
                          task_samples=(3, 5, 7))


@pytest.mark.slow   # compiles the certify program with its ray searches at the toy density (~10 CPU-s)
def test_the_verifications_regular_workspace_is_the_certify_programs_at_the_first_density(toy_run):
    # what the certify stage relies on when it takes the first density's figures from the verification: the
    # certify program's own ray searches give the same figures bit for bit, and leaving them out changes no other
    # figure
    from _config_helpers import compose
    from toy_jobs import TOY

    from deltajax.config import ga_reconfig_build, robot_from_config
    from deltajax.io import load
    from deltajax.optimize.workflow import designer_problem

    data = load(toy_run("ga_reconfig"))
    V, Cg = data["verify"], data["certify"]
    cfg = compose("ga_reconfig", *TOY["ga_reconfig"])
    robot, recon = robot_from_config(cfg.robot)
    s, space, _, _ = ga_reconfig_build(cfg.experiment, robot, recon)
    pb = designer_problem(s, fine=True)
    space = dataclasses.replace(space, n_R=s.verify.n_R)
    i = int(np.asarray(Cg["row"]).reshape(-1)[-1])                     # the last design certified
    design = space.decode(jnp.asarray(np.asarray(V["genes"], float)[i]))
    R_op = jnp.asarray(float(np.asarray(V["R_operating"]).reshape(-1)[i]))
    d, t, c = CE._densities(pb, None, None, None)
    full = CE.certified_program(pb, d, t, c)(design, R_op)
    rest = CE.certified_program(pb, d, t, c, rays=False)(design, R_op)
    for k in CE.REGULAR_FIGURES:
        assert float(full[k]) == float(np.asarray(V[k]).reshape(-1)[i]), k
        assert math.isnan(float(rest[k])), k
    for k in set(full) - set(CE.REGULAR_FIGURES):
        np.testing.assert_array_equal(rest[k], full[k], err_msg=k)


_ALL_ANY = {}


@settings(max_examples=20)
@given(st.integers(0, 2 ** 31 - 1), st.sampled_from([(15, 1), (15, 8), (3, 4)]))
def test_all_any_good_is_the_full_all_any_whatever_it_skips(seed, shape):
    # the designer's cylinder test (every point good at some R) through the necessary condition, the decided test
    # (wrong where it does not decide) and the early stops: the full test's all-any, on random tables, one R too
    from deltajax.optimize.designer import _all_any_good

    n_pts, n_R = shape
    rng = np.random.default_rng(seed)
    good = rng.random((n_pts, n_R)) < rng.choice([0.5, 0.9, 0.99])
    possible = good | (rng.random((n_pts, n_R)) < 0.4)
    decided = rng.random((n_pts, n_R)) < 0.8
    if shape not in _ALL_ANY:
        def run(G, Pm, D):
            def at(R, p):
                return p[0].astype(int), R.astype(int)

            def decided_R(R, p):
                i, j = at(R, p)
                return jnp.where(D[i, j], G[i, j], ~G[i, j]), D[i, j]

            return _all_any_good(lambda R, p: G[at(R, p)], lambda R, p: Pm[at(R, p)], jnp.arange(n_R, dtype=float),
                                 jnp.arange(n_pts, dtype=float)[:, None] * jnp.ones((1, 3)), decided_R)

        _ALL_ANY[shape] = jax.jit(run)
    out = _ALL_ANY[shape](jnp.asarray(good), jnp.asarray(possible), jnp.asarray(decided))
    assert bool(out) == bool(good.any(axis=1).all())


#: what the programs' full test and settle were asked, (point, R) pairs, appended by their debug callbacks
_ASKED, _SETTLED = [], []


@functools.lru_cache(maxsize=None)
def _where_possible_programs(n_pts, n_R, chunk):
    """The four programs of the test below for one shape (points, R samples, chunk), the tables their arguments,
    so that the examples of one shape share one compilation each (each example compiled its own: ~15 s of the
    suite)."""
    from deltajax.optimize.rays import Decided, any_good_where_possible, good_where_possible

    Rf = jnp.asarray(np.tile(np.arange(n_R, dtype=float), n_pts))                      # pairs point-major, R inner
    Pf = jnp.asarray(np.repeat(np.arange(n_pts, dtype=float), n_R)[:, None] * np.ones((1, 3)))
    Rm = jnp.asarray(np.repeat(np.arange(n_R, dtype=float), n_pts))    # R-major: every point's first R, then ...
    Pm3 = jnp.asarray(np.tile(np.arange(n_pts, dtype=float), n_R)[:, None] * np.ones((1, 3)))

    def at(R, p):
        return p[0].astype(int), R.astype(int)

    def tests(G, Pm, D):
        def good_R(R, p):
            return G[at(R, p)]

        def good_logged(R, p):
            jax.debug.callback(lambda r, q: _ASKED.append((int(q[0]), int(r))), R, p)
            return good_R(R, p)

        def possible_R(R, p):
            return Pm[at(R, p)]

        def decided_R(R, p):    # decides where D, and answers wrongly where it does not
            ij = at(R, p)
            return jnp.where(D[ij], G[ij], ~G[ij]), D[ij]

        def settle(ij):
            jax.debug.callback(lambda i, j: _SETTLED.append((int(i), int(j))), *ij)
            return G[ij]

        return good_R, good_logged, possible_R, decided_R, Decided(lambda R, p: decided_R(R, p) + (at(R, p),),
                                                                   settle)

    def per_pair(G, Pm, D):
        good_R, _, possible_R, _, _ = tests(G, Pm, D)
        return good_where_possible(good_R, possible_R, Rf, Pf, chunk)

    def any_R(G, Pm, D):
        _, good_logged, possible_R, _, _ = tests(G, Pm, D)
        return any_good_where_possible(good_logged, possible_R, Rm, Pm3, [(n_pts, n_R)], chunk)

    def per_pair_decided(G, Pm, D):
        _, good_logged, possible_R, decided_R, _ = tests(G, Pm, D)
        return good_where_possible(good_logged, possible_R, Rf, Pf, chunk, decided_R)

    def per_pair_settled(G, Pm, D):
        _, good_logged, possible_R, _, decided = tests(G, Pm, D)
        return good_where_possible(good_logged, possible_R, Rf, Pf, chunk, decided)

    return tuple(jax.jit(f) for f in (per_pair, any_R, per_pair_decided, per_pair_settled))


@pytest.mark.slow   # each shape compiles four programs
@settings(max_examples=8)
@given(st.integers(0, 2 ** 31 - 1), st.sampled_from([(1, 4, 4), (7, 3, 5), (40, 5, 64), (13, 1, 2)]))
def test_good_only_where_possible_is_the_full_test_and_skips_what_cannot_be_good(seed, shape):
    # a random good set and a random necessary condition of it (possible where good, and at some other pairs):
    # both packings give the full test's answer (per pair, and any over each point's R), and the full test runs in
    # rounds of ``chunk`` lanes over the possible pairs only (it records every lane it computes, padding included):
    # at most ceil(possible pairs / chunk) rounds, none when nothing is possible
    n_pts, n_R, chunk = shape
    per_pair, any_R, per_pair_decided, per_pair_settled = _where_possible_programs(*shape)
    rng = np.random.default_rng(seed)
    good = rng.random((n_pts, n_R)) < 0.3
    possible = good | (rng.random((n_pts, n_R)) < 0.4)
    # with a cheaper test that decides most pairs (and answers wrongly where it does not decide)
    decided = rng.random((n_pts, n_R)) < 0.8
    tables = (jnp.asarray(good), jnp.asarray(possible), jnp.asarray(decided))
    np.testing.assert_array_equal(np.asarray(per_pair(*tables)), good.reshape(-1))
    _ASKED.clear()
    np.testing.assert_array_equal(np.asarray(any_R(*tables)), good.any(axis=1))
    jax.effects_barrier()
    k = min(chunk, n_pts * n_R)
    assert len(_ASKED) <= k * -(-int(possible.sum()) // k)
    # the decided test: the same answers, and the full test runs only at undecided pairs
    _ASKED.clear()
    np.testing.assert_array_equal(np.asarray(per_pair_decided(*tables)), good.reshape(-1))
    jax.effects_barrier()
    und = {(i, j) for i, j in zip(*np.nonzero(possible & ~decided))}
    assert set(_ASKED) <= und                  # padding lanes repeat an undecided pair
    # a Decided hands its state to its settle (the good test: the IK solved once per pair): the same answers, the
    # full test never called, settle only at undecided pairs, from the state decide left there
    _ASKED.clear()
    _SETTLED.clear()
    np.testing.assert_array_equal(np.asarray(per_pair_settled(*tables)), good.reshape(-1))
    jax.effects_barrier()
    assert _ASKED == [] and set(_SETTLED) <= und and bool(_SETTLED) == bool(und)


@pytest.mark.slow
def test_ray_cylinders_with_a_necessary_condition_or_a_cheaper_test_give_the_same_cylinders():
    def good_R(R, p):
        return jnp.hypot(p[0], p[1]) <= 0.15 + R - 0.4 * (p[2] - 0.45) ** 2

    def possible_R(R, p):                                    # necessary: a wider barrel
        return jnp.hypot(p[0], p[1]) <= 0.2 + R - 0.2 * (p[2] - 0.45) ** 2

    dens = CE.RayDensity(n_phi=3, n_z=6, n_along=5, n_levels=2)
    sets = [jnp.asarray([0.0, 0.05, 0.03]), jnp.asarray([0.02])]
    def decided_R(R, p):    # undecided near the edge, and wrong there
        margin = 0.15 + R - 0.4 * (p[2] - 0.45) ** 2 - jnp.hypot(p[0], p[1])
        dec = jnp.abs(margin) > 0.01
        return jnp.where(dec, margin >= 0, margin < 0), dec

    full = CE.ray_cylinders(good_R, sets, R_MAX, Z0, Z1, HD, dens)
    pruned = CE.ray_cylinders(good_R, sets, R_MAX, Z0, Z1, HD, dens, possible_R=possible_R)
    settled = CE.ray_cylinders(good_R, sets, R_MAX, Z0, Z1, HD, dens, possible_R=possible_R, decided_R=decided_R)
    for a, b, c in zip(full, pruned, settled):
        for k in ("volume", "diameter", "height", "z_top"):
            assert float(getattr(a, k)) == float(getattr(b, k)) == float(getattr(c, k))
    assert float(full[0].volume) > 0


def test_certify_by_rule_runs_rays_only_for_the_baseline_and_the_designs_the_rule_stays_with():
    # three candidates: verified picks/min 10, 9, 8; their task-and-cycle certification lowers them to 7, 8.5 and 7.9;
    # design 2's rays put it under the volume floor (allowed: every design holds it by its verified volume)
    from deltajax.optimize.certify import certify_by_rule

    picks = {0: 5.0, 1: 10.0, 2: 9.0, 3: 8.0}
    floor_ok = {0: True, 1: True, 2: True, 3: True}
    cheap, rays = {1: 7.0, 2: 8.5, 3: 7.9}, {2: False}
    calls = []

    def certify(i, regular):
        calls.append((i, regular))
        picks[i] = cheap.get(i, picks[i])
        if regular:
            floor_ok[i] = rays.get(i, floor_ok[i])

    def choose():
        ok = [i for i in (1, 2, 3) if floor_ok[i]]
        return max(ok, key=lambda i: picks[i]) if ok else -1

    rec, done = certify_by_rule(choose, certify)
    assert rec == 3 and done == {0: True, 1: False, 2: True, 3: True}
    assert calls == [(0, True), (1, False), (2, False), (2, True), (3, False), (3, True)]
    # without design 2's volume dropping: its rays confirm it, and design 3 is never certified
    picks.update({1: 10.0, 2: 9.0, 3: 8.0}), floor_ok.update({2: True}), rays.clear(), calls.clear()
    assert certify_by_rule(choose, certify) == (2, {0: True, 1: False, 2: True})
    # at most max_full designs with their rays besides the baseline: the last of them is the answer
    picks.update({1: 10.0, 2: 9.0, 3: 8.0}), floor_ok.update({2: True}), rays.update({2: False}), calls.clear()
    assert certify_by_rule(choose, certify, max_full=1) == (2, {0: True, 1: False, 2: True})
    # no candidate: the baseline alone
    floor_ok.update({1: False, 2: False, 3: False}), calls.clear()
    assert certify_by_rule(choose, certify) == (-1, {0: True}) and calls == [(0, True)]
