"""The conformance table: every kernel function of every backend (:data:`deltajax.backends.KERNELS`) on the same
inputs, compared output by output against the JAX definition.

The inputs derive from one set of points: random ones over the franco2026 preset's box and invalid ones (outside
the reach, beyond the joint limits, on the z axis, huge, NaN and inf); a row's inputs are those points' values at
its step of the kernel (chain-local coordinates, loop closures, Jacobian blocks, their X matrices...), plus the
degenerate inputs of that step (a singular Jx, a zero d, a repeated eigenvalue, NaN). One adapter per backend and
row turns them into the backend's calling convention (Numba: scalars and tuples, one input at a time; JAX: one
jit(vmap); the reference: arrays) and its results into named arrays. Decisions (reach, ok, the side of the
singular-value formula) must be equal on every input; values are compared where the row says they are defined
(NaN/inf pattern exactly there) within the row's declared tolerances.
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import deltajax as dj
from deltajax import backends, reference
from deltajax.eigen3 import sym3_top2
from deltajax.indices import (INDEX_NAMES, Indices, criterion_of, indices_from_sv, k_tilde, point_kernel, point_value,
                              sigma_tilde, singular_values, singular_values_from_eig, sv_matrix)
from deltajax.jacobian import chain, jacobian_blocks, jq_theta, jx_det, jx_row
from deltajax.kinematics import (IK_JOINT_LIMIT, IK_NONFINITE, IK_OK, IK_UNREACHABLE, chain_local, ik_cos_sin,
                                 limit_terms, loop_closure, loop_vectors)
from deltajax.workspace import numba_kernel as nbk

ROBOT = dj.presets.franco2026(fixed_R=0.2)
R, r, L1, L2 = (float(v) for v in (ROBOT.base_radius, ROBOT.platform_radius, ROBOT.upper_arm, ROBOT.forearm))
TH_MIN, TH_MAX = float(ROBOT.theta_min), float(ROBOT.theta_max)
LIM_JAX = limit_terms(TH_MIN, TH_MAX)
LIM_NB = tuple(float(v) for v in nbk.limits_tuple(TH_MIN, TH_MAX))
B_V, B_F, BETA = 2.0, 4.2, 0.5
KT = tuple(float(v) for v in nbk.kt_tuple(B_V, B_F, BETA))
METHODS = (("jacobi", nbk.JACOBI), ("fast", nbk.FAST))


def _points() -> np.ndarray:
    """250 random points over the franco2026 box (above the base and below the reach too), 250 in its reachable
    core, and the invalid ones."""
    rng = np.random.default_rng(20261201)
    n = 250
    p = np.stack([rng.uniform(-0.45, 0.45, n), rng.uniform(-0.45, 0.45, n), rng.uniform(-0.3, 0.65, n)], -1)
    core = np.stack([rng.uniform(-0.25, 0.25, n), rng.uniform(-0.25, 0.25, n), rng.uniform(0.25, 0.55, n)], -1)
    special = [[0.0, 0.0, z] for z in np.linspace(0.1, 0.55, 6)]  # the z axis (repeated singular values)
    special += [[1e-9, -1e-9, 0.3], [0.3, 0.2, 0.1], [2.0, 0.0, 0.3], [1e200, 0.0, 0.3], [1e154, 0.1, 0.3],
                [0.0, 0.0, -0.3], [np.nan, 0.0, 0.3], [0.1, np.nan, 0.3], [np.inf, 0.1, 0.2], [0.1, -np.inf, 0.2],
                [0.1, 0.1, 0.0], [0.0, 0.0, 0.0]]
    return np.concatenate([p, core, np.array(special)])


P = _points()


def _jmap(fn, *cols):
    """``fn`` over the leading axis of ``cols`` in one jit(vmap); every leaf back as a NumPy array."""
    return jax.tree_util.tree_map(np.asarray, jax.jit(jax.vmap(fn))(*(jnp.asarray(c) for c in cols)))


def _nmap(fn, *cols, const=()) -> list[np.ndarray]:
    """The Numba function ``fn`` one input at a time (row k of every column, then ``const``): one array per output."""
    outs = [fn(*(c[k] for c in cols), *const) for k in range(len(cols[0]))]
    outs = [o if isinstance(o, tuple) else (o,) for o in outs]
    return [np.array(v) for v in zip(*outs)]


class Case(NamedTuple):
    """How a row of :data:`deltajax.backends.KERNELS` is run: its inputs and one adapter per backend.

    ``inputs()`` -> dict of input arrays; ``jax(inp)`` -> dict of named outputs (the definition);
    ``numba[name](fn, inp)`` / ``reference[name](fn, inp)`` -> dict of named outputs of that twin (a subset of
    the definition's names); ``exact``: outputs equal on every input (decisions); ``defined(inp, want)`` -> mask
    of the inputs where the other outputs have a value (NaN/inf pattern compared exactly there); ``ref_defined``
    the same for the reference where it defines fewer (default ``defined``).
    """

    inputs: Callable
    jax: Callable
    numba: dict
    reference: dict
    exact: tuple = ()
    defined: Callable = lambda inp, want: np.ones(len(next(iter(inp.values()))), bool)  # noqa: E731
    ref_defined: Callable | None = None


def _all(inp, want):
    return np.ones(len(next(iter(inp.values()))), bool)


def _finite(*keys):
    """Inputs whose every entry is finite: where a value is defined for steps that never see a non-finite input in
    the kernel (the loop closure boxes the point first; Numba's singular values give 0 or inf for a NaN entry, JAX
    NaN: neither is used)."""
    return lambda inp, want: np.all(np.column_stack([np.isfinite(inp[k]).reshape(len(inp[k]), -1) for k in keys]), 1)


def _where(key):
    return lambda inp, want: np.asarray(want[key], bool)


# -- inputs of each step, from the points -----------------------------------------------------------------------
def _per_chain():
    """(x, y, z, i) of every point for each chain i (the points repeated three times, chain 0's first)."""
    n = len(P)
    return {"x": np.tile(P[:, 0], 3), "y": np.tile(P[:, 1], 3), "z": np.tile(P[:, 2], 3),
            "i": np.repeat(np.arange(3), n)}


def _loop_inputs():
    """(dx, py, pz) of every chain at every point, plus a few raw non-finite / huge triples."""
    pc = _per_chain()
    cols = {k: [] for k in ("dx", "py", "pz")}
    for i in range(3):
        sel = pc["i"] == i
        px, py, pz = _jmap(lambda a, b, c: chain_local(a, b, c, i), pc["x"][sel], pc["y"][sel], pc["z"][sel])
        cols["dx"].append(px + r - R)
        cols["py"].append(py)
        cols["pz"].append(pz)
    raw = np.array([[np.inf, 0.0, 0.3], [np.nan, 0.0, 0.3], [1e300, 0.0, 0.3], [0.2, 1e155, 0.3], [0.0, 0.0, 0.0]])
    return {k: np.concatenate(v + [raw[:, j]]) for j, (k, v) in enumerate(cols.items())}


def _unit_inputs():
    """(ux, uy, uz, c, s) of the reachable chains (their loop closures) and random / non-finite ones."""
    li = _loop_inputs()
    lc = _jmap(lambda a, b, c: loop_closure(a, b, c, L1, L2, LIM_JAX), li["dx"], li["py"], li["pz"])
    reach = np.asarray(lc.reach)
    u = _jmap(lambda a, b, c, cs, sn: jnp.stack(loop_vectors(a, b, c, cs, sn, L1, L2)), li["dx"][reach],
              li["py"][reach], li["pz"][reach], lc.cos[reach], lc.sin[reach])
    rng = np.random.default_rng(7)
    extra = rng.normal(size=(20, 5))
    extra[:4] = [[np.nan, 0, 1, 1, 0], [np.inf, 0, 1, 0.5, 0.5], [0, 0, 0, 0, 0], [1e200, 1e200, 1, 1, 1]]
    cols = np.concatenate([np.column_stack([u, lc.cos[reach], lc.sin[reach]]), extra])
    return dict(zip(("ux", "uy", "uz", "c", "s"), cols.T)) | {"i": np.arange(len(cols)) % 3}


def _blocks():
    """(jx (n, 9), d (n, 3)) of the feasible points' Jacobian blocks, then degenerate ones: a singular Jx (det 0
    exactly), a zero d, the identity with distinct and with equal d, NaN and inf entries (both singular at once,
    0/0, is no input: M does not exist and no backend promises a value)."""
    jb = _jmap(lambda p: jacobian_blocks(p[0], p[1], p[2], R, r, L1, L2, LIM_JAX), np.nan_to_num(P))
    ok = np.asarray(jb.ok)
    jx = np.stack(jb.jx, -1)[ok]
    d = np.stack(jb.d, -1)[ok]
    eye = np.eye(3).ravel()
    flat = np.where(np.arange(9) % 3 == 2, 0.0, jx[0])  # forearms in one horizontal plane: det Jx = 0 exactly
    jx_x = np.array([flat, jx[1], eye, eye, np.where(np.arange(9) == 4, np.nan, eye), eye])
    d_x = np.array([d[0], [d[1, 0], 0.0, d[1, 2]], [0.3, 0.5, 0.7], [0.5, 0.5, 0.5], [0.3, 0.5, 0.7],
                    [np.inf, 0.5, 0.7]])
    return np.concatenate([jx, jx_x]), np.concatenate([d, d_x])


def _x_inputs():
    """sv_matrix's X (entries, c2, det) of the blocks, and random PSD matrices, a quarter with a repeated eigenvalue."""
    jx, d = _blocks()
    m = _jmap(lambda a, b: sv_matrix(tuple(a), tuple(b)), jx, d)
    fin = np.all(np.isfinite(np.column_stack(m[3:])), axis=1)
    x = np.column_stack(m[5:] + m[3:5])[fin]  # x00, x11, x22, x01, x02, x12, c2, det
    rng = np.random.default_rng(11)
    mats = []
    for k in range(60):
        Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        lam = rng.uniform(0.01, 3.0, 3)
        lam[1] = lam[0] if k % 4 == 0 else lam[1]
        lam[2] = 0.0 if k % 10 == 1 else lam[2]  # rank deficient
        A = Q @ np.diag(lam) @ Q.T
        c2 = A[1, 1] * A[2, 2] - A[1, 2] ** 2 + A[0, 0] * A[2, 2] - A[0, 2] ** 2 + A[0, 0] * A[1, 1] - A[0, 1] ** 2
        mats.append((A[0, 0], A[1, 1], A[2, 2], A[0, 1], A[0, 2], A[1, 2], c2, np.linalg.det(A)))
    mats.append((0.0,) * 8)  # the zero matrix
    return np.concatenate([x, np.array(mats)])


def _sv_inputs():
    """Sorted random singular values, then zeros, a repeated one, inf and NaN."""
    s = np.sort(np.random.default_rng(5).uniform(0.05, 5.0, (80, 3)), axis=1)[:, ::-1]
    s = np.concatenate([s, [[1.0, 0.5, 0.0], [2.0, 2.0, 2.0], [np.inf, 1.0, 0.5], [np.nan] * 3,
                            [1e-300, 1e-300, 1e-300]]])
    return {"s1": s[:, 0], "s2": s[:, 1], "s3": s[:, 2]}


# -- adapters ---------------------------------------------------------------------------------------------------
def _sv_ref(jx, d):
    with np.errstate(all="ignore"):
        return reference.singular_values(jx.reshape(-1, 3, 3), d)


def _ref_blocks(inp):
    with np.errstate(all="ignore"):  # NaN/inf points: the reference's floating-point warnings are expected here
        x, y, z = reference.chain_local(inp["p"])
        dx = x + r - R
        c, s, _, _, ok = reference.loop_closure(dx, y, z, L1, L2, TH_MIN, TH_MAX)
        Jx, d = reference.jacobian_blocks(*reference.loop_vectors(dx, y, z, c, s, L1, L2), c, s)
    return ok, Jx, d


def _quiet(f, *args):
    """The reference's ``f(*args)`` on non-finite inputs, without NumPy's expected floating-point warnings."""
    with np.errstate(all="ignore"):
        return f(*args)


def _feasible_where(want):
    return np.asarray(want["ok"], bool)


CASES: dict[str, Case] = {}

LIMITS = np.array([[TH_MIN, TH_MAX], [-np.inf, np.inf], [-math.pi, math.pi], [0.0, 2.0 * math.pi], [-0.5, 0.5],
                   [np.nan, 1.0], [-1.0, np.inf], [1.0, 1.5], [-2.0, 3.0]])
CASES["limit_terms"] = Case(
    inputs=lambda: {"lo": LIMITS[:, 0], "hi": LIMITS[:, 1]},
    jax=lambda inp: dict(zip(("cos_mid", "sin_mid", "cos_half"), _jmap(limit_terms, inp["lo"], inp["hi"]))),
    numba={"limits_tuple": lambda f, inp: dict(zip(("cos_mid", "sin_mid", "cos_half"), np.array(
        [f(a, b)[:3] for a, b in zip(inp["lo"], inp["hi"])]).T))},
    reference={})

CASES["chain_local"] = Case(
    inputs=_per_chain,
    jax=lambda inp: {k: np.concatenate([_jmap(lambda a, b, c: chain_local(a, b, c, i), *(
        inp[q][inp["i"] == i] for q in "xyz"))[j] for i in range(3)]) for j, k in enumerate(("px", "py", "pz"))},
    numba={"chain_local": lambda f, inp: dict(zip(("px", "py", "pz"), _nmap(
        f, inp["x"], inp["y"], inp["z"], inp["i"])))},
    reference={"chain_local": lambda f, inp: dict(zip(("px", "py", "pz"), (np.concatenate(
        [v[:, i] for i in range(3)]) for v in _quiet(f, P))))},
    # chain 0 is the identity in JAX and Numba; the reference rotates it too (inf * sin 0 = NaN)
    ref_defined=_finite("x", "y", "z"))

_LC = ("cos", "sin", "disc", "reach", "margin", "ok")
CASES["loop_closure"] = Case(
    inputs=_loop_inputs,
    jax=lambda inp: dict(zip(_LC, _jmap(lambda a, b, c: loop_closure(a, b, c, L1, L2, LIM_JAX),
                                        inp["dx"], inp["py"], inp["pz"]))),
    numba={"loop_closure": lambda f, inp: dict(zip(_LC, _nmap(f, inp["dx"], inp["py"], inp["pz"],
                                                               const=(L1, L2, LIM_NB))[:6]))},
    reference={"loop_closure": lambda f, inp: dict(zip(("cos", "sin", "disc", "reach", "ok"), f(
        inp["dx"], inp["py"], inp["pz"], L1, L2, TH_MIN, TH_MAX)))},
    exact=("reach", "ok"), defined=_where("reach"))

CASES["loop_vectors"] = Case(
    inputs=lambda: (lambda u: {"dx": u["ux"] * L2 + L1 * u["c"], "py": u["uy"] * L2, "pz": u["uz"] * L2 + L1 * u["s"],
                               "c": u["c"], "s": u["s"]})(_unit_inputs()),
    jax=lambda inp: dict(zip(("ux", "uy", "uz"), _jmap(lambda *a: loop_vectors(*a, L1, L2), *(
        inp[k] for k in ("dx", "py", "pz", "c", "s"))))),
    numba={"loop_vectors": lambda f, inp: dict(zip(("ux", "uy", "uz"), _nmap(f, *(
        inp[k] for k in ("dx", "py", "pz", "c", "s")), const=(L1, L2))))},
    reference={"loop_vectors": lambda f, inp: dict(zip(("ux", "uy", "uz"), f(*(
        inp[k] for k in ("dx", "py", "pz", "c", "s")), L1, L2)))})

CASES["jx_row"] = Case(
    inputs=_unit_inputs,
    jax=lambda inp: {k: np.concatenate([_jmap(lambda a, b, c: jx_row(a, b, c, i), *(
        inp[q][inp["i"] == i] for q in ("ux", "uy", "uz")))[j] for i in range(3)]) for j, k in enumerate("xyz")},
    numba={"jx_row": lambda f, inp: dict(zip("xyz", (np.concatenate([v[inp["i"] == i] for i in range(3)]) for v in
                                                     _nmap(f, inp["ux"], inp["uy"], inp["uz"], inp["i"]))))},
    reference={})

CASES["jq_theta"] = Case(
    inputs=_unit_inputs,
    jax=lambda inp: {"d": _jmap(jq_theta, inp["ux"], inp["uz"], inp["c"], inp["s"])},
    numba={"jq_theta": lambda f, inp: {"d": _nmap(f, inp["ux"], inp["uz"], inp["c"], inp["s"])[0]}},
    reference={})

CASES["jx_det"] = Case(
    inputs=lambda: {"jx": _blocks()[0]},
    jax=lambda inp: {"det": _jmap(lambda a: jx_det(*a), inp["jx"])},
    numba={"jx_det": lambda f, inp: {"det": _nmap(f, *inp["jx"].T)[0]}},
    reference={})

_CH = ("ok", "j0", "j1", "j2", "d")
CASES["chain"] = Case(
    inputs=_per_chain,
    jax=lambda inp: {k: np.concatenate([(lambda c: (c.loop.ok, *c.jx, c.d))(_jmap(
        lambda a, b, e: chain(a, b, e, R, r, L1, L2, LIM_JAX, i), *(inp[q][inp["i"] == i] for q in "xyz")))[j]
        for i in range(3)]) for j, k in enumerate(_CH)},
    numba={"chain": lambda f, inp: dict(zip(_CH, (np.concatenate([v[inp["i"] == i] for i in range(3)]) for v in _nmap(
        lambda x, y, z, i: f(x, y, z, R, r, L1, L2, LIM_NB, i), inp["x"], inp["y"], inp["z"], inp["i"])))),
        "chain_ok": lambda f, inp: {"ok": _nmap(lambda x, y, z, i: f(x, y, z, R, r, L1, L2, LIM_NB, i), inp["x"],
                                                inp["y"], inp["z"], inp["i"])[0]}},
    reference={}, exact=("ok",), defined=_where("ok"))

_JB = ("ok", "det", *(f"jx{k}" for k in range(9)), "d0", "d1", "d2")
CASES["jacobian_blocks"] = Case(
    inputs=lambda: {"p": P},
    jax=lambda inp: dict(zip(_JB, (lambda b: (b.ok, b.det_jx, *b.jx, *b.d))(_jmap(
        lambda p: jacobian_blocks(p[0], p[1], p[2], R, r, L1, L2, LIM_JAX), inp["p"])))),
    numba={"jacobian_blocks": lambda f, inp: dict(zip(_JB, _nmap(f, *inp["p"].T, const=(R, r, L1, L2, LIM_NB))))},
    reference={"jacobian_blocks": lambda f, inp: (lambda ok, Jx, d: {
        "ok": ok.all(axis=1), **{f"jx{k}": Jx.reshape(-1, 9)[:, k] for k in range(9)},
        **{f"d{k}": d[:, k] for k in range(3)}})(*_ref_blocks(inp))},
    exact=("ok",), defined=_where("ok"))

CASES["ik_cos_sin"] = Case(
    inputs=lambda: {"p": P},
    jax=lambda inp: {"ok": _jmap(lambda p: jnp.all(ik_cos_sin(ROBOT, p).ok), inp["p"])},
    numba={name: (lambda f, inp: {"ok": _nmap(f, *inp["p"].T, const=(R, r, L1, L2, LIM_NB))[0]})
           for name in ("ik_ok", "ik_ok_all")},
    reference={}, exact=("ok",))

_SVM = ("jx_side", "prod_d", "det_jx", "c2", "det_x", "x00", "x11", "x22", "x01", "x02", "x12")
CASES["sv_matrix"] = Case(
    inputs=lambda: dict(zip(("jx", "d"), _blocks())),
    jax=lambda inp: dict(zip(_SVM, _jmap(lambda a, b: sv_matrix(tuple(a), tuple(b)), inp["jx"], inp["d"]))),
    numba={"sv_matrix": lambda f, inp: dict(zip(_SVM, _nmap(f, *inp["jx"].T, *inp["d"].T)))},
    reference={}, exact=("jx_side",))


def _sym3_case(method, code):
    return Case(
        inputs=lambda: {"x": _x_inputs()},
        jax=lambda inp: dict(zip(("e1", "e2"), _jmap(lambda a: sym3_top2(*a, method), inp["x"]))),
        numba={"sym3_top2": lambda f, inp: dict(zip(("e1", "e2"), _nmap(f, *inp["x"].T, const=(code,))))},
        reference={})


def _sv_eig_inputs():
    jx, d = _blocks()
    m = _jmap(lambda a, b: sv_matrix(tuple(a), tuple(b)), jx, d)
    e = _jmap(lambda a: jnp.stack(sym3_top2(*a, "jacobi")), np.nan_to_num(np.column_stack(m[5:] + m[3:5])))
    return {"e1": e[:, 0], "e2": e[:, 1], "jx_side": m[0], "prod_d": m[1], "det_jx": m[2]}


_EIG = ("e1", "e2", "jx_side", "prod_d", "det_jx")
CASES["singular_values_from_eig"] = Case(
    inputs=_sv_eig_inputs,
    jax=lambda inp: dict(zip(("s1", "s2", "s3"), _jmap(singular_values_from_eig, *(inp[k] for k in _EIG)))),
    numba={"singular_values_from_eig": lambda f, inp: dict(zip(("s1", "s2", "s3"), _nmap(
        f, *(inp[k] for k in _EIG))))},
    reference={}, defined=_finite(*_EIG))


def _sv_case(method, code):
    return Case(
        inputs=lambda: dict(zip(("jx", "d"), _blocks())),
        jax=lambda inp: dict(zip(("s1", "s2", "s3"), _jmap(
            lambda a, b: singular_values(tuple(a), tuple(b), method=method), inp["jx"], inp["d"]))),
        numba={"singular_values": lambda f, inp: dict(zip(("s1", "s2", "s3"), _nmap(
            f, *inp["jx"].T, *inp["d"].T, const=(code,))))},
        defined=_finite("jx", "d"),
        reference={"singular_values": lambda f, inp: dict(zip(("s1", "s2", "s3"), (lambda s: s.T)(
            f(inp["jx"].reshape(-1, 3, 3), inp["d"]))))},
        # LAPACK's answer where M exists: Jx regular and every entry finite (NaN there, inf from the closed form)
        ref_defined=lambda inp, want: np.abs(_jmap(lambda a: jx_det(*a), inp["jx"])) > 0)


SIGMAS = np.concatenate([np.linspace(-0.5, 5.0, 60), [0.0, 1.0, 2.0, 2.1, 4.2, np.inf, np.nan, 1e300]])
CASES["sigma_tilde"] = Case(
    inputs=lambda: {"s": np.tile(SIGMAS, 2), "a": np.repeat([1.0, 2.1], len(SIGMAS)),
                    "b": np.repeat([2.0, 4.2], len(SIGMAS))},
    jax=lambda inp: {"v": _jmap(sigma_tilde, inp["s"], inp["a"], inp["b"])},
    numba={"sigma_tilde": lambda f, inp: {"v": _nmap(f, inp["s"], inp["a"], inp["b"])[0]}},
    reference={"sigma_tilde": lambda f, inp: {"v": f(inp["s"], inp["a"], inp["b"])}})

CASES["k_tilde"] = Case(
    inputs=lambda: {"sv": np.repeat(SIGMAS, len(SIGMAS)), "sf": np.tile(SIGMAS, len(SIGMAS))},
    jax=lambda inp: {"k": _jmap(lambda a, b: k_tilde(a, b, b_v=B_V, b_f=B_F, beta=BETA), inp["sv"],
                                inp["sf"])},
    numba={"k_tilde": lambda f, inp: {"k": _nmap(f, inp["sv"], inp["sf"], const=(KT,))[0]}},
    reference={"k_tilde": lambda f, inp: {"k": f(inp["sv"], inp["sf"], B_V, B_F, BETA)}})

CASES["indices_from_sv"] = Case(
    inputs=_sv_inputs,
    jax=lambda inp: (lambda ind: {n: getattr(ind, n) for n in INDEX_NAMES})(_jmap(
        lambda a, b, c: indices_from_sv(a, b, c, b_v=B_V, b_f=B_F, beta=BETA, raw_scale=L1 ** 3),
        inp["s1"], inp["s2"], inp["s3"])),
    numba={"indices_from_sv": lambda f, inp: dict(zip(INDEX_NAMES, _nmap(f, inp["s1"], inp["s2"], inp["s3"],
                                                                         const=(L1 ** 3, KT))))},
    reference={"indices_from_sv": lambda f, inp: f(np.column_stack([inp["s1"], inp["s2"], inp["s3"]]), L1 ** 3,
                                                   b_v=B_V, b_f=B_F, beta=BETA)})


def _nb_masked(vals):
    f, rest = vals[0].astype(bool), vals[1:]
    return f, [np.where(f, v, np.nan) for v in rest]


def _point_kernel_case(method, code):
    def jx(inp):
        k = _jmap(lambda p: point_kernel(ROBOT, p, sv_method=method, b_v=B_V, b_f=B_F, beta=BETA), inp["p"])
        return {"ok": k.ok & (k.det_jx != 0.0), **{n: getattr(k.indices, n) for n in INDEX_NAMES}}

    def nb(f, inp):
        ok, vals = _nb_masked(_nmap(f, *inp["p"].T, const=(R, r, L1, L2, LIM_NB, KT, code)))
        return {"ok": ok, **dict(zip(INDEX_NAMES, vals))}

    def ref(f, inp):
        with np.errstate(all="ignore"):
            out = f(R, r, L1, L2, TH_MIN, TH_MAX, inp["p"], b_v=B_V, b_f=B_F, beta=BETA)
        return {"ok": out["ok"], **{n: out[n] for n in INDEX_NAMES}}

    return Case(inputs=lambda: {"p": P}, jax=jx, numba={"point_kernel": nb}, reference={"point_indices": ref},
                exact=("ok",))


CRITERIA = ("k_tilde", "inv_cond")


def _point_value_case(method, code):
    def jx(inp):
        out = {}
        for c in CRITERIA:
            f, v = _jmap(lambda p: point_value(ROBOT, p, c, sv_method=method, b_v=B_V, b_f=B_F, beta=BETA), inp["p"])
            out |= {f"ok_{c}": f, c: np.where(f, v, np.nan)}
        return out

    def nb(f, inp):
        out = {}
        for c in CRITERIA:
            ok, (v,) = _nb_masked(_nmap(f, *inp["p"].T, const=(R, r, L1, L2, LIM_NB, KT, nbk.CRITERION[c], code)))
            out |= {f"ok_{c}": ok, c: v}
        return out

    def ref(f, inp):
        with np.errstate(all="ignore"):
            out = f(R, r, L1, L2, TH_MIN, TH_MAX, inp["p"], b_v=B_V, b_f=B_F, beta=BETA)
        return {c: np.where(out["ok"], out[c], np.nan) for c in CRITERIA}

    return Case(inputs=lambda: {"p": P}, jax=jx, numba={"point_value": nb}, reference={"point_indices": ref},
                exact=tuple(f"ok_{c}" for c in CRITERIA))


def _criterion_inputs():
    v = np.random.default_rng(3).uniform(0.0, 5.0, (len(INDEX_NAMES) * 4, len(INDEX_NAMES)))
    v[::5] = np.nan
    return {"v": v, "crit": np.arange(len(v)) % len(INDEX_NAMES)}


def _criterion_jax(inp):
    out = np.empty(len(inp["v"]))
    for k, name in enumerate(INDEX_NAMES):
        sel = inp["crit"] == k
        ind = Indices(*(jnp.asarray(inp["v"][sel, j]) for j in range(len(INDEX_NAMES))),
                                 singular_values=jnp.zeros((int(sel.sum()), 3)))
        out[sel] = np.asarray(criterion_of(ind, name))
    return {"value": out}


CASES["criterion_of"] = Case(
    inputs=_criterion_inputs, jax=_criterion_jax,
    numba={"criterion_of": lambda f, inp: {"value": _nmap(f, inp["crit"], *inp["v"].T)[0]}}, reference={})

#: rows run once per eigenvalue method (``sym3_top2``'s ``method``, the Numba code)
PER_METHOD = {"sym3_top2": _sym3_case, "singular_values": _sv_case, "point_kernel": _point_kernel_case,
              "point_value": _point_value_case}


def _cases():
    for row in backends.KERNELS:
        if row.name in PER_METHOD:
            for method, code in METHODS:
                name = f"{row.name}-{method}"
                yield pytest.param(row, PER_METHOD[row.name](method, code), id=name, marks=_tier(name))
        else:
            yield pytest.param(row, CASES.get(row.name), id=row.name, marks=_tier(row.name))


#: rows whose compilation takes over ~1 s on 2 cores: the full suite's tier (the fast tier keeps every other row)
SLOW_ROWS = ("singular_values_from_eig", "point_value-fast", "point_value-jacobi", "point_kernel-jacobi",
             "singular_values-jacobi", "chain", "sym3_top2-jacobi")


def _tier(name: str):
    return (pytest.mark.slow,) if name in SLOW_ROWS else ()


def _compare(want, got, mask, exact, rtol, what):
    assert set(got) <= set(want), f"{what}: outputs {sorted(set(got) - set(want))} not in the definition"
    assert got, f"{what}: compares nothing"
    for k, g in got.items():
        w, g = np.asarray(want[k]), np.asarray(g)
        assert w.shape == g.shape, f"{what} {k}: shape {g.shape} != {w.shape}"
        if k in exact or w.dtype == bool:
            np.testing.assert_array_equal(g.astype(w.dtype), w, err_msg=f"{what} {k}")
            continue
        # equal_nan / inf compared exactly; atol = rtol: the kernel's quantities are O(1) (metres of a ~1 m robot,
        # unit vectors, homogenised singular values), so near 0 the rounding is absolute
        np.testing.assert_allclose(g[mask], w[mask], rtol=rtol, atol=rtol, equal_nan=True, err_msg=f"{what} {k}")


@pytest.mark.parametrize("row,case", list(_cases()))
def test_backend_conforms_to_definition(row, case):
    """Every twin of the row agrees with the JAX definition on the row's inputs, output by output."""
    assert case is not None, f"row {row.name} of deltajax.backends.KERNELS has no case here"
    inp = case.inputs()
    want = case.jax(inp)
    mask = np.asarray(case.defined(inp, want), bool)
    for backend, adapters, rtol in (("numba", case.numba, row.numba_rtol),
                                    ("reference", case.reference, row.reference_rtol)):
        fns = dict(zip(getattr(row, backend), backends.resolve(row, backend)))
        assert set(adapters) == set(fns), f"{row.name}: {backend} adapters {sorted(adapters)} != row {sorted(fns)}"
        m = mask if backend == "numba" or case.ref_defined is None else mask & case.ref_defined(inp, want)
        assert m.sum() >= 8, f"{row.name}: {backend} compares values at {m.sum()} inputs only"
        for name, fn in fns.items():
            _compare(want, adapters[name](fn, inp), m, case.exact, rtol, f"{row.name}: {backend}.{name}")


def test_points_cover_every_input_class():
    """The shared points hold reachable ones, unreachable ones, joint-limit failures and non-finite ones."""
    reason = np.asarray(jax.jit(jax.vmap(lambda p: ik_cos_sin(ROBOT, p).reason))(jnp.asarray(P)))
    worst = reason.max(axis=1)
    for code in (IK_OK, IK_UNREACHABLE, IK_JOINT_LIMIT, IK_NONFINITE):
        assert (worst == code).sum() >= 2 if code != IK_OK else (reason == IK_OK).all(axis=1).sum() > 50, code
    assert (reason == IK_JOINT_LIMIT).any(axis=1).sum() > 10


@pytest.mark.slow
def test_oracles_agree_where_a_backend_has_no_twin():
    """The rows without a reference twin meet NumPy's own answer: det Jx (numpy.linalg.det) and the two largest
    eigenvalues of X (numpy.linalg.eigvalsh; the fast cubic to its ~sqrt(eps) split of a repeated pair)."""
    jx = _blocks()[0]
    fin = np.all(np.isfinite(jx), axis=1)
    det = _jmap(lambda a: jx_det(*a), jx[fin])
    np.testing.assert_allclose(det, np.linalg.det(jx[fin].reshape(-1, 3, 3)), rtol=1e-12, atol=1e-14)
    x = _x_inputs()
    A = np.stack([x[:, [0, 3, 4]], x[:, [3, 1, 5]], x[:, [4, 5, 2]]], axis=1)
    ev = np.linalg.eigvalsh(A)[:, ::-1][:, :2]
    for method, tol in (("jacobi", 1e-12), ("fast", 1e-7)):
        got = _jmap(lambda a: jnp.stack(sym3_top2(*a, method)), x)
        scale = np.abs(ev).max(axis=1, keepdims=True)  # a rank-deficient X: lambda_2 = 0 to rounding of lambda_1
        assert np.all(np.abs(got - ev) <= tol * np.maximum(np.abs(ev), scale)), method


def test_table_covers_every_kernel_function():
    """Every public function of the Numba mirror and of the reference is in a row (or declared not a kernel
    function), every name a row gives exists, and the JAX definition carries the row's name."""
    listed = {b: {n for row in backends.KERNELS for n in getattr(row, b)} for b in ("numba", "reference")}
    for backend, module in (("numba", nbk), ("reference", reference)):
        public = set(module.__all__) - backends.EXCLUDED[backend]
        assert public - listed[backend] == set(), f"{backend} functions in no row of deltajax.backends.KERNELS"
        assert backends.EXCLUDED[backend] <= set(module.__all__), f"{backend}: excluded names that do not exist"
        assert listed[backend] <= set(module.__all__), f"{backend}: rows name non-public functions"
    names = [row.name for row in backends.KERNELS]
    assert len(names) == len(set(names))
    for row in backends.KERNELS:
        for backend in backends.BACKENDS:
            assert all(callable(f) for f in backends.resolve(row, backend))
        assert row.jax.endswith(f":{row.name}"), row
        assert bool(row.why_none) == (not row.numba or not row.reference), f"{row.name}: why_none"
        assert row.why_rtol
        assert row.name in CASES or row.name in PER_METHOD, f"{row.name}: no case in this file"
    assert reference.INDEX_NAMES == INDEX_NAMES
    with pytest.raises(AttributeError):
        backends.resolve(backends.Kernel("nope", "deltajax.indices:nope", numba=("nope",)), "jax")
