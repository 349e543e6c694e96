"""Independent NumPy reference of the kinematic kernel (float64, vectorised over points; not for speed).

Used by tests ("every backend agrees": JAX core, Numba mirror, this file) and by the benchmarks as the NumPy
baseline. It mirrors the JAX decomposition name for name (:func:`loop_closure`, :func:`loop_vectors`,
:func:`singular_values`, :func:`indices_from_sv`, :func:`point_indices`; the rows of
:data:`deltajax.backends.KERNELS`) but is written independently: joint limits by comparing
the angle itself (``arctan2``), Jx from the explicit rotation, singular values from ``numpy.linalg.svd`` of
M = Jx^-1 diag(d) (no closed form), k~ from the paper's Eq. 15-17 written out.

Conventions: docs/CONVENTIONS.md (z down, chain i at alpha_i = 2 pi i / 3, theta positive downward, outer elbow).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["chain_local", "loop_closure", "loop_vectors", "jacobian_blocks", "singular_values", "sigma_tilde",
           "k_tilde", "indices_from_sv", "point_indices", "INDEX_NAMES"]

INDEX_NAMES = ("inv_cond", "sigma_min_v", "sigma_min_f", "omega_v", "omega_f", "k_tilde", "manipulability",
               "imi")
_ALPHA = np.array([0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0])


def chain_local(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, y, z) of points p (n, 3) in each chain's local frame, each (n, 3) [point, chain]."""
    p = np.asarray(p, np.float64).reshape(-1, 3)
    ca, sa = np.cos(_ALPHA), np.sin(_ALPHA)
    with np.errstate(invalid="ignore"):   # a non-finite coordinate times sin(0): NaN, as in the other backends
        x = p[:, :1] * ca + p[:, 1:2] * sa
        y = -p[:, :1] * sa + p[:, 1:2] * ca
    z = np.broadcast_to(p[:, 2:3], x.shape)
    return x, y, z


def loop_closure(dx, py, pz, L1, L2, theta_min=-math.inf, theta_max=math.inf, sign=1.0):
    """Loop closure of one chain (arrays broadcast): returns (cos, sin, disc, reach, ok), NaN cos/sin where
    the loop does not close. Limits tested on theta = atan2(sin, cos) against [theta_min, theta_max] mod 2 pi."""
    dx, py, pz = (np.asarray(a, np.float64) for a in (dx, py, pz))
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        rho2 = dx * dx + pz * pz
        m = (rho2 + py * py + L1 * L1 - L2 * L2) / (2.0 * L1)
        disc = rho2 - m * m
        reach = np.isfinite(disc) & (disc >= 0) & (rho2 > 0)
        w = np.sqrt(np.where(reach, disc, np.nan))
        c = (dx * m + sign * pz * w) / rho2
        s = (pz * m - sign * dx * w) / rho2
        if math.isfinite(theta_min) and math.isfinite(theta_max):
            th = np.arctan2(s, c)
            # shift theta into [theta_min, theta_min + 2 pi)
            th = theta_min + np.mod(th - theta_min, 2.0 * math.pi)
            # a theta a hair below theta_min lands near theta_min + 2 pi: compare both ways
            inside = (th <= theta_max) | (th - 2.0 * math.pi >= theta_min - 1e-15)
            inside = inside & reach
        else:
            inside = reach
    return c, s, disc, reach, inside


def loop_vectors(dx, py, pz, c, s, L1, L2):
    """Unit forearm vectors (ux, uy, uz) in the chain's local frame."""
    return (dx - L1 * c) / L2, np.asarray(py) / L2, (pz - L1 * s) / L2


def jacobian_blocks(ux, uy, uz, c, s):
    """(Jx (n, 3, 3), d (n, 3)): Jx row i = u_i rotated to the base frame; d_i = sin th2 sin th3."""
    ca, sa = np.cos(_ALPHA), np.sin(_ALPHA)
    Jx = np.stack([ux * ca - uy * sa, ux * sa + uy * ca, uz], axis=-1)
    d = uz * c - ux * s
    return Jx, d


def singular_values(Jx: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Singular values (n, 3), descending, of M = Jx^-1 diag(d) by LAPACK (solve + SVD)."""
    out = np.full(d.shape, np.nan)
    good = np.isfinite(Jx).all(axis=(1, 2)) & np.isfinite(d).all(axis=1)
    good &= np.abs(np.linalg.det(np.where(good[:, None, None], Jx, np.eye(3)))) > 0
    if good.any():
        M = np.linalg.solve(Jx[good], d[good][:, :, None] * np.eye(3)[None])
        fin = np.isfinite(M).all(axis=(1, 2))  # an overflowing solve: LAPACK's SVD must not see inf (DLASCL)
        sv = np.full(d[good].shape, np.nan)
        sv[fin] = np.linalg.svd(M[fin], compute_uv=False)
        out[good] = sv
    return out


def sigma_tilde(s, a, b):
    """The paper's piecewise quadratic (Eq. 16-17): 1 - ((s - a) / a)^2 up to a, 1 - ((s - a) / (b - a))^2 up to
    b, 0 above; NaN stays NaN."""
    s = np.asarray(s, np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        v = np.where(s <= a, 1.0 - ((s - a) / a) ** 2, np.where(s <= b, 1.0 - ((s - a) / (b - a)) ** 2, 0.0))
    return np.where(np.isnan(s), np.nan, v)  # NaN compares False: it would score 0 (a number) otherwise


def k_tilde(sigma_min_v, sigma_min_f, b_v=2.0, b_f=4.2, beta=0.5):
    """k~ = s~_v(sigma_min_v) s~_f(sigma_min_f), a_v = beta b_v, a_f = (1 - beta) b_f (paper Eq. 15-17)."""
    with np.errstate(invalid="ignore"):
        return sigma_tilde(sigma_min_v, beta * b_v, b_v) * sigma_tilde(sigma_min_f, (1 - beta) * b_f, b_f)


def point_indices(R, r, L1, L2, theta_min, theta_max, p, *, b_v=2.0, b_f=4.2, beta=0.5, sign=1.0) -> dict:
    """IK + every index (theta3x3, homogenised by L1) of points p (n, 3): dict with ``ok`` (n,), ``cos``,
    ``sin`` (n, 3), ``singular_values`` (n, 3) and each name of :data:`INDEX_NAMES` (n,), NaN where not ok."""
    x, y, z = chain_local(p)
    dx = x + r - R
    c, s, disc, reach, inside = loop_closure(dx, y, z, L1, L2, theta_min, theta_max, sign)
    ok = inside.all(axis=1)
    ux, uy, uz = loop_vectors(dx, y, z, c, s, L1, L2)
    Jx, d = jacobian_blocks(ux, uy, uz, c, s)
    sv = singular_values(np.where(ok[:, None, None], Jx, np.eye(3)), np.where(ok[:, None], d, 1.0))
    sv[~ok] = np.nan
    return {"ok": ok, "cos": c, "sin": s, "singular_values": sv,
            **indices_from_sv(sv, L1 ** 3, b_v=b_v, b_f=b_f, beta=beta)}


def indices_from_sv(sv, raw_scale, *, b_v=2.0, b_f=4.2, beta=0.5) -> dict:
    """Every index of :data:`INDEX_NAMES` (dict of (n,) arrays) from singular values ``sv`` (n, 3), descending,
    of the homogenised matrix; ``raw_scale`` = L1^3 (homogenised -> raw manipulability). NaN in, NaN out."""
    sv = np.asarray(sv, np.float64).reshape(-1, 3)
    s1, s2, s3 = sv[:, 0], sv[:, 1], sv[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        ov = s1 * s2 * s3
        return {"inv_cond": s3 / s1, "sigma_min_v": s3, "sigma_min_f": 1.0 / s1, "omega_v": ov, "omega_f": 1.0 / ov,
                "k_tilde": k_tilde(s3, 1.0 / s1, b_v, b_f, beta), "manipulability": ov * raw_scale,
                "imi": 1.0 / (ov * raw_scale)}
