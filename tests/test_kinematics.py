"""Kinematics against autodiff, finite differences and an integrated wire path (tension_zones/MODEL.md Sec. 1, 5)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import omega_jacobian
from hypothesis import given, settings
from hypothesis import strategies as st

import tension_zones as tz

STRAIGHT = np.pi / 2
POSES = [
    (STRAIGHT, 0.3),
    (STRAIGHT - 1e-7, 1.2),
    (STRAIGHT - 1e-3, -2.0),
    (STRAIGHT + 1e-4, 0.7),
    (1.0, 0.3),
    (0.2, 4.0),
    (np.radians(5.0), np.radians(187.5)),
]


def _design(n=3, angles=None):
    return tz.Design(n, 20.0, 2.0, wire_angles=angles)


def autodiff_twist_jacobian(design, theta_L, delta):
    psi = jnp.array([theta_L, delta])
    Jv = jax.jacfwd(lambda x: tz.tip_pose(design, x[0], x[1])[0])(psi)
    Jw = omega_jacobian(lambda x: tz.tip_pose(design, x[0], x[1])[1], psi)
    return np.vstack([Jv, Jw])


@pytest.mark.parametrize("theta_L, delta", POSES)
def test_J_xpsi_matches_jacfwd(theta_L, delta):
    d = _design()
    np.testing.assert_allclose(tz.J_xpsi(d, theta_L, delta), autodiff_twist_jacobian(d, theta_L, delta), atol=1e-12)


@given(st.floats(0.0, np.pi / 2), st.floats(-2 * np.pi, 2 * np.pi))
def test_J_xpsi_matches_finite_differences(theta_L, delta):
    d = _design()
    h = 1e-6
    p = lambda t, dd: np.asarray(tz.tip_pose(d, t, dd)[0])
    fd = np.stack(
        [
            (p(theta_L + h, delta) - p(theta_L - h, delta)) / (2 * h),
            (p(theta_L, delta + h) - p(theta_L, delta - h)) / (2 * h),
        ],
        axis=1,
    )
    np.testing.assert_allclose(tz.J_xpsi(d, theta_L, delta)[:3], fd, atol=1e-7)


def test_tip_pose_formula_and_rotation():
    d = _design()
    phi, delta = 0.8, 0.4
    p, R = tz.tip_pose(d, np.pi / 2 - phi, delta)
    L = 20.0
    expect = (L / phi) * np.array([np.cos(delta) * (1 - np.cos(phi)), -np.sin(delta) * (1 - np.cos(phi)), np.sin(phi)])
    np.testing.assert_allclose(p, expect, rtol=1e-13)

    def Rz(a):
        return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])

    def Ry(a):
        return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])

    np.testing.assert_allclose(R, Rz(-delta) @ Ry(phi) @ Rz(delta), atol=1e-14)
    # the tip tangent R[:, 2] is the curve's tangent dp/ds at s = L
    np.testing.assert_allclose(
        R[:, 2], [np.cos(delta) * np.sin(phi), -np.sin(delta) * np.sin(phi), np.cos(phi)], atol=1e-14
    )


def test_straight_pose_values():
    d = _design()
    p, R = tz.tip_pose(d, STRAIGHT, 1.234)
    np.testing.assert_allclose(p, [0, 0, 20.0], atol=1e-15)
    np.testing.assert_allclose(R, np.eye(3), atol=1e-15)


@pytest.mark.parametrize("n", [3, 4, 7])
@pytest.mark.parametrize("theta_L, delta", POSES)
def test_J_qpsi_is_derivative_of_wire_lengths(n, theta_L, delta):
    d = _design(n)
    J = jax.jacfwd(lambda x: tz.wire_lengths(d, x[0], x[1]))(jnp.array([theta_L, delta]))
    np.testing.assert_allclose(tz.J_qpsi(d, theta_L, delta), J, atol=1e-13)


def _integrated_wire_length(design, b, k, n_pts=4001):
    """Length of wire k's path: the backbone at arc length s plus R(s) times the wire's offset."""
    L = float(design.length)
    s = np.linspace(0.0, L, n_pts)
    a = float(design.wire_angles[k])
    offset = float(design.pitch_radius) * np.array([np.cos(a), np.sin(a), 0.0])

    def point(si):
        # a segment of length si with the same curvature: bending vector scaled by si / L
        sub = design.replace(length=jnp.maximum(si, 1e-12))
        p, R = tz.tip_pose_b(sub, jnp.asarray(b) * si / L)
        return p * (si > 0) + R @ offset

    pts = np.asarray(jax.jit(jax.vmap(point))(jnp.asarray(s)))
    return float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))


@pytest.mark.parametrize("b", [(0.9, 0.0), (-0.3, 0.7), (0.05, -1.1)])
def test_wire_lengths_match_integrated_path(b):
    d = _design(4, np.radians([10.0, 95.0, 190.0, 300.0]))
    lengths = np.asarray(tz.wire_lengths_b(d, jnp.array(b)))
    for k in range(4):
        # chord sums under-estimate an arc by ~ L kappa^2 h^2 / 24: far below 1e-5 mm here
        assert abs(_integrated_wire_length(d, b, k) - lengths[k]) < 1e-5
    th, de = tz.b_to_psi(jnp.array(b))
    np.testing.assert_allclose(tz.wire_lengths(d, th, de), lengths, atol=1e-12)


@given(st.floats(-2.5, 2.5), st.floats(-2.5, 2.5))
def test_b_and_psi_agree(u, v):
    d = _design(5)
    b = jnp.array([u, v])
    th, de = tz.b_to_psi(b)
    np.testing.assert_allclose(tz.psi_to_b(th, de), b, atol=1e-12)
    pb, Rb = tz.tip_pose_b(d, b)
    pp, Rp = tz.tip_pose(d, th, de)
    np.testing.assert_allclose(pb, pp, atol=1e-12)
    np.testing.assert_allclose(Rb, Rp, atol=1e-12)
    np.testing.assert_allclose(tz.J_qb(d) @ b, tz.wire_lengths_b(d, b) - 20.0, atol=1e-12)


@pytest.mark.parametrize("b", [(0.0, 0.0), (1e-9, -2e-9), (0.3, -0.2), (1.5, 0.4)])
def test_J_xb_matches_chain_rule_and_is_finite(b):
    d = _design()
    b = jnp.array(b, dtype=float)
    J = np.asarray(tz.J_xb(d, b))
    assert np.all(np.isfinite(J))
    h = 1e-6
    p = lambda bb: np.asarray(tz.tip_pose_b(d, bb)[0])
    fd = np.stack([(p(b + h * e) - p(b - h * e)) / (2 * h) for e in np.eye(2)], axis=1)
    np.testing.assert_allclose(J[:3], fd, atol=1e-7)
    if float(jnp.linalg.norm(b)) == 0.0:
        # straight: bending by b_dot tilts the tip about (-v_dot, u_dot, 0)
        np.testing.assert_allclose(J[3:], [[0, -1], [1, 0], [0, 0]], atol=1e-14)
        np.testing.assert_allclose(J[:3], [[10.0, 0], [0, 10.0], [0, 0]], atol=1e-12)


def test_no_nan_at_the_straight_pose():
    """Values and gradients at theta_L = pi/2 and b = 0 are finite (no input nudging)."""
    d = _design(4)

    def everything(x):
        th, de = x[0], x[1]
        p, R = tz.tip_pose(d, th, de)
        mask = tz.tension_mask(d, de)
        parts = [
            p,
            R.ravel(),
            tz.J_xpsi(d, th, de).ravel(),
            tz.J_qpsi(d, th, de).ravel(),
            tz.J_xq(d, th, de).ravel(),
            tz.J_xq(d, th, de, mask).ravel(),
            tz.reduced_J_xq(d, th, de).ravel(),
            tz.wire_lengths(d, th, de),
            tz.tension_score(d, de, th, jnp.array([-1.0, 0.3])),
        ]
        return jnp.concatenate(parts)

    everything = jax.jit(everything)
    x = jnp.array([np.pi / 2, 0.4])
    assert np.all(np.isfinite(everything(x)))
    assert np.all(np.isfinite(jax.jit(jax.jacfwd(everything))(x)))
    assert np.all(np.isfinite(jax.jit(jax.jacrev(everything))(x)))
    # second derivatives (the stiffness of the statics differentiates the Jacobians again)
    second = jax.jit(
        jax.hessian(
            lambda x: jnp.sum(tz.J_xpsi(d, x[0], x[1])) + jnp.sum(tz.J_xq(d, x[0], x[1], tz.tension_mask(d, x[1])))
        )
    )
    assert np.all(np.isfinite(second(x)))

    def in_b(b):
        p, R = tz.tip_pose_b(d, b)
        return jnp.concatenate([p, R.ravel(), tz.J_xb(d, b).ravel(), jnp.stack(tz.b_to_psi(b))])

    b0 = jnp.zeros(2)
    assert np.all(np.isfinite(in_b(b0)))
    assert np.all(np.isfinite(jax.jacfwd(in_b)(b0)))
    assert np.all(np.isfinite(jax.hessian(lambda b: tz.tip_pose_b(d, b)[0].sum())(b0)))
    # the curvature of z(b) at straight is -L/6 * 2 per axis: check a second derivative's value
    H = jax.hessian(lambda b: tz.tip_pose_b(d, b)[0][2])(b0)
    np.testing.assert_allclose(H, -20.0 / 3.0 * np.eye(2), atol=1e-12)


def test_series_branches_agree_with_closed_form():
    from tension_zones import _numerics as nm

    for x in [0.05, 0.2, 0.23, 0.25, 0.5]:
        x2 = x * x
        np.testing.assert_allclose(nm.sinc_sq(x2), np.sin(x) / x, rtol=1e-13)
        np.testing.assert_allclose(nm.versinc_sq(x2), (1 - np.cos(x)) / x**2, rtol=1e-12)
        exact = float((np.float64(x) * np.cos(x) - np.sin(x)) / x**3)
        np.testing.assert_allclose(nm.cubic_sq(x2), exact, rtol=1e-9)


def test_pinv_tall2_matches_numpy(rng):
    from tension_zones._numerics import pinv_tall2

    for n in (3, 4, 8):
        for _ in range(20):
            J = rng.normal(size=(n, 2))
            mask = rng.integers(0, 2, size=n)
            Jm = J * mask[:, None]
            np.testing.assert_allclose(pinv_tall2(jnp.asarray(Jm)), np.linalg.pinv(Jm), rtol=1e-10, atol=1e-12)
    # exact rank one: one non-zero row
    J = np.zeros((4, 2))
    J[2] = [0.3, -1.2]
    np.testing.assert_allclose(pinv_tall2(jnp.asarray(J)), np.linalg.pinv(J), atol=1e-15)
    np.testing.assert_array_equal(pinv_tall2(jnp.zeros((3, 2))), np.zeros((2, 3)))


def test_over_grid_shapes():
    d = _design(4)
    th = jnp.radians(jnp.arange(0.0, 90.0, 5.0))
    de = jnp.radians(jnp.arange(0.0, 362.5, 2.5))
    J = jax.jit(tz.over_grid(tz.J_xq))(d, th, de)
    assert J.shape == (18, 145, 6, 4)
    np.testing.assert_allclose(J[3, 7], tz.J_xq(d, th[3], de[7]), atol=1e-13)


def _J_xb_by_autodiff(d, b):
    """Independent reference: forward-mode derivative of the Rodrigues tip pose, omega = vee(R_dot R^T)."""
    p_of = lambda bb: tz.tip_pose_b(d, bb)[0]
    R_of = lambda bb: tz.tip_pose_b(d, bb)[1]
    dp = jax.jacfwd(p_of)(b)
    dR = jax.jacfwd(R_of)(b)  # (3, 3, 2)
    W = jnp.einsum("ijk,lj->kil", dR, R_of(b))
    omega = jnp.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=0)
    return jnp.concatenate([dp, omega], axis=0)


@pytest.mark.parametrize("x", [0.0, 1e-9, -0.05, 0.2, 0.23, 0.24, -0.7, 1.5, 3.0])
def test_series_from_sin_and_cos_equal_the_series_functions(x):
    """``sinc_versinc_cubic`` (from a sine and cosine the caller has) equals ``sinc_sq``, ``versinc_sq``
    and ``cubic_sq`` on both sides of the series switch (|x| ~ 0.23), and so do its gradients,
    finite at 0."""
    from tension_zones import _numerics as nm

    def mine(x):
        return jnp.stack(nm.sinc_versinc_cubic(x, jnp.sin(x), jnp.cos(x)))

    def ref(x):
        return jnp.stack([f(x * x) for f in (nm.sinc_sq, nm.versinc_sq, nm.cubic_sq)])

    x = jnp.float64(x)
    np.testing.assert_allclose(mine(x), ref(x), rtol=1e-12, atol=1e-300)
    g, g_ref = jax.jacfwd(mine)(x), jax.jacfwd(ref)(x)
    assert np.all(np.isfinite(g))
    np.testing.assert_allclose(g, g_ref, rtol=1e-9, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(u=st.floats(-2.5, 2.5), v=st.floats(-2.5, 2.5), scale=st.sampled_from([1.0, 1e-3, 0.2, 0.24]))
def test_closed_form_J_xb_equals_autodiff(u, v, scale):
    """The closed-form J_xb (left Jacobian of SO(3)) against differentiating the tip pose; the
    scales put b inside, at and just outside the series range (|b| < 0.23)."""
    d = _design()
    b = jnp.array([u, v]) * scale
    np.testing.assert_allclose(tz.J_xb(d, b), _J_xb_by_autodiff(d, b), rtol=0, atol=2e-13)


def test_series_derivatives_match_closed_forms_at_the_switch():
    """First and second x2-derivatives of the series functions agree across the series/closed switch."""
    from tension_zones import _numerics as nm

    thr = nm._series_threshold(jnp.float64(1.0))  # x2 < thr: series; one ulp apart on either side
    for f in (nm.sinc_sq, nm.versinc_sq, nm.cubic_sq, nm.sinc_comp_sq):
        lo = nm.with_derivatives(f, jnp.float64(np.nextafter(thr, 0.0)), order=2)
        hi = nm.with_derivatives(f, jnp.float64(np.nextafter(thr, 1.0)), order=2)
        for a, b, tol in zip(lo, hi, (1e-13, 1e-11, 1e-9)):
            assert abs(float(a) - float(b)) <= tol * max(abs(float(a)), 1e-3), (f.__name__, a, b)
