"""The same command reached along two histories in a recording: how far apart the tip lands.

In each out-and-back pattern of a recording (its ``pattern_label``: a segment bent out and back, a
wire pulled and released; the turn at the command farthest from the start on the pattern's dominant
wire), each sample on the way back is set against the way out at the same command: the two samples of
the way out whose dominant-wire commands bracket it, interpolated linearly (tip and every wire's
command). A pair is kept where the interpolated commands agree with the sample's on every wire within
a tolerance. ``|p_back - p_out|`` is the path dependence the model has to explain (a norm: any
tracker frame), the tracker's noise included.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np

from ._data import Dataset

#: A pair's commands agree on every wire within this (mm): a few servo steps of FTDCR's 0.0153 mm.
PAIR_TOL_MM = 0.05


@dataclasses.dataclass(frozen=True)
class PathPairs:
    """Samples on the way back (``back``, (P,) indices) against the way out between samples ``out`` and
    ``out_next`` at fraction ``t``; ``q`` (P, N) the back samples' commands; ``mismatch`` (P,) mm, the
    largest command difference on a wire; ``difference`` (P,) mm, ``|p_back - p_out|``."""

    back: np.ndarray
    out: np.ndarray
    out_next: np.ndarray
    t: np.ndarray
    q: np.ndarray
    mismatch: np.ndarray
    difference: np.ndarray


def _out_and_back(q):
    """``(dominant wire, index of the turn)`` of a pattern's commands (M, N), or None where it is not an
    out-and-back (fewer than three samples on either side of its farthest command)."""
    k = int(np.argmax(np.ptp(q, axis=0)))
    turn = int(np.argmax(np.abs(q[:, k] - q[0, k])))
    return (k, turn) if 3 <= turn <= q.shape[0] - 4 else None


def _bracket(q, b, way_out, k):
    """The way out's samples ``(o, o1, t)`` whose commands on wire ``k`` bracket sample ``b``'s, or None."""
    for o, o1 in itertools.pairwise(way_out):
        lo, hi = q[o, k], q[o1, k]
        if hi != lo and min(lo, hi) <= q[b, k] <= max(lo, hi):
            return int(o), int(o1), float((q[b, k] - lo) / (hi - lo))
    return None


def path_pairs(data: Dataset, tol: float = PAIR_TOL_MM) -> PathPairs:
    """Every pair of a recording (module docstring) whose commands agree within ``tol`` mm."""
    q, groups = np.asarray(data.q), np.asarray(data.groups)
    rows = []
    for g in np.unique(groups):
        idx = np.flatnonzero(groups == g)
        shape = _out_and_back(q[idx])
        if shape is None:
            continue
        k, turn = shape
        for b in idx[turn + 1 :]:
            found = _bracket(q, b, idx[: turn + 1], k)
            if found is not None:
                o, o1, frac = found
                gap = float(np.max(np.abs(q[b] - (q[o] + frac * (q[o1] - q[o])))))
                if gap <= tol:
                    rows.append((int(b), o, o1, frac, gap))
    back, out, nxt = (np.array([r[i] for r in rows], int) for i in range(3))
    t, mismatch = (np.array([r[i] for r in rows], float) for i in (3, 4))
    p = np.asarray(data.p)
    p_out = p[out] + t[:, None] * (p[nxt] - p[out])
    diff = np.linalg.norm(p[back] - p_out, axis=1)
    return PathPairs(back, out, nxt, t, q[back].reshape(-1, q.shape[1]), mismatch, diff)
