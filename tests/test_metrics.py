"""Performance measures (tension_zones/MODEL.md Sec. 3; paper Secs. 4, 6.1) against an independent NumPy reference.

The reference below is written from tension_zones/MODEL.md alone: its own J_xpsi and J_qpsi, the taut rows by the
boundary rule, ``numpy.linalg.pinv`` of the taut rows only, ``numpy.linalg.svd``, and the paper's
literal ``Q`` matrix with all ``3^n`` columns (Eqs. 17-19).
"""

import functools
import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

import tension_zones as tz
from tension_zones.analysis._metrics import MEASURES, pose_measures, pose_metrics, zonogon_vertices
from tension_zones.analysis._sweep import grid_deg, sweep_grid

rad = np.radians
TH = rad(grid_deg(85, 5))
DE = rad(grid_deg(360, 2.5))


# ------------------------------------------------------------------------------------------------
# Independent reference (NumPy, one pose)
# ------------------------------------------------------------------------------------------------
def ref_measures(L, r, alpha, theta_L, delta, dq, reduced):
    T = theta_L - np.pi / 2
    s, c = np.sin(theta_L), np.cos(theta_L)
    A = T * c - s + 1
    sd, cd = np.sin(delta), np.cos(delta)
    Jv = L * np.array(
        [[cd * A / T**2, -sd * (s - 1) / T], [-sd * A / T**2, -cd * (s - 1) / T], [(T * s + c) / T**2, 0.0]]
    )
    Jw = np.array([[-sd, cd * c], [-cd, -sd * c], [0.0, -1.0 + s]])
    dk = delta + np.asarray(alpha)
    n = dk.size
    Jq = r * np.stack([np.cos(dk), -T * np.sin(dk)], axis=1)
    keep = np.cos(dk) > 1e-9 if reduced else np.ones(n, bool)  # tension_zones/MODEL.md Sec. 2 boundary rule
    P = np.linalg.pinv(Jq[keep]) if keep.any() else np.zeros((2, 0))
    out = {}
    for part, J in (("v", Jv), ("w", Jw)):
        S = np.zeros(2)
        if keep.any():
            sv = np.linalg.svd(J @ P, compute_uv=False)
            S[: min(2, sv.size)] = sv[:2]
        rank = int(np.sum(S > S[0] * max(3, n) * np.finfo(float).eps)) if S[0] > 0 else 0
        out[f"kci_{part}"] = S[1] / S[0] if S[0] > 0 else 0.0
        out[f"sigma_min_{part}"] = S[1] if rank == 2 else 0.0
        out[f"sigma_min_nz_{part}"] = S[1] if rank == 2 else S[0]
    Q = np.array(list(itertools.product([-1.0, 0.0, 1.0], repeat=n))).T * dq  # (n, 3^n), Eq. 17
    dx = np.vstack([Jv, Jw]) @ P @ Q[keep]  # Eq. 18, Q~ = the taut wires' rows
    out["dp_max"] = np.linalg.norm(dx[:3], axis=0).max()  # Eq. 19
    out["dw_max"] = np.linalg.norm(dx[3:], axis=0).max()
    out["n_taut"] = int(np.sum(np.cos(dk) > 1e-9))
    return out


SCALE = {"kci_v": 1.0, "kci_w": 1.0}  # KCI is compared absolutely (it is a ratio in [0, 1])


def assert_matches_reference(res, design, i, j, dq, rtol=1e-9):
    """Every array of a sweep at grid point (i, j) against the reference, 1e-9 relative."""
    alpha = np.asarray(design.wire_angles)
    L, r = float(design.length), float(design.pitch_radius)
    for mode in ("full", "reduced"):
        ref = ref_measures(L, r, alpha, TH[i], DE[j], dq, mode == "reduced")
        assert int(res["n_taut"][i, j]) == ref["n_taut"]
        for k in MEASURES:
            got, want = float(res[f"{k}_{mode}"][i, j]), ref[k]
            # relative to the value, or to the largest singular value for a zero sigma_2 (NumPy
            # returns ~1e-17 where the closed form gives exactly 0)
            scale = max(
                abs(want), SCALE.get(k, 0.0), ref[f"sigma_min_nz_{k[-1]}"] if k.startswith("sigma_min_") else 0.0
            )
            assert abs(got - want) <= rtol * scale, (mode, k, got, want, np.degrees(DE[j]))


@functools.cache
def paper_sweep(n, angles_deg=None, dq=0.4):
    angles = None if angles_deg is None else rad(angles_deg)
    d = tz.Design(n, 20.0, 2.0, wire_angles=angles)
    return d, sweep_grid(pose_metrics, d, TH, DE, dq, quiet=True)


# ------------------------------------------------------------------------------------------------
# Agreement with the reference
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [3, 4, 5, 6, 7, 8])
def test_every_array_matches_reference_at_random_grid_points(n):
    d, res = paper_sweep(n)
    rng = np.random.default_rng(n)
    npts = 12 if n <= 6 else 5  # 3^8 columns per point for eight wires
    for i, j in zip(rng.integers(0, TH.size, npts), rng.integers(0, DE.size, npts)):
        assert_matches_reference(res, d, i, j, 0.4)
    assert all(np.all(np.isfinite(v)) for v in res.values())


@pytest.mark.parametrize(
    "angles", [(0.0, 80.0, 180.0, 260.0), (0.0, 50.0, 130.0, 200.0, 290.0), (10.0, 100.0, 250.0), (0.0, 20.0, 40.0)]
)
def test_uneven_angles_match_reference(angles):
    d, res = paper_sweep(len(angles), angles)
    rng = np.random.default_rng(len(angles))
    for i, j in zip(rng.integers(0, TH.size, 10), rng.integers(0, DE.size, 10)):
        assert_matches_reference(res, d, i, j, 0.4)
    # the uneven four-wire layout has one taut wire only on its zone ends 10, 90, 190, 270 deg
    if angles == (0.0, 80.0, 180.0, 260.0):
        deg = np.degrees(DE)
        one = np.isin(np.round(deg, 6), [10.0, 90.0, 190.0, 270.0])
        assert np.all(res["n_taut"][:, one] == 1) and np.all(res["n_taut"][:, ~one] == 2)
    # a crowded layout leaves directions with no taut wire: zeros, not NaNs
    if angles == (0.0, 20.0, 40.0):
        j = int(np.argmin(np.abs(np.degrees(DE) - 180.0)))
        assert np.all(res["n_taut"][:, j] == 0)
        for k in MEASURES:
            assert np.all(res[f"{k}_reduced"][:, j] == 0.0)
            assert_matches_reference(res, d, 5, j, 0.4)


def test_boundary_directions_follow_the_model_rule():
    """A wire exactly on the bending axis (|cos delta_k| <= 1e-9) is not taut (tension_zones/MODEL.md Sec. 2)."""
    d, res = paper_sweep(3)
    deg = np.degrees(DE)
    for b in (30.0, 90.0, 150.0, 210.0, 270.0, 330.0):
        j = int(np.argmin(np.abs(deg - b)))
        assert np.all(res["n_taut"][:, j] == 1), b  # the wire on the boundary is slack
        for i in (0, 7, 17):
            assert_matches_reference(res, d, i, j, 0.4)
        # one taut wire: rank one, sigma_2 = 0 and KCI = 0 exactly
        for k in ("kci_v", "kci_w", "sigma_min_v", "sigma_min_w"):
            assert np.all(res[f"{k}_reduced"][:, j] == 0.0)
    d4, res4 = paper_sweep(4)
    for b in (0.0, 90.0, 180.0, 270.0, 360.0):
        j = int(np.argmin(np.abs(deg - b)))
        assert np.all(res4["n_taut"][:, j] == 1)
        assert_matches_reference(res4, d4, 9, j, 0.4)


def test_three_wire_zone_structure_and_ratios():
    _d, res = paper_sweep(3)
    deg = np.degrees(DE)
    m = deg % 120.0  # one taut wire in (-30, 30) + 120 k, and on every zone end 30 + 60 k
    one = (m < 30.0) | (m > 90.0) | np.isclose(deg % 60.0, 30.0)
    assert np.all((res["n_taut"] == 1) == one[None, :])
    assert np.all(res["n_taut"][:, ~one] == 2)
    # "the traditional approach underestimates the position uncertainty by as much as 50%"
    ratio = res["dp_max_reduced"] / res["dp_max_full"]
    assert ratio.max() == pytest.approx(1.5, rel=1e-9)
    # traditional KCI overestimates (paper conclusion (1)): never below the reduced KCI here
    assert np.all(res["kci_v_full"] >= res["kci_v_reduced"] - 1e-12)


# ------------------------------------------------------------------------------------------------
# Invariants and properties
# ------------------------------------------------------------------------------------------------
@jax.jit
def _measures(d, theta_L, delta, dq, mask):
    """One compiled pose_measures for every property test; an all-ones mask is the full Jacobian."""
    return pose_measures(d, theta_L, delta, dq, mask)


def _measures3(d, theta_L, delta, dq, reduced):
    mask = tz.tension_mask(d, delta) if reduced else jnp.ones(d.n_wires)
    return _measures(d, theta_L, delta, dq, mask)


@given(st.floats(0.0, 1.5), st.floats(0.0, 2 * np.pi), st.floats(0.01, 5.0), st.floats(0.1, 20.0), st.booleans())
def test_bounds_are_linear_in_dq(theta_L, delta, dq, k, reduced):
    d = tz.Design(3, 20.0, 2.0)
    a = _measures3(d, theta_L, delta, dq, reduced)
    b = _measures3(d, theta_L, delta, k * dq, reduced)
    for key in ("dp_max", "dw_max"):
        assert float(b[key]) == pytest.approx(k * float(a[key]), rel=1e-12)
    for key in ("kci_v", "kci_w", "sigma_min_v", "sigma_min_w"):  # independent of dq
        assert float(b[key]) == float(a[key])


@given(st.floats(0.0, 1.5), st.floats(0.0, 2 * np.pi), st.floats(1.0, 100.0), st.floats(0.2, 10.0))
def test_scaling_in_length_and_pitch_radius(theta_L, delta, L, r):
    """dp ~ L/r, dw ~ 1/r, sigma_v ~ L/r, sigma_w ~ 1/r, KCI scale-free."""
    assume(r <= L / 2)  # a larger pitch radius is refused (Design: MAX_RADIUS_PER_LENGTH)
    d0 = tz.Design(3, 20.0, 2.0)
    a = _measures3(d0, theta_L, delta, 0.4, True)
    b = _measures3(d0.replace(length=L, pitch_radius=r), theta_L, delta, 0.4, True)
    f_v, f_w = (L / 20.0) / (r / 2.0), 1.0 / (r / 2.0)
    for key, f in (
        ("dp_max", f_v),
        ("sigma_min_v", f_v),
        ("sigma_min_nz_v", f_v),
        ("dw_max", f_w),
        ("sigma_min_w", f_w),
        ("kci_v", 1.0),
        ("kci_w", 1.0),
    ):
        assert float(b[key]) == pytest.approx(f * float(a[key]), rel=1e-10, abs=1e-14)
    for key in ("kci_v", "kci_w"):
        assert 0.0 <= float(a[key]) <= 1.0


@given(
    st.lists(st.floats(0.0, 359.0), min_size=3, max_size=3),
    st.floats(0.0, 1.48),
    st.floats(0.0, 2 * np.pi),
    st.floats(0.05, 2.0),
)
def test_any_three_wire_layout_matches_reference(angles_deg, theta_L, delta, dq):
    """Property test over the space of three-wire layouts and poses (reduced and full)."""
    a = np.sort(np.asarray(angles_deg))
    gaps = np.diff(np.concatenate([a, [a[0] + 360.0]]))
    assume(gaps.min() > 1.0)
    d = tz.Design(3, 20.0, 2.0, wire_angles=rad(a))
    for reduced in (False, True):
        got = _measures3(d, theta_L, delta, dq, reduced)
        ref = ref_measures(20.0, 2.0, rad(a), theta_L, delta, dq, reduced)
        for k in MEASURES:
            scale = max(
                abs(ref[k]),
                1.0 if k.startswith("kci") else 0.0,
                ref[f"sigma_min_nz_{k[-1]}"] if k.startswith("sigma_min_") else 0.0,
            )
            assert abs(float(got[k]) - ref[k]) <= 1e-9 * scale, (k, reduced)


_zonogon = jax.jit(zonogon_vertices)


# XLA on CPU flushes subnormals to zero, so keep products of components normal (|x| > 1e-100 or 0)
_comp = st.floats(-3, 3).filter(lambda x: x == 0.0 or abs(x) > 1e-100)


@given(st.lists(st.tuples(_comp, _comp), min_size=1, max_size=8), st.sampled_from(["generic", "parallel", "zeros"]))
def test_zonogon_vertices_equal_the_sign_vector_maximum(cols, kind):
    G = np.zeros((2, 8))  # eight generators, the unused ones zero (slack wires)
    G[:, : len(cols)] = np.array(cols, dtype=float).T
    if kind == "parallel":
        G = np.outer([0.6, -0.8], G[0])  # all generators on one line (the straight pose)
    elif kind == "zeros":
        G[:, ::2] = 0.0
    n = G.shape[1]
    signs = np.array(list(itertools.product([-1.0, 1.0], repeat=n)))
    M = np.array([[1.0, 0.3], [-0.2, 2.0], [0.5, 0.0]])
    brute = np.linalg.norm(signs @ G.T @ M.T, axis=1).max()
    V = np.asarray(_zonogon(G))
    assert V.shape == (2 * n, 2)
    assert np.linalg.norm(V @ M.T, axis=1).max() == pytest.approx(brute, rel=1e-12, abs=1e-300)


@given(st.floats(0.0, 1.5), st.floats(0.0, 2 * np.pi))
def test_one_taut_wire_is_rank_one(theta_L, delta):
    """Only wire 1 taut: sigma_2 = 0 and KCI = 0 exactly; sigma_min_nz is the one non-zero value."""
    d = tz.Design(3, 20.0, 2.0)
    m = _mask_one(d)
    out = _measures(d, theta_L, delta, 0.4, m)
    for k in ("kci_v", "kci_w", "sigma_min_v", "sigma_min_w"):
        assert float(out[k]) == 0.0
    Jx = np.asarray(tz.J_xpsi(d, theta_L, delta))
    row = np.asarray(tz.J_qpsi(d, theta_L, delta))[0]
    col = row / (row @ row)  # pinv of one row
    for part, sl in (("v", slice(0, 3)), ("w", slice(3, 6))):
        g = np.linalg.norm(Jx[sl] @ col)
        assert float(out[f"sigma_min_nz_{part}"]) == pytest.approx(g, rel=1e-12)
    assert float(out["dp_max"]) == pytest.approx(0.4 * np.linalg.norm(Jx[:3] @ col), rel=1e-12)


def _mask_one(d):
    return jnp.zeros(d.n_wires).at[0].set(1.0)


_NAMES = [f"{k}_{mode}" for mode in ("full", "reduced") for k in MEASURES]


def _stacked(theta_L, delta, r, angles, L):
    d = tz.Design(4, 20.0, 2.0).replace(pitch_radius=r, wire_angles=angles, length=L)
    out = pose_metrics(d, theta_L, delta)
    return jnp.stack([out[k] for k in _NAMES])


_stacked_jit = jax.jit(_stacked)
# values and the gradient of their sum w.r.t. every input: a NaN in any output's derivative
# propagates into it. One compiled function for both tests below (arguments always float64 arrays).
_value_and_grad = jax.jit(jax.value_and_grad(lambda *a: jnp.sum(_stacked(*a)), argnums=(0, 1, 2, 3, 4)))


def _call(theta_L, delta, r=2.0, L=20.0):
    angles = tz.Design(4, 20.0, 2.0).wire_angles
    args = tuple(jnp.asarray(x, jnp.float64) for x in (theta_L, delta, r, angles, L))
    return _value_and_grad(*args), _stacked_jit(*args)


def test_straight_pose_values_and_gradients_are_finite():
    for delta in (0.0, 0.3, np.pi / 4):
        (val, grads), vals = _call(np.pi / 2, delta)
        assert np.isfinite(float(val)) and np.all(np.isfinite(np.asarray(vals)))
        for g in jax.tree_util.tree_leaves(grads):
            assert np.all(np.isfinite(np.asarray(g)))


@pytest.mark.parametrize("delta_deg", [66.0, 90.0, 200.0])
def test_gradients_match_the_scaling_laws(delta_deg):
    """Every output is L^a r^b (a, b = 1, -1 for sigma_v, dp; 0, -1 for sigma_w, dw; 0, 0 for KCI),
    so r dS/dr = sum b_k v_k and L dS/dL = sum a_k v_k for their sum S: an analytic check of the
    reverse-mode gradient, through the straight-through mask (90 deg is a four-wire zone end)."""
    r, L = 2.0, 20.0
    (_, grads), vals = _call(0.6, rad(delta_deg), r, L)
    a = np.array([1.0 if (k.startswith("dp_") or "_v_" in k) and not k.startswith("kci") else 0.0 for k in _NAMES])
    b = np.array([0.0 if k.startswith("kci") else -1.0 for k in _NAMES])
    vals = np.asarray(vals)
    assert r * float(grads[2]) == pytest.approx(float(b @ vals), rel=1e-9)
    assert L * float(grads[4]) == pytest.approx(float(a @ vals), rel=1e-9)


def test_bad_mask_is_a_clear_error():
    d = tz.Design(4, 20.0, 2.0)
    with pytest.raises(ValueError, match=r"mask must have shape \(4,\) for 4 wires"):
        pose_measures(d, 0.5, 0.1, 0.4, jnp.ones(3))
    with pytest.raises(ValueError, match="mask must have shape"):
        pose_measures(d, 0.5, 0.1, 0.4, jnp.ones((4, 1)))


@pytest.mark.parametrize("n", [3, 8])
def test_a_swept_pose_evaluates_four_sines_and_cosines(n):
    """The compiled sweep program evaluates ``cos/sin theta_L`` and ``cos/sin delta`` once per pose and
    nothing else trigonometric per pose (the wires' angles enter by the addition theorem, per design).
    XLA:CPU re-evaluates a shared producer inside every consumer loop unless it is kept
    (``_numerics.keep``); this guards against that regression (benchmarks/PROFILE.md)."""
    import re

    d = tz.Design(n, 20.0, 2.0)
    N = 1000  # a batch size no design array has
    f = jax.jit(lambda d, t, e: jax.vmap(lambda a, b: pose_metrics(d, a, b))(t, e))
    hlo = f.lower(d, jnp.zeros(N), jnp.zeros(N)).compile().as_text()
    per_pose = re.findall(r"= f64\[([^\]]*)\]\S* (sine|cosine)\(", hlo)
    per_pose = sorted(op for shape, op in per_pose if str(N) in shape)
    assert per_pose == ["cosine", "cosine", "sine", "sine"]


# ------------------------------------------------------------------------------------------------
# Many wires: arrays over the wire axis above UNROLL_MAX_WIRES, same numbers
# ------------------------------------------------------------------------------------------------
def _measures_at(design, th, de, mask, dq=0.4):
    """The reduced measures at many poses (one mode: half the program of pose_metrics)."""
    return jax.jit(jax.vmap(lambda a, b, m: pose_measures(design, a, b, dq, m)))(th, de, mask)


@pytest.mark.parametrize("n, even", [(9, False)])
def test_many_wires_array_form_matches_the_unrolled_form(n, even, monkeypatch):
    from tension_zones import _numerics

    rng = np.random.default_rng(n)
    angles = None if even else np.sort(rng.uniform(0.0, 2 * np.pi, n))
    d = tz.Design(n, 20.0, 2.0, wire_angles=angles)
    th = jnp.asarray(np.concatenate([rng.uniform(0.0, 1.6, 60), [np.pi / 2, np.pi / 2 - 1e-7]]))
    de = jnp.asarray(np.concatenate([rng.uniform(-7.0, 7.0, 60), [0.3, 1.1]]))
    assert not _numerics.unrolled(n)
    mask = jax.vmap(lambda e: tz.tension_mask(d, e))(de)
    arrays = _measures_at(d, th, de, mask)
    monkeypatch.setattr(_numerics, "UNROLL_MAX_WIRES", 64)  # the per-wire scalars, unrolled
    lists = _measures_at(d, th, de, mask)
    for k in lists:
        np.testing.assert_allclose(arrays[k], lists[k], rtol=1e-12, atol=1e-14, err_msg=k)
    monkeypatch.undo()
    g = jax.grad(lambda r: pose_metrics(d.replace(pitch_radius=r), 0.7, 0.2)["dp_max_reduced"])(2.0)
    assert np.isfinite(float(g)) and float(g) < 0  # dp_max ~ L / r


def test_many_wires_match_the_reference():
    d = tz.Design(9, 20.0, 2.0, wire_angles=rad(np.sort(np.random.default_rng(9).uniform(0, 360, 9))))
    for t, e in ((0.6, 0.4), (1.2, 2.9), (np.pi / 2 - 0.01, 5.0)):
        out = pose_metrics(d, t, e, 0.3)
        for mode in ("full", "reduced"):
            ref = ref_measures(20.0, 2.0, np.asarray(d.wire_angles), t, e, 0.3, mode == "reduced")
            for k in MEASURES:
                scale = max(abs(ref[k]), SCALE.get(k, 0.0))
                assert abs(float(out[f"{k}_{mode}"]) - ref[k]) <= 1e-9 * scale, (mode, k)


@pytest.mark.parametrize("fn", ["kinematics", "compliance"])
def test_the_program_does_not_grow_with_the_wire_count(fn):
    """No per-wire unrolling above UNROLL_MAX_WIRES: the traced program of one pose has the same
    size for 16 and 64 wires (the unrolled one grows with n^2)."""

    def size(n):
        d = tz.Design(n, 20.0, 2.0)

        def f(t, e):
            if fn == "kinematics":
                return pose_metrics(d, t, e, 0.4)
            return tz.compliance_pose(d, t, e, jnp.asarray([5.0, 0.0, 0.0]))

        return len(jax.make_jaxpr(f)(0.5, 0.3).eqns)

    assert size(16) == size(64)


# ------------------------------------------------------------------------------------------------
# NaN in, NaN out: never a plausible 0
# ------------------------------------------------------------------------------------------------
NAN = float("nan")
_W = jnp.asarray([5.0, 0.0, 0.0])
_metrics_jit, _measures_jit = jax.jit(pose_metrics), jax.jit(pose_measures)


def _all_nan(out):
    for k, v in out.items():
        v = np.asarray(v)
        if v.dtype == bool:
            assert not v.any(), k
        elif np.issubdtype(v.dtype, np.integer):
            assert np.all(v == -1), k
        else:
            assert np.all(np.isnan(v)), k


@pytest.mark.parametrize("n", [3, 4, 12])
def test_nan_inputs_give_nan_for_every_measure(n):
    d = tz.Design(n, 20.0, 2.0, wire_stiffness=75.0, backbone_EI=1200.0)
    bad_inputs = {"theta_L": NAN, "delta": NAN, "dq": NAN, "inf theta_L": np.inf, "inf dq": np.inf}
    for bad, value in bad_inputs.items():
        pose = {"theta_L": 0.6, "delta": 0.4, "dq": 0.4, bad.split()[-1]: value}
        args = (d, pose["theta_L"], pose["delta"], pose["dq"])
        for out in (_metrics_jit(*args), _measures_jit(*args), _measures_jit(*args, tz.tension_mask(d, 0.4))):
            assert len(out) >= len(MEASURES)
            _all_nan(out)
        if "dq" not in bad:
            _all_nan(tz.compliance_pose_jit(d, pose["theta_L"], pose["delta"], _W))
    assert np.all(np.isnan(tz.tension_mask(d, NAN))) and np.all(np.isnan(tz.tension_score(d, NAN)))
    assert np.all(np.isnan(tz.tension_score(d, NAN, theta_L=0.6, psi_dot=[-1.0, 0.3])))
    # the box dq [-1, 1]^n is symmetric: a negative dq is the same box, not an error
    neg = _metrics_jit(d, 0.6, 0.4, -0.4)
    assert float(neg["dp_max_reduced"]) == float(_metrics_jit(d, 0.6, 0.4, 0.4)["dp_max_reduced"])
    # NaN in one pose of a sweep stays in that pose
    th = jnp.asarray([0.6, NAN, 0.8])
    dp = np.asarray(jax.vmap(_metrics_jit, in_axes=(None, 0, None, None))(d, th, 0.4, 0.4)["dp_max_reduced"])
    assert np.isnan(dp[1]) and np.all(np.isfinite(dp[[0, 2]]))


def test_nan_mask_gives_nan():
    d = tz.Design(3, 20.0, 2.0)
    _all_nan(pose_measures(d, 0.6, 0.4, 0.4, mask=jnp.asarray([1.0, NAN, 0.0])))


def test_finite_values_and_gradients_are_unchanged_by_the_nan_guard():
    d = tz.Design(4, 20.0, 2.0)
    g = jax.grad(lambda t: pose_metrics(d, t, 0.4, 0.4)["dp_max_reduced"])(0.6)
    h = 1e-6
    fd = (
        pose_metrics(d, 0.6 + h, 0.4, 0.4)["dp_max_reduced"] - pose_metrics(d, 0.6 - h, 0.4, 0.4)["dp_max_reduced"]
    ) / (2 * h)
    assert float(g) == pytest.approx(float(fd), rel=1e-6)
    g_mask = jax.grad(lambda e: jnp.sum(tz.tension_mask(d, e)))(0.4)  # the surrogate's gradient
    assert np.isfinite(float(g_mask)) and float(g_mask) != 0.0


@pytest.mark.parametrize(
    "field, value",
    [
        ("length", -20.0),
        ("pitch_radius", -2.0),
        ("pitch_radius", 0.0),
        ("wire_stiffness", -75.0),
        ("backbone_EI", -1.0),
        ("preload", -1.0),
        ("length", NAN),
        ("wire_angles", NAN),
    ],
)
def test_a_design_built_under_jit_with_an_invalid_value_gives_nan(field, value):
    """Design() cannot raise for traced values; the measures are NaN instead (Design docstring)."""

    def build(v):
        kw = {
            "n_wires": 3,
            "length": 20.0,
            "pitch_radius": 2.0,
            "wire_stiffness": 75.0,
            "backbone_EI": 1200.0,
            "preload": 0.5,
        }
        kw[field] = jnp.full(3, v).at[1:].set(jnp.asarray([2.0, 4.0])) if field == "wire_angles" else v
        return tz.Design(**kw)

    metrics = jax.jit(lambda v: pose_metrics(build(v), 0.6, 0.4, 0.4))
    comp = jax.jit(lambda v: tz.compliance_pose(build(v), 0.6, 0.4, _W))
    valid = {
        "length": 20.0,
        "pitch_radius": 2.0,
        "wire_stiffness": 75.0,
        "backbone_EI": 1200.0,
        "preload": 0.5,
        "wire_angles": 0.0,
    }[field]
    assert np.isfinite(float(metrics(valid)["dp_max_reduced"]))
    assert bool(jax.jit(lambda v: build(v).invalid())(value))
    assert not bool(jax.jit(lambda v: build(v).invalid())(valid))
    _all_nan(comp(value))
    if field in ("length", "pitch_radius", "wire_angles"):  # what the kinematic measures use
        _all_nan(metrics(value))
    with pytest.raises(ValueError, match=field):  # concrete: the constructor's one-line error
        build(value)
