"""The forward model (MODEL.md Sec. 5): equilibrium, implicit derivatives, path-dependent state."""

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from simulator import _equilibrium, position

import tension_zones as tz
from tension_zones.calib import SegmentModel, equilibrium, motion_direction, tip_position
from tension_zones.calib.effects import LIBRARY, NOMINAL, play
from tension_zones.calib.forward import energy
from tension_zones.calib.model import Problem, engine

D3 = tz.Design(3, 20.0, 2.0, wire_stiffness=75.0, backbone_EI=1200.0, preload=2.0)
PHYS = SegmentModel(3).physical(D3)
ONES = jnp.ones(3)
EQ = jax.jit(equilibrium)
ENERGY_GRAD = jax.jit(jax.grad(energy))

qs = st.lists(st.floats(-1.5, 1.5), min_size=3, max_size=3).map(np.array)
fs = st.lists(st.floats(-1.5, 1.5), min_size=3, max_size=3).map(np.array)


@given(qs, fs)
def test_equilibrium_is_stationary_and_matches_scipy(q, f):
    b = EQ(PHYS, jnp.asarray(q), jnp.asarray(f), ONES)
    g = ENERGY_GRAD(b, PHYS, jnp.asarray(q), jnp.asarray(f), ONES)
    assert np.abs(g).max() < 1e-8
    ref = _equilibrium(q, f, np.ones(3), 20.0, 2.0, np.asarray(PHYS["wire_angles"]), np.full(3, 75.0),
                       np.full(3, 2.0), 1200.0, np.zeros(2))
    np.testing.assert_allclose(b, ref, atol=1e-6)


def test_position_is_the_kinematics_tip_pose():
    for b in ([0.0, 0.0], [0.3, -0.2], [1e-9, 0.0], [-1.1, 0.6]):
        b = jnp.asarray(b)
        from tension_zones.calib.forward import _position

        np.testing.assert_allclose(_position(b, D3.length), tz.tip_pose_b(D3, b)[0], atol=1e-13)
        np.testing.assert_allclose(position(np.asarray(b), 20.0), tz.tip_pose_b(D3, b)[0], atol=1e-6)


def test_slack_wires_carry_nothing():
    # pull wire 1, release the others: they go slack, and the segment bends toward wire 1 as far as
    # wire 1 alone against the backbone allows: (EI / L) b = r k s_1
    q = jnp.array([-1.0, 1.0, 1.0])
    b = EQ(PHYS, q, jnp.zeros(3), ONES)
    a = PHYS["wire_angles"]
    s = -2.0 * (b[0] * jnp.cos(a) + b[1] * jnp.sin(a)) - q + 2.0 / 75.0
    assert s[0] > 0 and np.all(s[1:] < 0) and abs(b[1]) < 1e-12
    np.testing.assert_allclose(1200.0 / 20.0 * b[0], 2.0 * 75.0 * s[0], rtol=1e-10)


def test_implicit_derivatives_match_finite_differences():
    q, f = jnp.array([-0.8, 0.3, 0.5]), jnp.array([0.4, -0.3, -0.5])
    p_of = jax.jit(lambda ph: tip_position(ph, q, f, ONES))
    J = jax.jit(jax.jacfwd(p_of))(PHYS)
    Jr = jax.jit(jax.jacrev(p_of))(PHYS)
    for name in ("EI", "length", "pitch_radius", "wire_angles", "preload"):
        x0 = np.asarray(PHYS[name], float)
        for i in np.ndindex(x0.shape):
            h = 1e-6 * max(abs(float(x0[i])), 1.0)
            e = np.zeros_like(x0)
            e[i] = h
            fd = (p_of({**PHYS, name: x0 + e}) - p_of({**PHYS, name: x0 - e})) / (2 * h)
            np.testing.assert_allclose(np.asarray(J[name])[(...,) + i], fd, rtol=1e-5, atol=1e-8)
            np.testing.assert_allclose(np.asarray(Jr[name])[(...,) + i], fd, rtol=1e-5, atol=1e-8)


def test_finite_values_and_gradients_at_the_straight_pose():
    # no preload, no command: b* = 0 exactly, where |b| is not differentiable
    phys = {**PHYS, "preload": jnp.zeros(3)}
    z = jnp.zeros(3)
    grads = jax.jit(jax.grad(lambda ph: jnp.sum(tip_position(ph, z, z, ONES))))(phys)
    assert all(np.all(np.isfinite(g)) for g in jax.tree_util.tree_leaves(grads))
    Jq = jax.jit(jax.jacfwd(lambda q: tip_position(phys, q, z, ONES)))(z)
    assert np.all(np.isfinite(Jq)) and np.abs(Jq[:2]).max() > 1.0


def reference_play(q, c):
    out = np.empty_like(q)
    state = q[0].copy()
    for i, row in enumerate(q):
        state = np.minimum(np.maximum(state, row - c / 2), row + c / 2)
        out[i] = state
    return out


PLAY = jax.jit(play)


@given(st.lists(st.floats(-2, 2), min_size=30, max_size=30),
       st.lists(st.floats(0.0, 1.0), min_size=2, max_size=2))
def test_play_operator_matches_reference(path, c):
    q = np.stack([np.asarray(path), -np.asarray(path)], axis=1)  # one shape: one compilation
    np.testing.assert_allclose(PLAY(jnp.asarray(q), jnp.asarray(c)), reference_play(q, np.asarray(c)),
                               atol=1e-12)


def test_play_derivative_at_zero_is_half_the_direction():
    q = jnp.array([[0.0], [0.5], [0.5], [0.2], [0.2], [0.9]])
    d = jax.jacfwd(lambda c: play(q, c))(jnp.zeros(1))[:, 0, 0]
    np.testing.assert_allclose(d, [0.0, -0.5, -0.5, 0.5, 0.5, -0.5])


def test_motion_direction_keeps_last_direction():
    q = jnp.array([[0.0], [1.0], [1.0], [0.5], [0.5], [0.5], [2.0]])
    np.testing.assert_array_equal(motion_direction(q)[:, 0], [0, 1, 1, -1, -1, -1, 1])


class _Data:
    def __init__(self, n, seed=0):
        rng = np.random.default_rng(seed)
        self.q = rng.uniform(-1, 1, (n, 3))
        self.f = np.zeros((n, 3))
        self.p = rng.normal(size=(n, 3)) + [0, 0, 20]
        self.n_samples, self.n_wires = n, 3


def test_new_values_never_recompile():
    data = _Data(12)
    blocks = NOMINAL + LIBRARY
    pb = Problem(SegmentModel(3), D3, data, blocks)
    pb.fit(pb.null, ["backbone_EI"], np.ones(12), max_iter=2)
    size = engine._cache_size()
    other = tz.Design(3, 25.0, 1.5, wire_angles=[0.1, 2.0, 4.0], wire_stiffness=60.0, backbone_EI=900.0,
                      preload=1.0)
    data2 = _Data(12, seed=1)
    pb2 = Problem(SegmentModel(3), other, data2, blocks)
    pb2.fit(pb2.null + 0.01, ["backbone_EI", "backlash", "registration"], np.ones(12), huber_c=0.3,
            max_iter=3)
    pb2.jacobian(pb2.null)
    assert engine._cache_size() == size
