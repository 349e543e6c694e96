"""The JAX kernel's blocked batches (map_points) and the singular-value tail's reciprocals."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import deltajax as dj
from deltajax.indices import map_points, point_indices, singular_values

jax.config.update("jax_enable_x64", True)


@pytest.fixture(scope="module")
def robot():
    return dj.presets.franco2026().at(0.3)


@pytest.mark.slow  # two compilations of the whole kernel
def test_map_points_equals_one_vmap(robot):
    """Blocks (with padding of the last one) give the plain vmap's values, shapes and NaN pattern."""
    rng = np.random.default_rng(1)
    pts = jnp.asarray(rng.uniform([-0.35, -0.35, 0.05], [0.35, 0.35, 0.6], (2 * 64 + 7, 3)))
    fn = lambda q: point_indices(robot, q)[1]  # noqa: E731
    a = jax.jit(lambda p: map_points(fn, p, block=64))(pts)
    b = jax.jit(jax.vmap(fn))(pts)
    assert a.singular_values.shape == (pts.shape[0], 3)
    for name, x, y in zip(a._fields, a, b):
        x, y = np.asarray(x), np.asarray(y)
        assert np.array_equal(np.isnan(x), np.isnan(y)), name
        m = np.isfinite(y)
        assert m.any() and (~np.isnan(y)).sum() < y.size, name  # mixed batch: reachable and unreachable
        np.testing.assert_allclose(x[m], y[m], rtol=1e-9, err_msg=name)


@pytest.mark.slow  # one compilation of the whole kernel
def test_map_points_small_batch_is_one_vmap(robot):
    pts = jnp.asarray([[0.0, 0.0, 0.3], [0.05, -0.02, 0.35]])
    out = jax.jit(lambda p: map_points(lambda q: point_indices(robot, q)[1], p, block=64))(pts)
    assert out.k_tilde.shape == (2,) and bool(jnp.all(jnp.isfinite(out.k_tilde)))


def _random_config(rng):
    u = rng.normal(size=(3, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, rng.uniform(0.2, 1.0, 3) * rng.choice([-1.0, 1.0], 3)


#: one compiled tail for both scales below (the scale is data, not part of the program)
_JACOBI_TAIL = jax.jit(lambda jx, d: singular_values(tuple(jx.ravel()), tuple(d), method="jacobi",
                                                     with_inverses=True))


@pytest.mark.parametrize("scale", [1.0, 1e-4])  # scale < 1: nearly singular Jq, the Jx side of the S/T choice
@pytest.mark.slow
def test_tail_reciprocals_match_svd(scale):
    rng = np.random.default_rng(7)
    for _ in range(20):
        jx, d = _random_config(rng)
        d = d * np.array([1.0, 1.0, scale])
        t = _JACOBI_TAIL(jnp.asarray(jx), jnp.asarray(d))
        ref = np.linalg.svd(np.linalg.solve(jx, np.diag(d)), compute_uv=False)
        np.testing.assert_allclose([t.s1, t.s2, t.s3], ref, rtol=1e-10)
        np.testing.assert_allclose(t.inv_s1, 1.0 / ref[0], rtol=1e-10)
        np.testing.assert_allclose(t.omega, np.prod(ref), rtol=1e-10)
        np.testing.assert_allclose(t.inv_omega, 1.0 / np.prod(ref), rtol=1e-10)


@pytest.mark.slow
def test_tail_singular_jx_is_inf_with_finite_gradient():
    """det Jx = 0 exactly: s1 = omega = inf, 1/s1 = 0, and the gradient of a finite output stays finite."""
    jx = (1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)  # two equal rows
    d = (0.5, 0.6, 0.7)
    t = jax.jit(lambda a: singular_values(jx, (a, 0.6, 0.7), with_inverses=True))(0.5)
    assert np.isinf(t.s1) and np.isinf(t.omega) and t.inv_s1 == 0.0 and t.inv_omega == 0.0

    def f(a):
        return singular_values(jx, (a, 0.6, 0.7), with_inverses=True).inv_s1

    assert np.isfinite(jax.jit(jax.grad(f))(0.5))
