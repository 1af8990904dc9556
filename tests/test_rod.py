"""The rod model: each segment solved as constant-curvature pieces in the one equilibrium, checked
against the independent Kirchhoff-rod solver of ``tests/reference_rod.py`` (SciPy's solve_bvp)."""

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import reference_rod as rr

import tension_zones as tz
from tension_zones.model import Load
from tension_zones.model import _equilibrium as E
from tension_zones.model._robot import Structure, chain_tip

SEG = tz.Design(3, 60.0, 4.5, wire_stiffness=50.0, backbone_EI=2454.0)
Q = jnp.array([-3.0, 0.5, 0.5])


@partial(jax.jit, static_argnums=(1, 6))
def _solution(phys, st, q, f, d, loaded, jacobians):
    """One sample's equilibrium (``d`` the wires' directions of motion, used by friction only) and, at
    it, the tip, the non-conservative force, the tensions, and with ``jacobians`` the force's Jacobian
    in closed form and by forward mode: one program per structure (eagerly, every operation would
    compile a program of its own)."""
    B = E.solve(phys, st, q, f, d)
    x = B.reshape(-1)
    sm = E._Sample(phys, st, q, f, d, loaded)
    out = {"p": chain_tip(E.piece_lengths(phys, st), B)[0], "B": B, "force": sm.force(x)}
    out["tension"] = sm.k * jnp.maximum(sm.stretch(x), 0.0)
    if jacobians:
        out.update(force_jacobian=sm.force_jacobian(x), force_jacobian_ad=jax.jacfwd(sm.force)(x))
    return out


def solved(robot, q, load, m, freedom=None):
    """Tip position, piece bending vectors and the wires' tensions (N) of the package's solution."""
    phys = robot.params()
    phys["gravity"] = jnp.asarray(load.gravity, float)
    if freedom is not None:
        phys["curvature_freedom"] = jnp.asarray(freedom, float)
    st = Structure(robot.n_wires_per_segment, m)
    q = jnp.asarray(q, float)
    sol = _solution(phys, st, q, jnp.asarray(load.tip_force, float), jnp.zeros_like(q), jnp.asarray(True), False)
    return tuple(np.asarray(sol[k]) for k in ("p", "B", "tension"))


def test_tendons_alone_give_constant_curvature_exactly():
    robot = tz.Robot(SEG)
    p1, B1, _ = solved(robot, Q, Load.none(), 1)
    p4, B4, _ = solved(robot, Q, Load.none(), 4)
    np.testing.assert_allclose(p4, p1, atol=1e-9)
    np.testing.assert_allclose(B4, np.repeat(B1 / 4, 4, axis=0), atol=1e-10)  # every piece a quarter
    assert np.isclose(np.asarray(tz.forward(robot, Q, pieces=4)[0]), p1, atol=1e-9).all()


@pytest.mark.parametrize(
    "load", [Load(jnp.zeros(3), jnp.array([0.0, 0.0, -0.003])), Load(jnp.zeros(3), jnp.array([0.003, 0.0, 0.0]))]
)
def test_weight_converges_to_the_rod_at_second_order(load):
    """Planar: the rod (solve_bvp, same tendon tensions) is reached as O(1/m^2)."""
    robot = tz.Robot(SEG)
    errs = []
    for m in (2, 4, 8):
        p, _, tau = solved(robot, Q, load, m)
        ref = rr.solve_segment(60.0, 2454.0, np.asarray(SEG.wire_angles), 4.5, tau, weight=np.asarray(load.gravity))
        errs.append(np.linalg.norm(p - ref.tip_position))
    assert errs[2] < 0.01 and errs[0] / errs[2] > 10  # ~16 for second order
    p1, _, tau = solved(robot, Q, load, 1)
    ref = rr.solve_segment(60.0, 2454.0, np.asarray(SEG.wire_angles), 4.5, tau, weight=np.asarray(load.gravity))
    assert np.linalg.norm(p1 - ref.tip_position) > 5 * errs[2]  # constant curvature is further off


def test_tip_force_and_weight_in_3d_match_a_torsion_free_rod():
    """A lateral tip force on a bent segment: our pieces carry no twist, so they converge to the rod
    with a rigid torsion (GJ large); a solid rod's twist is a stated limit of the model."""
    robot = tz.Robot(SEG)
    load = Load(jnp.array([0.0, 0.4, -0.2]), jnp.array([0.002, 0.0, -0.002]))
    p, _, tau = solved(robot, Q, load, 16)
    ref = rr.solve_segment(
        60.0,
        2454.0,
        np.asarray(SEG.wire_angles),
        4.5,
        tau,
        weight=np.asarray(load.gravity),
        tip_force=np.asarray(load.tip_force),
        GJ=1e9,
    )
    assert np.linalg.norm(p - ref.tip_position) < 0.02


def test_two_segments_under_weight_match_the_rod():
    robot = tz.Robot(
        [
            tz.Design(3, 45.0, 3.5, wire_angles=np.radians([10, 130, 250]), wire_stiffness=30.0, backbone_EI=1500.0),
            tz.Design(
                4, 70.0, 5.0, wire_angles=np.radians([45, 135, 215, 315]), wire_stiffness=80.0, backbone_EI=3000.0
            ),
        ]
    )
    q = jnp.array([-1.5, 0.4, 0.4, 0.3, -1.0, 0.3, 0.3])
    load = Load(jnp.zeros(3), jnp.array([0.0, 0.002, -0.003]))
    p, _, tau = solved(robot, q, load, 8)
    segs = [
        rr.Segment(45.0, 1500.0, tuple(np.radians([10, 130, 250])), 3.5, tuple(tau[:3]), GJ=1e9),
        rr.Segment(70.0, 3000.0, tuple(np.radians([45, 135, 215, 315])), 5.0, tuple(tau[3:]), GJ=1e9),
    ]
    ref = rr.solve_rod(segs, weight=np.asarray(load.gravity))
    p1, _, _ = solved(robot, q, load, 1)
    assert np.linalg.norm(p - ref.tip_position) < 0.05 < np.linalg.norm(p1 - ref.tip_position)


def _with_friction(robot, q, mu, d, m, load=None, jacobians=False):
    """``_solution`` with friction along the routing (``mu``) and ``load``."""
    load = Load.none() if load is None else load
    phys = robot.params()
    phys.update(friction=jnp.asarray(mu, float), gravity=jnp.asarray(load.gravity, float))
    st = Structure(robot.n_wires_per_segment, m)
    loaded = jnp.asarray(bool(np.any(load.tip_force) or np.any(load.gravity)))
    f = jnp.asarray(load.tip_force, float)
    sol = _solution(phys, st, jnp.asarray(q, float), f, jnp.asarray(d, float), loaded, jacobians)
    return {k: np.asarray(v) for k, v in sol.items()}


@pytest.mark.parametrize("d", [-1.0, 1.0], ids=["pulled", "released"])
def test_friction_decays_the_tension_over_the_disks_as_the_capstan_rod(d):
    """One wire taut (the others slack), friction along the routing: the tension acting at arc length
    ``s`` is ``tau e^{d (mu_0 + mu_1 theta(s))}``, ``theta`` the bending wrapped so far, so
    ``theta' = c e^{d mu_1 theta}`` (``c = rho tau e^{d mu_0} / EI``): ``theta(s) = -d ln(1 - d mu_1 c s) /
    mu_1`` in closed form. The pieces converge to it at second order; constant curvature misses it."""
    robot = tz.Robot(SEG)
    q, mu = jnp.array([-3.0, 6.0, 6.0]), (0.2, 0.8)
    errs = []
    for m in (1, 4, 16):
        sol = _with_friction(robot, q, mu, [d, 0.0, 0.0], m)
        np.testing.assert_allclose(sol["force"], 0.0, atol=1e-9)  # the root of the non-conservative force
        p, tau = sol["p"], float(sol["tension"][0])
        c = 4.5 * tau * np.exp(d * mu[0]) / 2454.0
        s = np.linspace(0.0, 60.0, 20001)
        th = -d * np.log1p(-d * mu[1] * c * s) / mu[1]
        ref = np.array([np.trapezoid(np.sin(th), s), np.trapezoid(np.cos(th), s)])
        errs.append(np.hypot(np.hypot(p[0], p[1]) - ref[0], p[2] - ref[1]))
    assert errs[2] < 0.02 and errs[1] / errs[2] > 10 and errs[0] > 0.3  # ~16 for second order


def test_friction_force_jacobian_is_exact_with_loads_and_segments():
    """The implicit derivative's ``dF/dx`` in closed form against forward mode, two segments in pieces,
    wires pulled and released, a tip force and a weight; gradients finite at the straight pose."""
    robot = tz.Robot(
        [
            tz.Design(
                3,
                45.0,
                3.5,
                wire_angles=np.radians([10, 130, 250]),
                wire_stiffness=30.0,
                backbone_EI=1500.0,
                preload=1.0,
            ),
            tz.Design(
                4,
                70.0,
                5.0,
                wire_angles=np.radians([45, 135, 215, 315]),
                wire_stiffness=80.0,
                backbone_EI=3000.0,
                preload=1.0,
            ),
        ]
    )
    q = jnp.array([-1.5, 0.4, 0.4, 0.3, -1.0, 0.3, 0.3])
    d = np.sign(np.asarray(q))
    load = Load(jnp.array([0.05, -0.1, 0.0]), jnp.array([0.0, 0.002, -0.003]))
    sol = _with_friction(robot, q, (0.15, 0.5), d, 3, load, jacobians=True)
    np.testing.assert_allclose(sol["force"], 0.0, atol=1e-8)
    np.testing.assert_allclose(sol["force_jacobian"], sol["force_jacobian_ad"], rtol=1e-6, atol=1e-6)

    jac = jax.jit(jax.jacfwd(lambda mu, q: chain_tip(*_tip_args(robot, mu, q, d))[0], argnums=(0, 1)))
    for qq in (q, jnp.zeros(7)):
        assert all(np.all(np.isfinite(np.asarray(J))) for J in jac(jnp.asarray([0.15, 0.5]), qq))


def _tip_args(robot, mu, q, d):
    phys = robot.params()
    phys["friction"] = mu
    st = Structure(robot.n_wires_per_segment, 3)
    return E.piece_lengths(phys, st), E.solve(phys, st, q, jnp.zeros(3), jnp.asarray(d, float))


def test_curvature_freedom_interpolates_with_a_first_order_derivative_at_zero():
    robot = tz.Robot(SEG)
    load = Load(jnp.zeros(3), jnp.array([0.003, 0.0, 0.0]))
    p_cc, _, _ = solved(robot, Q, load, 1)
    p_rod, _, _ = solved(robot, Q, load, 4)
    p0, _, _ = solved(robot, Q, load, 4, freedom=[0.0])
    dev = np.linalg.norm(p_rod - p_cc)
    assert dev > 0.05 and np.linalg.norm(p0 - p_cc) < 2e-3 * dev

    def tip(r):
        phys = robot.params()
        phys.update(gravity=load.gravity, curvature_freedom=r)
        st = Structure((3,), 4)
        return chain_tip(E.piece_lengths(phys, st), E.solve(phys, st, Q, load.tip_force))[0]

    d0 = np.asarray(jax.jit(jax.jacfwd(tip))(jnp.zeros(1)))[:, 0]
    # the first-order variation points from constant curvature toward the rod
    assert np.dot(d0, p_rod - p_cc) > 0.5 * np.linalg.norm(d0) * dev


def test_straight_pose_values_and_gradients_finite_and_vmapped():
    robot = tz.Robot(SEG)
    load = Load(jnp.zeros(3), jnp.array([0.0, 0.0, -0.003]))

    def tip(q, g, r):
        phys = robot.params()
        phys.update(gravity=g, curvature_freedom=r)
        st = Structure((3,), 4)
        return chain_tip(E.piece_lengths(phys, st), E.solve(phys, st, q, jnp.zeros(3), loaded=jnp.asarray(True)))[0]

    value = jax.jit(tip)
    jac = jax.jit(jax.jacfwd(tip, argnums=(0, 1, 2)))
    grad = jax.jit(jax.grad(lambda q, g, r: tip(q, g, r)[0]))
    z = jnp.zeros(3)
    for g in (jnp.zeros(3), load.gravity):  # unloaded and loaded, rod and constant curvature: one program each
        for r in (jnp.zeros(1), jnp.ones(1)):
            assert np.all(np.isfinite(np.asarray(value(z, g, r))))
            assert all(np.all(np.isfinite(np.asarray(J))) for J in jac(z, g, r))
            assert np.all(np.isfinite(np.asarray(grad(z, g, r))))
    qs = jnp.asarray(np.random.default_rng(0).uniform(-2, 0.5, (5, 3)))
    batch = jax.vmap(lambda q: value(q, load.gravity, jnp.ones(1)))(qs)
    np.testing.assert_allclose(batch[3], value(qs[3], load.gravity, jnp.ones(1)), atol=1e-10)


def test_new_values_never_recompile():
    robot = tz.Robot(SEG)
    f = jax.jit(lambda rob, q, load: tz.forward(rob, q, load, pieces=4))
    f(robot, Q, Load.none())
    n = f._cache_size()
    for g, ei in ((0.001, 2000.0), (0.004, 3000.0)):
        rob = tz.Robot(tz.Design(3, 55.0, 4.0, wire_stiffness=40.0, backbone_EI=ei))
        f(rob, Q, Load(jnp.array([0.1, 0.0, 0.0]), jnp.array([0.0, 0.0, -g])))
    assert f._cache_size() == n


def test_pieces_must_be_a_positive_integer():
    with pytest.raises(ValueError, match="pieces must be a positive integer"):
        tz.forward(tz.Robot(SEG), Q, pieces=0)


@pytest.mark.slow
def test_a_large_rod_batch_runs_to_the_end():
    """1000 samples of a three-segment robot in pieces run to the end: XLA's concurrency-optimised
    CPU scheduler can leave such a vmapped while loop waiting with every thread idle, and the package
    turns it off (_xla.apply_settings)."""
    import subprocess
    import sys

    code = (
        "import numpy as np, jax, jax.numpy as jnp, tension_zones as tz\n"
        "r = tz.Robot.from_json(tz.example_path('ftdcr_v4/design.json'))\n"
        "Q = jnp.asarray(np.random.default_rng(0).uniform(-2, 0.5, (1000, 9)))\n"
        "p = jax.jit(jax.vmap(lambda q: tz.forward(r, q, pieces=4)[0]))(Q)\n"
        "print(bool(np.all(np.isfinite(np.asarray(p)))))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=240, check=False)
    assert out.returncode == 0 and out.stdout.strip() == "True", out.stderr[-2000:]


@pytest.mark.parametrize("m", [1, 4])
@pytest.mark.parametrize("friction", [False, True])
def test_a_warm_start_reaches_the_cold_start_equilibrium(m, friction):
    """``solve_warm`` from another solve's state (its equilibrium and learnt load curvature, at other
    parameters and commands) lands on the equilibrium a cold solve finds, and returns its own state;
    its derivatives are the cold solve's (the state carries none). Loaded: weight and a tip force.
    Jitted: eagerly it would compile dozens of one-primitive programs. (Each loaded program holds
    memory maps, and a worker of a full run comes near Linux's limit of them: the suite frees its
    programs past a soft limit, ``conftest.py``.)"""
    solve, solve_warm = jax.jit(E.solve, static_argnums=1), jax.jit(E.solve_warm, static_argnums=1)
    robot = tz.Robot([SEG, tz.Design(4, 40.0, 3.0, wire_stiffness=40.0, backbone_EI=1800.0)])
    st = Structure(robot.n_wires_per_segment, m)
    phys = robot.params()
    phys["gravity"] = jnp.asarray([0.002, 0.0, -0.003])
    phys["curvature_freedom"] = jnp.full(2, 0.7)
    if friction:
        phys["friction"] = jnp.asarray([0.02, 0.05])
    q = jnp.asarray([-2.0, 0.4, 0.6, -1.0, 0.2, 0.3, 0.1])
    f = jnp.asarray([0.1, -0.2, 0.05])
    d = jnp.sign(q)
    cold = solve(phys, st, q, f, d)
    near = dict(phys, EI=phys["EI"] * 1.01, preload=phys["preload"] + 0.05)
    _, state = solve_warm(near, st, q + 0.05, f * 1.1, d, E.cold_state(st))
    B, state2 = solve_warm(phys, st, q, f, d, state)
    np.testing.assert_allclose(np.asarray(B), np.asarray(cold), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(state2[0]), np.asarray(B).reshape(-1), rtol=0, atol=0)
    dq = jnp.linspace(-1.0, 1.0, 7)
    t_cold = jax.jvp(lambda qq: solve(phys, st, qq, f, d), (q,), (dq,))[1]
    t_warm = jax.jvp(lambda qq: solve_warm(phys, st, qq, f, d, state)[0], (q,), (dq,))[1]
    np.testing.assert_allclose(np.asarray(t_warm), np.asarray(t_cold), rtol=1e-8, atol=1e-12)
