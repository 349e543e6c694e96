"""The workspace_grid JAX path: mirror half + kernel only on reach candidates, compacted into blocks.

Every result must be the kernel's own, bit for bit: :func:`deltajax.workspace.grid.box_fields` and
:func:`deltajax.workspace.evaluators.make_grid_evaluator` against :func:`deltajax.workspace.index_fields` (the
kernel jitted on its own over every point), including NaN patterns; and the pre-test
:func:`deltajax.workspace.grid.reach_candidate` never rejects a point the kernel accepts.

"The kernel's own" needs one precision: XLA:CPU compiles the kernel into a vectorised loop, and a batch whose
length is not a multiple of the vector width gets scalar code for its remainder, whose values differ by a few
1e-14 relative (the fast closed-form singular values amplify a rounding; measured: 1 520 of 43 320 values of
the 19 x 19 x 15 grid below when the kernel runs on its 5 415 points, none when it runs on them padded to 5 416
or 8 192). The compacted path always runs whole blocks, so the reference runs the kernel on the same points
padded to a whole number of blocks: bit for bit; and on the unpadded points: the same ok and NaN pattern,
values within 1e-12 relative.
"""

import functools
import os
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import deltajax as dj
from deltajax.workspace import FIELD_NAMES, index_fields, make_grid
from deltajax.workspace.evaluators import make_grid_evaluator
from deltajax.workspace.grid import box_fields, mirrored_point_indices, reach_candidate

ROBOT = dj.presets.franco2026(fixed_R=0.2)
ROBOT = getattr(ROBOT, "robot", ROBOT)


@functools.lru_cache(maxsize=None)
def _kernel():
    """The reference: the kernel over every point, each field its own output (as index_fields returns them)."""
    return jax.jit(lambda r, p: index_fields(r, p))


@functools.lru_cache(maxsize=None)
def _box(block):
    """box_fields on GRID (numpy arrays; shared by the tests)."""
    ok, vals = jax.jit(lambda r, x, y, z: box_fields(r, x, y, z, block=block))(ROBOT, GRID.x, GRID.y, GRID.z)
    return np.asarray(ok), np.asarray(vals)


_candidate = jax.jit(jax.vmap(reach_candidate, in_axes=(None, 0)))
_kernel_ok = jax.jit(jax.vmap(lambda r, p: mirrored_point_indices(r, p)[0], in_axes=(None, 0)))


def reference(robot, grid, pad_to=64):
    """(ok[nx, ny, nz], values[nx, ny, nz, 8]) of the kernel at every grid point, run on the points padded to a
    multiple of ``pad_to`` (vectorised code for every point, as in the compacted path's blocks)."""
    pts = grid.points()
    ok, f = _kernel()(robot, np.resize(pts, (-(-len(pts) // pad_to) * pad_to, 3)))
    vals = np.stack([np.asarray(f[n])[: len(pts)] for n in FIELD_NAMES], axis=-1)
    return np.asarray(ok)[: len(pts)].reshape(grid.shape), vals.reshape(grid.shape + (len(FIELD_NAMES),))


def assert_bitwise(ok, vals, ref_ok, ref_vals):
    assert np.array_equal(ok, ref_ok)
    assert vals.dtype == ref_vals.dtype and vals.shape == ref_vals.shape
    # bit patterns: the same numbers AND the same NaN (unreachable points are NaN, never numbers)
    assert np.array_equal(vals.view(np.uint64), ref_vals.view(np.uint64))


GRID = make_grid((-0.36, 0.36), (-0.36, 0.36), (0.0, 0.56), h=0.04)  # 19 x 19 x 15, mirror-symmetric


@pytest.mark.parametrize("block", [8, 64, 4096])
@pytest.mark.slow
def test_box_fields_is_the_kernel_bit_for_bit(block):
    """Compaction in blocks of any (vector-width) size (8: many loop trips; 4096: one padded block) gives the
    kernel's values at every point and ok=False / NaN everywhere else."""
    ref_ok, ref_vals = reference(ROBOT, GRID)
    assert 0 < ref_ok.sum() < ref_ok.size
    ok, vals = _box(block)
    assert_bitwise(ok, vals, ref_ok, ref_vals)


@pytest.mark.slow
def test_box_fields_matches_the_unpadded_kernel_to_rounding():
    """Against the kernel on the grid's 5 415 points as they are (its remainder in scalar code): the same ok
    and NaN pattern, values within 1e-12 relative; and a block of one point (scalar code throughout) too."""
    ref_ok, ref_vals = reference(ROBOT, GRID, pad_to=1)
    for block in (1, 64):
        ok, vals = _box(block)
        assert np.array_equal(ok, ref_ok) and np.array_equal(np.isnan(vals), np.isnan(ref_vals))
        fin = np.isfinite(ref_vals)
        np.testing.assert_allclose(vals[fin], ref_vals[fin], rtol=1e-12, atol=0)


@pytest.mark.slow
def test_box_fields_without_candidates_is_all_masked():
    """A box the robot cannot reach: zero loop trips, every point ok=False and NaN (never a number)."""
    x, y, z = np.linspace(0.5, 0.6, 3), np.linspace(0.5, 0.6, 4), np.linspace(0.0, 0.1, 2)
    ok, vals = jax.jit(lambda r, x, y, z: box_fields(r, x, y, z, block=8))(ROBOT, x, y, z)
    assert not np.asarray(ok).any() and np.isnan(np.asarray(vals)).all()
    assert not np.asarray(_candidate(ROBOT, np.stack(np.meshgrid(x, y, z, indexing="ij"), -1).reshape(-1, 3))).any()


@pytest.mark.slow
def test_reach_candidate_keeps_every_reachable_point_and_drops_most_others():
    """The pre-test is a superset of the kernel's ok on a dense random cloud (the compaction's premise), and
    it is selective (else the compaction would save nothing)."""
    rng = np.random.default_rng(0)
    pts = rng.uniform([-0.45, -0.45, -0.1], [0.45, 0.45, 0.65], (200_000, 3))
    ok = np.asarray(_kernel_ok(ROBOT, pts))
    cand = np.asarray(_candidate(ROBOT, pts))
    assert ok.sum() > 10_000
    assert not (ok & ~cand).any()
    assert cand.sum() < 1.02 * ok.sum()


def _boundary_points(robot, n, seed):
    """Points within ~1e-12 m of the kernel's reachable-set boundary (bisection along random rays from a
    reachable centre): where a pre-test without slack could disagree with the kernel by a rounding."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    c = np.array([0.0, 0.0, 0.35])
    lo, hi = np.zeros(n), np.full(n, 0.8)
    for _ in range(45):
        mid = 0.5 * (lo + hi)
        inside = np.asarray(_kernel_ok(robot, c + mid[:, None] * d))
        lo, hi = np.where(inside, mid, lo), np.where(inside, hi, mid)
    return np.concatenate([c + lo[:, None] * d, c + hi[:, None] * d])


@pytest.mark.slow
@settings(max_examples=4)
@given(seed=st.integers(0, 2**31 - 1), forearm=st.floats(0.3, 0.5), tmax=st.floats(0.8, 1.9))
def test_reach_candidate_is_a_superset_on_the_boundary(seed, forearm, tmax):
    """On both sides of the reach and joint-limit boundaries (within 1e-12 m), for other designs too."""
    robot = dj.Delta(base_radius=0.2, platform_radius=0.065, upper_arm=0.2, forearm=forearm, theta_min=-0.698,
                     theta_max=tmax)
    pts = _boundary_points(robot, 512, seed)
    ok = np.asarray(_kernel_ok(robot, pts))
    assert ok.any() and not ok.all()
    assert not (ok & ~np.asarray(_candidate(robot, pts))).any()


ASYM = make_grid((-0.36, 0.36), (-0.2, 0.36), (0.0, 0.56), h=0.04)  # not mirror-symmetric: the whole box
PLANES = 4  # x-planes per chunk: 19 planes = 4 chunks + a padded one of 3


@functools.lru_cache(maxsize=None)
def _evaluate(grid, mirror):
    """The job's evaluator over the whole grid, chunk by chunk (numpy (ok, values) on the grid's shape)."""
    ev = make_grid_evaluator(grid, jax.local_device_count(), planes=PLANES, b_v=2.0, b_f=4.2, beta=0.5,
                             mirror=mirror, block=64)
    nx, ny, nz = grid.shape
    oks, vals = [], []
    for a in range(0, nx, PLANES):
        b = min(nx, a + PLANES)
        ok, v = ev(ROBOT, a, b)
        oks.append(np.asarray(ok)[: (b - a) * ny * nz])
        vals.append(np.asarray(v)[: (b - a) * ny * nz])
    return np.concatenate(oks).reshape(grid.shape), np.concatenate(vals).reshape(grid.shape + (len(FIELD_NAMES),))


@pytest.mark.parametrize("grid, mirror", [(GRID, True), (GRID, False), (ASYM, True)])
@pytest.mark.slow
def test_grid_evaluator_is_the_kernel_bit_for_bit(grid, mirror):
    """The job's JAX evaluator (mirror half when the grid allows it, compaction, chunks of x-planes with a
    padded last chunk) equals the kernel at every point of the grid, bit for bit."""
    assert grid.mirror_symmetric == (grid is GRID)
    ref_ok, ref_vals = reference(ROBOT, grid)
    assert_bitwise(*_evaluate(grid, mirror), ref_ok, ref_vals)


@pytest.mark.slow
def test_mirror_half_is_a_copy_bit_for_bit():
    """Mirror halving changes nothing: the evaluator with and without it agree bit for bit (the kernel
    evaluates (x, |y|, z), so the y < 0 half it would compute equals the copied one), and the fields are
    bitwise symmetric."""
    (ok_m, v_m), (ok_f, v_f) = _evaluate(GRID, True), _evaluate(GRID, False)
    assert_bitwise(ok_m, v_m, ok_f, v_f)
    assert_bitwise(ok_m, v_m, ok_m[:, ::-1], v_m[:, ::-1])


def test_grid_evaluator_refuses_a_block_it_was_not_built_for():
    ev = make_grid_evaluator(GRID, 1, planes=PLANES, b_v=2.0, b_f=4.2, beta=0.5)
    with pytest.raises(ValueError, match="x-planes 0:5"):
        ev(ROBOT, 0, 5)


_TWO_DEVICES = r"""
import os, sys
import numpy as np, jax
jax.config.update("jax_enable_x64", True)
sys.path.insert(0, os.environ["TESTS"])
import test_workspace_grid_jax as t
assert jax.local_device_count() == 2
g = t.GRID
ref_ok, ref_vals = t.reference(t.ROBOT, g)
ev = t.make_grid_evaluator(g, 2, planes=5, b_v=2.0, b_f=4.2, beta=0.5, block=128)
n = g.shape[1] * g.shape[2]
parts = [ev(t.ROBOT, a, min(g.shape[0], a + 5)) for a in range(0, g.shape[0], 5)]
ok = np.concatenate([np.asarray(o)[: (min(g.shape[0], a + 5) - a) * n] for (o, _), a in zip(parts, range(0, 99, 5))])
v = np.concatenate([np.asarray(x)[: (min(g.shape[0], a + 5) - a) * n] for (_, x), a in zip(parts, range(0, 99, 5))])
t.assert_bitwise(ok.reshape(g.shape), v.reshape(ref_vals.shape), ref_ok, ref_vals)
print("SAME")
"""


@pytest.mark.slow
def test_grid_evaluator_on_two_devices_is_the_kernel_bit_for_bit(tmp_path):
    """The planes split over two (host) devices, each with its own loop trip count (shard_map)."""
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2",
               TESTS=str(Path(__file__).parent), JAX_PLATFORMS="cpu")
    out = subprocess.run([sys.executable, "-c", _TWO_DEVICES], env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "SAME" in out.stdout


def _float32(robot):
    """The robot as ``precision=float32`` builds it (every float leaf float32)."""
    return jax.tree.map(lambda a: np.float32(a) if np.issubdtype(np.asarray(a).dtype, np.floating) else a, robot)


@pytest.mark.parametrize("forearm, tmax", [(0.4, 1.92), (0.3, 0.8), (0.5, 1.9)])
@pytest.mark.slow
def test_reach_candidate_is_a_superset_in_float32(forearm, tmax):
    """precision=float32 (the throughput mode): roundings 1e9 x larger than in float64, so its own slacks
    (CANDIDATE_SLACK_F32); superset on both sides of the boundary (bisected in float32) and on a random cloud."""
    robot = _float32(dj.Delta(base_radius=0.2, platform_radius=0.065, upper_arm=0.2, forearm=forearm,
                              theta_min=-0.698, theta_max=tmax))
    rng = np.random.default_rng(7)
    d = rng.normal(size=(2048, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    c, lo, hi = np.array([0.0, 0.0, 0.35]), np.zeros(len(d)), np.full(len(d), 0.8)
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        inside = np.asarray(_kernel_ok(robot, (c + mid[:, None] * d).astype(np.float32)))
        lo, hi = np.where(inside, mid, lo), np.where(inside, hi, mid)
    cloud = rng.uniform([-0.45, -0.45, -0.1], [0.45, 0.45, 0.65], (50_000, 3))
    pts = np.concatenate([c + lo[:, None] * d, c + hi[:, None] * d, cloud]).astype(np.float32)
    ok = np.asarray(_kernel_ok(robot, pts))
    cand = np.asarray(_candidate(robot, pts))
    assert ok.dtype == bool and 0 < ok.sum() < len(pts)
    assert not (ok & ~cand).any()
    # reach only (joint limits not pre-tested in float32): 2.3x the reachable points of the preset design (more
    # where the joint limits exclude most of the reach), still not the whole box
    n_ok, n_cand = ok[-len(cloud):].sum(), cand[-len(cloud):].sum()
    assert n_cand < 0.6 * len(cloud), (n_ok, n_cand)
