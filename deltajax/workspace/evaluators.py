"""The whole-plane kernels of a sharded grid job (``workspace_grid``): one call evaluates a block of x-planes.

- :func:`make_grid_evaluator`: the JAX path (mirror half, kernel only on reach candidates compacted into
  fixed-size blocks, planes split over devices; unchanged on a GPU);
- :func:`make_numba_evaluator`: the Numba path, the same call on :func:`deltajax.workspace.driver.fixed_workspace`;
- :func:`make_evaluator`: the previous JAX path (every point of the box; kept for bench_multidevice and as
  the benchmarks' baseline).
"""

from __future__ import annotations

import functools
from typing import Optional

import numpy as np
import jax
import jax.numpy as jnp
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P

from .driver import fixed_workspace
from .grid import box_fields, FIELD_NAMES, Grid, index_fields

__all__ = ["make_evaluator", "make_grid_evaluator", "make_numba_evaluator", "GRID_BLOCK"]


# -- whole-plane kernels of a sharded grid (workspace_grid) ----------------------------------------------------

@functools.lru_cache(maxsize=8)  # one jitted function per setting: repeated runs in a process compile once
def make_evaluator(n_devices: int, *, b_v: float, b_f: float, beta: float):
    """The JAX kernel of ``workspace_grid``: a jitted ``f(robot, points[n, 3]) -> (ok[n], values[n, n_index])``
    sharded over ``n_devices`` devices.

    ``n`` must be a multiple of ``n_devices``; the points are split along their first axis, the robot is
    replicated. Per-point results do not depend on the split (elementwise kernel).
    """
    devices = jax.local_devices()[:n_devices]
    mesh = Mesh(np.asarray(devices), ("d",))
    rows = NamedSharding(mesh, P("d", None))
    flat = NamedSharding(mesh, P("d"))
    repl = NamedSharding(mesh, P())

    def f(robot, pts):
        ok, fields = index_fields(robot, pts, b_v=b_v, b_f=b_f, beta=beta)
        return ok, jnp.stack([fields[n] for n in FIELD_NAMES], axis=-1)

    jf = jax.jit(f, out_shardings=(flat, rows))

    def evaluate(robot, pts):
        robot = jax.device_put(robot, repl)
        return jf(robot, jax.device_put(pts, rows))

    return evaluate


def _shard_map(f, mesh, in_specs, out_specs):
    """``shard_map`` without the replication check (each device's loop runs its own trip count)."""
    if hasattr(jax, "shard_map"):
        return jax.shard_map(f, mesh=mesh, in_specs=in_specs, out_specs=out_specs, check_vma=False)
    from jax.experimental.shard_map import shard_map  # jax < 0.7

    return shard_map(f, mesh=mesh, in_specs=in_specs, out_specs=out_specs, check_rep=False)


@functools.lru_cache(maxsize=8)  # one jitted program per setting (the grid's axes are arguments)
def _half_box_program(n_devices: int, j0: int, block: int, b_v: float, b_f: float, beta: float):
    """Jitted ``f(robot, xs[K], ys_half[nyh], zs[nz]) -> (ok[K ny nz], values[K ny nz, n_index])``: the x-planes
    ``xs`` split over ``n_devices`` devices (``K`` a multiple of it), each device evaluating its planes' half
    y >= 0 with :func:`deltajax.workspace.grid.box_fields` and copying the other half from it (rows
    ``j < j0`` are the images of rows ``ny - 1 - j``; ``j0 = 0``: no mirror half)."""
    mesh = Mesh(np.asarray(jax.local_devices()[:n_devices]), ("d",))

    def local(robot, xs, ys, zs):
        ok, vals = box_fields(robot, xs, ys, zs, block=block, b_v=b_v, b_f=b_f, beta=beta)
        if j0:  # the mirror images: bit for bit the kernel's values there (it evaluates (x, |y|, z))
            ok = jnp.concatenate([ok[:, ::-1][:, :j0], ok], axis=1)
            vals = jnp.concatenate([vals[:, ::-1][:, :j0], vals], axis=1)
        return ok.reshape(-1), vals.reshape(-1, vals.shape[-1])

    f = _shard_map(local, mesh, (P(), P("d"), P(), P()), (P("d"), P("d")))
    return jax.jit(f), mesh


#: points per kernel block of :func:`make_grid_evaluator` on the CPU (an accelerator gets 64 times more)
GRID_BLOCK = 4096


def make_grid_evaluator(grid: Grid, n_devices: int, *, planes: int, b_v: float, b_f: float, beta: float,
                        dtype=np.float64, mirror: bool = True, block: Optional[int] = None):
    """The JAX kernel of ``workspace_grid``: ``f(robot, a, b) -> (ok[n], values[n, n_index])`` for the x-planes
    ``a:b`` (at most ``planes`` of them) of ``grid``, the rows of those planes first (x-major, z fastest; the
    rest is padding, n = K ny nz with K = ``planes`` rounded up to a multiple of ``n_devices``).

    The kernel's values bit for bit (those of :func:`deltajax.workspace.index_fields` over the same points in
    whole vector-width batches; tests/test_workspace_grid_jax.py) -- :func:`make_evaluator`'s in-jit stack of the
    outputs compiles the kernel differently and differs at some points by <= ~6e-13 relative -- but the work
    follows the reachable points, as the Numba path's does: the planes are split over the devices; each evaluates only the
    y >= 0 half when the grid is mirror-symmetric (``mirror``; the kernel evaluates (x, |y|, z), so the other
    half is a copy), and runs the full kernel only on the points that pass the cheap
    :func:`deltajax.workspace.grid.reach_candidate` test, compacted into blocks of ``block`` points (static
    shapes: one compilation serves every chunk; unchanged on a GPU). Unreachable points stay ``ok=False`` and
    NaN.
    """
    nx, ny, nz = grid.shape
    j0 = ny // 2 if (mirror and grid.mirror_symmetric) else 0
    if block is None:
        block = GRID_BLOCK if jax.default_backend() == "cpu" else 64 * GRID_BLOCK
    K = -(-int(planes) // n_devices) * n_devices
    program, mesh = _half_box_program(n_devices, j0, int(block), float(b_v), float(b_f), float(beta))
    repl, split = NamedSharding(mesh, P()), NamedSharding(mesh, P("d"))
    gx = np.asarray(grid.x, dtype)
    ys = jax.device_put(np.asarray(grid.y[j0:], dtype), repl)
    zs = jax.device_put(np.asarray(grid.z, dtype), repl)

    def evaluate(robot, a: int, b: int):
        if not 0 <= a < b <= min(nx, a + K):
            raise ValueError(f"x-planes {a}:{b} are not a block of at most {K} planes of a grid of {nx}")
        xs = gx[np.minimum(np.arange(a, a + K), b - 1)]  # padding: copies of the last plane
        return program(jax.device_put(robot, repl), jax.device_put(xs, split), ys, zs)

    return evaluate


def make_numba_evaluator(grid, *, b_v: float, b_f: float, beta: float):
    """The Numba kernel of ``workspace_grid``: ``f(robot, a, b) -> (ok[n], values[n, n_index])`` for the x-planes
    ``a:b`` of ``grid``, on the CPU threads of :func:`fixed_workspace` (Numba, ``NUMBA_NUM_THREADS``; float64)."""
    def evaluate(robot, a: int, b: int):
        # the same coordinate values as the full grid (sliced, not rebuilt), so shards see identical points
        sub = Grid(x=grid.x[a:b], y=grid.y, z=grid.z, h=grid.h, bounds=grid.bounds)
        job = fixed_workspace(robot, sub, fields=True, b_v=b_v, b_f=b_f, beta=beta, chunk_size=sub.n_points,
                              mirror=True)
        vals = np.stack([job.fields[n] for n in FIELD_NAMES], axis=-1)
        return job.ok.reshape(-1), vals.reshape(-1, len(FIELD_NAMES))

    return evaluate
