"""Constant-curvature kinematics of one segment (tension_zones/MODEL.md Sec. 1 and 5; paper Sec. 2).

Every function here is written for **one pose** and is pure, so it can be ``jit``-ed, ``vmap``-ed
over a grid (:func:`over_grid`) and differentiated. Frames: everything is expressed in the base
frame {B}; twists are ``[p_dot; omega]`` with ``omega = vee(R_dot R^T)``.

Configuration ``psi = [theta_L, delta]`` (rad): ``theta_0 = pi/2`` is straight, the bending angle is
``phi = theta_0 - theta_L`` and the segment bends toward ``sigma = -delta``. The singularity-free
bending vector is ``b = (u, v) = phi (cos sigma, sin sigma)``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._numerics import (
    cubic_sq,
    float_dtype,
    pinv_tall2,
    rotvec_to_matrix,
    sinc_comp_sq,
    sinc_sq,
    sinc_versinc_cubic,
    versinc_sq,
    with_derivatives,
)
from ._design import Design

THETA_0 = jnp.pi / 2


def _as_float(design: Design, *xs):
    dt = float_dtype(design.length, *xs)
    return tuple(jnp.asarray(x, dt) for x in xs)


# --------------------------------------------------------------------------------------------
# Coordinates
# --------------------------------------------------------------------------------------------
def psi_to_b(theta_L, delta):
    """``(theta_L, delta)`` -> bending vector ``b = phi (cos delta, -sin delta)``, shape (2,)."""
    phi = THETA_0 - theta_L
    return jnp.stack([phi * jnp.cos(delta), -phi * jnp.sin(delta)])


def b_to_psi(b):
    """Bending vector (2,) -> ``(theta_L, delta)`` with ``phi >= 0`` and ``delta`` in (-pi, pi].

    ``delta`` is undefined at ``b = 0``; it is returned as 0 there, with zero gradient.
    """
    u, v = b[0], b[1]
    phi2 = u * u + v * v
    nz = phi2 > 0
    phi = jnp.sqrt(jnp.where(nz, phi2, 1.0))
    phi = jnp.where(nz, phi, 0.0)
    delta = jnp.where(nz, jnp.arctan2(-v, jnp.where(nz, u, 1.0)), 0.0)
    return THETA_0 - phi, delta


# --------------------------------------------------------------------------------------------
# Pose in psi coordinates
# --------------------------------------------------------------------------------------------
def tip_pose(design: Design, theta_L, delta):
    """Tip position ``p`` (3,) in mm and orientation ``R`` (3, 3) in {B} (tension_zones/MODEL.md Sec. 1).

    ``p = (L / phi) [cos d (1 - cos phi), -sin d (1 - cos phi), sin phi]``,
    ``R = Rz(-d) Ry(phi) Rz(d)``; smooth through the straight pose.
    """
    theta_L, delta = _as_float(design, theta_L, delta)
    return tip_pose_b(design, psi_to_b(theta_L, delta))


def wire_lengths(design: Design, theta_L, delta):
    """Wire lengths ``l_k = L + r cos(delta_k) (theta_L - theta_0)`` (n,), mm (paper Eq. 8)."""
    theta_L, delta = _as_float(design, theta_L, delta)
    delta_k = delta + design.wire_angles
    return design.length + design.pitch_radius * jnp.cos(delta_k) * (theta_L - THETA_0)


def J_xpsi(design: Design, theta_L, delta):
    """Analytic twist Jacobian ``xi = J_xpsi psi_dot``, (6, 2) (tension_zones/MODEL.md Sec. 1; paper Eq. 7).

    The ratios ``A/T^2``, ``(s - 1)/T`` and ``(T s + c)/T^2`` (``T = theta_L - theta_0``) are
    evaluated by series near ``T = 0`` so values and gradients are finite at the straight pose.
    """
    theta_L, delta = _as_float(design, theta_L, delta)
    return J_xpsi_from_terms(design.length, J_xpsi_terms(theta_L, delta))


def J_xpsi_terms(theta_L, delta, trig=None):
    """The transcendental part of :func:`J_xpsi`: ``(T, c, s, sd, cd, A/T^2, (s - 1)/T, (T s + c)/T^2)``.

    Split out so that a caller evaluating many measures per pose can compute these once (and keep
    them, see :func:`tension_zones._numerics.keep`); :func:`J_xpsi_from_terms` does the rest.
    ``trig = (cos theta_L, sin theta_L, sin delta, cos delta)`` if the caller already has them.
    """
    T = theta_L - THETA_0
    if trig is None:
        trig = (jnp.cos(theta_L), jnp.sin(theta_L), jnp.sin(delta), jnp.cos(delta))
    c, s, sd, cd = trig
    # sin T = -c and cos T = s, so the ratios need no further sine or cosine:
    # A/T^2 = (1 - cos T)/T^2 - sin T/T,  (s - 1)/T = -T (1 - cos T)/T^2,
    # (T s + c)/T^2 = T (T cos T - sin T)/T^3.
    sinc, versinc, cubic = sinc_versinc_cubic(T, -c, s)
    a_over_T2 = versinc - sinc
    s1_over_T = -T * versinc
    z_term = T * cubic
    return T, c, s, sd, cd, a_over_T2, s1_over_T, z_term


def J_xpsi_from_terms(L, terms):
    """:func:`J_xpsi` (6, 2) from the backbone length and :func:`J_xpsi_terms`."""
    T, c, s, sd, cd, a_over_T2, s1_over_T, z_term = terms
    z = jnp.zeros_like(T)
    Jv = L * jnp.array(
        [
            [cd * a_over_T2, -sd * s1_over_T],
            [-sd * a_over_T2, -cd * s1_over_T],
            [z_term, z],
        ]
    )
    Jw = jnp.array([[-sd, cd * c], [-cd, -sd * c], [z, -1.0 + s]])
    return jnp.concatenate([Jv, Jw], axis=0)


def J_qpsi(design: Design, theta_L, delta):
    """Joint Jacobian ``q_dot = J_qpsi psi_dot``, (n, 2); row k = ``r [cos d_k, -(theta_L - theta_0) sin d_k]``."""
    theta_L, delta = _as_float(design, theta_L, delta)
    delta_k = delta + design.wire_angles
    T = theta_L - THETA_0
    r = design.pitch_radius
    return jnp.stack([r * jnp.cos(delta_k), -r * T * jnp.sin(delta_k)], axis=1)


def jacobians(design: Design, theta_L, delta):
    """``(J_xpsi (6, 2), J_qpsi (n, 2))`` at one pose."""
    return J_xpsi(design, theta_L, delta), J_qpsi(design, theta_L, delta)


def J_xq(design: Design, theta_L, delta, mask=None):
    """Joint-to-task Jacobian ``J_xpsi pinv(J_qpsi)``, (6, n) (paper Eq. 12).

    ``mask`` (n,) of 0/1 keeps only the rows of the taut wires (the reduced Jacobian, paper
    Sec. 3.3); the columns of slack wires are then zero. ``None`` = all wires (push-pull).
    """
    Jx, Jq = jacobians(design, theta_L, delta)
    if mask is not None:
        Jq = Jq * jnp.asarray(mask, Jq.dtype)[:, None]
    return Jx @ pinv_tall2(Jq)


# --------------------------------------------------------------------------------------------
# Bending-vector coordinates (tension_zones/MODEL.md Sec. 5)
# --------------------------------------------------------------------------------------------
def tip_pose_b(design: Design, b):
    """Tip position (3,) and orientation (3, 3) from the bending vector ``b = (u, v)`` (rad).

    ``p = [L (1 - cos phi)/phi^2 u, L (1 - cos phi)/phi^2 v, L sin(phi)/phi]``, ``phi = |b|``;
    rotation vector ``(-v, u, 0)``. Smooth at ``b = 0``. (:func:`segment_pose` of the design's length.)
    """
    (b,) = _as_float(design, b)
    return segment_pose(design.length, b)


def segment_pose(L, b):
    """End-disk position (3,) and rotation (3, 3) of a constant-curvature segment of length ``L`` (mm)
    and bending vector ``b`` (2,), in the segment's base frame (tension_zones/MODEL.md Sec. 5).

    The one formula of a segment's pose: :func:`tip_pose_b` and a robot's chain of segments use it.
    """
    u, v = b[0], b[1]
    phi2 = u * u + v * v
    k = L * versinc_sq(phi2)
    p = jnp.stack([k * u, k * v, L * sinc_sq(phi2)])
    R = rotvec_to_matrix(jnp.stack([-v, u, jnp.zeros_like(u)]), phi2)
    return p, R


def segment_weight_moment(L, b):
    """``int_0^L p(s) ds`` (3,), mm^2: the first moment of a constant-curvature segment's backbone in its
    base frame, for a load distributed uniformly along it (self-weight).

    The point at arc length ``s`` has bending vector ``b s / L``; integrating :func:`segment_pose`'s
    position gives ``L^2 [g u, g v, c]`` with ``g = (phi - sin phi)/phi^3``, ``c = (1 - cos phi)/phi^2``
    (finite at ``b = 0``: ``L^2 [0, 0, 1/2]``, a straight rod's centroid at ``L/2`` times ``L``).
    """
    u, v = b[0], b[1]
    phi2 = u * u + v * v
    g = sinc_comp_sq(phi2)
    return L * L * jnp.stack([g * u, g * v, versinc_sq(phi2)])


def segment_weight_moment_jacobian(L, b):
    """``d (int_0^L p ds) / d b`` (3, 2) of :func:`segment_weight_moment`, in closed form: with
    ``x = |b|^2`` and ``'`` = ``d/dx``, columns ``L^2 [g + 2u^2 g', 2uv g', 2u c']`` and
    ``L^2 [2uv g', g + 2v^2 g', 2v c']``."""
    u, v = b[0], b[1]
    x2 = u * u + v * v
    g, g1 = with_derivatives(sinc_comp_sq, x2)
    _, c1 = with_derivatives(versinc_sq, x2)
    L2 = L * L
    du = jnp.stack([g + 2 * u * u * g1, 2 * u * v * g1, 2 * u * c1])
    dv = jnp.stack([2 * u * v * g1, g + 2 * v * v * g1, 2 * v * c1])
    return L2 * jnp.stack([du, dv], axis=1)


def moment_arms(radius, angles):
    """``d l / d b`` of wires at ``angles`` (rad) on a pitch circle of ``radius`` (mm): ``-r [cos a, sin a]``,
    shape ``angles.shape + (2,)``. Wire lengths are linear in ``b`` (tension_zones/MODEL.md Sec. 5)."""
    return -jnp.asarray(radius)[..., None] * jnp.stack([jnp.cos(angles), jnp.sin(angles)], axis=-1)


def wire_lengths_b(design: Design, b):
    """``l_k = L - r (u cos alpha_k + v sin alpha_k)`` (n,), mm: linear in ``b``."""
    (b,) = _as_float(design, b)
    return design.length - design.pitch_radius * (
        b[0] * jnp.cos(design.wire_angles) + b[1] * jnp.sin(design.wire_angles)
    )


def J_qb(design: Design, b=None):
    """``q_dot = J_qb b_dot``, (n, 2): the constant ``-r [cos alpha_k, sin alpha_k]``."""
    return moment_arms(design.pitch_radius, design.wire_angles)


def bend_coeffs(x2, second=False):
    """Scalar coefficients of the tip pose and its Jacobian in ``b``, as functions of ``x2 = |b|^2``.

    Returns ``(c, c', s', g)`` -- or with ``second=True`` ``(c, c', c'', s', s'', g, g')`` -- where
    ``c = (1 - cos phi)/phi^2``, ``s = sin(phi)/phi``, ``g = (phi - sin phi)/phi^3`` and ``'`` is
    ``d/d x2``; series near ``x2 = 0`` (finite values and gradients at the straight pose).
    """
    if not second:
        c, c1 = with_derivatives(versinc_sq, x2)
        return c, c1, 0.5 * cubic_sq(x2), sinc_comp_sq(x2)
    c, c1, c2 = with_derivatives(versinc_sq, x2, order=2)
    _, s1, s2 = with_derivatives(sinc_sq, x2, order=2)
    g, g1 = with_derivatives(sinc_comp_sq, x2)
    return c, c1, c2, s1, s2, g, g1


def J_xb_cols(L, u, v, coeffs):
    """:func:`J_xb` as its two columns ``(d/du, d/dv)``, each a list of 6 scalars, from
    :func:`bend_coeffs` ``(c, c', s', g)`` (elementwise: vmapped it fuses, no tiny matmuls)."""
    c, c1, s1, g = coeffs
    uv = u * v
    du = [L * (c + 2 * u * u * c1), L * 2 * uv * c1, L * 2 * u * s1, -g * uv, 1.0 - g * v * v, -c * v]
    dv = [L * 2 * uv * c1, L * (c + 2 * v * v * c1), L * 2 * v * s1, -1.0 + g * u * u, g * uv, c * u]
    return du, dv


def J_xb(design: Design, b):
    """Twist Jacobian in bending-vector coordinates, (6, 2): ``[p_dot; omega] = J_xb b_dot``.

    Closed form of the derivative of :func:`tip_pose_b` (tension_zones/MODEL.md Sec. 5), with ``x = |b|^2`` and
    the coefficients of :func:`bend_coeffs`: ``dp/du = L (c + 2u^2 c', 2uv c', 2u s')``,
    ``dp/dv = L (2uv c', c + 2v^2 c', 2v s')``; ``omega = J_l(rho) rho_dot`` for the rotation vector
    ``rho = (-v, u, 0)``, with SO(3)'s left Jacobian ``J_l = I + c K + g K^2`` (``K = skew(rho)``):
    ``omega_u = (-g uv, 1 - g v^2, -c v)``, ``omega_v = (-1 + g u^2, g uv, c u)``.
    """
    (b,) = _as_float(design, b)
    return segment_J_xb(design.length, b)


def segment_J_xb(L, b):
    """:func:`J_xb` of a segment of length ``L`` (6, 2), in its base frame (used by a robot's chain)."""
    u, v = b[0], b[1]
    du, dv = J_xb_cols(L, u, v, bend_coeffs(u * u + v * v))
    return jnp.stack([jnp.stack(du), jnp.stack(dv)], axis=1)


# --------------------------------------------------------------------------------------------
# Grids
# --------------------------------------------------------------------------------------------
def over_grid(fn):
    """Lift a single-pose ``fn(design, theta_L, delta, *args)`` to a ``(n_theta, n_delta)`` grid.

    Returns ``g(design, theta_L (n_theta,), delta (n_delta,), *args)``; every output gets the two
    leading grid axes. ``args`` are shared by all poses.
    """

    def g(design, theta_L, delta, *args):
        inner = jax.vmap(lambda t, d: fn(design, t, d, *args), in_axes=(None, 0))
        return jax.vmap(inner, in_axes=(0, None))(jnp.asarray(theta_L), jnp.asarray(delta))

    return g
