"""Checks of the independent reference rod solver (tests/reference_rod.py) against known solutions.

The reference is the yardstick for the package's rod model; here it is validated on its own:
(a) tendon tensions only -> constant-curvature arcs (tension_zones/MODEL.md Sec. 1 and 5, one and three segments);
(b) tip force -> Euler-Bernoulli F L^3 / (3 EI) for a small load, the large-deflection elastica
    (elliptic-integral solution and Bisshopp & Drucker's published values) for a large one;
(c) uniform weight -> w L^4 / (8 EI);
(d) equilibrium: ODE and boundary residuals, the moment resultant recomputed by quadrature, the
    tendon termination loads at the disks, frame orthogonality;
(e) a second code path (planar elastica by shooting) for combined tendon + weight + tip loads with
    large deflection, one and three segments;
(f) 3-D consistency: rotating the whole problem about the base axis rotates the solution.
"""

import numpy as np
import pytest
import reference_rod as rr
from scipy.integrate import quad
from scipy.optimize import brentq

EI = 2454.369  # FTDCR v4 backbone: 1 mm rod, E = 50 GPa
L = 60.0
R3 = np.deg2rad([0.0, 120.0, 240.0])


def arc_tip_sec5(length, b):
    """tension_zones/MODEL.md Sec. 5: tip position and rotation vector of an arc with bending vector b = (u, v)."""
    u, v = b
    phi = np.hypot(u, v)
    c = length * (1 - np.cos(phi)) / phi**2
    return np.array([c * u, c * v, length * np.sin(phi) / phi]), np.array([-v, u, 0.0])


def rotvec(R):
    w = 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])  # sin(th) axis
    s = np.linalg.norm(w)
    th = np.arctan2(s, (np.trace(R) - 1) / 2)
    return w * (th / s if s > 0 else 1.0)


# ------------------------------------------------------------------------------------------
# (a) tendon tensions only: constant curvature
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("tendons", ["full", "point"])
def test_tensions_only_single_segment_is_the_constant_curvature_arc(tendons):
    tau = np.array([3.0, 0.7, 0.0])
    r = 4.5
    sol = rr.solve_segment(L, EI, R3, r, tau, tendons=tendons)
    # curvature vector toward the pulled tendons
    kv = (tau * r) @ np.stack([np.cos(R3), np.sin(R3)], axis=1) / EI
    b = kv * L  # tension_zones/MODEL.md bending vector phi (cos sigma, sin sigma)
    p, w = arc_tip_sec5(L, b)
    np.testing.assert_allclose(sol.tip_position, p, rtol=0, atol=1e-8)
    np.testing.assert_allclose(rotvec(sol.tip_rotation), w, rtol=0, atol=1e-10)
    # Sec. 1 form (psi = [theta_L, delta]) agrees
    p1, R1 = rr.constant_curvature_tip(L, np.hypot(*b), np.arctan2(b[1], b[0]))
    np.testing.assert_allclose(sol.tip_position, p1, atol=1e-8)
    np.testing.assert_allclose(sol.tip_rotation, R1, atol=1e-10)
    # constant body curvature of magnitude |kv|, no twist, and the tip moves toward tendon 0
    np.testing.assert_allclose(np.hypot(sol.u[:, 0], sol.u[:, 1]), np.hypot(*kv), rtol=1e-9)
    assert np.max(np.abs(sol.u[:, 2])) < 1e-12
    assert sol.tip_position[0] > 0 and sol.tip_position[1] > 0  # tendon 0 at 0 deg, 1 at 120 deg


def test_tensions_only_three_segments_compose_constant_curvature_arcs():
    """Segment j's tendons end at its end disk and cross segments 0..j at their offsets, so segment
    i's curvature is the sum over the tendons of segments >= i; the tip pose is the product of the
    segments' arcs."""
    lengths = [60.0, 62.5, 64.0]
    eis = [EI, 1.5 * EI, 0.8 * EI]
    angles = [R3 + 0.1, R3 + 0.9, R3 - 0.4]
    taus = [np.array([1.0, 0.0, 0.3]), np.array([0.0, 0.8, 0.0]), np.array([0.2, 0.0, 0.6])]
    radii = [4.5, 4.0, 3.5]
    segs = [rr.Segment(lj, e, tuple(a), rj, tuple(t)) for lj, e, a, rj, t in zip(lengths, eis, angles, radii, taus)]
    sol = rr.solve_rod(segs)
    T = np.eye(4)
    for i in range(3):
        mom = sum((taus[j] * radii[j]) @ np.stack([np.cos(angles[j]), np.sin(angles[j])], 1) for j in range(i, 3))
        kv = mom / eis[i]
        p, Ri = rr.constant_curvature_tip(lengths[i], np.hypot(*kv) * lengths[i], np.arctan2(*kv[::-1]))
        Ti = np.eye(4)
        Ti[:3, :3], Ti[:3, 3] = Ri, p
        T = T @ Ti
        # the disk pose matches after each segment
        k = (i + 1) * 101 - 1
        np.testing.assert_allclose(sol.p[k], T[:3, 3], atol=1e-8)
        np.testing.assert_allclose(sol.R[k], T[:3, :3], atol=1e-10)


# ------------------------------------------------------------------------------------------
# (b) tip force
# ------------------------------------------------------------------------------------------
def test_small_tip_force_matches_euler_bernoulli():
    d = 1e-4 * L  # tip deflection of 1e-4 L: nonlinear terms ~ 1e-8 relative
    F = 3 * EI * d / L**3
    e = np.array([np.cos(0.5), np.sin(0.5), 0.0])  # any transverse direction
    sol = rr.solve_segment(L, EI, [], 0.0, [], tip_force=F * e, tol=1e-10)
    # transverse d, axial foreshortening int (w')^2 / 2 = 3 d^2 / (5 L)
    np.testing.assert_allclose(
        sol.tip_position, (L - 0.6 * d**2 / L) * np.array([0, 0, 1]) + d * e, rtol=0, atol=1e-6 * d
    )
    # tip slope F L^2 / (2 EI) about the axis z x e
    np.testing.assert_allclose(
        rotvec(sol.tip_rotation), F * L**2 / (2 * EI) * np.cross([0, 0, 1], e), rtol=1e-6, atol=1e-15
    )


def elastica_cantilever(alpha):
    """Planar elastica of a cantilever under a perpendicular dead tip load, alpha = F L^2 / EI:
    (transverse, axial) tip position / L, from the first integral
    theta'^2 = 2 alpha / L^2 (sin theta0 - sin theta) by quadrature and root finding."""

    def integral(g, th0):
        # theta = th0 (1 - w^2) removes the inverse-square-root end singularity:
        # sin th0 - sin th = 2 cos((th0 + th)/2) sin(th0 w^2 / 2), d theta = -2 th0 w dw
        def h(w):
            th = th0 * (1 - w * w)
            x = th0 * w * w / 2
            return g(th) * 2 * th0 / np.sqrt(th0 * np.cos(th0 - x) * np.sinc(x / np.pi))

        return quad(h, 0.0, 1.0, epsabs=1e-13, epsrel=1e-11, limit=200)[0]

    th0 = brentq(lambda t: integral(lambda th: 1.0, t) - np.sqrt(2 * alpha), 1e-9, np.pi / 2 - 1e-6, xtol=1e-15)
    y = integral(np.sin, th0) / np.sqrt(2 * alpha)
    x = integral(np.cos, th0) / np.sqrt(2 * alpha)
    assert np.isclose(x, np.sqrt(2 * np.sin(th0) / alpha), rtol=1e-10)
    return y, x, th0


@pytest.mark.parametrize("alpha, published", [(1.0, 0.3017), (2.0, 0.4935), (10.0, 0.8106)])
def test_large_tip_force_matches_the_elastica(alpha, published):
    F = alpha * EI / L**2
    sol = rr.solve_segment(L, EI, [], 0.0, [], tip_force=(0.0, F, 0.0))
    y, x, th0 = elastica_cantilever(alpha)
    np.testing.assert_allclose(sol.tip_position / L, [0.0, y, x], atol=2e-8)
    assert abs(np.arcsin(sol.tip_rotation[1, 2]) - th0) < 1e-7  # tip tangent (0, sin th0, cos th0)
    # Bisshopp & Drucker (1945), Quart. Appl. Math. 3: 272, transverse deflection / L
    assert abs(y - published) < 1e-4


# ------------------------------------------------------------------------------------------
# (c) distributed weight
# ------------------------------------------------------------------------------------------
def test_small_uniform_weight_matches_euler_bernoulli():
    d = 1e-4 * L
    w = 8 * EI * d / L**4
    sol = rr.solve_segment(L, EI, [], 0.0, [], weight=(0.0, -w, 0.0), tol=1e-10)
    # axial foreshortening int (w')^2 / 2 = 4 d^2 / (7 L)
    np.testing.assert_allclose(sol.tip_position, [0.0, -d, L - 4 * d**2 / (7 * L)], rtol=0, atol=1e-6 * d)
    # tip slope w L^3 / (6 EI) and base moment w L^2 / 2 (about -x: the load is along -y)
    np.testing.assert_allclose(rotvec(sol.tip_rotation), [w * L**3 / (6 * EI), 0, 0], rtol=1e-6)
    np.testing.assert_allclose(sol.M[0], [w * L**2 / 2, 0, 0], rtol=1e-6)
    # superposition with a small tip force
    F = 3 * EI * d / L**3
    both = rr.solve_segment(L, EI, [], 0.0, [], weight=(0.0, -w, 0.0), tip_force=(0.0, -F, 0.0), tol=1e-10)
    assert abs(both.tip_position[1] + 2 * d) < 1e-5 * d


# ------------------------------------------------------------------------------------------
# (d) equilibrium of a loaded three-segment robot
# ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def loaded3():
    segs = [
        rr.Segment(60.0, EI, tuple(R3), 4.5, (1.5, 0.0, 0.2)),
        rr.Segment(62.5, EI, tuple(R3 + 0.7), 4.5, (0.0, 1.0, 0.0)),
        rr.Segment(64.0, EI, tuple(R3 + 1.4), 4.5, (0.0, 0.0, 0.6)),
    ]
    g = np.array([0.0, 2e-3, -3.5e-3])
    F = np.array([0.05, -0.1, -0.2])
    return rr.solve_rod(segs, weight=g, tip_force=F), segs, g, F


def test_equilibrium_residuals(loaded3):
    sol, *_ = loaded3
    res = sol.residuals()
    assert res["ode"] < 1e-7
    assert res["bc"] < 1e-10
    assert res["orthogonality"] < 1e-9
    assert res["constitutive"] < 1e-8
    # the loads made it bend out of its tendon plane and twist
    assert np.max(np.abs(sol.u[:, 2])) > 1e-4


def test_moment_resultant_by_quadrature(loaded3):
    """M(s) = int_s^L (p(s') - p(s)) x g ds' + (p(L) - p(s)) x F, from the solved curve."""
    sol, _, g, F = loaded3
    st = np.linspace(0.0, sol.segment_ends[-1], 6001)
    P = sol.at(st)["p"]
    for s in [0.0, 31.0, 60.0, 100.0, 150.0]:
        m = st >= s
        ps = sol.at([s])["p"][0]
        integrand = np.cross(P[m] - ps, g)
        Mq = np.trapezoid(integrand, st[m], axis=0) + np.cross(P[-1] - ps, F)
        Ms = sol.at([s])["M"][0]
        Nq = g * (st[-1] - s) + F
        np.testing.assert_allclose(Ms, Mq, rtol=0, atol=1e-5 * np.abs(Mq).max() + 1e-9)
        np.testing.assert_allclose(sol.at([s])["N"][0], Nq, atol=1e-10)


def test_tendon_termination_loads_at_the_disks(loaded3):
    """Across disk j (no external load there) the backbone's moment jumps by the change of
    sum_k tau_k (R r_k) x t_k over the tendons crossing the cut, and its force by that of
    sum_k tau_k t_k (t_k = R (e3 + u x r_k) normalised, the tendon tangent; under twist the
    tendons that run on kink slightly at the disk). Without twist this is the termination
    load of the tendons that end there: the point moment R sum tau_k r_k x (-e3) and the axial
    compression -sum tau_k R e3."""

    def tendon_loads(i, first):
        r = np.concatenate([segs[k].offsets() for k in range(first, 3)])
        tau = np.concatenate([segs[k].tension_array() for k in range(first, 3)])
        t = np.array([0, 0, 1.0]) + np.cross(sol.u[i], r)
        t = (sol.R[i] @ (t / np.linalg.norm(t, axis=1, keepdims=True)).T).T
        rw = r @ sol.R[i].T
        return (tau[:, None] * np.cross(rw, t)).sum(0), (tau[:, None] * t).sum(0)

    sol, segs, *_ = loaded3
    for j in range(2):
        a, b = (j + 1) * 101 - 1, (j + 1) * 101  # the disk, proximal / distal side
        np.testing.assert_allclose(sol.p[a], sol.p[b], atol=1e-12)
        seg = segs[j]
        r = seg.offsets()
        tau = seg.tension_array()
        dm = sol.m_backbone[a] - sol.m_backbone[b]
        dn = sol.n_backbone[a] - sol.n_backbone[b]
        (ma, fa), (mb, fb) = tendon_loads(a, j), tendon_loads(b, j + 1)
        np.testing.assert_allclose(dm, -(ma - mb), atol=1e-9)
        np.testing.assert_allclose(dn, -(fa - fb), atol=1e-12)
        # point-moment approximation: off by the twist's tilt only (here u_z r ~ 1e-3)
        dm_point = sol.R[a] @ (tau[:, None] * np.cross(r, [0, 0, -1.0])).sum(0)
        assert np.linalg.norm(dm - dm_point) < 1e-3 * np.linalg.norm(dm)
        assert np.linalg.norm(dn + tau.sum() * sol.R[a][:, 2]) < 1e-3 * np.linalg.norm(dn)


# ------------------------------------------------------------------------------------------
# (e) a second code path: the planar elastica by shooting
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "lengths, eis, taus, g, F",
    [
        ([60.0], [EI], [(2.0, 0.0)], (-4e-3, -3e-3), (0.3, -0.1)),
        (
            [60.0, 62.5, 64.0],
            [EI, 1.3 * EI, 0.7 * EI],
            [(0.0, 0.6), (0.8, 0.0), (0.5, 0.0)],
            (3.5e-3, 0.0),
            (0.0, 0.05),
        ),
    ],
)
def test_planar_loads_agree_with_shooting(lengths, eis, taus, g, F):
    """Tendons at 0 and 180 deg, weight and tip force in the x-z plane: a large planar bend."""
    ang = (0.0, np.pi)
    segs = [rr.Segment(lj, e, ang, 4.5, t) for lj, e, t in zip(lengths, eis, taus)]
    sol = rr.solve_rod(segs, weight=(g[0], 0.0, g[1]), tip_force=(F[0], 0.0, F[1]))
    tm = [sum(4.5 * (taus[k][0] - taus[k][1]) for k in range(j, len(segs))) for j in range(len(segs))]
    (x, z), th = rr.planar_shooting(lengths, eis, tm, g, F)
    np.testing.assert_allclose(sol.tip_position, [x, 0.0, z], atol=1e-6)
    assert abs(np.arctan2(sol.tip_rotation[0, 2], sol.tip_rotation[2, 2]) - th) < 1e-8
    assert abs(th) > 0.3  # a large deflection
    # planar: no twist, so the full and the point tendon models coincide
    if len(segs) == 1:
        pt = rr.solve_rod(segs, weight=(g[0], 0.0, g[1]), tip_force=(F[0], 0.0, F[1]), tendons="point")
        np.testing.assert_allclose(pt.tip_position, sol.tip_position, atol=1e-9)


# ------------------------------------------------------------------------------------------
# (f) 3-D consistency
# ------------------------------------------------------------------------------------------
def test_rotating_the_problem_about_the_base_axis_rotates_the_solution():
    def solve(psi):
        c, s = np.cos(psi), np.sin(psi)
        Rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
        sol = rr.solve_segment(
            L,
            EI,
            R3 + psi,
            4.5,
            [2.0, 0.0, 0.5],
            weight=Rz @ [0.0, 3e-3, -2e-3],
            tip_force=Rz @ [0.1, 0.0, 0.0],
            tol=1e-9,
        )
        return sol, Rz

    s0, _ = solve(0.0)
    s1, Rz = solve(1.1)
    np.testing.assert_allclose(s1.tip_position, Rz @ s0.tip_position, atol=1e-7)
    np.testing.assert_allclose(s1.tip_rotation, Rz @ s0.tip_rotation @ Rz.T, atol=1e-9)
    # out-of-plane loads twist the segment; the tendons' tension stiffens the twist
    # (torsional stiffness GJ + sum tau rho^2 in the full model)
    pt = rr.solve_segment(
        L, EI, R3, 4.5, [2.0, 0.0, 0.5], weight=[0.0, 3e-3, -2e-3], tip_force=[0.1, 0.0, 0.0], tol=1e-9, tendons="point"
    )
    assert 0 < np.max(np.abs(s0.u[:, 2])) < np.max(np.abs(pt.u[:, 2]))
