"""The one kernel and failure as data: accuracy against LAPACK and the NumPy
reference, finite and correct gradients, invalid inputs and designs, singularity detection through IK."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import deltajax as dj
from deltajax import reference as ref

FRANCO = dj.presets.franco2026()
ROBOT = FRANCO.at(0.3)
GEO = lambda rb: [float(v) for v in (rb.base_radius, rb.platform_radius, rb.upper_arm, rb.forearm,  # noqa: E731
                                      rb.theta_min, rb.theta_max)]
DESIGN_FIELDS = ("base_radius", "platform_radius", "upper_arm", "forearm", "theta_min", "theta_max")

_fast = jax.jit(jax.vmap(lambda rb, q: dj.point_indices(rb, q)[1], in_axes=(None, 0)))
_jac = jax.jit(jax.vmap(lambda rb, q: dj.point_indices(rb, q, sv_method="jacobi")[1], in_axes=(None, 0)))


def _points(n, seed, axis=0):
    rng = np.random.default_rng(seed)
    p = np.array([-0.35, -0.35, 0.05]) + np.array([0.7, 0.7, 0.55]) * rng.random((n, 3))
    p[:axis, :2] = 0.0
    return p


@pytest.mark.parametrize("R", [0.14, 0.2, 0.3])
@pytest.mark.slow
def test_fast_and_exact_singular_values_match_lapack_reference(R):
    rb = FRANCO.at(R)
    p = _points(3000, 1, axis=100)
    r = ref.point_indices(*GEO(rb), p)
    for f, tol_axis in ((_fast, 1e-11), (_jac, 1e-11)):
        ind = f(rb, jnp.asarray(p))
        sv = np.asarray(ind.singular_values)
        ok = np.isfinite(sv).all(axis=1)
        np.testing.assert_array_equal(ok, r["ok"])
        good = ok & (r["inv_cond"] > 1e-3)
        assert good[:100].sum() > 5 and good.sum() > 200
        rel = np.abs(sv - r["singular_values"]) / r["singular_values"]
        assert rel[100:][good[100:]].max() < 1e-9
        assert rel[:100][good[:100]].max() < tol_axis  # exactly on the axis: two equal singular values
        for name in ref.INDEX_NAMES:
            assert np.isnan(np.asarray(getattr(ind, name))[~ok]).all()


@pytest.mark.slow
def test_indices_of_invalid_inputs_are_nan():
    th = dj.ik(ROBOT, jnp.array([0.02, 0.01, 0.35])).theta
    for p, theta in ((jnp.array([0.02, 0.01, 0.35]), th.at[1].set(jnp.nan)),
                     (jnp.array([jnp.nan, 0.0, 0.3]), th), (jnp.array([jnp.inf, 0.0, 0.3]), th)):
        ind = dj.indices(ROBOT, p, theta)
        for name in ("inv_cond", "sigma_min_v", "sigma_min_f", "omega_v", "omega_f", "k_tilde", "imi"):
            assert np.isnan(float(getattr(ind, name))), name
        s = dj.classify_singularity(ROBOT, p, theta)
        assert not bool(s.ok) and not bool(s.singular) and int(s.jx_rank) == -1


@pytest.mark.slow
def test_invalid_designs_in_a_vmapped_batch_give_ok_false():
    base = ROBOT
    bad = [("upper_arm", -0.2), ("forearm", -0.4), ("base_radius", 0.0), ("base_radius", -0.1),
           ("theta_min", jnp.nan), ("theta_max", -2.0), ("upper_arm", 0.0)]
    leaves = {f: jnp.stack([getattr(base, f)] * (len(bad) + 1)) for f in DESIGN_FIELDS}
    for k, (f, v) in enumerate(bad):
        leaves[f] = leaves[f].at[k].set(v)
    robots = eqx.tree_at(lambda r: tuple(getattr(r, f) for f in DESIGN_FIELDS), base,
                         tuple(leaves[f] for f in DESIGN_FIELDS))
    p = jnp.array([0.02, 0.01, 0.35])
    sol = jax.vmap(lambda rb: dj.ik(rb, p))(robots)
    cs, ind = jax.vmap(lambda rb: dj.point_indices(rb, p))(robots)
    th = jax.vmap(lambda rb: dj.ik(base, p).theta)(robots)
    fwd = jax.vmap(dj.fk)(robots, th)
    assert not np.asarray(sol.ok)[:-1].any() and bool(sol.ok[-1])
    assert (np.asarray(sol.reason)[:-1] == dj.kinematics.IK_INVALID_DESIGN).all()
    assert np.isnan(np.asarray(ind.k_tilde)[:-1]).all() and np.isfinite(float(ind.k_tilde[-1]))
    assert not np.asarray(fwd.ok)[:-1].any() and bool(fwd.ok[-1])


@pytest.mark.slow
def test_fk_flags_joint_limit_violations():
    p = jnp.array([0.05, -0.1, 0.45])
    theta = dj.ik(ROBOT, p).theta
    tight = _with(ROBOT, "theta_max", float(jnp.max(theta)) - 0.01)
    f = dj.fk(tight, theta)
    assert bool(dj.fk(ROBOT, theta).ok)
    assert not bool(f.ok) and int(f.reason) == dj.kinematics.FK_JOINT_LIMIT
    np.testing.assert_allclose(np.asarray(f.p), np.asarray(p), atol=1e-12)  # the pose is still reported


@pytest.mark.slow
def test_stretched_and_folded_chains_detected_through_ik():
    # chain 0 exactly stretched (|C - A| = L1 + L2) or folded (L2 - L1, against the arm) in its plane, over R
    pts, Rs = [], []
    for R in np.linspace(0.14, 0.49, 36):
        for t in np.linspace(-0.69, 1.91, 60):
            for rad in (0.6, -0.2):
                pts.append([R - 0.065 + rad * math.cos(t), 0.0, rad * math.sin(t)])
                Rs.append(R)

    def one(R, q):
        rb = FRANCO.at(R)
        sol = dj.ik(rb, q)
        return sol.ok, dj.classify_singularity(rb, q, sol.theta), dj.classify_singularity(rb, q, sol.theta,
                                                                                            rank_tol=1e-9)
    ok, s, old = jax.jit(jax.vmap(one))(jnp.asarray(Rs), jnp.asarray(pts))
    ok = np.asarray(ok)
    assert ok.sum() >= 20
    assert np.asarray(s.singular)[ok].all() and (np.asarray(s.stretched_or_folded)[ok] >= 1).all()
    assert np.asarray(s.ok)[ok].all() and (np.asarray(s.jq_rank)[ok] < 3).all()
    assert not np.asarray(old.singular)[ok].all()  # the old absolute 1e-9 tolerance misses IK round-off


# -- gradients -----------------------------------------------------------------------------------------------

def _with(rb, field, v):
    return eqx.tree_at(lambda r: getattr(r, field), rb, jnp.asarray(v, jnp.float64))


@pytest.mark.slow
def test_forearm_gradient_of_k_tilde_matches_svd_and_central_difference():
    rb = dj.presets.franco2026(fixed_R=0.2)
    p = jnp.array([0.02744933, 0.04406817, 0.25658779])

    def k(L2, method):
        r2 = _with(rb, "forearm", L2)
        if method == "svd":
            return dj.indices(r2, p, dj.ik(r2, p).theta, sv_method="svd").k_tilde
        return dj.point_indices(r2, p, sv_method=method)[1].k_tilde

    g_svd = float(jax.grad(k)(jnp.asarray(0.4), "svd"))
    h = 1e-6
    fd = (float(k(0.4 + h, "fast")) - float(k(0.4 - h, "fast"))) / (2 * h)
    for m in ("fast", "jacobi"):
        g = float(jax.grad(k)(jnp.asarray(0.4), m))
        assert g == pytest.approx(g_svd, rel=1e-6) and g == pytest.approx(fd, rel=1e-5)
    assert g_svd == pytest.approx(0.25, abs=0.01)


_grad_all = jax.jit(jax.vmap(jax.grad(
    lambda leaves, q: dj.point_indices(eqx.tree_at(lambda r: tuple(getattr(r, f) for f in DESIGN_FIELDS), ROBOT,
                                                   leaves), q)[1].k_tilde), in_axes=(None, 0)))


def _leaves(rb):
    return tuple(getattr(rb, f) for f in DESIGN_FIELDS)


#: k~ of a batch of designs (ROBOT with the DESIGN_FIELDS replaced, one row each) at a batch of points
_k_design = jax.jit(jax.vmap(
    lambda leaves, q: dj.point_indices(eqx.tree_at(lambda r: _leaves(r), ROBOT, leaves), q)[1].k_tilde))


@pytest.mark.slow
def test_design_gradients_finite_over_an_8mm_grid():
    g = dj.workspace.make_grid((-0.4, 0.4), (-0.4, 0.4), (0.0, 0.592), 0.008)
    pts = g.points()
    reach = np.asarray(dj.workspace.reachable_mask(ROBOT, jnp.asarray(pts)))
    pts = pts[reach]
    assert len(pts) > 1000
    grads = _grad_all(_leaves(ROBOT), jnp.asarray(pts))
    for f, gv in zip(DESIGN_FIELDS, grads):
        assert np.isfinite(np.asarray(gv)).all(), f
    # and they match central differences where k~ is smooth (a sample of points, away from kinks): every
    # perturbed design at every sampled point in one compiled batch (192 eager point_indices calls took ~10 s)
    idx = np.random.default_rng(0).choice(len(pts), 12, replace=False)
    h = 1e-6
    steps = np.asarray([h, -h, 2 * h, -2 * h])
    base = np.asarray([float(v) for v in _leaves(ROBOT)])
    rows = [(j, i, d) for j in range(4) for i in idx for d in steps]          # (field, point, step)
    L = np.repeat(base[None], len(rows), axis=0)
    for r, (j, _, d) in enumerate(rows):
        L[r, j] += d
    kk = _k_design(tuple(jnp.asarray(L[:, c]) for c in range(len(DESIGN_FIELDS))),
                   jnp.asarray(pts[[i for _, i, _ in rows]]))
    kk = np.asarray(kk).reshape(4, len(idx), len(steps))
    for j, f in enumerate(DESIGN_FIELDS[:4]):
        for n, i in enumerate(idx):
            kp, km, kp2, km2 = kk[j, n]
            fd = (kp - km) / (2 * h)
            fd2 = (kp2 - km2) / (4 * h)
            if abs(fd - fd2) > 1e-5 * max(1.0, abs(fd)):
                continue  # a kink of k~ (piecewise quadratic) or of s1 = s2 within the step
            assert float(grads[j][i]) == pytest.approx(fd, rel=1e-4, abs=1e-6), (f, pts[i])


@pytest.mark.slow
def test_gradients_finite_on_fuzzed_mixed_batches():
    rng = np.random.default_rng(3)
    good = _points(64, 4, axis=8)
    rb = ROBOT
    L1, L2, Rr = 0.2, 0.4, 0.3 - 0.065
    boundary = np.array([[Rr + (L1 + L2) * math.cos(t), 0.0, (L1 + L2) * math.sin(t)] for t in (0.9, 1.1, 1.3)])
    weird = np.array([[1e154, 0, 0.3], [0, -1e200, 0.3], [0, 0, 1e300], [np.nan, 0, 0.3], [np.inf, 0, 0.3],
                      [0, 0, 0], [0, 0, 5.0], [0.235, 0.0, 0.0]])
    pts = jnp.asarray(np.concatenate([good, boundary, weird, rng.normal(0, 0.4, (32, 3))]))

    def masked_ik(leaves):
        r2 = eqx.tree_at(lambda r: _leaves(r), rb, leaves)
        sol = jax.vmap(lambda q: dj.ik(r2, q))(pts)
        return jnp.sum(jnp.where(sol.ok[:, None], sol.theta, 0.0))

    def ik_then_indices(leaves):  # the README pattern
        r2 = eqx.tree_at(lambda r: _leaves(r), rb, leaves)

        def one(q):
            sol = dj.ik(r2, q)
            ind = dj.indices(r2, q, sol.theta)
            return jnp.where(sol.ok, ind.k_tilde, 0.0)
        return jnp.sum(jax.vmap(one)(pts))

    def fields(leaves):
        r2 = eqx.tree_at(lambda r: _leaves(r), rb, leaves)
        ok, f = dj.workspace.index_fields(r2, pts)
        return jnp.sum(jnp.where(ok, f["k_tilde"] + f["inv_cond"], 0.0))

    for fn in (masked_ik, ik_then_indices, fields):
        g = jax.grad(fn)(_leaves(rb))
        for f, gv in zip(DESIGN_FIELDS, g):
            assert np.isfinite(float(gv)), (fn.__name__, f)
    gp = jax.grad(lambda q: jnp.sum(jnp.where(jax.vmap(lambda x: dj.ik(rb, x).ok)(q)[:, None],
                                              jax.vmap(lambda x: dj.ik(rb, x).theta)(q), 0.0)))(pts)
    assert np.isfinite(np.asarray(gp)).all()


@pytest.mark.slow
def test_on_axis_gradient_is_finite():
    p = jnp.array([0.0, 0.0, 0.35])
    for m in ("fast", "jacobi"):
        g = jax.grad(lambda L2: dj.point_indices(_with(ROBOT, "forearm", L2), p, sv_method=m)[1].k_tilde)(0.4)
        gp = jax.grad(lambda q: dj.point_indices(ROBOT, q, sv_method=m)[1].sigma_min_v)(p)
        assert np.isfinite(float(g)) and np.isfinite(np.asarray(gp)).all()
