"""Failure is data at every batch size: invalid designs, non-finite points/angles and failed IK give NaN (and
``ok=False``) from every public per-configuration function, vmapped at batch 1, 8 and 4096 jitted (1 and 4096 not), in
float32 and float64 (XLA:CPU's vectorised loops dropped NaN through ``jnp.minimum`` at 4096 but not at 1 or 8).

One compiled function per (function, dtype), always called at 4096 rows (the small batches are the first rows of
that batch, padded with the valid case). The un-jitted vmap runs at 1 row (XLA:CPU's scalar loops) and at 4096
(its vectorised loops, where the NaN was lost); 8 rows run the same vectorised loops as 4096, and each size costs
its own compilation of every primitive (~10 CPU-s per size un-jitted, 2026-12-06).
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import deltajax as dj
from deltajax import constraints as C
from deltajax.indices import point_kernel

from _programs import kept

BASE = dj.presets.franco2026(fixed_R=0.2)
LINKS = C.LinkModel(plate_overhang=0.03)
SPEC = C.GoodSpec(joints=C.JointModel(limit=1.2), links=LINKS)
GOOD = (0.2, 0.065, 0.2, 0.4)
P_OK = (0.0, 0.05, 0.4)
NAN = float("nan")
#: (design (R, r, L1, L2), p, theta or None for the IK's, valid). Row 0 is the valid case.
CASES = [
    (GOOD, P_OK, None, True),
    ((0.2, 0.065, 0.2, 0.0), P_OK, (0.3, 0.5, 0.7), False),      # forearm 0
    ((0.2, 0.065, -0.2, 0.4), P_OK, (0.3, 0.5, 0.7), False),     # negative upper arm
    ((NAN, 0.065, 0.2, 0.4), P_OK, (0.3, 0.5, 0.7), False),      # NaN base radius
    ((0.2, -0.01, 0.2, 0.4), P_OK, (0.3, 0.5, 0.7), False),      # negative platform radius
    (GOOD, (0.0, 0.0, 2.0), None, False),                        # IK fails: theta NaN
    (GOOD, P_OK, (NAN, 0.5, 0.7), False),                        # non-finite theta
    (GOOD, (NAN, 0.05, 0.4), (0.3, 0.5, 0.7), False),            # non-finite point
]
BIG = 4096
#: the un-jitted batch sizes: XLA:CPU's scalar loops and its vectorised ones (module docstring)
EAGER_ROWS = (1, BIG)


def _cast(tree, dtype):
    return jax.tree_util.tree_map(lambda v: jnp.asarray(v, dtype) if eqx.is_inexact_array(v) else v, tree)


def _robot(x, dtype):
    r = _cast(BASE, dtype)
    return eqx.tree_at(lambda d: (d.base_radius, d.platform_radius, d.upper_arm, d.forearm), r,
                       tuple(x[i].astype(dtype) for i in range(4)))


def _batch(n, dtype):
    """(x, p, theta, valid) with n rows: the cases in turn (row 0 valid), theta from the IK where None."""
    rows = [CASES[i % len(CASES)] for i in range(n)]
    x = jnp.asarray([c[0] for c in rows], dtype)
    p = jnp.asarray([c[1] for c in rows], dtype)
    ik_theta = jax.vmap(lambda x_, p_: dj.ik(_robot(x_, dtype), p_).theta)(x, p)
    th = jnp.asarray([c[2] if c[2] is not None else (0.0, 0.0, 0.0) for c in rows], dtype)
    use_ik = jnp.asarray([c[2] is None for c in rows])
    theta = jnp.where(use_ik[:, None], ik_theta, th)
    return x, p, theta, np.asarray([c[3] for c in rows])


# every public function of one configuration: f(robot, p, theta) -> pytree
FUNCS = {
    "ik": lambda r, p, t, s: dj.ik(r, p),
    "ik_cos_sin": lambda r, p, t, s: dj.ik_cos_sin(r, p),
    "fk": lambda r, p, t, s: dj.fk(r, t),
    "jacobian": lambda r, p, t, s: dj.jacobian(r, p, t),
    "jacobians": lambda r, p, t, s: dj.jacobians(r, p, t),
    "indices": lambda r, p, t, s: dj.indices(r, p, t),
    "indices_svd": lambda r, p, t, s: dj.indices(r, p, t, sv_method="svd"),
    "indices_full3x4": lambda r, p, t, s: dj.indices(r, p, t, matrix="full3x4"),
    "point_indices": lambda r, p, t, s: dj.point_indices(r, p)[1],
    "point_kernel": lambda r, p, t, s: point_kernel(r, p).indices,
    "classify_singularity": lambda r, p, t, s: dj.classify_singularity(r, p, t),
    "passive_angles": lambda r, p, t, s: dj.passive_angles(r, p, t),
    "forearm_units": lambda r, p, t, s: dj.kinematics.forearm_units(r, p, t),
    "elbows": lambda r, p, t, s: dj.elbows(r, t),
    "joint_angles": lambda r, p, t, s: dj.joint_angles(r, p, t, s.joints),
    "joint_margin": lambda r, p, t, s: C.joint_margin(r, p, t, s.joints),
    "interference": lambda r, p, t, s: dj.interference(r, p, t, s.links),
    "good_point": lambda r, p, t, s: dj.good_point(r, p, s),
}
# cases a function cannot see: fk takes no p, ik/point functions no theta, elbows neither p nor L2
BLIND = {"fk": {7}, "ik": {6}, "ik_cos_sin": {6}, "point_indices": {6}, "point_kernel": {6}, "good_point": {6},
         "elbows": {1, 7}}


def _per_row(names, dtype):
    """vmap over rows of {name: FUNCS[name](robot of the row, p, theta, spec)} in ``dtype``."""
    spec = _cast(SPEC, dtype)
    return jax.vmap(lambda x, p, t: {n: FUNCS[n](_robot(x, dtype), p, t, spec) for n in names})


@functools.lru_cache(maxsize=None)
def _compiled(dtype):
    """Every function in one program per dtype (one compilation), called at 4096 rows; kept across sessions
    (tests/_programs.py: tracing and lowering it took ~6 s of each session)."""
    return kept(jax.jit(_per_row(tuple(FUNCS), dtype)), f"nan_every_function_{jnp.dtype(dtype).name}", __file__)


def _check_all(out, valid, n):
    for name, o in out.items():
        _check(name, o, valid, n)


def _check(name, out, valid, n):
    """Every output of ``name`` on the first ``n`` rows: all finite-or-not-NaN where the row is valid, all NaN
    where it is not (``ok``-like booleans: True exactly where valid); rows of BLIND cases are skipped."""
    leaves = jax.tree_util.tree_leaves_with_path(out)
    fields = {jax.tree_util.keystr(k): np.asarray(v) for k, v in leaves}
    case = np.arange(n) % len(CASES)
    keep = ~np.isin(case, sorted(BLIND.get(name, ())))
    valid = np.asarray(valid[:n], bool)
    for key, v in fields.items():
        v = v[:n].reshape(n, -1)
        if np.issubdtype(v.dtype, np.floating):
            nan = np.isnan(v)
            wrong = keep & np.where(valid, nan.any(axis=1), ~nan.all(axis=1))
        elif v.dtype == np.bool_ and key.split(".")[-1].strip("[]'") in ("ok", "good", "reachable"):
            wrong = keep & (v.all(axis=1) != valid)
        else:
            continue
        rows = np.flatnonzero(wrong)
        assert rows.size == 0, (name, key, "cases", sorted(set(case[rows].tolist())), "rows", rows[:5].tolist(),
                                v[rows[:2]].tolist())


DTYPES = [jnp.float64, jnp.float32]


#: the functions whose old code lost NaN through min/max/clip or had no design guard (the un-jitted check of
#: every function at 1, 8 and 4096 rows is the slow test below)
EAGER_FAST = ("interference", "joint_margin", "passive_angles", "jacobian")


@functools.lru_cache(maxsize=None)
def _compiled_min_max():
    return jax.jit(_per_row(EAGER_FAST, jnp.float64))


@pytest.mark.slow
def test_min_max_functions_are_nan_at_4096_jitted():
    """The fast tier's share of the property below: the functions whose NaN was lost at 4096 rows."""
    x, p, t, valid = _batch(BIG, jnp.float64)
    _check_all(_compiled_min_max()(x, p, t), valid, BIG)


@pytest.mark.slow
@pytest.mark.parametrize("dtype", DTYPES, ids=["f64", "f32"])
def test_invalid_input_is_nan_at_every_batch_size(dtype):
    x, p, t, valid = _batch(BIG, dtype)
    _check_all(_compiled(dtype)(x, p, t), valid, BIG)                          # jit, 4096
    for n in (1, 8):
        # jit at 1 and 8 rows: the first n rows of the 4096-row program's input, the rest the valid case
        pad = lambda a: jnp.concatenate([a[:n], jnp.repeat(a[:1], BIG - n, axis=0)])  # noqa: E731
        out = _compiled(dtype)(pad(x), pad(p), pad(t))
        _check_all(jax.tree_util.tree_map(lambda v: v[:n], out), valid, n)
    if dtype == jnp.float64:  # un-jitted float64: every function (EAGER_FAST included), the test below
        return
    eager = _per_row(EAGER_FAST, dtype)
    for n in EAGER_ROWS:                                                       # no jit
        _check_all(eager(x[:n], p[:n], t[:n]), valid, n)


@pytest.mark.slow
def test_invalid_input_is_nan_unjitted_every_function():
    """Every function un-jitted in float64 (float32 un-jitted: the min/max functions above)."""
    dtype = jnp.float64
    x, p, t, valid = _batch(BIG, dtype)
    eager = _per_row(tuple(FUNCS), dtype)
    for n in EAGER_ROWS:
        _check_all(eager(x[:n], p[:n], t[:n]), valid, n)


MOTOR = C.Motor(peak_torque=3.8, rated_torque=1.27, max_speed=628.0, corner_speed=400.0, rotor_inertia=3.4e-5,
                efficiency=0.9)


@pytest.mark.parametrize("bad", [NAN, float("inf"), 0.0, -20.0])
def test_concrete_bad_gear_ratio_raises_naming_it(bad):
    robot = dj.presets.franco2026(fixed_R=0.2, with_mass=True)
    cyc = dj.adept_cycle((0, 0, 0.4), n_samples=9)
    for f in (C.picks_per_minute, C.drive_loads, C.cycle_rate):
        with pytest.raises(C.ConstraintError, match="gear_ratio"):
            f(robot, cyc, MOTOR, bad)


def _traced_drive(n_rows):
    """cycle_rate over n_rows (gear ratio, rated torque) pairs: the cases in turn, row 0 valid."""
    robot = dj.presets.franco2026(fixed_R=0.2, with_mass=True)
    cyc = dj.adept_cycle((0, 0, 0.4), n_samples=9)
    cases = [(20.0, 1.27, True), (NAN, 1.27, False), (float("inf"), 1.27, False), (0.0, 1.27, False),
             (-20.0, 1.27, False), (20.0, NAN, False), (20.0, 5.0, False), (20.0, 0.0, False)]  # 5 > peak
    rows = [cases[i % len(cases)] for i in range(n_rows)]
    n = jnp.asarray([c[0] for c in rows])
    rated = jnp.asarray([c[1] for c in rows])

    def one(n_, rated_):
        m = eqx.tree_at(lambda q: q.rated_torque, MOTOR, rated_)
        return C.cycle_rate(robot, cyc, m, n_, n_iter=20)

    return jax.jit(jax.vmap(one))(n, rated), np.asarray([c[2] for c in rows])


@pytest.mark.parametrize("n_rows", [1, 8, BIG])
@pytest.mark.slow
def test_traced_invalid_motor_or_gear_is_nan(n_rows):
    out, valid = _traced_drive(n_rows)
    ppm, ok = np.asarray(out.picks_per_min), np.asarray(out.loads.ok)
    assert np.all(np.isnan(ppm[~valid])) and not ok[~valid].any()
    assert np.all(np.isfinite(ppm[valid]) & (ppm[valid] > 0)) and ok[valid].all()


@pytest.mark.slow
def test_traced_invalid_limits_give_no_cycle_time():
    """Limits checks concrete values; traced ones (a batch of limits) that are NaN or <= 0 give a NaN cycle time
    and ok=False, never 0 cycles/min or a number."""
    robot = dj.presets.franco2026(fixed_R=0.2, with_mass=True)
    cycle = dj.adept_cycle((0.0, 0.0, 0.4))
    torques = jnp.asarray([20.0, jnp.nan, 0.0, -1.0])

    @jax.jit
    @jax.vmap
    def rate(torque):
        m = dj.cycle_metrics(robot, cycle, dj.Limits(torque=torque, speed=10.0))
        return m.cycles_per_minute, m.ok

    cpm, ok = rate(torques)
    assert bool(ok[0]) and np.isfinite(cpm[0]) and cpm[0] > 0
    assert not np.any(np.asarray(ok[1:])) and np.all(np.isnan(np.asarray(cpm[1:])))
