"""The cheap-op arithmetic of deltajax.fastmath and the one-loop kernel it gives."""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import deltajax as dj
from deltajax.fastmath import fuse_outputs, recip, rsqrt, sqrt0
from deltajax.indices import point_indices

jax.config.update("jax_enable_x64", True)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_recip_rsqrt_sqrt0_within_two_ulp(dtype):
    x = np.exp(np.random.default_rng(3).uniform(-60.0, 60.0, 20000)).astype(dtype)
    eps = np.finfo(dtype).eps
    x64 = x.astype(np.float64)
    f = jax.jit(lambda v: (recip(v), rsqrt(v), sqrt0(v)))
    r, q, s = (np.asarray(a, np.float64) for a in f(x))
    assert np.max(np.abs(r * x64 - 1.0)) <= 2 * eps
    assert np.max(np.abs(q * np.sqrt(x64) - 1.0)) <= 2 * eps
    assert np.max(np.abs(s / np.sqrt(x64) - 1.0)) <= 2 * eps
    z = np.asarray(f(np.array([0.0, -1.0, -np.inf], dtype))[2])
    assert np.array_equal(z, [0.0, 0.0, 0.0])  # sqrt(max(x, 0))


def test_derivatives_are_the_analytic_ones_and_finite_at_zero():
    for x in (0.3, 2.0, 7.5):
        assert float(jax.grad(recip)(x)) == pytest.approx(-1.0 / x ** 2, rel=1e-14)
        assert float(jax.grad(rsqrt)(x)) == pytest.approx(-0.5 * x ** -1.5, rel=1e-14)
        assert float(jax.grad(sqrt0)(x)) == pytest.approx(0.5 / np.sqrt(x), rel=1e-14)
    assert float(jax.grad(sqrt0)(0.0)) == 0.0 and float(jax.grad(sqrt0)(-1.0)) == 0.0


@pytest.mark.slow
def test_fuse_outputs_is_the_identity_with_identity_tangents():
    def f(x):
        return fuse_outputs({"a": x * 2.0, "ok": x > 0, "n": jnp.int32(3), "v": jnp.stack([x, -x])})

    out = jax.vmap(f)(jnp.array([-1.0, 0.5]))
    np.testing.assert_array_equal(out["a"], [-2.0, 1.0])
    np.testing.assert_array_equal(out["ok"], [False, True])
    np.testing.assert_array_equal(out["n"], [3, 3])
    np.testing.assert_array_equal(out["v"], [[-1.0, 1.0], [0.5, -0.5]])
    assert float(jax.grad(lambda x: f(x)["a"] + f(x)["v"][1])(1.0)) == 1.0
    assert float(jax.jacfwd(lambda x: f(x)["a"])(1.0)) == 2.0


@pytest.mark.slow  # two compilations of the whole kernel
@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
def test_vmapped_kernel_is_one_loop_and_stays_in_its_dtype(dtype):
    """The issue-9 structure: every index of every point from one XLA loop (was ~65-90 loops); no float64 op in
    the float32 program."""
    robot = jax.tree_util.tree_map(lambda v: v.astype(dtype), dj.presets.franco2026().at(0.3))
    pts = jnp.zeros((4096, 3), dtype)
    hlo = jax.jit(jax.vmap(lambda q: point_indices(robot, q)[1])).lower(pts).compile().as_text()
    entry = hlo[hlo.index("ENTRY"):]
    big = [ln for ln in entry.splitlines() if re.search(r"= (?:\S+|\([^)]*\)) fusion\(", ln) and "4096" in ln]
    assert 1 <= sum("reduce" in ln for ln in big) <= 2  # the fused outputs
    assert len(big) <= 10, len(big)  # the point guard, the singular-value stack and the one kernel loop
    if dtype == jnp.float32:
        assert "f64" not in hlo
