"""Every differentiable public function composes: jit(vmap(grad(f))) over the design lengths (R, r, L1, L2) and
the point compiles and returns in seconds at toy size, with finite gradients at a regular configuration.

It runs in a subprocess under a wall-clock bound: a program that never returns (jit(vmap(grad(k_tilde))) ran for
minutes on 4 points while the bit-trick reciprocals of deltajax.eigen3 were in the differentiated program) fails
the test instead of hanging the suite. The subprocess uses the session's persistent XLA cache (tests/conftest.py):
a program the library's code has not changed is read back rather than compiled again (~50 s of XLA compilation
on 2 cores, the suite's second-slowest test); a changed library gives another program, which compiles and is
checked in full. The run time (the bound asserted) is measured either way.
"""

import os
import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent('''
    import time
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np
    jax.config.update("jax_enable_x64", True)
    import deltajax as dj
    from deltajax import constraints as C

    BASE = dj.presets.franco2026(fixed_R=0.2)
    SPEC = C.GoodSpec(joints=C.JointModel(limit=1.2), links=C.LinkModel(plate_overhang=0.03))

    def robot(x):
        return eqx.tree_at(lambda d: (d.base_radius, d.platform_radius, d.upper_arm, d.forearm), BASE,
                           (x[0], x[1], x[2], x[3]))

    def th(x, p):
        return dj.ik(robot(x), p).theta

    F = {
        "ik": lambda x, p: jnp.sum(th(x, p)),
        "fk": lambda x, p: jnp.sum(dj.fk(robot(x), jax.lax.stop_gradient(th(x, p))).p),
        "jacobian": lambda x, p: jnp.sum(dj.jacobian(robot(x), p, th(x, p))),
        "indices_k_tilde": lambda x, p: dj.indices(robot(x), p, th(x, p)).k_tilde,
        "indices_fast": lambda x, p: dj.indices(robot(x), p, th(x, p), sv_method="fast").inv_cond,
        "indices_svd": lambda x, p: dj.indices(robot(x), p, th(x, p), sv_method="svd").k_tilde,
        "point_indices": lambda x, p: dj.point_indices(robot(x), p)[1].k_tilde,
        "passive_angles": lambda x, p: jnp.sum(dj.passive_angles(robot(x), p, th(x, p))[1]),
        "joint_margin": lambda x, p: C.joint_margin(robot(x), p, th(x, p), SPEC.joints),
        "interference": lambda x, p: dj.interference(robot(x), p, th(x, p), SPEC.links).margin,
        "plate": lambda x, p: dj.interference(robot(x), p, th(x, p), SPEC.links).base_plate,
        "good_point": lambda x, p: dj.good_point(robot(x), p, SPEC).interference_margin,
    }
    g = jax.jit(jax.vmap(lambda x, p: {k: jax.grad(f, argnums=(0, 1))(x, p) for k, f in F.items()}))
    x = jnp.tile(jnp.array([0.2, 0.065, 0.2, 0.4]), (4, 1))
    p = jnp.tile(jnp.array([0.0, 0.05, 0.4]), (4, 1))
    t0 = time.time()
    c = g.lower(x, p).compile()
    t1 = time.time()
    out = jax.block_until_ready(c(x, p))
    t2 = time.time()
    bad = [k for k, v in out.items() if not all(np.all(np.isfinite(np.asarray(a))) for a in v)]
    print("compile", round(t1 - t0, 1), "run", round(t2 - t1, 3), "non-finite", bad, flush=True)
    assert not bad, bad
    assert t2 - t1 < 10.0, t2 - t1
    print("OK")
''')


@pytest.mark.slow
def test_jit_vmap_grad_of_every_differentiable_public_function_returns():
    from toy_jobs import JAX_CACHE

    # JAX's own variable for jax_compilation_cache_dir; the threshold (JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS)
    # is the session's, set by tests/conftest.py in os.environ
    env = {**os.environ, "JAX_COMPILATION_CACHE_DIR": JAX_CACHE}
    r = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=180, env=env)
    assert r.returncode == 0 and "OK" in r.stdout, r.stdout[-2000:] + r.stderr[-3000:]
