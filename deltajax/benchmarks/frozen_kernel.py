"""Frozen copy of the kernel as of main 9f54c88 (2026-12-01), the baseline of ``bench_kernel`` and
the kernel benchmarks (the old kernel kept as their yardstick). Not used by
the library; do not fix or share code with it, it is the yardstick."""

from __future__ import annotations

import jax.numpy as jnp

from ..geometry import CHAIN_ANGLES
from ..indices import Indices, k_tilde
from ..kinematics import IKCosSin

import math

__all__ = ["to_chain_frames", "ik_cos_sin", "singular_values_closed_form", "indices_from_singular_values", "point_indices",
           "redundancy_kernel", "mirrored_point_indices", "ik_cos_sin_result"]

_COS_A = tuple(math.cos(a) for a in CHAIN_ANGLES)
_SIN_A = tuple(math.sin(a) for a in CHAIN_ANGLES)


def _rot_cols(dtype):
    return jnp.asarray(_COS_A, dtype=dtype), jnp.asarray(_SIN_A, dtype=dtype)


def to_chain_frames(p):
    ca, sa = _rot_cols(p.dtype)
    px = ca * p[0] + sa * p[1]
    py = -sa * p[0] + ca * p[1]
    pz = jnp.broadcast_to(p[2], (3,))
    return jnp.stack([px, py, pz], axis=-1)


def _from_chain_frames(v_local):
    ca, sa = _rot_cols(v_local.dtype)
    x = ca * v_local[:, 0] - sa * v_local[:, 1]
    y = sa * v_local[:, 0] + ca * v_local[:, 1]
    return jnp.stack([x, y, v_local[:, 2]], axis=-1)


def _within_limits(c, s, lo, hi):
    finite = jnp.isfinite(lo) & jnp.isfinite(hi)
    mid = jnp.where(finite, 0.5 * (lo + hi), 0.0)
    half = jnp.where(finite, 0.5 * (hi - lo), 0.0)
    inside = c * jnp.cos(mid) + s * jnp.sin(mid) >= jnp.cos(half)
    return inside | ~finite


def ik_cos_sin(robot, p):
    p = jnp.asarray(p)
    dtype = jnp.result_type(p.dtype, robot.upper_arm.dtype)
    p = p.astype(dtype)
    finite_p = jnp.all(jnp.isfinite(p))
    p_safe = jnp.where(finite_p, p, jnp.zeros_like(p))
    loc = to_chain_frames(p_safe)
    L1, L2 = robot.upper_arm, robot.forearm
    dx = loc[:, 0] + robot.platform_radius - robot.base_radius
    py, pz = loc[:, 1], loc[:, 2]
    rho2 = dx * dx + pz * pz
    m = (rho2 + py * py + L1 * L1 - L2 * L2) / (2.0 * L1)
    disc = rho2 - m * m
    reach = (disc >= 0.0) & (rho2 > 0.0)
    w = jnp.sqrt(jnp.where(reach, disc, 1.0))
    inv_rho2 = 1.0 / jnp.where(reach, rho2, 1.0)
    c = (dx * m + pz * w) * inv_rho2
    s = (pz * m - dx * w) * inv_rho2
    limits = _within_limits(c, s, robot.theta_min, robot.theta_max)
    ok = reach & limits & finite_p
    nan = jnp.asarray(jnp.nan, dtype)
    return jnp.where(reach & finite_p, c, nan), jnp.where(reach & finite_p, s, nan), ok


def _jacobi_rotate(A, p: int, q: int):
    """One Jacobi rotation zeroing A[p, q] of a symmetric 3x3 matrix given as a dict of its 6 entries."""
    r = 3 - p - q
    app, aqq, apq = A[(p, p)], A[(q, q)], A[(p, q)]
    arp, arq = A[(r, p)], A[(r, q)]
    zero = apq == 0.0
    apq_safe = jnp.where(zero, 1.0, apq)
    tau = (aqq - app) / (2.0 * apq_safe)
    t = jnp.where(zero, 0.0, jnp.sign(tau + (tau == 0.0)) / (jnp.abs(tau) + jnp.sqrt(1.0 + tau * tau)))
    c = 1.0 / jnp.sqrt(1.0 + t * t)
    s = t * c
    out = dict(A)
    out[(p, p)] = app - t * apq
    out[(q, q)] = aqq + t * apq
    out[(p, q)] = out[(q, p)] = jnp.zeros_like(apq)
    out[(r, p)] = out[(p, r)] = c * arp - s * arq
    out[(r, q)] = out[(q, r)] = s * arp + c * arq
    return out


def _sym_eig_desc_entries(A: dict, sweeps: int = 4) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """Two largest eigenvalues of a symmetric 3x3 matrix, given as a dict of scalar entries, by cyclic Jacobi.

    Scalar entries keep the batched code structure-of-arrays under vmap. Jacobi (sqrt only, no inverse trig)
    keeps the eigenvalues accurate to ~eps ||S|| even for repeated eigenvalues (on the robot's axis two
    singular values coincide; the trigonometric Cardano formula loses sqrt(eps) there). Convergence is
    quadratic; 4 sweeps reach machine precision for 3x3.
    """
    for _ in range(sweeps):
        for p, q in ((0, 1), (0, 2), (1, 2)):
            A = _jacobi_rotate(A, p, q)
    e0, e1, e2 = A[(0, 0)], A[(1, 1)], A[(2, 2)]
    hi = jnp.maximum(jnp.maximum(e0, e1), e2)
    lo = jnp.minimum(jnp.minimum(e0, e1), e2)
    return hi, e0 + e1 + e2 - hi - lo


def _adj_sym_entries(G: dict) -> dict:
    """Adjugate of a symmetric 3x3 matrix given as a dict of scalar entries."""
    g00, g11, g22, g01, g02, g12 = G[(0, 0)], G[(1, 1)], G[(2, 2)], G[(0, 1)], G[(0, 2)], G[(1, 2)]
    c00 = g11 * g22 - g12 * g12
    c11 = g00 * g22 - g02 * g02
    c22 = g00 * g11 - g01 * g01
    c01 = g02 * g12 - g01 * g22
    c02 = g01 * g12 - g02 * g11
    c12 = g01 * g02 - g00 * g12
    return {(0, 0): c00, (1, 1): c11, (2, 2): c22, (0, 1): c01, (1, 0): c01, (0, 2): c02, (2, 0): c02,
            (1, 2): c12, (2, 1): c12}


def singular_values_closed_form(Jx: Float[Array, "3 3"], dhat: Float[Array, "3"]) -> Float[Array, "3"]:
    """Singular values (descending) of M = Jx^-1 diag(dhat) without forming the inverse or an SVD.

    Two exact reformulations, chosen per point by which factor is closer to singular:

    * Jq-side (|det Jx| >= |prod dhat|): M^T M = D adj(G) D / det G, so s1, s2 = sqrt(eig(D adj(G) D)) / |det Jx|;
    * Jx-side (otherwise): M^-1 M^-T = D^-1 G D^-1 = adj(D) G adj(D) / prod(d)^2, so s3, s2 = |prod d| /
      sqrt(eig(adj(D) G adj(D))).

    The remaining (smallest-eigenvalue) singular value comes from the exact determinant
    s1 s2 s3 = |prod dhat| / |det Jx|, so it keeps full relative accuracy near either kind of singularity.
    """
    # Scalars only (structure of arrays): under vmap, stacking into small matrices gives (N, 3, 3) arrays whose
    # entries are strided and do not vectorise on XLA:CPU.
    J = [[Jx[i, k] for k in range(3)] for i in range(3)]
    d = [dhat[0], dhat[1], dhat[2]]
    G = {(i, j): J[i][0] * J[j][0] + J[i][1] * J[j][1] + J[i][2] * J[j][2] for i in range(3) for j in range(3)}
    det_jx = jnp.abs(  # explicit cofactor expansion, no LU
        J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1])
        - J[0][1] * (J[1][0] * J[2][2] - J[1][2] * J[2][0])
        + J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]))
    prod_d = jnp.abs(d[0] * d[1] * d[2])
    jx_side = det_jx < prod_d
    adj_d = [d[1] * d[2], d[0] * d[2], d[0] * d[1]]
    adj_g = _adj_sym_entries(G)
    X = {(i, j): jnp.where(jx_side, adj_d[i] * G[(i, j)] * adj_d[j], d[i] * adj_g[(i, j)] * d[j])
         for i in range(3) for j in range(3)}
    e1, e2 = _sym_eig_desc_entries(X)
    r1 = jnp.sqrt(jnp.maximum(e1, 0.0))
    r2 = jnp.sqrt(jnp.maximum(e2, 0.0))
    # Jq side
    a1 = r1 / det_jx
    a2 = r2 / det_jx
    a12 = a1 * a2
    a3 = prod_d / (det_jx * jnp.where(a12 > 0, a12, 1.0))
    a3 = jnp.where(a12 > 0, a3, 0.0)
    # Jx side (only used when prod_d > det_jx >= 0, so prod_d > 0)
    b3 = prod_d / jnp.where(r1 > 0, r1, 1.0)
    b2 = prod_d / jnp.where(r2 > 0, r2, 1.0)
    b23 = b2 * b3
    b1 = prod_d / jnp.where(det_jx * b23 > 0, det_jx * b23, 1.0)
    b1 = jnp.where(det_jx * b23 > 0, b1, jnp.inf)
    return jnp.stack([jnp.where(jx_side, b1, a1), jnp.where(jx_side, b2, a2), jnp.where(jx_side, b3, a3)])


def indices_from_singular_values(s, *, b_v=2.0, b_f=4.2, beta=0.5, raw_scale=1.0):
    s1, s2, s3 = s[0], s[1], s[2]
    omega_v = s1 * s2 * s3
    manip = omega_v * raw_scale
    return Indices(inv_cond=s3 / s1, sigma_min_v=s3, sigma_min_f=1.0 / s1, omega_v=omega_v, omega_f=1.0 / omega_v,
                   k_tilde=k_tilde(s3, 1.0 / s1, b_v=b_v, b_f=b_f, beta=beta), manipulability=manip,
                   imi=1.0 / manip, singular_values=s)


def point_indices(robot, p, *, b_v=2.0, b_f=4.2, beta=0.5):
    """The old hot-path kernel (returns ok, Indices), as dj.point_indices computed it on main 9f54c88."""
    cos, sin, oks = ik_cos_sin(robot, p)
    ok = jnp.all(oks)
    c = jnp.where(ok, cos, 1.0)
    s = jnp.where(ok, sin, 0.0)
    L = robot.upper_arm
    loc = to_chain_frames(jnp.asarray(p, cos.dtype))
    L1 = robot.upper_arm
    ux = (loc[:, 0] + robot.platform_radius - robot.base_radius - L1 * c) / robot.forearm
    uz = (loc[:, 2] - L1 * s) / robot.forearm
    u_local = jnp.stack([ux, loc[:, 1] / robot.forearm, uz], axis=-1)
    Jx = _from_chain_frames(u_local)
    dhat = (L1 / L) * (uz * c - ux * s)
    sv = singular_values_closed_form(Jx, dhat)
    ind = indices_from_singular_values(sv, b_v=b_v, b_f=b_f, beta=beta, raw_scale=L ** 3)
    nan = jnp.asarray(jnp.nan, sv.dtype)
    return ok, Indices(*(jnp.where(ok, v, nan) for v in ind))


def redundancy_kernel(recon, p, k, b_v, b_f, beta):
    """The old ``workspace.redundancy._kernel`` (feasible, Indices) at sample k of canonical point p."""
    robot = recon.at(recon.R_min + jnp.asarray(k, recon.R_min.dtype) * recon.R_step)
    cos, sin, oks = ik_cos_sin(robot, p)
    ok = jnp.all(oks)
    c = jnp.where(ok, cos, 1.0)
    s = jnp.where(ok, sin, 0.0)
    loc = to_chain_frames(p)
    L1, L2 = robot.upper_arm, robot.forearm
    u = jnp.stack([loc[:, 0] + robot.platform_radius - robot.base_radius - L1 * c, loc[:, 1],
                   loc[:, 2] - L1 * s], axis=-1) / L2
    Jx = _from_chain_frames(u)
    det_jx = (Jx[0, 0] * (Jx[1, 1] * Jx[2, 2] - Jx[1, 2] * Jx[2, 1])
              - Jx[0, 1] * (Jx[1, 0] * Jx[2, 2] - Jx[1, 2] * Jx[2, 0])
              + Jx[0, 2] * (Jx[1, 0] * Jx[2, 1] - Jx[1, 1] * Jx[2, 0]))
    dhat = u[:, 2] * c - u[:, 0] * s
    sv = singular_values_closed_form(Jx, dhat)
    ind = indices_from_singular_values(sv, b_v=b_v, b_f=b_f, beta=beta, raw_scale=L1 ** 3)
    return ok & (det_jx != 0.0), ind


def mirrored_point_indices(robot, p, *, b_v=2.0, b_f=4.2, beta=0.5, sv_method=None):
    """The old ``workspace.point_indices`` (ok, Indices) at the mirror image (x, |y|, z)."""
    q = jnp.stack([p[0], jnp.abs(p[1]), p[2]])
    return point_indices(robot, q, b_v=b_v, b_f=b_f, beta=beta)


def ik_cos_sin_result(robot, p, branch="outer"):
    """The old algebraic IK in the public IKCosSin shape (reason codes zero: the fitness never reads them)."""
    cos, sin, ok = ik_cos_sin(robot, p)
    return IKCosSin(cos=cos, sin=sin, ok=ok, reason=jnp.zeros(3, jnp.int32))

