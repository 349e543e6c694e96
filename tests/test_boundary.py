"""Boundary search (deltajax.workspace.boundary) and the boundary_search experiment, on coarse angle grids."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import deltajax as dj
from deltajax.config import ConfigError
from deltajax.workspace import boundary as B

CENTRE = (0.0, 0.0, 1.62)
EPS = 0.01
RHO_MAX = 5.12
STEP = 15.0


@pytest.fixture(scope="module")
def robot():
    return dj.presets.boundary2d()


@pytest.fixture(scope="module")
def reach(robot):
    """Jitted batched Test-Pose."""
    return jax.jit(jax.vmap(lambda p: B.test_pose(robot, p)))


@pytest.fixture(scope="module")
def searches(robot):
    """Both searches and the dense ray profiles at 15 deg (shared so that each compiles once)."""
    conti = B.boundary_search(robot, CENTRE, step_deg=STEP, eps=EPS, rho_max=RHO_MAX, method="conti")
    cont = B.boundary_search(robot, CENTRE, step_deg=STEP, eps=EPS, rho_max=RHO_MAX, method="continuation")
    prof = B.ray_profiles(robot, conti, rho_max=RHO_MAX, n_samples=1024)
    return conti, cont, prof


def test_angle_grid_matches_paper_loops():
    polar, azimuth = B.angle_grid(2.0)
    assert polar.shape == (91,) and azimuth.shape == (181,)  # the paper's 181 subplot calls
    assert polar[0] == 0.0 and azimuth[-1] == pytest.approx(2 * np.pi, abs=1e-15)
    assert B.angle_grid(1.0)[0].size * B.angle_grid(1.0)[1].size == 181 * 361
    with pytest.raises(ValueError, match="does not divide"):
        B.angle_grid(7.0)
    with pytest.raises(ValueError, match="positive"):
        B.angle_grid(0.0)


def test_bisection_call_count_theory():
    assert B.bisection_calls(5.12, 0.01) == 9  # 5.12 / 2^9 = 0.01 exactly
    assert B.bisection_calls(5.13, 0.01) == 10
    assert B.bisection_calls(1.0, 0.01) == math.ceil(math.log2(100))
    with pytest.raises(ValueError):
        B.bisection_calls(0.01, 0.1)


@pytest.mark.slow
def test_conti_count_reproduces_paper_table3(robot):
    """The paper's Table 3: 148239 Test-Pose calls at 2 deg, eps = 0.01 = 9 calls x 91 x 181 rays."""
    res = B.boundary_search(robot, CENTRE, step_deg=2.0, eps=EPS, rho_max=RHO_MAX, method="conti")
    calls = np.asarray(res.calls)
    assert calls.shape == (181, 91)
    assert int(calls.sum()) == dj.papers.BOUNDARY_SEARCH["calls_conti_2deg"] == 9 * 91 * 181
    assert bool(np.all(np.asarray(res.ok)))
    width = np.asarray(res.radius_out - res.radius_in)
    np.testing.assert_allclose(width, RHO_MAX / 2 ** 9, rtol=1e-12)


@pytest.mark.slow
def test_bracket_is_a_boundary_crossing(reach, searches):
    """radius_in reachable, radius_out not, for both methods; on star rays a point eps beyond is unreachable."""
    conti, cont, prof = searches
    test = reach
    d = np.asarray(B.ray_directions(conti.polar, conti.azimuth)).reshape(-1, 3)
    star = np.asarray(prof.n_exits).reshape(-1) == 1
    assert star.mean() > 0.8 and (~star).any()
    for res in (conti, cont):
        assert bool(np.all(np.asarray(res.ok)))
        r_in, r_out = np.asarray(res.radius_in).reshape(-1), np.asarray(res.radius_out).reshape(-1)
        assert np.all(r_out - r_in <= EPS + 1e-12) and np.all(r_out > r_in)
        c = np.asarray(CENTRE)
        assert np.all(np.asarray(test(jnp.asarray(c + r_in[:, None] * d))))
        assert not np.any(np.asarray(test(jnp.asarray(c + r_out[:, None] * d))))
        beyond = np.asarray(test(jnp.asarray(c + (r_in + EPS)[:, None] * d)))
        assert not np.any(beyond[star])


@pytest.mark.slow
def test_methods_agree_on_star_rays(searches):
    conti, cont, prof = searches
    star = np.asarray(prof.n_exits) == 1
    diff = np.abs(np.asarray(conti.radius_in) - np.asarray(cont.radius_in))
    assert np.all(diff[star] < EPS)
    # both brackets contain the densely sampled exit (sample spacing RHO_MAX / 1024)
    dr = RHO_MAX / 1024
    for res in (conti, cont):
        fe = np.asarray(prof.first_exit)[star]
        assert np.all(np.asarray(res.radius_in)[star] <= fe + dr)
        assert np.all(np.asarray(res.radius_out)[star] >= fe - dr)


@pytest.mark.slow
def test_continuation_call_counts(searches):
    """First ray per azimuth: the bisection count; later rays: 1 + number of eps steps, bracket width eps."""
    _, cont, _ = searches
    calls = np.asarray(cont.calls)
    assert np.all(calls[:, 0] == B.bisection_calls(RHO_MAX, EPS))
    assert np.all(calls[:, 1:] >= 2)
    np.testing.assert_allclose(np.asarray(cont.radius_out - cont.radius_in)[:, 1:], EPS, atol=1e-12)
    # the eps-steps walk from the tangent prediction rho_prev / cos(dphi) to the new bracket
    dphi = np.diff(np.asarray(cont.polar))[0]
    pred = np.asarray(cont.radius_in)[:, :-1] / np.cos(dphi)
    r_in, r_out = np.asarray(cont.radius_in)[:, 1:], np.asarray(cont.radius_out)[:, 1:]
    up = r_in >= pred - 1e-12
    steps = np.where(up, np.round((r_in - pred) / EPS) + 1, np.round((pred - r_out) / EPS) + 1)
    np.testing.assert_array_equal(calls[:, 1:], 1 + steps)


@pytest.mark.slow
def test_non_star_rays_detected(reach, searches):
    """Rays that leave and re-enter: a reachable point beyond a first exit that is unreachable."""
    conti, _, prof = searches
    n_exits = np.asarray(prof.n_exits)
    j, i = np.argwhere(n_exits > 1)[0]
    d = np.asarray(B.ray_directions(conti.polar, conti.azimuth))[j, i]
    c = np.asarray(CENTRE)
    dr = RHO_MAX / 1024
    fe, le = float(prof.first_exit[j, i]), float(prof.last_exit[j, i])
    assert le > fe + 2 * dr
    pts = jnp.asarray([c + (fe - 0.5 * dr) * d, c + (fe + 0.5 * dr) * d, c + (le - 0.5 * dr) * d])
    inside = np.asarray(reach(pts))
    np.testing.assert_array_equal(inside, [True, False, True])


@pytest.mark.slow
def test_ray_integral_matches_grid_volume(robot):
    """Dense ray integration is the exact volume even where the set is not star-shaped: check against a grid."""
    res = B.boundary_search(robot, CENTRE, step_deg=6.0, eps=0.05, rho_max=RHO_MAX, method="conti")
    prof = B.ray_profiles(robot, res, rho_max=RHO_MAX, n_samples=256)
    w = B.vertex_weights(res.polar, res.azimuth)
    v_ray = float(np.sum(w * np.asarray(prof.vol_integrand)))
    gv = B.grid_volume(robot, 0.1, ((-2.8, 2.8), (-2.8, 2.8), (0.0, 4.2)), chunk=1 << 16)
    assert gv.volume == pytest.approx(45.097, rel=5e-3)  # h = 0.005 converged value: 45.0973 m^3
    assert v_ray == pytest.approx(gv.volume, rel=1e-2)
    assert gv.centroid[2] == pytest.approx(1.6195, abs=5e-3) and abs(gv.centroid[1]) < 1e-9


def test_vertex_weights_sum_to_sphere():
    polar, azimuth = B.angle_grid(10.0)
    np.testing.assert_allclose(B.vertex_weights(polar, azimuth).sum(), 4 * np.pi, rtol=1e-13)
    polar, azimuth = B.angle_grid(10.0, (0.0, 90.0), (0.0, 180.0))
    np.testing.assert_allclose(B.vertex_weights(polar, azimuth).sum(), np.pi, rtol=1e-13)


@settings(max_examples=10)
@given(a=st.floats(0.5, 3.0), fx=st.floats(-0.3, 0.3), fz=st.floats(-0.3, 0.3))
def test_sector_volume_of_spheres(a, fx, fz):
    """Radius function of a sphere of radius a seen from a point offset by (fx, 0, fz) * a inside it."""
    ox, oz = fx * a, fz * a
    polar, azimuth = B.angle_grid(3.0)
    d = np.asarray(B.ray_directions(polar, azimuth))
    c = -np.array([ox, 0.0, oz])  # sphere centre relative to the search centre
    dc = d @ c
    rho = dc + np.sqrt(dc ** 2 + a ** 2 - c @ c)
    exact = 4.0 / 3.0 * np.pi * a ** 3
    v_pyr = B.sector_volume(rho, polar, azimuth, "pyramid")
    v_sph = B.sector_volume(rho, polar, azimuth, "spherical")
    assert v_pyr < exact  # inscribed polyhedron
    assert v_pyr == pytest.approx(exact, rel=2e-3)
    assert v_sph == pytest.approx(exact, rel=2e-3)


def test_sector_volume_rules_on_centred_sphere():
    polar, azimuth = B.angle_grid(2.0)
    rho = np.full((azimuth.size, polar.size), 2.0)
    exact = 4.0 / 3.0 * np.pi * 8.0
    assert B.sector_volume(rho, polar, azimuth, "spherical") == pytest.approx(exact, rel=1e-13)
    # an inscribed polyhedron: 1 - V/V_sphere = O(step^2) (5.07e-4 at 2 deg, 1/4 of that at 1 deg)
    deficit2 = 1 - B.sector_volume(rho, polar, azimuth, "pyramid") / exact
    assert 4e-4 < deficit2 < 6e-4
    p1, a1 = B.angle_grid(1.0)
    deficit1 = 1 - B.sector_volume(np.full((a1.size, p1.size), 2.0), p1, a1, "pyramid") / exact
    assert deficit1 == pytest.approx(deficit2 / 4, rel=0.02)
    # the naive sum over the paper's inclusive loops counts the azimuth seam twice: ~181/180
    naive = B.sector_volume(rho, polar, azimuth, "riemann_naive")
    assert naive / exact == pytest.approx(181 / 180, rel=2e-4)
    with pytest.raises(ValueError, match="rule"):
        B.sector_volume(rho, polar, azimuth, "cubes")
    with pytest.raises(ValueError, match="shape"):
        B.sector_volume(rho.T, polar, azimuth)


def test_saturated_and_bad_inputs(robot):
    # rho_max inside the workspace: every test is true, the rays are flagged, radii NaN
    res = B.boundary_search(robot, CENTRE, step_deg=30.0, eps=EPS, rho_max=1.0, method="conti")
    assert not np.any(np.asarray(res.ok)) and np.all(np.isnan(np.asarray(res.radius_in)))
    # centre outside the workspace (z < 0 with half_space): nothing ok
    for method in B.METHODS:
        res = B.boundary_search(robot, (0.0, 0.0, -1.0), step_deg=STEP, eps=EPS, rho_max=RHO_MAX, method=method)
        assert not np.any(np.asarray(res.ok)) and np.all(np.isnan(np.asarray(res.radius_out)))
    with pytest.raises(ValueError, match="eps"):
        B.boundary_search(robot, CENTRE, step_deg=30.0, eps=-1.0, rho_max=RHO_MAX)
    with pytest.raises(ValueError, match="method"):
        B.boundary_search(robot, CENTRE, step_deg=30.0, method="newton")
    with pytest.raises(ValueError, match="predictor"):
        B.continuation_rays(robot, CENTRE, *B.angle_grid(30.0), eps=EPS, rho_max=RHO_MAX, predictor="magic")
    with pytest.raises(ValueError, match="grid box side z"):
        B.grid_volume(robot, 0.2, ((-2.8, 2.8), (-2.8, 2.8), (0.0, 4.1)))


def test_experiment_config_errors():
    from omegaconf import OmegaConf

    from deltajax.config import boundary_search_spec as _check

    base = OmegaConf.load("configs/experiment/boundary_search.yaml").experiment
    ok = _check(base)
    assert ok.rho_max == 5.12 and ok.steps_deg == [2.0, 1.0]
    for key, value, match in (("eps", -0.01, "experiment.eps"), ("steps_deg", [7.0], "experiment.steps_deg"),
                              ("centre", [0.0, 1.0], "experiment.centre"),
                              ("predictor", "magic", "experiment.predictor"),
                              ("grid_h", 0.03, "experiment.grid_box"), ("rho_max", 0.001, "experiment.rho_max")):
        bad = OmegaConf.merge(base, {key: value})
        with pytest.raises(ConfigError, match=match):
            _check(bad)


@pytest.mark.slow
def test_experiment_writes_results(toy_run, searches):
    from deltajax.io import load

    from toy_jobs import TOY

    # the session's shared toy run: steps of STEP degrees, grid_h=0.2, 64 profile samples, one centre-sweep z
    assert f"experiment.steps_deg=[{STEP}]" in TOY["boundary_search"]
    path = toy_run("boundary_search")
    out = load(path)
    assert "boundary2d" in out["attrs"]["config"]  # the experiment's default robot
    g = out["boundary"]["step_15deg"]
    conti, cont = g["conti"], g["continuation"]
    assert conti["radius_in"].shape == (25, 13) and conti["units"]["radius_in"] == "m"
    assert conti["units"]["azimuth"] == "rad"
    assert conti["attrs"]["calls_total"] == 9 * 25 * 13
    np.testing.assert_allclose(conti["radius_in"], np.asarray(searches[0].radius_in), rtol=1e-12)
    np.testing.assert_array_equal(cont["calls"], np.asarray(searches[1].calls))
    assert out["boundary"]["attrs"]["paper_volume_m3"] == dj.papers.BOUNDARY_SEARCH["volume_m3"]
    assert 40 < out["boundary"]["attrs"]["grid_volume"] < 50
    assert out["boundary"]["centre_sweep"]["calls_conti"][0] == 9 * 25 * 13
    import xarray as xr

    ds = xr.open_dataset(path, group="boundary/step_15deg/conti", engine="h5netcdf")
    assert ds["radius_in"].dims == ("azimuth", "polar")
    ds.close()


def test_continuation_matches_sequential_reference(robot, searches):
    """The vmapped scan/while_loop gives the brackets and call counts of a plain sequential loop (3 azimuths)."""
    _, cont, _ = searches
    test1 = jax.jit(lambda p: B.test_pose(robot, p))
    polar, azimuth = np.asarray(cont.polar), np.asarray(cont.azimuth)
    dirs = np.asarray(B.ray_directions(polar, azimuth))
    c = np.asarray(CENTRE)
    n_bis = B.bisection_calls(RHO_MAX, EPS)
    for j in (0, 7, 19):
        lo, hi = 0.0, RHO_MAX
        for _ in range(n_bis):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if bool(test1(c + mid * dirs[j, 0])) else (lo, mid)
        r_in, calls = [lo], [n_bis]
        for i in range(1, polar.size):
            rho0 = min(max(r_in[-1] / math.cos(polar[i] - polar[i - 1]), 0.0), RHO_MAX)
            t0 = bool(test1(c + rho0 * dirs[j, i]))
            sgn, k = (1.0 if t0 else -1.0), 0
            while True:
                k += 1
                rk = min(max(rho0 + sgn * k * EPS, 0.0), RHO_MAX)
                if bool(test1(c + rk * dirs[j, i])) != t0:
                    break
            prev = rho0 + sgn * (k - 1) * EPS
            r_in.append(prev if t0 else rk)
            calls.append(k + 1)
        np.testing.assert_array_equal(np.asarray(cont.calls)[j], calls)
        np.testing.assert_allclose(np.asarray(cont.radius_in)[j], r_in, rtol=0, atol=1e-13)
