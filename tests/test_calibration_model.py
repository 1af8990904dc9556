"""The calibration's model: effects as one parameter vector, path-dependent inputs, one compilation."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
from conftest import two_segments
from hypothesis import given
from hypothesis import strategies as st

import tension_zones as tz
from tension_zones.calibration import Dataset, Problem, RobotModel, compilations, motion_direction
from tension_zones.calibration._model import data_clock, elapsed_hours
from tension_zones.calibration._problem import predict_theta
from tension_zones.calibration.effects import ALL, BY_NAME, library, nominal, play

D3 = tz.Design(3, 20.0, 2.0, wire_stiffness=75.0, backbone_EI=1200.0, preload=2.0)
TWO = two_segments(preload=1.0)


def reference_play(q, c, reset):
    out = np.empty_like(q)
    state = q[0].copy()
    for i, row in enumerate(q):
        if reset[i]:
            state = row.copy()
        state = np.minimum(np.maximum(state, row - c / 2), row + c / 2)
        out[i] = state
    return out


PLAY = jax.jit(play)


@given(
    st.lists(st.floats(-2, 2), min_size=30, max_size=30),
    st.lists(st.floats(0.0, 1.0), min_size=2, max_size=2),
    st.integers(1, 29),
)
def test_play_operator_matches_reference(path, c, cut):
    q = np.stack([np.asarray(path), -np.asarray(path)], axis=1)  # one shape: one compilation
    reset = np.zeros(30)
    reset[cut] = 1.0  # a second recording starts here: the play restarts centred
    np.testing.assert_allclose(
        PLAY(jnp.asarray(q), jnp.asarray(c), jnp.asarray(reset)),
        reference_play(q, np.asarray(c), reset > 0),
        atol=1e-12,
    )


def test_play_derivative_at_zero_is_half_the_direction():
    q = jnp.array([[0.0], [0.5], [0.5], [0.2], [0.2], [0.9]])
    d = jax.jacfwd(lambda c: play(q, c))(jnp.zeros(1))[:, 0, 0]
    np.testing.assert_allclose(d, [0.0, -0.5, -0.5, 0.5, 0.5, -0.5])


def test_motion_direction_keeps_last_direction_and_restarts():
    q = jnp.array([[0.0], [1.0], [1.0], [0.5], [0.5], [0.5], [2.0], [2.0], [1.0]])
    reset = jnp.array([1, 0, 0, 0, 0, 0, 0, 1, 0.0])
    np.testing.assert_array_equal(motion_direction(q)[:, 0], [0, 1, 1, -1, -1, -1, 1, 1, -1])
    np.testing.assert_array_equal(motion_direction(q, reset)[:, 0], [0, 1, 1, -1, -1, -1, 1, 0, -1])


def test_the_drifts_clock_holds_within_the_fit_datas_span():
    """Hours since the fit data's first timestamp, held within its span (a later or earlier recording
    takes the drift at the nearest end; one without timestamps the end); zeros without a clock; the
    drift effect adds its rate times them to every wire's command."""
    fit = dataclasses.replace(_data(5, 3), timestamp=1000.0 + 900.0 * np.arange(5))  # one hour
    clock = data_clock(fit)
    assert clock == (1000.0, 1.0)
    np.testing.assert_allclose(elapsed_hours(fit), [0, 0.25, 0.5, 0.75, 1.0])
    later = dataclasses.replace(_data(3, 3), timestamp=np.array([0.0, 2800.0, 9000.0]))
    np.testing.assert_allclose(elapsed_hours(later, clock), [0.0, 0.5, 1.0])
    np.testing.assert_allclose(elapsed_hours(_data(2, 3), clock), [1.0, 1.0])
    assert data_clock(_data(2, 3)) is None and not np.any(elapsed_hours(_data(2, 3)))
    inputs = RobotModel.of(tz.Robot(D3)).inputs(later, clock)
    out = BY_NAME["drift"].on_inputs(jnp.array([0.4]), inputs, None, {})
    np.testing.assert_allclose(out["q"] - later.q, 0.4 * np.array([[0.0], [0.5], [1.0]]) * np.ones(3))


def _data(n, N, seed=0, frame="base"):
    rng = np.random.default_rng(seed)
    return Dataset(
        sample=np.arange(n),
        q=rng.uniform(-1, 1, (n, N)),
        f=np.zeros((n, N and 3)),
        p=rng.normal(size=(n, 3)) + [0, 0, 20],
        frame=frame,
    )


def test_new_values_other_effects_and_another_robot_never_recompile():
    blocks = nominal("base") + library("base")
    pb = Problem(RobotModel.of(tz.Robot(D3)), tz.Robot(D3), _data(12, 3), blocks)
    pb.fit(pb.null, ["backbone_EI"], np.ones(12), max_iter=2)
    size = compilations()
    other = tz.Robot(
        tz.Design(3, 25.0, 1.5, wire_angles=[0.1, 2.0, 4.0], wire_stiffness=60.0, backbone_EI=900.0, preload=1.0)
    )
    pb2 = Problem(RobotModel.of(other), other, _data(40, 3, seed=1), blocks)  # the same padding bucket
    pb2.fit(
        pb2.null + 0.01, ["backbone_EI", "backlash", "registration", "gravity"], np.ones(40), huber_c=0.3, max_iter=3
    )
    pb2.jacobian(pb2.null, ["backbone_EI", "friction"])
    assert compilations() == size


def test_padding_changes_nothing():
    # the engine pads sample counts to a multiple of PAD (128) at zero weight; results must not notice
    data = _data(40, 3, seed=2)
    model = RobotModel.of(tz.Robot(D3))
    pb = Problem(model, tz.Robot(D3), data, nominal("base") + library("base"))
    theta = pb.null.copy()
    theta[pb.spec.slices()["backlash"]] = [0.1, 0.2, 0.3]
    on = jnp.asarray(pb.on(["backbone_EI", "backlash"]))
    direct = jax.jit(predict_theta, static_argnums=0)(pb.spec, jnp.asarray(theta), on, pb.phys0, model.inputs(data))[
        "p"
    ]
    np.testing.assert_allclose(pb.predict(theta, ["backbone_EI", "backlash"]), direct, atol=1e-12)
    # padded rows carry no weight: the fit of 40 samples equals that of a set whose 41st..64th
    # samples are wildly different (they would pull a fit that saw them)
    wild = Dataset(
        sample=np.arange(64),
        q=np.r_[data.q, np.ones((24, 3))],
        f=np.r_[data.f, np.ones((24, 3))],
        p=np.r_[data.p, np.full((24, 3), 50.0)],
    )
    pb64 = Problem(model, tz.Robot(D3), wild, nominal("base") + library("base"))
    a = pb.fit(pb.null, ["backbone_EI"], np.ones(40), max_iter=10)
    b = pb64.fit(pb64.null, ["backbone_EI"], np.r_[np.ones(40), np.zeros(24)], max_iter=10)
    np.testing.assert_allclose(a, b, atol=1e-12)


def test_every_effect_is_defined_for_any_robot_and_null_means_none():
    """Each effect of the library on a two-segment robot with 3 + 4 wires: its null values leave the
    prediction unchanged, a small change of every parameter moves it, and its sensitivities are
    finite (the score test differentiates there). The model is in pieces (the rod, for the variable
    curvature), the samples carry known tip forces (without a load the rod is constant curvature) and
    timestamps (the drift's clock)."""
    data = _data(30, 7, seed=3, frame="tracker")
    data = dataclasses.replace(
        data, f=np.random.default_rng(5).normal(0.0, 0.3, (30, 3)), timestamp=60.0 * np.arange(30)
    )
    pb = Problem(RobotModel.of(TWO), TWO, data, ALL)  # with the variable curvature on: the rod's program
    sl = pb.spec.slices()
    names = [b.name for b in ALL]
    base = pb.predict(pb.null, names)
    _r, J = pb.jacobian(pb.null, names)
    assert np.all(np.isfinite(J))
    # without the pattern rotation and the offset in the model the registration also turns about the
    # robot's axis and translates (with them, it leaves those to them: see effects/registration.py)
    J = pb.jacobian(pb.null, [n for n in names if n not in ("pattern_rotation", "offset")])[1]
    rng = np.random.default_rng(0)
    for b in ALL:
        theta = pb.null.copy()
        theta[sl[b.name]] += 0.01 * rng.uniform(0.5, 1.5, sl[b.name].stop - sl[b.name].start)
        moved = np.abs(pb.predict(np.clip(theta, pb.lo, pb.hi), names) - base).max()
        assert moved > 1e-6, b.name
        cols = J[:, :, sl[b.name]]
        assert np.all(np.abs(cols).reshape(-1, cols.shape[-1]).max(axis=0) > 0), b.name  # every parameter seen


def test_wire_angle_offsets_are_deviations_when_the_pattern_rotation_is_fitted():
    data = _data(20, 7, seed=4, frame="tracker")
    pb = Problem(RobotModel.of(TWO), TWO, data, ALL)
    sl = pb.spec.slices()
    theta = pb.null.copy()
    theta[sl["wire_angle_offset"]] = 0.05  # a common offset per segment is a rotation of the pattern
    with_rot = ["pattern_rotation", "wire_angle_offset"]
    np.testing.assert_allclose(pb.predict(theta, with_rot), pb.predict(pb.null, with_rot), atol=1e-12)
    assert np.abs(pb.predict(theta, ["wire_angle_offset"]) - pb.predict(pb.null, [])).max() > 1e-3


def test_the_routing_twist_turns_only_the_wires_crossing_segments_they_do_not_end_in():
    """Three segments: a wire of segment o runs through segment j < o turned by the twists between
    them (tau_j + ... + tau_{o-1}), and at its own angle in its own segment; one segment has none."""
    three = tz.Robot([tz.Design(3, 30.0, 2.0), tz.Design(3, 30.0, 2.0), tz.Design(4, 30.0, 2.0)])
    model = RobotModel.of(three)
    phys = model.physical(three)
    tau = np.array([0.1, -0.03])
    got = np.asarray(BY_NAME["routing_twist"].on_params(jnp.asarray(tau), phys, model, {})["route_angles"])
    want = np.array(phys["route_angles"])
    for k, o in enumerate(three.owner):
        for j in range(o):
            want[k, j] += tau[j:o].sum()
    np.testing.assert_allclose(got, want, atol=1e-15)
    assert BY_NAME["routing_twist"].size(RobotModel.of(tz.Robot(D3)), None) == 0


def test_a_fit_on_its_own_rows_equals_the_fit_on_all(monkeypatch):
    """On a large recording a fit evaluates only its weighted samples (a second program); the play's
    path still runs over the whole recording, so the fit must equal the one over every sample."""
    from tension_zones.calibration import _problem
    from tension_zones.calibration.effects import BY_NAME

    rng = np.random.default_rng(7)
    n = 200
    q = np.cumsum(rng.normal(0.0, 0.2, (n, 3)), axis=0)
    data = Dataset(sample=np.arange(n), q=q, f=np.zeros((n, 3)), p=rng.normal(size=(n, 3)) + [0, 0, 20])
    blocks = (BY_NAME["backbone_EI"], BY_NAME["backlash"])
    w = (rng.uniform(size=n) < 0.5).astype(float)
    active = ["backbone_EI", "backlash"]
    pb = Problem(RobotModel.of(tz.Robot(D3)), tz.Robot(D3), data, blocks)
    start = pb.null + np.r_[0.0, 0.1, 0.2, 0.3][: pb.null.size]
    full = pb.fit(start, active, w, max_iter=8)
    monkeypatch.setattr(_problem, "FIT_ROWS_MIN", 64)
    pb = Problem(RobotModel.of(tz.Robot(D3)), tz.Robot(D3), data, blocks)  # (the first fit fixes the rows)
    rows, wk = pb._fit_rows(np.r_[w, np.zeros(pb.n_padded - n)])
    assert len(rows) == 128 and wk.sum() == w.sum()  # 200 -> 256 padded; ~100 weighted -> 128
    np.testing.assert_allclose(pb.fit(start, active, w, max_iter=8), full, rtol=1e-9, atol=1e-12)


def test_evaluations_in_the_fits_program_equal_one_evaluation_and_compile_nothing(monkeypatch):
    """Once fits run on their own rows (and push forward only their free columns), evaluations call
    that program on pieces of the samples, every column or none: the residuals and the Jacobian equal
    one evaluation of every sample and parameter, and no program is compiled for them."""
    from tension_zones.calibration import _problem
    from tension_zones.calibration.effects import BY_NAME

    rng = np.random.default_rng(8)
    n = 300  # 320 padded: two pieces of 192 rows (the second padded)
    q = np.cumsum(rng.normal(0.0, 0.2, (n, 3)), axis=0)
    data = Dataset(sample=np.arange(n), q=q, f=np.zeros((n, 3)), p=rng.normal(size=(n, 3)) + [0, 0, 20])
    blocks = tuple(BY_NAME[k] for k in ("backbone_EI", "backlash", "preload", "wire_stiffness"))
    theta = Problem(RobotModel.of(tz.Robot(D3)), tz.Robot(D3), data, blocks).null + 0.01
    names = [b.name for b in blocks]
    reference = Problem(RobotModel.of(tz.Robot(D3)), tz.Robot(D3), data, blocks).jacobian(theta, names)
    monkeypatch.setattr(_problem, "FIT_ROWS_MIN", 64)
    pb = Problem(RobotModel.of(tz.Robot(D3)), tz.Robot(D3), data, blocks)
    pb.fit(theta, ["backbone_EI", "backlash"], (rng.uniform(size=n) < 0.55).astype(float), max_iter=2)
    assert pb._rows < pb.n_padded  # its own rows (and, by the traced column count, every column)
    size = compilations()
    r, J = pb.jacobian(theta, names)
    np.testing.assert_allclose(r, reference[0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(J, reference[1], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(pb.residuals(theta, names), reference[0], rtol=1e-12, atol=1e-12)
    # some samples only (the score test's held-out ones), in pieces of that program too
    some = np.sort(rng.choice(n, 250, replace=False))
    r, J = pb.jacobian(theta, names, samples=some)
    np.testing.assert_allclose(r, reference[0][some], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(J, reference[1][some], rtol=1e-10, atol=1e-12)
    assert compilations() == size


def test_a_program_compiled_ahead_on_a_thread_is_the_one_the_fits_run():
    from functools import partial

    from tension_zones.calibration import _problem

    data = _data(650, 3, seed=5)  # 768 padded rows: a program no other test makes
    pb = Problem(RobotModel.of(tz.Robot(D3)), tz.Robot(D3), data, nominal("base") + library("base"))
    active, w = ["backbone_EI", "backlash"], np.ones(650)
    before = compilations()
    thread = pb.compile_ahead(active, w)
    assert thread is not None and compilations() == before + 1
    theta = pb.fit(pb.null + 0.01, active, w, max_iter=4)  # waits for the thread's program
    thread.join()
    assert pb.compile_ahead(active, w) is None and compilations() == before + 1
    # the same numbers as the engine jitted and compiled the usual way
    spec, *args = pb._args(
        np.clip(pb.null + 0.01, pb.lo, pb.hi),
        active,
        pb.mask(active),
        np.arange(768),
        np.r_[w, np.zeros(118)],
        np.inf,
        4,
        *pb._fit_cols(pb.mask(active)),
    )
    ref = jax.jit(partial(_problem._engine, spec), compiler_options=_problem.fast_compile_options())(*args)
    np.testing.assert_array_equal(theta, np.asarray(ref[0]))


#: A script that starts compiling a program ahead (one segment, 40 samples) and exits at once.
EXIT_WHILE_COMPILING = """
import sys
import numpy as np
import tension_zones as tz
from tension_zones.calibration import Dataset, Problem, RobotModel
from tension_zones.calibration.effects import library, nominal
robot = tz.Robot(tz.Design(3, 20.0, 2.0))
rng = np.random.default_rng(0)
data = Dataset(sample=np.arange(40), q=rng.uniform(-1, 1, (40, 3)), f=np.zeros((40, 3)), p=rng.normal(size=(40, 3)))
pb = Problem(RobotModel.of(robot), robot, data, nominal("base") + library("base"))
thread = pb.compile_ahead(["backbone_EI", "backlash"], np.ones(40))
print("compiling at exit:", thread.is_alive(), flush=True)
sys.exit(3)
"""


def test_a_script_that_exits_while_a_program_compiles_ends_with_its_status():
    """The interpreter's exit waits for a program compiling on a thread: a thread inside XLA's compiler
    when the interpreter finalises aborted the process (status 134, "FATAL: exception not rethrown")."""
    import subprocess
    import sys

    r = subprocess.run(
        [sys.executable, "-c", EXIT_WHILE_COMPILING], check=False, capture_output=True, text=True, timeout=300
    )
    assert "compiling at exit: True" in r.stdout, r.stdout + r.stderr
    assert r.returncode == 3 and "FATAL" not in r.stderr, r.stderr[-2000:]


def test_the_runner_compiles_the_final_refits_program_ahead_without_workers(monkeypatch):
    from tension_zones.calibration import _fits

    monkeypatch.setattr(_fits, "spare_core", lambda: True)  # (a one-core machine compiles nothing ahead)
    data = _data(1000, 3, seed=6)  # 1024 padded rows: fits on 640 of them, the final refit on all
    pb = Problem(RobotModel.of(tz.Robot(D3)), tz.Robot(D3), data, nominal("base") + library("base"))
    train = np.arange(1000) < 600
    fits = _fits.Fits(pb, train, ~train)
    active = ["backbone_EI", "backlash"]
    with _fits.Runner(fits, 0, warm={"final": (active, "all"), "other": (active, "train")}) as run:
        fits.fit(pb.null, active, max_iter=1)  # the training fits' program (640 rows)
        before = compilations()
        run.ahead("final")
        run.ahead("nothing")  # (not a warm-up program: ignored)
        assert len(run._threads) == 1 and compilations() == before + 1
        theta, _ = run.map("refit_all", [(pb.null, active, False)])[0]
        assert compilations() == before + 1 and np.all(np.isfinite(theta))
    assert run._threads == []  # joined on leaving


def test_only_a_one_segment_rods_program_skips_llvms_optimisation_and_it_fits_the_same():
    """The rod's program of a one-segment robot compiles at LLVM level 0 (it runs little: see
    ``_problem._optimised``); every other program at 3. Its fit is the optimised program's."""
    from functools import partial

    from tension_zones.calibration import _problem

    data = _data(40, 3, seed=7)
    data = dataclasses.replace(data, f=np.random.default_rng(8).normal(0.0, 0.3, (40, 3)))  # a load: a rod
    one = Problem(RobotModel.of(tz.Robot(D3)), tz.Robot(D3), data, nominal("base") + library("base"))
    two = Problem(RobotModel.of(TWO), TWO, _data(40, 7, seed=7), nominal("base") + library("base"))
    rod = ["backbone_EI", "variable_curvature"]
    assert one.spec_for(rod).model.structure.pieces > 1 and two.spec_for(rod).model.structure.pieces > 1
    assert not _problem._optimised(one.spec_for(rod))
    assert _problem._optimised(one.spec_for(["backbone_EI"])) and _problem._optimised(two.spec_for(rod))
    assert _problem._optimised(two.spec_for(["backbone_EI"]))

    w = np.ones(40)
    theta = one.fit(one.null, rod, w, max_iter=6)
    spec, *args = one._args(
        np.clip(one.null, one.lo, one.hi),
        rod,
        one.mask(rod),
        np.arange(one.n_padded),
        np.r_[w, np.zeros(one.n_padded - 40)],
        np.inf,
        6,
        *one._fit_cols(one.mask(rod)),
    )
    ref = jax.jit(partial(_problem._engine, spec), compiler_options=_problem.fast_compile_options(True))(*args)
    assert not np.allclose(theta, one.null)  # (it moved)
    np.testing.assert_allclose(theta, np.asarray(ref[0]), rtol=1e-9, atol=1e-12)
