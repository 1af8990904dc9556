"""OpenCR reader (format, mapping, sign, errors) and the robot fit on a synthetic multi-segment set."""

import jax.numpy as jnp
import numpy as np
import pytest

import tension_zones as tz
from tension_zones.model import _robot as ms
from tension_zones import robot_fit as rf
from tension_zones.opencr import read_opencr, servo_map_from_labels

HEADER = "timestamp,pattern_label,servo_2_mm,servo_1_mm,servo_3_mm,tip_x,tip_y,tip_z"
ROWS = [
    "1.0,rep1_tendon0_id2_pull,0.5,-1.0,-1.0,1.0,2.0,188.0",
    "1.5,rep1_tendon0_id2_pull,1.0,-2.0,-2.0,3.0,2.0,187.0",
    "2.0,rep1_tendon1_id1_pull,-1.0,0.5,-1.0,0.0,-3.0,187.5",
    "2.5,rep1_tendon2_id3_pull_hold,-1.0,-1.0,0.25,-1.0,1.0,187.9",
]


def write(tmp_path, rows=ROWS, header=HEADER, name="d.csv"):
    p = tmp_path / name
    p.write_text("\n".join([header, *rows]) + "\n")
    return p


def test_reads_mapping_sign_and_order(tmp_path):
    d = read_opencr(write(tmp_path), n_wires=3)
    assert d.servo_ids == (2, 1, 3)
    # tendon order and MODEL.md sign (negative = pulled in)
    np.testing.assert_allclose(d.q[0], [-0.5, 1.0, 1.0])
    np.testing.assert_allclose(d.q[3], [1.0, 1.0, -0.25])
    np.testing.assert_allclose(d.p[1], [3.0, 2.0, 187.0])
    assert d.patterns[3] == "rep1_tendon2_id3_pull"
    # an explicit mapping reorders the columns
    d2 = read_opencr(write(tmp_path), servo_ids=[1, 2, 3])
    np.testing.assert_allclose(d2.q[:, 0], d.q[:, 1])


@pytest.mark.parametrize("rows, header, kw, message", [
    (ROWS, HEADER.replace("tip_y", "tip_q"), {}, "missing column 'tip_y'"),
    ([ROWS[0], ROWS[1].replace("3.0,2.0", "nan,2.0")], HEADER, {"servo_ids": [2, 1, 3]},
     "column 'tip_x', row 3: non-finite"),
    ([ROWS[0], ROWS[1].replace("1.0,-2.0", "x,-2.0")], HEADER, {"servo_ids": [2, 1, 3]},
     "column 'servo_2_mm', row 3: not a number"),
    (ROWS[:2], HEADER, {}, "no 'tendon<i>_id<servo>' pattern label for tendon 1"),
    (ROWS, HEADER, {"n_wires": 6}, "3 servo columns but the design has 6 wires"),
    (ROWS, HEADER, {"servo_ids": [2, 1, 4]}, "missing column 'servo_4_mm'"),
    ([ROWS[1], ROWS[0]], HEADER, {"servo_ids": [2, 1, 3]}, "column 'timestamp', row 3"),
    (ROWS + ["3.0,rep1_tendon0_id1_pull,0,0,0,0,0,188"], HEADER, {}, "tendon 0 is driven by servo 1"),
    ([ROWS[0] + ",7"], HEADER, {}, "row 2 has 9 fields"),
])
def test_bad_data_errors_name_column_and_row(tmp_path, rows, header, kw, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace("<", "<")):
        read_opencr(write(tmp_path, rows, header), **kw)


def test_servo_map_from_labels():
    assert servo_map_from_labels(["rep1_tendon4_id2_pull", "x", "rep2_tendon4_id2_pull"]) == {4: 2}


def test_play_operator():
    q = jnp.array([0.0, 1.0, 2.0, 1.8, 1.0, 1.0, 2.5])[:, None]
    y = np.asarray(rf.play(q, jnp.array([0.5])))[:, 0]
    np.testing.assert_allclose(y, [0.0, 0.5, 1.5, 1.5, 1.5, 1.5, 2.0])


def test_fit_recovers_known_parameters_on_a_synthetic_two_segment_set():
    """Data from the model itself with known angles, offset and pretension; the fit (started from
    the nominal design) must recover them within a few standard deviations."""
    robot = ms.Robot([tz.Design(3, 60.0, 4.5, backbone_EI=2454.0, wire_stiffness=50.0),
                      tz.Design(3, 62.5, 4.5, backbone_EI=2454.0, wire_stiffness=50.0)])
    rng = np.random.default_rng(0)
    # the lab's protocol: one wire pulled in at a time, the others paid out (slack), then random
    # antagonistic commands; pretension is only visible where wires go slack
    pulls = []
    for k in range(6):
        block = np.full((12, 6), 3.0)
        block[:, k] = -np.linspace(0.0, 2.0, 12)
        pulls.append(block)
    Q = np.concatenate(pulls + [0.6 * rng.normal(size=(60, 6))])
    truth = {"segment_angle": np.radians([25.0, -40.0]), "offset": np.array([1.0, -2.0, 0.5]),
             "pretension": np.array([0.3, -0.2])}
    P = np.asarray(rf.predict(robot, {k: jnp.asarray(v) for k, v in truth.items()}, Q))
    P = P + 0.05 * rng.normal(size=P.shape)
    labels = [f"rep1_tendon{k}_id{k + 1}_pull" for k in range(6) for _ in range(12)] + ["rnd"] * 60
    a0 = rf.initial_segment_angles(robot, Q, P, labels)
    np.testing.assert_allclose(a0, truth["segment_angle"], atol=np.radians(10.0))
    res = rf.fit(robot, Q, P, ["pretension"], init={"segment_angle": a0}, max_iter=15)
    assert res.rmse_fit_mm < 0.1
    for k, v in truth.items():
        err = np.abs(res.params[k] - v)
        assert np.all(err < 5 * res.std[k] + 1e-9), (k, res.params[k], v, res.std[k])
