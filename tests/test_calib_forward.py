"""The forward model (MODEL.md Sec. 5): equilibrium, implicit derivatives, path-dependent state."""

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from simulator import _equilibrium, position

import tension_zones as tz
from tension_zones.calibration import Dataset, SegmentModel, equilibrium, motion_direction, tip_position
from tension_zones.calibration.effects import LIBRARY, NOMINAL, play
from tension_zones.calibration.forward import energy
from tension_zones.calibration.model import Problem, engine, predict_theta

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
        from tension_zones.calibration.forward import _position

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
    both = jax.jit(jax.jacfwd(lambda ph, q: tip_position(ph, q, z, ONES), argnums=(0, 1)))
    grads, Jq = both(phys, z)
    assert all(np.all(np.isfinite(g)) for g in jax.tree_util.tree_leaves(grads))
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


def _Data(n, seed=0):
    rng = np.random.default_rng(seed)
    return Dataset(sample=np.arange(n), q=rng.uniform(-1, 1, (n, 3)), f=np.zeros((n, 3)),
                   p=rng.normal(size=(n, 3)) + [0, 0, 20])


def test_new_values_never_recompile():
    data = _Data(12)
    blocks = NOMINAL + LIBRARY
    pb = Problem(SegmentModel(3), D3, data, blocks)
    pb.fit(pb.null, ["backbone_EI"], np.ones(12), max_iter=2)
    size = engine._cache_size()
    other = tz.Design(3, 25.0, 1.5, wire_angles=[0.1, 2.0, 4.0], wire_stiffness=60.0, backbone_EI=900.0,
                      preload=1.0)
    data2 = _Data(40, seed=1)  # another size in the same padding bucket
    pb2 = Problem(SegmentModel(3), other, data2, blocks)
    pb2.fit(pb2.null + 0.01, ["backbone_EI", "backlash", "registration"], np.ones(40), huber_c=0.3,
            max_iter=3)
    pb2.jacobian(pb2.null)
    assert engine._cache_size() == size


def test_padding_changes_nothing():
    # the engine pads sample counts to a multiple of 64 at zero weight; results must not notice
    data = _Data(40, seed=2)
    pb = Problem(SegmentModel(3), D3, data, NOMINAL + LIBRARY)
    theta = pb.null.copy()
    theta[pb.spec.slices()["backlash"]] = [0.1, 0.2, 0.3]
    direct = jax.jit(predict_theta, static_argnums=0)(pb.spec, jnp.asarray(theta), pb.phys0,
                                                      SegmentModel(3).inputs(data))
    np.testing.assert_allclose(pb.predict(theta), direct, atol=1e-12)
    # padded rows carry no weight: the fit of 40 samples equals that of a set whose 41st..64th
    # samples are wildly different (they would pull a fit that saw them)
    wild = Dataset(sample=np.arange(64), q=np.r_[data.q, np.ones((24, 3))], f=np.r_[data.f, np.ones((24, 3))],
                   p=np.r_[data.p, np.full((24, 3), 50.0)])
    pb64 = Problem(SegmentModel(3), D3, wild, NOMINAL + LIBRARY)
    a = pb.fit(pb.null, ["backbone_EI"], np.ones(40), max_iter=10)
    b = pb64.fit(pb64.null, ["backbone_EI"], np.r_[np.ones(40), np.zeros(24)], max_iter=10)
    np.testing.assert_allclose(a, b, atol=1e-12)
