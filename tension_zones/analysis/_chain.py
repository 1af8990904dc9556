"""Single-configuration measures of a robot of any number of segments (tension_zones/MODEL.md Sec. 3, chained).

The measures of :mod:`._metrics` for a :class:`~tension_zones.model.Robot`: at a configuration ``B``
(S, 2) the wire-to-tip Jacobian is ``J_xq = J_xB pinv(J~_qB)`` (6, N), ``J~_qB`` the rows of the
wires kept (all: traditional, push-pull; the taut ones: reduced). A distal wire crosses the proximal
segments, so its row acts on each of them, and it is taut by the chained tension-zone rule of
:meth:`Robot.tension_score` (each segment bending further in its own plane).

With two or more segments ``J_v`` and ``J_w`` (3 x N) have rank up to 3 (``min(3, 2S)``): ``KCI`` and
``sigma_min`` use the ``min(3, 2S)``-th singular value, which for one segment is the paper's
``sigma_2``. The uncertainty box ``dq [-1, 1]^N`` maps to the zonotope ``J_v dq [-1, 1]^N`` in
space, whose largest norm is at a vertex; :func:`zonotope_max_sq` lists a superset of its vertices,
each a point of the zonotope, so the maximum is exact (no sampling): the box's ``2^(N - 1)``
vertex pairs for a few wires, the ends of the zonotope's face edges (``O(N^3)``) for many.

**Coordinates.** The chain's configuration coordinates are the bending vectors ``B``: regular at the
straight pose and the same in every bending direction. Where the taut wires' rows have full rank
(``2S``) the measures do not depend on that choice; where fewer act (one taut wire of a segment), the
pseudo-inverse's minimum-norm step does. A one-segment robot is therefore the segment's own code path
(:func:`~._metrics.pose_measures`, the paper's ``(theta_L, delta)``), so its numbers are exactly a
:class:`~tension_zones.model.Design`'s; ``general=True`` takes the chain formulas instead.
"""

from __future__ import annotations

import functools
import itertools

import jax
import jax.numpy as jnp
import numpy as np

from .._numerics import dot_lists, eps_of, singular_values
from ..model._kinematics import b_to_psi
from ..model._robot import Robot
from ._metrics import DEFAULT_DQ, PARALLEL_TOL, _div0, _sqrt0, pose_measures, pose_metrics
from ._sweep import ROBOT_CHUNK

#: Up to this many generators the largest norm is taken over every vertex of the box
#: (:func:`_box_vertices_max_sq`, ``2^(N - 1)`` points: ``s`` and ``-s`` give the same norm), beyond
#: over the ends of the zonotope's face edges, whose cost grows as ``N^3`` where the box's grows as
#: ``2^N``; past the crossover the box's points no longer fuse into one pass (crossover measured:
#: ``benchmarks/``, ROBOTS).
BOX_VERTICES_MAX = 14


def zonotope_max_sq(G):
    """``max |G s|^2`` over ``s in [-1, 1]^N`` for generators ``G`` (3, N): the squared largest norm of
    the zonotope ``G [-1, 1]^N``, exactly.

    A norm is convex, so its maximum is at a vertex of the box's image. Up to
    :data:`BOX_VERTICES_MAX` generators every vertex of the box is mapped (:func:`_box_vertices_max_sq`),
    beyond only the ends of the zonotope's face edges (:func:`_face_edges_max_sq`); both are exact.
    """
    if G.shape[1] <= BOX_VERTICES_MAX:
        return _box_vertices_max_sq(G)
    return _face_edges_max_sq(G)


@functools.cache
def _box_signs(n: int, first_positive: bool) -> np.ndarray:
    """(n, m): every sign vector of ``{-1, 1}^n`` (``m = 2^n``), or only those whose first entry is
    ``+1`` (``m = 2^(n - 1)``)."""
    signs = np.array(list(itertools.product((1.0, -1.0), repeat=n)), dtype=float)
    return (signs[signs[:, 0] > 0] if first_positive else signs).T


#: Up to this many vertex pairs (``2^(N - 1)``, nine generators) :func:`_box_vertices_max_sq` writes
#: every vertex's norm as scalar operations: vmapped, one fused pass over the batch (its contiguous
#: axis). The program grows with the pairs, so beyond it maps the box's points as arrays.
SCALAR_VERTICES_MAX = 256


@jax.custom_jvp
def _box_vertices_max_sq(G):
    """:func:`zonotope_max_sq` over every vertex of the box, one of each pair ``s, -s``.

    The generators split in two halves, ``G s = G_1 s_1 + G_2 s_2``: the points of each half's box
    (``2^(k - 1)`` with ``s_1``'s first sign fixed, ``2^(N - k)``) are summed pairwise, ``|x_1 + x_2|^2``
    for every pair, which is every vertex of the box for about a fifth of the products of ``G`` with
    all ``2^(N - 1)`` sign vectors. Written elementwise, so that vmapped it fuses: up to
    :data:`SCALAR_VERTICES_MAX` pairs on scalars. Its derivative is that of the same sums as arrays
    (:func:`_box_pairs_max_sq`), whose program stays small where the scalars' would not.
    """
    k = (G.shape[1] + 1) // 2
    s1, s2 = _box_signs(k, True), _box_signs(G.shape[1] - k, False)
    if s1.shape[1] * s2.shape[1] > SCALAR_VERTICES_MAX:
        return _box_pairs_max_sq(G)
    x1, x2 = _box_points_scalar(G[:, :k], s1), _box_points_scalar(G[:, k:], s2)
    vertices = ([a + b for a, b in zip(p, q)] for p in x1 for q in x2)
    return _max_of([dot_lists(x, x) for x in vertices])


@_box_vertices_max_sq.defjvp
def _box_vertices_max_sq_jvp(primals, tangents):
    return jax.jvp(_box_pairs_max_sq, primals, tangents)


def _box_pairs_max_sq(G):
    """:func:`_box_vertices_max_sq` with each half's points as (m,) arrays."""
    k = (G.shape[1] + 1) // 2
    x1 = _box_points(G[:, :k], _box_signs(k, True))
    x2 = _box_points(G[:, k:], _box_signs(G.shape[1] - k, False))
    return jnp.max(sum((a[:, None] + b[None, :]) ** 2 for a, b in zip(x1, x2)))


def _box_points_scalar(G, signs):
    """The points ``G s`` for the columns ``s`` of ``signs`` (n, m), each a list of three scalars."""
    g = [[G[c, i] for i in range(G.shape[1])] for c in range(3)]
    return [[sum(x if si > 0 else -x for si, x in zip(s, g[c])) for c in range(3)] for s in signs.T]


def _max_of(values):
    """The largest of a list of scalars, as a balanced tree of pairwise maxima."""
    while len(values) > 1:
        values = [functools.reduce(jnp.maximum, values[i : i + 2]) for i in range(0, len(values), 2)]
    return values[0]


def _box_points(G, signs):
    """The points ``G s`` for the columns ``s`` of ``signs`` (n, m), as three (m,) coordinates; the
    origin alone for no generators."""
    zero = jnp.zeros(signs.shape[1], G.dtype)
    return [sum((G[c, i] * jnp.asarray(signs[i], G.dtype) for i in range(G.shape[1])), zero) for c in range(3)]


def _face_edges_max_sq(G):
    """:func:`zonotope_max_sq` over the ends of the zonotope's face edges, ``O(N^3)``.

    Every vertex is an end of an edge on a face. For each pair ``i < j`` of generators, with the face
    normal ``w = g_i x g_j`` and the in-face direction ``t = w x g_i``, the candidates take the signs
    of ``g_k . (w + e s t + e^2 r g_i)`` for a small ``e`` and ``s, r = +-1`` (ties, within
    ``PARALLEL_TOL`` eps, go to the next term): the ends of the face's edges parallel to ``g_i``, on
    both sides. A face's edges along all but one of its directions reach all its vertices, so
    ``i < j`` suffices (``i = j`` adds the ends of a zonotope of one direction, a single taut wire);
    every candidate is a point of the zonotope, so none can exceed the maximum. This holds for a flat
    zonotope or a segment (a straight robot, one segment: every ``w`` is normal to the plane and the
    in-face terms decide) and for parallel or zero generators.

    Written elementwise over the pairs (no batched matrix products), so that vmapped it fuses.
    """
    iu, ju = np.triu_indices(G.shape[1])  # i == j: w = t = 0, the extremes along g_i (a zonotope of one direction)
    tol = PARALLEL_TOL * eps_of(G)
    g = [G[c] for c in range(3)]  # (N,) each
    gi, gj = [x[iu] for x in g], [x[ju] for x in g]  # (P,) each
    w = _cross(gi, gj)
    t = _cross(w, gi)

    def dots(v):  # (P, N): v_p . g_k
        return sum(v[c][:, None] * g[c][None, :] for c in range(3))

    def norm(v):
        return jnp.sqrt(jax.lax.stop_gradient(sum(x * x for x in v)))

    ng = norm(g)[None, :]
    dw, dt, de = dots(w), dots(t), dots(gi)
    tie_w = jnp.abs(dw) <= tol * norm(w)[:, None] * ng
    tie_t = tie_w & (jnp.abs(dt) <= tol * norm(t)[:, None] * ng)
    signs = [  # the three terms' signs, each where the earlier ones tie (stop_gradient: piecewise constant)
        jax.lax.stop_gradient(jnp.where(tie_w, 0.0, jnp.sign(dw))),
        jax.lax.stop_gradient(jnp.where(tie_w & ~tie_t, jnp.sign(dt), 0.0)),
        jax.lax.stop_gradient(jnp.where(tie_t, jnp.sign(de), 0.0)),
    ]
    X = [[jnp.sum(s * g[c][None, :], axis=1) for c in range(3)] for s in signs]  # (P,) each
    best = []
    for side in (1.0, -1.0):
        for end in (1.0, -1.0):
            x = [X[0][c] + side * X[1][c] + end * X[2][c] for c in range(3)]
            best.append(jnp.max(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]))
    return functools.reduce(jnp.maximum, best)


def _cross(a, b):
    """Cross product of 3-vectors given by their components (lists of arrays)."""
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _rank_cap(robot: Robot) -> int:
    """The rank ``J_v`` and ``J_w`` can reach: ``min(3, 2S)``."""
    return min(3, 2 * robot.n_segments)


def _singular(J, r: int, n_wires: int):
    """``(sigma_1, sigma_r, sigma_min_nz)`` of a (3, N) block: the largest, the ``r``-th and the smallest
    non-zero singular value among the first ``r`` (NumPy's rank rule ``max(3, N) eps sigma_1``).
    Singular values only (no vectors): the gradient is finite where two of them meet."""
    s = singular_values(J)
    s1 = s[0]
    rtol = max(3, n_wires) * eps_of(J)
    head = s[:r]
    nz = jnp.min(jnp.where(head > rtol * s1, head, jnp.inf))
    return s1, head[-1], jnp.where(jnp.isfinite(nz), nz, s1)


def _chain_measures(robot: Robot, B, dq, masks):
    """Every measure of :func:`config_measures` by the general chain formulas (any ``S``), for each
    mask of ``masks`` (a list: ``None`` or (N,) 0/1): a list of dicts. Their Jacobians' blocks are
    measured together (vmapped over the blocks): one program for every block."""
    Js = jnp.stack([robot.J_xq(B, m) for m in masks])  # (M, 6, N); slack wires' columns exactly zero
    blocks = jnp.concatenate([Js[:, :3], Js[:, 3:]])  # (2M, 3, N): each J_v, then each J_w
    r = _rank_cap(robot)
    s1, sr, snz = jax.vmap(lambda b: _singular(b, r, robot.n_wires))(blocks)
    bound = _sqrt0(jax.vmap(zonotope_max_sq)(blocks * jnp.asarray(dq, Js.dtype)))
    out = []
    for i in range(len(masks)):
        d = {}
        for part, k in (("v", i), ("w", len(masks) + i)):
            d[f"kci_{part}"] = _div0(sr[k], s1[k])
            d[f"sigma_min_{part}"] = sr[k]
            d[f"sigma_min_nz_{part}"] = snz[k]
        d["dp_max"], d["dw_max"] = bound[i], bound[len(masks) + i]
        out.append(d)
    return out


def _check_config(robot: Robot, B) -> None:
    shape = (robot.n_segments, 2)
    if np.shape(B) != shape:  # shapes are static: a clear error, never a broadcast
        raise ValueError(f"B must have shape {shape} (one bending vector per segment, rad), got {jnp.shape(B)}")
    if not isinstance(B, jax.core.Tracer):
        phi = np.sqrt(np.sum(np.asarray(B, dtype=float) ** 2, axis=1))
        big = np.isfinite(phi) & (phi > np.pi)
        if np.any(big):
            j = int(np.argmax(big))
            raise ValueError(f"segment {j} bends by {phi[j]:g} rad, beyond pi: B is in radians (|b_j| = bending angle)")


def _one_segment(robot: Robot, B):
    """The segment and its pose ``(theta_L, delta)`` for a one-segment robot at ``B`` (1, 2)."""
    theta_L, delta = b_to_psi(jnp.asarray(B, robot.route_angles.dtype)[0])
    return robot.segments[0], theta_L, delta


def config_measures(robot: Robot, B, dq=DEFAULT_DQ, mask=None, general: bool = False):
    """Every measure of :data:`~._metrics.MEASURES` at one configuration, full or reduced.

    Args:
        robot: the robot (its shapes are static, its numbers traced).
        B: (S, 2) bending vectors, one per segment (rad; ``|b_j|`` is segment ``j``'s bending angle).
        dq: joint-level uncertainty bound (mm): a scalar, the box ``dq [-1, 1]^N``, or one per wire
            (N,), e.g. a calibration's play (a vector takes the chain formulas for one segment too).
        mask: ``None`` (traditional, all wires) or (N,) 0/1 (reduced: the taut wires' rows).
        general: use the chain formulas even for one segment (the same numbers wherever the taut wires
            fix the configuration; see the module's note on coordinates).

    Returns a dict of scalars, as :func:`~._metrics.pose_measures`: ``kci_v``, ``kci_w`` (the
    ``min(3, 2S)``-th over the largest singular value of ``J_v``, ``J_w``), ``sigma_min_v``,
    ``sigma_min_w``, ``sigma_min_nz_v``, ``sigma_min_nz_w``, ``dp_max`` (mm) and ``dw_max`` (rad): the
    largest tip displacement and rotation over the box, exact. Base frame.
    """
    _check_config(robot, B)
    if robot.n_segments == 1 and not general and np.ndim(dq) == 0:
        seg, theta_L, delta = _one_segment(robot, B)
        return pose_measures(seg, theta_L, delta, dq, mask)
    return _chain_measures(robot, B, dq, [mask])[0]


def config_metrics(robot: Robot, B, dq=DEFAULT_DQ, general: bool = False):
    """Full and reduced measures at one configuration, flat, as :func:`~._metrics.pose_metrics`:
    ``{"n_taut", "<measure>_full", "<measure>_reduced"}`` plus ``n_taut_segments`` (S,), the taut
    wires acting on each segment (a distal wire counts in every segment it crosses).

    ``B`` (S, 2) in rad; the reduced mask is :meth:`Robot.tension_mask` (every segment bending further
    in its own plane), with its straight-through gradient.
    """
    _check_config(robot, B)
    B = jnp.asarray(B, robot.route_angles.dtype)
    mask = robot.tension_mask(B)
    crossing = jnp.sum(jnp.where(robot.crosses, (mask > 0.5)[:, None], False), axis=0).astype(jnp.int32)
    if robot.n_segments == 1 and not general and np.ndim(dq) == 0:
        seg, theta_L, delta = _one_segment(robot, B)
        out = pose_metrics(seg, theta_L, delta, dq)
    else:
        bad = ~jnp.all(jnp.isfinite(B)) | ~jnp.all(jnp.isfinite(jnp.asarray(dq, B.dtype)))
        out = {"n_taut": jnp.where(bad, -1, jnp.sum(mask > 0.5)).astype(jnp.int32)}
        for mode, measures in zip(("full", "reduced"), _chain_measures(robot, B, dq, [None, mask])):
            for k, v in measures.items():
                out[f"{k}_{mode}"] = v
    out["n_taut_segments"] = crossing
    return out


#: Configurations per chunk of a sweep of :func:`config_metrics` (:func:`~._sweep.sweep_configs`' default)
#: up to :data:`BOX_VERTICES_MAX` wires: its working set is then a few kilobytes per configuration, so
#: a chunk larger than a loaded sweep's spreads each call's fixed costs (the full Jacobian's
#: pseudo-inverse, the check of the shared table of every mask's reduced one:
#: :func:`~tension_zones._numerics.shared_mask_table`) over more configurations.
#: Beyond, the face edges' pair terms take :data:`~._sweep.ROBOT_CHUNK`.
METRICS_CHUNK = 1 << 13


def _metrics_chunk(robot: Robot) -> int:
    return METRICS_CHUNK if robot.n_wires <= BOX_VERTICES_MAX else ROBOT_CHUNK


# sweep_configs' default chunk for it (_sweep.robot_chunk)
config_metrics.chunk_size = _metrics_chunk  # type: ignore[attr-defined]
