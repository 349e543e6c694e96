"""Two largest eigenvalues of a symmetric positive semi-definite 3x3, flat scalars (no stacked matrices).

``sym3_top2`` is the eigenvalue step of the kernel's singular values (:func:`deltajax.indices.singular_values`):
``method="fast"`` a closed-form cubic without inverse trig (polynomial start + one Halley step), or
``"jacobi"`` cyclic Jacobi sweeps (exact to ~eps, repeated eigenvalues too). Both share one custom JVP that is
finite everywhere, repeated eigenvalues included (the gradient users depend on it).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax import lax

__all__ = ["sym3_top2", "T_POLY", "recip", "rsqrt", "sqrt0", "fuse_outputs"]

# -- per-point arithmetic for XLA:CPU (public face: deltajax.fastmath, which explains why) -----------------------
# (integer type, reciprocal magic, inverse-square-root magic, cubic-order Newton steps) per float type: the
# magic constants give a first guess within 12.5 % (1/x) / 3.5 % (1/sqrt x); each cubic step cubes the error
_BITS = {
    jnp.dtype(jnp.float64): (jnp.int64, 0x7FDE623822FC16E6, 0x5FE6EB50C7B537A9, 3),
    jnp.dtype(jnp.float32): (jnp.int32, 0x7EF311C7, 0x5F375A86, 2),
}


def _bits(x):
    x = jnp.asarray(x)
    if x.dtype not in _BITS:
        raise TypeError(f"fastmath supports float32/float64, got {x.dtype}")
    return x, _BITS[x.dtype]


@jax.custom_jvp
def recip(x):
    """1/x for positive normal x (the caller guards zero, sign and non-finite inputs), ~1 ulp."""
    x, (it, magic, _, steps) = _bits(x)
    y = lax.bitcast_convert_type(jnp.asarray(magic, it) - lax.bitcast_convert_type(x, it), x.dtype)
    for _ in range(steps):
        e = 1.0 - x * y
        y = y + y * (e + e * e)
    e = 1.0 - x * y
    return y + y * e  # last step quadratic: rounding


@recip.defjvp
def _recip_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    y = 1.0 / x  # plain divide under differentiation (see _PLAIN)
    return y, -dx * y * y


@jax.custom_jvp
def rsqrt(x):
    """1/sqrt(x) for positive normal x (the caller guards the rest), ~1 ulp."""
    x, (it, _, magic, steps) = _bits(x)
    y = lax.bitcast_convert_type(jnp.asarray(magic, it) - (lax.bitcast_convert_type(x, it) >> 1), x.dtype)
    for _ in range(steps):
        e = 1.0 - x * y * y
        y = y + y * e * (0.5 + 0.375 * e)
    e = 1.0 - x * y * y
    return y + 0.5 * y * e


@rsqrt.defjvp
def _rsqrt_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    y = lax.rsqrt(x)  # plain under differentiation (see _PLAIN)
    return y, -0.5 * dx * y * y * y


@jax.custom_jvp
def sqrt0(x):
    """sqrt(max(x, 0)), ~1 ulp; derivative 0 at and below 0 (finite everywhere, no 0 * inf)."""
    x = jnp.asarray(x)
    xs = jnp.where(x > 0.0, x, 0.0)
    y = rsqrt(jnp.maximum(xs, jnp.finfo(x.dtype).tiny))
    s = xs * y
    return s + 0.5 * y * (xs - s * s)


@sqrt0.defjvp
def _sqrt0_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    x = jnp.asarray(x)
    pos = x > 0.0
    y = lax.rsqrt(jnp.where(pos, x, 1.0))  # plain under differentiation (see _PLAIN)
    return jnp.where(pos, x * y, 0.0), jnp.where(pos, 0.5 * dx * y, 0.0)


def _sqrt0_plain(x):
    pos = x > 0.0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


#: (recip, rsqrt, sqrt0) of the forward kernels, and their plain twins (divide, lax.rsqrt, sqrt) for every program
#: that is differentiated: the JVP rules above and sym3_top2's. The bit-trick Newton chains reuse each iterate
#: several times; in a transposed (reverse-mode) program under vmap XLA:CPU fuses them through the slices, pads
#: and concatenates of the backward pass and re-emits each reuse instead of sharing it, so the work grows
#: geometrically with the chain depth: jit(vmap(grad(k_tilde))) ran for minutes on 4 points without returning.
_PLAIN = (lambda x: 1.0 / x, lax.rsqrt, _sqrt0_plain)


def _sink(leaves):
    lane0 = lax.iota(jnp.int32, 2) == 0
    ops = tuple(jnp.where(lane0.reshape((1,) * v.ndim + (2,)), v[..., None], jnp.zeros((), v.dtype))
                for v in leaves)
    init = tuple(jnp.zeros((), v.dtype) for v in leaves)

    def combine(a, b):
        return tuple((u | w) if u.dtype == jnp.bool_ else u + w for u, w in zip(a, b))

    return lax.reduce(ops, init, combine, (ops[0].ndim - 1,))


@jax.custom_jvp
def _fused(*leaves):
    return tuple(_sink(leaves))


@_fused.defjvp
def _fused_jvp(primals, tangents):
    return _fused(*primals), tuple(tangents)


def fuse_outputs(tree):
    """``tree`` unchanged (every leaf the same value, shape and dtype), as outputs of ONE XLA:CPU loop.

    Apply it to what a per-point function returns (under ``vmap`` each leaf is a per-point array): the leaves'
    shared intermediates are then computed once per point instead of once per output. Leaves of any (small)
    shape and of float, integer or bool dtype, split into scalars for the one variadic reduce and stacked back
    after it; -0.0 comes back as +0.0. Differentiable (identity tangents).
    """
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    if not leaves:
        return tree
    arrays = [jnp.asarray(v) for v in leaves]
    scalars = [a.reshape(-1)[k] for a in arrays for k in range(a.size)]
    fused = list(_fused(*scalars))
    out = []
    for a in arrays:
        parts, fused = fused[:a.size], fused[a.size:]
        out.append(parts[0].reshape(a.shape) if a.ndim == 0 else jnp.stack(parts).reshape(a.shape))
    return jax.tree_util.tree_unflatten(treedef, out)


_FAST = (recip, rsqrt, sqrt0)

# -- the eigenvalue solvers --------------------------------------------------------------------------------------
#: t = u P(u), u = sqrt(c), approximates the root t in [0, 1] of t^2 (t + 3) = c (c in [0, 4]) to 3.2e-6
#: relative (least-squares Chebyshev fit); one Halley step then gives ~3e-16 relative (measured over 4e5 c).
T_POLY = (0.5773484152710456, -0.055513434266994274, 0.013131880611233873, -0.0035774990190131535,
           0.0007894847448390405, -8.944924427049106e-05)


def _cubic_root01(c, ops=None):
    """The root t in [0, 1] of t^2 (t + 3) = c for c in [0, 4]: polynomial start in sqrt(c), one Halley step."""
    recip, _, sqrt0 = ops or _FAST
    u = sqrt0(c)
    poly = T_POLY[-1]
    for a in T_POLY[-2::-1]:
        poly = poly * u + a
    t = u * poly
    g = t * t * (t + 3.0) - c
    g1 = 3.0 * t * (t + 2.0)
    g2 = 6.0 * (t + 1.0)
    den = 2.0 * g1 * g1 - g * g2  # >= 0 near the root; 0 only at c = t = 0 where g = 0 too
    return t - 2.0 * g * g1 * recip(den + jnp.finfo(jnp.result_type(c)).tiny)


def _eig_top2_fast(x00, x11, x22, x01, x02, x12, c2, det, ops=None):
    """Two largest eigenvalues of a symmetric PSD 3x3 by the closed-form cubic, without inverse trig.

    With q = tr/3, p^2 = ||X - q I||_F^2 / 6 and r = det((X - q I)/p) / 2 in [-1, 1], the eigenvalues are
    q + p x with x^3 - 3x = 2r. The largest x = 1 + t, t^2 (t + 3) = 2 (1 + r) (polynomial start and one
    Halley step, :func:`_cubic_root01`): lambda_1 = q + p (1 + t), all terms positive, relative accuracy ~eps.
    lambda_2 does not come from the cubic's middle root (it cancels to ~sqrt(eps) lambda_1 when lambda_2,
    lambda_3 << lambda_1) but from the invariants the caller knows accurately: the sum of principal 2x2 minors
    ``c2`` and ``det``: lambda_2 lambda_3 = det / lambda_1 = pi, lambda_2 + lambda_3 = (c2 - pi) / lambda_1 =
    sigma, lambda_2 = sigma / 2 + sqrt(sigma^2 / 4 - pi) (no cancellation). A split below the cubic's
    ~sqrt(eps) noise (a repeated eigenvalue, e.g. on the robot's axis) is reported as the pair's mean.
    """
    recip, rsqrt, sqrt0 = ops or _FAST
    q = (x00 + x11 + x22) * (1.0 / 3.0)
    b00, b11, b22 = x00 - q, x11 - q, x22 - q
    p2 = (b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (x01 * x01 + x02 * x02 + x12 * x12)) * (1.0 / 6.0)
    # forward values only: derivatives come from sym3_top2's custom JVP, so no double-where guards here; cheap-op
    # rsqrt/recip/sqrt0 (deltajax.fastmath) keep the whole kernel in one XLA:CPU loop
    tiny = jnp.finfo(jnp.result_type(x00)).tiny
    rp = rsqrt(jnp.maximum(p2, tiny))
    p = p2 * rp
    det_b = b00 * (b11 * b22 - x12 * x12) - x01 * (x01 * b22 - x12 * x02) + x02 * (x01 * x12 - b11 * x02)
    r = jnp.clip(((0.5 * det_b * rp) * rp) * rp, -1.0, 1.0)  # det_b / (2 p^3), in an order that cannot overflow
    t = _cubic_root01(2.0 * (1.0 + r), ops)
    t2 = _cubic_root01(2.0 * (1.0 - r), ops)
    l1, l2c = q + p * (1.0 + t), q + p * (t2 - t)
    eps = jnp.finfo(jnp.result_type(x00)).eps
    # r carries an absolute error ~eps (1 + |q| / p) (cancellation in X - q I); t moves by its square root
    tie12 = (l1 - l2c) ** 2 <= 64.0 * eps * p * (p + jnp.abs(q))
    l1 = jnp.where(tie12, 0.5 * (l1 + l2c), l1)
    inv1 = recip(jnp.maximum(l1, tiny))  # X is PSD: l1 >= 0
    prod23 = det * inv1
    sum23 = (c2 - prod23) * inv1
    disc = 0.25 * sum23 * sum23 - prod23
    root = sqrt0(jnp.where(disc > 64.0 * eps * sum23 * sum23, disc, 0.0))
    l2 = jnp.where(tie12, l1, 0.5 * sum23 + root)
    return l1, l2


def _jacobi_rotate(A, p: int, q: int, ops=None):
    """One Jacobi rotation zeroing A[p, q] of a symmetric 3x3 matrix given as a dict of its 6 entries."""
    recip, rsqrt, _ = ops or _FAST
    r = 3 - p - q
    app, aqq, apq = A[(p, p)], A[(q, q)], A[(p, q)]
    arp, arq = A[(r, p)], A[(r, q)]
    fi = jnp.finfo(jnp.result_type(apq))
    zero = jnp.abs(apq) < fi.tiny  # 0 or subnormal: nothing to rotate (recip needs a normal argument)
    apq_safe = jnp.where(zero, 1.0, apq)
    # tau = (aqq - app) / (2 apq); t = sign(tau) / (|tau| + sqrt(1 + tau^2)); c = 1 / sqrt(1 + t^2): cheap-op
    # recip/rsqrt (deltajax.fastmath), each argument positive and normal where it is used
    atau = jnp.abs(aqq - app) * recip(2.0 * jnp.abs(apq_safe))
    sgn = jnp.where((aqq - app) * apq_safe >= 0.0, 1.0, -1.0)
    big = atau > 0.5 * float(fi.max) ** 0.5  # tau^2 would overflow: t = 1 / (2 |tau|) to full precision
    tau2 = jnp.where(big, 1.0, atau * atau)
    hyp = (1.0 + tau2) * rsqrt(1.0 + tau2)  # sqrt(1 + tau^2)
    t = jnp.where(zero, 0.0, sgn * jnp.where(big, 0.5 * recip(jnp.where(big, atau, 1.0)),
                                               recip(atau + hyp)))
    c = rsqrt(1.0 + t * t)
    s = t * c
    out = dict(A)
    out[(p, p)] = app - t * apq
    out[(q, q)] = aqq + t * apq
    out[(p, q)] = out[(q, p)] = jnp.zeros_like(apq)
    out[(r, p)] = out[(p, r)] = c * arp - s * arq
    out[(r, q)] = out[(q, r)] = s * arp + c * arq
    return out


def _eig_top2_jacobi(x00, x11, x22, x01, x02, x12, sweeps: int = 4, ops=None):
    """Two largest eigenvalues of a symmetric 3x3 by cyclic Jacobi (exact to ~eps ||X||, repeated ones too).

    Convergence is quadratic; 4 sweeps reach machine precision for 3x3. sqrt only, no inverse trig.
    """
    A = {(0, 0): x00, (1, 1): x11, (2, 2): x22, (0, 1): x01, (1, 0): x01, (0, 2): x02, (2, 0): x02,
         (1, 2): x12, (2, 1): x12}
    for _ in range(sweeps):
        for p, q in ((0, 1), (0, 2), (1, 2)):
            A = _jacobi_rotate(A, p, q, ops)
    e0, e1, e2 = A[(0, 0)], A[(1, 1)], A[(2, 2)]
    hi = jnp.maximum(jnp.maximum(e0, e1), e2)
    lo = jnp.minimum(jnp.minimum(e0, e1), e2)
    return hi, e0 + e1 + e2 - hi - lo




@functools.partial(jax.custom_jvp, nondiff_argnums=(8,))
def sym3_top2(x00, x11, x22, x01, x02, x12, c2, det, method: str = "fast"):
    """(lambda_1, lambda_2), the two largest eigenvalues of the symmetric PSD 3x3 [[x00, x01, x02],
    [., x11, x12], [., ., x22]]; scalars. ``c2`` (sum of the principal 2x2 minors) and ``det`` are the
    matrix's invariants, passed in because the caller knows them without cancellation (``"fast"`` uses them
    for lambda_2; ``"jacobi"`` ignores them). ``method``: ``"fast"`` (closed-form cubic) or ``"jacobi"``.

    Custom JVP (finite everywhere): d lambda = tr(adj(X - lambda I) dX) / tr(adj(X - lambda I)) (the
    eigen-projector) for an eigenvalue separated from the others by more than eps^0.4 max|lambda|; a pair
    closer than that gets the derivative of its mean (tr(dX) minus the isolated one's, halved), a triple
    tr(dX) / 3. The projector eigenvalues come from Jacobi in both methods; c2 and det must be consistent
    with X (their tangents are not used).
    """
    if method == "fast":
        return _eig_top2_fast(x00, x11, x22, x01, x02, x12, c2, det)
    if method == "jacobi":
        return _eig_top2_jacobi(x00, x11, x22, x01, x02, x12)
    raise ValueError(f"method must be 'fast' or 'jacobi', got {method!r}")


@sym3_top2.defjvp
def _sym3_top2_jvp(method, primals, tangents):
    x00, x11, x22, x01, x02, x12 = primals[:6]
    d00, d11, d22, d01, d02, d12 = tangents[:6]
    # plain arithmetic in the differentiated program (_PLAIN); values equal the forward ones to ~1 ulp
    lam1, lam2 = (_eig_top2_fast(*primals, ops=_PLAIN) if method == "fast"
                  else _eig_top2_jacobi(*primals[:6], ops=_PLAIN))
    l1, l2 = (lam1, lam2) if method == "jacobi" else _eig_top2_jacobi(*primals[:6], ops=_PLAIN)
    l3 = x00 + x11 + x22 - l1 - l2
    dtr = d00 + d11 + d22

    def proj(lam):
        a00, a11, a22 = x00 - lam, x11 - lam, x22 - lam
        c00 = a11 * a22 - x12 * x12
        c11 = a00 * a22 - x02 * x02
        c22 = a00 * a11 - x01 * x01
        c01 = x02 * x12 - x01 * a22
        c02 = x01 * x12 - x02 * a11
        c12 = x01 * x02 - a00 * x12
        num = c00 * d00 + c11 * d11 + c22 * d22 + 2.0 * (c01 * d01 + c02 * d02 + c12 * d12)
        return num, c00 + c11 + c22

    eps = jnp.finfo(jnp.result_type(x00)).eps
    tol = eps ** 0.4 * jnp.maximum(jnp.maximum(jnp.abs(l1), jnp.abs(l3)), jnp.finfo(jnp.result_type(x00)).tiny)
    sep12 = (l1 - l2) > tol
    sep23 = (l2 - l3) > tol
    n1, den1 = proj(l1)
    n3, den3 = proj(l3)
    g1 = n1 / jnp.where(sep12, den1, 1.0)
    g3 = n3 / jnp.where(sep23, den3, 1.0)
    dl1 = jnp.where(sep12, g1, jnp.where(sep23, 0.5 * (dtr - g3), dtr / 3.0))
    dl2 = jnp.where(sep12, jnp.where(sep23, dtr - g1 - g3, 0.5 * (dtr - g1)), dl1)
    return (lam1, lam2), (dl1, dl2)
