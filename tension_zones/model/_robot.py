"""A robot: one or more constant-curvature segments in series (tension_zones/MODEL.md Sec. 5, chained).

A :class:`Robot` is a chain of segments (:class:`~tension_zones.model.Design`), proximal first.
Segment ``j`` has its own bending vector ``b_j = (u_j, v_j)``; a configuration is ``B``, shape
``(S, 2)``. Wires are numbered segment by segment (segment 0's first). Every wire ends at the end
disk of its own segment (its *owner*) and runs through every proximal segment at an angle and pitch
radius there (``route_angles[k, j]``, ``route_radii[k, j]``, in segment ``j``'s base frame). Its
length is the sum over the segments it crosses (linear in ``B``):

    l_k = sum_{j <= owner(k)} L_j - r_kj (u_j cos a_kj + v_j sin a_kj).

**Default routing.** Where the design file does not say how a wire crosses the proximal segments,
it keeps its own segment's angle and pitch radius there (it runs parallel to the backbone through
holes of the proximal disks at the same place). A robot whose proximal disks hold distal wires
elsewhere says so per segment with ``route_angles_deg`` / ``route_radii_mm`` (see
:meth:`Robot.from_dict`).

Kinematics are the segment formulas of :mod:`._kinematics` (``segment_pose``, ``segment_J_xb``,
``moment_arms``) chained: a one-segment robot gives exactly the single-segment results. Functions of
one configuration are methods (``robot.tip_pose(B)``); ``vmap`` them over configurations.
"""

from __future__ import annotations

import dataclasses
import functools
import warnings
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .._numerics import masked_pinv, pinv_tall2, skew, straight_through
from ._design import Design, MissingDesignKeyWarning, missing_physical_keys, read_json
from ._kinematics import moment_arms, segment_J_xb, segment_pose
from ._zones import BOUNDARY_TOL, TEMPERATURE


@dataclasses.dataclass(frozen=True)
class Structure:
    """The static part of a robot: the wire count of each segment (proximal first) and the number of
    constant-curvature pieces each segment's backbone is solved as (1: constant curvature; more: the
    rod model of :mod:`._equilibrium`). Hashable, so a compiled function depends on it and on nothing
    else of the robot."""

    n_wires_per_segment: tuple
    pieces: int = 1

    @property
    def n_segments(self) -> int:
        return len(self.n_wires_per_segment)

    @property
    def n_wires(self) -> int:
        return sum(self.n_wires_per_segment)

    @functools.cached_property
    def owner(self) -> np.ndarray:
        """``(N,)`` the segment each wire ends in."""
        return np.repeat(np.arange(self.n_segments), self.n_wires_per_segment)

    @functools.cached_property
    def crosses(self) -> np.ndarray:
        """``(N, S)`` bool: wire ``k`` runs through segment ``j`` (``j <= owner(k)``)."""
        return np.arange(self.n_segments)[None, :] <= self.owner[:, None]

    @property
    def n_pieces(self) -> int:
        return self.n_segments * self.pieces

    @functools.cached_property
    def piece_crosses(self) -> np.ndarray:
        """``(N, S m)`` bool: wire ``k`` runs through piece ``i`` (piece ``i`` of segment ``i // m``)."""
        return np.repeat(self.crosses, self.pieces, axis=1)


# --------------------------------------------------------------------------------------------
# Kinematics of a chain, from the segment lengths (S,) and the routing: used by Robot's methods,
# the equilibrium and the calibration model alike
# --------------------------------------------------------------------------------------------
#: Chains of up to this many links (segments, or pieces of the rod model) are unrolled: the fastest to
#: run. Longer ones are vectorised and composed by a ``scan``, which compiles to the size of one link
#: (a rod of many pieces compiles much faster that way and runs no slower); a chain of three (the
#: constant-curvature model of a three-segment robot) runs faster unrolled, so it stays unrolled.
CHAIN_UNROLL_MAX = 3


def chain_poses(lengths, B):
    """Base-frame poses of every disk along the chain: positions (S + 1, 3) and rotations (S + 1, 3, 3);
    index 0 is the base, ``j + 1`` the end disk of segment ``j``."""
    dt = jnp.result_type(lengths, B, float)
    p0, R0 = jnp.zeros(3, dt), jnp.eye(3, dtype=dt)
    if B.shape[0] <= CHAIN_UNROLL_MAX:
        p, R = p0, R0
        ps, Rs = [p], [R]
        for j in range(B.shape[0]):
            pj, Rj = segment_pose(lengths[j], B[j])
            p, R = p + R @ pj, R @ Rj
            ps.append(p)
            Rs.append(R)
        return jnp.stack(ps), jnp.stack(Rs)
    pj, Rj = jax.vmap(segment_pose)(jnp.asarray(lengths, dt), jnp.asarray(B, dt))

    def step(carry, own):
        p, R = carry
        p, R = p + R @ own[0], R @ own[1]
        return (p, R), (p, R)

    _, (ps, Rs) = jax.lax.scan(step, (p0, R0), (pj, Rj))
    return jnp.concatenate([p0[None], ps]), jnp.concatenate([R0[None], Rs])


def chain_J_xB(lengths, B):
    """Tip twist Jacobian ``[p_dot; omega] = J_xB vec(B_dot)``, (6, 2S), base frame, in closed form.

    Segment ``j``'s own Jacobian ``[J_v; J_w]`` (its base frame) is rotated by its base rotation
    ``R_j``; moving segment ``j`` turns everything distal to it about its end disk ``p_{j+1}``, so the
    tip's velocity gains ``omega x (p_tip - p_{j+1})``.
    """
    return _J_xB_of(lengths, B, *chain_poses(lengths, B))


def _J_xB_of(lengths, B, ps, Rs):
    if B.shape[0] <= CHAIN_UNROLL_MAX:
        cols = []
        for j in range(B.shape[0]):
            J = segment_J_xb(lengths[j], B[j])
            w = Rs[j] @ J[3:]
            v = Rs[j] @ J[:3] - skew(ps[-1] - ps[j + 1]) @ w
            cols.append(jnp.concatenate([v, w], axis=0))
        return jnp.concatenate(cols, axis=1)
    J = jax.vmap(segment_J_xb)(lengths, B)  # (S, 6, 2)
    w = jnp.einsum("sij,sjk->sik", Rs[:-1], J[:, 3:])
    v = jnp.einsum("sij,sjk->sik", Rs[:-1], J[:, :3]) - jax.vmap(lambda d, a: skew(d) @ a)(ps[-1] - ps[1:], w)
    return jnp.concatenate([v, w], axis=1).transpose(1, 0, 2).reshape(6, -1)  # columns (u_0, v_0, u_1, ...)


@jax.custom_jvp
def chain_tip(lengths, B):
    """Tip position (3,) and rotation (3, 3) of the chain: :func:`chain_poses`' last disk, with a
    closed-form derivative (:func:`chain_J_xB`; a segment's position is linear in its length), so that
    many tangents at once (a Jacobian in many parameters) cost a matrix product, not a pass each."""
    ps, Rs = chain_poses(lengths, B)
    return ps[-1], Rs[-1]


@chain_tip.defjvp
def _chain_tip_jvp(primals, tangents):
    lengths, B = primals
    dL, dB = tangents
    ps, Rs = chain_poses(lengths, B)
    tw = _J_xB_of(lengths, B, ps, Rs) @ dB.reshape(-1)
    unit = jax.vmap(lambda b: segment_pose(jnp.ones((), B.dtype), b)[0])(B)  # (S, 3): d p_j / d L_j
    dp = tw[:3] + jnp.einsum("sij,sj,s->i", Rs[:-1], unit, dL)
    return (ps[-1], Rs[-1]), (dp, skew(tw[3:]) @ Rs[-1])


def routing_matrix(route_angles, route_radii, crosses):
    """``J_qB`` (N, 2S): ``d l / d vec(B)``, columns ``(u_0, v_0, u_1, ...)``; zero where a wire does not
    cross a segment. Constant: wire lengths are linear in ``B``."""
    J = moment_arms(route_radii, route_angles)  # (N, S, 2)
    J = jnp.where(jnp.asarray(crosses)[..., None], J, 0.0)
    return J.reshape(J.shape[0], -1)


# --------------------------------------------------------------------------------------------
# The robot
# --------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True, init=False, repr=False, eq=False)
class Robot:
    """A chain of segments (proximal first) with the routing of every wire.

    Args:
        segments: a sequence of :class:`Design` (or a single Design: a one-segment robot).
        route_angles: ``(N, S)`` angle (rad) of wire ``k`` in segment ``j``'s frame; ``None`` = the
            wire's own angle in every segment it crosses. Entries with ``j > owner(k)`` are unused.
        route_radii: ``(N, S)`` pitch radius (mm) likewise; ``None`` = its own segment's radius.

    A wire's stiffness and preload are those its own segment declares. Only the wire counts are
    static (:attr:`structure`): changing any number never recompiles.
    """

    segments: tuple
    route_angles: jax.Array
    route_radii: jax.Array

    def __init__(self, segments, route_angles=None, route_radii=None):
        if isinstance(segments, Design):
            segments = (segments,)
        segments = tuple(segments)
        if not segments or not all(isinstance(s, Design) for s in segments):
            raise ValueError("a Robot needs at least one segment, each a Design")
        object.__setattr__(self, "segments", segments)
        own_a = jnp.concatenate([s.wire_angles for s in segments])
        own_r = jnp.concatenate([jnp.broadcast_to(s.pitch_radius, (s.n_wires,)) for s in segments])
        S = len(segments)
        ra = jnp.tile(own_a[:, None], (1, S)) if route_angles is None else jnp.asarray(route_angles)
        rr = jnp.tile(own_r[:, None], (1, S)) if route_radii is None else jnp.asarray(route_radii)
        for name, arr in (("route_angles", ra), ("route_radii", rr)):
            if arr.shape != (self.n_wires, S):
                raise ValueError(f"{name} must have shape {(self.n_wires, S)}, got {arr.shape}")
            if not isinstance(arr, jax.core.Tracer):
                used = np.asarray(arr)[self.crosses]
                if not np.all(np.isfinite(used)):
                    raise ValueError(f"{name} must be finite where a wire crosses a segment")
        if (
            route_radii is not None
            and not isinstance(rr, jax.core.Tracer)
            and np.any(np.asarray(rr)[self.crosses] <= 0)
        ):
            raise ValueError("route_radii must be positive where a wire crosses a segment")
        object.__setattr__(self, "route_angles", ra.astype(own_a.dtype))
        object.__setattr__(self, "route_radii", rr.astype(own_a.dtype))

    # -- pytree ------------------------------------------------------------------------------
    def _tree_flatten(self):
        return (self.segments, self.route_angles, self.route_radii), None

    @classmethod
    def _tree_unflatten(cls, _, children):
        obj = object.__new__(cls)
        for name, v in zip(("segments", "route_angles", "route_radii"), children):
            object.__setattr__(obj, name, v)
        return obj

    # -- static structure ---------------------------------------------------------------------
    @property
    def structure(self) -> Structure:
        return Structure(tuple(s.n_wires for s in self.segments))

    @property
    def n_segments(self) -> int:
        return len(self.segments)

    @property
    def n_wires_per_segment(self) -> tuple[int, ...]:
        return self.structure.n_wires_per_segment

    @property
    def n_wires(self) -> int:
        return self.structure.n_wires

    @property
    def owner(self) -> np.ndarray:
        return self.structure.owner

    @property
    def crosses(self) -> np.ndarray:
        return self.structure.crosses

    # -- per-segment and per-wire values --------------------------------------------------------
    def _stack(self, field):
        return jnp.stack([jnp.asarray(getattr(s, field)) for s in self.segments])

    @property
    def lengths(self):
        """``(S,)`` segment lengths (mm)."""
        return self._stack("length")

    @property
    def backbone_EI(self):
        """``(S,)`` backbone bending stiffness of each segment (N mm^2)."""
        return self._stack("backbone_EI")

    @property
    def wire_stiffness(self):
        """``(N,)`` each wire's stiffness (its owner's ``wire_stiffness``, N/mm)."""
        return self._stack("wire_stiffness")[self.owner]

    @property
    def preload(self):
        """``(N,)`` each wire's preload (its owner's ``preload``, N)."""
        return self._stack("preload")[self.owner]

    @property
    def wire_angles(self):
        """``(N,)`` each wire's angle in its own segment (rad)."""
        return jnp.concatenate([s.wire_angles for s in self.segments])

    def params(self) -> dict:
        """The physical parameters as a flat dict of arrays, the form the equilibrium and the
        calibration effects work on: ``length``, ``EI`` (S,); ``route_angles``, ``route_radii``
        (N, S); ``wire_stiffness``, ``preload`` (N,); ``friction`` (2,), ``gravity`` (3,) and the holes'
        ``clearance`` (2,), zero;
        ``curvature_freedom`` (S,), one (a segment solved in pieces is an elastic rod, see
        :mod:`._equilibrium`)."""
        dt = self.route_angles.dtype
        return {
            "length": self.lengths.astype(dt),
            "EI": self.backbone_EI.astype(dt),
            "curvature_freedom": jnp.ones(self.n_segments, dt),
            "route_angles": self.route_angles,
            "route_radii": self.route_radii,
            "wire_stiffness": self.wire_stiffness.astype(dt),
            "preload": self.preload.astype(dt),
            "friction": jnp.zeros(2, dt),
            "gravity": jnp.zeros(3, dt),
            "clearance": jnp.zeros(2, dt),
        }

    # -- kinematics of one configuration B (S, 2) ----------------------------------------------
    def _B(self, B):
        return jnp.asarray(B, self.route_angles.dtype)

    def disk_poses(self, B):
        """Base-frame poses of the end disks: positions (S, 3) and rotations (S, 3, 3)."""
        ps, Rs = chain_poses(self.lengths, self._B(B))
        return ps[1:], Rs[1:]

    def tip_pose(self, B):
        """Tip position (3,) and orientation (3, 3): the product of the segment transforms."""
        return chain_tip(self.lengths, self._B(B))

    def J_xB(self, B):
        """Tip twist Jacobian ``[p_dot; omega] = J_xB vec(B_dot)``, (6, 2S), base frame."""
        return chain_J_xB(self.lengths, self._B(B))

    def J_qB(self, B=None):
        """``q_dot = J_qB vec(B_dot)``, (N, 2S), constant; columns ordered ``(u_0, v_0, u_1, v_1, ...)``."""
        return routing_matrix(self.route_angles, self.route_radii, self.crosses)

    def wire_length_changes(self, B):
        """``l_k(B) - l_k(0)`` (N,), mm."""
        return self.J_qB() @ self._B(B).reshape(-1)

    def wire_lengths(self, B):
        """Wire lengths from the base to each wire's end disk (N,), mm."""
        Ls = jnp.sum(jnp.where(self.crosses, self.lengths[None, :], 0.0), axis=1)
        return Ls + self.wire_length_changes(B)

    # -- tension zones and reduced Jacobians ---------------------------------------------------
    def tension_score(self, B, B_dot=None):
        """Normalised pull rate of each wire, (N,), in [-1, 1]: ``-q_dot_k / sum_j r_kj |b_dot_j|``.

        ``B_dot = None``: every segment bends further in its own plane. For one segment this is
        the single-segment ``tension_score`` (``cos(delta + alpha_k)``).
        """
        B = self._B(B)
        B_dot = _unit_directions(B) if B_dot is None else jnp.asarray(B_dot, B.dtype)
        q_dot = self.J_qB() @ B_dot.reshape(-1)
        norms = jnp.sqrt(jnp.sum(B_dot**2, axis=1))
        scale = jnp.sum(jnp.where(self.crosses, self.route_radii * norms[None, :], 0.0), axis=1)
        nz = scale > 0
        return jnp.where(nz, -q_dot / jnp.where(nz, scale, 1.0), 0.0)

    def segment_tension_scores(self, B):
        """``(N, S)``: ``cos(a_kj + delta_j)`` for the wires crossing segment ``j`` (0 elsewhere):
        positive where pulling wire ``k`` bends segment ``j`` further in its plane."""
        d = _unit_directions(self._B(B))
        a = self.route_angles
        sc = jnp.cos(a) * d[None, :, 0] + jnp.sin(a) * d[None, :, 1]
        return jnp.where(self.crosses, sc, 0.0)

    def tension_mask(self, B, B_dot=None, temperature=TEMPERATURE):
        """Wires in tension for the motion ``B_dot``, (N,) 0/1 with a straight-through gradient."""
        score = self.tension_score(B, B_dot)
        return straight_through(score > BOUNDARY_TOL, jax.nn.sigmoid(score / temperature))

    def J_xq(self, B, mask=None):
        """``J_xB pinv(J_qB)``, (6, N); ``mask`` (N,) keeps only the taut wires' rows (reduced)."""
        Jx, Jq = self.J_xB(B), self.J_qB()
        mask = jnp.ones(self.n_wires, Jq.dtype) if mask is None else jnp.asarray(mask, Jq.dtype)
        if self.n_segments == 1:
            return Jx @ (pinv_tall2(Jq * mask[:, None]) * mask[None, :])  # slack wires' columns exactly zero
        return Jx @ masked_pinv(Jq, mask)

    def reduced_J_xq(self, B, B_dot=None):
        """The reduced Jacobian: only the wires in their tension zone for ``B_dot``, (6, N)."""
        return self.J_xq(B, self.tension_mask(B, B_dot))

    # -- files -----------------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, d: dict[str, Any], warn_missing: bool = False) -> Robot:
        """``{"segments": [segment, ...]}`` (proximal first) or a single-segment design dict.

        A segment is a design dict (tension_zones/MODEL.md Sec. 6 keys). Segment ``j`` may add how its wires cross
        the proximal segments ``0 .. j-1``: ``route_angles_deg`` and/or ``route_radii_mm``, each a
        list with one entry per wire of the segment, every entry a list of ``j`` numbers (the wire's
        angle / pitch radius in segments 0, ..., j-1). Missing: the wire keeps its own angle and
        radius there (the default routing, see the module docstring).

        ``warn_missing``: one :class:`MissingDesignKeyWarning` naming every segment's physical keys
        that were left out (their defaults are used): a calibration should be told them, or it may
        "find" a default as an effect.
        """
        if not isinstance(d, dict):
            raise ValueError(f"a design file must hold a JSON object, got {type(d).__name__}")
        if "segments" not in d:
            return cls(Design.from_dict(d, warn_missing=warn_missing))
        extra = sorted(set(d) - {"segments", "calibrated"})
        if extra:
            raise ValueError(f"unknown robot design key(s) {extra}; known: ['calibrated', 'segments']")
        segs = d["segments"]
        if not isinstance(segs, list) or not segs:
            raise ValueError("'segments' must be a non-empty list of segment designs")
        designs, routes = [], []
        for i, s in enumerate(segs):
            if not isinstance(s, dict):
                raise ValueError(f"segment {i}: must be a JSON object, got {type(s).__name__}")
            s = dict(s)
            route = {k: s.pop(k) for k in ("route_angles_deg", "route_radii_mm") if k in s}
            try:
                designs.append(Design.from_dict(s))
            except ValueError as e:
                raise ValueError(f"segment {i}: {e}") from None
            routes.append(route)
        if warn_missing:
            _warn_missing(designs, segs)
        robot = cls(designs)
        if "calibrated" in d:
            check_calibrated(d["calibrated"], robot.n_wires)
        if not any(routes):
            return robot
        ra, rr = np.array(robot.route_angles), np.array(robot.route_radii)
        given = np.zeros(ra.shape, bool)
        k0 = 0
        for j, (seg, route) in enumerate(zip(designs, routes)):
            for key, arr, scale in (("route_angles_deg", ra, np.pi / 180), ("route_radii_mm", rr, 1.0)):
                if key in route:
                    arr[k0 : k0 + seg.n_wires, :j] = _routing_entry(route[key], j, seg.n_wires, key) * scale
                    given[k0 : k0 + seg.n_wires, :j] = True
            k0 += seg.n_wires
        _check_holes(robot, ra, rr, given)
        return cls(designs, route_angles=ra, route_radii=rr)

    @staticmethod
    def calibrated_block(d: dict[str, Any]) -> dict[str, Any]:
        """A design file's ``calibrated`` block (``{}`` if it has none): the per-wire values a
        calibration found (``calibrate``'s ``calibrated.design.json``, see
        :mod:`tension_zones.calibration._design_file`), checked by :meth:`from_dict`."""
        return dict(d.get("calibrated", {})) if isinstance(d, dict) else {}

    @classmethod
    def from_json(cls, path, warn_missing: bool = False) -> Robot:
        """:meth:`from_dict` of a JSON file; errors and the missing-key warning name the file."""
        d = read_json(path, "design file")
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", MissingDesignKeyWarning)
                robot = cls.from_dict(d, warn_missing=warn_missing)
        except ValueError as e:
            raise ValueError(f"design file {str(path)!r}: {e}") from None
        for w in caught:
            msg = f"design file {str(path)!r}: {w.message}" if w.category is MissingDesignKeyWarning else w.message
            warnings.warn(msg, w.category, stacklevel=2)
        return robot

    def to_dict(self) -> dict[str, Any]:
        out, k0 = [], 0
        ra, rr = np.degrees(np.asarray(self.route_angles)), np.asarray(self.route_radii)
        for j, s in enumerate(self.segments):
            seg = s.to_dict()
            rows = slice(k0, k0 + s.n_wires)
            own_a, own_r = np.degrees(np.asarray(s.wire_angles)), float(s.pitch_radius)
            if j and not np.allclose(ra[rows, :j], own_a[:, None]):
                seg["route_angles_deg"] = ra[rows, :j].tolist()
            if j and not np.allclose(rr[rows, :j], own_r):
                seg["route_radii_mm"] = rr[rows, :j].tolist()
            out.append(seg)
            k0 += s.n_wires
        return {"segments": out}

    def astype(self, dtype) -> Robot:
        return jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype), self)

    def __repr__(self) -> str:
        return f"Robot({', '.join(repr(s) for s in self.segments)})"


jax.tree_util.register_pytree_node(Robot, Robot._tree_flatten, Robot._tree_unflatten)


#: A design file's ``calibrated`` block: the per-wire and robot-wide values of a calibration that a design file keeps beside its segments.
CALIBRATED_KEYS = (
    "wire_play_mm",
    "preload_N",
    "wire_stiffness_N_per_mm",
    "friction",
    "gravity_N_per_mm",
    "clearance_mm_per_rad",
    "report",
)


def check_calibrated(block, n_wires: int) -> dict[str, Any]:
    """A design file's ``calibrated`` block, checked: known keys; per-wire lists of ``n_wires`` finite
    numbers (a play at least 0); the rest lists of finite numbers. One ValueError line otherwise."""
    if not isinstance(block, dict):
        raise ValueError(f"'calibrated' must be a JSON object, got {type(block).__name__}")
    unknown = sorted(set(block) - set(CALIBRATED_KEYS))
    if unknown:
        raise ValueError(f"unknown 'calibrated' key(s) {unknown}; known: {sorted(CALIBRATED_KEYS)}")
    for key, value in block.items():
        if key == "report":
            if not isinstance(value, str):
                raise ValueError(f"calibrated.report must be a file name, got {value!r}")
            continue
        ok = isinstance(value, list) and all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x) for x in value
        )
        if not ok:
            raise ValueError(f"calibrated.{key} must be a list of finite numbers")
        per_wire = key in ("wire_play_mm", "preload_N", "wire_stiffness_N_per_mm")
        if per_wire and len(value) != n_wires:
            raise ValueError(f"calibrated.{key} has {len(value)} values for {n_wires} wires")
        if key == "wire_play_mm" and min(value, default=0.0) < 0:
            raise ValueError("calibrated.wire_play_mm must be at least 0 (a play, mm)")
    return block


def _warn_missing(designs, dicts) -> None:
    """One warning naming each segment's physical keys left out of the file (defaults used)."""
    parts = []
    for i, (seg, d) in enumerate(zip(designs, dicts)):
        used = {
            "wire_stiffness_N_per_mm": seg.wire_stiffness,
            "backbone_EI_Nmm2": seg.backbone_EI,
            "preload_N": seg.preload,
        }
        missing = missing_physical_keys(d)
        if missing:
            parts.append(f"segment {i}: " + ", ".join(f"{k!r} (default {float(used[k]):g} used)" for k in missing))
    if parts:
        warnings.warn("design leaves out " + "; ".join(parts), MissingDesignKeyWarning, stacklevel=3)


def _check_holes(robot: Robot, ra, rr, given) -> None:
    """Refuse a routed wire that shares another wire's hole: two wires crossing a segment at the same
    angle and pitch radius there, one of them routed by the file (the default routing is left as
    the file's author chose it)."""
    owner, n_of = robot.owner, robot.n_wires_per_segment
    first = np.concatenate([[0], np.cumsum(n_of)])
    for j in range(robot.n_segments):
        ks = np.flatnonzero(robot.crosses[:, j])
        for a, k in enumerate(ks):
            for m in ks[a + 1 :]:
                if not (given[k, j] or given[m, j]):
                    continue
                gap = abs((ra[k, j] - ra[m, j] + np.pi) % (2 * np.pi) - np.pi)
                if gap <= 1e-9 and abs(rr[k, j] - rr[m, j]) <= 1e-9 * max(rr[k, j], 1.0):
                    w, o = (m, k) if given[m, j] else (k, m)
                    wire, other = (f"wire {x - first[owner[x]] + 1} of segment {owner[x]}" for x in (w, o))
                    raise ValueError(
                        f"segment {owner[w]}: its routing runs {wire} through segment {j} in the "
                        f"hole of {other} ({np.degrees(ra[o, j]):g} deg, radius {rr[o, j]:g} mm); "
                        "each wire needs its own hole"
                    )


def _routing_entry(value, j: int, n: int, key: str) -> np.ndarray:
    """A segment's ``route_*`` entry as an (n, j) array, or a one-line error naming the key."""
    if j == 0:
        raise ValueError(
            f"segment 0: {key} has no place on the first segment (it gives a wire's path through the "
            "segments before its own, and none lies before segment 0)"
        )
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"segment {j}: {key} must be a list of {n} lists of {j} numbers") from None
    if a.shape != (n, j):
        raise ValueError(
            f"segment {j}: {key} must be a list of {n} lists (one per wire) of {j} numbers "
            f"(segments 0..{j - 1}), got shape {a.shape}"
        )
    if not np.all(np.isfinite(a)):
        raise ValueError(f"segment {j}: {key} must be finite")
    if key == "route_radii_mm" and np.any(a <= 0):
        raise ValueError(f"segment {j}: {key} must be positive")
    return a


def _unit_directions(B):
    """Each segment's 'bend further' direction (S, 2): ``b_j/|b_j|``, ``(1, 0)`` at ``b_j = 0``
    (the ``delta = 0`` convention of ``b_to_psi``), with zero gradient there."""
    phi2 = jnp.sum(B * B, axis=1, keepdims=True)
    nz = phi2 > 0
    d = B / jnp.sqrt(jnp.where(nz, phi2, 1.0))  # double where: finite gradients at b_j = 0
    return jnp.where(nz, d, jnp.asarray([1.0, 0.0], B.dtype))
