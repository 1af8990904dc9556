"""Single-pose performance measures, full and reduced (tension_zones/MODEL.md Sec. 3; paper Secs. 4 and 6.1).

Every function here is written for **one pose** ``(theta_L, delta)`` (rad) and is pure, so it can be
``jit``-ed, ``vmap``-ed (:func:`tension_zones.over_grid`, :mod:`tension_zones.analysis`) and
differentiated. ``mask = None`` means the traditional (push-pull, "full") Jacobian; a 0/1 ``(n,)``
mask keeps only the taut wires' rows (the reduced Jacobian, paper Sec. 3.3).

Structure used throughout: ``J_xq = J_xpsi P`` with ``P = pinv(J~_qpsi)`` (2 x n), so each 3 x n
block ``J_v = J_xpsi[:3] P`` (or ``J_w``) has rank <= 2 and its two largest singular values follow in
closed form from 2x2 quantities (:func:`_sv2`), and the joint-uncertainty box ``dq [-1, 1]^n`` maps
to the zonogon ``P dq [-1, 1]^n`` in the 2-D configuration space, whose 2n vertices carry the
maximum of any convex norm (:func:`zonogon_vertices`). No SVD, no ``3^n`` or ``2^n`` enumeration.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._numerics import (
    cauchy_binet,
    eps_of,
    gram_pinv_cols,
    keep,
    per_wire,
    pinv_rows,
    unrolled,
    wmap,
    wstack,
    wsum,
)
from ..model._design import Design
from ..model._kinematics import J_xpsi_from_terms, J_xpsi_terms, _as_float
from ..model._zones import mask_from_score

#: The paper's headline joint-level uncertainty (mm), Figs. 11-12.
DEFAULT_DQ = 0.4
#: Names of the per-mode measures returned by :func:`pose_measures`.
MEASURES = (
    "kci_v",
    "kci_w",
    "sigma_min_v",
    "sigma_min_w",
    "sigma_min_nz_v",
    "sigma_min_nz_w",
    "dp_max",
    "dw_max",
)
MODES = ("full", "reduced")


# --------------------------------------------------------------------------------------------
# Guarded elementary functions (double-where: finite values *and* gradients at 0)
# --------------------------------------------------------------------------------------------
@jax.custom_jvp
def _sqrt0(x):
    """sqrt(max(x, 0)) with a zero (not infinite) gradient at 0; NaN for NaN. The value reads ``x``
    once: XLA recomputes a fused producer of ``x`` (a bound's vertex tree) in every consumer."""
    return jnp.sqrt(jnp.maximum(x, 0.0))


@_sqrt0.defjvp
def _sqrt0_jvp(primals, tangents):
    (x,), (t,) = primals, tangents
    pos = ~(x <= 0)  # not x > 0: a NaN stays NaN instead of becoming a plausible 0
    y = jnp.sqrt(jnp.where(pos, x, 1.0))
    return jnp.where(pos, y, 0.0), jnp.where(pos, t / (2.0 * y), 0.0)


def _div0(a, b):
    """a / b, and 0 where b == 0 (gradient finite)."""
    nz = b != 0
    return jnp.where(nz, a / jnp.where(nz, b, 1.0), 0.0)


def _norm0(x, axis=-1):
    return _sqrt0(jnp.sum(x * x, axis=axis))


# --------------------------------------------------------------------------------------------
# Building blocks
# --------------------------------------------------------------------------------------------
def _column_cross(P):
    """``C[j, k] = P[:, j] x P[:, k]`` (2-D cross product) for a (2, n) matrix: (n, n).

    Antisymmetric in exact arithmetic; compiled code may fuse it into FMAs, so callers never rely on
    ``C[j, j] == 0`` or ``C[j, k] == -C[k, j]`` bit for bit.
    """
    return P[0][:, None] * P[1][None, :] - P[1][:, None] * P[0][None, :]


#: Generators closer to parallel than ``PARALLEL_TOL * eps`` (|sin| of their angle; eps of the
#: dtype) count as parallel in :func:`zonogon_vertices`; the bound is exact to about that relative error.
PARALLEL_TOL = 1e3


def _sv2(A, Gp, det_Gp):
    """The two largest singular values ``(s1, s2)`` of ``A P`` with ``Gp = P P^T`` (2x2).

    ``A`` (3, 2) is a block of ``J_xpsi``; ``det_Gp`` is ``det(P P^T)`` by Cauchy-Binet (exactly 0 when
    at most one wire is taut). With the Cholesky factor ``R`` of ``A^T A`` (``A = Q R``) the non-zero
    singular values of ``A P`` are the square roots of the eigenvalues of the symmetric 2x2
    ``S = R Gp R^T``; ``l1 = (tr S + sqrt((S00 - S11)^2 + 4 S01^2)) / 2`` and, by
    ``det S = det(A^T A) det(Gp)``, ``l2 = |a1 x a2|^2 det(Gp) / l1`` -- both free of cancellation, and
    ``l2`` exactly 0 for rank one (one taut wire, or the straight pose).
    """
    a1, a2 = A[:, 0], A[:, 1]
    h00 = jnp.dot(a1, a1)
    det_H = jnp.sum(jnp.cross(a1, a2) ** 2)  # det(A^T A) without cancellation
    r00 = _sqrt0(h00)
    r01 = _div0(jnp.dot(a1, a2), r00)
    r11 = _div0(_sqrt0(det_H), r00)
    s00 = r00 * r00 * Gp[0, 0] + 2 * r00 * r01 * Gp[0, 1] + r01 * r01 * Gp[1, 1]
    s01 = r00 * r11 * Gp[0, 1] + r01 * r11 * Gp[1, 1]
    s11 = r11 * r11 * Gp[1, 1]
    l1 = 0.5 * (s00 + s11 + _sqrt0((s00 - s11) ** 2 + 4 * s01 * s01))
    l2 = jnp.minimum(_div0(det_H * det_Gp, l1), l1)
    return _sqrt0(l1), _sqrt0(l2)


def zonogon_vertices(G):
    """Vertices of the centred zonogon ``{G x : x in [-1, 1]^n}`` for generators ``G`` (2, n).

    Returns (2n, 2): one vertex of each pair ``+-v`` (the zonogon is centrally symmetric, so a norm's
    maximum over these equals its maximum over the whole zonogon). For each generator ``g_j`` the
    support point in the direction normal to ``g_j`` is ``w_j = sum_k sign(g_j x g_k) g_k`` over the
    generators not parallel to ``g_j``; the edge there is ``w_j +- (sum of the generators parallel to
    ``g_j``, each signed along ``g_j``)``. Zero generators (slack wires) contribute nothing; parallel
    generators (the straight pose) are exact. Parallel means ``|g_j x g_k| <= 1e3 eps |g_j||g_k|``,
    a test that does not depend on how the compiler rounds the cross product.
    """
    C = _column_cross(G)
    D = G[0][:, None] * G[0][None, :] + G[1][:, None] * G[1][None, :]  # Gram; elementwise (vmap-fast)
    nrm = jnp.sqrt(jax.lax.stop_gradient(jnp.diagonal(D)))
    tol = PARALLEL_TOL * eps_of(G)
    parallel = jnp.abs(C) <= tol * nrm[:, None] * nrm[None, :]  # incl. k = j
    side = jnp.where(parallel, 0.0, jnp.sign(C))
    edge = jnp.where(parallel, jnp.sign(D), 0.0)  # the edge along g_j, signed consistently
    edge = jnp.where(jnp.eye(G.shape[1], dtype=bool), 1.0, edge)  # g_j itself, even if |g_j|^2 flushes
    coef = jnp.concatenate([side + edge, side - edge], axis=0)  # (2n, n)
    return jnp.stack([jnp.sum(coef * G[0], axis=1), jnp.sum(coef * G[1], axis=1)], axis=1)


def _radius_or_nan(design: Design, dq):
    """The pitch radius, or NaN for an invalid (traced) design or a non-finite ``dq``: once per
    design, and every measure depends on it through ``P = pinv(J~_qpsi)``, so NaN in is NaN out at
    no cost per pose (NaN poses and masks propagate by themselves: every guard here lets a NaN
    through)."""
    return jnp.where(design.invalid(), jnp.nan, design.pitch_radius) + 0.0 * jnp.asarray(dq)


def _pose_inputs(design: Design, theta_L, delta, dq):
    """What every measure of one pose needs, computed once: ``J_xpsi`` (6, 2), the columns ``a``, ``b``
    of ``J_qpsi`` and the tension scores ``cos(delta_k)`` (per-wire values: lists of n scalars, or
    (n,) arrays above :data:`~tension_zones._numerics.UNROLL_MAX_WIRES` wires).

    The sines and cosines are kept (:func:`~tension_zones._numerics.keep`): otherwise XLA:CPU
    re-evaluates them inside the loop of each of the 17 outputs. Same formulas as
    :func:`~tension_zones.model.jacobians` and :func:`~tension_zones.tension_mask`.
    """
    theta_L, delta = _as_float(design, theta_L, delta)
    n = design.n_wires
    # the four sines and cosines are kept first: XLA:CPU would otherwise re-evaluate them inside each
    # value kept below (it duplicates a producer into every consumer loop)
    trig = keep([jnp.cos(theta_L), jnp.sin(theta_L), jnp.sin(delta), jnp.cos(delta)], design.length)
    sd, cd = trig[2], trig[3]
    terms = J_xpsi_terms(theta_L, delta, trig)
    # cos/sin(delta + alpha_k) by the addition theorem: the wires' angles are the design's, so their
    # sines and cosines are computed once per design, not per pose (2n fewer per pose)
    ca, sa = per_wire(jnp.cos(design.wire_angles)), per_wire(jnp.sin(design.wire_angles))
    cos_k = wmap(lambda c, s: cd * c - sd * s, ca, sa)
    sin_k = wmap(lambda c, s: sd * c + cd * s, ca, sa)
    if unrolled(n):
        kept = keep(list(terms) + cos_k + sin_k, design.length)
        terms, cos_k, sin_k = kept[:8], kept[8 : 8 + n], kept[8 + n :]
    else:
        kept = keep(list(terms) + [cos_k, sin_k], design.length)
        terms, (cos_k, sin_k) = kept[:8], kept[8:]
    T, r = terms[0], _radius_or_nan(design, dq)
    a = wmap(lambda c: r * c, cos_k)
    b = wmap(lambda s: -r * T * s, sin_k)
    return J_xpsi_from_terms(design.length, terms), a, b, cos_k


def _block_parts(A):
    """The pose-only pieces of :func:`_sv2` for a (3, 2) block (shared by full and reduced).

    On scalars: vmapped, ``jnp.dot``/``jnp.cross`` of 3-vectors become batched products that
    XLA:CPU hands to a library call each (a fifth of a kinematic chunk's time)."""
    a1, a2 = [A[i, 0] for i in range(3)], [A[i, 1] for i in range(3)]
    cross = [a1[1] * a2[2] - a1[2] * a2[1], a1[2] * a2[0] - a1[0] * a2[2], a1[0] * a2[1] - a1[1] * a2[0]]
    det_H = sum(c * c for c in cross)
    r00 = _sqrt0(sum(x * x for x in a1))
    return det_H, r00, _div0(sum(x * y for x, y in zip(a1, a2)), r00), _div0(_sqrt0(det_H), r00)


def _kept_blocks(Jx, design):
    """:func:`_block_parts` of ``J_v`` and ``J_w``, kept: each feeds six outputs."""
    kept = keep(list(_block_parts(Jx[:3])) + list(_block_parts(Jx[3:])), design.length)
    return tuple(kept[:4]), tuple(kept[4:])


def _sv2_parts(parts, g00, g01, g11, det_Gp):
    """:func:`_sv2` from :func:`_block_parts` and ``Gp = P P^T`` given by its entries."""
    det_H, r00, r01, r11 = parts
    s00 = r00 * r00 * g00 + 2 * r00 * r01 * g01 + r01 * r01 * g11
    s01 = r00 * r11 * g01 + r01 * r11 * g11
    s11 = r11 * r11 * g11
    l1 = 0.5 * (s00 + s11 + _sqrt0((s00 - s11) ** 2 + 4 * s01 * s01))
    l2 = jnp.minimum(_div0(det_H * det_Gp, l1), l1)
    return _sqrt0(l1), _sqrt0(l2)


def _zonogon_vertices_cols(g0, g1):
    """:func:`zonogon_vertices` on generators given as two lists of n scalars; the 2n vertices as
    ``(x, y)`` pairs, ``+`` vertices first. Elementwise, so that vmapped it fuses.

    Each pair is tested once: ``parallel`` and ``sign(g_j . g_k)`` are symmetric and, outside the
    parallel band (``|C| > 1e3 eps |g_j||g_k|``, far above its rounding error), ``sign(C)`` is
    antisymmetric whatever the compiler does with FMAs; inside it the sign is not used. ``g_j`` with
    itself is always parallel (side 0, edge 1).
    """
    n = len(g0)
    nrm = [jnp.sqrt(jax.lax.stop_gradient(g0[j] * g0[j] + g1[j] * g1[j])) for j in range(n)]
    tol = PARALLEL_TOL * eps_of(g0[0])
    coef = [[None] * n for _ in range(n)]  # (side, edge) of generator k at vertex j
    for j in range(n):
        coef[j][j] = (0.0, 1.0)
        for k in range(j + 1, n):
            C = g0[j] * g1[k] - g1[j] * g0[k]
            parallel = jnp.abs(C) <= tol * nrm[j] * nrm[k]
            side = jnp.where(parallel, 0.0, jnp.sign(C))
            edge = jnp.where(parallel, jnp.sign(g0[j] * g0[k] + g1[j] * g1[k]), 0.0)
            coef[j][k], coef[k][j] = (side, edge), (-side, edge)
    plus, minus = [], []
    for j in range(n):
        px = py = mx = my = 0.0
        for k in range(n):
            side, edge = coef[j][k]
            px, py = px + (side + edge) * g0[k], py + (side + edge) * g1[k]
            mx, my = mx + (side - edge) * g0[k], my + (side - edge) * g1[k]
        plus.append((px, py))
        minus.append((mx, my))
    return plus + minus


def _zonogon_max_sq(g0, g1, Jx):
    """``(max |Jx[:3] v|^2, max |Jx[3:] v|^2)`` over the zonogon ``{G x : x in [-1, 1]^n}``,
    generators ``G = [g0; g1]`` given as (n,) arrays: the many-wire form of
    :func:`_zonogon_vertices_cols`.

    Each generator is flipped into the upper half-plane (the zonogon does not change); in the order
    of their angles the boundary from ``-sum g`` to ``+sum g`` steps through the partial sums
    ``V_j = -sum g + 2 (g_(1) + ... + g_(j))``, and the other half is their negatives (same norms).
    ``V_j`` is summed over the generators at or before ``j`` in that order (ties by index): (n, n)
    comparisons that XLA fuses, faster under ``vmap`` on XLA:CPU than a sort. Parallel and zero
    generators need no care: they only add points on an edge.
    """
    flip = (g1 < 0) | ((g1 == 0) & (g0 < 0))
    h0, h1 = jnp.where(flip, -g0, g0), jnp.where(flip, -g1, g1)
    den = jnp.abs(h0) + h1
    # a pseudo-angle, increasing with the angle on [0, pi): no arctangent needed to order them
    key = jax.lax.stop_gradient(jnp.where(den > 0, -h0 / jnp.where(den > 0, den, 1.0), 0.0))
    idx = np.arange(g0.shape[0])
    same, earlier = key[None, :] == key[:, None], idx[None, :] <= idx[:, None]
    upto = (key[None, :] < key[:, None]) | (same & earlier)
    v0 = 2.0 * jnp.sum(jnp.where(upto, h0[None, :], 0.0), axis=1) - jnp.sum(h0)
    v1 = 2.0 * jnp.sum(jnp.where(upto, h1[None, :], 0.0), axis=1) - jnp.sum(h1)
    dX = [v0 * Jx[row, 0] + v1 * Jx[row, 1] for row in range(6)]
    return (
        jnp.max(dX[0] * dX[0] + dX[1] * dX[1] + dX[2] * dX[2]),
        jnp.max(dX[3] * dX[3] + dX[4] * dX[4] + dX[5] * dX[5]),
    )


def _uncertainty_sq(P0, P1, dq, Jx):
    """Squared ``(dp_max, dw_max)``: the largest ``|dx[:3]|^2``, ``|dx[3:]|^2`` of
    ``dx = J_xpsi v`` over the vertices ``v`` of the zonogon ``P dq [-1, 1]^n`` (per-wire rows
    ``P0``, ``P1`` of ``P``)."""
    dq = jnp.asarray(dq, Jx.dtype)
    g0, g1 = wmap(lambda x: x * dq, P0), wmap(lambda y: y * dq, P1)
    if not isinstance(g0, list):  # many wires: (n,) arrays
        return _zonogon_max_sq(g0, g1, Jx)
    V = _zonogon_vertices_cols(g0, g1)
    sq = [[0.0, 0.0] for _ in V]  # |dx[:3]|^2, |dx[3:]|^2 per vertex, dx = Jx v
    for i, (v0, v1) in enumerate(V):
        dX = [v0 * Jx[row, 0] + v1 * Jx[row, 1] for row in range(6)]
        sq[i] = [dX[0] * dX[0] + dX[1] * dX[1] + dX[2] * dX[2], dX[3] * dX[3] + dX[4] * dX[4] + dX[5] * dX[5]]
    return (functools.reduce(jnp.maximum, [q[0] for q in sq]), functools.reduce(jnp.maximum, [q[1] for q in sq]))


def _measures(Jx, blocks, a, b, dq, design):
    """Every measure of :func:`pose_measures` from :func:`_pose_inputs` (masked columns ``a``, ``b``)
    and the two blocks' :func:`_block_parts`; ``design`` for its wire count and as the anchor of
    :func:`~tension_zones._numerics.keep`."""
    # rows of P = pinv(J~_qpsi) (2, n); zero columns for slack wires. pinv(G) first: kept, so that
    # its Gram matrix and determinant are not recomputed for each of P's 2n entries
    P0, P1 = pinv_rows(keep(gram_pinv_cols(a, b), design.length), a, b)
    n = design.n_wires
    if unrolled(n):
        kept = keep(P0 + P1, design.length)  # shared by the 8 outputs below: computed once
        P0, P1 = kept[:n], kept[n:]
    else:
        P0, P1 = keep([P0, P1], design.length)
    # Cauchy-Binet over distinct column pairs: exactly 0 with one non-zero column (one taut wire)
    det_Gp = cauchy_binet(P0, P1)
    g00 = wsum(wmap(lambda x: x * x, P0))
    g01 = wsum(wmap(lambda x, y: x * y, P0, P1))
    g11 = wsum(wmap(lambda y: y * y, P1))
    rtol = max(3, design.n_wires) * eps_of(Jx)
    out = {}
    for part, parts in zip("vw", blocks):
        s1, s2 = _sv2_parts(parts, g00, g01, g11, det_Gp)
        out[f"kci_{part}"] = _div0(s2, s1)
        out[f"sigma_min_{part}"] = s2
        out[f"sigma_min_nz_{part}"] = jnp.where(s2 > rtol * s1, s2, s1)
    # Paper Eqs. 17-19 without the 3^n columns: the box maps to the zonogon P dq [-1, 1]^n in the
    # configuration space; a norm of J_xpsi z is convex in z, so its maximum is at a vertex.
    # sqrt is monotonic and correctly rounded: sqrt(max) == max(sqrt), one root instead of 2n
    dp2, dw2 = _uncertainty_sq(P0, P1, dq, Jx)
    out["dp_max"] = _sqrt0(dp2)
    out["dw_max"] = _sqrt0(dw2)
    return out


def _check_concrete_pose(theta_L, delta, dq) -> None:
    """The NumPy edge of the public measures: concrete inputs in degrees, or a negative ``dq``, are a
    ValueError (a bending angle beyond pi or a direction beyond 2 pi is not radians). Traced values
    (``jit``, ``vmap``, sweeps) are not checked: NaN in, NaN out there."""
    import math

    for name, value, limit, what in (("theta_L", theta_L, math.pi, "pi"), ("delta", delta, 2 * math.pi, "2 pi")):
        if isinstance(value, jax.core.Tracer):
            continue
        v = np.asarray(value, dtype=float)
        big = np.isfinite(v) & (np.abs(v) > limit)
        if np.any(big):
            x = float(v[big].flat[0])
            raise ValueError(
                f"{name} = {x:g} is beyond +-{what}: radians are expected (np.radians({x:g}) = {math.radians(x):.6g})"
            )
    if not isinstance(dq, jax.core.Tracer) and np.any(np.asarray(dq, dtype=float) < 0):
        raise ValueError(f"dq must be non-negative (a bound on each joint's error, mm), got {np.asarray(dq).tolist()}")


# --------------------------------------------------------------------------------------------
# Public single-pose measures
# --------------------------------------------------------------------------------------------
def pose_measures(design: Design, theta_L, delta, dq=DEFAULT_DQ, mask=None):
    """Every measure of tension_zones/MODEL.md Sec. 3 at one pose, for one Jacobian (full or reduced).

    Args:
        design: the segment.
        theta_L, delta: the pose (rad), scalars.
        dq: joint-level uncertainty bound (mm), scalar; the box is ``dq [-1, 1]^n`` (paper Eq. 17).
        mask: ``None`` (traditional, all wires) or (n,) 0/1 taut mask (reduced, paper Sec. 3.3).

    Returns a dict of scalars (the keys of :data:`MEASURES`), every one NaN for a NaN (or
    infinite) pose, ``dq`` or mask entry, or an invalid design (:meth:`Design.invalid`):
        ``kci_v``, ``kci_w``: ``sigma_2 / sigma_1`` of ``J_v = J_xq[:3]`` and ``J_w = J_xq[3:]``
        (0 when the rank is below 2); ``sigma_min_v`` (mm/mm), ``sigma_min_w`` (rad/mm):
        ``sigma_2``; ``sigma_min_nz_v``, ``sigma_min_nz_w``: the smallest *non-zero* singular value
        (``sigma_1`` where ``sigma_2 <= max(3, n) eps sigma_1``, NumPy's rank rule);
        ``dp_max`` (mm), ``dw_max`` (rad): the largest ``||dx[:3]||`` and ``||dx[3:]||`` with
        ``dx = J_xpsi pinv(J~_qpsi) dq_vec`` over the box (paper Eqs. 17-19), exact.
    """
    _check_concrete_pose(theta_L, delta, dq)
    Jx, a, b, _ = _pose_inputs(design, theta_L, delta, dq)
    if mask is not None:
        mask = jnp.asarray(mask, Jx.dtype)
        if mask.shape != (design.n_wires,):  # shapes are static: a clear error, never a broadcast
            raise ValueError(f"mask must have shape ({design.n_wires},) for {design.n_wires} wires, got {mask.shape}")
        m = per_wire(mask)
        a, b = wmap(lambda x, mk: x * mk, a, m), wmap(lambda y, mk: y * mk, b, m)
    blocks = _kept_blocks(Jx, design)
    return _measures(Jx, blocks, a, b, dq, design)


def pose_metrics(design: Design, theta_L, delta, dq=DEFAULT_DQ):
    """Full and reduced measures at one pose, flat: ``{"n_taut", "<measure>_full", "<measure>_reduced"}``.

    The keys are those of the ``tension-zones sweep`` file (``kci_v_full``, ``dp_max_reduced``, ...);
    ``n_taut`` is the number of wires in tension (tension_zones/MODEL.md Sec. 2, boundary rule included). The
    reduced mask carries the straight-through gradient of :func:`tension_zones.tension_mask`. NaN
    in, NaN out, as :func:`pose_measures` (``n_taut`` is -1 there).
    """
    _check_concrete_pose(theta_L, delta, dq)
    Jx, a, b, score = _pose_inputs(design, theta_L, delta, dq)  # shared by both modes
    mask = mask_from_score(wstack(score))
    bad = ~jnp.isfinite(theta_L + delta + _radius_or_nan(design, dq))  # cheap: no measure in it
    out = {"n_taut": jnp.where(bad, -1, jnp.sum(mask > 0.5)).astype(jnp.int32)}
    blocks = _kept_blocks(Jx, design)
    m = per_wire(mask)
    reduced = (wmap(lambda x, mk: x * mk, a, m), wmap(lambda y, mk: y * mk, b, m))
    for mode, (aa, bb) in (("full", (a, b)), ("reduced", reduced)):
        for k, v in _measures(Jx, blocks, aa, bb, dq, design).items():
            out[f"{k}_{mode}"] = v
    return out
