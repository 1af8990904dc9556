"""The structure test's pieces against plain references: neighbours, leave-one-out smoother, verdicts."""

import numpy as np

from tension_zones.calibration._diagnose import _knn, _loo_sse, structure_test


def test_neighbours_in_blocks_are_the_brute_force_ones():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(2500, 2))  # 2500 rows: two blocks of 1677 and 823
    nb = _knn(X, 7, np.random.default_rng(1))
    d2 = ((X[:, None] - X[None]) ** 2).sum(-1)
    np.fill_diagonal(d2, np.inf)
    ref = np.argsort(d2, axis=1)[:, :7]
    assert np.array_equal(np.sort(nb, axis=1), np.sort(ref, axis=1))


def test_leave_one_out_smoother_matches_a_loop_and_batches():
    rng = np.random.default_rng(2)
    r, nb = rng.normal(size=(40, 3)), rng.integers(0, 40, (40, 5))
    ref = sum(np.sum((r[i] - r[nb[i]].mean(axis=0)) ** 2) for i in range(40))
    np.testing.assert_allclose(_loo_sse(r, nb), ref, rtol=1e-13)
    perms = np.stack([rng.permutation(40) for _ in range(3)])
    np.testing.assert_allclose(_loo_sse(r[perms], nb), [_loo_sse(r[p], nb) for p in perms], rtol=1e-13)


def test_structure_is_found_in_the_feature_that_has_it_and_nowhere_else():
    rng = np.random.default_rng(3)
    m = 300
    feats = {"bending_direction": rng.uniform(-np.pi, np.pi, m), "order": np.arange(m, dtype=float)}
    noise = rng.normal(scale=0.1, size=(m, 3))
    shaped = noise + 0.3 * np.stack([np.cos(feats["bending_direction"]), np.zeros(m), np.zeros(m)], axis=1)
    out = structure_test(shaped, feats, np.full(3, 0.1), n_perm=200)
    assert out["bending_direction"]["z"] > 10 and abs(out["order"]["z"]) < 4
    out = structure_test(noise, feats, np.full(3, 0.1), n_perm=200)
    assert all(abs(out[k]["z"]) < 4 for k in feats)
