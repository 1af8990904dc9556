"""The backbone's compression under the wires' tension: the equilibrium against an independent
minimisation with the shortening as unknowns of its own, the stretch's semismooth Newton against a
brute-force search of the taut sets, derivatives (at zero compliance too, where the score test takes
them) against differences, and no recompilation for new values."""

import functools
import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize

import tension_zones as tz
from tension_zones.calibration._model import _declared
from tension_zones.model import _equilibrium as eq
from tension_zones.model._robot import chain_tip

jax.config.update("jax_enable_x64", True)


def robot(n_segments=3):
    segs = [
        tz.Design(3, 60.0, 4.5, wire_stiffness=50.0, backbone_EI=12000.0, preload=3.0),
        tz.Design(4, 62.5, 4.0, wire_stiffness=40.0, backbone_EI=9000.0, preload=2.0),
        tz.Design(3, 64.0, 4.5, wire_stiffness=60.0, backbone_EI=15000.0, preload=4.0),
    ][:n_segments]
    return tz.Robot(segs)


def phys_of(rob, compliance):
    phys = dict(_declared(rob))
    phys["axial_compliance"] = jnp.asarray(compliance, float)
    return phys


def commands(rob, rng):
    return jnp.asarray(rng.uniform(-3.0, 1.0, rob.n_wires))


@functools.partial(jax.jit, static_argnums=2)
def _tip(phys, q, st_):
    B = eq.solve(phys, st_, q, jnp.zeros(3))
    return chain_tip(eq.compressed_lengths(phys, st_, q, jnp.zeros(3), None, B), B)[0]


def tip(phys, st_, q):
    return _tip(phys, q, st_)


def reference_equilibrium(phys, st_, q):
    """``min over (x, e)`` of the backbone's bending, the wires' stretch ``A x + c - X e`` and the
    backbone's axial energy ``sum e^2 / (2 a)``, by BFGS (SciPy): the shortening ``e`` (per segment)
    an unknown of its own, not eliminated as in the package."""
    sm = eq._Sample(phys, st_, q, jnp.zeros(3), jnp.zeros(q.shape[0]), jnp.asarray(False))
    A, c, k, E = (np.asarray(v) for v in (sm.A, sm.c, sm.k, sm.E))
    X, a = np.asarray(sm.crosses), np.asarray(phys["axial_compliance"])
    n = A.shape[1]

    def V(z):
        x, e = z[:n], z[n:]
        s = A @ x + c - X @ e
        taut = np.maximum(s, 0.0)
        val = 0.5 * E @ (x * x) + 0.5 * np.sum(k * taut**2) + 0.5 * np.sum(e**2 / a)
        return val, np.r_[E * x + A.T @ (k * taut), -X.T @ (k * taut) + e / a]

    z = minimize(V, np.zeros(n + X.shape[1]), jac=True, method="BFGS", options={"gtol": 1e-11}).x
    return z[:n], z[n:]


@pytest.mark.parametrize("n_segments", [1, 3])
def test_equilibrium_matches_a_minimisation_with_the_shortening_as_unknowns(n_segments):
    rob = robot(n_segments)
    rng = np.random.default_rng(n_segments)
    for a in (1.5e-3, 8e-3):
        phys = phys_of(rob, np.full(n_segments, a) * (1 + np.arange(n_segments)))
        q = commands(rob, rng)
        B = eq.solve(phys, rob.structure, q, jnp.zeros(3))
        x_ref, e_ref = reference_equilibrium(phys, rob.structure, q)
        np.testing.assert_allclose(np.asarray(B).reshape(-1), x_ref, atol=1e-6)
        shortening = rob.lengths - eq.compressed_lengths(phys, rob.structure, q, jnp.zeros(3), None, B)
        np.testing.assert_allclose(np.asarray(shortening), e_ref, atol=1e-7)
        assert np.all(e_ref > 0)  # the wires pull: the backbone shortens


def test_zero_compliance_is_the_rigid_backbone():
    rob = robot()
    q = commands(rob, np.random.default_rng(0))
    rigid = dict(_declared(rob))
    del rigid["axial_compliance"]
    np.testing.assert_array_equal(
        np.asarray(tip(phys_of(rob, np.zeros(3)), rob.structure, q)), np.asarray(tip(rigid, rob.structure, q))
    )


def brute_force_stretch(s0, k, G):
    """The root of ``s + G k max(s, 0) = s0`` by trying every taut set (NumPy)."""
    n = s0.shape[0]
    for taut in itertools.product([False, True], repeat=n):
        w = k * np.asarray(taut)
        s = np.linalg.solve(np.eye(n) + G * w[None, :], s0)
        if np.all(np.where(taut, s > -1e-12, s < 1e-12)):  # the set it assumed
            return s
    raise AssertionError("no taut set")


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_the_stretch_is_the_root_whatever_the_taut_set(seed):
    rng = np.random.default_rng(seed)
    rob = robot()
    phys = phys_of(rob, rng.uniform(0.0, 2e-2, 3))
    phys["wire_stiffness"] = jnp.asarray(rng.uniform(10.0, 150.0, rob.n_wires))
    sm = eq._Sample(
        phys, rob.structure, jnp.zeros(rob.n_wires), jnp.zeros(3), jnp.zeros(rob.n_wires), jnp.asarray(False)
    )
    s0 = rng.normal(0.0, 1.0, rob.n_wires)
    s = np.asarray(eq._relax(jnp.asarray(s0), sm.k, sm.G))
    np.testing.assert_allclose(s, brute_force_stretch(s0, np.asarray(sm.k), np.asarray(sm.G)), atol=1e-10)


def test_derivatives_in_the_compliance_at_zero_and_beyond():
    rob = robot()
    q = commands(rob, np.random.default_rng(3))

    @jax.jit
    def f(a):
        return tip(phys_of(rob, a), rob.structure, q)

    # at zero (the score test's null): one-sided second-order differences
    J = np.asarray(jax.jit(jax.jacfwd(f))(jnp.zeros(3)))
    h = 1e-6
    fd = np.stack(
        [
            (-3 * f(jnp.zeros(3)) + 4 * f(jnp.zeros(3).at[i].set(h)) - f(jnp.zeros(3).at[i].set(2 * h))) / (2 * h)
            for i in range(3)
        ],
        axis=1,
    )
    np.testing.assert_allclose(J, fd, rtol=1e-4, atol=1e-3)
    assert np.abs(J).max() > 10.0  # mm per (mm/N): the effect is seen at zero
    a0 = jnp.asarray([2e-3, 4e-3, 1e-3])
    J = np.asarray(jax.jit(jax.jacfwd(f))(a0))
    fd = np.stack([(f(a0.at[i].add(1e-7)) - f(a0.at[i].add(-1e-7))) / 2e-7 for i in range(3)], axis=1)
    np.testing.assert_allclose(J, fd, rtol=1e-5, atol=1e-5)


def test_derivatives_in_the_commands_with_compression():
    rob = robot()
    q0 = commands(rob, np.random.default_rng(4))
    phys = phys_of(rob, [3e-3, 2e-3, 1e-3])
    f = jax.jit(lambda q: tip(phys, rob.structure, q))
    J = np.asarray(jax.jit(jax.jacfwd(f))(q0))
    fd = np.stack([(f(q0.at[i].add(1e-6)) - f(q0.at[i].add(-1e-6))) / 2e-6 for i in range(rob.n_wires)], axis=1)
    np.testing.assert_allclose(J, fd, rtol=1e-5, atol=1e-6)


def test_new_compliances_do_not_recompile():
    rob = robot()
    q = commands(rob, np.random.default_rng(5))
    traces = []

    @jax.jit
    def f(a):
        traces.append(1)
        return tip(phys_of(rob, a), rob.structure, q)

    for a in (np.zeros(3), np.full(3, 2e-3), np.array([0.0, 5e-3, 1e-3])):
        f(jnp.asarray(a)).block_until_ready()
    assert len(traces) == 1


def test_with_friction_and_clearance_the_solve_is_the_root_of_the_force_and_differentiable():
    """Friction makes the force no gradient: within a Newton step the wires stand in ``V`` at their
    mean factors (stiffness ``t k``, the compression solved with them too) and the rest of the force
    is frozen; the line search must still find descent, and the solve end at ``F = 0``."""
    rob = robot()
    rng = np.random.default_rng(6)
    q0 = commands(rob, rng)
    direction = jnp.asarray(rng.choice([-1.0, 1.0], rob.n_wires))
    phys = phys_of(rob, [4e-3, 3e-3, 2e-3])
    phys["friction"] = jnp.asarray([0.1, 0.3])
    phys["clearance"] = jnp.asarray([0.1, 0.2])

    @jax.jit
    def tip_f(compliance, q):
        ph = dict(phys, axial_compliance=compliance)
        B = eq.solve(ph, rob.structure, q, jnp.zeros(3), direction)
        return chain_tip(eq.compressed_lengths(ph, rob.structure, q, jnp.zeros(3), direction, B), B)[0], B

    a0 = phys["axial_compliance"]
    _, B = tip_f(a0, q0)
    sm = eq._Sample(phys, rob.structure, q0, jnp.zeros(3), direction, jnp.asarray(False))
    assert float(jnp.max(jnp.abs(sm.force(B.reshape(-1))))) < 1e-9
    J = np.asarray(jax.jit(jax.jacfwd(lambda a: tip_f(a, q0)[0]))(a0))
    fd = np.stack(
        [(tip_f(a0.at[i].add(1e-7), q0)[0] - tip_f(a0.at[i].add(-1e-7), q0)[0]) / 2e-7 for i in range(3)], axis=1
    )
    np.testing.assert_allclose(J, fd, rtol=1e-5, atol=1e-5)
    J = np.asarray(jax.jit(jax.jacfwd(lambda q: tip_f(a0, q)[0]))(q0))
    fd = np.stack(
        [(tip_f(a0, q0.at[i].add(1e-6))[0] - tip_f(a0, q0.at[i].add(-1e-6))[0]) / 2e-6 for i in range(rob.n_wires)],
        axis=1,
    )
    np.testing.assert_allclose(J, fd, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("compliance, friction", [((0.008, 0.005), (0.1, 0.3)), ((0.02, 0.01), (0.2, 0.5))])
def test_a_wire_pulled_alone_with_friction_and_compression_reaches_the_generators_equilibrium(compliance, friction):
    """With friction and the backbone's compression, V's full Newton steps (its rest of the friction
    force frozen) can alternate between two taut sets on the generator's robot for a wire pulled
    alone, the others paid out. Every cold solve of the generator's training commands is the root of
    the force and the generator's own equilibrium (``tests/simulator.py``, MINPACK and BFGS)."""
    import simulator as sim

    from tension_zones.model._robot import Structure

    truth = sim.RobotTruth(compression=compliance, friction=friction)
    rob = sim._Robot(truth)
    robot_ = tz.Robot.from_dict(sim.ROBOT)
    phys = robot_.params()
    phys["EI"] = phys["EI"] * jnp.asarray(truth.EI_factors)
    turn = np.radians(np.asarray(truth.pattern_rotation_deg))[rob.owner]
    phys["route_angles"] = phys["route_angles"] + jnp.asarray(turn)[:, None]
    phys["friction"], phys["axial_compliance"] = jnp.asarray(friction), jnp.asarray(compliance)
    st_ = Structure(robot_.n_wires_per_segment, 1)
    pats = sim.robot_patterns(sim.ROBOT, np.random.default_rng(3), servos=list(range(1, 8)), steps=6)
    Q = np.concatenate([q for label, q in pats if "pull" in label])  # the single-wire pulls
    dQ = np.diff(Q, axis=0, prepend=Q[:1])
    D = np.zeros_like(Q)
    for i in range(len(Q)):  # each wire's last direction of motion
        D[i] = np.where(dQ[i] > 0, 1.0, np.where(dQ[i] < 0, -1.0, D[i - 1] if i else 0.0))

    def cold(q, d):
        B = eq.solve(phys, st_, q, jnp.zeros(3), d).reshape(-1)
        return B, eq._Sample(phys, st_, q, jnp.zeros(3), d, jnp.asarray(False)).force(B)

    X, F = jax.jit(jax.vmap(cold))(jnp.asarray(Q), jnp.asarray(D))
    assert float(jnp.max(jnp.abs(F))) < 1e-9
    x, ref = np.zeros(4), []
    for q, d in zip(Q, D):
        x = rob.equilibrium(q, d, x)
        ref.append(x)
    np.testing.assert_allclose(np.asarray(X), np.array(ref), atol=1e-7)


def test_every_cold_solve_with_friction_compression_clearance_and_a_load_is_a_root():
    """1000 random commands and directions of motion on the three-segment robot, with friction, the
    backbone's compression, the hole clearance, a weight and a tip force at once: every cold solve
    ends at ``F = 0`` (friction's safeguard: from the 8th iteration a step must lower ``|F|``, or a few
    of them would cycle between taut sets)."""
    rob = robot()
    rng = np.random.default_rng(0)
    Q = jnp.asarray(rng.uniform(-3.0, 1.0, (1000, rob.n_wires)))
    D = jnp.asarray(rng.choice([-1.0, 0.0, 1.0], (1000, rob.n_wires)))
    phys = phys_of(rob, [0.01, 0.007, 0.005])
    phys["friction"] = jnp.asarray([0.1, 0.3])
    phys["clearance"] = jnp.asarray([0.1, 0.2])
    phys["gravity"] = jnp.asarray([0.002, 0.0, -0.002])
    f = jnp.asarray([0.1, 0.0, -0.1])

    def residual(q, d):
        B = eq.solve(phys, rob.structure, q, f, d).reshape(-1)
        return jnp.max(jnp.abs(eq._Sample(phys, rob.structure, q, f, d, jnp.asarray(True)).force(B)))

    F = np.asarray(jax.jit(jax.vmap(residual))(Q, D))
    assert F.max() < 1e-9, (F.max(), int((F > 1e-9).sum()))
