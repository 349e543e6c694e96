"""Jacobian-based performance indices, the singularity-sensitive index k~, singularity classification.

The paper's tabulated numbers (Franco-López 2026, Tables 2-8) are computed from the homogenised 3x3
theta-block M = J^[:, 1:4] of the Jacobian with R frozen (SPEC §1), not from the 3x4 matrix its prose
describes; ``matrix="theta3x3"`` (default) does that, ``matrix="full3x4"`` uses the homogenised 3x4 J.

Closed-form singular values (hot path). With D = diag(sin th2 sin th3) (the homogenised theta-block of Jq)
and G = Jx Jx^T (Gram matrix of the unit forearm vectors), M^T M = D G^-1 D = D adj(G) D / det(G). The
two largest eigenvalues of the symmetric S = D adj(G) D give sigma_1,2 = sqrt(lambda_1,2(S)) / |det Jx|, and
sigma_3 = |det M| / (sigma_1 sigma_2) with the exact
determinant det M = prod(D) / det Jx (see :func:`singular_values_closed_form`; the eigenvalues come from
cyclic Jacobi sweeps, not Cardano, to stay exact on the robot's axis). ``sv_method="svd"`` uses
``jnp.linalg.svd`` instead.
"""

from __future__ import annotations

from typing import NamedTuple, Optional

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .geometry import Delta
from .jacobian import _resolve_length, homogenise, jq_diagonal
from .kinematics import _from_chain_frames, forearm_units, passive_angles

__all__ = [
    "Indices",
    "indices",
    "indices_from_singular_values",
    "singular_values",
    "k_tilde",
    "sigma_tilde",
    "Singularity",
    "classify_singularity",
    "MATRICES",
    "INDEX_NAMES",
    "point_indices",
]

MATRICES = ("theta3x3", "full3x4")
#: Names of the scalar indices returned by :func:`indices`, usable as a redundancy-resolution criterion.
INDEX_NAMES = ("inv_cond", "sigma_min_v", "sigma_min_f", "omega_v", "omega_f", "k_tilde", "manipulability",
               "imi")


class Indices(NamedTuple):
    """Performance indices at one configuration (NaN where the configuration is invalid).

    Attributes:
        inv_cond: 1/k = s3 / s1 (0 singular, 1 isotropic).
        sigma_min_v: s3, velocity minimum singular value.
        sigma_min_f: 1 / s1, force minimum singular value.
        omega_v: s1 s2 s3, velocity manipulability (of the homogenised matrix).
        omega_f: 1 / omega_v, force manipulability.
        k_tilde: singularity-sensitive index in [0, 1] (paper Eq. 15-17).
        manipulability: Yoshikawa's sqrt(det(J J^T)) of the *non-homogenised* matrix (m^3/rad^3 for theta3x3).
        imi: inverse manipulability index 1 / sqrt(det(J J^T)) (GA paper), non-homogenised.
        singular_values: (s1, s2, s3), descending, of the homogenised matrix.
    """

    inv_cond: Float[Array, ""]
    sigma_min_v: Float[Array, ""]
    sigma_min_f: Float[Array, ""]
    omega_v: Float[Array, ""]
    omega_f: Float[Array, ""]
    k_tilde: Float[Array, ""]
    manipulability: Float[Array, ""]
    imi: Float[Array, ""]
    singular_values: Float[Array, "3"]


def sigma_tilde(sigma, a, b):
    """Piecewise-quadratic normalisation of a minimum singular value (paper Eq. 16-17).

    1 - ((s - a)/a)^2 on [0, a], 1 - ((s - a)/(b - a))^2 on (a, b], 0 beyond b; NaN stays NaN.
    """
    left = 1.0 - ((sigma - a) / a) ** 2
    right = 1.0 - ((sigma - a) / (b - a)) ** 2
    val = jnp.where(sigma <= a, left, jnp.where(sigma <= b, right, 0.0))
    return jnp.where(jnp.isnan(sigma), jnp.nan, val)


def k_tilde(sigma_min_v, sigma_min_f, *, b_v=2.0, b_f=4.2, beta=0.5):
    """Singularity-sensitive index k~ = s~_v(sigma_min_v) * s~_f(sigma_min_f), a_v = beta b_v, a_f = (1-beta) b_f."""
    return sigma_tilde(sigma_min_v, beta * b_v, b_v) * sigma_tilde(sigma_min_f, (1.0 - beta) * b_f, b_f)


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


def singular_values(M: Float[Array, "3 n"]) -> Float[Array, "3"]:
    """Singular values (descending) of a 3 x n matrix by ``jnp.linalg.svd`` (reference method)."""
    return jnp.linalg.svd(M, compute_uv=False)


def indices_from_singular_values(s: Float[Array, "3"], *, b_v=2.0, b_f=4.2, beta=0.5,
                                 raw_scale: Float[Array, ""] | float = 1.0) -> Indices:
    """All indices from the singular values ``s`` (descending) of the homogenised matrix.

    ``raw_scale`` converts the homogenised manipulability to the raw one (length**3 for theta3x3).
    """
    s1, s2, s3 = s[0], s[1], s[2]
    omega_v = s1 * s2 * s3
    manip = omega_v * raw_scale
    return Indices(
        inv_cond=s3 / s1,
        sigma_min_v=s3,
        sigma_min_f=1.0 / s1,
        omega_v=omega_v,
        omega_f=1.0 / omega_v,
        k_tilde=k_tilde(s3, 1.0 / s1, b_v=b_v, b_f=b_f, beta=beta),
        manipulability=manip,
        imi=1.0 / manip,
        singular_values=s,
    )


def indices(robot: Delta, p: Float[Array, "3"], theta: Float[Array, "3"], *, matrix: str = "theta3x3",
            b_v: float = 2.0, b_f: float = 4.2, beta: float = 0.5, length: Optional[float] = None,
            sv_method: str = "closed_form") -> Indices:
    """Performance indices at platform position ``p`` (m, base frame) and actuated angles ``theta`` (rad).

    Args:
        robot: the robot (R frozen at ``robot.base_radius``).
        p: platform centre (m).
        theta: actuated angles (rad), NaN for an invalid configuration (all indices then NaN).
        matrix: ``"theta3x3"`` (default; the paper's numbers) or ``"full3x4"`` (the homogenised 3x4 J).
        b_v, b_f, beta: parameters of k~ (paper: 2, 4.2, 0.5).
        length: homogenising length (default L1).
        sv_method: ``"closed_form"`` (default, theta3x3 only) or ``"svd"``.

    Returns:
        :class:`Indices`.
    """
    if matrix not in MATRICES:
        raise ValueError(f"matrix must be one of {MATRICES}, got {matrix!r}")
    if sv_method not in ("closed_form", "svd"):
        raise ValueError(f"sv_method must be 'closed_form' or 'svd', got {sv_method!r}")
    theta = jnp.asarray(theta)
    L = _resolve_length(robot, length)
    u_local = forearm_units(robot, p, theta)
    Jx = _from_chain_frames(u_local)
    dhat = jq_diagonal(robot, u_local, theta) / L  # homogenised theta-block diagonal
    if matrix == "theta3x3":
        if sv_method == "closed_form":
            s = singular_values_closed_form(Jx, dhat)
        else:
            s = singular_values(jnp.linalg.solve(Jx, jnp.diag(dhat)))
        return indices_from_singular_values(s, b_v=b_v, b_f=b_f, beta=beta, raw_scale=L ** 3)
    Jq = jnp.concatenate([u_local[:, :1], jnp.diag(dhat * L)], axis=1)
    J = jnp.linalg.solve(Jx, Jq)
    s = singular_values(homogenise(J, L))
    ind = indices_from_singular_values(s, b_v=b_v, b_f=b_f, beta=beta)
    manip = jnp.sqrt(jnp.abs(jnp.linalg.det(J @ J.T)))
    return ind._replace(manipulability=manip, imi=1.0 / manip)


def point_indices(robot: Delta, p: Float[Array, "3"], *, branch: str = "outer", b_v: float = 2.0,
                  b_f: float = 4.2, beta: float = 0.5, length: Optional[float] = None):
    """IK and all indices of one point in the hot-path form (the workspace/benchmark kernel).

    No inverse trig and no SVD: cos/sin of theta come from the algebraic IK, the Jacobians from them, the
    singular values from :func:`singular_values_closed_form`. Equals ``indices(robot, p, ik(robot, p).theta)``
    (theta3x3 matrix) to rounding, with NaN indices where the point is not reachable.

    Returns:
        (``IKCosSin``, :class:`Indices`).
    """
    from .kinematics import ik_cos_sin, to_chain_frames

    cs = ik_cos_sin(robot, p, branch=branch)
    ok = jnp.all(cs.ok)
    # double-where guard: failed points run the kernel on a harmless angle, so gradients stay finite
    c = jnp.where(ok, cs.cos, 1.0)
    s = jnp.where(ok, cs.sin, 0.0)
    L = _resolve_length(robot, length)
    loc = to_chain_frames(jnp.asarray(p, cs.cos.dtype))
    L1 = robot.upper_arm
    ux = (loc[:, 0] + robot.platform_radius - robot.base_radius - L1 * c) / robot.forearm
    uz = (loc[:, 2] - L1 * s) / robot.forearm
    u_local = jnp.stack([ux, loc[:, 1] / robot.forearm, uz], axis=-1)
    Jx = _from_chain_frames(u_local)
    dhat = (L1 / L) * (uz * c - ux * s)
    sv = singular_values_closed_form(Jx, dhat)
    ind = indices_from_singular_values(sv, b_v=b_v, b_f=b_f, beta=beta, raw_scale=L ** 3)
    nan = jnp.asarray(jnp.nan, sv.dtype)
    return cs, Indices(*(jnp.where(ok, v, nan) for v in ind))


class Singularity(NamedTuple):
    """Singularity classification of one configuration (paper §4 and §5.1).

    Attributes:
        type1: all chains theta3 = pi/2 and theta1 + theta2 = pi (forearms coplanar with the platform).
        type2: all chains theta3 = pi/2 and theta1 + theta2 = pi/2 (forearms vertical).
        type3: number of chains (0..3) with theta2 = 0 and theta1 = pi/2 (vertical, stretched).
        type4: theta2 = 0 for two or more chains that are not of type 3.
        jx_rank: numerical rank of Jx (3 = regular).
        jq_rank: numerical rank of the theta-block of Jq (fixed robot).
        jq_full_rank: numerical rank of the 3x4 Jq (reconfigurable robot, R column included).
        near_singular: any of 1/k, sigma_min_v, sigma_min_f below ``near_tol`` or omega_v, omega_f below
            ``omega_tol`` (paper §5.1: 0.1 and 1e-3).
        singular: any exact (within tolerance) singularity above.
    """

    type1: Bool[Array, ""]
    type2: Bool[Array, ""]
    type3: Int[Array, ""]
    type4: Bool[Array, ""]
    jx_rank: Int[Array, ""]
    jq_rank: Int[Array, ""]
    jq_full_rank: Int[Array, ""]
    near_singular: Bool[Array, ""]
    singular: Bool[Array, ""]


def _angle_close(a, b, tol):
    d = jnp.mod(a - b + jnp.pi, 2.0 * jnp.pi) - jnp.pi
    return jnp.abs(d) <= tol


def classify_singularity(robot: Delta, p: Float[Array, "3"], theta: Float[Array, "3"], *,
                         angle_tol: float = 1e-6, rank_tol: float = 1e-9, near_tol: float = 0.1,
                         omega_tol: float = 1e-3) -> Singularity:
    """Classify the singularities of a configuration.

    Args:
        robot, p, theta: the configuration (m, rad).
        angle_tol: tolerance on the analytic angle conditions (rad).
        rank_tol: relative singular-value tolerance for the numerical ranks of Jx and Jq.
        near_tol: threshold on 1/k, sigma_min_v and sigma_min_f for "near singular".
        omega_tol: threshold on omega_v and omega_f for "near singular".
    """
    theta = jnp.asarray(theta)
    th2, th3 = passive_angles(robot, p, theta)
    half_pi = 0.5 * jnp.pi
    th12 = theta + th2
    t3_plane = _angle_close(th3, half_pi, angle_tol)
    type1 = jnp.all(t3_plane & _angle_close(th12, jnp.pi, angle_tol))
    type2 = jnp.all(t3_plane & _angle_close(th12, half_pi, angle_tol))
    stretched = _angle_close(th2, 0.0, angle_tol)
    vertical = stretched & _angle_close(theta, half_pi, angle_tol)
    type3 = jnp.sum(vertical).astype(jnp.int32)
    type4 = jnp.sum(stretched & ~vertical) >= 2

    u_local = forearm_units(robot, p, theta)
    Jx = _from_chain_frames(u_local)
    diag = jq_diagonal(robot, u_local, theta)
    Jq = jnp.concatenate([u_local[:, :1], jnp.diag(diag)], axis=1)
    sx = jnp.linalg.svd(Jx, compute_uv=False)
    jx_rank = jnp.sum(sx > rank_tol * jnp.maximum(sx[0], 1e-300)).astype(jnp.int32)
    jq_rank = jnp.sum(jnp.abs(diag) > rank_tol * robot.upper_arm).astype(jnp.int32)
    sq = jnp.linalg.svd(homogenise(Jq, robot.upper_arm), compute_uv=False)
    jq_full_rank = jnp.sum(sq > rank_tol * jnp.maximum(sq[0], 1e-300)).astype(jnp.int32)

    ind = indices(robot, p, theta)
    near = ((ind.inv_cond < near_tol) | (ind.sigma_min_v < near_tol) | (ind.sigma_min_f < near_tol)
            | (ind.omega_v < omega_tol) | (ind.omega_f < omega_tol))
    singular = type1 | type2 | (type3 > 0) | type4 | (jx_rank < 3) | (jq_rank < 3)
    return Singularity(type1=type1, type2=type2, type3=type3, type4=type4, jx_rank=jx_rank, jq_rank=jq_rank,
                       jq_full_rank=jq_full_rank, near_singular=near | singular, singular=singular)
