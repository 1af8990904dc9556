"""The one least-squares solver of the package: bounded, robust Levenberg-Marquardt, traced.

Used by the calibration (every fit of the loop) and by the paper's identification. Written to run
inside ``jit`` as one ``while_loop`` with one evaluation of the model per pass, so a calibration
compiles it once and then refits any subset of parameters (a 0/1 ``free`` mask), with any sample
weights, Huber threshold and iteration limit, without recompiling.

Why not ``jaxopt.LevenbergMarquardt``: on the FTDCR v4 fit both reach the same training RMSE, but
jaxopt compiles far longer, and it runs faster only by differentiating just the free columns as a
new program for every set of effects (this solver takes the free set as data, and differentiates
only the free columns, their count as data too: ``n_cols``). What decides is robustness: it has no
bounds (the calibration's
parameters have physical ones, e.g. a play or a friction coefficient cannot be negative, and their
null values sit on them), no per-sample weights or robust loss, and an isotropic damping ``mu I``
where the parameters' scales span six orders of magnitude; Marquardt's ``diag(J'WJ)`` scaling below is
scale-free. So the package keeps this one solver and does not depend on jaxopt.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

#: Jacobian columns pushed forward together (see ``n_cols``): forward mode costs about one model
#: evaluation per column, so a group of 8 wastes at most 7 on padding.
COL_GROUP = 8


def huber_weights(r, c):
    """IRLS weights of the Huber loss on each row's residual norm (``r`` (M, d); ``c = inf``: least
    squares)."""
    n = jnp.sqrt(jnp.sum(r * r, axis=-1) + 1e-300)
    return jnp.where(n <= c, 1.0, c / n)


def huber_cost(r, w, c):
    """``sum_i w_i rho_c(|r_i|)``, ``rho_c`` the Huber function (quadratic below ``c``)."""
    n = jnp.sqrt(jnp.sum(r * r, axis=-1))
    rho = jnp.where(n <= c, 0.5 * n * n, c * n - 0.5 * c * c)
    return jnp.sum(w * rho)


def levenberg_marquardt(
    fun,
    theta0,
    free=None,
    weights=None,
    huber=jnp.inf,
    lo=-jnp.inf,
    hi=jnp.inf,
    max_iter=40,
    tol=1e-10,
    rows=None,
    cols=None,
    state=None,
    n_cols=None,
):
    """Minimise ``sum_i w_i rho(|fun(theta)_i|)`` over the ``free`` parameters within ``[lo, hi]``.

    Args:
        fun: ``theta (P,) -> residuals (M, d)`` (rows are samples; a (M,) result is taken as (M, 1)).
            Its Jacobian is taken by forward mode (``P`` columns).
        theta0: start (P,); the parameters with ``free = 0`` stay there.
        free: 0/1 (P,), default all; weights: per-row weights (M,), default 1 (0 = not in the fit).
        huber: Huber threshold on a row's residual norm (``inf``: least squares; otherwise
            iteratively reweighted).
        lo, hi: bounds (scalars or (P,)), enforced by projecting every step.
        max_iter: iteration limit (may be traced); ``0`` just evaluates residuals and Jacobian.
        tol: stop when an accepted step lowers the cost by less than this, relative.
        rows: the residuals' shape ``(M, d)`` where the caller knows it (spares tracing ``fun`` once
            just for its shape).
        cols: (K,) indices of the only columns to differentiate (default all ``P``): every free
            parameter must be among them; an index listed again is ignored (pads ``K`` to a size
            that serves many free sets with one compiled program). Forward mode costs about one
            model evaluation per column (the FTDCR v4 model's Jacobian: 32 of 71 columns in about a
            third of the time of all 71).
        n_cols: how many of ``cols``, from the front, to differentiate (may be traced; default all):
            the Jacobian is pushed forward ``COL_GROUP`` columns at a time, as many groups as hold
            ``n_cols``, the others left 0. One compiled program then serves every number of free
            parameters at the cost of its own columns, and ``max_iter = 0, n_cols = 0`` evaluates the
            residuals alone. ``cols`` must list every free parameter within its first ``n_cols``.
        state: a warm start for ``fun`` (any pytree), or ``None``. Given one, ``fun`` is
            ``(theta, state) -> (residuals, state)``: every pass evaluates the candidate from the
            state of the last accepted parameters (e.g. the model's equilibria there, from which a
            nearby candidate's take fewer iterations; the result must not depend on it beyond the
            model's own tolerance). Not differentiated.
    Returns ``(theta, cost, iterations, residuals (M, d), Jacobian (M, d, K))`` at the result.

    Marquardt's scaling (damping ``lam diag(J'WJ)``), a step accepted only if the cost falls (a
    non-finite cost is rejected, so a model that fails somewhere just shortens the step). Bounds by an
    active set: a parameter on a bound whose gradient points out of the box is held there for the
    step, and the others take the step of the problem without it (the projected-Newton rule of
    Bertsekas 1982); clipping the full step instead leaves the others with a step that assumed the
    held one moves, which the cost test then rejects or shortens again and again (the rod's curvature
    freedom on its bound of 1 in a calibration: 41 passes, the limit, and 0.1108 mm held out; with the
    active set 19 passes and 0.0833 mm).
    """
    theta0 = jnp.asarray(theta0)
    pr, warm, K0 = _problem(fun, theta0, free, weights, huber, lo, hi, max_iter, tol, rows, cols, state, n_cols)
    th, cost, it, r, J = _solve(pr, _init(pr, theta0, warm))
    return th, cost, it, r, J[..., :K0]


class _Problem(NamedTuple):
    """What every pass of :func:`levenberg_marquardt` shares: the model, the weights and bounds, and the
    Jacobian's columns (``K`` of them, whole groups of ``COL_GROUP``)."""

    res: Callable  # (theta (P,), warm) -> (residuals (M, d), warm)
    shape: tuple  # the residuals' (M, d)
    w: jax.Array  # (M,) row weights
    huber: Any  # Huber threshold (``inf``: least squares)
    lo: jax.Array  # (P,) lower bounds
    hi: jax.Array  # (P,) upper bounds
    cols: jax.Array  # (K,) the parameter of each differentiated column
    basis: jax.Array  # (K, P) the tangents pushed forward
    freeb: jax.Array  # (K,) bool: the free columns, each once
    eye: jax.Array  # (K, K)
    groups: Any  # groups of columns pushed forward (may be traced)
    max_iter: Any
    tol: Any


class _State(NamedTuple):
    """The loop's state: the accepted point, the candidate evaluated next and the damping."""

    theta: jax.Array  # (P,) the accepted parameters
    r: jax.Array  # (M, d) their residuals
    J: jax.Array  # (M, d, K) their Jacobian's columns
    cost: jax.Array  # () their cost
    cand: jax.Array  # (P,) the candidate
    lam: jax.Array  # () Marquardt's damping
    it: Any  # () passes so far
    done: Any  # () bool: nothing left to try
    warm: Any  # the model's warm-start state at ``theta``


def _problem(fun, theta0, free, weights, huber, lo, hi, max_iter, tol, rows, cols, state, n_cols):
    """:func:`levenberg_marquardt`'s arguments as a :class:`_Problem`, with the warm start (``()``
    without one) and ``K0``, the number of columns asked for (``theta0`` a JAX array)."""
    P = theta0.shape[0]
    free = jnp.ones(P, theta0.dtype) if free is None else jnp.asarray(free, theta0.dtype)
    cols = jnp.arange(P) if cols is None else jnp.asarray(cols)
    n_cols = cols.shape[0] if n_cols is None else n_cols
    K0 = cols.shape[0]
    cols = jnp.concatenate([cols, jnp.full((-K0) % COL_GROUP, cols[-1])])  # whole groups
    K = cols.shape[0]
    basis = jax.nn.one_hot(cols, P, dtype=theta0.dtype)  # (K, P): the tangents pushed forward
    first = jnp.argmax(cols[:, None] == cols[None, :], axis=1) == jnp.arange(K)
    freeb = (free[cols] > 0) & first  # (K,): the free columns, each once
    eye = jnp.eye(K, dtype=theta0.dtype)
    lo = jnp.broadcast_to(jnp.asarray(lo, theta0.dtype), (P,))
    hi = jnp.broadcast_to(jnp.asarray(hi, theta0.dtype), (P,))
    if state is None:  # no warm start: an empty state
        state, plain = (), fun
        fun = lambda th, s: (plain(th), s)
    res = functools.partial(_as_rows, fun)
    groups = (n_cols + COL_GROUP - 1) // COL_GROUP
    shape = jax.eval_shape(res, theta0, state)[0].shape if rows is None else (rows[0], rows[1] if len(rows) > 1 else 1)
    w = jnp.ones(shape[0], theta0.dtype) if weights is None else jnp.asarray(weights, theta0.dtype)
    return _Problem(res, shape, w, huber, lo, hi, cols, basis, freeb, eye, groups, max_iter, tol), state, K0


def _as_rows(fun, th, s):
    """``fun``'s residuals as rows (M, d) (a (M,) result as (M, 1)) and its warm state."""
    r, s = fun(th, s)
    return (r[:, None] if r.ndim == 1 else r), s


def _linearise(pr: _Problem, th, s):
    """Residuals (M, d) at ``th``, the model linearised there (traced and compiled once, its primal run
    once) and the warm state: the primal's."""
    s = jax.lax.stop_gradient(s)
    return jax.linearize(lambda t: pr.res(t, s), th, has_aux=True)


def _jacobian(pr: _Problem, r, lin, groups):
    """The Jacobian's columns (M, d, K) from the linearised model ``lin``: pushed forward a group of
    columns at a time, the first ``groups`` groups (a loop with a traced count: the column count is
    data, not shape; 0 for a candidate the cost test rejects, whose Jacobian is never used), the others
    left 0."""

    def group(j, J):
        V = jax.lax.dynamic_slice_in_dim(pr.basis, j * COL_GROUP, COL_GROUP)  # (G, P)
        return jax.lax.dynamic_update_slice_in_dim(
            J, jnp.moveaxis(jax.vmap(lin)(V), 0, -1), j * COL_GROUP, axis=J.ndim - 1
        )

    return jax.lax.fori_loop(0, groups, group, jnp.zeros(r.shape + (pr.cols.shape[0],), r.dtype))


def _propose(pr: _Problem, th, r, J, lam):
    """The next candidate (P,) from ``th`` (residuals ``r``, Jacobian ``J``): Marquardt's damped step
    over the free columns, those on a bound that the gradient pushes outward held there (without them
    the others' step is the constrained one, not a clipped unconstrained one), projected on the box."""
    cols, lo, hi = pr.cols, pr.lo, pr.hi
    sw = pr.w * huber_weights(r, pr.huber)
    g = jnp.einsum("nip,ni,n->p", J, r, sw)
    at_lo, at_hi = th[cols] <= lo[cols], th[cols] >= hi[cols]
    fb = pr.freeb & ~((at_lo & (g > 0)) | (at_hi & (g < 0)))
    J = J * fb
    A = jnp.einsum("nip,niq,n->pq", J, J, sw)
    d = jnp.diag(A)
    d = jnp.maximum(d, 1e-12 * jnp.max(d) + 1e-300)
    A = jnp.where(fb[:, None] & fb[None, :], A + lam * jnp.diag(d), pr.eye)
    step = -jnp.linalg.solve(A, jnp.where(fb, g, 0.0))
    return jnp.clip(th + jnp.zeros(th.shape[0], th.dtype).at[cols].add(jnp.where(fb, step, 0.0)), lo, hi)


def _init(pr: _Problem, theta0, warm) -> _State:
    """The state before the first pass: the start (clipped to the box) is the first candidate."""
    dt = theta0.dtype
    start = jnp.clip(theta0, pr.lo, pr.hi)
    K = pr.cols.shape[0]
    zero = jnp.zeros(pr.shape, dt)
    return _State(
        start,
        zero,
        jnp.zeros(pr.shape + (K,), dt),
        jnp.asarray(jnp.inf, dt),
        start,
        jnp.asarray(1e-3, dt),
        0,
        False,
        warm,
    )


def _step(pr: _Problem, st: _State) -> _State:
    """One pass, one model evaluation: evaluate the candidate, accept it if it lowers the cost (the
    first pass always does) and only then differentiate it, adapt the damping, propose the next
    candidate."""
    th, r, J, cost, cand, lam, it, _, s = st
    r_c, lin, s_c = _linearise(pr, cand, s)
    cost_c = huber_cost(r_c, pr.w, pr.huber)
    ok = cost_c < cost
    ok = ok | (it == 0)
    J_c = _jacobian(pr, r_c, lin, jnp.where(ok, pr.groups, 0))  # a rejected candidate's is not needed
    rel = (cost - cost_c) / jnp.maximum(jnp.abs(cost), 1e-300)
    done = (ok & (it > 0) & (rel < pr.tol)) | (lam > 1e12)
    th, r, J = (jnp.where(ok, a, b) for a, b in ((cand, th), (r_c, r), (J_c, J)))
    s = jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), s_c, s)
    cost = jnp.where(ok, cost_c, cost)
    lam = jnp.where(it == 0, lam, jnp.where(ok, lam / 3.0, lam * 4.0))
    cand = _propose(pr, th, r, J, lam)
    # no parameter can move (each free one held on its bound): nothing left to try
    return _State(th, r, J, cost, cand, lam, it + 1, done | jnp.all(cand == th), s)


def _running(pr: _Problem, st: _State):
    """Whether another pass is due: within the iteration limit and not done."""
    return (st.it <= pr.max_iter) & ~st.done


def _solve(pr: _Problem, st: _State) -> tuple:
    """Passes until done: ``(theta, cost, iterations, residuals, Jacobian)`` at the result."""
    st = jax.lax.while_loop(functools.partial(_running, pr), functools.partial(_step, pr), st)
    return st.theta, st.cost, st.it, st.r, st.J
