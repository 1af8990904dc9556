"""Tension transition zones, tension maps and reduced Jacobians (tension_zones/MODEL.md Sec. 2; paper Sec. 3).

Wire ``k`` is in its tension zone when pulling it (``q_dot_k < 0``) moves the segment as asked. For
the paper's default motion, bending further in a fixed plane (``psi_dot = [-1, 0]``), that is
``cos(delta_k) > 0`` with ``delta_k = delta + alpha_k``; for a general ``psi_dot`` the zones shift
in phase (paper Figs. 3-4). A wire with a zero moment arm (``|cos delta_k| <= 1e-9``, or in general
a normalised pull rate within ``1e-9`` of zero) is *not* taut (tension_zones/MODEL.md Sec. 2, boundary rule).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from .._numerics import float_dtype, nan_where, not_finite, straight_through
from ._design import Design
from ._kinematics import THETA_0, J_qpsi, J_xq

#: Boundary rule: a wire whose normalised pull rate is at most this is not in tension.
BOUNDARY_TOL = 1e-9
#: Temperature of the sigmoid surrogate behind the straight-through mask's gradient. The pull rate
#: is normalised to [-1, 1] (a cosine for psi_dot = [-1, 0]), so 0.05 smooths over about +-3 deg.
TEMPERATURE = 0.05


def tension_score(design: Design, delta, theta_L=None, psi_dot=None):
    """Normalised pull rate of each wire, (n,), in [-1, 1]; the wire can be taut where it is > 0.

    ``psi_dot = None`` is the paper's default, bending further in a fixed plane: the score is
    ``cos(delta + alpha_k)`` and ``theta_L`` is not needed. Otherwise the score is
    ``-q_dot_k / (r |(theta_dot_L, (theta_L - theta_0) delta_dot)|)`` with ``q_dot = J_qpsi psi_dot``:
    a phase-shifted cosine (paper Figs. 3-4). Zero when the motion moves no wire.
    """
    dt = float_dtype(design.length, delta)
    delta = jnp.asarray(delta, dt)
    if psi_dot is None:
        return nan_where(design.invalid(), jnp.cos(delta + design.wire_angles))
    if theta_L is None:
        raise ValueError("a tension score for a given psi_dot needs theta_L")
    theta_L = jnp.asarray(theta_L, dt)
    psi_dot = jnp.asarray(psi_dot, dt)
    q_dot = J_qpsi(design, theta_L, delta) @ psi_dot
    scale2 = psi_dot[0] ** 2 + ((theta_L - THETA_0) * psi_dot[1]) ** 2
    nz = scale2 > 0
    scale = design.pitch_radius * jnp.sqrt(jnp.where(nz, scale2, 1.0))
    bad = design.invalid() | not_finite(theta_L, delta, psi_dot)  # the guard would give 0 for NaN
    return nan_where(bad, jnp.where(nz, -q_dot / scale, 0.0))


def tension_mask(design: Design, delta, theta_L=None, psi_dot=None, temperature=TEMPERATURE):
    """Which wires are in tension, (n,) float 0/1, with a straight-through gradient.

    Forward: exactly ``1.0`` where ``tension_score > 1e-9`` (tension_zones/MODEL.md boundary rule), else ``0.0``;
    NaN where the score is (NaN inputs, an invalid design).
    Backward: the gradient of ``sigmoid(score / temperature)``, so design variables that move a
    wire across its zone boundary (wire angles, the bending direction) get a useful gradient.
    """
    return mask_from_score(tension_score(design, delta, theta_L, psi_dot), temperature)


def mask_from_score(score, temperature=TEMPERATURE):
    """:func:`tension_mask` from a :func:`tension_score` the caller has (NaN where it is NaN)."""
    mask = straight_through(score > BOUNDARY_TOL, jax.nn.sigmoid(score / temperature))
    return jnp.where(jnp.isnan(score), jnp.nan, mask)


def reduced_J_qpsi(design: Design, theta_L, delta, psi_dot=None):
    """``J~_qpsi``, (n, 2): the rows of ``J_qpsi`` of slack wires set to zero (paper Sec. 3.3)."""
    mask = tension_mask(design, delta, theta_L, psi_dot)
    return J_qpsi(design, theta_L, delta) * mask[:, None]


def reduced_J_xq(design: Design, theta_L, delta, psi_dot=None):
    """``J~_xq = J_xpsi pinv(J~_qpsi)``, (6, n); the columns of slack wires are zero."""
    return J_xq(design, theta_L, delta, tension_mask(design, delta, theta_L, psi_dot))


# --------------------------------------------------------------------------------------------
# Tension map: exact sector intervals (host-side, NumPy)
# --------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Sector:
    """Bending directions ``delta`` from ``start_deg`` to ``end_deg`` over which the set of wires that
    can be taut is ``wires`` (1-based). Ends are included where ``closed_start``/``closed_end`` say
    so; ``start_deg == end_deg`` is a single direction (a point sector)."""

    start_deg: float
    end_deg: float
    wires: tuple[int, ...]
    closed_start: bool = False
    closed_end: bool = False

    @property
    def width_deg(self) -> float:
        return self.end_deg - self.start_deg

    @property
    def n_taut(self) -> int:
        return len(self.wires)

    def __str__(self) -> str:
        if self.width_deg == 0:
            return f"{{{self.start_deg:g}}}"
        lb = "[" if self.closed_start else "("
        rb = "]" if self.closed_end else ")"
        return f"{lb}{self.start_deg:g}, {self.end_deg:g}{rb}"


@dataclasses.dataclass(frozen=True)
class TensionMap:
    """The tension map of a design (paper Figs. 2, 5, 7): each wire's zone and the sectors of
    ``delta`` in [0, 360) deg over which the taut set is constant, in order.

    ``zones_deg[k] = (start, end)``: wire ``k + 1`` can be taut for ``delta`` in the open interval
    ``(start, end)`` modulo 360 (always 180 deg wide). ``sectors`` cover [0, 360) exactly, in
    order; a zone end belongs to the neighbouring interval with the same taut set, and is listed as
    a point sector of its own only where the boundary rule leaves a taut set that neither neighbour
    has (four wires: one taut wire on the lines through a wire).
    """

    n_wires: int
    phase_deg: float
    zones_deg: tuple[tuple[float, float], ...]
    sectors: tuple[Sector, ...]

    def taut_at(self, delta_deg: float) -> tuple[int, ...]:
        """The taut wires (1-based) at a bending direction ``delta_deg``."""
        return _taut_set(self.zones_deg, float(delta_deg))

    def table(self) -> str:
        """A plain-text sector table."""
        rows = [f"{'delta (deg)':<22} {'taut':>4}  wires"]
        for s in self.sectors:
            rows.append(f"{s!s:<22} {s.n_taut:>4}  {', '.join(map(str, s.wires)) or '-'}")
        return "\n".join(rows)


def _taut_set(zones_deg, delta_deg: float) -> tuple[int, ...]:
    out = []
    for k, (a, _) in enumerate(zones_deg):
        # cos of the angle from the zone's centre; same boundary rule as the traced mask
        if np.cos(np.radians(delta_deg - (a + 90.0))) > BOUNDARY_TOL:
            out.append(k + 1)
    return tuple(out)


def tension_map(design: Design, theta_L=None, psi_dot=None) -> TensionMap:
    """Exact tension map for any wire count and wire angles (host-side).

    With ``psi_dot = None`` the zones are ``cos(delta + alpha_k) > 0``. With a ``psi_dot`` (and
    ``theta_L``) every zone shifts by the phase ``gamma = atan2((theta_L - theta_0) delta_dot,
    -theta_dot_L)`` (paper Figs. 3-4): wire k is taut where ``cos(delta + alpha_k - gamma) > 0``.
    """
    alpha = np.degrees(np.asarray(design.wire_angles, dtype=float))
    gamma = 0.0
    if psi_dot is not None:
        if theta_L is None:
            raise ValueError("a tension map for a given psi_dot needs theta_L")
        td, dd = (float(x) for x in np.asarray(psi_dot, dtype=float))
        T = float(theta_L) - np.pi / 2
        if td == 0.0 and T * dd == 0.0:
            raise ValueError("psi_dot moves no wire at this pose: no tension zone is defined")
        gamma = np.degrees(np.arctan2(T * dd, -td))
    centres = np.mod(gamma - alpha, 360.0)
    zones = tuple((float(c - 90.0), float(c + 90.0)) for c in centres)
    ends = np.concatenate([centres - 90.0, centres + 90.0])
    return TensionMap(design.n_wires, float(gamma), zones, sectors_from_ends(ends, lambda d: _taut_set(zones, d)))


def sectors_from_ends(ends_deg, taut) -> tuple[Sector, ...]:
    """Sectors of constant taut set covering [0, 360), from the zones' ends (deg) and ``taut(delta_deg)``
    (the wires taut at a direction): open intervals between the ends and the ends themselves, each
    end absorbed into a neighbour with the same taut set."""
    # breakpoints: every zone end, wrapped to [0, 360), merged when within 1e-9 deg
    ends = np.mod(np.asarray(ends_deg, float), 360.0)
    ends = np.sort(np.where(ends > 360.0 - 1e-9, 0.0, ends))
    pts: list[float] = []
    for e in ends:
        if not pts or e - pts[-1] > 1e-9:
            pts.append(float(e))
    if len(pts) > 1 and pts[0] + 360.0 - pts[-1] <= 1e-9:
        pts.pop()
    if not pts:  # no zone ends: one taut set everywhere
        return (Sector(0.0, 360.0, taut(0.0), closed_start=True),)
    raw: list[Sector] = []  # open intervals and points, alternating, covering [0, 360)
    if pts[0] > 0.0:
        raw.append(Sector(0.0, pts[0], taut(0.5 * (pts[-1] - 360.0 + pts[0]))))
    for i, p in enumerate(pts):
        nxt = pts[i + 1] if i + 1 < len(pts) else 360.0
        raw.append(Sector(p, p, taut(p)))
        mid = 0.5 * (p + nxt) if i + 1 < len(pts) else 0.5 * (p + pts[0] + 360.0)
        if nxt > p:
            raw.append(Sector(p, nxt, taut(mid)))
    return _fold_points(raw)


def _fold_points(raw: list[Sector]) -> tuple[Sector, ...]:
    """Absorb each point sector into a neighbouring interval with the same taut set."""
    out: list[Sector] = []
    i = 0
    while i < len(raw):
        s = raw[i]
        if s.width_deg == 0:
            nxt = raw[i + 1] if i + 1 < len(raw) else None
            if out and out[-1].width_deg > 0 and out[-1].wires == s.wires:
                out[-1] = dataclasses.replace(out[-1], closed_end=True)
            elif nxt is not None and nxt.wires == s.wires:
                out.append(dataclasses.replace(nxt, closed_start=True))
                i += 1
            else:
                out.append(s)
        else:
            out.append(s)
        i += 1
    if out and out[0].start_deg == 0.0 and out[0].width_deg > 0 and not out[0].closed_start:
        out[0] = dataclasses.replace(out[0], closed_start=True)  # 0 itself: interior of the wrap
    return tuple(out)
