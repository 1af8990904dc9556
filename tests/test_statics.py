"""Tension-only statics and compliance (tension_zones/MODEL.md Sec. 4-5): tension QP, stiffness, compliance."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

import tension_zones as tz
from tension_zones.model import _statics as S


def _design(n, **kw):
    kw = {"wire_stiffness": 75.0, "backbone_EI": 60.0, **kw}
    return tz.Design(n, 15.0, 1.6, **kw)


_pose = S.compliance_pose_jit
_comp = jax.jit(S.compliance)
_tens = jax.jit(S.tensions)
_Kpsi = jax.jit(S.stiffness_psi)


@jax.jit
def _solve(design, theta_L, delta, w):
    A, rhs = S.equilibrium_b(design, tz.psi_to_b(theta_L, delta), w)
    return A, rhs, S.min_norm_tensions(A, rhs, design.preload)


# ------------------------------------------------------------------------------ tension QP
@settings(max_examples=30, deadline=None)
@given(
    n=st.sampled_from([3, 4, 5]),
    theta_deg=st.floats(0.0, 90.0),
    delta_deg=st.floats(-180.0, 180.0),
    f=st.lists(st.floats(-10.0, 10.0), min_size=3, max_size=3),
    preload=st.sampled_from([0.0, 0.5, 5.0]),
)
def test_tension_qp_kkt(n, theta_deg, delta_deg, f, preload):
    d = _design(n, preload=preload)
    A, rhs, sol = _solve(d, np.radians(theta_deg), np.radians(delta_deg), jnp.asarray(f + [0, 0, 0]))
    A, rhs, tau, lam = (np.asarray(x) for x in (A, rhs, sol.tau, sol.lam))
    scale = np.linalg.norm(rhs) + np.linalg.norm(A) * max(tau.max(), preload) + 1e-300
    assert bool(sol.feasible)  # evenly spaced wires hold any pose
    assert float(sol.kkt_residual) < 1e-9
    assert np.linalg.norm(A @ tau - rhs) < 1e-9 * scale  # equilibrium
    assert np.all(tau >= preload - 1e-12 * scale)  # pull only, above the preload
    # stationarity + complementarity + dual feasibility: tau = max(f_min, A^T lam)
    assert np.max(np.abs(tau - np.maximum(preload, A.T @ lam))) < 1e-9 * max(tau.max(), 1.0)


def test_tension_qp_is_the_minimum_norm(d3):
    """Against scipy's SLSQP on the same QP."""
    from scipy.optimize import minimize

    d = _design(4, preload=1.0)
    A, rhs, sol = _solve(d, np.radians(60.0), np.radians(20.0), jnp.asarray([3.0, -1.0, 2.0, 0, 0, 0]))
    A, rhs = np.asarray(A), np.asarray(rhs)
    ref = minimize(
        lambda t: t @ t,
        np.full(4, 3.0),
        jac=lambda t: 2 * t,
        method="SLSQP",
        constraints=[{"type": "eq", "fun": lambda t: A @ t - rhs, "jac": lambda t: A}],
        bounds=[(1.0, None)] * 4,
        options={"ftol": 1e-14, "maxiter": 500},
    )
    np.testing.assert_allclose(np.asarray(sol.tau), ref.x, atol=1e-6)


def test_infeasible_pose_is_flagged_not_clipped():
    """Wires at 0, 40, 80 deg cannot pull the tip toward sigma = 200 deg (delta = -200 deg)."""
    d = tz.Design(3, 15.0, 1.6, wire_angles=np.radians([0.0, 40.0, 80.0]), backbone_EI=60.0)
    bad = _pose(d, np.radians(60.0), np.radians(-200.0), jnp.zeros(3))
    good = _pose(d, np.radians(60.0), np.radians(-40.0), jnp.zeros(3))
    assert not bool(bad["feasible"]) and bool(good["feasible"])
    assert np.all(np.isnan(np.asarray(bad["tensions"])))
    assert np.isnan(float(bad["deflection_mm_reduced"])) and np.isnan(float(bad["deflection_deg_full"]))
    assert np.isfinite(float(good["deflection_mm_reduced"]))


def test_taut_set_rule():
    d = _design(3)
    tau = jnp.asarray([2.0, 1e-7, 0.0])
    np.testing.assert_array_equal(np.asarray(S.taut_mask(d, tau)), [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(np.asarray(S.taut_mask(d.replace(preload=1.0), tau)), [1, 1, 1])
    np.testing.assert_array_equal(np.asarray(S.taut_mask(d, jnp.zeros(3))), [0, 0, 0])
    g = jax.grad(lambda t: jnp.sum(S.taut_mask(d, t) * jnp.arange(3.0)))(jnp.asarray([2.0, 1e-5, 0.0]))
    assert np.all(np.isfinite(np.asarray(g))) and float(g[1]) != 0.0  # straight-through surrogate


# ------------------------------------------------------------------------------ stiffness
@jax.jit
def _both_routes(d, th, de, w):
    """Compliance (full, reduced) via K_b and via the four-term K_psi, at one pose."""
    tau = S.tensions(d, th, de, w).tau
    mask = S.taut_mask(d, tau)
    Jx = tz.J_xpsi(d, th, de)
    out = []
    for m in (None, mask):
        C_b, ok = S.compliance(d, th, de, w, m)
        C_psi = Jx @ jnp.linalg.solve(S.stiffness_psi(d, th, de, w, tau, m), Jx.T)
        out.append((C_b, ok, C_psi))
    return out


@pytest.mark.parametrize("n", [3, 4])
def test_psi_and_b_routes_agree(n):
    """K_psi with its four terms gives the same compliance as the singularity-free K_b."""
    d = _design(n)
    for w in ([5.0, 0, 0, 0, 0, 0], [1.0, -2.0, 3.0, 4.0, -5.0, 6.0]):
        for th, de in [(50.0, 10.0), (75.0, 133.0), (88.0, 250.0)]:
            for C_b, ok, C_psi in _both_routes(d, np.radians(th), np.radians(de), jnp.asarray(w)):
                assert bool(ok)
                np.testing.assert_allclose(np.asarray(C_b), np.asarray(C_psi), rtol=1e-8, atol=1e-10)


@settings(max_examples=20, deadline=None)
@given(
    theta_deg=st.floats(1.0, 89.0),
    delta_deg=st.floats(0.0, 360.0),
    f=st.lists(st.floats(-10.0, 10.0), min_size=3, max_size=3),
)
def test_K_psi_symmetric_for_a_force(theta_deg, delta_deg, f):
    """Without a moment every term of K_psi is a Hessian (of U, tau.l, -f.p): symmetric."""
    d = _design(3)
    th, de, w = np.radians(theta_deg), np.radians(delta_deg), jnp.asarray(f)
    tau = _tens(d, th, de, w).tau
    K = np.asarray(_Kpsi(d, th, de, w, tau, S.taut_mask(d, tau)))
    assert abs(K[0, 1] - K[1, 0]) <= 1e-10 * np.abs(K).max()


def test_K_psi_not_symmetric_for_a_fixed_moment():
    """A moment fixed in the base frame is not conservative: theory gives no symmetry."""
    d = _design(3)
    w = jnp.asarray([0.0, 0.0, 0.0, 50.0, 0.0, 0.0])
    th, de = np.radians(60.0), np.radians(30.0)
    tau = _tens(d, th, de, w).tau
    K = np.asarray(_Kpsi(d, th, de, w, tau, None))
    assert abs(K[0, 1] - K[1, 0]) > 1e-3 * np.abs(K).max()


# ------------------------------------------------------------------------------ vs nonlinear
def _nonlinear_tip(d, q, f, b0, push_pull):
    """Minimise V(b) of tension_zones/MODEL.md Sec. 5 directly (Newton from b0); return (p, R, |grad V|) at b*."""
    L, k, fp = d.length, d.wire_stiffness, d.preload

    def V(b):
        s = (tz.wire_lengths_b(d, b) - L) - q + fp / k
        s = s if push_pull else jnp.maximum(s, 0.0)
        return d.backbone_EI * b @ b / (2 * L) + 0.5 * k * jnp.sum(s**2) - f @ tz.tip_pose_b(d, b)[0]

    g, H = jax.grad(V), jax.hessian(V)
    b = jax.lax.fori_loop(0, 30, lambda i, b: b - jnp.linalg.solve(H(b), g(b)), b0)
    return (*tz.tip_pose_b(d, b), jnp.linalg.norm(g(b)))


@jax.jit
def _fd_vs_compliance(d, th, de, f0, dw, eps):
    """(finite difference of the nonlinear tip pose, C_x dw) for pull-only and push-pull wires."""
    b0 = tz.psi_to_b(th, de)
    tau = S.tensions(d, th, de, f0).tau
    mask = S.taut_mask(d, tau)
    # actuator commands that hold b0 with these tensions (tension_zones/MODEL.md Sec. 5)
    q = (tz.wire_lengths_b(d, b0) - d.length) + d.preload / d.wire_stiffness - tau / d.wire_stiffness
    slack = jnp.where(mask > 0, 0.0, 0.02)  # pull-only: slack wires get 0.02 mm of slack
    out = []
    for push_pull, m in ((False, mask), (True, None)):
        qq = q if push_pull else q + slack
        (pp, Rp, gp), (pm, Rm, gm) = (_nonlinear_tip(d, qq, f0 + s * eps * dw, b0, push_pull) for s in (1.0, -1.0))
        W = (Rp - Rm) @ tz.tip_pose_b(d, b0)[1].T / (2 * eps)
        fd = jnp.concatenate([(pp - pm) / (2 * eps), jnp.array([W[2, 1], W[0, 2], W[1, 0]])])
        C, ok = S.compliance(d, th, de, f0, m)
        out.append((fd, C @ jnp.concatenate([dw, jnp.zeros(3)]), ok, jnp.maximum(gp, gm)))
    return out


@pytest.mark.parametrize("n,preload", [(3, 0.0), (4, 0.0), (3, 2.0)])
def test_compliance_matches_nonlinear_equilibrium(n, preload):
    """C_x dw against central differences of the pull-only energy minimum (tension_zones/MODEL.md Sec. 5);
    with push-pull wires (every wire a spring) against the traditional compliance."""
    d = _design(n, preload=preload)
    th, de = np.radians(65.0), np.radians(37.0)
    f0, dw = jnp.asarray([0.4, -0.2, 0.3]), jnp.asarray([0.3, 0.5, -0.2])
    for fd, pred, ok, grad_norm in _fd_vs_compliance(d, th, de, f0, dw, 1e-4):
        assert bool(ok) and float(grad_norm) < 1e-9  # converged equilibria
        np.testing.assert_allclose(np.asarray(fd[:3]), np.asarray(pred[:3]), rtol=1e-5, atol=1e-7)
        np.testing.assert_allclose(np.asarray(fd[3:]), np.asarray(pred[3:]), rtol=1e-5, atol=1e-9)


# ------------------------------------------------------------------------------ pose dict, grid
def test_preload_makes_reduced_equal_traditional():
    g = S.compliance_grid(_design(3, preload=5.0))
    assert np.all(g["n_taut_statics"] == 3) and np.all(g["feasible"])
    for q in ("mm", "deg"):
        np.testing.assert_allclose(g[f"deflection_{q}_reduced"], g[f"deflection_{q}_full"], rtol=1e-9, atol=0)
    g0 = S.compliance_grid(_design(3))
    assert np.all(g0["deflection_mm_reduced"] > 1.5 * g0["deflection_mm_full"])  # slack wires matter


def test_grid_shapes_and_no_recompile():
    d3 = _design(3)
    g = S.compliance_grid(d3)
    assert g["tensions"].shape == (10, 25, 3) and g["deflection_mm_full"].shape == (10, 25)
    assert g["n_taut_statics"].dtype.kind == "i" and g["feasible"].dtype == bool
    n0 = S.compliance_grid_jit._cache_size()
    S.compliance_grid(d3.replace(length=20.0, wire_stiffness=105.0, preload=5.0), wrench=[1.0, 2.0, 3.0])
    S.compliance_grid(d3.replace(backbone_EI=500.0), wrench=[1.0, 2.0, 3.0, 0.1, 0.2, 0.3])
    assert S.compliance_grid_jit._cache_size() == n0


def test_straight_pose_is_finite_with_finite_gradients():
    d = _design(3)

    def f(L, EI, th, w):
        dd = tz.Design(3, L, 1.6, backbone_EI=EI)
        out = S.compliance_pose(dd, th, 0.3, w)
        return out["deflection_mm_reduced"] + out["deflection_deg_full"] + jnp.sum(out["tensions"])

    # one directional derivative along (1, 1, 1): a NaN in any partial would propagate into it
    fg = jax.jit(lambda x, w: jax.jvp(lambda y: f(*y, w), (x,), (jnp.ones(3),)))
    for w in (jnp.asarray([5.0, 0.0, 0.0]), jnp.zeros(3)):  # loaded; unloaded (every wire slack)
        v, dv = fg(jnp.asarray([15.0, 60.0, np.pi / 2]), w)
        assert np.isfinite(float(v)) and np.isfinite(float(dv))
    out = _pose(d, np.pi / 2, 0.0, jnp.zeros(3))
    assert int(out["n_taut_statics"]) == 0 and float(out["deflection_mm_reduced"]) == 0.0


def test_bad_input_is_a_clear_error():
    d = _design(3)
    with pytest.raises(ValueError, match="3 .force. or 6"):
        S.compliance_grid(d, wrench=[1.0, 2.0])
    with pytest.raises(ValueError, match="finite"):
        S.as_wrench([1.0, np.nan, 0.0])
    with pytest.raises(ValueError, match="theta_L_deg"):
        S.compliance_grid(d, theta_L_deg=[[10.0]])
    with pytest.raises(ValueError, match="theta_L_deg"):
        S.compliance_grid(d, theta_L_deg=[95.0])


# ------------------------------------------------------------------------------ closed forms
@settings(max_examples=40, deadline=None)
@given(
    u=st.floats(-1.6, 1.6),
    v=st.floats(-1.6, 1.6),
    scale=st.sampled_from([1.0, 1e-3, 0.2, 0.24]),
    w=st.lists(st.floats(-10.0, 10.0), min_size=6, max_size=6),
)
def test_load_terms_equal_nested_autodiff(u, v, scale, w):
    """The closed-form d(J_xb^T w)/db (force and moment parts) against forward mode over J_xb."""
    d = _design(3)
    b, w = jnp.array([u, v]) * scale, jnp.asarray(w) * jnp.array([1, 1, 1, 20, 20, 20])
    Jx, load_geo = S._load_terms_b(d, b, w)
    ref = jax.jacfwd(lambda bb: tz.J_xb(d, bb).T @ w)(b)
    np.testing.assert_allclose(Jx, tz.J_xb(d, b), rtol=0, atol=1e-13)
    np.testing.assert_allclose(load_geo, ref, rtol=0, atol=1e-11 * (1 + float(jnp.abs(ref).max())))


def _qp_reference(A, rhs, f_min):
    """Independent: every subset by NumPy least squares, the KKT-consistent one (plain loops);
    returns the tensions and whether they meet the KKT conditions (the pose is feasible)."""
    n = A.shape[1]
    best = None
    for bits in range(2**n):
        free = np.array([(bits >> k) & 1 for k in range(n)], bool)
        r = rhs - f_min * A[:, ~free].sum(axis=1)
        tau = np.full(n, f_min)
        lam = np.zeros(2)
        if free.any():
            lam = np.linalg.lstsq(A[:, free] @ A[:, free].T, r, rcond=None)[0]
            tau[free] = A[:, free].T @ lam
        err = np.linalg.norm(A @ tau - rhs) + np.abs(tau - np.maximum(f_min, A.T @ lam)).max()
        if best is None or err < best[0]:
            best = (err, tau)
    err, tau = best
    scale = np.linalg.norm(rhs) + np.abs(A).max() * max(np.abs(tau).max(), f_min, 1e-300)
    return tau, bool(err <= 1e-9 * scale and tau.min() >= f_min - 1e-9 * scale)


@settings(max_examples=40, deadline=None)
@given(
    angles=st.lists(st.floats(0.0, 360.0), min_size=3, max_size=6),
    rhs=st.lists(
        st.floats(-20.0, 20.0).filter(lambda x: x == 0 or abs(x) > 1e-6),  # no underflow
        min_size=2,
        max_size=2,
    ),
    f_min=st.sampled_from([0.0, 0.5, 3.0]),
)
@example(angles=[0.0, 0.0, 1.192092896e-07], rhs=[-1.0, 0.0], f_min=0.0)  # found by CI on 2026-12-04
def test_tension_qp_matches_reference_for_any_layout(angles, rhs, f_min):
    """Uneven (and nearly coincident) wire layouts: the same tensions as the NumPy reference,
    wherever the pose is feasible. Where the free wires are nearly coincident (their ``A A^T``
    conditioned beyond 1e8) the min-norm tensions are not continuous in the data: three wires at 0, 0
    and 1.2e-7 deg pulling along x give (0.3125, 0.3125, 0) exactly (the third wire's y-component
    forbids it any tension) and the reference's least squares, which drops that component,
    (0.2083, 0.2083, 0.2083), 7e-10 off the balance. There both must balance the load and respect
    the minimum tension."""
    a = np.radians(np.asarray(angles))
    A = -1.6 * np.stack([np.cos(a), np.sin(a)])
    rhs = np.asarray(rhs)
    sol = jax.jit(S.min_norm_tensions)(A, rhs, f_min)
    ref, ref_ok = _qp_reference(A, rhs, f_min)
    if bool(sol.feasible) and ref_ok:
        scale = max(1.0, ref.max())
        free = ref > f_min + 1e-9 * scale
        if not free.any() or np.linalg.cond(A[:, free] @ A[:, free].T) < 1e8:
            np.testing.assert_allclose(sol.tau, ref, rtol=1e-7, atol=1e-7 * scale)
        else:
            tau = np.asarray(sol.tau)
            np.testing.assert_allclose(A @ tau, rhs, rtol=0, atol=1e-9 * (np.linalg.norm(rhs) + 1.6 * tau.max()))
            assert tau.min() >= f_min - 1e-9 * scale
    elif ref_ok and np.linalg.cond(A @ A.T) < 1e8:
        pytest.fail(f"feasible by the reference, flagged infeasible: {sol}")


# ------------------------------------------------------------------------------------------------
# Many wires: the free set among O(n^2) runs of wires instead of 2^n subsets
# ------------------------------------------------------------------------------------------------
_subsets_qp = jax.jit(jax.vmap(S.min_norm_tensions, in_axes=(None, 0, None)))


@settings(max_examples=15, deadline=None)
@given(
    n=st.sampled_from([5, 9]), even=st.booleans(), seed=st.integers(0, 2**16), f_min=st.sampled_from([0.0, 0.5, 5.0])
)
def test_runs_of_wires_give_the_same_tensions_as_all_subsets(n, even, seed, f_min):
    """The solution's free set is a run of wires consecutive in angle (A = J_qb^T): choosing among
    the runs gives the tensions, multipliers and feasibility of the 2^n-subset enumeration."""
    rng = np.random.default_rng(seed)
    a = np.arange(n) * 2 * np.pi / n if even else np.sort(rng.uniform(0.0, 2 * np.pi, n))
    A = jnp.asarray(-1.6 * np.stack([np.cos(a), np.sin(a)]))
    rhs = jnp.asarray(rng.normal(0.0, 10.0, (64, 2)) * rng.choice([1e-3, 1.0, 10.0], (64, 1)))
    subsets = _subsets_qp(A, rhs, f_min)
    runs = _runs_qp_jit(A, rhs, f_min)
    np.testing.assert_array_equal(np.asarray(runs.feasible), np.asarray(subsets.feasible))
    ok = np.asarray(subsets.feasible)
    scale = 1.0 + np.abs(np.asarray(subsets.tau)[ok])
    assert np.all(np.abs(np.asarray(runs.tau)[ok] - np.asarray(subsets.tau)[ok]) <= 1e-10 * scale)


def _runs_qp(A, rhs, f_min):
    """min_norm_tensions with the runs of wires whatever the wire count (set while tracing)."""
    saved = S.MAX_SUBSET_WIRES
    S.MAX_SUBSET_WIRES = 0
    try:
        return S.min_norm_tensions(A, rhs, f_min)
    finally:
        S.MAX_SUBSET_WIRES = saved


_runs_qp_jit = jax.jit(jax.vmap(_runs_qp, in_axes=(None, 0, None)))


@pytest.mark.parametrize("n, preload", [(16, 0.0), (32, 2.0), (64, 0.0)])
def test_many_wires_hold_every_pose_by_pulling(n, preload):
    """Evenly spaced wires hold any pose: feasible, KKT to 1e-9, equilibrium, pull only."""
    d = _design(n, preload=preload)
    rng = np.random.default_rng(n)
    th, de = rng.uniform(0.0, np.pi / 2, 40), rng.uniform(-np.pi, np.pi, 40)
    w = jnp.asarray([3.0, -2.0, 1.0, 0.0, 0.0, 0.0])
    A, rhs, sol = jax.vmap(lambda t, e: _solve(d, t, e, w))(jnp.asarray(th), jnp.asarray(de))
    assert np.all(np.asarray(sol.feasible)) and float(jnp.max(sol.kkt_residual)) < 1e-9
    tau = np.asarray(sol.tau)
    assert np.all(tau >= preload - 1e-9)
    np.testing.assert_allclose(np.einsum("pij,pj->pi", np.asarray(A), tau), np.asarray(rhs), atol=1e-8)
    out = _pose(d, 0.9, 0.3, w)
    assert bool(out["feasible"]) and np.isfinite(float(out["deflection_mm_reduced"]))
