"""Private numerical helpers shared by every module.

* Even functions with removable singularities at 0 (``sin x / x`` and friends), written as functions
  of ``x**2`` so that they stay smooth where ``|x|`` is not, evaluated by a Taylor series near 0 and
  the closed form elsewhere, with the double-``where`` trick so that neither branch can leak a NaN
  into values or gradients.
* The one straight-through helper of the package.
* A pseudo-inverse for tall ``(n, 2)`` matrices, exact and differentiable, with an exact zero
  determinant when fewer than two rows are active (see :func:`pinv_tall2`).
"""

from __future__ import annotations

import contextlib
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from . import _config  # noqa: F401  (float64 before any array is made)


def float_dtype(*xs):
    """The floating dtype the inputs promote to (float64 when x64 is on and nothing says otherwise)."""
    return jnp.result_type(*xs, float)


def eps_of(x) -> float:
    return float(jnp.finfo(float_dtype(x)).eps)


def _series_threshold(x2) -> float:
    # Balance the closed form's cancellation error (~eps / x^2) against the truncation error of a
    # series kept to x^8 (~1e-8 x^10): float64 -> |x| < 0.23, float32 -> |x| < 1.2.
    return (eps_of(x2) * 1e8) ** (1.0 / 6.0)


def _even_fn(x2, closed, coeffs):
    """f(x) for an even f given x2 = x**2: series sum(c_k x2^k) near 0, `closed(x)` elsewhere."""
    x2 = jnp.asarray(x2, float_dtype(x2))
    small = x2 < _series_threshold(x2)
    x2_safe = jnp.where(small, jnp.ones_like(x2), x2)  # double-where: the unused branch stays finite
    big = closed(jnp.sqrt(x2_safe))
    series = jnp.polyval(jnp.asarray(coeffs[::-1], x2.dtype), x2)
    return jnp.where(small, series, big)


def _taylor(term, count=8):
    """``count`` Taylor coefficients ``term(k)``, k = 0, 1, ... (kept to x^14: the second derivatives
    taken of them by the statics stay accurate to ~1e-15 relative inside the series range)."""
    return [term(k) for k in range(count)]


_F = math.factorial
_SINC = _taylor(lambda k: (-1) ** k / _F(2 * k + 1))
_VERSINC = _taylor(lambda k: (-1) ** k / _F(2 * k + 2))
_CUBIC = _taylor(lambda k: (-1) ** (k + 1) * (2 * k + 2) / _F(2 * k + 3))
_SINC_COMP = _taylor(lambda k: (-1) ** k / _F(2 * k + 3))


# Closed forms as functions of (x, sin x, cos x): evaluated from x by the *_sq functions, or from a
# sine and cosine the caller already has (sinc_versinc_cubic).
def _sinc_closed(x, s, c):
    return s / x


def _versinc_closed(x, s, c):
    return (1.0 - c) / x**2


def _cubic_closed(x, s, c):
    return (x * c - s) / x**3


def _sinc_comp_closed(x, s, c):
    return (x - s) / x**3


def _of_x(closed):
    return lambda x: closed(x, jnp.sin(x), jnp.cos(x))  # the unused one is dropped by the compiler


def sinc_sq(x2):
    """sin(x)/x as a function of x2 = x**2."""
    return _even_fn(x2, _of_x(_sinc_closed), _SINC)


def versinc_sq(x2):
    """(1 - cos x)/x**2 as a function of x2 = x**2."""
    return _even_fn(x2, _of_x(_versinc_closed), _VERSINC)


def cubic_sq(x2):
    """(x cos x - sin x)/x**3 as a function of x2 = x**2 (twice the x2-derivative of sin(x)/x)."""
    return _even_fn(x2, _of_x(_cubic_closed), _CUBIC)


def sinc_comp_sq(x2):
    """(x - sin x)/x**3 as a function of x2 = x**2 (the K^2 coefficient of SO(3)'s left Jacobian)."""
    return _even_fn(x2, _of_x(_sinc_comp_closed), _SINC_COMP)


def sinc_versinc_cubic(x, sin_x, cos_x):
    """``(sinc_sq, versinc_sq, cubic_sq)`` of ``x**2`` from ``sin x`` and ``cos x`` the caller already has.

    The same series, switch and closed forms as the functions above, without evaluating a sine or
    cosine: float64 ``sin``/``cos`` cost ~15 ns each on XLA:CPU, the largest part of a kinematic sweep.
    Double ``where`` on ``x``: the closed forms see ``x = 1`` inside the series range.
    """
    x2 = x * x
    small = x2 < _series_threshold(x2)
    xs = jnp.where(small, jnp.ones_like(x), x)
    return tuple(
        jnp.where(small, jnp.polyval(jnp.asarray(coeffs[::-1], x2.dtype), x2), closed(xs, sin_x, cos_x))
        for coeffs, closed in ((_SINC, _sinc_closed), (_VERSINC, _versinc_closed), (_CUBIC, _cubic_closed))
    )


def with_derivatives(f, x2, order=1):
    """``(f, f', ...)`` up to ``order`` (1 or 2) for an even function of ``x2`` from this module,
    by forward mode on the scalar: the series branch differentiates its polynomial, the closed branch
    its closed form, and the double ``where`` keeps both finite."""
    one = jnp.ones_like(x2)
    if order == 1:
        return jax.jvp(f, (x2,), (one,))
    (f0, f1), (_, f2) = jax.jvp(lambda x: jax.jvp(f, (x,), (jnp.ones_like(x),)), (x2,), (one,))
    return f0, f1, f2


_SURROGATE = [True]


@contextlib.contextmanager
def frozen_masks():
    """Inside this context, functions *traced* here see every straight-through mask as a constant
    (zero gradient): the exact gradient of the piecewise-smooth function, which finite differences
    reproduce away from mask switches. For checks and diagnostics; jit-compiled functions keep the
    behaviour they were traced with, so trace (call a fresh ``jit``) inside the context."""
    _SURROGATE.append(False)
    try:
        yield
    finally:
        _SURROGATE.pop()


def keep(xs, anchor):
    """The list of arrays ``xs`` unchanged, each computed once: a fusion barrier for XLA:CPU.

    XLA:CPU has no multi-output fusion: it re-computes a fusible producer inside the loop of every
    consumer, so a pose's sines and cosines were evaluated once per output measure (17 outputs).
    The values pass through a conditional whose predicate (``anchor`` is finite) is known only at run
    time; its operands are materialised once, and both branches return them (one as ``x + 0``, so that
    the compiler cannot merge the branches and drop the conditional). ``anchor`` is a scalar that is
    not batched where ``keep`` runs under ``vmap`` (the design's length): a batched predicate turns
    the conditional into a select, which is still exact but no barrier. Exact (the branch never taken
    for a finite anchor may turn ``-0.0`` into ``+0.0``); linear, so gradients pass unchanged.
    (The earlier barrier, a product with the 2x2 identity, cost a library call and two transposes per
    keep: about a third of a kinematic sweep.)
    """
    xs = tuple(xs)
    pred = jnp.isfinite(jnp.asarray(anchor))
    return list(jax.lax.cond(pred, lambda t: t, lambda t: tuple(x + jnp.zeros_like(x) for x in t), xs))


@jax.custom_jvp
def _hard_value_soft_tangent(hard, soft):
    return hard


@_hard_value_soft_tangent.defjvp
def _hard_value_soft_tangent_jvp(primals, tangents):
    return primals[0], tangents[1]


def straight_through(hard, soft):
    """Forward value exactly ``hard``; gradient that of ``soft``.

    A custom JVP (value ``hard``, tangent ``soft``'s) rather than ``hard + (soft - stop_gradient(soft))``:
    the forward value is bit-for-bit the hard value, and a program that is not differentiated never
    evaluates ``soft`` (the compiler drops it; n exponentials per pose fewer in a sweep).
    """
    hard = jax.lax.stop_gradient(jnp.asarray(hard, soft.dtype))
    if not _SURROGATE[-1]:
        return hard
    return _hard_value_soft_tangent(hard, soft)


def nan_where(bad, out):
    """NaN in, NaN out: every floating leaf of ``out`` (a dict or other pytree) NaN where ``bad``;
    integer leaves (counts) ``-1`` and boolean leaves (flags) ``False`` there.

    The measures guard their square roots and divisions (double ``where``), which would otherwise
    turn a NaN input into a plausible 0; this one select at the end restores it. ``bad`` is a scalar
    (a pose's inputs or the design's values); finite inputs keep their values and gradients.
    """

    def one(x):
        x = jnp.asarray(x)
        if jnp.issubdtype(x.dtype, jnp.inexact):
            return jnp.where(bad, jnp.nan, x)
        return jnp.where(bad, False if x.dtype == jnp.bool_ else -1, x).astype(x.dtype)

    if isinstance(out, dict):  # keep the keys' order (tree_map would sort them)
        return {k: nan_where(bad, v) for k, v in out.items()}
    return jax.tree_util.tree_map(one, out)


def not_finite(*xs):
    """True where any of the arrays has a NaN or an infinite entry (a scalar)."""
    return functools.reduce(jnp.logical_or, [~jnp.all(jnp.isfinite(jnp.asarray(x))) for x in xs])


#: ``skew(w) = _CROSS @ w``: the cross-product matrix as one product with a constant (the nine
#: elements written out traced about 28 operations per call, some 15 % of the calibration model).
_CROSS = np.array(
    [[[0, 0, 0], [0, 0, -1], [0, 1, 0]], [[0, 0, 1], [0, 0, 0], [-1, 0, 0]], [[0, -1, 0], [1, 0, 0], [0, 0, 0]]],
    dtype=np.float64,
)


def skew(w):
    """(3,) -> (3, 3) cross-product matrix."""
    return jnp.tensordot(jnp.asarray(_CROSS, dtype=jnp.result_type(w)), w, axes=1)


def vee(S):
    """(3, 3) skew part -> (3,), inverse of :func:`skew` (antisymmetrised)."""
    return 0.5 * jnp.array([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]])


def rotvec_to_matrix(w, t2=None):
    """Rodrigues' formula ``I + sinc K + versinc K^2`` (``K = skew(w)``), smooth at ``w = 0``, written
    entry by entry (``K^2 = w w^T - |w|^2 I``): vmapped it fuses, no tiny matrix products. ``t2``:
    ``|w|^2``, where the caller has it (the compiler then shares its sine and cosine with the caller's)."""
    x, y, z = w[0], w[1], w[2]
    t2 = x * x + y * y + z * z if t2 is None else t2
    s, c = sinc_sq(t2), versinc_sq(t2)
    xy, xz, yz = c * x * y, c * x * z, c * y * z
    return jnp.stack(
        [
            jnp.stack([1.0 - c * (y * y + z * z), xy - s * z, xz + s * y]),
            jnp.stack([xy + s * z, 1.0 - c * (x * x + z * z), yz - s * x]),
            jnp.stack([xz - s * y, yz + s * x, 1.0 - c * (x * x + y * y)]),
        ]
    )


# --------------------------------------------------------------------------------------------
# Per-wire values: a list of n per-pose scalars (few wires) or an (n,) array (many)
# --------------------------------------------------------------------------------------------
#: Up to this many wires, per-wire work is written on lists of per-pose scalars, unrolled: vmapped
#: they are plain (N,) arrays that XLA:CPU fuses, the fastest to run (benchmarks/README.md). Above
#: it, on (n,) arrays: the unrolled program grows with n (pair terms with n^2) and so does its
#: compile time (at 24 wires the kinematic measures' program compiles far longer than it runs); the
#: array program does not.
UNROLL_MAX_WIRES = 8


_COMPACT = [False]


@contextlib.contextmanager
def compact_programs():
    """Inside this context, functions *traced* here take the forms that compile fastest: per-wire
    work on (n,) arrays and the statics' free sets vectorised, whatever the wire count.

    For programs whose compile time outweighs their run time, such as the design optimiser's (its
    compile is most of its first run, and the compact forms compile faster). Same values up to
    rounding. Like :func:`frozen_masks`, a ``jit`` keeps the form it was
    traced with: trace inside the context.
    """
    _COMPACT.append(True)
    try:
        yield
    finally:
        _COMPACT.pop()


def compact() -> bool:
    """Whether :func:`compact_programs` is in force."""
    return _COMPACT[-1]


def unrolled(n: int) -> bool:
    """Whether ``n`` wires are handled as a list of scalars (else as an array)."""
    return n <= UNROLL_MAX_WIRES and not compact()


def _is_list(xs) -> bool:
    return isinstance(xs, (list, tuple))


def per_wire(x):
    """An (n,) array in the per-wire form for its wire count: a list of its n entries or itself."""
    return [x[k] for k in range(x.shape[0])] if unrolled(x.shape[0]) else x


def wmap(f, *xss):
    """``f`` applied wire by wire (elementwise) to per-wire values of one form."""
    return [f(*t) for t in zip(*xss)] if _is_list(xss[0]) else f(*xss)


def wsum(xs):
    """Sum over the wires (a list is summed left to right, as Python's ``sum``)."""
    return sum(xs) if _is_list(xs) else jnp.sum(xs, axis=0)


def wmax(xs):
    """Maximum over the wires."""
    return functools.reduce(jnp.maximum, xs) if _is_list(xs) else jnp.max(xs, axis=0)


def wstack(xs):
    """Per-wire values as an (n,) array."""
    return jnp.stack(xs) if _is_list(xs) else xs


def cauchy_binet(a, b):
    """``sum_{i<j} (a_i b_j - b_i a_j)^2``: the determinant of ``J^T J`` for ``J = [a b]`` (n, 2)
    given by its columns (per-wire values). Exactly 0 when at most one row is non-zero, and accurate
    when small. Pairs only (the diagonal is left out: under FMA it need not be exactly 0). Arrays:
    the (n, n) pair terms in one reduction, which XLA fuses (nothing of size n^2 is stored)."""
    if _is_list(a):
        n = len(a)
        return sum((a[i] * b[j] - b[i] * a[j]) ** 2 for i in range(n) for j in range(i + 1, n))
    C = a[:, None] * b[None, :] - b[:, None] * a[None, :]
    upper = np.triu(np.ones((a.shape[0],) * 2, bool), 1)
    return jnp.sum(jnp.where(upper, C * C, 0.0), axis=(0, 1))


def pinv_tall2(J):
    """Moore-Penrose pseudo-inverse of an ``(n, 2)`` matrix, ``(2, n)``.

    ``pinv(J) = pinv(G) J^T`` with the 2x2 Gram matrix ``G = J^T J``. Its determinant is taken by
    Cauchy-Binet as the sum of squared 2x2 row minors, so it is exactly zero when fewer than two rows
    are non-zero (one taut wire) and accurate when small. Rank 2 when ``det > rcond^2 tr(G)^2`` with
    NumPy's default ``rcond = max(n, 2) * eps`` on singular values; rank 1 uses
    ``pinv(G) = G / tr(G)^2``; rank 0 gives zeros. Both branches are guarded (double ``where``).
    """
    r0, r1 = pinv_tall2_cols(per_wire(J[:, 0]), per_wire(J[:, 1]))
    return jnp.stack([wstack(r0), wstack(r1)])


def pinv_tall2_cols(a, b):
    """The pseudo-inverse of :func:`pinv_tall2` (its one implementation), the matrix given by its two
    columns ``a``, ``b`` as per-wire values (lists of ``n`` scalars, or (n,) arrays above
    :data:`UNROLL_MAX_WIRES`).

    Returns the rows of the (2, n) pseudo-inverse in the same form. Lists are written elementwise:
    vmapped over poses these are plain (N,) arrays that XLA fuses, where the matrix form becomes
    tiny batched matmuls and ``triu_indices`` gathers.
    """
    return pinv_rows(gram_pinv_cols(a, b), a, b)


def gram_pinv_cols(a, b):
    """``(i00, i01, i11)``: the entries of ``pinv(G)``, ``G = J^T J``, for the matrix ``J`` (n, 2) given
    by its columns (see :func:`pinv_tall2`); ``pinv(J) = pinv(G) J^T`` (:func:`pinv_rows`)."""
    n = len(a) if _is_list(a) else a.shape[0]
    g00 = wsum(wmap(lambda x: x * x, a))
    g01 = wsum(wmap(lambda x, y: x * y, a, b))
    g11 = wsum(wmap(lambda y: y * y, b))
    det = cauchy_binet(a, b)
    tr = g00 + g11
    rcond = max(n, 2) * eps_of(g00)
    # ~(x <= y) rather than x > y: the same for numbers, and NaN goes through (never a plausible 0)
    rank2 = ~(det <= (rcond * tr) ** 2)
    rank_pos = ~(tr <= 0)
    det_safe = jnp.where(rank2, det, 1.0)
    tr_safe = jnp.where(rank_pos, tr, 1.0)

    def inv(adj, g):  # one entry of pinv(G): adj / det (rank 2), G / tr^2 (rank 1), 0
        return jnp.where(rank2, adj / det_safe, jnp.where(rank_pos, g / tr_safe**2, 0.0))

    return inv(g11, g00), inv(-g01, g01), inv(g00, g11)


def pinv_rows(gram_pinv, a, b):
    """The rows of ``pinv(J) = pinv(G) J^T`` (per-wire values) from :func:`gram_pinv_cols`."""
    i00, i01, i11 = gram_pinv
    return wmap(lambda x, y: i00 * x + i01 * y, a, b), wmap(lambda x, y: i01 * x + i11 * y, a, b)


# -- the pseudo-inverse of a matrix's rows kept by a 0/1 mask ------------------------------------------
#: A vmapped :func:`masked_pinv` whose matrix is shared and whose mask is batched takes each mask's
#: pseudo-inverse from a table of every mask (``2^N`` entries) when the batch has at least this many
#: members per entry: the table's cost is then shared by them (a batch of LAPACK calls costs about the
#: same per matrix), and each member's is a lookup.
MASK_TABLE_SHARE = 2


def _masked_pinv(A, mask):
    """``pinv(A * mask[:, None]) * mask[None, :]`` for ``A`` (N, n), ``mask`` (N,)."""
    return jnp.linalg.pinv(A * mask[:, None]) * mask[None, :]


@jax.custom_batching.custom_vmap
def _masked_pinv_batched(A, mask):
    return _masked_pinv(A, mask)


@_masked_pinv_batched.def_vmap
def _masked_pinv_rule(axis_size, in_batched, A, mask):
    a_batched, m_batched = in_batched
    if a_batched or not m_batched or not uses_mask_table(A.shape[-2], axis_size):
        return jax.vmap(_masked_pinv, in_axes=(0 if a_batched else None, 0 if m_batched else None))(A, mask), True
    index = jnp.sum(jnp.where(mask > 0.5, 2 ** jnp.arange(A.shape[-2]), 0), axis=1)
    return _table_for(A)[index], True


def uses_mask_table(n_rows: int, batch: int) -> bool:
    """Whether :func:`masked_pinv` vmapped over ``batch`` masks of one (n_rows, n) matrix takes them
    from a table of every mask (:data:`MASK_TABLE_SHARE`)."""
    return batch >= MASK_TABLE_SHARE * 2**n_rows


def mask_table(A):
    """Every mask's :func:`masked_pinv` of ``A`` (N, n): (2^N, n, N), entry ``i`` for the mask whose
    wire ``k`` is bit ``k`` of ``i``."""
    every = jnp.asarray(_mask_bits(A.shape[-2]), A.dtype)
    return jax.vmap(_masked_pinv, in_axes=(None, 0))(A, every)


_SHARED_TABLES: list = []


@contextlib.contextmanager
def shared_mask_table(A, table):
    """Inside this context, functions *traced* here that vmap :func:`masked_pinv` over masks of a
    matrix equal to ``A`` take ``table`` (:func:`mask_table` of ``A``, made once, e.g. for a whole
    sweep) instead of making the table in every call. Checked where it runs: a matrix that differs
    from ``A`` in any entry makes its own table."""
    _SHARED_TABLES.append((A, table))
    try:
        yield
    finally:
        _SHARED_TABLES.pop()


def _table_for(A):
    """The shared table of the innermost :func:`shared_mask_table` of ``A``'s shape and dtype where
    its matrix equals ``A``, else ``A``'s own."""
    shared = [(ref, t) for ref, t in _SHARED_TABLES if ref.shape == A.shape and ref.dtype == A.dtype]
    if not shared:
        return mask_table(A)
    ref, table = shared[-1]
    return jax.lax.cond(jnp.all(A == ref), lambda: table, lambda: mask_table(A))


@functools.cache
def _mask_bits(n: int) -> np.ndarray:
    """(2^n, n): row ``i`` holds the bits of ``i``, wire ``k`` at bit ``k``."""
    return (np.arange(2**n)[:, None] >> np.arange(n)[None, :]) & 1


@jax.custom_jvp
def masked_pinv(A, mask):
    """The pseudo-inverse of ``A`` (N, n) with only the rows ``mask`` (N,) 0/1 keeps, its other columns
    zero: ``pinv(A * mask[:, None]) * mask[None, :]``, (n, N) (JAX's ``pinv`` and its rank rule).

    Vmapped over masks of a shared ``A``, each member's matrix comes from a table of every mask's
    (:data:`MASK_TABLE_SHARE`), which turns a batch of SVDs into a lookup. Derivatives (in ``A`` and in
    the mask, e.g. a straight-through one) are those of the formula.
    """
    return _masked_pinv_batched(A, mask)


@masked_pinv.defjvp
def _masked_pinv_jvp(primals, tangents):
    return jax.jvp(_masked_pinv, primals, tangents)


# -- singular values of a small matrix by one-sided Jacobi ----------------------------------------
#: The most Jacobi sweeps (each rotates every pair of rows once); convergence is quadratic, so a few
#: suffice in practice and the loop ends as soon as every pair is orthogonal to rounding.
JACOBI_MAX_SWEEPS = 30
#: Sweeps written out before the loop: vmapped, a loop's step is taken by the whole batch until its
#: last member has converged, each member's state kept by a select; a 3 x 3 factor converges to
#: rounding in about four sweeps, so the loop that follows rarely runs (it ends every member).
JACOBI_UNROLLED = 4
#: Jacobi's rotations grow as the square of the rows, LAPACK's batch of calls costs about the same per
#: matrix: vmapped over a chunk, Jacobi is the faster up to three rows (a robot's (3, N) Jacobian
#: blocks), LAPACK from six (a three-segment robot's (N, 6) taut wire directions).
JACOBI_MAX_ROWS = 3


def dot_lists(u, v):
    """Dot product of two vectors given as lists of scalars."""
    return sum(x * y for x, y in zip(u, v))


def _gram_schmidt_rows(rows):
    """Modified Gram-Schmidt on ``k`` rows of ``n`` scalars (k <= n): the rows of ``L`` (k, k), lower
    triangular, with ``R = L Q_0`` and ``Q_0``'s rows orthonormal. ``L``'s singular values are ``R``'s
    to ``O(n eps |R|)``: MGS's triangular factor is backward stable (Bjorck & Paige 1992), also where
    ``R`` is rank deficient. A zero row gives a zero column."""
    k = len(rows)
    zero = jnp.zeros((), rows[0][0].dtype)
    r = [list(x) for x in rows]
    L = [[zero] * k for _ in range(k)]
    for i in range(k):
        size = jnp.sqrt(dot_lists(r[i], r[i]))
        L[i][i] = size
        q = [x / jnp.where(size > 0, size, 1.0) for x in r[i]]
        for j in range(i + 1, k):
            L[j][i] = dot_lists(q, r[j])
            r[j] = [x - L[j][i] * y for x, y in zip(r[j], q)]
    return L


def _jacobi_rows(rows, tol, rotation=True):
    """One-sided Jacobi (Hestenes) on ``k`` rows (lists of scalars): plane rotations ``Q`` (k, k),
    orthogonal, such that the rows of ``W = Q R`` are orthogonal (each pair to ``tol``); their norms are
    ``R``'s singular values. Every step is a scalar operation: vmapped, each is one elementwise
    operation over the batch (the batch is the contiguous axis), and the sweeps run until every member
    has converged. Returns ``W`` and ``Q`` as lists of rows (``Q`` only with ``rotation``, else
    ``None``: the values alone carry half the state)."""
    k = len(rows)
    dtype = rows[0][0].dtype
    pairs = [(i, j) for i in range(k) for j in range(i + 1, k)]
    floor = tol * sum(dot_lists(x, x) for x in rows)  # rows of rounding's size (a zero singular value) point anywhere

    def rotate(u, v, cs, sn):
        return [cs * x - sn * y for x, y in zip(u, v)], [sn * x + cs * y for x, y in zip(u, v)]

    def sweep(state):
        r, q, n, _ = state
        r, q, worst = [list(x) for x in r], [list(x) for x in q], jnp.zeros((), dtype)
        for i, j in pairs:
            a, b, c = dot_lists(r[i], r[i]), dot_lists(r[j], r[j]), dot_lists(r[i], r[j])
            size = jnp.maximum(jnp.sqrt(a) * jnp.sqrt(b), floor)
            worst = jnp.maximum(worst, jnp.abs(c) / jnp.where(size > 0, size, 1.0))
            t = _jacobi_tangent(a, b, c)
            cs = 1.0 / jnp.sqrt(1.0 + t * t)
            r[i], r[j] = rotate(r[i], r[j], cs, cs * t)
            if rotation:
                q[i], q[j] = rotate(q[i], q[j], cs, cs * t)
        return _tuples(r), _tuples(q), n + 1, worst

    def going(state):
        return (state[2] < JACOBI_MAX_SWEEPS) & ~(state[3] <= tol)  # (NaN ends at the cap)

    eye = _rows(jnp.eye(k, dtype=dtype)) if rotation else []
    state = (_tuples(rows), _tuples(eye), jnp.zeros((), jnp.int32), jnp.ones((), dtype))
    for _ in range(0 if rotation else JACOBI_UNROLLED):  # values only: the derivative's program stays small
        state = sweep(state)
    W, Q, _, _ = jax.lax.while_loop(going, sweep, state)
    return W, (Q if rotation else None)


def _jacobi_tangent(a, b, c):
    """``t = tan(theta)`` of the rotation that makes two rows orthogonal, from their squared norms ``a``,
    ``b`` and dot product ``c``: the smaller root of ``t^2 + 2 zeta t = 1``, ``zeta = (b - a) / (2 c)``,
    written as ``2 c / (d + sqrt(d^2 + 4 c^2))`` with ``d = |b - a|`` (sign of ``b - a``, ``+`` at a tie):
    no division by ``c``, ``|t| <= 1`` for any rounding of the inputs, 0 where ``c = 0`` and 45 degrees
    where ``a = b``."""
    d = b - a
    den = jnp.abs(d) + jnp.sqrt(d * d + 4.0 * c * c)  # (rows scaled to entries <= 1: no overflow)
    t = jnp.where(d >= 0, 2.0, -2.0) * c / jnp.where(den > 0, den, 1.0)
    return jnp.where(den > 0, t, 0.0)


def _rows(M):
    """The rows of a matrix as lists of scalars."""
    return [[M[i, j] for j in range(M.shape[1])] for i in range(M.shape[0])]


def _tuples(rows):
    """Rows of scalars as a loop's state (tuples)."""
    return tuple(tuple(x) for x in rows)


def _scaled_jacobi(R, rotation=True):
    """Jacobi (:func:`_jacobi_rows`) on the Gram-Schmidt factor (:func:`_gram_schmidt_rows`) of
    ``R / c`` (k, n), ``c`` its largest entry's magnitude (squares neither underflow nor overflow): the
    rotation ``Q`` (k, k; ``None`` without ``rotation``), the singular values of ``R / c`` (k,),
    unsorted, and ``c``. Rotating the ``k x k`` factor rather than the ``k x n`` rows costs ``k^2`` per
    step, not ``k n``."""
    c = jnp.max(jnp.abs(R))
    c = jnp.where(c > 0, c, 1.0)
    W, Q = _jacobi_rows(_gram_schmidt_rows(_rows(R / c)), R.shape[1] * eps_of(R), rotation)  # tol: a dot's rounding
    return (jnp.asarray(Q) if rotation else None), jnp.stack([jnp.sqrt(dot_lists(w, w)) for w in W]), c


@jax.custom_jvp
def _row_norms_orthogonalised(R):
    """The singular values of ``R`` (k, n), k <= n, unsorted (:func:`_scaled_jacobi`)."""
    _, s, c = _scaled_jacobi(R, rotation=False)
    return c * s


@_row_norms_orthogonalised.defjvp
def _row_norms_orthogonalised_jvp(primals, tangents):
    """``d sigma_i = u_i^T dR v_i`` with ``u_i`` row ``i`` of ``Q`` and ``v_i = W_i / |W_i|``,
    ``W = Q R`` (JAX's ``svd`` rule): finite where two values meet (no rotation angle is
    differentiated), 0 at a zero."""
    (R,), (dR,) = primals, tangents
    Q, s, c = _scaled_jacobi(R)
    W = Q @ (R / c)
    n = jnp.sqrt(jnp.sum(W * W, axis=1))
    pos = n > 0
    ds = jnp.einsum("ki,ij,kj->k", Q, dR, W) / jnp.where(pos, n, 1.0)
    return c * s, jnp.where(pos, ds, 0.0)


def singular_values(A):
    """The singular values of a small matrix ``A`` (m, n), descending (``min(m, n)``): those of
    ``jnp.linalg.svd(A, compute_uv=False)`` to rounding. Up to :data:`JACOBI_MAX_ROWS` rows of ``A``
    or ``A^T`` (whichever has fewer) by one-sided Jacobi (:func:`_jacobi_rows`), beyond by LAPACK;
    the derivative is finite where two values meet."""
    k = min(A.shape)
    if k > JACOBI_MAX_ROWS:
        return jnp.linalg.svd(A, compute_uv=False)
    s = _row_norms_orthogonalised(A if A.shape[0] <= A.shape[1] else A.T)
    if k == 3:  # a sorting network: three elementwise minima and maxima
        hi, lo = jnp.maximum(s[0], s[1]), jnp.minimum(s[0], s[1])
        return jnp.stack([jnp.maximum(hi, s[2]), jnp.maximum(lo, jnp.minimum(hi, s[2])), jnp.minimum(lo, s[2])])
    return -jnp.sort(-s)
