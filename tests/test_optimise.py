"""Design optimiser: scenario validation, exact constraint handling, controllability, optima."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import tension_zones as tz
from tension_zones import optimise as opt
from tension_zones.scenario import DEFAULTS, load_scenario, parse_scenario


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
    sc = parse_scenario({"pitch_radius_mm": [0.1, 5.0],
                         "constraints": {"outer_diameter_mm": 6.0, "wire_diameter_mm": 0.4,
                                         "min_wall_mm": 0.3, "min_wire_gap_mm": 0.2}})
    lo, hi = sc.r_bounds(3)
    assert hi == pytest.approx(3.0 - 0.3 - 0.2)
    assert lo == pytest.approx(0.6 / (2 * math.sin(math.pi / 3)))
    assert sc.r_bounds(8)[0] == pytest.approx(0.6 / (2 * math.sin(math.pi / 8)))


# -- parametrisation: every variable vector gives a design that meets the constraints exactly ----
def _sc(arc=None, **kw):
    d = {"free_wire_angles": True, "pitch_radius_mm": [0.8, 2.5],
         "constraints": {"wire_diameter_mm": 0.4, "min_wire_gap_mm": 0.3, "min_wall_mm": 0.2,
                         "outer_diameter_mm": 6.0}}
    if arc is not None:
        d["forbidden_arc_deg"] = arc
    d.update(kw)
    return parse_scenario(d)


@given(st.integers(3, 8), st.floats(-4, 4), st.floats(-4, 4), st.floats(-10, 10),
       st.lists(st.floats(-6, 6), min_size=9, max_size=9), st.booleans())
def test_parametrisation_meets_constraints(n, zr, zk, za, zg, with_arc):
    sc = _sc(arc=[150.0, 210.0] if with_arc else None)
    b = opt._bounds(sc, n)
    if not opt._feasible_arc(sc, n, float(b.r_hi)):
        return
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
