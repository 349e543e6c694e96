"""The GA fitness's speed-ups keep the exact answer: the population-level task coverage
(:func:`deltajax.optimize.screens.task_cover`) gives the exact sweep's flags, the fitness with and without
it is identical, and the flat peak-speed term equals the Jacobian-solve formulation.

Tiny sizes: populations of 16-48 designs, 44 task points, n_R 16 (the bench's), chunks of 8 so that the
second pass runs several chunks. Each test compiles a population-sized function (10-50 s on the shared 2
cores), hence all ``slow``.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import deltajax as dj
from deltajax.optimize import DesignSpace, Problem, evaluate_design, evaluate_population
from deltajax.optimize import objectives as O
from deltajax.optimize import screens as S
from deltajax.workspace import reconfigurable_reachable, resolve_redundancy

BOUNDS = {"R_min": [0.10, 0.20], "R_max": [0.30, 0.55], "platform_radius": [0.04, 0.09],
          "upper_arm": [0.14, 0.30], "forearm": [0.30, 0.55]}
SPACE = DesignSpace.from_bounds(dj.presets.franco2026(with_mass=True), BOUNDS, n_R=16)


@functools.lru_cache(maxsize=None)
def _problem(k_min=0.2, weights=None):
    cfg = {"workspace": {"n_r": 4, "n_phi": 2, "n_z": 4}, "task": {"n_r": 2, "n_phi": 6, "n_z": 3},
           "cycle": {"n_samples": 12, "n_R_operating": 2},
           "objectives": {"weights": weights or {"volume": 1.0, "peak_torque": 1.0, "peak_speed": 1.0}},
           "constraints": {"k_min": k_min, "max_arm_sum": 0.6}}
    pb = Problem.from_config(cfg, r_max=1.1, z_max=0.85)
    base = jax.jit(lambda g: evaluate_design(pb, SPACE.decode(g)))(jnp.asarray(SPACE.baseline_genes()))
    return pb.with_baseline({k: float(v) for k, v in base.items()})


# task points plus hard ones: on the z axis (two equal singular values), a hair off it, on the mirror plane
# y = 0 and near the reach boundary (stretched / folded chains, near-singular Jx and Jq)
TASK = O.cylinder_points(0.30, 0.10, 0.35, 2, 6, 3)  # the task points of _problem()
HARD = np.concatenate([TASK, [[0.0, 0.0, 0.30], [0.0, 0.0, 0.45], [1e-9, 0.0, 0.4], [0.0, -1e-12, 0.38],
                                        [0.25, 0.0, 0.55], [-0.3, 0.0, 0.25], [0.05, 0.05, 0.7], [0.0, 0.35, 0.1]]])


def _exact_covered(pb, designs, pts):
    """The exact sweep's flags: best feasible sample's value >= k_min (resolve_redundancy, all samples)."""
    def one(d):
        red = resolve_redundancy(d, pts, criterion=pb.index, b_v=pb.b_v, b_f=pb.b_f, beta=pb.beta)
        return red.ok & (jnp.where(red.ok, red.value, 0.0) - pb.k_min >= 0.0)
    return jax.vmap(one)(designs)


def _cover_fns(pb):
    exact = jax.jit(lambda G, P: _exact_covered(pb, jax.vmap(SPACE.decode)(G), P))
    screened = jax.jit(lambda G, P: S.task_cover(pb, jax.vmap(SPACE.decode)(G), P, chunk=8))
    return exact, screened


@functools.lru_cache(maxsize=None)
def _fns(k_min):
    """(problem, exact, screened) compiled once per k_min; k_min = 0.6 leaves most points to the second pass."""
    pb = _problem(k_min)
    return (pb,) + _cover_fns(pb)


def _genes(seed, n):
    g = np.array(jax.random.uniform(jax.random.PRNGKey(seed), (n, SPACE.dim), dtype=jnp.float64))
    g[0] = SPACE.baseline_genes()
    g[1] = 0.0  # corners of the box: extreme designs
    g[2] = 1.0
    return jnp.asarray(g)


@pytest.mark.slow
@pytest.mark.parametrize("k_min", [0.2, 0.6])
def test_task_cover_equals_the_exact_sweep_on_random_designs_and_hard_points(k_min):
    _, exact, screened = _fns(k_min)
    G = _genes(0, 48)
    pts = jnp.asarray(HARD)
    want = np.asarray(exact(G, pts))
    got = screened(G, pts)
    np.testing.assert_array_equal(np.asarray(got.covered), want)
    # the second pass really ran (several chunks) and stayed below the sweep
    assert int(got.n_rest) > 8 and int(got.n_first) + int(got.n_rest) < got.n_sweep
    assert 0 < want.mean() < 1  # both outcomes present


@pytest.mark.slow
@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), high=st.booleans(),
       offsets=st.lists(st.tuples(st.floats(-0.4, 0.4), st.floats(-0.4, 0.4), st.floats(0.05, 0.75)),
                        min_size=len(HARD), max_size=len(HARD)))
def test_task_cover_property_random_points_and_designs(seed, high, offsets):
    """Any designs, any points (a third of them put on or next to the z axis): the same flags as the sweep."""
    _, exact, screened = _fns(0.6 if high else 0.2)
    pts = np.asarray(offsets, dtype=float)
    pts[::3, :2] *= np.array([0.0, 1e-9])  # x = 0, y ~ 1e-10: on / a hair off the axis
    G = _genes(seed, 48)
    np.testing.assert_array_equal(np.asarray(screened(G, jnp.asarray(pts)).covered),
                                  np.asarray(exact(G, jnp.asarray(pts))))


@pytest.mark.slow
def test_reach_cover_equals_the_sweep_including_points_at_the_reach_limit():
    """Workspace points of random and extreme designs plus points placed exactly at (and 1e-9 m either side
    of) a chain's reach limit, where the closed-form exclusion is tightest."""
    G = _genes(7, 24)
    designs = jax.vmap(SPACE.decode)(G)
    ws = O.wedge_points(1.1, 0.85, 6, 2, 6)[0]
    d0 = SPACE.decode(G[0])  # the baseline: points straight below chain 0 at its full stretch L1 + L2
    L = float(d0.robot.upper_arm + d0.robot.forearm)
    edge = [[0.0, 0.0, L + e] for e in (-1e-9, 0.0, 1e-9)] + [[0.05, 0.0, L - 0.002 + e] for e in (-1e-9, 0.0, 1e-9)]
    pts = jnp.asarray(np.concatenate([ws, edge, HARD]))
    got = jax.jit(lambda ds: S.reach_cover(ds, pts, chunk=64))(designs)
    want = jax.jit(jax.vmap(lambda d: reconfigurable_reachable(d, pts)))(designs)
    np.testing.assert_array_equal(np.asarray(got.reachable), np.asarray(want))
    assert int(got.n_excluded) > 0 and int(got.n_rest) > 64  # all three routes taken, several chunks
    assert 0 < float(np.mean(np.asarray(want))) < 1


@pytest.mark.slow
def test_population_metrics_with_and_without_the_screens_are_identical():
    """The screened terms of evaluate_population (what make_fitness calls) equal the per-design sweeps bit for
    bit; the fitness is a fixed function of these metrics (the full fitness is compared by the bench)."""
    pb = _problem(0.2)  # the k_min = 0.2 problem of the task-cover tests (one lru_cache entry: ~6 CPU-s to build)
    G = _genes(3, 32)
    need = ("volume", "task_coverage")
    keys = set()

    def screened(G):
        m = evaluate_population(pb, SPACE, G, need)
        keys.update(m)  # what evaluate_population returns, seen while tracing (a separate eval_shape: ~3 CPU-s)
        return {k: m[k] for k in need}

    # only the screened terms leave the jit: the cycle dynamics are dead code (compile time)
    m_s = jax.jit(screened)(G)
    assert keys and "task_index_mean" not in keys  # not needed, hence not computed
    m_e = jax.jit(lambda G: {k: evaluate_population(pb, SPACE, G, need, screen=False)[k] for k in need})(G)
    for k in need:
        np.testing.assert_array_equal(np.asarray(m_s[k]), np.asarray(m_e[k]), err_msg=k)
    assert 0 < float(np.mean(np.asarray(m_s["task_coverage"]) == 1.0)) < 1
    # the task index terms, when needed, come from the exact sweep (the screen only decides coverage)
    assert "task_index_min" in jax.eval_shape(lambda G: evaluate_population(pb, SPACE, G, ("task_index_min",)), G)


def _ee_speed_solve(robot, pts, motor_speed):
    """Independent formulation: ik -> theta -> J = solve(Jx, Jq) (the public Jacobian) -> vertex speeds."""
    def one(p):
        sol = dj.ik(robot, p)
        theta = jnp.where(sol.ok, sol.theta, 0.0)
        J = dj.jacobian(robot, p, theta)[:, 1:]
        v = jnp.asarray(O.speed_vertices, J.dtype) @ J.T
        return jnp.max(jnp.sqrt(jnp.sum(v * v, axis=-1))) * motor_speed, sol.ok
    s, ok = jax.vmap(one)(pts)
    return jnp.where(jnp.sum(ok) > 0, jnp.sum(jnp.where(ok, s, 0.0)) / jnp.maximum(jnp.sum(ok), 1), 0.0), ok


@pytest.mark.slow
def test_peak_speed_term_equals_the_jacobian_solve():
    G = _genes(5, 16)
    pts = jnp.asarray(HARD)

    def both(g):
        d = SPACE.decode(g)
        out = []
        for R in (d.R_min, d.R_max):
            new = O._ee_speed(d.at(R), pts, 10.0)
            ref, ok = _ee_speed_solve(d.at(R), pts, 10.0)
            out.append((new, ref, jnp.sum(ok)))
        return out
    res = jax.jit(jax.vmap(both))(G)
    for new, ref, n in res:
        new, ref = np.asarray(new), np.asarray(ref)
        assert np.sum(np.asarray(n) > 0) >= 8  # most designs reach some of the points
        np.testing.assert_allclose(new, ref, rtol=1e-12, atol=0.0)  # 0 where none is reachable
