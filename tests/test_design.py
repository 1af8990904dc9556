import jax
import jax.numpy as jnp
import numpy as np
import pytest

import tension_zones as tz


def test_defaults_and_even_angles():
    d = tz.Design(4, 20.0, 2.0)
    assert d.n_wires == 4
    np.testing.assert_allclose(d.wire_angles, np.radians([0, 90, 180, 270]))
    assert d.dtype == jnp.float64
    assert float(d.wire_stiffness) == tz.DEFAULT_WIRE_STIFFNESS


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"n_wires": 2, "length": 20.0, "pitch_radius": 2.0}, "n_wires"),
        ({"n_wires": 3.0, "length": 20.0, "pitch_radius": 2.0}, "n_wires"),
        ({"n_wires": 3, "length": 0.0, "pitch_radius": 2.0}, "length"),
        ({"n_wires": 3, "length": -1.0, "pitch_radius": 2.0}, "length"),
        ({"n_wires": 3, "length": 20.0, "pitch_radius": 0.0}, "pitch_radius"),
        ({"n_wires": 3, "length": 20.0, "pitch_radius": 2.0, "wire_stiffness": 0.0}, "wire_stiffness"),
        ({"n_wires": 3, "length": 20.0, "pitch_radius": 2.0, "backbone_EI": -1.0}, "backbone_EI"),
        ({"n_wires": 3, "length": 20.0, "pitch_radius": 2.0, "preload": -0.5}, "preload"),
        ({"n_wires": 3, "length": float("nan"), "pitch_radius": 2.0}, "length"),
        ({"n_wires": 3, "length": 20.0, "pitch_radius": float("inf")}, "pitch_radius"),
        ({"n_wires": 3, "length": 20.0, "pitch_radius": 2.0, "wire_angles": [0.0, 1.0]}, "wire_angles"),
        ({"n_wires": 3, "length": 20.0, "pitch_radius": 2.0, "wire_angles": [0.0, 1.0, 2 * np.pi]}, "wire_angles"),
        ({"n_wires": 3, "length": 20.0, "pitch_radius": 2.0, "wire_angles": [0.0, 1.0, np.nan]}, "wire_angles"),
        ({"n_wires": 3, "length": "long", "pitch_radius": 2.0}, "length"),
        ({"n_wires": 3, "length": [1.0, 2.0], "pitch_radius": 2.0}, "length"),
    ],
)
def test_validation_names_field_and_value(kwargs, field):
    with pytest.raises(ValueError, match=field) as e:
        tz.Design(**kwargs)
    assert str(e.value)  # one clear message


def test_validation_message_has_value():
    with pytest.raises(ValueError, match=r"-1\.0"):
        tz.Design(3, -1.0, 2.0)
    with pytest.raises(ValueError, match="coincident wires 1 and 3"):
        tz.Design(3, 20.0, 2.0, wire_angles=[0.0, 1.0, 2 * np.pi])


def test_pytree_static_wire_count_and_no_recompile():
    traces = []

    @jax.jit
    def f(design):
        traces.append(1)
        return tz.tip_pose(design, 1.0, 0.3)[0]

    f(tz.Design(3, 20.0, 2.0))
    f(tz.Design(3, 25.0, 1.5, wire_angles=[0.1, 2.0, 4.0], wire_stiffness=90.0, preload=3.0))
    assert len(traces) == 1, "new values of the same shapes must not recompile"
    f(tz.Design(4, 20.0, 2.0))
    assert len(traces) == 2, "a new wire count is a new shape"
    leaves, _treedef = jax.tree_util.tree_flatten(tz.Design(5, 20.0, 2.0))
    assert len(leaves) == 6 and all(isinstance(x, jax.Array) for x in leaves)


def test_vmap_over_a_family_of_designs():
    base = tz.Design(3, 20.0, 2.0)
    family = jax.vmap(lambda r: base.replace(pitch_radius=r))(jnp.linspace(1.0, 3.0, 5))
    q = jax.vmap(lambda d: tz.wire_lengths(d, 1.0, 0.0))(family)
    assert q.shape == (5, 3)
    np.testing.assert_allclose(q[:, 0], 20.0 + np.linspace(1.0, 3.0, 5) * (1.0 - np.pi / 2))


def test_frozen_and_replace():
    d = tz.Design(3, 20.0, 2.0)
    with pytest.raises(dataclasses_FrozenError()):
        d.length = 3.0
    d2 = d.replace(pitch_radius=3.0)
    assert float(d2.pitch_radius) == 3.0 and float(d.pitch_radius) == 2.0
    with pytest.raises(ValueError, match="pitch_radius"):
        d.replace(pitch_radius=-3.0)
    d5 = d.replace(n_wires=5)
    assert d5.wire_angles.shape == (5,)


def dataclasses_FrozenError():
    import dataclasses

    return dataclasses.FrozenInstanceError


def test_from_dict_roundtrip_and_errors(tmp_path):
    d = tz.Design(4, 20.0, 2.0, wire_angles=np.radians([0, 80, 180, 260]), preload=2.0)
    d2 = tz.Design.from_dict(d.to_dict())
    np.testing.assert_allclose(d2.wire_angles, d.wire_angles)
    assert d2.n_wires == 4 and float(d2.preload) == 2.0
    with pytest.raises(ValueError, match="unknown design key"):
        tz.Design.from_dict({**d.to_dict(), "colour": "red"})
    with pytest.raises(ValueError, match="length_mm"):
        tz.Design.from_dict({"n_wires": 3, "pitch_radius_mm": 2.0})
    with pytest.raises(ValueError, match="wire_angles_deg"):
        tz.Design.from_dict({"n_wires": 3, "length_mm": 20, "pitch_radius_mm": 2, "wire_angles_deg": [0, 90]})
    p = tmp_path / "bad.json"
    p.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        tz.Design.from_json(p)
    with pytest.raises(ValueError, match="does not exist"):
        tz.Design.from_json(tmp_path / "missing.json")


def test_shared_design_files_load():
    import pathlib

    shared = pathlib.Path(__file__).resolve().parents[1].parent / "shared" / "data" / "synthetic"
    files = sorted(shared.glob("*.design.json"))
    if not files:
        pytest.skip("shared data not present")
    for f in files:
        d = tz.Design.from_json(f)
        assert d.n_wires in (3, 4)


def test_float32_design():
    d = tz.Design(3, 20.0, 2.0).astype(jnp.float32)
    p, R = tz.tip_pose(d, jnp.float32(1.0), jnp.float32(0.3))
    assert p.dtype == jnp.float32 and R.dtype == jnp.float32
    J = tz.J_xq(d, jnp.float32(np.pi / 2), jnp.float32(0.3), tz.tension_mask(d, jnp.float32(0.3)))
    assert J.dtype == jnp.float32 and np.all(np.isfinite(J))
    d64 = tz.Design(3, 20.0, 2.0)
    np.testing.assert_allclose(p, tz.tip_pose(d64, 1.0, 0.3)[0], rtol=1e-5)


# -- design files: one line naming the key -------------------------------------------
_BASE = {"n_wires": 3, "length_mm": 20, "pitch_radius_mm": 2}


@pytest.mark.parametrize(
    "change, needle",
    [
        ({"n_wires": "3"}, r"n_wires must be an integer of at least 3, got '3' \(a string\)"),
        ({"n_wires": "3", "wire_angles_deg": [0, 120, 240]}, r"n_wires must be an integer.*'3'"),
        ({"n_wires": True}, r"n_wires must be an integer.*True \(a boolean\)"),
        ({"n_wires": 3.5}, r"n_wires must be an integer.*3\.5"),
        ({"n_wires": None}, r"n_wires must be an integer.*null"),
        ({"length_mm": "20"}, r"length_mm must be a number, got '20' \(a string\)"),
        ({"length_mm": True}, r"length_mm must be a number, got True \(a boolean\)"),
        ({"pitch_radius_mm": None}, r"pitch_radius_mm must be a number, got null"),
        ({"preload_N": [1]}, r"preload_N must be a number, got \[1\] \(a list\)"),
        ({"backbone_EI_Nmm2": {"v": 1}}, r"backbone_EI_Nmm2 must be a number.*\(an object\)"),
        ({"length_mm": -1}, r"length_mm must be positive, got -1\.0"),
        ({"wire_stiffness_N_per_mm": 0}, r"wire_stiffness_N_per_mm must be positive"),
        ({"preload_N": float("nan")}, r"preload_N must be finite"),
        ({"wire_angles_deg": 5}, r"wire_angles_deg must be a list of numbers, got 5"),
        ({"wire_angles_deg": ["a", 1, 2]}, r"wire_angles_deg\[0\] must be a number, got 'a' \(a string\)"),
        ({"wire_angles_deg": [0, True, 2]}, r"wire_angles_deg\[1\] must be a number, got True"),
        ({"wire_angles_deg": [0, [1], 2]}, r"wire_angles_deg\[1\] must be a number, got \[1\] \(a list\)"),
        ({"wire_angles_deg": [0, 90]}, r"wire_angles_deg must have n_wires = 3 entries, got 2 entries"),
    ],
)
def test_design_file_errors_name_the_key(change, needle):
    with pytest.raises(ValueError, match=needle) as e:
        tz.Design.from_dict({**_BASE, **change})
    assert "\n" not in str(e.value)


def test_from_json_names_the_file_and_accepts_a_bom(tmp_path):
    p = tmp_path / "d.design.json"
    p.write_bytes(b"\xef\xbb\xbf" + b'{"n_wires": 3, "length_mm": 20, "pitch_radius_mm": 2}')
    assert tz.Design.from_json(p).n_wires == 3
    p.write_text('{"n_wires": "3", "length_mm": 20, "pitch_radius_mm": 2}')
    with pytest.raises(ValueError, match=r"^design file '.*d\.design\.json': n_wires must be an integer"):
        tz.Design.from_json(p)
    p.write_bytes(b'{"n_wires": 3, "length_mm": \xff}')
    with pytest.raises(ValueError, match="is not UTF-8 text"):
        tz.Design.from_json(p)


def test_missing_physical_keys_are_named_on_request():
    import warnings

    from tension_zones.model import PHYSICAL_KEYS, MissingDesignKeyWarning, missing_physical_keys

    assert PHYSICAL_KEYS == ("wire_stiffness_N_per_mm", "backbone_EI_Nmm2", "preload_N")
    d = {**_BASE, "wire_stiffness_N_per_mm": 80.0}
    assert missing_physical_keys(d) == ["backbone_EI_Nmm2", "preload_N"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # opt-in: no warning by default
        assert float(tz.Design.from_dict(d).backbone_EI) == tz.DEFAULT_BACKBONE_EI
    with pytest.warns(
        MissingDesignKeyWarning,
        match=r"'backbone_EI_Nmm2' \(default 1200 used\), "
        r"'preload_N' \(default 0 used\)",
    ) as rec:
        tz.Design.from_dict(d, warn_missing=True)
    assert len(rec) == 1 and "wire_stiffness" not in str(rec[0].message)
    full = {**d, "backbone_EI_Nmm2": 900.0, "preload_N": 1.0}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tz.Design.from_dict(full, warn_missing=True)


def test_constructor_rejects_booleans_and_strings():
    with pytest.raises(ValueError, match=r"length must be a number, got True"):
        tz.Design(3, True, 2.0)
    with pytest.raises(ValueError, match=r"pitch_radius must be a number, got '2'"):
        tz.Design(3, 20.0, "2")
