"""The bending's friction (hysteresis): the play operator in moment space against a plain NumPy loop,
its derivatives where the score test takes them, and the calibration model's memory variant."""

import jax
import jax.numpy as jnp
import numpy as np
from conftest import two_segments
from hypothesis import given, settings
from hypothesis import strategies as st

from tension_zones.calibration import Dataset, Problem, RobotModel, compilations
from tension_zones.calibration.effects import library, nominal
from tension_zones.model._equilibrium import bending_memory

MEMORY = jax.jit(bending_memory)


def reference_memory(X, K, h, reset):
    """The friction's step written out: keep the last bending unless, piece by piece, the moment
    pulling it back to this sample's equilibrium exceeds ``h``; then move until it is ``h``."""
    out = np.empty_like(X)
    prev = X[0]
    for i, (x, k) in enumerate(zip(X, K)):
        if reset[i]:
            prev = x
        mom = (k @ (prev - x)).reshape(-1, 2)
        for j, m in enumerate(mom):
            size = np.hypot(*m)
            if size > h[j]:
                mom[j] = m * h[j] / size
        prev = x + np.linalg.solve(k, mom.reshape(-1))
        out[i] = prev
    return out


def _spd(rng, n, size):
    A = rng.normal(size=(n, size, size))
    return np.einsum("nij,nkj->nik", A, A) + 5.0 * np.eye(size)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.lists(st.floats(0.0, 3.0), min_size=2, max_size=2), st.integers(1, 19))
def test_memory_matches_reference(seed, h, cut):
    rng = np.random.default_rng(seed)
    X = np.cumsum(rng.normal(scale=0.1, size=(20, 4)), axis=0)
    X[5:8] = X[5]  # a hold: the same equilibrium thrice
    K = _spd(rng, 20, 4)
    reset = np.zeros(20)
    reset[cut] = 1.0
    got = np.asarray(MEMORY(jnp.asarray(X), jnp.asarray(K), jnp.asarray(h), jnp.asarray(reset)))
    np.testing.assert_allclose(got, reference_memory(X, K, np.asarray(h), reset), atol=1e-10)


def test_no_friction_is_the_equilibrium_and_its_derivative_is_the_unit_moment():
    rng = np.random.default_rng(0)
    X = np.cumsum(rng.normal(scale=0.1, size=(10, 4)), axis=0)
    X[4] = X[3]  # no motion: no moment, nothing infinite, the state (and its derivative) held
    K = _spd(rng, 10, 4)
    out, d = jax.jvp(lambda h: bending_memory(jnp.asarray(X), jnp.asarray(K), h), (jnp.zeros(2),), (jnp.ones(2),))
    np.testing.assert_array_equal(np.asarray(out), X)
    d = np.asarray(d)
    assert np.all(np.isfinite(d))
    np.testing.assert_array_equal(d[0], 0.0)
    np.testing.assert_allclose(d[4], d[3], atol=1e-12)
    for i in (1, 2, 5):  # dx/dh = K^-1 (the unit moment of the previous equilibrium about this one)
        m = (K[i] @ (X[i - 1] - X[i])).reshape(2, 2)
        want = np.linalg.solve(K[i], (m / np.linalg.norm(m, axis=1, keepdims=True)).reshape(-1))
        np.testing.assert_allclose(d[i], want, atol=1e-12)
    g = jax.grad(lambda h: jnp.sum(bending_memory(jnp.asarray(X), jnp.asarray(K), h) ** 2))(jnp.array([0.3, 0.0]))
    assert np.all(np.isfinite(np.asarray(g)))


def test_a_large_friction_keeps_the_shape_until_the_recording_restarts():
    rng = np.random.default_rng(1)
    X = rng.normal(size=(6, 2))
    K = _spd(rng, 6, 2)
    reset = np.array([1.0, 0, 0, 1, 0, 0])
    out = np.asarray(bending_memory(jnp.asarray(X), jnp.asarray(K), jnp.array([1e6]), jnp.asarray(reset)))
    np.testing.assert_allclose(out[:3], np.repeat(X[:1], 3, 0), atol=1e-12)
    np.testing.assert_allclose(out[3:], np.repeat(X[3:4], 3, 0), atol=1e-12)


TWO = two_segments(preload=0.0)


def _pulls(n_wires, steps=6):
    """Each wire pulled and released in turn, the others paid out: the robot ends every pull slack."""
    t = np.r_[np.linspace(0, 1, steps), np.linspace(1, 0, steps)[1:]]
    blocks = []
    for k in range(n_wires):
        q = np.full((len(t), n_wires), 0.5)
        q[:, k] = -1.5 * t
        blocks.append(q)
    return np.concatenate(blocks)


def test_the_memory_is_kept_where_every_wire_is_slack_and_values_never_recompile():
    q = _pulls(TWO.n_wires)
    data = Dataset(sample=np.arange(len(q)), q=q, f=np.zeros((len(q), 3)), p=np.zeros((len(q), 3)), frame="base")
    pb = Problem(RobotModel.of(TWO), TWO, data, nominal("base") + library("base", ["bending_friction"]))
    sl = pb.spec.slices()["bending_friction"]
    active = ["backbone_EI", "bending_friction"]
    free = pb.predict(pb.null, ["backbone_EI"])
    np.testing.assert_allclose(pb.predict(pb.null, active), free, atol=1e-12)  # h = 0: no memory
    size = compilations()
    theta = pb.null.copy()
    theta[sl] = [3.0, 2.0]
    held = pb.predict(theta, active)
    theta[sl] = [1.0, 4.0]
    pb.predict(theta, active)
    assert compilations() == size  # new values: the same program
    home = free[0]
    slack = np.flatnonzero(np.all(q >= 0.0, axis=1) & (np.arange(len(q)) > 0))  # every wire paid out or at 0
    assert slack.size == 2 * TWO.n_wires - 1
    # without friction every slack sample is the straight robot; with it, the robot stays bent
    np.testing.assert_allclose(free[slack], np.repeat(home[None], slack.size, 0), atol=1e-9)
    assert np.min(np.linalg.norm(held[slack] - home, axis=1)) > 0.05
    _, J = pb.jacobian(pb.null, active)
    assert np.all(np.isfinite(J)) and np.linalg.norm(J[..., sl]) > 0  # the score test sees it at null


def test_the_memory_models_jacobian_matches_central_differences():
    """Through the equilibria, their stiffness and the play: away from the play's switches (a sample
    that starts or stops sticking) the residuals are smooth and the Jacobian exact."""
    q = _pulls(TWO.n_wires)
    rng = np.random.default_rng(2)
    data = Dataset(sample=np.arange(len(q)), q=q, f=np.zeros((len(q), 3)), p=rng.normal(size=(len(q), 3)), frame="base")
    pb = Problem(RobotModel.of(TWO), TWO, data, nominal("base") + library("base", ["bending_friction"]))
    sl = pb.spec.slices()
    active = ["backbone_EI", "bending_friction", "preload"]
    theta = pb.null.copy()
    theta[sl["bending_friction"]] = [3.0, 2.0]
    theta[sl["backbone_EI"]] = [0.1, -0.2]
    theta[sl["preload"]] = rng.uniform(0.0, 1.0, TWO.n_wires)
    _, J = pb.jacobian(theta, active)
    cols = [
        *range(sl["backbone_EI"].start, sl["backbone_EI"].stop),
        *range(sl["bending_friction"].start, sl["bending_friction"].stop),
        sl["preload"].start + 2,
    ]
    for col in cols:
        e = np.zeros_like(theta)
        e[col] = 1e-6
        fd = (pb.residuals(theta + e, active) - pb.residuals(theta - e, active)) / 2e-6
        np.testing.assert_allclose(J[..., col], fd, atol=1e-5 * max(1.0, np.abs(fd).max()))
