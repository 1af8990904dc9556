"""Multi-segment model: single-segment equivalence, routed wire lengths, equilibrium, Jacobians."""

import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

import tension_zones as tz
from tension_zones.model import _robot as ms

DEG = np.pi / 180


def three_segments(k_w=60.0, preload=0.0):
    return ms.Robot([
        tz.Design(3, 60.0, 4.5, wire_angles=np.radians([10, 130, 250]), backbone_EI=2400.0,
                  wire_stiffness=k_w, preload=preload),
        tz.Design(4, 62.5, 4.0, wire_angles=np.radians([40, 125, 220, 310]), backbone_EI=2000.0,
                  wire_stiffness=k_w, preload=preload),
        tz.Design(3, 64.0, 3.5, wire_angles=np.radians([80, 200, 320]), backbone_EI=1500.0,
                  wire_stiffness=k_w, preload=preload),
    ])


EQ = jax.jit(ms.equilibrium)
FWD = jax.jit(lambda r, q, load: ms.forward(r, q, load)[0])
J_PQ = jax.jit(ms.equilibrium_J_pq)
B_BENT = np.array([[0.3, -0.2], [-0.4, 0.1], [0.25, 0.5]])


# ---------------------------------------------------------------------------------------------
# one segment = the single-segment code
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("b", [np.zeros(2), np.array([0.4, -0.7]), np.array([1e-9, 2e-9])])
def test_single_segment_kinematics_identical(b):
    d = tz.Design(3, 20.0, 2.0, wire_angles=np.radians([5, 110, 250]))
    rob = ms.Robot(d)
    B = b[None, :]
    np.testing.assert_array_equal(ms.wire_lengths(rob, B), tz.wire_lengths_b(d, b))
    p, R = ms.tip_pose(rob, B)
    p1, R1 = tz.tip_pose_b(d, b)
    np.testing.assert_array_equal(p, p1)
    np.testing.assert_array_equal(R, R1)
    np.testing.assert_array_equal(ms.J_qB(rob), tz.J_qb(d))
    np.testing.assert_allclose(ms.J_xB(rob, B), tz.J_xb(d, b), rtol=0, atol=1e-14)
    _, delta = tz.b_to_psi(jnp.asarray(b))
    np.testing.assert_allclose(ms.tension_score(rob, B), tz.tension_score(d, delta), atol=1e-15)
    np.testing.assert_array_equal(ms.tension_mask(rob, B), tz.tension_mask(d, delta))


def test_single_segment_jacobians_match_psi_coordinates():
    d = tz.Design(3, 20.0, 2.0)
    theta, delta = np.radians(60.0), np.radians(66.0)  # two taut wires (1 and 3)
    B = np.asarray(tz.psi_to_b(theta, delta))[None, :]
    rob = ms.Robot(d)
    np.testing.assert_allclose(ms.J_xq(rob, B), tz.J_xq(d, theta, delta), atol=1e-10)
    np.testing.assert_allclose(ms.reduced_J_xq(rob, B), tz.reduced_J_xq(d, theta, delta), atol=1e-10)


def _single_equilibrium_reference(d, q, f):
    """MODEL.md Sec. 5 written out in NumPy and minimised by SciPy (an independent solver)."""
    L, r, a = float(d.length), float(d.pitch_radius), np.asarray(d.wire_angles)
    kw, EI, pre = float(d.wire_stiffness), float(d.backbone_EI), float(d.preload)

    def V(b):
        u, v = b
        phi = max(np.hypot(u, v), 1e-12)
        p = np.array([L * (1 - np.cos(phi)) / phi**2 * u, L * (1 - np.cos(phi)) / phi**2 * v,
                      L * np.sin(phi) / phi])
        s = -r * (u * np.cos(a) + v * np.sin(a)) - q + pre / kw
        return EI * (u * u + v * v) / (2 * L) + 0.5 * kw * np.sum(np.maximum(s, 0) ** 2) - f @ p

    return minimize(V, np.array([0.1, 0.1]), method="BFGS", options=dict(gtol=1e-10)).x


@pytest.mark.parametrize("q, f", [
    (np.array([-0.8, 0.3, 0.4]), np.zeros(3)),
    (np.array([-0.2, -0.5, 0.6]), np.array([0.3, -0.2, 0.0])),
    (np.array([0.1, 0.1, 0.1]), np.zeros(3)),
])
def test_single_segment_equilibrium_matches_independent_solver(q, f):
    d = tz.Design(3, 20.0, 2.0, wire_stiffness=70.0, backbone_EI=1200.0, preload=1.0)
    B = EQ(ms.Robot(d), q, ms.Load(f, np.zeros(3)))
    np.testing.assert_allclose(B[0], _single_equilibrium_reference(d, q, f), atol=1e-6)


def test_robot_from_dict_single_and_multi(tmp_path):
    single = {"n_wires": 3, "length_mm": 20.0, "pitch_radius_mm": 2.0}
    rob = ms.Robot.from_dict(single)
    assert rob.n_segments == 1 and rob.n_wires == 3
    seg = dict(length_mm=60.0, n_wires=3, pitch_radius_mm=4.5, wire_angles_deg=[0, 120, 240],
               backbone_EI_Nmm2=2454.0, wire_stiffness_N_per_mm=50.0, preload_N=0.5)
    rob3 = ms.Robot.from_dict({"segments": [seg, dict(seg, length_mm=62.5), dict(seg, length_mm=64.0)]})
    assert rob3.n_wires_per_segment == (3, 3, 3)
    np.testing.assert_allclose(rob3.lengths, [60.0, 62.5, 64.0])
    assert ms.Robot.from_dict(rob3.to_dict()).n_wires == 9
    with pytest.raises(ValueError, match="segment 1: pitch_radius_mm must be positive"):
        ms.Robot.from_dict({"segments": [seg, dict(seg, pitch_radius_mm=-1.0)]})
    with pytest.raises(ValueError, match="unknown robot design key"):
        ms.Robot.from_dict({"segments": [seg], "twist": 1})
    example = ms.Robot.from_json(
        __import__("pathlib").Path(tz.__file__).parent / "examples" / "ftdcr_v4.design.json")
    assert example.n_wires_per_segment == (3, 3, 3)
    np.testing.assert_allclose(float(jnp.sum(example.lengths)), 186.5)


# ---------------------------------------------------------------------------------------------
# routed wire lengths against an integrated wire path
# ---------------------------------------------------------------------------------------------
def _segment_frame(L, b, s):
    """Position and rotation at arc length s of a constant-curvature segment (SciPy rotations)."""
    u, v = b
    phi = np.hypot(u, v) * s / L
    rot = Rotation.from_rotvec(np.array([-v, u, 0.0]) * s / L)
    if phi < 1e-12:
        return np.array([0.0, 0.0, s]), rot.as_matrix()
    rho = s / phi
    sig = np.arctan2(v, u)
    return np.array([rho * (1 - np.cos(phi)) * np.cos(sig), rho * (1 - np.cos(phi)) * np.sin(sig),
                     rho * np.sin(phi)]), rot.as_matrix()


def _integrated_wire_length(rob, B, k, n=400):
    owner = rob.owner[k]
    p0, R0, total, prev = np.zeros(3), np.eye(3), 0.0, None
    for j in range(owner + 1):
        L = float(rob.lengths[j])
        a, r = float(rob.route_angles[k, j]), float(rob.route_radii[k, j])
        hole = np.array([r * np.cos(a), r * np.sin(a), 0.0])
        for s in np.linspace(0.0, L, n + 1):
            p, R = _segment_frame(L, B[j], s)
            x = p0 + R0 @ (p + R @ hole)
            if prev is not None:
                total += np.linalg.norm(x - prev)
            prev = x
        p, R = _segment_frame(L, B[j], L)
        p0, R0 = p0 + R0 @ p, R0 @ R
        prev = None  # the wire enters the next segment at its own hole there
    return total


def test_distal_wire_lengths_match_integrated_path():
    rob = three_segments()
    lengths = np.asarray(ms.wire_lengths(rob, B_BENT))
    for k in [0, 4, 6, 9]:  # a proximal, a middle and two distal wires
        np.testing.assert_allclose(lengths[k], _integrated_wire_length(rob, B_BENT, k), atol=2e-3)
    # a distal wire changes length with every segment it crosses
    for j in range(3):
        B = np.zeros((3, 2))
        B[j] = [0.3, 0.1]
        dl = np.asarray(ms.wire_length_changes(rob, B))
        assert np.all(np.abs(dl[rob.crosses[:, j]]) > 0)
        np.testing.assert_array_equal(dl[~rob.crosses[:, j]], 0.0)


def test_tip_pose_is_product_of_segment_transforms():
    rob = three_segments()
    T = np.eye(4)
    for j in range(3):
        p, R = _segment_frame(float(rob.lengths[j]), B_BENT[j], float(rob.lengths[j]))
        Tj = np.eye(4)
        Tj[:3, :3], Tj[:3, 3] = R, p
        T = T @ Tj
    p, R = ms.tip_pose(rob, B_BENT)
    np.testing.assert_allclose(p, T[:3, 3], atol=1e-10)
    np.testing.assert_allclose(R, T[:3, :3], atol=1e-12)


# ---------------------------------------------------------------------------------------------
# Jacobians
# ---------------------------------------------------------------------------------------------
def test_J_qB_and_J_xB_match_finite_differences():
    rob = three_segments()
    tip = jax.jit(ms.tip_pose)
    x = B_BENT.reshape(-1)
    h = 1e-6
    Jq_fd, Jp_fd = [], []
    for i in range(6):
        e = np.zeros(6)
        e[i] = h
        Bp, Bm = (x + e).reshape(3, 2), (x - e).reshape(3, 2)
        Jq_fd.append((ms.wire_lengths(rob, Bp) - ms.wire_lengths(rob, Bm)) / (2 * h))
        Jp_fd.append((tip(rob, Bp)[0] - tip(rob, Bm)[0]) / (2 * h))
    np.testing.assert_allclose(ms.J_qB(rob), np.stack(Jq_fd, 1), atol=1e-7)
    Jx = ms.J_xB(rob, B_BENT)
    np.testing.assert_allclose(Jx[:3], np.stack(Jp_fd, 1), atol=1e-6)
    # angular part: vee(dR R^T) by finite differences
    R0 = np.asarray(ms.tip_pose(rob, B_BENT)[1])
    for i in range(6):
        e = np.zeros(6)
        e[i] = h
        dR = (np.asarray(tip(rob, (x + e).reshape(3, 2))[1])
              - np.asarray(tip(rob, (x - e).reshape(3, 2))[1])) / (2 * h)
        W = dR @ R0.T
        np.testing.assert_allclose(Jx[3:, i], [W[2, 1], W[0, 2], W[1, 0]], atol=1e-6)


def test_reduced_jacobian_zeroes_slack_columns():
    rob = three_segments()
    mask = np.asarray(ms.tension_mask(rob, B_BENT))
    J = np.asarray(ms.reduced_J_xq(rob, B_BENT))
    assert 0 < mask.sum() < rob.n_wires
    np.testing.assert_array_equal(J[:, mask == 0], 0.0)
    assert np.all(np.isfinite(J))


# ---------------------------------------------------------------------------------------------
# statics
# ---------------------------------------------------------------------------------------------
Q_CASES = [
    np.array([-0.8, 0.5, 0.5, 0.0, -0.3, 0.2, 0.1, -0.6, 0.3, 0.3]),
    np.array([0.2, 0.2, -1.5, 0.1, 0.4, -0.9, 0.4, 0.0, 0.1, -0.4]),
]


@pytest.mark.parametrize("q", Q_CASES)
def test_equilibrium_is_optimal_and_pull_only(q):
    rob = three_segments(preload=0.5)
    _check_optimal(rob, q, None)


@pytest.mark.skipif(not os.environ.get("TZ_SLOW_TESTS"),
                    reason="~2 min to compile the load's Hessian; set TZ_SLOW_TESTS=1")
def test_loaded_equilibrium_is_optimal_with_exact_derivatives():
    """Tip force and gravity on two segments."""
    rob = ms.Robot(three_segments(preload=0.5).segments[:2])
    q = jnp.asarray(Q_CASES[0][:7])
    load = ms.Load(jnp.array([0.2, -0.1, 0.0]), jnp.array([0.0, 5e-4, -1e-3]))
    _check_optimal(rob, q, load)
    _assert_J_PQ_matches_fd(rob, q, load, h=1e-4, atol=2e-4)


def _assert_J_PQ_matches_fd(rob, q, load, h, atol):
    """The equilibrium's tip Jacobian against central differences, wire by wire."""
    J = np.asarray(J_PQ(rob, q, load))
    for k in range(rob.n_wires):
        e = jnp.zeros(rob.n_wires).at[k].set(h)
        fd = (FWD(rob, q + e, load) - FWD(rob, q - e, load)) / (2 * h)
        np.testing.assert_allclose(J[:, k], fd, atol=atol)


def test_loaded_single_segment_equilibrium_is_optimal():
    d = tz.Design(3, 20.0, 2.0, wire_stiffness=70.0, backbone_EI=1200.0, preload=1.0)
    q = jnp.array([-0.8, 0.3, 0.4])
    _check_optimal(ms.Robot(d), q, ms.Load(jnp.array([0.3, -0.2, 0.0]), jnp.array([0.0, 1e-3, -2e-3])))


def _check_optimal(rob, q, load):
    B = EQ(rob, q, load)
    g = jax.grad(lambda b: ms.energy(rob, b, q, load))(B)
    np.testing.assert_allclose(g, 0.0, atol=1e-9)
    tau = np.asarray(ms.wire_tensions(rob, B, q))
    s = np.asarray(ms.wire_stretch(rob, B, q))
    assert np.all(tau >= 0)
    np.testing.assert_array_equal(tau[s <= 0], 0.0)
    assert 0 < np.sum(tau > 0) < rob.n_wires  # some wires pull, some are slack
    V = jax.jit(ms.energy)
    V0 = float(V(rob, B, q, load))
    rng = np.random.default_rng(1)
    for _ in range(20):
        assert float(V(rob, B + 1e-3 * rng.normal(size=B.shape), q, load)) > V0


def test_distal_wire_bends_every_segment_it_crosses():
    rob = three_segments()
    q = np.full(rob.n_wires, 2.0)  # every other wire paid out (slack)
    q[8] = -1.0  # pull a distal wire
    B = np.asarray(EQ(rob, q, None))
    assert np.all(np.linalg.norm(B, axis=1) > 1e-3)


def test_equilibrium_derivatives_match_finite_differences():
    rob = three_segments(preload=0.5)
    q = jnp.asarray(Q_CASES[0])
    _assert_J_PQ_matches_fd(rob, q, None, h=1e-6, atol=1e-5)
    # reverse mode through the implicit rule, in a robot parameter
    @jax.jit
    def tip_x(ei):
        segs = (ms._design_with(rob.segments[0], backbone_EI=ei),) + rob.segments[1:]
        return ms.forward(ms.Robot(segs), q)[0][0]

    g = jax.jit(jax.grad(tip_x))(2400.0)
    fd = (tip_x(2400.0 + 1e-3) - tip_x(2400.0 - 1e-3)) / 2e-3
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-9)


def test_straight_pose_values_and_gradients_finite():
    rob = three_segments(preload=0.0)
    q = jnp.zeros(rob.n_wires)
    B = EQ(rob, q, None)
    np.testing.assert_array_equal(B, 0.0)
    J = J_PQ(rob, q, None)
    assert np.all(np.isfinite(J)) and np.abs(J).max() > 0
    assert np.all(np.isfinite(ms.J_xB(rob, B)))
    assert np.all(np.isfinite(ms.reduced_J_xq(rob, B)))
    g = jax.jit(jax.grad(lambda r: ms.forward(r, q)[0][0]))(rob)
    assert all(np.all(np.isfinite(x)) for x in jax.tree_util.tree_leaves(g))


def test_vmapped_and_new_values_do_not_recompile():
    rob = three_segments()
    f = jax.jit(jax.vmap(lambda r, q: ms.forward(r, q)[0], in_axes=(None, 0)))
    Q = jnp.asarray(np.stack(Q_CASES))
    P = f(rob, Q)
    np.testing.assert_allclose(P[1], ms.forward(rob, Q[1])[0], atol=1e-12)
    f(three_segments(k_w=80.0, preload=0.2), Q)
    assert f._cache_size() == 1
