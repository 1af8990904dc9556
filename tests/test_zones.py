"""Tension zones, maps and the straight-through mask (tension_zones/MODEL.md Sec. 2; paper Sec. 3)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import tension_zones as tz

rad = np.radians


def taut(design, delta_deg, **kw):
    m = np.asarray(tz.tension_mask(design, rad(delta_deg), **kw))
    return tuple(int(k) + 1 for k in np.flatnonzero(m))


def test_three_wire_taut_sets_of_the_paper(d3):
    assert taut(d3, 0.0) == (1,)
    assert taut(d3, 66.0) == (1, 3)
    assert taut(d3, 90.0) == (3,)  # wire 1 on the boundary: zero moment arm, not taut
    assert taut(d3, 20.0) == (1,) and taut(d3, 40.0) == (1, 3)
    # one taut wire for |delta| < 30 deg, two in (30, 90) deg (tension_zones/MODEL.md Sec. 2)
    for dd in np.arange(-29.5, 30.0, 0.5):
        assert taut(d3, dd) == (1,)


def test_four_wire_taut_sets_of_the_paper(d4):
    for dd in np.arange(0.0, 360.0, 1.0):
        n = len(taut(d4, dd))
        assert n == (1 if dd % 90 == 0 else 2), dd


def test_boundary_rule_is_exact(d3):
    # cos(delta + alpha) within 1e-9 of zero is not in tension
    assert taut(d3, 90.0) == (3,)
    eps_deg = np.degrees(5e-10)
    assert 1 not in taut(d3, 90.0 - eps_deg)
    assert 1 in taut(d3, 90.0 - np.degrees(1e-8))


@pytest.mark.parametrize("n", [3, 4, 5, 6, 7, 8])
def test_sector_tables_even_layouts(n):
    d = tz.Design(n, 20.0, 2.0)
    tmap = tz.tension_map(d)
    # sectors tile [0, 360) in order
    assert tmap.sectors[0].start_deg == 0.0 and tmap.sectors[-1].end_deg == 360.0
    for a, b in zip(tmap.sectors, tmap.sectors[1:]):
        assert a.end_deg == pytest.approx(b.start_deg, abs=1e-9)
    # taut counts: n even -> n/2 everywhere but on wire lines (n/2 - 1 there... for n=4: 1);
    # n odd -> alternating (n-1)/2 and (n+1)/2 in sectors of 180/n deg
    widths = [s.width_deg for s in tmap.sectors if s.width_deg > 0]
    counts = [s.n_taut for s in tmap.sectors if s.width_deg > 0]
    if n % 2:
        assert set(counts) == {(n - 1) // 2, (n + 1) // 2}
        interior = widths[1:-1]  # the first and last split at 0 deg
        np.testing.assert_allclose(interior, 180.0 / n, atol=1e-9)
    else:
        assert set(counts) == {n // 2}
        points = [s for s in tmap.sectors if s.width_deg == 0]
        assert len(points) == n and all(s.n_taut == n // 2 - 1 for s in points)
    # the table agrees with the traced mask everywhere on a fine grid (and at every sector edge)
    grid = np.unique(np.concatenate([np.arange(0.0, 360.0, 0.1), [s.start_deg for s in tmap.sectors]]))
    masks = np.asarray(jax.vmap(lambda x: tz.tension_mask(d, x))(rad(grid)))
    for dd, m in zip(grid, masks):
        assert tmap.taut_at(dd) == tuple(np.flatnonzero(m) + 1), dd


def test_three_wire_table_matches_paper(d3):
    rows = [(s.start_deg, s.end_deg, s.wires) for s in tz.tension_map(d3).sectors]
    expect = [
        (0, 30, (1,)),
        (30, 90, (1, 3)),
        (90, 150, (3,)),
        (150, 210, (2, 3)),
        (210, 270, (2,)),
        (270, 330, (1, 2)),
        (330, 360, (1,)),
    ]
    assert len(rows) == len(expect)
    for (a, b, w), (ea, eb, ew) in zip(rows, expect):
        assert (a, b, w) == (pytest.approx(ea), pytest.approx(eb), ew)


def test_uneven_layout_table():
    d = tz.Design(4, 20.0, 2.0, wire_angles=rad([0.0, 80.0, 180.0, 260.0]))
    tmap = tz.tension_map(d)
    pts = [(s.start_deg, s.wires) for s in tmap.sectors if s.width_deg == 0]
    assert [p for p, _ in pts] == pytest.approx([10.0, 90.0, 190.0, 270.0])
    # a crowded layout leaves directions with no taut wire at all
    crowd = tz.Design(3, 20.0, 2.0, wire_angles=rad([0.0, 20.0, 40.0]))
    cm = tz.tension_map(crowd)
    assert any(s.n_taut == 0 for s in cm.sectors)
    assert cm.taut_at(0.0) == (1, 2, 3) and cm.taut_at(180.0) == () and cm.taut_at(60.0) == (1, 2)


@given(st.floats(-720, 720), st.floats(0, 360))
def test_periodicity_and_rotation_symmetry(delta_deg, shift_deg):
    d = tz.Design(5, 20.0, 2.0, wire_angles=rad([0.0, 50.0, 130.0, 200.0, 290.0]))
    m = tz.tension_mask(d, rad(delta_deg))
    np.testing.assert_array_equal(m, tz.tension_mask(d, rad(delta_deg) + 2 * np.pi * 3))
    # rotating every wire by +s and the bending direction by -s changes nothing (up to ties)
    rot = d.replace(wire_angles=d.wire_angles + rad(shift_deg))
    s_old = np.asarray(tz.tension_score(d, rad(delta_deg)))
    s_new = np.asarray(tz.tension_score(rot, rad(delta_deg - shift_deg)))
    np.testing.assert_allclose(s_old, s_new, atol=1e-12)


def test_phase_shift_for_a_moving_bending_plane(d3):
    theta_L = 1.0
    T = theta_L - np.pi / 2
    for psi_dot in ([-1.0, 0.0], [-1.0, 0.8], [-0.3, -1.0], [0.5, 0.2]):
        tmap = tz.tension_map(d3, theta_L=theta_L, psi_dot=psi_dot)
        gamma = np.degrees(np.arctan2(T * psi_dot[1], -psi_dot[0]))
        assert tmap.phase_deg == pytest.approx(gamma)
        for dd in np.arange(0.0, 360.0, 0.7):
            q_dot = np.asarray(tz.J_qpsi(d3, theta_L, rad(dd))) @ np.asarray(psi_dot)
            by_definition = tuple(np.flatnonzero(q_dot < -1e-9) + 1)  # Eq. 13: pulled wires
            assert taut(d3, dd, theta_L=theta_L, psi_dot=jnp.asarray(psi_dot)) == by_definition
            assert tmap.taut_at(dd) == by_definition
    with pytest.raises(ValueError, match="theta_L"):
        tz.tension_map(d3, psi_dot=[-1.0, 0.0])


def test_straight_through_mask_value_and_gradient(d3):
    def mask_sum(delta, angles):
        d = d3.replace(wire_angles=angles)
        return tz.tension_mask(d, delta)

    angles = d3.wire_angles
    for delta in rad([0.0, 25.0, 66.0, 89.0, 200.0]):
        hard = np.cos(delta + np.asarray(angles)) > 1e-9
        np.testing.assert_array_equal(mask_sum(delta, angles), hard.astype(float))
        g = jax.jacfwd(mask_sum, argnums=(0, 1))(delta, angles)
        score = np.cos(delta + np.asarray(angles))
        sig = 1 / (1 + np.exp(-score / tz.TEMPERATURE))
        dsoft = sig * (1 - sig) / tz.TEMPERATURE * -np.sin(delta + np.asarray(angles))
        np.testing.assert_allclose(g[0], dsoft, rtol=1e-10, atol=1e-300)
        np.testing.assert_allclose(g[1], np.diag(dsoft), rtol=1e-10, atol=1e-300)


def test_straight_through_helper_exact_forward():
    from tension_zones._numerics import straight_through

    soft = jnp.array([0.3, 0.7, 0.1 + 0.2, 1e-17])
    hard = jnp.array([1.0, 0.0, 1.0, 1.0])
    np.testing.assert_array_equal(straight_through(hard, soft), hard)
    g = jax.grad(lambda s: jnp.sum(straight_through(hard, s) * jnp.arange(4.0)))(soft)
    np.testing.assert_array_equal(g, jnp.arange(4.0))
    # forward mode and vmap carry the soft tangent too
    _, t = jax.jvp(lambda s: straight_through(hard, s), (soft,), (jnp.ones(4),))
    np.testing.assert_array_equal(t, jnp.ones(4))
    gv = jax.vmap(jax.grad(lambda s: straight_through(1.0, jnp.tanh(s))))(soft)
    np.testing.assert_allclose(gv, 1 - jnp.tanh(soft) ** 2, rtol=1e-15)


def test_straight_through_forward_never_evaluates_the_surrogate():
    """A program that is not differentiated drops the soft value (no exp per wire in a sweep)."""
    from tension_zones._numerics import straight_through

    fwd = jax.jit(lambda x: straight_through(x > 0, jax.nn.sigmoid(x / 0.05)))
    cost = fwd.lower(jnp.linspace(-1.0, 1.0, 64)).compile().cost_analysis()
    cost = cost[0] if isinstance(cost, list) else cost
    assert cost.get("transcendentals", 0.0) == 0.0


def test_reduced_jacobians(d3, d4):
    theta_L, delta = rad(40.0), rad(10.0)  # three wires: only wire 1 taut
    Jq = tz.reduced_J_qpsi(d3, theta_L, delta)
    assert np.count_nonzero(np.abs(np.asarray(Jq)).sum(axis=1)) == 1
    Jxq = np.asarray(tz.reduced_J_xq(d3, theta_L, delta))
    np.testing.assert_array_equal(Jxq[:, 1:], 0.0)
    assert np.linalg.matrix_rank(Jxq, tol=1e-9) == 1
    # the reduced Jacobian equals J_xpsi pinv(rows of the taut wires), columns re-inserted
    Jx, Jfull = (np.asarray(x) for x in tz.jacobians(d4, theta_L, rad(30.0)))
    rows = [0, 3]
    ref = np.zeros((6, 4))
    ref[:, rows] = Jx @ np.linalg.pinv(Jfull[rows])
    np.testing.assert_allclose(tz.reduced_J_xq(d4, theta_L, rad(30.0)), ref, atol=1e-12)
    assert np.linalg.matrix_rank(np.asarray(tz.J_xq(d4, theta_L, rad(30.0))), tol=1e-9) == 2


def test_whole_grid_is_one_jitted_vmap(d3):
    th = jnp.radians(jnp.arange(0.0, 90.0, 5.0))
    de = jnp.radians(jnp.arange(0.0, 362.5, 2.5))
    traces = []

    @jax.jit
    def grid(design, th, de):
        traces.append(1)
        return tz.over_grid(tz.reduced_J_xq)(design, th, de)

    J = grid(d3, th, de)
    grid(d3.replace(pitch_radius=3.0, wire_angles=d3.wire_angles + 0.1), th, de)
    assert len(traces) == 1 and J.shape == (18, 145, 6, 3)
    assert np.all(np.isfinite(J))
