"""The equilibrium of a robot under commanded wire displacements and loads (tension_zones/MODEL.md Sec. 5, chained).

One solver for every robot, one segment or many. A configuration is ``x = vec(B)`` (2S,), the
segments' bending vectors. Commanded wire displacements ``q`` (N,) (negative = pulled in), a known
tip force ``f`` (3,) and the robot's weight per unit length ``g`` (3,) (N/mm, base frame) give
``B* = argmin V``,

    V(x) = sum_j EI_j |b_j|^2 / (2 L_j) + sum_k (t_k k_k / 2) max(s_k, 0)^2
           - f . p_tip(x) - g . sum_j int_{segment j} p ds,
    s_k  = (l_k(x) - l_k(0)) - q_k + f_pre,k / k_k               (pull only: a slack wire carries nothing)

(the weight is integrated exactly along each arc, :func:`~._kinematics.segment_weight_moment`).
Friction along the routing (capstan) makes the tension decay over every disk a wire crosses, in
the direction of its motion: the share of wire ``k``'s tension (at the actuator) that acts on piece
``i`` (a segment, or a piece of one in the rod model) is ``T_ki = exp(d_k (mu_0 + mu_1 w_ki))``, with
``d_k`` the wire's last direction of motion (+1 released: friction holds the wire back, -1 pulled in:
it loses tension on the way, 0 not yet moved), ``mu_0`` the routing before the robot and ``mu_1`` per
radian of the bending ``w_ki = sum_{l < i crossed} |b_l| + |b_i| / 2`` the wire has wrapped around
before the middle of piece ``i``. A pulled wire then bends its proximal pieces more than its distal
ones, and a distal segment's wire loses tension to the bending of the proximal segments it crosses.
The generalised force is ``F(x) = E x + sum_k k_k max(s_k, 0) (T_k * a_k) + (load)`` (``a_k`` the
wire's row of the routing matrix, ``T_k`` its factors per piece). Without friction (``mu = 0``)
``F = grad V`` and the problem is the energy minimisation of tension_zones/MODEL.md; with it, friction is not
conservative: ``T`` depends on ``x`` and ``F`` is no gradient. Within a Newton step, each wire's mean
factor ``t_k`` stands in ``V``, and the rest of the friction force, ``sum_k tau_k (T_k - t_k) a_k``, is
frozen at the iterate as a constant force (a linear term of ``V``): ``V``'s gradient there is ``F``,
so the iteration's fixed point is the root of ``F``.

**Hole clearance.** A wire under tension hugs the side of each disk's hole nearest the centre of
curvature, so its path through a bent piece is shorter than the routing's by ``C_ki |b_i|`` whichever
way the piece bends (``C_ki`` mm per rad: ``clearance[0]`` in the segment the wire ends in,
``clearance[1]`` in the proximal ones it crosses): ``s_k`` loses ``sum_i C_ki |b_i|``, and a distal
segment's wires slacken as the proximal segments bend. The wires' moment arms stay the routing's
(``a_k`` in ``F``): the contact's own moment, ``tau_k C_ki`` per radian, is left out. Against the
change of length it is of relative size ``EI / (L k r^2)`` (about 4 % on a 50 N/mm wire at 4.5 mm on
a 2454 N mm^2, 60 mm backbone) and, kept, it would make a preloaded straight robot buckle into a
ring of equal minima (``|b|`` has a cone at ``b = 0``). The shortening is frozen at the iterate within
a Newton step (a constant in ``V``, whose own step is taken): a fixed point on the shortening, which
contracts by about ``c / r`` a step. Its part of ``dF/dx`` (:meth:`_Sample.clearance_matrix`) enters
only the implicit derivative. In the step's LU solve (as friction's part is) it would converge in
fewer iterations, but its mere presence in that branch makes every rod solve slower, those without
clearance included, and the solves with clearance too.

**Compression of the backbone.** The wires' tension shortens each piece's backbone by ``a_i`` (mm/N,
``axial_compliance`` per segment spread over its pieces) times the tension of the wires that cross it,
and every wire's path through it with it: ``s = s0 - G tau``, ``G = X diag(a) X^T`` (``X`` (N, P) the
pieces each wire crosses), ``tau = k max(s, 0)``. For a given bending ``s`` is the root of the
piecewise-linear ``s + G k max(s, 0) = s0`` (:func:`_relax`), ``V`` gains the backbone's axial
energy ``tau^T G tau / 2``, the wires' Hessian is ``A^T W (I + G W)^-1 A`` (the taut wires in series
with the backbone) and the tip's kinematics takes the shortened lengths (:func:`compressed_lengths`).

**Friction of the bending** (hysteresis) is not part of one sample's solve: it depends on the
bending before. :func:`bending_memory` applies it to a recording's equilibria in acquisition order,
a play operator on each piece's bending in the metric of the elastic stiffness :func:`elastic_stiffness`
(the backbone's and the taut wires': the load's curvature, small and possibly indefinite, left out,
which also keeps the derivatives cheap).

**Solver.** Damped Newton on ``V`` (friction frozen at the iterate, above): the backbone's and the
wires' Hessian exact, the load's curvature learnt along the way (see :func:`_newton`), and a
backtracking line search over ten step sizes, the largest that satisfies Armijo's condition taken.
``max(s, 0)^2`` is only C1, so Newton is exact within a set of taut wires and the line search
handles set changes; with friction, from the 8th iteration on, a step must lower ``|F|`` too (V's
full steps can cycle between taut sets, docs/pages/model-reference.md). The derivatives come from the implicit
function theorem on ``F(x*) = 0``
(a custom JVP), never from the iterations. Per sample; ``vmap`` it.

**The rod model** (``Structure.pieces = m > 1``). Each segment's backbone is solved as ``m`` pieces of
length ``L/m``, each of constant curvature with its own bending vector, so ``x`` has ``2 S m``
components and the curvature may vary along a segment: the distributed weight, a tip force and
friction make it do so, as in an elastic (Kirchhoff) rod without shear or extension, to which the
pieces converge as ``m`` grows (``O(1/m^2)``, checked against a ``solve_bvp`` solution of the rod
equations in the tests). It is the same energy (each piece's bending ``EI m |b_i|^2 / (2 L)``, the
wires' stretch summed over the pieces they cross, the load integrated exactly along every piece),
so under tendon loads alone and without friction every piece of a segment takes the same bending
and the segment is exactly the constant-curvature one. ``curvature_freedom`` ``r_j`` (S,) in ``[0, 1]`` interpolates:
``1`` is the rod, ``0`` pins every piece to its segment's mean bending (constant curvature, up to
``1e-3`` of the rod's variation), by a penalty ``kappa_j |b_i - mean_j b|^2 / 2`` with ``kappa_j =
EI_j m / L_j (1 - r_j) / (r_j + 1e-3)``; its derivative at ``r = 0`` is the rod's first-order
variation, which is what lets the calibration score "variable curvature" like any other effect.

Physical parameters are the flat dict of :meth:`Robot.params` (``length``, ``EI`` (S,);
``route_angles``, ``route_radii`` (N, S); ``wire_stiffness``, ``preload`` (N,); ``friction`` (2,);
``gravity`` (3,); ``clearance`` (2,) and ``axial_compliance`` (S,), optional, zero if absent); the calibration's effects change
them, so the solver works on that dict and a :class:`~._robot.Structure` (the static wire counts).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._numerics import skew
from ._kinematics import segment_J_xb, segment_weight_moment, segment_weight_moment_jacobian
from ._robot import Robot, Structure, chain_poses, chain_tip, routing_matrix

#: Newton iterations at most (a piecewise-quadratic problem converges in a handful; set changes and
#: large bending take more).
MAX_ITER = 50
#: Largest change of a bending-vector component in one Newton step (rad): far from the equilibrium
#: of a loaded robot a Newton step can be huge; the line search then starts from this.
MAX_STEP = 0.5
#: ``curvature_freedom`` regularisation: at ``r = 0`` a segment's pieces deviate from their mean bending
#: by this fraction of the rod's variation.
_FREEDOM_EPS = 1e-3
#: Semismooth Newton steps for the stretch of wires that compress the backbone (:func:`_relax`):
#: piecewise linear, so a few reach the root (checked in the tests).
_RELAX_ITER = 6
#: Step sizes of the line search, tried from the largest down.
_STEPS = 2.0 ** -np.arange(10)

#: With friction, the iteration from which a step must lower ``|F|`` (``_newton``): V's steps end
#: almost every solve before it, and its full steps can cycle between taut sets
_FORCE_SEARCH = 8


@dataclasses.dataclass(frozen=True)
class Load:
    """External load in the base frame: ``tip_force`` (3,) N at the tip and ``gravity`` (3,) N/mm,
    the robot's weight per unit length (distributed exactly along every segment)."""

    tip_force: jax.Array
    gravity: jax.Array

    @classmethod
    def none(cls, dtype=None) -> Load:
        z = jnp.zeros(3, dtype or jnp.result_type(float))
        return cls(z, z)


jax.tree_util.register_pytree_node(Load, lambda x: ((x.tip_force, x.gravity), None), lambda _, c: Load(*c))


def _guarded_norm(b):
    """``|b|`` with a zero (not NaN) gradient at ``b = 0`` (double ``where``)."""
    s = jnp.sum(b * b, axis=-1)
    nz = s > 0
    return jnp.where(nz, jnp.sqrt(jnp.where(nz, s, 1.0)), 0.0)


def _pieces(lengths, B):
    """Per segment (or piece), vectorised: base poses ``ps`` (S+1, 3), ``Rs`` (S+1, 3, 3) along the
    chain, own end poses ``pj`` (S, 3), ``Rj`` (S, 3, 3) and first moments ``w`` (S, 3)."""
    ps, Rs = chain_poses(lengths, B)
    w = jax.vmap(segment_weight_moment)(lengths, B)
    return ps, Rs, w


@jax.jit  # (jitted: traced once per shape, not at each of its call sites in a solve's trace)
def load_potential(lengths, x, f, g):
    """``-f . p_tip - g . sum_j int p ds`` (N mm) for the configuration ``x`` (2S,)."""
    B = x.reshape(-1, 2)
    ps, Rs, w = _pieces(lengths, B)
    moment = jnp.sum(lengths[:, None] * ps[:-1] + jnp.einsum("sij,sj->si", Rs[:-1], w), axis=0)
    return -jnp.dot(f, ps[-1]) - jnp.dot(g, moment)


@jax.jit  # (jitted: its ~10 call sites in a calibration program's trace reuse one trace)
def load_jacobians(lengths, x):
    """``(d p_tip / d x, d M / d x)``, each (3, 2S), in closed form along the chain; ``M`` is the
    backbone's first moment ``sum_j int p ds`` (what a uniform weight acts on). The load's gradient is
    ``-(G_tip^T f + G_M^T g)``.

    Bending segment ``i`` moves everything distal to its end disk ``p_{i+1}`` by its world-frame
    Jacobian ``[J_v; J_w]`` (rotated by its base rotation ``R_i``): a point ``X`` distal to it moves by
    ``J_v + omega x (X - p_{i+1})``. The tip force sees ``X = p_tip``; the weight sees each distal
    segment's first moment ``M_j = L_j p_j + R_j int p ds`` (moving like ``L_j`` points at its
    centroid) and segment ``i``'s own ``R_i d(int p ds)/d b_i``. Vectorised over the segments (the
    distal sums are reversed cumulative sums), so a rod of many pieces compiles to the same size.
    (No reverse-mode autodiff: the load term's Hessian by differences of this compiles several
    times smaller.)
    """
    B = x.reshape(-1, 2)
    ps, Rs, w = _pieces(lengths, B)
    R0, tip, ends = Rs[:-1], ps[-1], ps[1:]
    moments = lengths[:, None] * ps[:-1] + jnp.einsum("sij,sj->si", R0, w)  # (S, 3)

    def distal(a):  # sum over j > i, (S, ...)
        c = jnp.cumsum(a[::-1], axis=0)[::-1]
        return jnp.concatenate([c[1:], jnp.zeros_like(c[:1])], axis=0)

    L_out, M_out = distal(lengths), distal(moments)
    J = jax.vmap(segment_J_xb)(lengths, B)  # (S, 6, 2)
    Jv, Jw = jnp.einsum("sij,sjk->sik", R0, J[:, :3]), jnp.einsum("sij,sjk->sik", R0, J[:, 3:])
    cross = jax.vmap(lambda a, m: skew(a) @ m)
    Gt = Jv - cross(tip[None, :] - ends, Jw)
    Gm = (
        L_out[:, None, None] * Jv
        - cross(M_out - L_out[:, None] * ends, Jw)
        + jnp.einsum("sij,sjk->sik", R0, jax.vmap(segment_weight_moment_jacobian)(lengths, B))
    )
    return jnp.concatenate(list(Gt), axis=1), jnp.concatenate(list(Gm), axis=1)


def load_gradient(lengths, x, f, g):
    """``d load_potential / d x`` (2S,), closed form (:func:`load_jacobians`)."""
    Gt, Gm = load_jacobians(lengths, x)
    return -(Gt.T @ f + Gm.T @ g)


@jax.custom_jvp
def _load_jacobians(lengths, x):
    """:func:`load_jacobians` whose derivative in the lengths is taken once for the ``S`` lengths (forward
    mode) and then contracted with any number of tangents: a calibration's Jacobian pushes dozens of
    tangents through here, nearly all of them zero in the lengths, and the configuration carries none."""
    return load_jacobians(lengths, x)


def _load_jacobians_jvp(primals, tangents):
    lengths, x = primals
    dL, dx = tangents
    out = load_jacobians(lengths, x)
    zero = tuple(jnp.zeros_like(o) for o in out)
    if type(dL) is jax.custom_derivatives.SymbolicZero:
        d = zero
    else:
        JL = jax.jacfwd(load_jacobians, argnums=0)(lengths, x)  # ((3, 2S, S), (3, 2S, S)): once, not per tangent
        d = tuple(j @ dL for j in JL)
    if type(dx) is not jax.custom_derivatives.SymbolicZero:
        _, dxo = jax.jvp(lambda y: load_jacobians(lengths, y), (x,), (dx,))
        d = tuple(a + b for a, b in zip(d, dxo))
    return out, d


_load_jacobians.defjvp(_load_jacobians_jvp, symbolic_zeros=True)


@jax.custom_jvp
def _relax(s0, k, G):
    """The stretch ``s`` (N,) of wires whose tension ``k max(s, 0)`` compresses the backbone: the root
    of ``s + G k max(s, 0) = s0`` (``s0`` the stretch of a rigid backbone, ``G`` (N, N) the
    compliance the wires share, module notes), by semismooth Newton from ``s0``: the equations are
    piecewise linear, so a few steps reach the root exactly (at most ``_RELAX_ITER``). Without
    compliance ``s0`` is the root and no step is taken (a ``while_loop`` that stops at a zero
    residual; docs/pages/model-reference.md has the alternatives). The derivative is the root's implicit one (a custom JVP: forward and
    reverse mode, never through the iterations), ``-dG k max(s0, 0)`` at ``G = 0``, what the score
    test needs there."""
    tol = 1e-13 * (1.0 + jnp.max(jnp.abs(s0)))
    eye = jnp.eye(s0.shape[0], dtype=s0.dtype)

    def residual(s):
        return s + G @ (k * jnp.maximum(s, 0.0)) - s0

    def more(c):
        return (c[1] < _RELAX_ITER) & (jnp.max(jnp.abs(residual(c[0]))) > tol)

    def step(c):
        return c[0] - jnp.linalg.solve(eye + G * (k * (c[0] > 0))[None, :], residual(c[0])), c[1] + 1

    return jax.lax.while_loop(more, step, (s0, jnp.asarray(0)))[0]


@_relax.defjvp
def _relax_jvp(primals, tangents):
    s0, k, G = primals
    ds0, dk, dG = tangents
    s = _relax(s0, k, G)
    taut = jnp.maximum(s, 0.0)
    rhs = ds0 - dG @ (k * taut) - G @ (dk * taut)  # d(s + G k max(s, 0)) = ds0 at fixed taut set
    return s, jnp.linalg.solve(jnp.eye(s.shape[0], dtype=s.dtype) + G * (k * (s > 0))[None, :], rhs)


class _Sample:
    """The pieces of ``V`` and ``F`` for one sample, gradient and generalised Hessian written out.

    ``loaded`` is a scalar that is *not* batched over samples (any tip force in the data, or a weight):
    when it is false the load terms are skipped by a conditional (exactly zero then), which keeps an
    unloaded robot's solve cheap while the derivatives with respect to a load stay exact (they need
    only the load's Jacobians, not their change with the configuration)."""

    def __init__(self, phys, structure: Structure, q, f, direction, loaded):
        m = structure.pieces
        L = phys["length"]
        ra, rr = phys["route_angles"], phys["route_radii"]
        if m > 1:  # every piece crossed at its segment's routing
            ra, rr = jnp.repeat(ra, m, axis=1), jnp.repeat(rr, m, axis=1)
        self.A = routing_matrix(ra, rr, structure.piece_crosses)  # (N, 2P)
        self.k = phys["wire_stiffness"]
        self.c = -q + phys["preload"] / self.k  # s = A x + c
        stiff = phys["EI"] * m / L  # (S,) one piece's EI / length
        self.E = jnp.repeat(stiff, 2 * m)
        self.lengths = jnp.repeat(L / m, m)  # (P,)
        self.m = m
        if m > 1:
            r = phys["curvature_freedom"]
            self.kappa = jnp.repeat(stiff * (1.0 - r) / (r + _FREEDOM_EPS), 2 * m)
            S = L.shape[0]
            avg = np.kron(np.eye(S), np.kron(np.full((m, m), 1.0 / m), np.eye(2)))
            self.D = jnp.asarray(np.eye(2 * S * m) - avg, self.A.dtype)  # deviation from the segment mean
        self.f, self.g = f, phys["gravity"]
        self.mu = phys["friction"]
        self.has_friction = jnp.any(self.mu != 0)
        self.direction = direction
        self.crosses = jnp.asarray(structure.piece_crosses, self.A.dtype)
        # (N, P, P): how much of piece l's bending wire k has wrapped before the middle of piece i
        before = np.tril(np.ones((structure.n_pieces,) * 2), -1) + 0.5 * np.eye(structure.n_pieces)
        c = np.asarray(structure.piece_crosses, float)
        self.wraps = jnp.asarray(c[:, :, None] * c[:, None, :] * before[None], self.A.dtype)
        self.loaded = loaded
        # hole clearance (module notes): wire k's path through piece i shortened by C_ki |b_i|
        cl = phys.get("clearance", jnp.zeros(2, self.A.dtype))
        own = np.asarray(structure.owner)[:, None] == np.repeat(np.arange(structure.n_segments), m)[None, :]
        proximal = np.asarray(structure.piece_crosses, bool) & ~own
        self.C = cl[0] * jnp.asarray(own, self.A.dtype) + cl[1] * jnp.asarray(proximal, self.A.dtype)  # (N, P)
        self.has_clearance = jnp.any(cl != 0)
        # the backbone's axial compliance (module notes): piece i shortens by a_i times the tension of
        # the wires that cross it, and so does every wire's path through it: G = X diag(a) X^T (N, N)
        comp = phys.get("axial_compliance", jnp.zeros(L.shape[0], self.A.dtype))
        self.a = jnp.repeat(comp / m, m)  # (P,) mm/N per piece
        self.G = (self.crosses * self.a[None, :]) @ self.crosses.T

    def _deviation(self, x):
        """``kappa * (x - segment mean)`` (2P,): the curvature-freedom penalty's gradient (0 if m = 1)."""
        if self.m == 1:
            return jnp.zeros_like(x)
        X = x.reshape(-1, self.m, 2)
        return self.kappa * (X - X.mean(axis=1, keepdims=True)).reshape(-1)

    def _if_loaded(self, fn, x, zero):
        return jax.lax.cond(self.loaded, fn, lambda _: zero, x)

    def piece_factors(self, x):
        """``T`` (N, P): the share of each wire's tension that acts on each piece, past friction along
        the routing and over the disks before the piece's middle (1 where the wire does not cross it)."""
        c = self.crosses
        wrap = c * _guarded_norm(x.reshape(-1, 2))[None, :]
        before = jnp.cumsum(wrap, axis=1) - 0.5 * wrap  # pieces are numbered from the base
        return jnp.where(c > 0, jnp.exp(self.direction[:, None] * (self.mu[0] + self.mu[1] * before)), 1.0)

    def factor(self, x):
        """Each wire's mean share ``t_k`` (N,) over the pieces it crosses (the Newton step's ``V``)."""
        return jnp.sum(self.crosses * self.piece_factors(x), axis=1) / jnp.sum(self.crosses, axis=1)

    def _spread(self, T):
        """Per-piece factors (N, P) as the routing matrix's columns (N, 2P)."""
        return jnp.repeat(T, 2, axis=1)

    def friction_rest(self, x, t, s=None, s_t=None):
        """The friction force beyond the mean factors ``t`` (2P,): the wires' part of ``F``, ``sum_k
        tau_k T_k a_k``, less the gradient of ``V`` with the mean factors (:meth:`grad`; ``sum_k tau_k
        (T_k - t_k) a_k`` for a rigid backbone). ``s``, ``s_t``: the stretch at ``x`` under wires of
        stiffness ``k`` and ``t k`` where the caller has them (:meth:`stretch`)."""
        kt = t * self.k
        tau = self.k * jnp.maximum(self.stretch(x) if s is None else s, 0.0)
        tau_t = kt * jnp.maximum(self.stretch(x, k=kt) if s_t is None else s_t, 0.0)
        return (self.A * self._spread(self.piece_factors(x))).T @ tau - self.A.T @ tau_t

    def shortening(self, x):
        """The hole clearance's shortening of each wire's path, ``C |b|`` (N,), mm (0 without it)."""
        return self.C @ _guarded_norm(x.reshape(-1, 2))

    def stretch(self, x, shortening=None, k=None):
        """``s`` (N,), mm; ``shortening`` (N,): the clearance's, frozen (a Newton step's), else at ``x``;
        less the backbone's compression (:func:`_relax`) under wires of stiffness ``k`` (default the
        wires'; a Newton step's ``V`` has them at their mean friction factors, ``t k``). Each call is
        a solve (a ``while_loop``): the methods below take it as ``s`` where the caller has it, so a
        Newton iteration solves it once per stiffness, not once per use (smaller programs)."""
        s0 = self.A @ x + self.c - (self.shortening(x) if shortening is None else shortening)
        return _relax(s0, self.k if k is None else k, self.G)

    def tension_matrix(self, x, shortening=None, k=None, s=None):
        """``d tau / d s0`` (N, N): the taut wires' stiffness in series with the backbone's compression,
        ``W (I + G W)^-1``, ``W = diag(k [s > 0])`` (symmetric), by Woodbury over the pieces,
        ``W - W X D (I + X^T W X D)^-1 X^T W`` with ``D = diag(a)`` (``W`` itself without compliance;
        no square root of ``a``, whose derivative at 0 is infinite)."""
        k = self.k if k is None else k
        s = self.stretch(x, shortening, k) if s is None else s
        w = k * (s > 0).astype(x.dtype)
        WX = w[:, None] * self.crosses  # (N, P)
        M = jnp.eye(WX.shape[1], dtype=w.dtype) + (self.crosses.T @ WX) * self.a[None, :]
        return jnp.diag(w) - (WX * self.a[None, :]) @ jnp.linalg.solve(M, WX.T)

    def wire_hessian(self, x, t, shortening=None, s=None):
        """The taut wires' part of ``V``'s Hessian with the mean factors ``t`` (2P, 2P): ``A^T K A``
        with ``K`` :meth:`tension_matrix` for wires of stiffness ``t k`` (``s``: their stretch)."""
        return self.A.T @ self.tension_matrix(x, shortening, t * self.k, s) @ self.A

    def compression(self, x):
        """Each piece's axial shortening (P,), mm: ``a_i`` times the tension of the wires crossing it."""
        tau = self.k * jnp.maximum(self.stretch(x), 0.0)
        return self.a * (self.crosses.T @ tau)

    def value(self, x, t, shortening=None, s=None):
        """``V`` with the wires at their mean friction factors ``t`` (stiffness ``t k``), ``shortening``
        frozen; its gradient is :meth:`grad` (the backbone's compression eliminated at its minimum)."""
        kt = t * self.k
        s = self.stretch(x, shortening, kt) if s is None else s
        load = self._if_loaded(lambda y: load_potential(self.lengths, y, self.f, self.g), x, jnp.zeros((), x.dtype))
        elastic = 0.5 * jnp.dot(self.E * x + self._deviation(x), x)
        tau = kt * jnp.maximum(s, 0.0)  # the backbone's compression stores tau^T G tau / 2 (0 without)
        return elastic + 0.5 * jnp.sum(kt * jnp.maximum(s, 0.0) ** 2) + 0.5 * tau @ self.G @ tau + load

    def load_grad(self, x):
        return self._if_loaded(lambda y: load_gradient(self.lengths, y, self.f, self.g), x, jnp.zeros_like(x))

    def grad(self, x, t, load_grad=None, shortening=None, s=None):
        kt = t * self.k
        tau = kt * jnp.maximum(self.stretch(x, shortening, kt) if s is None else s, 0.0)
        load = self.load_grad(x) if load_grad is None else load_grad
        return self.E * x + self._deviation(x) + self.A.T @ tau + load

    def _load_hessian(self, x):
        """The load term's Hessian by central differences of its closed-form gradient: accurate to
        ~1e-10 relative (Newton still converges to round-off, implicit derivatives carry that error);
        its exact second derivatives would make the compiled program several times larger."""

        def fd(x):
            n = x.shape[0]
            h = jnp.finfo(x.dtype).eps ** (1.0 / 3.0) * jnp.maximum(1.0, jnp.max(jnp.abs(x)))
            E = h * jnp.eye(n, dtype=x.dtype)
            G = jax.vmap(lambda y: load_gradient(self.lengths, y, self.f, self.g))(jnp.concatenate([x + E, x - E]))
            H = (G[:n] - G[n:]).T / (2.0 * h)
            return 0.5 * (H + H.T)

        return self._if_loaded(fd, x, jnp.zeros((x.shape[0],) * 2, x.dtype))

    def hess(self, x, t, s_t=None):
        """Generalised Hessian of ``V`` with ``t`` frozen: exact for the backbone and the wires,
        :meth:`_load_hessian` for the load (the exact implicit derivative uses it)."""
        return self.newton_matrix(x, t, s=s_t) + self._load_hessian(x)

    def newton_matrix(self, x, t, shortening=None, s=None):
        """The Newton step's matrix: the backbone's and the taut wires' Hessian, positive definite.
        The load's curvature is left out: it is small against the wires' (a tip force or a weight on
        a robot that holds it) and may be indefinite; the line search and the fixed point make up for
        it at a few more iterations, each much cheaper (no differences of the load's gradient, a
        Cholesky solve instead of an eigendecomposition)."""
        H = jnp.diag(self.E) + self.wire_hessian(x, t, shortening, s)
        return H if self.m == 1 else H + self.kappa[:, None] * self.D

    def force(self, x):
        """The generalised force ``F(x)`` whose root is the equilibrium (``t`` depends on ``x``).

        Its load part is ``-(G_tip^T f + G_M^T g)``; unloaded, the Jacobians ``G`` are constants (their
        change multiplies ``f = g = 0``), so derivatives in ``f`` and ``g`` cost two products."""
        wires = self._wires_force(x)

        def loaded(y):
            Gt, Gm = _load_jacobians(self.lengths, y)
            return -(Gt.T @ self.f + Gm.T @ self.g)

        def unloaded(y):
            Gt, Gm = jax.lax.stop_gradient(load_jacobians(self.lengths, y))
            return -(Gt.T @ self.f + Gm.T @ self.g)

        return self.E * x + self._deviation(x) + wires + jax.lax.cond(self.loaded, loaded, unloaded, x)

    def _wires_force(self, x):
        """The wires' part of ``F`` (2P,): ``sum_k tau_k T_k a_k``, their tensions past friction."""
        tau = self.k * jnp.maximum(self.stretch(x), 0.0)
        return (self.A * self._spread(self.piece_factors(x))).T @ tau

    def force_value(self, x, load_grad):
        """``F(x)`` (2P,) given the load's gradient there (:meth:`load_grad`): its value alone, for the
        Newton step's safeguard (:meth:`force` is the one differentiated)."""
        return self.E * x + self._deviation(x) + self._wires_force(x) + load_grad

    def friction_matrix(self, x, t, s=None, s_t=None):
        """What friction adds to ``dF/dx`` beyond ``V``'s Hessian with the mean factors ``t`` (2P, 2P),
        zero without friction: the rest of the factors times the taut wires' stiffness, and the
        factors' own change with the bending, ``dT_ki/db_l = T_ki d_k mu_1 dw_ki/db_l`` with
        ``dw_ki/db_l = b_l / |b_l|`` for a crossed piece ``l < i`` and half that for ``l = i``
        (``s``, ``s_t`` as in :meth:`friction_rest`)."""
        P = self.crosses.shape[1]
        T = self.piece_factors(x)
        stretch = self.stretch(x) if s is None else s
        rest = (self.A * self._spread(T)).T @ self.tension_matrix(x, s=stretch) @ self.A - self.wire_hessian(
            x, t, s=s_t
        )
        B = x.reshape(-1, 2)
        nb = _guarded_norm(B)
        unit = B / jnp.where(nb > 0, nb, 1.0)[:, None]  # d|b|/db, 0 at b = 0
        coef = (self.k * jnp.maximum(stretch, 0.0) * self.direction * self.mu[1])[:, None] * T * self.crosses
        turn = jnp.einsum("kp,kpi,kpl,lj->pilj", coef, self.A.reshape(-1, P, 2), self.wraps, unit)
        return rest + turn.reshape(2 * P, 2 * P)

    def clearance_matrix(self, x, s=None):
        """What the hole clearance adds to ``dF/dx`` (2P, 2P), zero without it: each taut wire's moment
        arms (times its friction factors) times the change of its shortening ``C_k |b|``,
        ``-sum_k k_k (T_k * a_k) (C_ki b_i / |b_i|)^T`` (0 at ``b_i = 0``)."""
        B = x.reshape(-1, 2)
        nb = _guarded_norm(B)
        unit = (B / jnp.where(nb > 0, nb, 1.0)[:, None]).reshape(-1)  # d|b|/db, 0 at b = 0
        arms = self.A * self._spread(self.piece_factors(x))
        return -arms.T @ (self.tension_matrix(x, s=s) @ (self._spread(self.C) * unit[None, :]))

    def coupling_matrix(self, x, t, s=None, s_t=None):
        """The non-symmetric part of ``dF/dx`` beyond ``V``'s Hessian with the mean factors ``t``:
        :meth:`friction_matrix` plus :meth:`clearance_matrix`."""
        s = self.stretch(x) if s is None else s
        return self.friction_matrix(x, t, s, s_t) + self.clearance_matrix(x, s)

    def force_jacobian(self, x):
        """``dF/dx`` (2P, 2P): :meth:`hess` with the mean factors plus :meth:`coupling_matrix` (a
        run-time branch, skipped where friction and clearance are zero)."""
        t = self.factor(x)
        s_t = self.stretch(x, k=t * self.k)
        zero = jnp.zeros((x.shape[0],) * 2, x.dtype)
        coupling = self.has_friction | self.has_clearance
        return self.hess(x, t, s_t) + jax.lax.cond(coupling, self.coupling_matrix, lambda *_: zero, x, t, None, s_t)


class _NewtonState(NamedTuple):
    """The state of :func:`_newton`'s loop."""

    x: jax.Array  # (2P,) the iterate
    HL: jax.Array  # (2P, 2P) the load's curvature learnt so far
    gl: jax.Array  # (2P,) the load's gradient at x (the last step's, not computed twice)
    it: jax.Array  # () iterations so far
    done: jax.Array  # () bool: the last step was below round-off


def _newton(sm: _Sample, x0, HL0):
    """Damped Newton on ``V`` (friction and the clearance's shortening frozen within a step): the
    backbone's and the wires' Hessian exact, the load's curvature learnt from its gradients along the
    way (a symmetric rank-one update, zero at the start and without a load), so that a loaded solve
    converges superlinearly without second derivatives of the chain. With friction (a run-time branch
    on ``mu != 0``) its part of ``dF/dx`` is added (not symmetric: an LU solve) and its force beyond
    the mean factors is frozen in ``V``; without it the step is a Cholesky solve. A hole clearance's
    shortening is frozen in ``V`` too (a fixed point; module notes). Where that step gives no descent the
    step falls back to the elastic part alone. Steps are capped (``MAX_STEP``) and the largest of
    ``_STEPS`` with Armijo's decrease is taken (tried from the largest down). Starts from ``x0``
    (2P,) with the load curvature ``HL0`` (2P, 2P) (a previous solve's, :func:`solve_warm`; zero for
    a cold start) and returns both at the end."""
    steps = jnp.asarray(_STEPS, x0.dtype)
    init = _NewtonState(x0, HL0, sm.load_grad(x0), jnp.asarray(0), jnp.asarray(False))
    st = jax.lax.while_loop(_newton_running, functools.partial(_newton_step, sm, steps), init)
    return st.x, st.HL


def _newton_running(st: _NewtonState):
    """Whether another Newton step is due: within ``MAX_ITER`` and not converged."""
    return (st.it < MAX_ITER) & ~st.done


def _newton_step(sm: _Sample, steps, st: _NewtonState) -> _NewtonState:
    """One Newton step: the direction at ``st.x`` (:func:`_direction`), its length by the line
    searches, then the load's curvature updated from the change of its gradient along the step."""
    x, HL, gl, it, _ = st
    t = sm.factor(x)
    # the clearance's shortening, frozen within the step; a run-time branch: the iterations carry no
    # derivative (the implicit one is taken from F at the root), so zero clearance skips it
    short = jax.lax.cond(sm.has_clearance, sm.shortening, lambda y: jnp.zeros_like(sm.c), x)
    s_t = sm.stretch(x, short, t * sm.k)  # once, for V's value, gradient and matrix at x
    d, g, rest = _direction(sm, x, t, short, s_t, HL, gl)
    v0 = sm.value(x, t, short, s_t)
    step = _force_search(sm, steps, x, d, g, _armijo_search(sm, steps, x, d, t, rest, g, v0, short), it)
    x_new = x + step
    gl_new = sm.load_grad(x_new)
    HL = _sr1(HL, gl_new - gl, step)
    done = jnp.max(jnp.abs(step)) <= 1e-13 * (1.0 + jnp.max(jnp.abs(x)))
    return _NewtonState(x_new, HL, gl_new, it + 1, done)


def _direction(sm: _Sample, x, t, short, s_t, HL, gl):
    """The step's direction (2P,) at ``x``, ``F(x)`` (2P,) and friction's frozen rest (2P,): Newton's
    on ``V`` with the learnt load curvature ``HL`` (with friction, on ``F``), the elastic part's alone
    where that gives no descent, capped at ``MAX_STEP`` (a trust region)."""
    g0, H = sm.grad(x, t, gl, short, s_t), sm.newton_matrix(x, t, short, s_t)
    # a run-time branch on the friction coefficients: they are shared by a vmap over samples, so
    # it stays a branch there, and a robot without friction skips its terms and the LU solve
    rest, d_full = jax.lax.cond(
        sm.has_friction, functools.partial(_friction_step, sm), _elastic_step, x, t, s_t, H + HL, g0
    )
    g = g0 + rest  # F(x)
    d_elastic = _cholesky_step(H, g)  # the elastic part's step, where the full one gives no descent
    d = jnp.where(jnp.all(jnp.isfinite(d_full)) & (jnp.dot(g, d_full) < 0), d_full, d_elastic)
    return d * jnp.minimum(1.0, MAX_STEP / jnp.maximum(jnp.max(jnp.abs(d)), 1e-300)), g, rest


def _cholesky_step(H, g):
    """``-H^-1 g`` for a positive definite ``H`` (2P, 2P)."""
    return -jax.scipy.linalg.cho_solve(jax.scipy.linalg.cho_factor(H), g)


def _friction_step(sm: _Sample, x, t, s_t, H, g0):
    """With friction: its force beyond the mean factors, frozen at the iterate (a constant force in
    ``V``, module notes), and the step to the root of ``F`` (friction's part of ``dF/dx`` is not
    symmetric: an LU solve)."""
    s = sm.stretch(x)
    rest = sm.friction_rest(x, t, s, s_t)
    return rest, -jnp.linalg.solve(H + sm.friction_matrix(x, t, s, s_t), g0 + rest)


def _elastic_step(x, t, s_t, H, g0):
    """Without friction: no rest, and ``V``'s own Newton step (symmetric: Cholesky)."""
    return jnp.zeros_like(g0), _cholesky_step(H, g0)


def _armijo_search(sm: _Sample, steps, x, d, t, rest, g, v0, short):
    """The step (2P,) along ``d``: the largest of ``steps`` with Armijo's decrease of ``V`` (value
    ``v0`` at ``x``; a round-off allowance, so converged steps are not rejected by noise in V), tried
    from the largest down, 0 where none. Under a vmap over samples it runs until every sample has its
    step, which near the equilibrium is the first (so the load's gradient is computed once per step,
    not for all ten step sizes at once, which costs more on loaded samples)."""

    def more(c):
        return (c[0] < steps.shape[0]) & ~c[1]

    def next_step(c):
        s = steps[c[0]]
        ok = sm.value(x + s * d, t, short) + s * jnp.dot(rest, d) <= v0 + 1e-4 * s * jnp.dot(g, d) + 1e-13 * (
            1.0 + jnp.abs(v0)
        )
        return jnp.where(ok, c[0], c[0] + 1), ok

    j, found = jax.lax.while_loop(more, next_step, (jnp.asarray(0), jnp.asarray(False)))
    return jnp.where(found, steps[jnp.minimum(j, steps.shape[0] - 1)], 0.0) * d


def _force_search(sm: _Sample, steps, x, d, g, step, it):
    """Friction's safeguard on the step (2P,) along ``d``. ``V`` (its rest frozen) describes the step's
    start only, and its full steps can cycle: with the backbone's compression a wire pulled alone
    alternated between two taut sets for all the iterations (tests/test_compression.py). So from
    iteration ``_FORCE_SEARCH`` on, the step must lower ``|F|^2`` (Armijo's on the force, which ``g`` is
    at ``x``: the Newton direction on ``F`` descends it), the largest of ``steps`` that does, ``V``'s
    own ``step`` where none does. A while loop, not a branch: under a vmap over samples it runs no
    trial at all until some sample is that far (a branch would be a select, its force evaluated every
    time)."""
    n = steps.shape[0]
    gg = jnp.dot(g, g)
    noise = (1e-9 * (1.0 + jnp.max(jnp.abs(sm.E * x)))) ** 2  # |F| this small: converged

    def more(c):
        return sm.has_friction & (it >= _FORCE_SEARCH) & (c[0] < n) & ~c[1]

    def next_step(c):
        s = steps[c[0]]
        y = x + s * d
        F = sm.force_value(y, sm.load_grad(y))
        ok = jnp.dot(F, F) <= (1.0 - 1e-4 * s) * gg + noise
        return jnp.where(ok, c[0], c[0] + 1), ok

    j, found = jax.lax.while_loop(more, next_step, (jnp.asarray(0), jnp.asarray(False)))
    return jnp.where(found, steps[jnp.minimum(j, n - 1)] * d, step)


def _sr1(HL, dg, step):
    """The load's curvature ``HL`` (2P, 2P) after a symmetric rank-one update from the change ``dg``
    of its gradient along ``step`` (skipped where the update's denominator is round-off)."""
    r = dg - HL @ step
    rs = jnp.dot(r, step)
    use = jnp.abs(rs) > 1e-8 * jnp.sqrt(jnp.dot(r, r) * jnp.dot(step, step)) + 1e-300
    return HL + jnp.where(use, jnp.outer(r, r) / jnp.where(use, rs, 1.0), 0.0)


@functools.cache
def _solver(structure: Structure):
    """The implicitly differentiated solve for one robot structure (static)."""

    def force(x, phys, q, f, direction, loaded):
        return _Sample(phys, structure, q, f, direction, loaded).force(x)

    @jax.custom_jvp
    def solve_x(phys, q, f, direction, loaded, x0, HL0):
        return _newton(_Sample(phys, structure, q, f, direction, loaded), x0, HL0)

    @solve_x.defjvp
    def solve_x_jvp(primals, tangents):
        # Implicit function theorem on F(x*, p) = 0: dx = -(dF/dx)^-1 (dF/dp . dp); dF/dp . dp by
        # forward mode at fixed x (x carries no tangent), dF/dx in closed form. The start and the
        # learnt load curvature (a warm start's state) carry no derivative.
        phys, q, f, direction, loaded, _, _ = primals
        x, HL = solve_x(*primals)
        _, rhs = jax.jvp(lambda *p: force(x, *p, loaded), primals[:4], tangents[:4])
        Jx = _Sample(phys, structure, q, f, direction, loaded).force_jacobian(x)
        return (x, HL), (-jnp.linalg.solve(Jx, rhs), jnp.zeros_like(HL))

    return solve_x


def solve(phys, structure: Structure, q, f, direction=None, x0=None, loaded=None):
    """Equilibrium bending vectors ``B*`` (P, 2) of one sample, one per piece (``P = S m``, pieces of
    segment ``j`` at rows ``j m .. j m + m - 1``; ``m = structure.pieces``, 1: one per segment),
    implicitly differentiable in ``phys``, ``q``, ``f`` (the initial guess ``x0`` (2P,) is not
    differentiated). The tip is ``chain_tip(piece_lengths(phys, structure), B*)``.

    Args: ``phys`` the physical parameters (:meth:`Robot.params` form); ``q`` (N,) commanded wire
    displacements (mm); ``f`` (3,) tip force (N, base frame); ``direction`` (N,) the wires' last
    directions of motion (only friction uses it; ``None`` = 0); ``loaded``: a bool scalar, false only
    if neither this sample nor any other under the same ``vmap`` has a tip force and ``phys`` has no
    weight (``None``: decided from this sample; pass it from outside a ``vmap`` over samples, where it
    is one value for all, to keep unloaded robots cheap).
    """
    state = cold_state(structure, jnp.result_type(phys["length"], q, float))
    if x0 is not None:
        state = (jnp.asarray(x0, state[0].dtype).reshape(-1), state[1])
    return solve_warm(phys, structure, q, f, direction, state, loaded)[0]


def cold_state(structure: Structure, dtype=float):
    """The state :func:`solve_warm` starts from without a previous solve: ``(x (2P,), HL (2P, 2P))``,
    zero bending and no load curvature learnt."""
    n = 2 * structure.n_pieces
    return jnp.zeros(n, dtype), jnp.zeros((n, n), dtype)


def solve_warm(phys, structure: Structure, q, f, direction, state, loaded=None):
    """:func:`solve` started from ``state`` = ``(x (2P,), HL (2P, 2P))``: a previous solve's bending and
    the load curvature its Newton iterations learnt (:func:`_newton`), or :func:`cold_state`. Returns
    ``(B* (P, 2), state)``, the state to start a solve for nearby parameters from (e.g. the next pass
    of a fit: the load's curvature already learnt, Newton converges in fewer iterations). The result
    is the same root whatever the start (to the Newton tolerance); the state carries no derivative.
    Per sample; ``loaded`` as in :func:`solve`."""
    dt = jnp.result_type(phys["length"], q, float)
    q, f = jnp.asarray(q, dt), jnp.asarray(f, dt)
    direction = jnp.zeros_like(q) if direction is None else jnp.asarray(direction, dt)
    if loaded is None:
        loaded = jnp.any(f != 0) | jnp.any(phys["gravity"] != 0)
    x0, HL0 = (jax.lax.stop_gradient(jnp.asarray(a, dt)) for a in state)
    x, HL = _solver(structure)(phys, q, f, direction, jax.lax.stop_gradient(loaded), x0.reshape(-1), HL0)
    return x.reshape(structure.n_pieces, 2), (x, HL)


def piece_lengths(phys, structure: Structure):
    """``(P,)`` the pieces' lengths (mm): each segment's length over its ``m`` pieces."""
    m = structure.pieces
    return phys["length"] if m == 1 else jnp.repeat(phys["length"] / m, m)


def compressed_lengths(phys, structure: Structure, q, f, direction, B):
    """``(P,)`` the pieces' lengths (mm) at the bending ``B`` (P, 2) of one sample, each shortened by
    the backbone's compression under the tension of the wires that cross it (``axial_compliance``;
    :func:`piece_lengths` without it). Arguments as in :func:`solve`."""
    dt = jnp.result_type(phys["length"], q, float)
    q, f = jnp.asarray(q, dt), jnp.asarray(f, dt)
    direction = jnp.zeros_like(q) if direction is None else jnp.asarray(direction, dt)
    sm = _Sample(phys, structure, q, f, direction, jnp.zeros((), bool))
    return piece_lengths(phys, structure) - sm.compression(jnp.asarray(B, dt).reshape(-1))


def segment_bending(B, structure: Structure):
    """``(S, 2)`` each segment's total bending vector from the pieces' ``B`` (P, 2) (their sum: exact
    for constant curvature, the mean curvature times the length for the rod)."""
    return B.reshape(structure.n_segments, structure.pieces, 2).sum(axis=1)


def elastic_stiffness(phys, structure: Structure, q, f, direction, B, loaded=None):
    """The backbone's and the taut wires' stiffness (2P, 2P) at the bending ``B`` (P, 2) of one sample
    (the Newton step's matrix: symmetric, positive definite; each taut wire at its mean friction
    factor; the load's curvature left out). Where every wire of a segment is slack it is that
    backbone's ``EI / L`` alone. Arguments as in :func:`solve`."""
    dt = jnp.result_type(phys["length"], q, float)
    q, f = jnp.asarray(q, dt), jnp.asarray(f, dt)
    direction = jnp.zeros_like(q) if direction is None else jnp.asarray(direction, dt)
    loaded = jnp.zeros((), bool) if loaded is None else loaded  # the load's curvature is not used
    sm = _Sample(phys, structure, q, f, direction, loaded)
    x = jnp.asarray(B, dt).reshape(-1)
    return sm.newton_matrix(x, sm.factor(x))


def bending_memory(X, K, h, reset=None):
    """Coulomb friction of the bending (hysteresis): each piece's bending sticks until the elastic
    moment that pulls it back to equilibrium exceeds a friction moment ``h``.

    ``X`` (n, 2P) the equilibria without that friction, in acquisition order; ``K`` (n, 2P, 2P) the
    stiffness there (:func:`elastic_stiffness`: symmetric, positive definite); ``h`` (P,) each piece's
    friction moment (N mm, >= 0); ``reset`` (n,) 0/1 where a recording starts (no memory of what came
    before) -> (n, 2P) the bending with friction. A play operator in moment space: the moment ``m = K (x_prev - x*)`` of the previous
    bending about this sample's equilibrium is clamped, piece by piece, to the norm ``h``, and
    ``x = x* + K^-1 m_clamped`` (``x_prev`` kept where ``|m| <= h`` everywhere). Where a segment's
    wires are taut its stiffness is the wires' and the play is small; where they are all slack it is
    the backbone's alone and the robot keeps most of its last shape. It is the incremental minimum of
    ``V + h |x - x_prev|`` for a quadratic ``V`` of isotropic stiffness per piece (for another, its
    first-order approximation). Written with double ``where`` so that at ``h = 0`` (``x = x*``) the
    derivative with respect to ``h`` is ``K^-1`` times the unit moment (what the score test needs),
    finite where two samples are the same."""
    n, P = X.shape[0], h.shape[0]
    reset = jnp.zeros(n, X.dtype) if reset is None else jnp.asarray(reset, X.dtype)
    K_inv = jnp.linalg.inv(K)  # batched, outside the sequential scan

    def step(prev, xs):
        x, k, k_inv, r = xs
        prev = jnp.where(r > 0, x, prev)
        mom = (k @ (prev - x)).reshape(P, 2)
        sq = jnp.sum(mom**2, axis=-1)
        moving = sq > h**2
        norm = jnp.sqrt(jnp.where(moving, sq, 1.0))
        scale = jnp.where(moving, h / norm, 1.0)
        cur = jnp.where(jnp.any(moving), x + k_inv @ (mom * scale[:, None]).reshape(-1), prev)
        return cur, cur

    _, out = jax.lax.scan(step, X[0], (X, K, K_inv, reset))
    return out


# --------------------------------------------------------------------------------------------
# The same for a Robot (the public, single-sample API)
# --------------------------------------------------------------------------------------------
def _phys(robot: Robot, load: Load | None):
    phys = robot.params()
    if load is not None:
        phys["gravity"] = jnp.asarray(load.gravity, phys["length"].dtype)
    f = jnp.zeros(3, phys["length"].dtype) if load is None else jnp.asarray(load.tip_force, phys["length"].dtype)
    return phys, f


def _structure(robot: Robot, pieces: int) -> Structure:
    if not isinstance(pieces, int) or isinstance(pieces, bool) or pieces < 1:
        raise ValueError(f"pieces must be a positive integer, got {pieces!r}")
    return Structure(robot.n_wires_per_segment, pieces)


def equilibrium(robot: Robot, q, load: Load | None = None, B0=None, pieces: int = 1):
    """Equilibrium bending vectors for one sample of wire displacements ``q`` (N,): ``(S, 2)``, one
    per segment, with ``pieces=1`` (constant curvature); ``(S * pieces, 2)``, one per piece, for the
    rod model (each segment solved as ``pieces`` constant-curvature pieces, see the module notes).

    Differentiable in ``robot``, ``q`` and ``load`` by the implicit function theorem, forward and
    reverse mode. ``vmap`` it over samples. ``pieces`` is static (a shape).
    """
    phys, f = _phys(robot, load)
    return solve(phys, _structure(robot, pieces), q, f, x0=B0)


def forward(robot: Robot, q, load: Load | None = None, pieces: int = 1):
    """Commanded wire displacements (N,) -> equilibrium tip position (3,) and rotation (3, 3);
    ``pieces > 1``: the rod model (see :func:`equilibrium`)."""
    st = _structure(robot, pieces)
    phys, f = _phys(robot, load)
    B = solve(phys, st, q, f)
    return chain_tip(compressed_lengths(phys, st, q, f, None, B), B)


def wire_stretch(robot: Robot, B, q):
    """``s_k = (l_k - l_k(0)) - q_k + f_pre / k_w``, (N,), mm (tension_zones/MODEL.md Sec. 5)."""
    return robot.wire_length_changes(B) - q + robot.preload / robot.wire_stiffness


def wire_tensions(robot: Robot, B, q):
    """Pull-only tensions ``k_w max(s, 0)``, (N,), N (no friction)."""
    return robot.wire_stiffness * jnp.maximum(wire_stretch(robot, B, q), 0.0)


def energy(robot: Robot, B, q, load: Load | None = None):
    """Potential energy ``V(B)`` (N mm) for commanded wire displacements ``q`` (N,) (no friction)."""
    phys, f = _phys(robot, load)
    sm = _Sample(
        phys, robot.structure, jnp.asarray(q, phys["length"].dtype), f, jnp.zeros(robot.n_wires), jnp.asarray(True)
    )
    return sm.value(jnp.asarray(B, phys["length"].dtype).reshape(-1), jnp.ones(robot.n_wires))


def equilibrium_J_pq(robot: Robot, q, load: Load | None = None):
    """``d p_tip / d q`` at equilibrium, (3, N): slack wires give zero columns."""
    return jax.jacfwd(lambda qq: forward(robot, qq, load)[0])(jnp.asarray(q, robot.route_angles.dtype))
