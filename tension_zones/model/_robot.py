"""Multi-segment robots in bending-vector coordinates (MODEL.md Sec. 5, extended to several segments).

A :class:`Robot` is a chain of constant-curvature segments, proximal first. Segment ``j`` has its
own bending vector ``b_j = (u_j, v_j)``; a configuration is ``B``, shape ``(S, 2)``. Every wire
ends at the end disk of its own segment (its *owner*) and runs through every proximal segment at
its own angular position and pitch radius there (``route_angles[k, j]``, ``route_radii[k, j]``,
measured in segment ``j``'s base frame). Its length is the sum over the segments it crosses:

    l_k = sum_{j <= owner(k)} L_j - r_kj (u_j cos a_kj + v_j sin a_kj)        (linear in B)

Tip pose: the product of the segment transforms (``kinematics.tip_pose_b`` per segment).
Equilibrium: ``B* = argmin V(B)`` with

    V = sum_j EI_j |b_j|^2 / (2 L_j) + sum_k (k_k / 2) max(s_k, 0)^2 - f . p_tip(B)
        - sum_j (g L_j) . p_mid_j(B),      s_k = (l_k(B) - l_k(0)) - q_k + f_pre,k / k_k,

(pull-only wires with preload; ``f`` a tip force, ``g`` a line weight in N/mm lumped at each
segment's mid-point). A wire's stiffness ``k_k`` and preload are those its owner segment declares.
Solved per sample by a damped Newton method; derivatives by the implicit function theorem.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .._numerics import pinv_tall2, straight_through
from ._design import Design, read_json
from ._kinematics import b_to_psi, tip_pose_b
from ._zones import BOUNDARY_TOL, TEMPERATURE


# --------------------------------------------------------------------------------------------
# The robot
# --------------------------------------------------------------------------------------------
def _design_with(d: Design, **fields) -> Design:
    """``d`` with some data fields replaced, unvalidated (safe inside jit/vmap/grad)."""
    leaves, n = d._tree_flatten()
    names = ("length", "pitch_radius", "wire_angles", "wire_stiffness", "backbone_EI", "preload")
    leaves = tuple(jnp.asarray(fields.get(k, v)) for k, v in zip(names, leaves))
    return Design._tree_unflatten(n, leaves)


@dataclasses.dataclass(frozen=True, init=False, repr=False, eq=False)
class Robot:
    """A chain of segments (proximal first) with the routing of every wire.

    Args:
        segments: a sequence of :class:`Design` (or a single Design: a one-segment robot).
        route_angles: ``(N, S)`` angle (rad) of wire ``k`` in segment ``j``'s frame; ``None`` = the
            wire's own angle in every segment it crosses. Entries with ``j > owner(k)`` are unused.
        route_radii: ``(N, S)`` pitch radius (mm) likewise; ``None`` = its own segment's radius.

    Wires are numbered segment by segment (segment 0's wires first). Only the wire counts are
    static: changing any number never recompiles.
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
        if route_radii is not None and not isinstance(rr, jax.core.Tracer):
            if not np.all(np.isfinite(np.asarray(rr))) or np.any(np.asarray(rr) <= 0):
                raise ValueError("route_radii must be finite and positive")
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
    def n_segments(self) -> int:
        return len(self.segments)

    @property
    def n_wires_per_segment(self) -> tuple[int, ...]:
        return tuple(s.n_wires for s in self.segments)

    @property
    def n_wires(self) -> int:
        return sum(self.n_wires_per_segment)

    @property
    def owner(self) -> np.ndarray:
        """``(N,)`` segment index each wire ends in."""
        return np.repeat(np.arange(self.n_segments), self.n_wires_per_segment)

    @property
    def crosses(self) -> np.ndarray:
        """``(N, S)`` bool: wire ``k`` runs through segment ``j`` (``j <= owner(k)``)."""
        return np.arange(self.n_segments)[None, :] <= self.owner[:, None]

    # -- per-segment and per-wire values --------------------------------------------------------
    def _stack(self, field):
        return jnp.stack([jnp.asarray(getattr(s, field)) for s in self.segments])

    @property
    def lengths(self):
        return self._stack("length")

    @property
    def backbone_EI(self):
        return self._stack("backbone_EI")

    @property
    def wire_stiffness(self):
        """``(N,)`` each wire's stiffness (its owner's ``wire_stiffness``)."""
        return self._stack("wire_stiffness")[self.owner]

    @property
    def preload(self):
        """``(N,)`` each wire's preload (its owner's ``preload``)."""
        return self._stack("preload")[self.owner]

    @property
    def wire_angles(self):
        """``(N,)`` each wire's angle in its own segment."""
        return jnp.concatenate([s.wire_angles for s in self.segments])

    # -- construction from files ---------------------------------------------------------------
    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Robot:
        """``{"segments": [segment, ...]}`` (proximal first) or a single-segment design dict."""
        if isinstance(d, dict) and "segments" in d:
            extra = sorted(set(d) - {"segments"})
            if extra:
                raise ValueError(f"unknown robot design key(s) {extra}; known: ['segments']")
            segs = d["segments"]
            if not isinstance(segs, list) or not segs:
                raise ValueError("'segments' must be a non-empty list of segment designs")
            out = []
            for i, s in enumerate(segs):
                try:
                    out.append(Design.from_dict(s))
                except ValueError as e:
                    raise ValueError(f"segment {i}: {e}") from None
            return cls(out)
        return cls(Design.from_dict(d))

    @classmethod
    def from_json(cls, path) -> Robot:
        return cls.from_dict(read_json(path, "design file"))

    def to_dict(self) -> dict[str, Any]:
        return {"segments": [s.to_dict() for s in self.segments]}

    def astype(self, dtype) -> Robot:
        return jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype), self)

    def __repr__(self) -> str:
        return f"Robot({', '.join(repr(s) for s in self.segments)})"


jax.tree_util.register_pytree_node(Robot, Robot._tree_flatten, Robot._tree_unflatten)


@dataclasses.dataclass(frozen=True)
class Load:
    """External load in the base frame: ``tip_force`` (3,) N at the tip and ``gravity`` (3,) N/mm,
    the robot's weight per unit length, lumped at each segment's mid-point."""

    tip_force: jax.Array
    gravity: jax.Array

    @classmethod
    def none(cls, dtype=None) -> Load:
        z = jnp.zeros(3, dtype or jnp.result_type(float))
        return cls(z, z)


jax.tree_util.register_pytree_node(
    Load, lambda x: ((x.tip_force, x.gravity), None), lambda _, c: Load(*c)
)


# --------------------------------------------------------------------------------------------
# Kinematics
# --------------------------------------------------------------------------------------------
def wire_length_changes(robot: Robot, B):
    """``l_k(B) - l_k(0)``, (N,), mm: ``-sum_{j <= owner(k)} r_kj (u_j cos a_kj + v_j sin a_kj)``."""
    B = jnp.asarray(B, robot.route_angles.dtype)
    a, r = robot.route_angles, robot.route_radii
    per = r * (B[:, 0][None, :] * jnp.cos(a) + B[:, 1][None, :] * jnp.sin(a))
    return -jnp.sum(jnp.where(robot.crosses, per, 0.0), axis=1)


def wire_lengths(robot: Robot, B):
    """Wire lengths from the base to each wire's end disk, (N,), mm."""
    B = jnp.asarray(B, robot.route_angles.dtype)
    a, r = robot.route_angles, robot.route_radii
    per = robot.lengths[None, :] - r * (B[:, 0][None, :] * jnp.cos(a) + B[:, 1][None, :] * jnp.sin(a))
    return jnp.sum(jnp.where(robot.crosses, per, 0.0), axis=1)


def J_qB(robot: Robot, B=None):
    """``q_dot = J_qB vec(B_dot)``, (N, 2S), constant; columns ordered ``(u_0, v_0, u_1, v_1, ...)``."""
    a, r = robot.route_angles, robot.route_radii
    J = -r[..., None] * jnp.stack([jnp.cos(a), jnp.sin(a)], axis=-1)  # (N, S, 2)
    J = jnp.where(robot.crosses[..., None], J, 0.0)
    return J.reshape(robot.n_wires, 2 * robot.n_segments)


def disk_poses(robot: Robot, B):
    """Base-frame poses of the end disks: positions (S, 3) and rotations (S, 3, 3)."""
    B = jnp.asarray(B, robot.route_angles.dtype)
    p, R = tip_pose_b(robot.segments[0], B[0])
    ps, Rs = [p], [R]
    for j in range(1, robot.n_segments):
        pj, Rj = tip_pose_b(robot.segments[j], B[j])
        p, R = p + R @ pj, R @ Rj
        ps.append(p)
        Rs.append(R)
    return jnp.stack(ps), jnp.stack(Rs)


def tip_pose(robot: Robot, B):
    """Tip position (3,) and orientation (3, 3): the product of the segment transforms."""
    ps, Rs = disk_poses(robot, B)
    return ps[-1], Rs[-1]


def mid_points(robot: Robot, B):
    """Base-frame positions of the segments' mid-points (S, 3) (exact for constant curvature:
    the half segment has half the bending vector and half the length)."""
    return _disks_and_mids(robot, B)[1]


def _disks_and_mids(robot: Robot, B):
    """Tip position (3,) and mid-point positions (S, 3) in one pass along the chain."""
    B = jnp.asarray(B, robot.route_angles.dtype)
    p = jnp.zeros(3, B.dtype)
    R = jnp.eye(3, dtype=B.dtype)
    mids = []
    for j, seg in enumerate(robot.segments):
        mids.append(p + R @ (0.5 * tip_pose_b(seg, 0.5 * B[j])[0]))
        pj, Rj = tip_pose_b(seg, B[j])
        p, R = p + R @ pj, R @ Rj
    return p, jnp.stack(mids)


def J_xB(robot: Robot, B):
    """Tip twist Jacobian ``[p_dot; omega] = J_xB vec(B_dot)``, (6, 2S), base frame."""
    B = jnp.asarray(B, robot.route_angles.dtype)
    S = robot.n_segments
    p_of = lambda x: tip_pose(robot, x.reshape(S, 2))[0]  # noqa: E731
    R_of = lambda x: tip_pose(robot, x.reshape(S, 2))[1]  # noqa: E731
    x = B.reshape(-1)
    dp = jax.jacfwd(p_of)(x)
    dR = jax.jacfwd(R_of)(x)
    W = jnp.einsum("ijk,lj->kil", dR, R_of(x))
    omega = jnp.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=0)
    return jnp.concatenate([dp, omega], axis=0)


# --------------------------------------------------------------------------------------------
# Tension zones and reduced Jacobians
# --------------------------------------------------------------------------------------------
def _unit_directions(B):
    """Each segment's 'bend further' direction (S, 2): ``b_j/|b_j|``, ``(1, 0)`` at ``b_j = 0``
    (the ``delta = 0`` convention of ``kinematics.b_to_psi``)."""
    _, delta = jax.vmap(b_to_psi)(B)
    return jnp.stack([jnp.cos(delta), -jnp.sin(delta)], axis=1)


def tension_score(robot: Robot, B, B_dot=None):
    """Normalised pull rate of each wire, (N,), in [-1, 1]: ``-q_dot_k / sum_j r_kj |b_dot_j|``.

    ``B_dot = None``: every segment bends further in its own plane. For one segment this is
    ``zones.tension_score`` (``cos(delta + alpha_k)``).
    """
    B = jnp.asarray(B, robot.route_angles.dtype)
    B_dot = _unit_directions(B) if B_dot is None else jnp.asarray(B_dot, B.dtype)
    q_dot = J_qB(robot) @ B_dot.reshape(-1)
    norms = jnp.sqrt(jnp.sum(B_dot**2, axis=1))
    scale = jnp.sum(jnp.where(robot.crosses, robot.route_radii * norms[None, :], 0.0), axis=1)
    nz = scale > 0
    return jnp.where(nz, -q_dot / jnp.where(nz, scale, 1.0), 0.0)


def segment_tension_scores(robot: Robot, B):
    """``(N, S)``: ``cos(a_kj + delta_j)`` for the wires crossing segment ``j`` (0 elsewhere):
    positive where pulling wire ``k`` bends segment ``j`` further in its plane (its tension zone)."""
    B = jnp.asarray(B, robot.route_angles.dtype)
    d = _unit_directions(B)
    a = robot.route_angles
    sc = jnp.cos(a) * d[None, :, 0] + jnp.sin(a) * d[None, :, 1]
    return jnp.where(robot.crosses, sc, 0.0)


def tension_mask(robot: Robot, B, B_dot=None, temperature=TEMPERATURE):
    """Wires in tension for the motion ``B_dot``, (N,) 0/1 with a straight-through gradient."""
    score = tension_score(robot, B, B_dot)
    return straight_through(score > BOUNDARY_TOL, jax.nn.sigmoid(score / temperature))


def J_xq(robot: Robot, B, mask=None):
    """``J_xB pinv(J_qB)``, (6, N); ``mask`` (N,) keeps only the taut wires' rows (reduced)."""
    Jx, Jq = J_xB(robot, B), J_qB(robot)
    if mask is None:
        mask = jnp.ones(robot.n_wires, Jq.dtype)
    mask = jnp.asarray(mask, Jq.dtype)
    Jq = Jq * mask[:, None]
    pinv = pinv_tall2(Jq) if robot.n_segments == 1 else jnp.linalg.pinv(Jq)
    return Jx @ (pinv * mask[None, :])  # slack wires' columns exactly zero


def reduced_J_xq(robot: Robot, B, B_dot=None):
    """The robot's reduced Jacobian: only wires in their tension zone for ``B_dot``, (6, N)."""
    return J_xq(robot, B, tension_mask(robot, B, B_dot))


# --------------------------------------------------------------------------------------------
# Statics: energy, equilibrium (damped Newton + implicit differentiation)
# --------------------------------------------------------------------------------------------
def wire_stretch(robot: Robot, B, q):
    """``s_k = (l_k - l_k(0)) - q_k + f_pre / k_w``, (N,), mm (MODEL.md Sec. 5)."""
    return wire_length_changes(robot, B) - q + robot.preload / robot.wire_stiffness


def wire_tensions(robot: Robot, B, q):
    """Pull-only tensions ``k_w max(s, 0)``, (N,), N."""
    return robot.wire_stiffness * jnp.maximum(wire_stretch(robot, B, q), 0.0)


def load_potential(robot: Robot, B, load: Load):
    """``-f . p_tip - sum_j (g L_j) . p_mid_j`` (N mm)."""
    tip, mids = _disks_and_mids(robot, B)
    w = load.gravity[None, :] * robot.lengths[:, None]
    return -jnp.dot(load.tip_force, tip) - jnp.sum(w * mids)


def energy(robot: Robot, B, q, load: Load | None = None):
    """Potential energy ``V(B)`` (N mm) for commanded wire displacements ``q`` (N,) (negative =
    pulled in); ``load = None`` is no load at all (cheaper than a zero load)."""
    B = jnp.asarray(B, robot.route_angles.dtype)
    s = jnp.maximum(wire_stretch(robot, B, q), 0.0)
    V = jnp.sum(robot.backbone_EI * jnp.sum(B**2, axis=1) / (2.0 * robot.lengths))
    V = V + 0.5 * jnp.sum(robot.wire_stiffness * s**2)
    return V if load is None else V + load_potential(robot, B, load)


def _grad(robot, x, q, load):
    """Gradient of ``V`` in ``x = vec(B)``: closed form for the backbone and the wires (wire
    lengths are linear in ``B``), autodiff for the load."""
    S = robot.n_segments
    kb = jnp.repeat(robot.backbone_EI / robot.lengths, 2)
    tau = wire_tensions(robot, x.reshape(S, 2), q)
    g = kb * x + J_qB(robot).T @ tau
    if load is not None:
        g = g + jax.grad(lambda xx: load_potential(robot, xx.reshape(S, 2), load))(x)
    return g


def _grad_hess(robot, x, q, load):
    """Gradient and Hessian of ``V`` in ``x = vec(B)``."""
    S = robot.n_segments
    Jq = J_qB(robot)
    kb = jnp.repeat(robot.backbone_EI / robot.lengths, 2)
    s = wire_stretch(robot, x.reshape(S, 2), q)
    k = robot.wire_stiffness
    g = kb * x + Jq.T @ (k * jnp.maximum(s, 0.0))
    H = jnp.diag(kb) + (Jq.T * (k * (s > 0))[None, :]) @ Jq
    if load is not None:
        Vl = lambda xx: load_potential(robot, xx.reshape(S, 2), load)  # noqa: E731
        g = g + jax.grad(Vl)(x)
        H = H + jax.hessian(Vl)(x)
    return g, H


MAX_ITER = 60


def _newton(robot, q, load, B0):
    """Damped (Levenberg) Newton on ``V``; a step is taken only if ``V`` does not increase."""
    S = robot.n_segments
    V = lambda xx: energy(robot, xx.reshape(S, 2), q, load)  # noqa: E731
    x0 = jnp.asarray(B0, robot.route_angles.dtype).reshape(-1)
    n = x0.shape[0]
    eye = jnp.eye(n, dtype=x0.dtype)

    def body(state):
        x, mu, it, _ = state
        g, H = _grad_hess(robot, x, q, load)
        scale = jnp.trace(H) / n
        step = -jnp.linalg.solve(H + mu * scale * eye, g)
        x_new = x + step
        ok = V(x_new) <= V(x)
        x = jnp.where(ok, x_new, x)
        mu = jnp.where(ok, jnp.maximum(mu * 0.1, 1e-12), mu * 10.0)
        small = jnp.max(jnp.abs(step)) < 1e-13
        return x, mu, it + 1, ok & small

    def cond(state):
        return (state[2] < MAX_ITER) & ~state[3]

    init = (x0, jnp.asarray(1e-6, x0.dtype), jnp.asarray(0), jnp.asarray(False))
    x, *_ = jax.lax.while_loop(cond, body, init)
    return x.reshape(-1, 2)


@jax.custom_jvp
def _equilibrium(robot, q, load, B0):
    return _newton(robot, q, load, B0)


@_equilibrium.defjvp
def _equilibrium_jvp(primals, tangents):
    robot, q, load, B0 = primals
    B = _newton(robot, q, load, B0)
    x = B.reshape(-1)
    grad_at_x = lambda r, qq, ld: _grad(r, x, qq, ld)  # noqa: E731
    _, dg = jax.jvp(grad_at_x, (robot, q, load), tuple(tangents[:3]))
    H = _grad_hess(robot, x, q, load)[1]
    return B, (-jnp.linalg.solve(H, dg)).reshape(B.shape)


def equilibrium(robot: Robot, q, load: Load | None = None, B0=None):
    """Equilibrium bending vectors ``B*`` (S, 2) for one sample of wire displacements ``q`` (N,).

    Differentiable in ``robot``, ``q`` and ``load`` by the implicit function theorem
    (``dB = -H^-1 d(grad V)``), forward and reverse mode. ``vmap`` it over samples.
    """
    dt = robot.route_angles.dtype
    q = jnp.asarray(q, dt)
    if load is not None:
        load = jax.tree_util.tree_map(lambda x: jnp.asarray(x, dt), load)
    B0 = jnp.zeros((robot.n_segments, 2), dt) if B0 is None else jnp.asarray(B0, dt)
    return _equilibrium(robot, q, load, B0)


def forward(robot: Robot, q, load: Load | None = None):
    """Commanded wire displacements (N,) -> equilibrium tip position (3,) and rotation (3, 3)."""
    return tip_pose(robot, equilibrium(robot, q, load))


def equilibrium_J_pq(robot: Robot, q, load: Load | None = None):
    """``d p_tip / d q`` at equilibrium, (3, N): slack wires give zero columns."""
    return jax.jacfwd(lambda qq: forward(robot, qq, load)[0])(jnp.asarray(q, robot.route_angles.dtype))
