"""Samples of a robot's configurations: the bending vectors ``B`` (S, 2) of its segments.

A workspace grid of one segment is ``theta_L x delta`` (:func:`~._sweep.sweep_grid`); with several
segments a product grid of the ``2S`` coordinates grows as a power of ``S``, so the configurations are
the first points of a Halton sequence (low discrepancy: the whole space covered evenly at any count,
and the same points every run), each segment's ``b_j`` uniform over the disk ``|b_j| <= max_bend``.
"""

from __future__ import annotations

import numpy as np


def halton(n: int, dims: int, start: int = 1) -> np.ndarray:
    """Points ``start .. start + n - 1`` of the Halton sequence in ``[0, 1)^dims``, (n, dims).

    Dimension j is the radical inverse of the index in the j-th prime base (2, 3, 5, ...). Point 0
    is the origin, so the default starts at 1. Deterministic, unscrambled (``scipy.stats.qmc.Halton``
    with ``scramble=False`` gives the same points); fine for the handful of dimensions of a space.
    """
    idx = np.arange(start, start + n)
    out = np.zeros((n, dims))
    for j, base in enumerate(_primes(dims)):
        k, f = idx.copy(), 1.0
        while np.any(k > 0):
            f /= base
            out[:, j] += f * (k % base)
            k //= base
    return out


def _primes(count: int) -> list[int]:
    primes: list[int] = []
    c = 2
    while len(primes) < count:
        if all(c % p for p in primes if p * p <= c):
            primes.append(c)
        c += 1
    return primes


def config_samples(n_segments: int, n: int, max_bend_deg: float = 90.0, start: int = 1) -> np.ndarray:
    """The first ``n`` Halton configurations of ``n_segments`` segments, (n, S, 2) rad.

    Segment ``j`` takes dimensions ``2j, 2j + 1``: the bending angle ``max_bend sqrt(u)`` (uniform over
    the disk's area) and the direction ``delta = 2 pi v``, ``b_j = phi (cos delta, -sin delta)``
    (tension_zones/MODEL.md Sec. 5). Points ``start .. start + n - 1``, as :func:`halton`.
    """
    if not (np.isfinite(max_bend_deg) and 0 < max_bend_deg <= 180):
        raise ValueError(f"max_bend_deg must be in (0, 180] degrees, got {max_bend_deg:g}")
    u = halton(n, 2 * n_segments, start).reshape(n, n_segments, 2)
    phi = np.radians(max_bend_deg) * np.sqrt(u[..., 0])
    delta = 2 * np.pi * u[..., 1]
    return np.stack([phi * np.cos(delta), -phi * np.sin(delta)], axis=-1)
