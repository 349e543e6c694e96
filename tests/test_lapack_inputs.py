"""LAPACK never sees a non-finite matrix: its SVD prints "** On entry to DLASCL parameter number 4 had an illegal
value" on stdout for inf entries (e.g. a solve through a singular Jx); the public paths mask the input so the
output is NaN and nothing is printed."""

import jax
import jax.numpy as jnp
import numpy as np

import deltajax as dj
from deltajax.indices import singular_values
from deltajax import reference


def test_singular_values_of_non_finite_matrices_are_nan_and_silent(capfd):
    M = jnp.stack([jnp.eye(3), jnp.full((3, 3), jnp.inf), jnp.eye(3).at[0, 1].set(jnp.nan), 2 * jnp.eye(3)])
    s = np.asarray(jax.vmap(singular_values)(M))
    s1 = np.asarray(singular_values(jnp.full((3, 4), -jnp.inf)))
    out = capfd.readouterr()
    assert "DLASCL" not in out.out + out.err
    np.testing.assert_allclose(s[[0, 3]], [[1, 1, 1], [2, 2, 2]])
    assert np.isnan(s[1:3]).all() and np.isnan(s1).all()


def test_reference_singular_values_of_an_overflowing_solve_are_nan_and_silent(capfd):
    Jx = np.stack([np.eye(3), np.diag([1.0, 1.0, 1e-300])])   # det > 0, but the solve overflows to inf
    d = np.array([[1.0, 2.0, 3.0], [1.0, 1.0, 1e10]])
    s = reference.singular_values(Jx, d)
    out = capfd.readouterr()
    assert "DLASCL" not in out.out + out.err
    np.testing.assert_allclose(s[0], [3, 2, 1])
    assert np.isnan(s[1]).all()
