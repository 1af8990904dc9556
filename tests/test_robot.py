"""The robot model (one or more segments): single-segment equivalence, routing, chained kinematics,
Jacobians and the one equilibrium solver."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import minimize, root
from scipy.spatial.transform import Rotation

import tension_zones as tz
from tension_zones import model as ms

DEG = np.pi / 180


def three_segments(k_w=60.0, preload=0.0):
    return ms.Robot(
        [
            tz.Design(
                3,
                60.0,
                4.5,
                wire_angles=np.radians([10, 130, 250]),
                backbone_EI=2400.0,
                wire_stiffness=k_w,
                preload=preload,
            ),
            tz.Design(
                4,
                62.5,
                4.0,
                wire_angles=np.radians([40, 125, 220, 310]),
                backbone_EI=2000.0,
                wire_stiffness=k_w,
                preload=preload,
            ),
            tz.Design(
                3,
                64.0,
                3.5,
                wire_angles=np.radians([80, 200, 320]),
                backbone_EI=1500.0,
                wire_stiffness=k_w,
                preload=preload,
            ),
        ]
    )


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
    np.testing.assert_array_equal(rob.wire_lengths(B), tz.wire_lengths_b(d, b))
    p, R = rob.tip_pose(B)
    p1, R1 = tz.tip_pose_b(d, b)
    np.testing.assert_array_equal(p, p1)
    np.testing.assert_array_equal(R, R1)
    np.testing.assert_array_equal(rob.J_qB(), tz.J_qb(d))
    np.testing.assert_allclose(rob.J_xB(B), tz.J_xb(d, b), rtol=0, atol=1e-14)
    _, delta = tz.b_to_psi(jnp.asarray(b))
    np.testing.assert_allclose(rob.tension_score(B), tz.tension_score(d, delta), atol=1e-15)
    np.testing.assert_array_equal(rob.tension_mask(B), tz.tension_mask(d, delta))


def test_single_segment_jacobians_match_psi_coordinates():
    d = tz.Design(3, 20.0, 2.0)
    theta, delta = np.radians(60.0), np.radians(66.0)  # two taut wires (1 and 3)
    B = np.asarray(tz.psi_to_b(theta, delta))[None, :]
    rob = ms.Robot(d)
    np.testing.assert_allclose(rob.J_xq(B), tz.J_xq(d, theta, delta), atol=1e-10)
    np.testing.assert_allclose(rob.reduced_J_xq(B), tz.reduced_J_xq(d, theta, delta), atol=1e-10)


def _single_equilibrium_reference(d, q, f):
    """tension_zones/MODEL.md Sec. 5 written out in NumPy and minimised by SciPy (an independent solver)."""
    L, r, a = float(d.length), float(d.pitch_radius), np.asarray(d.wire_angles)
    kw, EI, pre = float(d.wire_stiffness), float(d.backbone_EI), float(d.preload)

    def V(b):
        u, v = b
        phi = max(np.hypot(u, v), 1e-12)
        p = np.array([L * (1 - np.cos(phi)) / phi**2 * u, L * (1 - np.cos(phi)) / phi**2 * v, L * np.sin(phi) / phi])
        s = -r * (u * np.cos(a) + v * np.sin(a)) - q + pre / kw
        return EI * (u * u + v * v) / (2 * L) + 0.5 * kw * np.sum(np.maximum(s, 0) ** 2) - f @ p

    return minimize(V, np.array([0.1, 0.1]), method="BFGS", options={"gtol": 1e-10}).x


@pytest.mark.parametrize(
    "q, f",
    [
        (np.array([-0.8, 0.3, 0.4]), np.zeros(3)),
        (np.array([-0.2, -0.5, 0.6]), np.array([0.3, -0.2, 0.0])),
        (np.array([0.1, 0.1, 0.1]), np.zeros(3)),
    ],
)
def test_single_segment_equilibrium_matches_independent_solver(q, f):
    d = tz.Design(3, 20.0, 2.0, wire_stiffness=70.0, backbone_EI=1200.0, preload=1.0)
    B = EQ(ms.Robot(d), q, ms.Load(f, np.zeros(3)))
    np.testing.assert_allclose(B[0], _single_equilibrium_reference(d, q, f), atol=1e-6)


def test_robot_from_dict_single_and_multi(tmp_path):
    single = {"n_wires": 3, "length_mm": 20.0, "pitch_radius_mm": 2.0}
    rob = ms.Robot.from_dict(single)
    assert rob.n_segments == 1 and rob.n_wires == 3
    seg = {
        "length_mm": 60.0,
        "n_wires": 3,
        "pitch_radius_mm": 4.5,
        "wire_angles_deg": [0, 120, 240],
        "backbone_EI_Nmm2": 2454.0,
        "wire_stiffness_N_per_mm": 50.0,
        "preload_N": 0.5,
    }
    rob3 = ms.Robot.from_dict({"segments": [seg, dict(seg, length_mm=62.5), dict(seg, length_mm=64.0)]})
    assert rob3.n_wires_per_segment == (3, 3, 3)
    np.testing.assert_allclose(rob3.lengths, [60.0, 62.5, 64.0])
    assert ms.Robot.from_dict(rob3.to_dict()).n_wires == 9
    with pytest.raises(ValueError, match="segment 1: pitch_radius_mm must be positive"):
        ms.Robot.from_dict({"segments": [seg, dict(seg, pitch_radius_mm=-1.0)]})
    with pytest.raises(ValueError, match="unknown robot design key"):
        ms.Robot.from_dict({"segments": [seg], "twist": 1})
    example = ms.Robot.from_json(tz.example_path("ftdcr_v4/design.json"))
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
    return np.array(
        [rho * (1 - np.cos(phi)) * np.cos(sig), rho * (1 - np.cos(phi)) * np.sin(sig), rho * np.sin(phi)]
    ), rot.as_matrix()


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
    lengths = np.asarray(rob.wire_lengths(B_BENT))
    for k in [0, 4, 6, 9]:  # a proximal, a middle and two distal wires
        np.testing.assert_allclose(lengths[k], _integrated_wire_length(rob, B_BENT, k), atol=2e-3)
    # a distal wire changes length with every segment it crosses
    for j in range(3):
        B = np.zeros((3, 2))
        B[j] = [0.3, 0.1]
        dl = np.asarray(rob.wire_length_changes(B))
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
    p, R = rob.tip_pose(B_BENT)
    np.testing.assert_allclose(p, T[:3, 3], atol=1e-10)
    np.testing.assert_allclose(R, T[:3, :3], atol=1e-12)


# ---------------------------------------------------------------------------------------------
# Jacobians
# ---------------------------------------------------------------------------------------------
def test_J_qB_and_J_xB_match_finite_differences():
    rob = three_segments()
    tip = jax.jit(lambda r, B: r.tip_pose(B))
    x = B_BENT.reshape(-1)
    h = 1e-6
    Jq_fd, Jp_fd = [], []
    for i in range(6):
        e = np.zeros(6)
        e[i] = h
        Bp, Bm = (x + e).reshape(3, 2), (x - e).reshape(3, 2)
        Jq_fd.append((rob.wire_lengths(Bp) - rob.wire_lengths(Bm)) / (2 * h))
        Jp_fd.append((tip(rob, Bp)[0] - tip(rob, Bm)[0]) / (2 * h))
    np.testing.assert_allclose(rob.J_qB(), np.stack(Jq_fd, 1), atol=1e-7)
    Jx = rob.J_xB(B_BENT)
    np.testing.assert_allclose(Jx[:3], np.stack(Jp_fd, 1), atol=1e-6)
    # angular part: vee(dR R^T) by finite differences
    R0 = np.asarray(rob.tip_pose(B_BENT)[1])
    for i in range(6):
        e = np.zeros(6)
        e[i] = h
        dR = (np.asarray(tip(rob, (x + e).reshape(3, 2))[1]) - np.asarray(tip(rob, (x - e).reshape(3, 2))[1])) / (2 * h)
        W = dR @ R0.T
        np.testing.assert_allclose(Jx[3:, i], [W[2, 1], W[0, 2], W[1, 0]], atol=1e-6)


def test_reduced_jacobian_zeroes_slack_columns():
    rob = three_segments()
    mask = np.asarray(rob.tension_mask(B_BENT))
    J = np.asarray(rob.reduced_J_xq(B_BENT))
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
    g = jax.jit(jax.grad(ms.energy, argnums=1))(rob, B, q, load)
    np.testing.assert_allclose(g, 0.0, atol=1e-9)
    tau = np.asarray(jax.jit(ms.wire_tensions)(rob, B, q))
    s = np.asarray(jax.jit(ms.wire_stretch)(rob, B, q))
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
        leaves, treedef = jax.tree_util.tree_flatten(rob.segments[0])
        leaves[4] = ei  # backbone_EI (Design's leaves: length, pitch_radius, wire_angles, k_w, EI, preload)
        segs = (jax.tree_util.tree_unflatten(treedef, leaves),) + rob.segments[1:]
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
    assert np.all(np.isfinite(rob.J_xB(B)))
    assert np.all(np.isfinite(rob.reduced_J_xq(B)))
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


# ---------------------------------------------------------------------------------------------
# closed forms of the chain and the load, routing from design files, friction
# ---------------------------------------------------------------------------------------------
from tension_zones.model import _equilibrium as E
from tension_zones.model import _kinematics as K
from tension_zones.model._robot import chain_poses, chain_tip


@pytest.mark.parametrize("b", [np.array([0.0, 0.0]), np.array([0.7, -0.4]), np.array([1e-7, 0.0])])
def test_weight_moment_is_the_integral_of_the_arc(b):
    L = 30.0
    x, w = np.polynomial.legendre.leggauss(20)
    s = 0.5 * L * (x + 1.0)
    pts = np.stack([np.asarray(K.segment_pose(si, b * si / L)[0]) for si in s])
    np.testing.assert_allclose(K.segment_weight_moment(L, jnp.asarray(b)), 0.5 * L * w @ pts, rtol=1e-12, atol=1e-9)
    J = jax.jit(jax.jacfwd(lambda bb: K.segment_weight_moment(L, bb)))(jnp.asarray(b))
    np.testing.assert_allclose(K.segment_weight_moment_jacobian(L, jnp.asarray(b)), J, atol=1e-9)


@pytest.mark.parametrize("x", [np.zeros(6), B_BENT.reshape(-1)])
def test_load_jacobians_and_chain_tip_derivative_are_exact(x):
    L = jnp.asarray([60.0, 62.5, 64.0])
    f, g = jnp.asarray([0.3, -0.2, 0.5]), jnp.asarray([1e-3, 2e-3, -4e-3])
    x = jnp.asarray(x)
    np.testing.assert_allclose(
        jax.jit(E.load_gradient)(L, x, f, g), jax.jit(jax.grad(E.load_potential, argnums=1))(L, x, f, g), atol=1e-10
    )
    # the custom derivative of the tip against forward mode through the plain chain, in B and L
    plain = lambda LL, xx: chain_poses(LL, xx.reshape(3, 2))[0][-1]
    fast = lambda LL, xx: chain_tip(LL, xx.reshape(3, 2))[0]
    for arg in (0, 1):
        np.testing.assert_allclose(
            jax.jit(jax.jacfwd(fast, argnums=arg))(L, x), jax.jit(jax.jacfwd(plain, argnums=arg))(L, x), atol=1e-10
        )
    Rp = jax.jit(jax.jacfwd(lambda xx: chain_poses(L, xx.reshape(3, 2))[1][-1]))(x)
    Rf = jax.jit(jax.jacfwd(lambda xx: chain_tip(L, xx.reshape(3, 2))[1]))(x)
    np.testing.assert_allclose(Rf, Rp, atol=1e-10)


def test_long_chains_as_a_scan_equal_the_unrolled_chain(monkeypatch):
    """Chains longer than CHAIN_UNROLL_MAX (the rod's pieces) are composed by a scan: the same poses,
    tip Jacobian and custom derivative as the unrolled chain, straight pieces included."""
    from tension_zones.model import _robot as R

    rng = np.random.default_rng(4)
    L = jnp.asarray(rng.uniform(5.0, 20.0, 6))
    x = jnp.asarray(np.r_[0.0, 0.0, rng.uniform(-0.6, 0.6, 10)])  # the first piece straight

    def everything():
        B = x.reshape(6, 2)
        ps, Rs = R.chain_poses(L, B)
        tip = jax.jacfwd(lambda LL, xx: R.chain_tip(LL, xx.reshape(6, 2))[0], argnums=(0, 1))(L, x)
        return ps, Rs, R.chain_J_xB(L, B), *tip

    monkeypatch.setattr(R, "CHAIN_UNROLL_MAX", 0)
    scanned = jax.jit(everything)()  # (a jit of its own each: the chain's form is fixed at tracing)
    monkeypatch.setattr(R, "CHAIN_UNROLL_MAX", 100)
    for a, b in zip(scanned, jax.jit(everything)()):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)


def test_declared_routing_is_read_and_written(tmp_path):
    seg = {"length_mm": 40.0, "n_wires": 3, "pitch_radius_mm": 3.0}
    d = {
        "segments": [
            seg,
            dict(
                seg,
                wire_angles_deg=[30.0, 150.0, 270.0],
                route_angles_deg=[[35.0], [155.0], [275.0]],
                route_radii_mm=[[4.0], [4.0], [4.0]],
            ),
        ]
    }
    rob = ms.Robot.from_dict(d)
    np.testing.assert_allclose(np.degrees(rob.route_angles[3:, 0]), [35.0, 155.0, 275.0])
    np.testing.assert_allclose(rob.route_radii[3:, 0], 4.0)
    np.testing.assert_allclose(np.degrees(rob.route_angles[3:, 1]), [30.0, 150.0, 270.0])  # own segment
    np.testing.assert_allclose(ms.Robot.from_dict(rob.to_dict()).route_radii, rob.route_radii)
    B = np.array([[0.3, 0.1], [0.0, 0.0]])
    default = ms.Robot.from_dict({"segments": [seg, dict(seg, wire_angles_deg=[30.0, 150.0, 270.0])]})
    assert not np.allclose(rob.wire_lengths(B)[3:], default.wire_lengths(B)[3:])
    with pytest.raises(ValueError, match="segment 1: route_radii_mm must be a list of 3 lists"):
        ms.Robot.from_dict({"segments": [seg, dict(seg, route_radii_mm=[[4.0, 1.0]] * 3)]})
    with pytest.raises(ValueError, match="route_radii_mm must be positive"):
        ms.Robot.from_dict({"segments": [seg, dict(seg, route_radii_mm=[[-4.0]] * 3)]})


def _solve(rob, q, mu, direction, load=None):
    phys = rob.params()
    phys["friction"] = jnp.asarray(mu)
    f = jnp.zeros(3) if load is None else load.tip_force
    if load is not None:
        phys["gravity"] = load.gravity
    return E.solve(phys, rob.structure, q, f, direction)


def test_friction_equilibrium_is_the_root_and_its_derivatives_are_exact():
    rob = three_segments(preload=0.5)
    q, d = jnp.asarray(Q_CASES[0]), jnp.asarray(np.sign(Q_CASES[0]))
    mu = jnp.asarray([0.1, 0.2])
    B = jax.jit(_solve)(rob, q, mu, d)
    phys = rob.params()
    phys["friction"] = mu
    F = E._Sample(phys, rob.structure, q, jnp.zeros(3), d, jnp.asarray(False)).force(B.reshape(-1))
    np.testing.assert_allclose(F, 0.0, atol=1e-9)
    assert np.abs(np.asarray(B) - np.asarray(EQ(rob, q, None))).max() > 1e-3  # friction matters
    tip = jax.jit(lambda m: rob.tip_pose(_solve(rob, q, m, d))[0])
    J = jax.jit(jax.jacfwd(tip))(mu)
    h = 1e-6
    for i in range(2):
        e = jnp.zeros(2).at[i].set(h)
        np.testing.assert_allclose(J[:, i], (tip(mu + e) - tip(mu - e)) / (2 * h), rtol=1e-5, atol=1e-6)


def _clearance_solve(rob, q, c, mu=(0.0, 0.0), direction=None, pieces=1):
    phys = rob.params()
    phys["clearance"], phys["friction"] = jnp.asarray(c), jnp.asarray(mu)
    st = ms.Structure(rob.n_wires_per_segment, pieces)
    return E.solve(phys, st, q, jnp.zeros(3), direction)


@pytest.mark.parametrize("case", [0, 1])
def test_clearance_equilibrium_matches_an_independent_root_and_its_derivatives_are_exact(case):
    """The hole clearance shortens wire k's path by ``C_kj |b_j|`` in every segment j it crosses
    (``c_own`` in its own, ``c_proximal`` before): the solve is the root of a NumPy force written here
    from the constant routing ``J_qB`` (and MINPACK's root of it from nearby), and its implicit
    derivatives in the clearance and the commands match central differences."""
    rob = three_segments(preload=0.5)
    q, c = jnp.asarray(Q_CASES[case]), jnp.asarray([0.1, 0.3])
    B = np.asarray(jax.jit(_clearance_solve)(rob, q, c)).reshape(-1)
    A = np.asarray(rob.J_qB())
    owner = np.repeat(np.arange(3), rob.n_wires_per_segment)
    C = np.where(
        np.arange(3)[None, :] == owner[:, None], 0.1, np.where(np.arange(3)[None, :] < owner[:, None], 0.3, 0.0)
    )
    k, pre = np.asarray(rob.wire_stiffness), np.asarray(rob.preload)
    Ek = np.repeat(np.asarray(rob.backbone_EI) / np.asarray(rob.lengths), 2)

    def force(x):
        s = A @ x - np.asarray(q) + pre / k - C @ np.hypot(*x.reshape(3, 2).T)
        return Ek * x + A.T @ (k * np.maximum(s, 0.0))

    np.testing.assert_allclose(force(B), 0.0, atol=1e-8)  # the solve is a root of the NumPy force
    ref = root(force, B + 1e-3, method="hybr", options={"xtol": 1e-13}).x  # and MINPACK's from near it
    np.testing.assert_allclose(B, ref, atol=1e-9)
    assert np.abs(B - np.asarray(EQ(rob, q, None)).reshape(-1)).max() > 1e-3  # the clearance matters
    tip = jax.jit(lambda c, q: rob.tip_pose(_clearance_solve(rob, q, c))[0])
    Jc, Jq = jax.jit(jax.jacfwd(tip, argnums=(0, 1)))(c, q)
    h = 1e-6
    for i in range(2):
        e = jnp.zeros(2).at[i].set(h)
        np.testing.assert_allclose(Jc[:, i], (tip(c + e, q) - tip(c - e, q)) / (2 * h), rtol=1e-5, atol=1e-6)
    for i in range(q.shape[0]):
        e = jnp.zeros(q.shape[0]).at[i].set(h)
        np.testing.assert_allclose(Jq[:, i], (tip(c, q + e) - tip(c, q - e)) / (2 * h), rtol=1e-5, atol=1e-6)


def test_clearance_with_friction_in_the_rod_is_the_root_and_its_derivatives_are_exact():
    """Both non-conservative parts at once, in pieces: the force vanishes at the solve and the
    derivative in the clearance matches central differences."""
    rob = three_segments(preload=0.5)
    q, d = jnp.asarray(Q_CASES[0]), jnp.asarray(np.sign(Q_CASES[0]))
    c, mu = jnp.asarray([0.1, 0.3]), jnp.asarray([0.1, 0.2])
    st = ms.Structure(rob.n_wires_per_segment, 3)
    B = jax.jit(_clearance_solve, static_argnums=5)(rob, q, c, mu, d, 3)
    phys = rob.params()
    phys["clearance"], phys["friction"] = c, mu
    phys["curvature_freedom"] = jnp.ones(3)
    F = E._Sample(phys, st, q, jnp.zeros(3), d, jnp.asarray(False)).force(B.reshape(-1))
    np.testing.assert_allclose(F, 0.0, atol=1e-9)
    tip = jax.jit(lambda c: chain_tip(E.piece_lengths(phys, st), _clearance_solve(rob, q, c, mu, d, 3))[0])
    J = jax.jit(jax.jacfwd(tip))(c)
    h = 1e-6
    for i in range(2):
        e = jnp.zeros(2).at[i].set(h)
        np.testing.assert_allclose(J[:, i], (tip(c + e) - tip(c - e)) / (2 * h), rtol=1e-5, atol=1e-6)


def test_clearance_at_the_straight_pose_is_finite_with_finite_gradients():
    """``|b|`` has a cone at ``b = 0``; a preloaded segment of evenly spaced wires at
    ``q = 0`` stays straight and the tip's derivatives in the clearance and the commands are finite
    there."""
    rob = ms.Robot([tz.Design(3, 60.0, 4.5, backbone_EI=2400.0, wire_stiffness=60.0, preload=0.5)])
    q, c = jnp.zeros(rob.n_wires), jnp.asarray([0.1, 0.0])
    B = jax.jit(_clearance_solve)(rob, q, c)
    np.testing.assert_allclose(B, 0.0, atol=1e-12)
    Jc, Jq = jax.jit(jax.jacfwd(lambda c, q: rob.tip_pose(_clearance_solve(rob, q, c))[0], argnums=(0, 1)))(c, q)
    assert np.all(np.isfinite(Jc)) and np.all(np.isfinite(Jq))


def test_loaded_equilibrium_from_an_unstable_start_reaches_a_minimum():
    """One wire pulled, the others paid out, a tip force pushing down and sideways: the energy's
    Hessian at the straight start has a negative eigenvalue. The solve must still reach a stationary
    point that is a minimum (a Newton step on that Hessian would be near-infinite and stay at the
    start)."""
    rob = ms.Robot(
        [
            tz.Design(3, 45.0, 3.5, wire_angles=np.radians([10, 130, 250]), backbone_EI=1800.0, wire_stiffness=30.0),
            tz.Design(
                4, 70.0, 5.0, wire_angles=np.radians([45, 135, 215, 315]), backbone_EI=2400.0, wire_stiffness=80.0
            ),
        ]
    )
    q = jnp.asarray([0.8, 0.8, -2.0, 0.8, 0.8, 0.8, 0.8])
    load = ms.Load(jnp.asarray([0.3, -0.2, -0.4]), jnp.zeros(3))
    x = np.asarray(EQ(rob, q, load)).reshape(-1)
    V = jax.jit(lambda y: ms.energy(rob, y.reshape(2, 2), q, load))
    G = jax.jit(jax.grad(lambda y: ms.energy(rob, y.reshape(2, 2), q, load)))
    np.testing.assert_allclose(G(jnp.asarray(x)), 0.0, atol=1e-8)
    rng = np.random.default_rng(0)
    assert all(float(V(jnp.asarray(x + 1e-3 * rng.normal(size=4)))) > float(V(jnp.asarray(x))) for _ in range(20))
    ref = minimize(
        lambda y: float(V(jnp.asarray(y))),
        np.zeros(4),
        jac=lambda y: np.asarray(G(jnp.asarray(y))),
        method="BFGS",
        options={"gtol": 1e-10},
    )
    assert float(V(jnp.asarray(x))) <= ref.fun + 1e-9


def test_robot_file_names_missing_physical_keys_per_segment(tmp_path):
    import json
    import warnings

    from tension_zones.model import MissingDesignKeyWarning

    full = {
        "n_wires": 3,
        "length_mm": 20.0,
        "pitch_radius_mm": 2.0,
        "wire_stiffness_N_per_mm": 80.0,
        "backbone_EI_Nmm2": 900.0,
        "preload_N": 0.5,
    }
    part = {k: v for k, v in full.items() if k != "preload_N"}
    p = tmp_path / "r.json"
    p.write_text(json.dumps({"segments": [full, part]}))
    with pytest.warns(MissingDesignKeyWarning, match=r"r\.json.*segment 1: 'preload_N' \(default 0 used\)") as rec:
        tz.Robot.from_json(p, warn_missing=True)
    assert len(rec) == 1 and "segment 0" not in str(rec[0].message)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tz.Robot.from_json(p)  # opt-in only
        p.write_text(json.dumps({"segments": [full, full]}))
        tz.Robot.from_json(p, warn_missing=True)
