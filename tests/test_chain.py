"""Measures of robots of one, two and three segments (tension_zones/analysis/_chain.py) against an
independent NumPy reference (tests/reference_chain.py), the segment's own measures and brute force."""

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st
from reference_chain import compliance as compliance_reference
from reference_chain import measures

import tension_zones as tz
from tension_zones._numerics import MASK_TABLE_SHARE, mask_table, masked_pinv, shared_mask_table, singular_values
from tension_zones.analysis import config_measures, config_metrics, zonotope_max_sq
from tension_zones.analysis._chain import BOX_VERTICES_MAX, _face_edges_max_sq
from tension_zones.model import Robot
from tension_zones.model._chain_statics import config_compliance
from tension_zones.model._chain_zones import crossing_wires, segment_tension_map
from tension_zones.model._kinematics import psi_to_b

SEGMENTS = (
    tz.Design(3, 30.0, 4.0),
    tz.Design(4, 25.0, 3.0, wire_angles=np.radians([10, 100, 190, 280])),
    tz.Design(3, 20.0, 2.5, wire_angles=np.radians([30, 150, 270])),
)


def _robot(S, routed=False):
    if not routed:
        return Robot(SEGMENTS[:S])
    n = sum(s.n_wires for s in SEGMENTS[:S])
    rng = np.random.default_rng(S)
    return Robot(SEGMENTS[:S], route_angles=rng.uniform(0, 2 * np.pi, (n, S)), route_radii=rng.uniform(2, 5, (n, S)))


# compiled once per robot structure: new configurations and robots of the same shape reuse it
METRICS = jax.jit(config_metrics, static_argnames="general")


def _reference(robot, B, dq=0.4):
    args = (np.asarray(robot.lengths), np.asarray(robot.route_angles), np.asarray(robot.route_radii))
    return measures(*args, np.asarray(robot.crosses), B, dq)


def _compare(robot, B, tol=1e-6):
    got, want = METRICS(robot, jnp.asarray(B, float), 0.4, general=True), _reference(robot, B)
    for k, v in want.items():
        assert float(got[k]) == pytest.approx(v, rel=tol, abs=tol), (k, np.asarray(B).tolist())


# the straight robot, one straight segment, a wire on its zone boundary (segment 0's wire 0 at 0 deg:
# bending towards 90 deg puts it at cos = 0), and general configurations
SPECIAL = {
    2: [np.zeros((2, 2)), [[0.0, 0.0], [0.5, -0.2]], [[0.0, 0.4], [0.0, 0.0]], [[0.0, 0.4], [0.0, 0.4]]],
    3: [np.zeros((3, 2)), [[0.0, 0.0], [0.0, 0.0], [0.6, 0.1]], [[0.0, -0.7], [0.3, 0.0], [0.0, 0.0]]],
}


@pytest.mark.parametrize("S", [2, 3])
@pytest.mark.parametrize("routed", [False, True])
def test_straight_boundary_and_general_configurations_match_the_numpy_reference(S, routed):
    rob = _robot(S, routed)
    rng = np.random.default_rng(7)
    for B in SPECIAL[S] + [rng.uniform(-1.2, 1.2, (S, 2)) for _ in range(3)]:
        _compare(rob, np.asarray(B, float))


@given(st.lists(st.floats(-1.5, 1.5), min_size=4, max_size=4))
def test_two_segments_match_the_numpy_reference_anywhere(x):
    _compare(_robot(2, routed=True), np.reshape(x, (2, 2)))


def test_a_one_segment_robot_gives_the_designs_numbers_on_the_paper_grid():
    th, de = np.meshgrid(np.radians(np.arange(0, 86, 5.0)), np.radians(np.arange(0, 360.1, 2.5)), indexing="ij")
    th, de = jnp.asarray(th.ravel()), jnp.asarray(de.ravel())
    for seg in (tz.Design(3, 20.0, 2.0), tz.Design(4, 20.0, 2.0)):
        B = jax.vmap(psi_to_b)(th, de)[:, None, :]
        got = jax.jit(jax.vmap(config_metrics, (None, 0, None)))(Robot(seg), B, 0.4)
        want = jax.jit(jax.vmap(tz.pose_metrics, (None, 0, 0, None)))(seg, th, de, 0.4)
        for k in want:
            np.testing.assert_allclose(np.asarray(got[k]), np.asarray(want[k]), rtol=1e-10, atol=1e-10, err_msg=k)


def test_the_chain_formulas_agree_with_the_segments_where_the_taut_wires_fix_the_configuration():
    """With one segment the chain formulas (bending vectors) and the segment's (theta_L, delta) differ
    only where fewer than two wires act (the pseudo-inverse's minimum norm depends on the coordinates):
    all wires, and the reduced Jacobian of four wires, agree."""
    rob = Robot(tz.Design(4, 20.0, 2.0))
    for th, de in itertools.product(np.radians([85.0, 60.0, 5.0]), np.radians([20.0, 135.0, 250.0])):
        B = psi_to_b(th, de)[None]
        got, want = METRICS(rob, B, 0.4, general=True), METRICS(rob, B, 0.4)
        for k in want:
            np.testing.assert_allclose(np.asarray(got[k]), np.asarray(want[k]), rtol=1e-10, atol=1e-12, err_msg=k)


@pytest.mark.parametrize("S", [2, 3])
def test_gradients_are_finite_at_straight_and_boundary_configurations(S):
    rob = _robot(S)

    def total(B, r):
        m = config_metrics(r, B, 0.4)
        return sum(jnp.sum(v) for k, v in m.items() if not k.startswith("n_taut"))

    grad = jax.jit(jax.grad(total, argnums=(0, 1)))
    for B in SPECIAL[S]:
        grads = grad(jnp.asarray(B, float), rob)
        assert all(bool(jnp.all(jnp.isfinite(g))) for g in jax.tree_util.tree_leaves(grads))


def _brute(G):
    s = np.array(list(itertools.product([-1.0, 1.0], repeat=G.shape[1]))).T
    return np.max(np.sum((G @ s) ** 2, axis=0))


@st.composite
def generators(draw, max_n=7):
    n = draw(st.integers(1, max_n))
    G = np.array(draw(st.lists(st.floats(-3, 3), min_size=3 * n, max_size=3 * n))).reshape(3, n)
    kind = draw(st.sampled_from(["any", "flat", "line", "parallel", "zeros"]))
    if kind == "flat":
        G[2] = 0.0
    elif kind == "line":
        G = np.outer([0.3, -1.0, 2.0], G[0])
    elif kind == "parallel" and n > 1:
        G[:, -1] = -2.0 * G[:, 0]
    elif kind == "zeros":
        G[:, : n // 2] = 0.0
    return G


ZONOTOPE = jax.jit(zonotope_max_sq)
FACE_EDGES = jax.jit(_face_edges_max_sq)


@given(generators(max_n=BOX_VERTICES_MAX + 2))
def test_the_zonotopes_largest_norm_is_its_largest_vertex(G):
    assert float(ZONOTOPE(jnp.asarray(G))) == pytest.approx(_brute(G), rel=1e-12, abs=1e-12)


@given(generators())
def test_the_face_edges_ends_reach_the_largest_vertex(G):
    """The enumeration taken beyond ``BOX_VERTICES_MAX`` generators, on few: flat, parallel, zero."""
    assert float(FACE_EDGES(jnp.asarray(G))) == pytest.approx(_brute(G), rel=1e-12, abs=1e-12)


@st.composite
def small_matrices(draw):
    m, n = draw(st.integers(1, 8)), draw(st.integers(1, 12))
    A = np.array(draw(st.lists(st.floats(-3, 3), min_size=m * n, max_size=m * n))).reshape(m, n)
    A[np.abs(A) < 1e-100] = 0.0  # (XLA on a CPU flushes subnormal numbers to zero; LAPACK does not)
    kind = draw(st.sampled_from(["any", "zero row", "rank one", "near rank deficient", "equal"]))
    if kind == "zero row":
        A[-1] = 0.0
    elif kind == "rank one":
        A = np.outer(np.linspace(-1.0, 2.0, m), A[0])
    elif kind == "near rank deficient" and m >= 3:
        A[-1] = 0.4 * A[0] - A[1] + 1e-9 * A[-1]
    elif kind == "equal":
        A = 2.0 * np.eye(m, n)
    return A * 10.0 ** draw(st.integers(-3, 3))


SINGULAR = jax.jit(jax.vmap(singular_values))
SINGULAR_JVP = jax.jit(lambda A, dA: jax.jvp(singular_values, (A,), (dA,)))


@given(small_matrices())
@example(np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]]))
def test_a_small_matrixs_singular_values_are_numpys_and_their_derivatives_are_finite(A):
    """The chain's blocks (3, N) and the taut wires' directions (N, 2S) take these (either shape)."""
    want = np.linalg.svd(A, compute_uv=False)
    got = np.asarray(SINGULAR(jnp.asarray(A)[None])[0])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13 * max(want[0], 1e-300))
    dA = np.cos(np.arange(A.size)).reshape(A.shape)
    _, tangent = SINGULAR_JVP(jnp.asarray(A), jnp.asarray(dA))
    assert np.all(np.isfinite(np.asarray(tangent)))
    gap = np.min(np.abs(np.diff(want)), initial=np.inf)
    h = 1e-3 * min(want[-1], gap)  # within the smallest value and gap: no value crosses zero or another
    if want[-1] > 1e-6 * want[0] and gap > 1e-6 * want[0] and h > 1e-280:  # distinct, non-zero, a step
        fd = (np.linalg.svd(A + h * dA, compute_uv=False) - np.linalg.svd(A - h * dA, compute_uv=False)) / (2 * h)
        np.testing.assert_allclose(np.asarray(tangent), fd, rtol=1e-5, atol=1e-6 * max(1.0, want[0]))


def test_a_batch_takes_the_taut_wires_pseudo_inverses_from_a_table_and_matches_the_reference():
    """Vmapped over a batch of at least ``MASK_TABLE_SHARE x 2^N`` configurations, each reduced
    Jacobian's pseudo-inverse is looked up in a table of every mask's (one SVD batch of ``2^N``), and
    the measures are the per-configuration NumPy reference's, the straight and boundary ones included."""
    rob = _robot(3, routed=True)
    n = rob.n_wires
    size = MASK_TABLE_SHARE * 2**n
    rng = np.random.default_rng(7)
    B = rng.uniform(-0.8, 0.8, (size, 3, 2))
    B[: len(SPECIAL[3])] = np.asarray(SPECIAL[3], float)
    reduced = jax.vmap(lambda b: rob.J_xq(b, rob.tension_mask(b)))
    assert f"f64[{2**n},{n},6]" in str(jax.make_jaxpr(reduced)(B))  # the table: 2^N matrices in one SVD
    assert f"f64[{2**n},{n},6]" not in str(jax.make_jaxpr(reduced)(B[:8]))  # a small batch: one SVD each
    got = jax.jit(jax.vmap(lambda b: config_metrics(rob, b, 0.4)))(jnp.asarray(B))
    for i in [*range(len(SPECIAL[3])), *rng.choice(size, 60, replace=False)]:
        for k, v in _reference(rob, B[i]).items():
            assert float(got[k][i]) == pytest.approx(v, rel=1e-6, abs=1e-6), (k, B[i].tolist())


def test_the_pseudo_inverse_of_the_kept_rows_has_the_formulas_derivatives():
    """``masked_pinv``'s derivatives, in the matrix and in the mask (a straight-through mask's soft
    part), are the formula's, vmapped over a batch that takes the table."""
    rng = np.random.default_rng(3)
    A = jnp.asarray(rng.normal(size=(5, 4)))
    masks = jnp.asarray((np.arange(2**5)[:, None] >> np.arange(5)) & 1, float)
    masks = jnp.concatenate([masks] * MASK_TABLE_SHARE)  # every mask, enough for the table
    dA = jnp.asarray(rng.normal(size=(5, 4)))
    dm = jnp.asarray(rng.normal(size=masks.shape))

    def formula(A, m):
        return jnp.linalg.pinv(A * m[:, None]) * m[None, :]

    batched = jax.vmap(masked_pinv, in_axes=(None, 0))
    assert "f64[32,5,4]" in str(jax.make_jaxpr(batched)(A, masks))  # the table of every mask
    want = jax.vmap(formula, in_axes=(None, 0))(A, masks)
    np.testing.assert_allclose(batched(A, masks), want, rtol=0, atol=1e-13)
    np.testing.assert_allclose(want[5], np.linalg.pinv(np.asarray(A) * np.asarray(masks[5])[:, None]), atol=1e-13)
    _, tangent = jax.jvp(batched, (A, masks), (dA, dm))
    _, tangent_want = jax.jvp(jax.vmap(formula, in_axes=(None, 0)), (A, masks), (dA, dm))
    np.testing.assert_allclose(tangent, tangent_want, rtol=0, atol=1e-12)
    grad = jax.grad(lambda A: jnp.sum(batched(A, masks) ** 2))(A)
    step = 1e-6
    fd = [
        (jnp.sum(batched(A + step * E, masks) ** 2) - jnp.sum(batched(A - step * E, masks) ** 2)) / (2 * step)
        for E in np.eye(20).reshape(20, 5, 4)[:6]
    ]
    np.testing.assert_allclose(np.ravel(grad)[:6], fd, rtol=1e-6)


def test_a_shared_table_is_taken_only_for_its_own_matrix():
    """Inside ``shared_mask_table(A, table)`` a batch of masks of ``A`` is looked up in ``table`` (made
    once, e.g. per sweep): a deliberately wrong table shows it is the one used. Any other matrix of
    the same shape, checked where it runs, gets its own pseudo-inverses."""
    rng = np.random.default_rng(5)
    A, other = (jnp.asarray(rng.normal(size=(4, 3))) for _ in range(2))
    masks = jnp.asarray(rng.integers(0, 2, (MASK_TABLE_SHARE * 2**4, 4)), float)
    batched = jax.vmap(masked_pinv, in_axes=(None, 0))

    @jax.jit
    def shared(ref, table, M):
        with shared_mask_table(ref, table):
            return batched(M, masks)

    wrong = jnp.full_like(mask_table(A), 7.0)
    np.testing.assert_array_equal(shared(A, wrong, A), 7.0)
    np.testing.assert_array_equal(shared(A, mask_table(A), A), batched(A, masks))
    np.testing.assert_array_equal(shared(A, wrong, other), batched(other, masks))


def test_new_values_never_recompile():
    f = jax.jit(lambda r, B, dq: config_metrics(r, B, dq))
    f(_robot(2), jnp.zeros((2, 2)), 0.4)
    f(_robot(2, routed=True), jnp.ones((2, 2)) * 0.3, 0.7)
    assert f._cache_size() == 1


@pytest.mark.parametrize(
    "B, message",
    [(np.zeros((3, 2)), r"shape \(2, 2\)"), ([[0.0, 60.0], [0.0, 0.0]], "beyond pi: B is in radians")],
)
def test_a_configuration_of_the_wrong_shape_or_in_degrees_is_refused(B, message):
    with pytest.raises(ValueError, match=message):
        config_measures(_robot(2), B)


def test_nan_in_gives_nan_out():
    m = METRICS(_robot(2), jnp.array([[np.nan, 0.0], [0.1, 0.2]]), 0.4)
    assert int(m["n_taut"]) == -1
    assert all(bool(jnp.isnan(v)) for k, v in m.items() if not k.startswith("n_taut"))


# ------------------------------------------------------------------------------------------------
# Tension maps of a robot's segments
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "seg",
    [
        tz.Design(3, 20.0, 2.0),
        tz.Design(4, 20.0, 2.0),
        tz.Design(5, 20.0, 2.0, wire_angles=np.radians([0, 50, 130, 200, 300])),
    ],
)
def test_a_one_segment_robots_map_is_the_segments(seg):
    assert segment_tension_map(Robot(seg), 0) == tz.tension_map(seg)


@given(
    st.floats(0.0, 360.0),
    st.one_of(st.just(0.0), st.floats(1e-6, 1.5)),
    st.floats(-np.pi, np.pi),
    st.sampled_from([0, 1, 2]),
)
def test_a_segments_map_gives_the_robots_taut_wires(delta_deg, phi, other_dir, j):
    """The map's taut set at any direction is the wires ``Robot.tension_score`` pulls in, with segment
    ``j`` bending further there and the others bent and bending further in their own planes."""
    rob = _robot(3, routed=True)
    B = np.tile([phi * np.cos(other_dir), -phi * np.sin(other_dir)], (3, 1))
    B[j] = 0.0
    tmap = segment_tension_map(rob, j, B)
    d = np.radians(delta_deg)
    B_dot = B / np.maximum(np.linalg.norm(B, axis=1, keepdims=True), 1e-300)
    B_dot[j] = [np.cos(d), -np.sin(d)]
    score = np.asarray(rob.tension_score(jnp.asarray(B), jnp.asarray(B_dot)))
    wires = crossing_wires(rob, j)
    want = tuple(int(k) + 1 for k, w in enumerate(wires) if score[w - 1] > 1e-9)
    assert tmap.taut_at(delta_deg) == want


# ------------------------------------------------------------------------------------------------
# Tension-only statics and compliance of a robot
# ------------------------------------------------------------------------------------------------
STATIC_SEGMENTS = (
    tz.Design(3, 30.0, 4.0, wire_stiffness=60.0, backbone_EI=3000.0),
    tz.Design(4, 25.0, 3.0, wire_stiffness=80.0, backbone_EI=2000.0, preload=0.5),
    tz.Design(3, 20.0, 2.5, backbone_EI=1500.0),
)
COMPLIANCE = jax.jit(config_compliance, static_argnames="general")
WRENCHES = (np.array([2.0, -1.0, 0.5, 0.0, 0.0, 0.0]), np.array([0.5, 1.0, -1.0, 20.0, -10.0, 5.0]))


@pytest.mark.parametrize("S", [2, 3])
def test_a_robots_compliance_matches_a_scipy_qp_and_finite_differences(S):
    rob = Robot(STATIC_SEGMENTS[:S])
    rng = np.random.default_rng(S)
    args = [np.asarray(x) for x in (rob.lengths, rob.backbone_EI, rob.route_angles, rob.route_radii, rob.crosses)]
    args += [np.asarray(rob.wire_stiffness), np.asarray(rob.preload)]
    for B, w in itertools.product([np.zeros((S, 2)), rng.uniform(-0.8, 0.8, (S, 2))], WRENCHES):
        got, want = COMPLIANCE(rob, jnp.asarray(B), jnp.asarray(w)), compliance_reference(*args, B, w)
        assert bool(got["feasible"])
        for k, v in want.items():
            np.testing.assert_allclose(np.asarray(got[k]), v, rtol=1e-6, atol=1e-6, err_msg=k)


def test_a_one_segment_robots_compliance_is_the_segments():
    rob = Robot(STATIC_SEGMENTS[0])
    for (th, de), w in itertools.product([(1.2, 0.3), (0.9, 2.5), (0.3, 4.0)], WRENCHES):
        B = psi_to_b(th, de)[None]
        a, b = COMPLIANCE(rob, B, w, general=True), COMPLIANCE(rob, B, w)
        for k in b:
            np.testing.assert_allclose(np.asarray(a[k]), np.asarray(b[k]), rtol=1e-10, atol=1e-12, err_msg=k)


def test_every_free_sets_residual_by_its_affine_form_is_the_sets_own():
    """The tensions try every free set through forms affine in the equilibrium's right-hand side,
    formed once per robot; each set's KKT residual equals that of the set's own closed form
    (``_set_tensions`` then ``kkt_residual``), bent, straight, preloaded, and under a wrench that
    bunched wires cannot hold. Vmapped over configurations, the forms are not per configuration: a
    chunk of a 12-wire robot's compliance needs a fraction of the memory of every set's tensions."""
    from tension_zones.model._chain_statics import (
        _set_residuals,
        _set_tensions,
        _subsets,
        chain_equilibrium,
        kkt_residual,
    )

    bunched = Robot([tz.Design(3, 30.0, 3.0, wire_angles=np.radians([0, 10, 20])) for _ in range(2)])
    rng = np.random.default_rng(4)
    for rob, w in ((Robot(STATIC_SEGMENTS), WRENCHES[1]), (bunched, np.array([5.0, 0, 0, 0, 0, 0]))):
        S, f = rob.n_segments, jnp.asarray(rob.preload)
        sets = jnp.asarray(_subsets(rob.n_wires))
        for B in (np.zeros((S, 2)), rng.uniform(-0.8, 0.8, (S, 2))):
            A, rhs = chain_equilibrium(rob, jnp.asarray(B), jnp.asarray(w))
            own = jax.vmap(lambda s, A=A, rhs=rhs, f=f: kkt_residual(A, rhs, f, *_set_tensions(A, rhs, f, s)))(sets)
            np.testing.assert_allclose(_set_residuals(A, rhs, f, sets), own, rtol=1e-9, atol=1e-12)
    twelve = Robot([tz.Design(4, 30.0, 2.0 + 0.3 * j, preload=1.0) for j in range(3)])
    chunk = jax.jit(jax.vmap(lambda B: config_compliance(twelve, B, WRENCHES[0])))
    temp = chunk.lower(jnp.zeros((2048, 3, 2))).compile().memory_analysis().temp_size_in_bytes
    assert temp < 2048 * 2**12 * twelve.n_wires * 8  # (below every set's tensions, for each configuration)


def test_a_load_the_wires_cannot_hold_is_infeasible_and_nan():
    """Wires bunched on one side of each segment cannot pull the other way: no deflection is made up."""
    bunched = [tz.Design(3, 30.0, 3.0, wire_angles=np.radians([0, 10, 20])) for _ in range(2)]
    out = COMPLIANCE(Robot(bunched), jnp.zeros((2, 2)), jnp.array([5.0, 0, 0, 0, 0, 0]))
    assert not bool(out["feasible"]) and np.isnan(float(out["deflection_mm_reduced"]))


def test_compliance_gradients_are_finite_at_the_straight_configuration_and_nan_gives_nan():
    """With respect to every number of the robot (what a design optimiser varies), straight and bent."""
    rob = Robot(STATIC_SEGMENTS[:2])
    g = jax.jit(jax.grad(lambda B, r: config_compliance(r, B, WRENCHES[0])["deflection_mm_reduced"], argnums=1))
    for B in (jnp.zeros((2, 2)), jnp.array([[0.0, 0.0], [0.4, -0.2]])):
        assert all(bool(jnp.all(jnp.isfinite(x))) for x in jax.tree_util.tree_leaves(g(B, rob)))
    out = COMPLIANCE(rob, jnp.array([[np.nan, 0.0], [0.0, 0.0]]), WRENCHES[0])
    assert int(out["n_taut_statics"]) == -1 and not bool(out["feasible"]) and np.isnan(float(out["deflection_mm_full"]))


def test_a_robots_sweep_compiles_once_per_structure():
    """Two robots of the same wire counts with other numbers, and other configurations: one program,
    and one for the table of every mask's reduced pseudo-inverse the chunks share."""
    from tension_zones.analysis import compiled_chunk_count, config_samples, sweep_configs

    a = Robot(SEGMENTS[:2])
    b = Robot([s.replace(pitch_radius=s.pitch_radius * 1.2, length=s.length * 0.9) for s in SEGMENTS[:2]])
    chunk = MASK_TABLE_SHARE * 2**a.n_wires  # large enough for the shared table
    sweep_configs(config_metrics, a, config_samples(2, 100, 60.0), 0.4, chunk_size=chunk, quiet=True)
    before = compiled_chunk_count()
    out = sweep_configs(config_metrics, b, config_samples(2, 150, 80.0, start=500), 0.7, chunk_size=chunk, quiet=True)
    assert compiled_chunk_count() == before and out["dp_max_reduced"].shape == (150,)
