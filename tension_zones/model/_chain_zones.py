"""Tension maps of one segment of a robot (tension_zones/MODEL.md Sec. 2, chained; host-side, NumPy).

Segment ``j`` bends further in the direction ``delta`` (its own frame) while the other segments hold
their bending ``B`` and either stay still or bend further in their own planes. A wire crossing
segment ``j`` is pulled in, and can be taut, where its pull rate is positive
(:meth:`Robot.tension_score`, boundary rule included):

    r_kj cos(a_kj + delta) + c_k > 1e-9 s_k,   c_k = sum_{l != j} r_kl cos(a_kl + delta_l) m_l,

``m_l`` 1 for a segment that bends further and 0 for one that holds still, ``s_k`` the normalising
sum of the wire's moment arms in the moving segments. A wire of segment ``j`` alone (``c_k = 0``) has
the segment's 180 deg zone; a distal wire's zone shrinks or grows with the bending of the segments
it also crosses, and may vanish or cover every direction: that is how the others' bending moves a
segment's zones.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ._robot import Robot
from ._zones import BOUNDARY_TOL, Sector, TensionMap, sectors_from_ends


@dataclasses.dataclass(frozen=True)
class SegmentTensionMap(TensionMap):
    """A :class:`TensionMap` of one segment of a robot: zones of any width (see the module docstring),
    ``terms`` the per-wire ``(r_kj, a_kj, c_k, s_k)`` of its pull rates, for :meth:`taut_at`."""

    terms: tuple = ()

    def taut_at(self, delta_deg: float) -> tuple[int, ...]:
        r, a, c, s = (np.asarray(x, float) for x in self.terms)
        score = r * np.cos(a + np.radians(float(delta_deg))) + c
        return tuple(int(k) + 1 for k in np.flatnonzero(score > BOUNDARY_TOL * s))


def _moving(B, still) -> np.ndarray:
    """Each segment's unit 'bend further' direction (S, 2) where it moves, zero where it holds still."""
    B = np.asarray(B, float)
    norms = np.linalg.norm(B, axis=1)
    d = np.where(norms[:, None] > 0, B / np.where(norms > 0, norms, 1.0)[:, None], [1.0, 0.0])
    return np.where(np.asarray(still)[:, None], 0.0, d)


def _terms(robot: Robot, j: int, B, still):
    """The map's per-wire terms for the wires crossing segment ``j``: their indices, ``r_kj``,
    ``a_kj``, ``c_k`` and ``s_k`` (see the module docstring)."""
    ra, rr = np.asarray(robot.route_angles, float), np.asarray(robot.route_radii, float)
    crosses = np.asarray(robot.crosses)
    wires = np.flatnonzero(crosses[:, j])
    d = _moving(B, still)
    d[j] = 0.0  # segment j's own motion is the map's variable
    others = rr * (np.cos(ra) * d[None, :, 0] + np.sin(ra) * d[None, :, 1])  # (N, S): r cos(a + delta_l)
    c = np.sum(np.where(crosses, others, 0.0), axis=1)
    moving = np.linalg.norm(d, axis=1) > 0
    s = rr[:, j] + np.sum(np.where(crosses & moving[None, :], rr, 0.0), axis=1)
    return wires, rr[wires, j], ra[wires, j], c[wires], s[wires]


def segment_tension_map(robot: Robot, j: int, B=None, still=None) -> TensionMap:
    """The tension map of segment ``j`` as it bends further in each direction ``delta`` (deg, its base
    frame), the others at ``B`` (S, 2) rad (default straight) and still where ``still`` (S,) says so
    (default: a straight segment holds still, a bent one bends further in its own plane).

    The map's wires are those crossing segment ``j``, numbered 1.. in the robot's order (its first is
    the robot's wire ``robot.n_wires - n + 1``, see :func:`crossing_wires`); a zone is ``(start,
    end)`` deg, empty (``start == end``) for a wire that cannot be taut, 360 deg for one always taut.
    """
    S = robot.n_segments
    if not 0 <= j < S:
        raise ValueError(f"segment {j} does not exist: the robot has segments 0 .. {S - 1}")
    B = np.zeros((S, 2)) if B is None else np.asarray(B, float)
    if B.shape != (S, 2) or not np.all(np.isfinite(B)):
        raise ValueError(f"B must be finite with shape ({S}, 2) (rad), got {B.shape}")
    still = np.linalg.norm(B, axis=1) == 0 if still is None else np.asarray(still, bool)
    wires, r, a, c, s = _terms(robot, j, B, still)
    # pulled in where cos(a + delta) > rho: an arc of half-width arccos(rho) about delta = -a; its ends
    # (a zero pull rate) are decided by the boundary rule, as a segment's
    # (a wire the rule never counts taut, r + c <= 1e-9 * s_k, has no zone; one it always does, all of them)
    rho, rule_rho = -c / r, (BOUNDARY_TOL * s - c) / r
    centre = np.mod(-np.degrees(a), 360.0)
    half = np.degrees(np.arccos(np.clip(rho, -1.0, 1.0)))
    half = np.where(rule_rho >= 1.0, 0.0, np.where(rule_rho < -1.0, 180.0, half))
    zones = tuple((float(m - h), float(m + h)) for m, h in zip(centre, half))

    terms = tuple(tuple(float(v) for v in x) for x in (r, a, c, s))
    rule = SegmentTensionMap(len(wires), 0.0, zones, (), terms)
    ends = [e for (lo, hi), h in zip(zones, half) if 0.0 < h < 180.0 for e in (lo, hi)]
    sectors = _merge_equal(sectors_from_ends(ends, rule.taut_at))
    if np.all(c == 0):  # every zone 180 deg wide: the segment's own map (the same class as a Design's)
        return TensionMap(len(wires), 0.0, zones, sectors)
    return dataclasses.replace(rule, sectors=sectors)


def _merge_equal(sectors: tuple[Sector, ...]) -> tuple[Sector, ...]:
    """Join neighbouring intervals with the same taut set (a zone end where nothing changes: a zone that
    only touches the boundary rule's margin)."""
    out: list[Sector] = []
    for sec in sectors:
        if out and out[-1].width_deg > 0 and out[-1].wires == sec.wires:
            out[-1] = dataclasses.replace(out[-1], end_deg=sec.end_deg, closed_end=sec.closed_end)
        else:
            out.append(sec)
    return tuple(out)


def crossing_wires(robot: Robot, j: int) -> np.ndarray:
    """The robot's wires (1-based) that cross segment ``j``, in the order of its tension map."""
    return np.flatnonzero(np.asarray(robot.crosses)[:, j]) + 1
