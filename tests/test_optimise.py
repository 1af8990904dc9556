"""Design optimiser: scenario validation, exact constraint handling, controllability, optima."""

import dataclasses
import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import SMALL_SCENARIO as SMALL
from hypothesis import example, given
from hypothesis import strategies as st

import tension_zones as tz
from tension_zones.design import _optimise as opt
from tension_zones.design._layout import hole_gaps, interleaved_angles, with_numbers
from tension_zones.design._scenario import DEFAULTS, load_scenario, parse_scenario


# -- scenario -----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "bad, needle",
    [
        ({"colour": 1}, "unknown scenario key"),
        ({"weights": {"cost": 1}}, "'weights': unknown sub-key"),
        ({"n_wires": [2, 3]}, "'n_wires'"),
        ({"n_wires": "3"}, "'n_wires'"),
        ({"pitch_radius_mm": [3.0, 1.0]}, "'pitch_radius_mm': min 3.0 is larger"),
        ({"pitch_radius_mm": [0.0, 1.0]}, "'pitch_radius_mm': must be > 0"),
        ({"length_mm": -5}, "'length_mm'"),
        ({"joint_uncertainty_mm": float("nan")}, "'joint_uncertainty_mm'"),
        ({"theta_L_deg": [0, 120, 5]}, "'theta_L_deg': must lie within"),
        ({"delta_deg": [0, 90, 0]}, "'delta_deg': step must be positive"),
        ({"min_spread": 1.5}, "'min_spread'"),
        ({"load_N": [1, 2]}, "'load_N'"),
        ({"forbidden_arc_deg": [10, 50]}, "needs free_wire_angles"),
        ({"constraints": {"outer_diameter_mm": 1.0}}, "no pitch radius fits"),
        ({"optimizer": {"starts": 0}}, "'optimizer.starts'"),
        ({"free_wire_angles": "yes"}, "'free_wire_angles'"),
    ],
)
def test_scenario_errors_name_the_key(bad, needle):
    with pytest.raises(ValueError, match=needle):
        parse_scenario(bad)


def test_scenario_defaults_and_file(tmp_path):
    sc = parse_scenario({})
    assert sc.n_wires == tuple(DEFAULTS["n_wires"]) and sc.min_spread == 0.25
    p = tmp_path / "s.json"
    p.write_text('{"n_wires": [4], "theta_L_deg": [10, 80, 10]}')
    sc = load_scenario(p)
    np.testing.assert_allclose(np.degrees(sc.theta_L), np.arange(10, 81, 10))
    with pytest.raises(ValueError, match="not valid JSON"):
        p.write_text("{")
        load_scenario(p)


def test_geometric_radius_bounds():
    sc = parse_scenario(
        {
            "pitch_radius_mm": [0.1, 5.0],
            "constraints": {
                "outer_diameter_mm": 6.0,
                "wire_diameter_mm": 0.4,
                "min_wall_mm": 0.3,
                "min_wire_gap_mm": 0.2,
            },
        }
    )
    lo, hi = sc.r_bounds(3)
    assert hi == pytest.approx(3.0 - 0.3 - 0.2)
    assert lo == pytest.approx(0.6 / (2 * math.sin(math.pi / 3)))
    assert sc.r_bounds(8)[0] == pytest.approx(0.6 / (2 * math.sin(math.pi / 8)))


# -- parametrisation: every variable vector gives a design that meets the constraints exactly ----
def _sc(arc=None, **kw):
    d = {
        "free_wire_angles": True,
        "pitch_radius_mm": [0.8, 2.5],
        "constraints": {"wire_diameter_mm": 0.4, "min_wire_gap_mm": 0.3, "min_wall_mm": 0.2, "outer_diameter_mm": 6.0},
    }
    if arc is not None:
        d["forbidden_arc_deg"] = arc
    d.update(kw)
    return parse_scenario(d)


@example(6, 0.0, 0.0, 0.0, [0.0] * 9, True)  # regression: smallest radius with a forbidden arc
@given(
    st.integers(3, 8),
    st.floats(0, 1),
    st.floats(0, 1),
    st.floats(-10, 10),
    st.lists(st.floats(-6, 6), min_size=9, max_size=9),
    st.booleans(),
)
def test_parametrisation_meets_constraints(n, zr, zk, za, zg, with_arc):
    sc = _sc(arc=[150.0, 210.0] if with_arc else None)
    lo, hi = opt._r_range(sc, n)
    if lo > hi:  # no room for n wires: the optimiser reports the count infeasible
        return
    b = opt._bounds(sc, n)
    zg = jnp.asarray(zg[: n + 1 if with_arc else n])
    z = {"r": jnp.asarray(zr), "k": jnp.asarray(zk), "a0": jnp.asarray(za), "gaps": zg}
    d = opt._design(z, b, n, True, with_arc, opt._base(sc, n))
    r = float(d.pitch_radius)
    assert float(b.r_lo) - 1e-12 <= r <= float(b.r_hi) + 1e-12
    assert 55.0 - 1e-9 <= float(d.wire_stiffness) <= 105.0 + 1e-9
    a = np.sort(np.mod(np.asarray(d.wire_angles), 2 * np.pi))
    gaps = np.diff(np.concatenate([a, a[:1] + 2 * np.pi]))
    chords = 2 * r * np.sin(gaps / 2)
    assert np.all(chords >= 0.4 + 0.3 - 1e-9), "neighbouring wire holes keep the gap"
    if with_arc:
        lo, hi = np.radians(150.0), np.radians(210.0)
        for ang in np.asarray(d.wire_angles):
            # the wire hole's edge keeps the gap from the forbidden arc
            rel = np.mod(ang - lo, 2 * np.pi)
            assert rel > hi - lo
            dist = min(rel - (hi - lo), 2 * np.pi - rel)
            assert 2 * r * np.sin(dist / 2) >= 0.2 + 0.3 - 1e-9


# -- controllability --------------------------------------------------------------------------
def test_controllability_is_checked_between_grid_points():
    # four evenly spaced wires rotated so that no 10-deg grid direction hits a wire line: under the
    # strict rule still one taut wire on those lines, so still infeasible over the continuous range
    task = {
        "n_wires": [4],
        "delta_deg": [0.0, 350.0, 10.0],
        "theta_L_deg": [40.0, 80.0, 40.0],
        "weights": {"deflection": 0.0},
    }
    sc = parse_scenario({**task, "strict_controllability": True})
    rotated = tz.Design(4, 20.0, 2.0, wire_angles=np.radians([5.0, 95.0, 185.0, 275.0]))
    row = opt.evaluate_design(sc, rotated)
    assert not row["feasible"] and row["min_spread"] == 0.0
    # the default rule: a one-wire sector of finite width (265-268 deg) between grid points
    skew = tz.Design(4, 20.0, 2.0, wire_angles=np.radians([2.0, 92.0, 185.0, 272.0]))
    row = opt.evaluate_design(parse_scenario(task), skew)
    assert not row["feasible"] and row["min_spread"] == 0.0 and row["spread_violations"] == 1
    sc = parse_scenario(
        {
            "n_wires": [4],
            "delta_deg": [0.0, 350.0, 10.0],
            "theta_L_deg": [40.0, 80.0, 40.0],
            "weights": {"deflection": 0.0},
        }
    )
    five = opt.evaluate_design(sc, tz.Design(5, 20.0, 2.0))
    assert five["feasible"] and five["min_spread"] > 0.5
    # a range that excludes every wire line: the four-wire design is fine there
    sc2 = parse_scenario(
        {
            "n_wires": [4],
            "delta_deg": [10.0, 80.0, 10.0],
            "theta_L_deg": [40.0, 80.0, 40.0],
            "weights": {"deflection": 0.0},
        }
    )
    assert opt.evaluate_design(sc2, tz.Design(4, 20.0, 2.0))["feasible"]


def test_spread_matches_svd_and_flags_one_wire():
    d = tz.Design(3, 20.0, 2.0, wire_angles=np.radians([10.0, 100.0, 250.0]))
    for delta in np.radians(np.arange(0.0, 360.0, 7.0)):
        m = np.asarray(tz.tension_mask(d, delta)) > 0
        dk = delta + np.asarray(d.wire_angles)
        U = np.stack([np.cos(dk), np.sin(dk)], axis=1)[m]
        ref = np.linalg.svd(U, compute_uv=False)[-1] if U.shape[0] >= 2 else 0.0
        assert float(opt.spread(d, delta)) == pytest.approx(ref, abs=1e-12)
    even = tz.Design(3, 20.0, 2.0)
    assert float(opt.spread(even, 0.0)) == 0.0  # one taut wire: not controllable
    g = jax.grad(lambda a: opt.spread(d.replace(wire_angles=a), 0.7))(d.wire_angles)
    assert np.all(np.isfinite(g))


# -- optima -------------------------------------------------------------------------------------
RESTRICTED = {
    "n_wires": [3],
    "free_wire_angles": True,
    "pitch_radius_mm": [2.0, 2.0],
    "wire_stiffness_N_per_mm": [75.0, 75.0],
    "theta_L_deg": [20.0, 80.0, 20.0],
    "delta_deg": [-45.0, 45.0, 5.0],
    "weights": {"position_uncertainty": 1.0, "deflection": 0.0, "wire_count": 0.0},
    "optimizer": {"starts": 6, "steps": 250, "learning_rate": 0.05},
}


def _brute_force(sc, step_deg, centre=None, half_width=None):
    """Exact objective of every 3-wire layout on an angle grid (optionally a box around `centre`)."""
    if centre is None:
        axes = [np.radians(np.arange(0.0, 360.0, step_deg))] * 3
    else:
        axes = [c + np.radians(np.arange(-half_width, half_width + 1e-9, step_deg)) for c in centre]
    A = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    r = sc.pitch_radius[0]
    srt = np.sort(np.mod(A, 2 * np.pi), axis=1)
    gaps = np.diff(np.concatenate([srt, srt[:, :1] + 2 * np.pi], axis=1), axis=1)
    ok_gap = np.all(2 * r * np.sin(gaps / 2) >= sc.wire_diameter + sc.min_wire_gap - 1e-12, axis=1)
    A = A[ok_gap]
    task = opt._task(sc)
    base = tz.Design(3, sc.length, r, wire_stiffness=sc.wire_stiffness[0], backbone_EI=sc.backbone_EI)

    @jax.jit
    def score(angles):
        def one(a):
            _, exact, pieces = opt._objective(base.replace(wire_angles=a), task, 3, 1.0, False)
            return exact, pieces["violations"]

        return jax.lax.map(one, angles, batch_size=512)

    exact, viol = (np.asarray(x) for x in score(jnp.asarray(A)))
    feasible = viol == 0
    i = np.argmin(np.where(feasible, exact, np.inf))
    return exact[i], A[i]


@pytest.mark.slow
def test_restricted_directions_match_brute_force_and_even_layout_is_infeasible():
    sc = parse_scenario(RESTRICTED)
    even = opt.evaluate_design(sc, tz.Design(3, 20.0, 2.0))
    assert not even["feasible"] and even["spread_violations"] > 0  # delta = 0: one taut wire
    coarse, a = _brute_force(sc, 10.0)
    fine, _ = _brute_force(sc, 1.0, centre=a, half_width=10.0)
    res = opt.optimize(sc, progress=False)
    best = res["best"]
    assert best is not None and best["feasible"]
    assert best["objective"] <= fine * 1.01, (best, fine, coarse)
    # what the optimiser reports is the exact objective of the design it returns
    d = tz.Design(3, 20.0, 2.0, wire_angles=np.radians(best["wire_angles_deg"]))
    assert opt.evaluate_design(sc, d)["objective"] == pytest.approx(best["objective"], rel=1e-9)


@pytest.mark.slow
def test_known_optimum_pitch_radius_and_stiffness_at_upper_bounds():
    # dp_max ~ L / r and the deflection falls with r and k_w: with no geometric limit and no cost
    # on them the optimum is both upper bounds
    res = opt.optimize(parse_scenario(SMALL), progress=False)
    (row,) = res["per_wire_count"]
    assert row["pitch_radius_mm"] == pytest.approx(2.5, rel=1e-9)
    assert row["wire_stiffness_N_per_mm"] == pytest.approx(105.0, rel=1e-9)
    assert res["evaluations"] == 2 * 41 and len(res["history"]["3"]) == 40
    # an outer diameter that binds moves the optimum to the geometric limit
    limited = parse_scenario(
        {**SMALL, "constraints": {"outer_diameter_mm": 4.0, "wire_diameter_mm": 0.3, "min_wall_mm": 0.2}}
    )
    (row,) = opt.optimize(limited, progress=False)["per_wire_count"]
    assert row["pitch_radius_mm"] == pytest.approx(2.0 - 0.2 - 0.15, rel=1e-9)


@pytest.mark.slow
def test_new_numbers_of_the_same_shapes_do_not_recompile():
    opt.optimize(parse_scenario(SMALL), progress=False)
    before = opt.programs()
    other = {
        **SMALL,
        "length_mm": 31.0,
        "pitch_radius_mm": [0.9, 2.2],
        "joint_uncertainty_mm": 0.7,
        "load_N": [0.0, 3.0, 1.0],
        "backbone_EI_Nmm2": 900.0,
        "theta_L_deg": [35.0, 85.0, 25.0],
        "delta_deg": [5.0, 355.0, 25.0],
        "weights": {"position_uncertainty": 2.0, "deflection": 0.5, "wire_count": 0.3},
        "optimizer": {"starts": 2, "steps": 40, "learning_rate": 0.2, "seed": 5},
    }
    opt.optimize(parse_scenario(other), progress=False)
    assert opt.programs() == before


def test_a_later_process_runs_the_stored_program_without_tracing(monkeypatch):
    """The optimiser's program is kept on disk before tracing (``_xla.stored_program``): with this
    process's programs forgotten, as in a new process, the run loads it, traces nothing and gives the
    same result, bit for bit."""
    sc = parse_scenario(SMALL)
    first = opt.optimize(sc, progress=False)
    monkeypatch.setattr(opt, "_RUNS", {})

    def traced(*args, **kwargs):
        raise AssertionError("the optimiser's program was traced again")

    monkeypatch.setattr(opt, "_run_starts", traced)
    again = opt.optimize(sc, progress=False)
    first.pop("seconds"), again.pop("seconds")
    assert json.dumps(again, default=str) == json.dumps(first, default=str)


@pytest.mark.slow
def test_gradients_agree_with_finite_differences_away_from_switches():
    from tension_zones._numerics import frozen_masks

    sc = parse_scenario(
        {"n_wires": [4], "free_wire_angles": True, "theta_L_deg": [40.0, 70.0, 30.0], "delta_deg": [20.0, 70.0, 25.0]}
    )
    n, task, b, base = 4, opt._task(sc), opt._bounds(sc, 4), opt._base(sc, 4)
    # wires near 0, 95, 180, 275 deg: at delta = 20..70 deg no wire is near a zone boundary
    z = {
        "r": jnp.asarray(0.4),
        "k": jnp.asarray(0.6),
        "a0": jnp.asarray(0.05),
        "gaps": jnp.asarray([0.1, -0.05, 0.08, -0.1]),
    }

    def f(z):
        return opt._objective(opt._design(z, b, n, True, False, base), task, n, 5.0, True)[0]

    flat, unravel = jax.flatten_util.ravel_pytree(z)
    with frozen_masks():  # the exact gradient of the piecewise-smooth objective
        g_exact = jax.jit(lambda x: jax.grad(lambda y: f(unravel(y)))(x))(flat)
    g_st = jax.jit(lambda x: jax.grad(lambda y: f(unravel(y)))(x))(flat)
    fj = jax.jit(lambda x: f(unravel(x)))
    h = 1e-6
    fd = np.array([(fj(flat.at[i].add(h)) - fj(flat.at[i].add(-h))) / (2 * h) for i in range(flat.size)])
    np.testing.assert_allclose(g_exact, fd, rtol=1e-5, atol=1e-7)
    # the straight-through surrogates only add terms that are small this far from any switch
    np.testing.assert_allclose(g_st, fd, rtol=0.05, atol=0.05 * np.abs(fd).max())


@pytest.mark.parametrize("n", [3, 4])
def test_compact_forms_give_the_unrolled_values(n):
    """The optimiser traces its objective in the compact forms (per-wire arrays, the statics' free sets
    vectorised): the same per-pose terms and controllability as the unrolled forms the sweeps use."""
    from tension_zones._numerics import compact_programs

    sc = parse_scenario({"n_wires": [n], "theta_L_deg": [10.0, 80.0, 35.0], "delta_deg": [0.0, 350.0, 50.0]})
    d = tz.Design(n, 20.0, 2.0, wire_stiffness=70.0, wire_angles=np.radians(np.arange(n) * 360.0 / n + 7.0))
    plain = jax.jit(lambda d: opt._grid_terms(d, opt._task(sc)))(d)
    with compact_programs():
        compact = jax.jit(lambda d: opt._grid_terms(d, opt._task(sc)))(d)
    for a, b in zip(jax.tree_util.tree_leaves(plain), jax.tree_util.tree_leaves(compact)):
        np.testing.assert_allclose(np.asarray(a, float), np.asarray(b, float), rtol=1e-10, atol=1e-12)


def test_design_readme_documents_every_scenario_key_and_default():
    """The scenario reference lives beside the code (tension_zones/design/README.md)."""
    import json
    import pathlib

    from tension_zones.design._scenario import DOC

    readme = (pathlib.Path(tz.__file__).parent / "design" / "README.md").read_text()
    assert set(DOC) == set(DEFAULTS)
    for key, value in DEFAULTS.items():
        assert f"| `{key}` | `{json.dumps(value)}` | {DOC[key]} |" in readme, key


@given(st.integers(3, 4), st.lists(st.floats(0.0, 2 * np.pi), min_size=4, max_size=4))
def test_strict_full_circle_controllability_needs_five_wires(n, angles):
    # the open half-planes of a direction and its opposite hold at most n - 1 wires when their
    # dividing line passes through a wire: three or four wires always leave a direction with one
    # (a single direction for four even wires: a violation only with strict_controllability)
    a = np.sort(np.mod(angles[:n], 2 * np.pi))
    if np.min(np.diff(np.concatenate([a, a[:1] + 2 * np.pi]))) < 1e-3:
        return  # coincident wires are not a design
    d = tz.Design(n, 20.0, 2.0, wire_angles=a)
    spreads = jax.vmap(lambda x: opt.spread(d, x))(opt.zone_boundaries(d))
    assert float(jnp.min(spreads)) == 0.0
    five = tz.Design(5, 20.0, 2.0)
    assert float(jnp.min(jax.vmap(lambda x: opt.spread(five, x))(opt.zone_boundaries(five)))) > 0.5


# -- zero width: single directions are reported, finite sectors are violations ----------
FULL_CIRCLE = {
    "theta_L_deg": [30.0, 80.0, 25.0],
    "delta_deg": [0.0, 360.0, 10.0],
    "pitch_radius_mm": [1.0, 2.5],
    "weights": {"position_uncertainty": 1.0, "deflection": 0.0, "wire_count": 0.0},
    "optimizer": {"starts": 2, "steps": 40, "learning_rate": 0.1},
}


@pytest.mark.slow
def test_four_even_wires_over_a_full_circle_are_feasible_and_reach_the_radius_bound():
    res = opt.optimize(parse_scenario({**FULL_CIRCLE, "n_wires": [4]}), progress=False)
    best = res["best"]
    assert best is not None and best["feasible"] and best["n_wires"] == 4
    assert best["pitch_radius_mm"] == pytest.approx(2.5, rel=1e-9)  # dp_max ~ L / r
    assert best["spread_violations"] == 0 and best["min_spread"] == pytest.approx(1.0)
    # one taut wire exactly along each wire's line: reported, not counted
    assert best["zero_width_directions_deg"] == [0.0, 90.0, 180.0, 270.0]
    assert res["strict_controllability"] is False


def test_three_even_wires_stay_infeasible_and_strict_keeps_the_old_rule():
    sc = parse_scenario(FULL_CIRCLE)
    three = opt.evaluate_design(sc, tz.Design(3, 20.0, 2.0))
    # the three one-wire sectors are 60 deg wide: finite, so violations under either rule
    assert not three["feasible"] and three["spread_violations"] == 3
    assert three["zero_width_directions_deg"] == []
    strict = parse_scenario({**FULL_CIRCLE, "strict_controllability": True})
    assert not opt.evaluate_design(strict, tz.Design(3, 20.0, 2.0))["feasible"]
    four = opt.evaluate_design(strict, tz.Design(4, 20.0, 2.0))
    # the old rule: grid directions 0, 90, 180, 270, 360 and the 8 zone boundaries, one wire each
    assert not four["feasible"] and four["spread_violations"] == 13 and four["min_spread"] == 0.0
    assert four["zero_width_directions_deg"] == [0.0, 90.0, 180.0, 270.0]
    old = opt._range_spread(tz.Design(4, 20.0, 2.0), opt._task(strict))
    assert int(jnp.sum(old < strict.min_spread)) == four["spread_violations"]


def test_zero_width_at_the_ends_of_a_partial_range_and_a_single_direction():
    four = tz.Design(4, 20.0, 2.0)
    part = parse_scenario({**FULL_CIRCLE, "delta_deg": [0.0, 90.0, 10.0]})
    row = opt.evaluate_design(part, four)
    assert row["feasible"] and row["zero_width_directions_deg"] == [0.0, 90.0]
    # a task of one direction, exactly along a wire: that direction is all it needs (strict there)
    one = parse_scenario({**FULL_CIRCLE, "delta_deg": [90.0, 90.0, 10.0]})
    assert not opt.evaluate_design(one, four)["feasible"]
    assert opt.evaluate_design(parse_scenario({**FULL_CIRCLE, "delta_deg": [45.0, 45.0, 10.0]}), four)["feasible"]


_sector_min = jax.jit(lambda d, task: jnp.min(opt._sector_spread(d, task)))


@given(st.lists(st.floats(0.0, 2 * np.pi), min_size=4, max_size=4), st.floats(0.4, 2.7))
def test_four_wires_need_opposite_wires_opposite(angles, gap):
    """Without zero width, four wires pass a full circle only when opposite wires are diametrically
    opposite (else three consecutive wires span less than 180 deg: a one-wire sector of finite width)."""
    task = opt._task(parse_scenario(FULL_CIRCLE))
    a = np.sort(np.mod(angles, 2 * np.pi))
    gaps = np.diff(np.concatenate([a, a[:1] + 2 * np.pi]))
    if np.min(gaps) < 1e-3:
        return  # coincident wires are not a design
    opposite = abs(gaps[0] - gaps[2]) < 1e-9 and abs(gaps[1] - gaps[3]) < 1e-9
    got = float(_sector_min(tz.Design(4, 20.0, 2.0, wire_angles=a), task))
    assert (got > 0.0) == opposite, (np.degrees(a), got)
    par = tz.Design(4, 20.0, 2.0, wire_angles=np.array([0.0, gap, np.pi, np.pi + gap]) + a[0])
    assert float(_sector_min(par, task)) == pytest.approx(np.sqrt(1 - abs(np.cos(gap))), rel=1e-9)


def test_scenario_strict_controllability_must_be_a_boolean():
    with pytest.raises(ValueError, match="'strict_controllability': must be true or false"):
        parse_scenario({"strict_controllability": "yes"})
    assert parse_scenario({}).strict_controllability is False


# -- several segments ------------------------------------------------------------------------------
TWO = json.loads(tz.example_path("design/two_segments.scenario.json").read_text())


def test_a_one_segment_scenario_in_the_segments_form_is_the_one_segment_scenario():
    """Every per-segment key moved into a ``segments`` entry of one: the same scenario, the same result."""
    flat = {**SMALL, "length_mm": 25.0, "preload_N": 1.0, "constraints": {"outer_diameter_mm": 4.5}}
    seg_keys = ("n_wires", "length_mm", "pitch_radius_mm", "wire_stiffness_N_per_mm", "preload_N", "constraints")
    form = {k: v for k, v in flat.items() if k not in seg_keys}
    form["segments"] = [{k: flat[k] for k in seg_keys}]
    a, b = parse_scenario(flat), parse_scenario(form)
    for f in dataclasses.fields(a):
        if f.name != "raw":
            np.testing.assert_equal(getattr(a, f.name), getattr(b, f.name), err_msg=f.name)
    fast = {"optimizer": {"starts": 2, "steps": 3}}
    ra, rb = (opt.optimize(parse_scenario({**d, **fast}), progress=False) for d in (flat, form))
    assert {**ra, "seconds": 0} == {**rb, "seconds": 0}


def test_interleaved_wires_keep_every_disk_s_holes_apart():
    for counts in [(3, 3), (4, 3), (3, 4, 5), (4, 4, 4), (6, 4)]:
        angles = interleaved_angles(counts)
        gaps = hole_gaps(angles)
        assert min(gaps) > 1e-6 and gaps == sorted(gaps), counts  # distal disks hold fewer holes
        lcm = math.lcm(*counts)
        assert gaps[0] >= 2 * math.pi / (len(counts) * lcm) - 1e-12  # the lattice argument's bound
    # equal counts: the first disk's holes evenly spaced; the shipped two-segment design's layout
    assert hole_gaps(interleaved_angles((3, 3)))[0] == pytest.approx(math.pi / 3)
    np.testing.assert_allclose(np.degrees(interleaved_angles((3, 3))[1]), [60.0, 180.0, 300.0])
    # a disk's pitch radius keeps its holes apart: four wires and three distal ones 15 deg apart
    r_lo = opt._chain_bounds(parse_scenario(TWO), (4, 3)).r_lo
    assert float(r_lo[0]) == pytest.approx(max(1.5, 0.5 / (2 * math.sin(math.radians(7.5)))))


def test_chain_spread_of_one_segment_is_the_segment_s_spread():
    d = tz.Design(4, 20.0, 2.0, wire_angles=np.radians([10.0, 100.0, 170.0, 260.0]))
    robot = tz.Robot(d)
    for delta in np.radians(np.arange(3.0, 360.0, 11.0)):
        B = np.array([[0.6 * np.cos(delta), -0.6 * np.sin(delta)]])
        assert float(opt.chain_spread(robot, B)) == pytest.approx(float(opt.spread(d, delta)), abs=1e-12)


def _two(**change):
    segments = [{**TWO["segments"][0]}, {**TWO["segments"][1], "n_wires": [4]}]
    return parse_scenario({**TWO, "segments": segments, **change})


@pytest.mark.slow
def test_a_robot_s_optimum_beats_its_start_and_is_what_a_fresh_evaluation_gives():
    """With the deflection term on (a tip load): the best robot's objective and pieces are what a fresh
    evaluation of its design file gives, and no worse than the mid-range start's."""
    sc = _two(load_N=[0.5, 0.0, 0.0], weights={"position_uncertainty": 1.0, "deflection": 1.0, "wire_count": 0.05})
    res = opt.optimize(sc, progress=False)
    best = res["best"]
    assert res["segments"] == 2 and best["feasible"] and best["n_wires"] == [4, 4]
    robot = tz.Robot.from_dict(best["design"])  # the best robot as a design file
    again = opt.evaluate_design(sc, robot)
    assert again["objective"] == pytest.approx(best["objective"], rel=1e-9)
    assert again["worst_position_uncertainty_mm"] == pytest.approx(best["worst_position_uncertainty_mm"], rel=1e-9)
    assert again["worst_deflection_mm"] == pytest.approx(best["worst_deflection_mm"], rel=1e-9)
    assert best["worst_deflection_mm"] > 0 and best["statics_infeasible_poses"] == 0
    # start 0 is every box variable mid-range: the optimum is no worse
    b = opt._chain_bounds(sc, (4, 4))
    ends = {"pitch_radius": (b.r_lo, b.r_hi), "wire_stiffness": (b.k_lo, b.k_hi), "preload": (b.p_lo, b.p_hi)}
    mid = {f: 0.5 * (np.asarray(lo) + np.asarray(hi)) for f, (lo, hi) in ends.items()}
    start = opt.evaluate_design(sc, with_numbers(opt._base_robot(sc, (4, 4)), **mid))
    assert start["feasible"] and best["objective"] <= start["objective"]
    assert res["history"]["4+4"][-1] == pytest.approx(best["objective"]) and len(res["history"]["4+4"]) == sc.steps
    # each disk's hole circle within its outer diameter and its range; every wire routed on it
    assert best["pitch_radius_mm"][1] <= 3.0 - 0.2 - 0.15 + 1e-12 and best["pitch_radius_mm"][0] <= 4.0
    np.testing.assert_allclose(np.asarray(robot.route_radii)[4:, 0], best["pitch_radius_mm"][0])


@pytest.mark.slow
def test_new_numbers_of_a_robot_s_shapes_do_not_recompile():
    opt.optimize(_two(weights={"deflection": 0.0}), progress=False)
    before = opt.programs()
    segments = [
        {**TWO["segments"][0], "length_mm": 50.0, "pitch_radius_mm": [1.0, 3.5], "preload_N": [0.5, 1.0]},
        {**TWO["segments"][1], "n_wires": [4], "length_mm": 20.0, "backbone_EI_Nmm2": 900.0},
    ]
    other = {
        **TWO,
        "segments": segments,
        "max_bend_deg": 80.0,
        "joint_uncertainty_mm": 0.7,
        "min_spread": 0.4,
        "weights": {"position_uncertainty": 2.0, "deflection": 0.0, "wire_count": 0.3},
        "optimizer": {**TWO["optimizer"], "learning_rate": 0.2, "seed": 5},
    }
    opt.optimize(parse_scenario(other), progress=False)
    assert opt.programs() == before


def test_a_loaded_robot_s_new_numbers_do_not_recompile():
    """With the deflection term on (a tip load): another load, weights, geometry, stiffness, preload
    and step size run the program compiled for the first scenario."""
    small = {"samples": 16, "optimizer": {"starts": 1, "steps": 3, "learning_rate": 0.1}}
    opt.optimize(_two(**small), progress=False)
    before = opt.programs()
    segments = [
        {**TWO["segments"][0], "length_mm": 45.0, "backbone_EI_Nmm2": 3000.0, "wire_stiffness_N_per_mm": [70.0, 70.0]},
        {**TWO["segments"][1], "n_wires": [4], "pitch_radius_mm": [1.5, 2.5], "preload_N": [0.5, 1.5]},
    ]
    other = {
        **TWO,
        **small,
        "segments": segments,
        "load_N": [0.2, -0.4, 0.3],
        "weights": {"position_uncertainty": 0.5, "deflection": 3.0, "wire_count": 0.1},
        "optimizer": {**small["optimizer"], "learning_rate": 0.05, "seed": 2},
    }
    res = opt.optimize(parse_scenario(other), progress=False)
    assert opt.programs() == before
    assert res["best"]["worst_deflection_mm"] > 0  # the deflection term ran


def test_a_robot_s_deflection_term_is_its_worst_reduced_deflection_under_the_tip_load():
    """The objective's pieces against the robot's compliance (``config_compliance``, itself checked against
    an independent reference in test_chain) at each of the task's configurations, under a load off every
    axis; a three-wire distal segment cannot steer every configuration of the disk, so infeasible."""
    weights = {"position_uncertainty": 1.0, "deflection": 2.0, "wire_count": 0.05}
    sc = parse_scenario({**TWO, "load_N": [0.5, 0.2, -0.3], "weights": weights})
    robot = with_numbers(opt._base_robot(sc, (4, 3)), pitch_radius=[3.0, 2.0], preload=[0.0, 0.5])
    row = opt.evaluate_design(sc, robot)
    c = jax.jit(jax.vmap(lambda B: tz.config_compliance(robot, B, sc.load)))(sc.configs)
    ok = np.asarray(c["feasible"]) & np.isfinite(np.asarray(c["deflection_mm_reduced"]))
    worst = np.max(np.where(ok, c["deflection_mm_reduced"], 0.0))
    assert row["worst_deflection_mm"] == pytest.approx(worst, rel=1e-12) and worst > 0
    assert row["statics_infeasible_poses"] == int(np.sum(~ok))
    assert row["objective"] == pytest.approx(row["worst_position_uncertainty_mm"] + 2.0 * worst + 0.05 * 7, rel=1e-12)
    assert row["spread_violations"] > 0 and not row["feasible"]


def test_a_scenario_for_a_robot_takes_what_it_leaves_out_from_the_robot():
    """``for_robot``: a segment's own key first, then the file's top level, then the robot's value (a
    one-value range: fixed); the joint uncertainty is the largest play unless the scenario sets it."""
    robot = tz.Robot.from_json(tz.example_path("design/two_segments.design.json"))
    d = {"segments": [{}, {"pitch_radius_mm": [1.0, 2.0]}], "n_wires": [3, 4], "max_bend_deg": 40.0, "samples": 8}
    sc = parse_scenario(d, robot, play=[0.1, 0.3, 0.0, 0.2, 0.1, 0.1])
    a, b = robot.segments
    assert [s.n_wires for s in sc.segments] == [(3, 4), (3, 4)]  # the file's top level
    assert sc.segments[0].pitch_radius == (float(a.pitch_radius),) * 2  # the robot's, fixed
    assert sc.segments[1].pitch_radius == (1.0, 2.0)  # the segment's own
    assert [s.length for s in sc.segments] == [float(a.length), float(b.length)]
    assert [s.backbone_EI for s in sc.segments] == [float(a.backbone_EI), float(b.backbone_EI)]
    assert sc.dq == pytest.approx(0.3)
    assert parse_scenario({**d, "joint_uncertainty_mm": 0.5}, robot, play=[0.3]).dq == 0.5
    with pytest.raises(ValueError, match="'segments': has 3 entries; the design file has 2 segment"):
        parse_scenario({**d, "segments": [{}, {}, {}]}, robot)


def test_optimize_from_a_robot_reports_the_robot_itself_as_the_start():
    """``optimize(..., start=robot)``: ``start`` is the robot as it is (its own routing) under the
    scenario, what ``evaluate_design`` gives; fixed values stay the robot's in every result."""
    robot = tz.Robot.from_json(tz.example_path("design/two_segments.design.json"))
    d = {"max_bend_deg": 40.0, "samples": 16, "weights": {"deflection": 0.0}, "optimizer": {"starts": 1, "steps": 2}}
    sc = parse_scenario(d, robot)
    res = opt.optimize(sc, progress=False, start=robot)
    assert res["start"] == opt.evaluate_design(sc, robot)
    assert res["start"]["design"] == robot.to_dict()
    assert [r["n_wires"] for r in res["per_wire_count"]] == [list(robot.n_wires_per_segment)]
    assert res["per_wire_count"][0]["pitch_radius_mm"] == [float(s.pitch_radius) for s in robot.segments]
