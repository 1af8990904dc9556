"""The same command reached along two histories in a recording: how far apart the tip lands.

A pair, within one pattern of a recording (its ``pattern_label``: a segment bent out and back, a wire
pulled and released): a sample ``b`` and a point on the way to it, on the line between two
consecutive earlier samples ``o, o + 1`` of the pattern (commands and tip interpolated linearly), at
the point closest to ``b``'s command (least squares), such that

* every wire's command there agrees with ``b``'s within ``tol`` (:data:`PAIR_TOL_MM`), and
* every wire that moved in between (its command left ``b``'s by more than ``tol`` at a sample from
  ``o`` to ``b``) last moved the other way at ``b`` than at ``o + 1``
  (:func:`~tension_zones.calibration.motion_direction`): the command was reached going one way, then
  the other.

Each sample keeps its closest such point. ``|p_b - p_out|`` is the path dependence the model has to
explain (a norm: any tracker frame), the tracker's noise included.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ._data import Dataset
from ._model import motion_direction

#: A servo step of the FTDCR robots' recordings (mm): 4096 steps a turn of a 10 mm pulley; every
#: recorded command is a whole number of them.
SERVO_STEP_MM = 2 * np.pi * 10.0 / 4096
#: A pair's commands agree on every wire within this (mm): two servo steps, rounded up to the files'
#: last digits. A recorded command and a point between two recorded ones differ by up to one step
#: for the same true command (half a step of rounding at each end); the second step is the servo's
#: own error.
PAIR_TOL_MM = 0.031


@dataclasses.dataclass(frozen=True)
class PathPairs:
    """Samples ``back`` (P,) against the way to them between samples ``out`` and ``out_next`` at
    fraction ``t``; ``q`` (P, N) the ``back`` samples' commands, ``q_out`` (P, N) the interpolated
    ones; ``mismatch`` (P,) mm, the largest difference on a wire; ``difference`` (P,) mm,
    ``|p_back - p_out|``."""

    back: np.ndarray
    out: np.ndarray
    out_next: np.ndarray
    t: np.ndarray
    q: np.ndarray
    q_out: np.ndarray
    mismatch: np.ndarray
    difference: np.ndarray


def _closest(q, b, way):
    """The point of each line ``way[i] -> way[i + 1]`` closest to ``q[b]``: fractions (K,) in [0, 1]
    and the interpolated commands (K, N)."""
    q0, step = q[way[:-1]], np.diff(q[way], axis=0)
    den = np.einsum("kn,kn->k", step, step)
    t = np.clip(np.einsum("kn,kn->k", q[b] - q0, step) / np.where(den > 0, den, 1.0), 0.0, 1.0)
    return t, q0 + t[:, None] * step


def _reversed(q, direction, idx, i, bi, tol):
    """Whether every wire that moved between pattern samples ``idx[i]`` and ``idx[bi]`` (its command
    more than ``tol`` from the latter's) last moved the other way at ``idx[bi]`` than at ``idx[i + 1]``."""
    b, o1 = idx[bi], idx[i + 1]
    moved = np.max(np.abs(q[idx[i : bi + 1]] - q[b]), axis=0) > tol
    return bool(moved.any() and np.all(direction[o1, moved] * direction[b, moved] < 0))


def _pair(q, direction, idx, bi, tol):
    """``(o, o1, t, q_out, mismatch)`` for pattern sample ``idx[bi]``, or None."""
    t, q_out = _closest(q, idx[bi], idx[:bi])
    gap = np.max(np.abs(q[idx[bi]] - q_out), axis=1)
    for i in np.argsort(gap, kind="stable"):
        if gap[i] > tol:
            return None
        if _reversed(q, direction, idx, int(i), bi, tol):
            return int(idx[i]), int(idx[i + 1]), float(t[i]), q_out[i], float(gap[i])
    return None


def path_pairs(data: Dataset, tol: float = PAIR_TOL_MM) -> PathPairs:
    """Every pair of a recording (module docstring) whose commands agree within ``tol`` mm."""
    if data.groups is None:
        raise ValueError("pairs need the recording's pattern labels (groups)")
    q, groups, p = np.asarray(data.q), np.asarray(data.groups), np.asarray(data.p)
    direction = np.asarray(motion_direction(q, data.reset))
    rows = []
    for g in dict.fromkeys(groups):
        idx = np.flatnonzero(groups == g)
        for bi in range(2, idx.size):
            found = _pair(q, direction, idx, bi, tol)
            if found is not None:
                rows.append((int(idx[bi]), *found))
    back, out, nxt = (np.array([r[i] for r in rows], int) for i in range(3))
    t, mismatch = (np.array([r[i] for r in rows], float) for i in (3, 5))
    q_out = np.array([r[4] for r in rows], float).reshape(-1, q.shape[1])
    p_out = p[out] + t[:, None] * (p[nxt] - p[out])
    diff = np.linalg.norm(p[back] - p_out, axis=1)
    return PathPairs(back, out, nxt, t, q[back].reshape(-1, q.shape[1]), q_out, mismatch, diff)
