"""The package's one least-squares solver (bounded, robust Levenberg-Marquardt, traced)."""

import jax
import jax.numpy as jnp
import numpy as np

from tension_zones._lsq import levenberg_marquardt

T = jnp.linspace(0.0, 1.0, 20)
Y = 2.0 * jnp.exp(-1.5 * T)


def _exp_fit(x):
    return x[0] * jnp.exp(-x[1] * T) - Y


def test_rejects_non_finite_steps():
    """An exponential fit whose unconstrained path crosses a region where the residuals are NaN."""

    def res(x):
        return jnp.where(x[0] > 1.2, _exp_fit(x), jnp.nan)  # NaN "unstable" region below 1.2

    x, cost, it, r, J = jax.jit(lambda x0: levenberg_marquardt(res, x0, max_iter=50, tol=1e-14))(
        jnp.asarray([5.0, 0.1])
    )
    np.testing.assert_allclose(np.asarray(x), [2.0, 1.5], rtol=1e-8)
    assert int(it) > 1 and float(cost) < 1e-20 and r.shape == (20, 1) and J.shape == (20, 1, 2)


def test_linear_least_squares_matches_numpy():
    rng = np.random.default_rng(0)
    A, y = rng.normal(size=(30, 4)), rng.normal(size=30)
    x, *_ = levenberg_marquardt(lambda th: jnp.asarray(A) @ th - y, jnp.zeros(4), tol=1e-15)
    np.testing.assert_allclose(x, np.linalg.lstsq(A, y, rcond=None)[0], atol=1e-10)


def test_bounds_and_frozen_parameters():
    # the unconstrained optimum (2, 1.5) lies outside x1 <= 1: the bound holds exactly
    x, *_ = levenberg_marquardt(
        _exp_fit, jnp.asarray([1.0, 0.5]), lo=jnp.asarray([0.0, 0.0]), hi=jnp.asarray([10.0, 1.0])
    )
    assert float(x[1]) == 1.0 and 0.0 < float(x[0]) < 10.0
    # a frozen parameter stays where it starts; the other is the conditional optimum
    x, *_ = levenberg_marquardt(_exp_fit, jnp.asarray([3.0, 1.5]), free=jnp.asarray([0.0, 1.0]))
    assert float(x[0]) == 3.0 and abs(float(x[1]) - 1.5) > 0.1


def test_huber_loss_resists_outliers():
    rng = np.random.default_rng(1)
    y = np.asarray(Y) + 0.01 * rng.normal(size=20)
    y[[3, 11]] += 2.0  # two gross outliers
    fun = lambda x: x[0] * jnp.exp(-x[1] * T) - y
    ls, *_ = levenberg_marquardt(fun, jnp.asarray([1.0, 1.0]))
    hub, *_ = levenberg_marquardt(fun, jnp.asarray([1.0, 1.0]), huber=0.05)
    assert np.abs(np.asarray(hub) - [2.0, 1.5]).max() < 0.05 < np.abs(np.asarray(ls) - [2.0, 1.5]).max()


def test_zero_iterations_only_evaluates_and_new_masks_do_not_recompile():
    f = jax.jit(lambda x0, free, n: levenberg_marquardt(_exp_fit, x0, free=free, max_iter=n))
    x0 = jnp.asarray([1.0, 1.0])
    x, _, _, r, J = f(x0, jnp.ones(2), 0)
    np.testing.assert_array_equal(x, x0)
    np.testing.assert_allclose(r[:, 0], _exp_fit(x0))
    np.testing.assert_allclose(J[:, 0], jax.jacfwd(_exp_fit)(x0))
    f(x0, jnp.asarray([1.0, 0.0]), 30)
    f(x0, jnp.asarray([0.0, 1.0]), 10)
    assert f._cache_size() == 1


def test_differentiating_only_the_free_columns_gives_the_same_fit():
    """``cols``: the free parameters (padded with a repeat) are the only columns differentiated; the
    fit equals the one that differentiates every column, and the others never move."""
    rng = np.random.default_rng(3)
    A = rng.normal(size=(40, 6))
    fun = lambda th: jnp.tanh(jnp.asarray(A) @ th) - 0.3
    free = jnp.asarray([1.0, 0.0, 1.0, 1.0, 0.0, 0.0])
    x0 = jnp.asarray(rng.normal(size=6) * 0.1)
    lo = jnp.asarray([-jnp.inf, -jnp.inf, 0.02, -jnp.inf, -jnp.inf, -jnp.inf])  # binds (free optimum 0.008)
    full = levenberg_marquardt(fun, x0, free=free, lo=lo, max_iter=30)
    some = jax.jit(lambda x, c: levenberg_marquardt(fun, x, free=free, lo=lo, max_iter=30, cols=c))(
        x0, jnp.asarray([0, 2, 3, 3, 3])
    )
    np.testing.assert_allclose(some[0], full[0], rtol=1e-12, atol=1e-14)
    assert int(some[2]) == int(full[2]) and some[4].shape == (40, 1, 5)
    np.testing.assert_array_equal(np.asarray(some[0])[[1, 4, 5]], np.asarray(x0)[[1, 4, 5]])
    np.testing.assert_allclose(some[4][:, :, :3], np.asarray(full[4])[:, :, [0, 2, 3]], rtol=1e-12)
    assert float(some[0][2]) == 0.02


def test_a_traced_column_count_differentiates_only_those_columns():
    """``n_cols`` (traced): one compiled program differentiates the first ``n_cols`` of ``cols``
    (whole groups of ``COL_GROUP``, the rest 0), equal to ``jax.jacfwd`` there; ``n_cols = 0`` gives
    the residuals alone, and a fit with the free columns first equals the one over every column."""
    from tension_zones._lsq import COL_GROUP

    rng = np.random.default_rng(4)
    P = 2 * COL_GROUP + 3
    A = jnp.asarray(rng.normal(size=(30, P)) / np.sqrt(P))
    fun = lambda th: jnp.sin(A @ th) - 0.2
    x0 = jnp.asarray(rng.normal(size=P) * 0.3)
    cols = jnp.asarray(rng.permutation(P))
    f = jax.jit(lambda x, n, it, free: levenberg_marquardt(fun, x, free=free, max_iter=it, cols=cols, n_cols=n))
    ref = np.asarray(jax.jacfwd(fun)(x0))[:, None, :][:, :, np.asarray(cols)]
    ones = jnp.ones(P)
    for n in (0, 1, COL_GROUP, COL_GROUP + 1, P):
        _, _, _, r, J = f(x0, n, 0, ones)
        assert J.shape == (30, 1, P)
        np.testing.assert_allclose(r[:, 0], fun(x0), rtol=1e-14)
        done = min(P, -(-n // COL_GROUP) * COL_GROUP)
        np.testing.assert_allclose(J[:, :, :done], ref[:, :, :done], rtol=1e-12, atol=1e-15)
        np.testing.assert_array_equal(np.asarray(J[:, :, done:]), 0.0)
    free = np.zeros(P)
    free[np.asarray(cols)[:5]] = 1.0
    some = f(x0, 5, 30, jnp.asarray(free))
    full = levenberg_marquardt(fun, x0, free=jnp.asarray(free), max_iter=30)
    np.testing.assert_allclose(some[0], full[0], rtol=1e-12, atol=1e-14)
    assert int(some[2]) == int(full[2])
    assert f._cache_size() == 1


def test_bounded_linear_least_squares_matches_scipy_in_a_few_passes():
    """Correlated columns whose free optimum lies outside the box in several coordinates: the
    bounded solution is SciPy's (BVLS), reached in a few passes (an active set, not a clipped step:
    clipping left these 0.1-0.9 off after 40 passes). With every parameter held on a bound the
    solver stops at once, not after the damping has grown to its limit."""
    from scipy.optimize import lsq_linear

    rng = np.random.default_rng(4)
    fit = jax.jit(
        lambda A, y, lo, hi: levenberg_marquardt(
            lambda th: A @ th - y, jnp.zeros(5), lo=lo, hi=hi, max_iter=40, tol=1e-12
        )
    )
    held = []
    for _ in range(5):
        A = rng.normal(size=(60, 5)) @ (np.eye(5) + 0.4 * rng.normal(size=(5, 5)))
        y = A @ (2.0 * rng.normal(size=5)) + 0.01 * rng.normal(size=60)
        lo, hi = -np.ones(5), np.ones(5)
        ref = lsq_linear(A, y, bounds=(lo, hi), method="bvls", tol=1e-15).x
        x, _, it, *_ = fit(A, y, lo, hi)
        np.testing.assert_allclose(x, ref, atol=1e-9)
        assert int(it) <= 12
        held.append(int(np.sum(np.abs(ref) == 1.0)))
    assert max(held) == 5 and min(held) >= 3  # the cases span partly and wholly held boxes


def test_a_warm_start_state_follows_the_accepted_parameters():
    """``state``: every pass starts the model from the state of the last accepted pass (here the roots
    of ``z^3 = a t + b``, solved by Newton from the state, exact from any start, and the parameters
    they were solved for), and the fit is the one without a warm start."""
    t = jnp.linspace(0.0, 1.0, 30)
    y = jnp.cbrt(6.0 * t + 2.0) + 0.01 * jnp.sin(40.0 * t)  # not an exact fit: some steps are rejected
    seen = []

    def roots(x, z):
        c = x[0] * t + x[1]
        step = lambda z: z - (z**3 - c) / (3.0 * z**2)
        return jax.lax.while_loop(lambda z: jnp.max(jnp.abs(step(z) - z)) > 1e-14, step, z)

    def warm(x, state):
        jax.debug.callback(lambda x, s: seen.append((np.array(x), np.array(s[0]), np.array(s[1]))), x, state)
        z = roots(x, state[0])
        return z - y, (z, x)

    x0 = jnp.asarray([1.0, 9.0])
    x, cost, it, _, _ = levenberg_marquardt(warm, x0, max_iter=60, tol=1e-15, state=(jnp.ones_like(t), x0))
    x_cold, cost_cold, *_ = levenberg_marquardt(lambda x: roots(x, jnp.ones_like(t)) - y, x0, max_iter=60, tol=1e-15)
    np.testing.assert_allclose(np.asarray(x), np.asarray(x_cold), rtol=1e-7)  # the same minimum
    assert abs(float(cost) - float(cost_cold)) < 1e-12 and len(seen) == int(it)
    cost_of = [float(np.sum((np.cbrt(xk[0] * np.asarray(t) + xk[1]) - np.asarray(y)) ** 2)) for xk, _, _ in seen]
    for k in range(1, len(seen)):
        _, zk, sx = seen[k]
        j = [i for i in range(k) if np.array_equal(seen[i][0], sx)]  # the pass whose state it is
        assert j and cost_of[j[0]] <= min(cost_of[:k]) + 1e-12  # the best so far: the accepted one
        np.testing.assert_allclose(zk, np.cbrt(sx[0] * np.asarray(t) + sx[1]), rtol=1e-12)
    rejected = sum(np.array_equal(seen[k][2], seen[k + 1][2]) for k in range(1, len(seen) - 1))
    assert rejected > 0  # the state stayed with the accepted parameters past a rejected pass
