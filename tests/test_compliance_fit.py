"""The identification machinery of paper Sec. 6.2 (the full fit runs in test_reproduce)."""

import pytest

from tension_zones.paper import _identify as cf


def test_paper_means_order():
    m = cf.paper_means()
    assert m.shape == (12,) and len(cf.FIT_KEYS) == 12
    assert m[cf.FIT_KEYS.index((3, 75, "mm"))] == 3.052
    assert m[cf.FIT_KEYS.index((4, 105, "deg"))] == 8.06


def test_initial_guess_is_a_plausible_wrist():
    L, r, EI = cf.initial_guess()
    assert 10 < L < 40 and 1 < r < 3 and EI > 0


def test_identify_rejects_bad_start():
    with pytest.raises(ValueError, match="positive"):
        cf.identify(initial=(15.0, -1.0, 80.0))
