"""Pairs of one command reached along two histories (tension_zones/calibration/_hysteresis.py)."""

import numpy as np

import tension_zones as tz
from tension_zones.calibration import Dataset, path_pairs
from tension_zones.calibration._hysteresis import PAIR_TOL_MM


def _recording(gap_mm: float, jitter: float = 0.0):
    """One wire pulled out and back in 0.3 mm steps (the way back half a step off), a second wire
    released alongside; the tip a linear map of the commands plus ``gap_mm`` along y on the way back."""
    out = -0.3 * np.arange(11)
    back = out[-2::-1] + 0.15
    q0 = np.concatenate([out, back])
    q = np.stack([q0, -0.5 * q0 + jitter * np.sin(np.arange(q0.size))], axis=1)
    p = np.stack([2.0 * q[:, 0], 3.0 * q[:, 1], 100 + q[:, 0] - q[:, 1]], axis=1)
    p[out.size :, 1] += gap_mm
    pull = np.stack([np.linspace(0, -3, 8), np.zeros(8)], axis=1)  # monotone: no way back
    n = q.shape[0] + pull.shape[0]
    return Dataset(
        sample=np.arange(n),
        q=np.concatenate([q, pull]),
        f=np.zeros((n, 3)),
        p=np.concatenate([p, np.tile([0.0, 0.0, 100.0], (8, 1))]),
        groups=tuple(["seg1_dir0"] * q.shape[0] + ["tendon0_pull"] * 8),
    )


def test_each_sample_on_the_way_back_meets_the_way_out_at_its_command():
    pairs = path_pairs(_recording(0.7))
    assert pairs.back.size == 9  # the way back's samples inside the way out's range, not the monotone pull
    np.testing.assert_allclose(pairs.difference, 0.7, rtol=1e-12)
    np.testing.assert_allclose(pairs.t, 0.5, atol=1e-12)
    assert np.all(pairs.mismatch < 1e-12)


def test_commands_that_disagree_beyond_the_tolerance_make_no_pair():
    assert path_pairs(_recording(0.7, jitter=0.2)).back.size < path_pairs(_recording(0.7)).back.size
    loose = path_pairs(_recording(0.0, jitter=0.2), tol=0.2)
    assert 0 < loose.back.size < 9 and np.all(loose.mismatch <= 0.2)


def test_the_shipped_ftdcr_v4_recording_has_pairs_apart_by_more_than_its_noise():
    data = tz.read_opencr(tz.example_path("ftdcr_v4/train.csv"), n_wires=9)
    pairs = path_pairs(data)
    assert pairs.back.size > 30 and np.all(pairs.mismatch <= PAIR_TOL_MM)
    assert np.median(pairs.difference) > 2 * 0.4155  # twice the calibration's noise floor


def test_a_wire_that_moved_on_without_turning_makes_no_pair():
    """The same command twice in a pattern, the wire still going the same way (a pull, a hold, the
    pull again): not two histories."""
    q0 = np.concatenate([-0.3 * np.arange(6), [-1.5, -1.5], -1.5 - 0.3 * np.arange(1, 4)])
    n = q0.size
    data = Dataset(
        sample=np.arange(n),
        q=np.stack([q0, np.zeros(n)], axis=1),
        f=np.zeros((n, 3)),
        p=np.stack([q0, np.arange(n, dtype=float), np.full(n, 100.0)], axis=1),
        groups=tuple(["tendon0_pull"] * n),
    )
    assert path_pairs(data).back.size == 0


def test_pairs_interpolate_the_way_out_and_report_its_commands():
    data = _recording(0.7)
    pairs = path_pairs(data)
    q = np.asarray(data.q)
    np.testing.assert_allclose(pairs.q_out, q[pairs.out] + pairs.t[:, None] * (q[pairs.out_next] - q[pairs.out]))
    np.testing.assert_allclose(pairs.q_out, pairs.q, atol=1e-12)
    assert np.all(pairs.out_next == pairs.out + 1) and np.all(pairs.out_next < pairs.back)
