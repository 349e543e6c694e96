"""Screen-and-verify redundancy resolution (fast mode) on the Numba kernel of :mod:`.numba_kernel`.

The screen evaluates an approximation of the criterion at every sample of a point's window together with a
bound on its difference from the exact kernel's value; only samples that can still be the exact argmax are
then evaluated by the exact kernel (:func:`.numba_kernel.point_value`, Jacobi eigenvalues). See
:func:`resolve_screened` and the module docstring of :mod:`.redundancy` for the argument; the constants below
are the bound's ingredients. The screen and the exact kernel share the per-chain loop closure, Jacobian blocks
and the matrix whose eigenvalues give the singular values (the same inlined functions, hence the same
floating-point values and the same feasibility decisions); they differ only in the eigenvalue solver.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .numba_kernel import (INLINE, INV_COND, JACOBI, K_TILDE, MANIPULABILITY, OMEGA_F, OMEGA_V, OPTS, SIGMA_MIN_F,
                         SIGMA_MIN_V, as_tuple4, criterion_of, ik_ok_all, jacobian_blocks, point_kernel, point_value,
                         sigma_tilde, sv_matrix)

__all__ = ["tcubic", "tcubic2", "eig_cubic_parts", "eig_with_bound", "screen_window", "TRIM_BLOCK", "ik_block",
           "trim_window", "point_window", "window_buffers", "VERIFY_BATCH", "resolve_screened", "screen_audit"]


_EPS = 2.220446049250313e-16
#: eigenvalue rounding of both solvers (Jacobi: backward stable, ~eps ||A|| per rotation, 12 rotations; the
#: trigonometric formula: q, p and the final sums), in units of eps (|q| + 2 p) >= eps ||A||_2. Measured
#: worst case over 2e6 random workspace samples: ~6 (tests/test_workspace_screen.py); 512 is the bound used.
_C_LAMBDA = 512.0
#: rounding of r = det(B) / 2 with B = (A - q I) / p, in units of eps (1 + |q| / p): the entries of B are
#: <= sqrt 6 (6 products of 3 entries), and the diagonal a_ii - q carries the rounding of q, ~3 eps |q|,
#: which is large relative to p when the eigenvalues are clustered (near the robot's axis |q| / p ~ 1e4).
_C_R = 512.0
#: residual of tcubic (polynomial guess + one Halley step) over w in [0, 4]: measured 5.6e-16 (tested).
_T_NEWTON = 1e-14


# -- the screen's eigenvalues: trigonometric Cardano form with an error bound ---------------------------------
# (the kernel's fast cubic, :func:`.numba_kernel._eig_top2_fast`, has the same roots; this form exposes q, p and
# the roots t, t' that the bound below needs.)
#: least-squares fit of t / s, s = sqrt(w / 3), on [0, 2 / sqrt 3] (max error of the guess 1.1e-5)
_TC4, _TC3, _TC2, _TC1, _TC0 = (0.004862740934509117, -0.02386905831264214, 0.06417057523483471,
                                -0.16573685947992756, 0.9999539697770844)


@nb.njit(**INLINE)
def _guess(w):
    s = math.sqrt(w * (1.0 / 3.0))
    return s * ((((_TC4 * s + _TC3) * s + _TC2) * s + _TC1) * s + _TC0)


@nb.njit(**INLINE)
def tcubic(w):
    """Root t in [0, 1] of t^2 (t + 3) = w, w in [0, 4]; branch-free, one sqrt and one division.

    With c = (1 + t) / 2 this is the largest root of the Chebyshev equation 4 c^3 - 3 c = w / 2 - 1, i.e.
    cos(acos(r) / 3) of the trigonometric Cardano formula, without inverse trigonometry (vectorisable).
    A polynomial guess in s = sqrt(w / 3) (t = s (1 - s / 6 + ...)) and one Halley step (cubic convergence).
    """
    t = _guess(w)
    f = t * t * (t + 3.0) - w
    fp = 3.0 * t * (t + 2.0)
    den = 2.0 * fp * fp - f * (6.0 * t + 6.0)
    return t - 2.0 * f * fp / max(den, 1e-300)


@nb.njit(**INLINE)
def tcubic2(wp, wm):
    """:func:`tcubic` of two arguments with one shared division (x / a, y / b = x b / (a b), y a / (a b))."""
    tp = _guess(wp)
    tm = _guess(wm)
    fp_ = tp * tp * (tp + 3.0) - wp
    dp_ = 3.0 * tp * (tp + 2.0)
    np_ = 2.0 * fp_ * dp_
    ep_ = max(2.0 * dp_ * dp_ - fp_ * (6.0 * tp + 6.0), 1e-150)
    fm_ = tm * tm * (tm + 3.0) - wm
    dm_ = 3.0 * tm * (tm + 2.0)
    nm_ = 2.0 * fm_ * dm_
    em_ = max(2.0 * dm_ * dm_ - fm_ * (6.0 * tm + 6.0), 1e-150)
    inv = 1.0 / (ep_ * em_)
    return tp - np_ * em_ * inv, tm - nm_ * ep_ * inv


@nb.njit(**INLINE)
def eig_cubic_parts(a00, a11, a22, a01, a02, a12):
    """Trigonometric Cardano form of the eigenvalues: (q, p, tp, tm, ip) with lambda_max = q + p (1 + tp),
    lambda_mid = q + p (tm - tp), lambda_min = q - p (1 + tm); ip = 1 / p (0 where p = 0).

    q = tr A / 3, p^2 = ||A - q I||_F^2 / 6, r = det((A - q I) / p) / 2 in [-1, 1], tp, tm the roots of
    t^2 (t + 3) = 2 (1 +- r) (:func:`tcubic2`).
    """
    q = (a00 + a11 + a22) * (1.0 / 3.0)
    b00 = a00 - q
    b11 = a11 - q
    b22 = a22 - q
    p2 = (b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)) * (1.0 / 6.0)
    p = math.sqrt(p2)
    ip = 1.0 / p if p > 0.0 else 0.0
    n00 = b00 * ip
    n11 = b11 * ip
    n22 = b22 * ip
    n01 = a01 * ip
    n02 = a02 * ip
    n12 = a12 * ip
    rr = 0.5 * (n00 * (n11 * n22 - n12 * n12) - n01 * (n01 * n22 - n12 * n02) + n02 * (n01 * n12 - n11 * n02))
    rr = min(max(rr, -1.0), 1.0)
    tp, tm = tcubic2(2.0 * (1.0 + rr), 2.0 * (1.0 - rr))
    return q, p, tp, tm, ip


@nb.njit(**INLINE)
def _dt_bound2(tp, tm, a, dw):
    """Bound on |t(w + e) - t(w)| for |e| <= dw (a = sqrt(dw / 3)), for the roots tp and tm (summed): a always
    (t^2 (t + 3) >= 3 t^2 and t increasing), dw / f'(t - a) where the root is away from 0 (t is concave in
    w), 1 (t in [0, 1]); plus the solver residual. One shared division."""
    lp = tp - a
    lm = tm - a
    fp_ = 3.0 * lp * (lp + 2.0) if lp > 0.0 else 1e-150
    fm_ = 3.0 * lm * (lm + 2.0) if lm > 0.0 else 1e-150
    inv = dw / (fp_ * fm_)
    return min(min(a, fm_ * inv), 1.0) + min(min(a, fp_ * inv), 1.0) + 2.0 * _T_NEWTON


@nb.njit(**INLINE)
def eig_with_bound(a00, a11, a22, a01, a02, a12):
    """:func:`eig_cubic_parts` (q, p, tp, tm) and e_lam, a bound on the distance of each of the three
    eigenvalues so obtained from the exact kernel's (Jacobi) eigenvalue of the same floating-point matrix:
    the rounding of both solvers plus how far the roots move under the rounding of r (:func:`_dt_bound2`)."""
    q, p, tp, tm, ip = eig_cubic_parts(a00, a11, a22, a01, a02, a12)
    dw = 2.0 * _C_R * _EPS * (1.0 + abs(q) * ip) if p > 0.0 else 0.0  # error of wp, wm
    dt_a = math.sqrt(dw * (1.0 / 3.0))
    return q, p, tp, tm, _C_LAMBDA * _EPS * (abs(q) + 2.0 * p) + p * _dt_bound2(tp, tm, dt_a, dw)


@nb.njit(**INLINE)
def _criterion_bound(crit, sv3, inv1, er1, er3, prod_d, det_jx, L13, kt):
    """(approximate value, absolute error bound, bound unavailable) of criterion ``crit`` from the screened
    s3, 1/s1 and their relative error bounds er3, er1.

    k~ = s~_v(s3) s~_f(1/s1) with both factors in [0, 1] and slopes <= 2 / min(a, b - a); the volume-type
    criteria (omega_v, omega_f, manipulability, imi) do not depend on the eigenvalues at all:
    s1 s2 s3 = |prod d| / |det Jx|, so only rounding differs (64 eps).
    """
    a_v, b_v, a_f, b_f = kt[0], kt[1], kt[2], kt[3]
    if crit == K_TILDE:
        val = sigma_tilde(sv3, a_v, b_v) * sigma_tilde(inv1, a_f, b_f)
        err = 2.0 / min(a_v, b_v - a_v) * sv3 * er3 + 2.0 / min(a_f, b_f - a_f) * inv1 * er1 + 16.0 * _EPS
        return val, err, False
    if crit == INV_COND:
        val = sv3 * inv1
        return val, val * 2.0 * (er1 + er3), False
    if crit == SIGMA_MIN_V:
        return sv3, sv3 * er3, False
    if crit == SIGMA_MIN_F:
        return inv1, inv1 * er1, False
    ov = prod_d / det_jx
    if crit == OMEGA_V:
        val = ov
    elif crit == OMEGA_F:
        val = 1.0 / ov
    elif crit == MANIPULABILITY:
        val = ov * L13
    else:  # IMI
        val = 1.0 / (ov * L13)
    return val, abs(val) * 64.0 * _EPS, (not (ov > 0.0)) | (not (ov < math.inf))


@nb.njit(**OPTS)
def screen_window(x, y, z, k0, k1, R_min, R_step, r, L1, L2, lim, kt, crit, tol, lo, hi, feas):
    """Approximate criterion at samples k0 <= k < k1 of canonical point (x, y, z), with error bounds.

    Writes, for j = k - k0: ``feas[j]`` = 1 where the exact kernel finds the sample feasible (IK within limits
    and det Jx != 0: the same inlined functions as the exact kernel, so the same decision), and an interval
    [lo[j], hi[j]] that contains the exact kernel's criterion value (-inf, -inf where infeasible; -inf, +inf
    where no bound is available). Straight-line loop body (no inverse trig, no early exit) so that LLVM can
    vectorise it over the samples.

    Eigenvalues: the exact kernel's matrix (:func:`.numba_kernel.sv_matrix`), by the trigonometric Cardano
    formula (:func:`eig_cubic_parts`) instead of Jacobi.
    """
    lim, kt = as_tuple4(lim), as_tuple4(kt)
    L13 = L1 * L1 * L1
    for j in range(k1 - k0):
        R = R_min + (k0 + j) * R_step
        ok, det_s, j00, j01, j02, j10, j11, j12, j20, j21, j22, d0, d1, d2 = jacobian_blocks(x, y, z, R, r, L1, L2,
                                                                                             lim)
        ok = ok & (det_s != 0.0)
        jx_side, prod_d, det_jx, _, _, a00, a11, a22, a01, a02, a12 = sv_matrix(j00, j01, j02, j10, j11, j12, j20,
                                                                                 j21, j22, d0, d1, d2)
        q, p, tp, tm, e_lam = eig_with_bound(a00, a11, a22, a01, a02, a12)
        lam_hi = q + p * (1.0 + tp)
        lam_mid = q + p * (tm - tp)
        # singular values (the formulas of singular_values_from_eig, rearranged: two divisions)
        r1 = math.sqrt(max(lam_hi, 0.0))
        r2 = math.sqrt(max(lam_mid, 0.0))
        ir12 = 1.0 / (r1 * r2)
        ir1 = r2 * ir12
        # Jx side: s3 = |prod d| / r1, s2 = |prod d| / r2, 1/s1 = |det Jx| |prod d| / (r1 r2)
        # Jq side: s1 = r1 / |det Jx|, s2 = r2 / |det Jx|, s3 = |prod d| |det Jx| / (r1 r2)
        pdj = prod_d * det_jx * ir12
        sv3 = prod_d * ir1 if jx_side else pdj
        inv1 = pdj if jx_side else det_jx * ir1
        # relative error bounds (first order x 2; each lambda known to e_lam; 8 eps for the rearrangement)
        rho_hi = e_lam * ir1 * ir1
        rho_mid = e_lam * (ir12 * r1) * (ir12 * r1)
        ea = 2.0 * rho_hi + 8.0 * _EPS  # singular value from lambda_max
        eb = 2.0 * rho_mid + 8.0 * _EPS  # from lambda_mid
        ec = 2.0 * (ea + eb) + 8.0 * _EPS  # from the determinant
        er1 = ec if jx_side else ea
        er3 = ea if jx_side else ec
        big = ((max(ea, eb) > 0.05) | (not (lam_hi > 0.0)) | (not (lam_mid > 0.0)) | (not (inv1 > 0.0))
               | (not (sv3 >= 0.0)) | (not (inv1 < math.inf)) | (not (sv3 < math.inf)))
        val, err, no_bound = _criterion_bound(crit, sv3, inv1, er1, er3, prod_d, det_jx, L13, kt)
        err = err + tol
        unknown = big | no_bound | (val != val) | (err != err)
        lo_j = -math.inf if unknown else val - err
        hi_j = math.inf if unknown else val + err
        lo[j] = lo_j if ok else -math.inf
        hi[j] = hi_j if ok else -math.inf
        feas[j] = 1 if ok else 0


@nb.njit(**OPTS)
def _verify(x, y, z, k0, n, R_min, R_step, r, L1, L2, lim, kt, crit, feas, hi, T):
    """Exact kernel on the samples k0 + i (i < n) with feas[i] and hi[i] >= T, increasing k, strict > (ties
    keep the smallest k): (best k, best value, exact kernels run)."""
    lim, kt = as_tuple4(lim), as_tuple4(kt)
    bk = -1
    bv = -math.inf
    cnt = 0
    for i in range(n):
        if feas[i] == 0 or not (hi[i] >= T):
            continue
        cnt += 1
        f, v = point_value(x, y, z, R_min + (k0 + i) * R_step, r, L1, L2, lim, kt, crit, JACOBI)
        if f and v > bv:
            bv = v
            bk = k0 + i
    return bk, bv, cnt


#: samples tested per step of :func:`trim_window` (one vectorised block of IK tests)
TRIM_BLOCK = 16


@nb.njit(**OPTS)  # a call per block, not inlined: inlined into its caller the loop is not vectorised (measured)
def ik_block(x, y, z, k, step, R_min, R_step, r, L1, L2, lim, tb):
    """``tb[i]`` = 1 where every chain closes within its limits at sample k + step i (i < len(tb)), else 0: the
    exact kernel's loop closures (:func:`.numba_kernel.ik_ok_all`, hence the same decisions), branch-free in
    one loop over the block that LLVM vectorises (uint8 stores)."""
    lim = as_tuple4(lim)
    for i in range(tb.shape[0]):
        tb[i] = ik_ok_all(x, y, z, R_min + (k + step * i) * R_step, r, L1, L2, lim)


@nb.njit(**OPTS)  # a call per point
def trim_window(x, y, z, k0, k1, R_min, R_step, r, L1, L2, lim, tb):
    """[k0, k1) trimmed to its first and last IK-feasible samples (k0 == k1 where none is feasible).

    The IK test runs on blocks of ``len(tb)`` (:data:`TRIM_BLOCK`) samples from each end (:func:`ik_block`,
    vectorised; measured ~16x the scalar test with early exit); ``tb`` is a uint8 scratch array. Samples past
    the window's end in the last block are tested but never used.
    """
    nb_ = tb.shape[0]
    while k0 < k1:
        ik_block(x, y, z, k0, 1, R_min, R_step, r, L1, L2, lim, tb)
        i = 0
        while i < nb_ and k0 < k1 and tb[i] == 0:
            k0 += 1
            i += 1
        if i < nb_:
            break
    while k1 > k0:
        ik_block(x, y, z, k1 - 1, -1, R_min, R_step, r, L1, L2, lim, tb)
        i = 0
        while i < nb_ and k1 > k0 and tb[i] == 0:
            k1 -= 1
            i += 1
        if i < nb_:
            break
    return k0, k1


@nb.njit(**INLINE)
def point_window(pts, k_start, k_stop, j):
    """Point j made mirror-canonical (y -> |y|) and its sample window [k0, k1)."""
    return pts[j, 0], abs(pts[j, 1]), pts[j, 2], k_start[j], k_stop[j]


@nb.njit(**OPTS)
def window_buffers(k_start, k_stop):
    """(lo, hi, feas) scratch arrays long enough for the widest window [k_start, k_stop) of a block."""
    width = 1
    for j in range(k_start.shape[0]):
        width = max(width, k_stop[j] - k_start[j])
    return np.empty(width), np.empty(width), np.empty(width, np.uint8)


#: points per batch of :func:`resolve_screened`: their candidates are verified together in one vectorised loop
VERIFY_BATCH = 256


@nb.njit(**OPTS)
def _values_at(cx, cy, cz, ck, n, R_min, R_step, r, L1, L2, lim, kt, crit, cf, cv):
    """(feasible, criterion value) of the exact kernel at the candidates c < n (canonical point (cx, cy, cz)[c],
    sample ck[c]): :func:`.numba_kernel.point_value` on each, in one branch-free loop over the candidates
    (vectorised across points; the same expressions, hence the same values as the scalar call)."""
    for c in range(n):
        f, i0, i1, i2, i3, i4, i5, i6, i7 = point_kernel(cx[c], cy[c], cz[c], R_min + ck[c] * R_step, r, L1, L2,
                                                         lim, kt, JACOBI)
        cf[c] = f
        cv[c] = criterion_of(crit, i0, i1, i2, i3, i4, i5, i6, i7)


@nb.njit(**OPTS)
def resolve_screened(pts, k_start, k_stop, R_min, R_step, r, L1, L2, lim, kt, crit, tol, best_k, best_v, n_full,
                     n_fallback):
    """Screen-and-verify version of :func:`.numba_fields.resolve`: the identical selection, far fewer exact kernels.

    Per point: :func:`screen_window` gives intervals [lo_k, hi_k] around the exact value v_k of every
    feasible sample; with T = max_k lo_k, a sample with hi_k < T has v_k < T <= v_m for the sample m of the
    largest lo, so it cannot be the (first) argmax. The exact kernel then runs on the candidates
    (hi_k >= T) and they are compared in increasing k with the comparison of :func:`.numba_fields.resolve` (strict >:
    ties to the smallest k). Certification: every non-candidate has v_k <= hi_k < T, so if the best exact
    candidate value is >= T the result is the exact sweep's; otherwise (only possible if a bound failed, e.g. a
    NaN exact value at the sample defining T) the point falls back to the full exact sweep of its window
    (counted in n_fallback). The candidates of :data:`VERIFY_BATCH` points are evaluated together
    (:func:`_values_at`, a vectorised loop: 5x the scalar exact kernel) before each point's comparison.
    """
    lim, kt = as_tuple4(lim), as_tuple4(kt)
    lo, hi, feas = window_buffers(k_start, k_stop)
    width = lo.shape[0]
    tb = np.empty(TRIM_BLOCK, np.uint8)
    B = VERIFY_BATCH
    cap = B * width
    cx, cy, cz, ck = np.empty(cap), np.empty(cap), np.empty(cap), np.empty(cap, np.int64)
    cf, cv = np.empty(cap, np.bool_), np.empty(cap)
    cstart = np.empty(B + 1, np.int64)
    Tb, kb0, kb1 = np.empty(B), np.empty(B, np.int64), np.empty(B, np.int64)
    anyb = np.empty(B, np.bool_)
    npts = pts.shape[0]
    for base in range(0, npts, B):
        top = min(base + B, npts)
        nc = 0
        for j in range(base, top):
            x, y, z, k0, k1 = point_window(pts, k_start, k_stop, j)
            k0, k1 = trim_window(x, y, z, k0, k1, R_min, R_step, r, L1, L2, lim, tb)
            cstart[j - base] = nc
            T = -math.inf
            anyf = False
            if k1 > k0:
                screen_window(x, y, z, k0, k1, R_min, R_step, r, L1, L2, lim, kt, crit, tol, lo, hi, feas)
                for i in range(k1 - k0):
                    if feas[i] != 0:
                        anyf = True
                        T = max(T, lo[i])
                if anyf:
                    for i in range(k1 - k0):
                        if feas[i] != 0 and hi[i] >= T:
                            cx[nc] = x
                            cy[nc] = y
                            cz[nc] = z
                            ck[nc] = k0 + i
                            nc += 1
            Tb[j - base] = T
            anyb[j - base] = anyf
            kb0[j - base] = k0
            kb1[j - base] = k1
        cstart[top - base] = nc
        _values_at(cx, cy, cz, ck, nc, R_min, R_step, r, L1, L2, lim, kt, crit, cf, cv)
        for j in range(base, top):
            t = j - base
            bk = -1
            bv = -math.inf
            for c in range(cstart[t], cstart[t + 1]):
                if cf[c] and cv[c] > bv:
                    bv = cv[c]
                    bk = ck[c]
            cnt = cstart[t + 1] - cstart[t]
            fb = 0
            if anyb[t] and not (bv >= Tb[t]):  # a bound failed: the exact sweep of the window
                fb = 1
                x, y, z, k0, k1 = pts[j, 0], abs(pts[j, 1]), pts[j, 2], kb0[t], kb1[t]
                screen_window(x, y, z, k0, k1, R_min, R_step, r, L1, L2, lim, kt, crit, tol, lo, hi, feas)
                bk, bv, c2 = _verify(x, y, z, k0, k1 - k0, R_min, R_step, r, L1, L2, lim, kt, crit, feas, hi,
                                     -math.inf)
                cnt += c2
            best_k[j] = bk
            best_v[j] = bv
            n_full[j] = cnt
            n_fallback[j] = fb


@nb.njit(**OPTS)
def screen_audit(pts, k_start, k_stop, R_min, R_step, r, L1, L2, lim, kt, crit, out):
    """Check the screen against the exact kernel at every sample of every window (tests, benchmark).

    ``out`` (n, 4) per point: [max |approx - exact|, max |approx - exact| / bound (the screen's error bound
    without margin), number of samples outside their interval or with a different feasibility decision,
    number of feasible samples]; approx is the interval's centre. NaN exact values are skipped.
    """
    lim, kt = as_tuple4(lim), as_tuple4(kt)
    lo, hi, feas = window_buffers(k_start, k_stop)
    for j in range(pts.shape[0]):
        x, y, z, k0, k1 = point_window(pts, k_start, k_stop, j)
        e_abs, e_rel, bad, nf = 0.0, 0.0, 0, 0
        if k1 > k0:
            screen_window(x, y, z, k0, k1, R_min, R_step, r, L1, L2, lim, kt, crit, 0.0, lo, hi, feas)
            for i in range(k1 - k0):
                f, v = point_value(x, y, z, R_min + (k0 + i) * R_step, r, L1, L2, lim, kt, crit, JACOBI)
                if f != (feas[i] != 0):
                    bad += 1
                    continue
                if not f:
                    continue
                nf += 1
                if math.isnan(v):
                    continue
                if not (lo[i] <= v <= hi[i]):
                    bad += 1
                if math.isinf(lo[i]) or math.isinf(hi[i]):
                    continue
                c = 0.5 * (lo[i] + hi[i])
                hw = 0.5 * (hi[i] - lo[i])
                e = abs(c - v)
                e_abs = max(e_abs, e)
                if hw > 0:
                    e_rel = max(e_rel, e / hw)
                elif e > 0:
                    e_rel = math.inf
        out[j, 0] = e_abs
        out[j, 1] = e_rel
        out[j, 2] = bad
        out[j, 3] = nf
