"""Tension-only statics and compliance of one segment (tension_zones/MODEL.md Sec. 4; paper Sec. 5 and 6.2).

Single-pose, pure functions, lifted to grids with :func:`~tension_zones.model.over_grid`.
Frames and units: the tip wrench ``w = [f; m]`` (N, N mm) and the twist-like deflection
``dx = [dp; dtheta]`` (mm, rad) are in the base frame {B}; tensions in N; stiffness in
N mm / rad^2 (configuration space).

Equilibrium (paper Eq. 23): ``J_xpsi^T w - grad U - J_qpsi^T tau = 0`` with pull-only wires
``tau >= f_min``. The computation runs in the bending vector ``b = (u, v)`` (tension_zones/MODEL.md Sec. 5), where
``J_qb = -r [cos alpha_k, sin alpha_k]`` is constant and nothing is singular at the straight pose.
``psi -> b`` is a diffeomorphism away from the straight pose, so the ``b``-form equilibrium
``J_qb^T tau = J_xb^T w - EI b / L`` is the psi-form multiplied by an invertible ``(d psi/d b)^T``,
and at an equilibrium the stiffness transforms as a tensor (``K_b = P^T K_psi P``,
``P = d psi / d b``): both give the same task-space compliance (tested).
"""

from __future__ import annotations

import functools
import itertools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._numerics import (
    compact,
    eps_of,
    keep,
    nan_where,
    not_finite,
    per_wire,
    pinv_tall2,
    pinv_tall2_cols,
    straight_through,
    wmap,
    wmax,
    wstack,
    wsum,
)
from ._design import Design
from ._kinematics import J_qb, J_qpsi, J_xb, J_xb_cols, J_xpsi, bend_coeffs, over_grid, psi_to_b

#: A wire is taut when ``tau_k > TAUT_REL_TOL * max_j tau_j`` (tension_zones/MODEL.md Sec. 4, ``f_min = 0``).
TAUT_REL_TOL = 1e-6
#: Relative KKT violation up to which a tension candidate is accepted (else: infeasible pose).
KKT_TOL = 1e-9
#: Temperature of the sigmoid surrogate behind the taut mask's straight-through gradient, on the
#: normalised tension ``tau_k / max_j tau_j``.
STATICS_TEMPERATURE = 0.05

#: The paper's Sec. 6.2 sweep: theta_L = 89, 84, ..., 45 deg; delta = 0, 15, ..., 360 deg.
PAPER_THETA_L_DEG = np.linspace(89.0, 45.0, 10)
PAPER_DELTA_DEG = np.arange(0.0, 360.0 + 1e-9, 15.0)
#: The paper's tip wrench: 5 N along x_b (a force fixed in the base frame).
PAPER_WRENCH = (5.0, 0.0, 0.0, 0.0, 0.0, 0.0)

MODES = ("full", "reduced")


def as_wrench(wrench) -> jnp.ndarray:
    """A tip wrench ``[fx, fy, fz(, mx, my, mz)]`` (N, N mm) as a (6,) array; 3 values = a force.

    Raises ``ValueError`` for any other shape or for non-finite values (concrete input only).
    """
    w = jnp.asarray(wrench, dtype=jnp.result_type(float))
    if w.shape not in ((3,), (6,)):
        raise ValueError(f"a wrench must have 3 (force) or 6 (force, moment) components, got shape {w.shape}")
    if not isinstance(w, jax.core.Tracer) and not np.all(np.isfinite(np.asarray(w))):
        raise ValueError(f"a wrench must be finite, got {np.asarray(w).tolist()}")
    return jnp.concatenate([w, jnp.zeros(6 - w.shape[0], w.dtype)])


# --------------------------------------------------------------------------------------------
# Tension distribution: min ||tau||^2  s.t.  A tau = rhs, tau >= f_min   (A: 2 x n)
# --------------------------------------------------------------------------------------------
class TensionSolution(NamedTuple):
    """Solution of the tension QP at one pose.

    tau: (n,) tensions (N); lam: (2,) multipliers of the equality, with
    ``tau = max(f_min, A^T lam)``; feasible: bool, the wires can hold the pose by pulling; kkt_residual: relative KKT violation.
    """

    tau: jax.Array
    lam: jax.Array
    feasible: jax.Array
    kkt_residual: jax.Array


def _free_sets(n: int) -> np.ndarray:
    """All ``2^n`` candidate free sets (wires strictly above the bound) as 0/1 rows, (2^n, n)."""
    return np.array(list(itertools.product((0.0, 1.0), repeat=n)))


#: Up to this many candidate free sets (``2^n``: n <= 4 wires) the set choice is unrolled (fast to run,
#: slower to compile, and much slower to compile beyond); above it is vectorised over the sets.
_UNROLL_MAX_SETS = 16
#: Up to this many wires the free set is chosen among all 2^n subsets (exact for any ``A``); above
#: it among the O(n^2) runs of wires of :func:`_arc_free_mask` (2^n grows too fast: 65536 sets at
#: 16 wires and 4e9 at 32).
MAX_SUBSET_WIRES = 8


def _choose_free_set(A, rhs, f_min):
    """Index (into :func:`_free_sets`) of the free set of the QP's solution; no gradient.

    For every set ``S``: ``lam = pinv(A_S A_S^T)(rhs - f_min A 1_{not S})`` and the tensions
    ``A_S^T lam`` (free) or ``f_min`` (bound). The solution's set is the one whose ``lam`` lies on the
    right side of ``f_min`` for every wire (``A^T lam >= f_min`` on ``S``, ``<= f_min`` off it) and
    reaches ``rhs``; the first set of least violation is chosen (exactly one has none when the pose
    is feasible; ties are sets giving the same tensions). Everything that depends on ``A`` and
    ``f_min`` alone is shared by all poses under ``vmap``; per pose and set it is a 2x2 product and
    an ``n``-vector test, elementwise.
    """
    A, rhs, f_min = (jax.lax.stop_gradient(x) for x in (A, rhs, f_min))
    S = jnp.asarray(_free_sets(A.shape[1]), A.dtype)  # (m, n)

    def per_set(m):  # independent of rhs
        P = pinv_tall2(A.T * m[:, None])  # (2, n) = pinv(A_S)^T
        return P @ P.T, f_min * (A @ (1.0 - m))  # pinv(A_S A_S^T), the bound wires' pull

    M, c = jax.vmap(per_set)(S)  # (m, 2, 2), (m, 2)
    inv_norm_A = 1.0 / jnp.linalg.norm(A)

    def violation(free, lam0, lam1):  # lam on the wrong side of f_min for a wire, or rhs missed
        y = [lam0 * A[0, k] + lam1 * A[1, k] for k in range(len(free))]  # A^T lam
        tau = [jnp.where(f, yk, f_min) for f, yk in zip(free, y)]
        wrong = functools.reduce(jnp.maximum, [jnp.where(f, f_min - yk, yk - f_min) for f, yk in zip(free, y)])
        miss = (
            jnp.abs(sum(t * A[0, k] for k, t in enumerate(tau)) - rhs[0])
            + jnp.abs(sum(t * A[1, k] for k, t in enumerate(tau)) - rhs[1])
        ) * inv_norm_A
        return jnp.maximum(wrong, 0.0) + miss

    def lam_of(j):
        r0, r1 = rhs[0] - c[j, 0], rhs[1] - c[j, 1]
        return M[j, 0, 0] * r0 + M[j, 0, 1] * r1, M[j, 1, 0] * r0 + M[j, 1, 1] * r1

    sets = _free_sets(A.shape[1]) > 0.5
    if len(sets) > _UNROLL_MAX_SETS or compact():  # vectorised over the sets (compiles fast)
        return jnp.argmin(violation(list(sets.T), *lam_of(slice(None)))).astype(A.dtype)
    # few wires: unrolled over the static sets, elementwise, so that vmapped over poses it is one
    # fused loop (the (m, n)-array form with an argmin runs 2-3x slower on XLA:CPU)
    best = best_j = None
    for j, free in enumerate(sets):
        viol = violation(list(free), *lam_of(j))
        if best is None:
            best, best_j = viol, jnp.zeros_like(viol)
        else:  # strict: the first set of least violation wins
            best_j = jnp.where(viol < best, float(j), best_j)
            best = jnp.minimum(viol, best)
    return best_j


def _arc_runs(n: int):
    """Starts and lengths (static, NumPy) of the candidate free sets of :func:`_arc_free_mask`: the
    empty set, then every run of ``m = 1..n`` wires consecutive in angular order from every
    start."""
    m, s = np.meshgrid(np.arange(1, n + 1), np.arange(n), indexing="ij")
    return np.concatenate([[0], s.ravel()]), np.concatenate([[0], m.ravel()])


def _arc_free_mask(A, rhs, f_min):
    """The free set of the QP's solution, (n,) 0/1, for many wires: ``O(n^2)`` candidates, not
    ``2^n``.

    A wire is free when ``a_k . lam > f_min``. With ``a_k = rho (cos b_k, sin b_k)`` of one norm
    ``rho`` (``A = J_qb^T``: every wire on the pitch circle), or with ``f_min = 0`` and any norms,
    that is ``cos(phi - b_k) > f_min / (rho |lam|)`` for ``lam = |lam| (cos phi, sin phi)``: the
    wires within an open arc of less than 180 deg centred on ``phi``. So the solution's free set is
    empty or a run of wires consecutive in the order of their angles ``b_k``, spanning less than
    180 deg: ``n^2 + 1`` candidates. A run is the solution's set exactly when its ``lam`` puts its
    two end wires above ``f_min`` and the two wires just outside it at or below (the free set of
    any ``lam`` is such an arc) and reaches ``rhs``: four wires checked per candidate, against
    every wire for the 2^n subsets of :func:`_choose_free_set`. Everything but ``lam`` and that
    check depends on
    ``A`` and ``f_min`` alone (shared by all poses under ``vmap``). No gradient. For ``A`` with
    unequal column norms and ``f_min > 0`` the solution's set need not be a run: such poses come out
    flagged infeasible, never wrong (``min_norm_tensions`` checks the KKT conditions).
    """
    A, rhs, f_min = (jax.lax.stop_gradient(x) for x in (A, rhs, f_min))
    n = A.shape[1]
    order = jnp.argsort(jnp.arctan2(A[1], A[0]))  # the wires in angular order
    a0, a1 = A[0][order], A[1][order]
    start, length = _arc_runs(n)

    # sums over each run by differences of prefix sums over the wires twice round (no (K, n) array:
    # K = n^2 + 1 runs; at 256 wires that would be 134 MB of constants)
    def run_sum(x):
        cs = jnp.concatenate([jnp.zeros(1, x.dtype), jnp.cumsum(jnp.concatenate([x, x]))])
        return cs[start + length] - cs[start]

    g00, g01, g11 = run_sum(a0 * a0), run_sum(a0 * a1), run_sum(a1 * a1)  # A_S A_S^T
    det = g00 * g11 - g01 * g01  # the wires of a run span < 180 deg: no two parallel
    tr = g00 + g11
    rank2 = (length > 1) & (det > (max(n, 2) * eps_of(A) * tr) ** 2)
    rank1 = ~rank2 & (tr > 0)
    det_s, tr_s = jnp.where(rank2, det, 1.0), jnp.where(rank1, tr, 1.0)

    def pinv_entry(adj, g):  # of pinv(A_S A_S^T): adj / det (rank 2), G / tr^2 (rank 1), 0
        return jnp.where(rank2, adj / det_s, jnp.where(rank1, g / tr_s**2, 0.0))

    i00, i01, i11 = pinv_entry(g11, g00), pinv_entry(-g01, g01), pinv_entry(g00, g11)
    c0 = f_min * (jnp.sum(a0) - run_sum(a0))  # the bound wires' pull, f_min A 1_{not S}
    c1 = f_min * (jnp.sum(a1) - run_sum(a1))
    ang = jnp.arctan2(a1, a0)
    first, last = start, (start + length - 1) % n
    span = jnp.mod(ang[last] - ang[first], 2 * jnp.pi)
    runs = (length > 0) & ((length == 1) | (span < jnp.pi))  # a free set spans less than 180 deg
    inside = length < n  # the run has wires outside it
    before, after = (start - 1) % n, (start + length) % n
    inv_norm_A = 1.0 / jnp.linalg.norm(A)

    r0, r1 = rhs[0] - c0, rhs[1] - c1
    lam0, lam1 = i00 * r0 + i01 * r1, i01 * r0 + i11 * r1

    def y(k):  # a_k . lam of each candidate's wire k
        return a0[k] * lam0 + a1[k] * lam1

    wrong = jnp.maximum(
        jnp.maximum(f_min - y(first), f_min - y(last)),
        jnp.where(inside, jnp.maximum(y(before), y(after)) - f_min, -jnp.inf),
    )
    wrong = jnp.where(length > 0, jnp.maximum(wrong, 0.0), 0.0)  # the empty set: lam = 0, all bound
    miss = (
        jnp.abs(g00 * lam0 + g01 * lam1 + c0 - rhs[0]) + jnp.abs(g01 * lam0 + g11 * lam1 + c1 - rhs[1])
    ) * inv_norm_A
    viol = jnp.where(runs | (length == 0), wrong + miss, jnp.inf)
    best = jnp.argmin(viol)  # the first of least violation
    # the chosen run's wires, in angular order
    member = (np.arange(n) - jnp.asarray(start)[best]) % n < jnp.asarray(length)[best]
    return jnp.zeros(n, A.dtype).at[order].set(member.astype(A.dtype))  # back to the wires' order


def min_norm_tensions(A, rhs, f_min) -> TensionSolution:
    """Exact solution of ``min ||tau||^2 s.t. A tau = rhs, tau >= f_min`` for ``A`` of shape (2, n).

    Closed-form active set: the KKT conditions are ``tau = max(f_min, A^T lam)``, ``A tau = rhs``.
    The free set ``S`` (wires strictly above the bound) is found among the ``2^n`` subsets, a static
    enumeration (:func:`_choose_free_set`); the tensions are then the closed form for that set, the
    minimum-norm solution of ``A_S tau_S = rhs - f_min A 1_{not S}``: ``lam = pinv(A_S A_S^T)(...)``,
    ``tau_S = A_S^T lam`` (the QP is strictly convex, so the KKT point is unique in ``tau``).
    Differentiable: the closed form carries the gradient, the choice of set does not.
    ``feasible`` is False (and the pose must be flagged) when the result misses the KKT conditions
    by more than ``KKT_TOL`` relative, i.e. the wires cannot hold the pose without pushing.
    """
    A = jnp.asarray(A)
    n = A.shape[1]
    dt = jnp.result_type(A, rhs, f_min, float)
    A, rhs, f_min = A.astype(dt), jnp.asarray(rhs, dt), jnp.asarray(f_min, dt)
    # The chosen set, materialised once (`keep`): XLA:CPU would otherwise repeat the enumeration
    # inside the loop of every value that depends on it.
    if n > MAX_SUBSET_WIRES:  # many wires: the runs of _arc_free_mask, O(n^2) candidates
        free = keep([_arc_free_mask(A, rhs, f_min)], A[0, 0])[0]
    else:  # the 2^n subsets; the chosen index's bits are the free mask (_free_sets lists the
        # subsets in binary order, first wire most significant)
        chosen = keep([_choose_free_set(A, rhs, f_min)], A[0, 0])[0].astype(jnp.int32)
        free = jnp.stack([(chosen >> (n - 1 - k)) & 1 for k in range(n)]).astype(dt)
    fr, a0, a1 = per_wire(free), per_wire(A[0]), per_wire(A[1])
    P0, P1 = pinv_tall2_cols(wmap(lambda x, f: x * f, a0, fr), wmap(lambda x, f: x * f, a1, fr))
    r = [rhs[i] - f_min * wsum(wmap(lambda x, f: x * (1.0 - f), ai, fr)) for i, ai in enumerate((a0, a1))]
    t = wmap(lambda p0, p1: p0 * r[0] + p1 * r[1], P0, P1)  # pinv(A_S)^T r: the free tensions
    tau = wstack(wmap(lambda tk, f: tk + f_min * (1.0 - f), t, fr))
    lam = jnp.stack([wsum(wmap(lambda p, tk: p * tk, P0, t)), wsum(wmap(lambda p, tk: p * tk, P1, t))])
    res = kkt_residual(A, rhs, f_min, tau, lam)
    return TensionSolution(tau, lam, res <= KKT_TOL, res)


def kkt_residual(A, rhs, f_min, tau, lam):
    """Relative KKT violation: ``|A tau - rhs|`` and ``|tau - max(f_min, A^T lam)|``.

    Both are zero exactly at the optimum (stationarity, bounds, dual feasibility and
    complementarity are all in ``tau = max(f_min, A^T lam)``); scaled by ``|rhs| + |A| max tau``.
    Any number of rows (a robot's ``2S``); ``f_min`` a scalar or one per wire. Written on scalars:
    vmapped, the per-pose products stay elementwise instead of tiny batched matrix products, which
    XLA:CPU hands to a library call per chunk.
    """
    rows, tk = [per_wire(A[i]) for i in range(A.shape[0])], per_wire(tau)
    norm_A = jnp.linalg.norm(A)  # the design's: once per batch under vmap
    primal = _norm([wsum(wmap(lambda x, t: x * t, ai, tk)) - rhs[i] for i, ai in enumerate(rows)])

    def pull(*xs):  # a_k . lam, the rows in order
        return functools.reduce(jnp.add, [x * lam[i] for i, x in enumerate(xs)])

    fk = per_wire(jnp.broadcast_to(f_min, tau.shape))
    station = wmax(wmap(lambda t, f, *xs: jnp.abs(t - jnp.maximum(f, pull(*xs))), tk, fk, *rows))
    max_tau = wmax(wmap(jnp.abs, tk))
    scale = _norm(rhs) + norm_A * jnp.maximum(max_tau, jnp.max(f_min)) + jnp.finfo(A.dtype).tiny
    return (primal + station * norm_A) / scale


def equilibrium_b(design: Design, b, wrench):
    """The equilibrium ``A tau = rhs`` in bending-vector coordinates at one pose.

    ``A = J_qb^T`` (2, n), ``rhs = J_xb^T w - grad_b U`` (2,), ``U = EI |b|^2 / (2L)``
    (tension_zones/MODEL.md Sec. 4-5).
    """
    w = as_wrench(wrench)
    A = J_qb(design, b).T
    rhs = J_xb(design, b).T @ w - design.backbone_EI * b / design.length
    return A, rhs


def tensions(design: Design, theta_L, delta, wrench) -> TensionSolution:
    """Minimum-norm pull-only tensions holding the pose ``(theta_L, delta)`` (rad) under ``wrench``.

    ``tau >= design.preload`` (N). See :func:`min_norm_tensions`.
    """
    A, rhs = equilibrium_b(design, psi_to_b(theta_L, delta), wrench)
    return min_norm_tensions(A, rhs, design.preload)


def taut_mask(design: Design, tau):
    """The statics taut set, (n,) 0/1 with a straight-through gradient (tension_zones/MODEL.md Sec. 4).

    Without preload: ``tau_k > 1e-6 max_j tau_j``; with a preload every wire is taut.
    Gradient: that of ``sigmoid((tau_k / max tau - 1e-6) / STATICS_TEMPERATURE)`` (zero with a preload).
    """
    tmax = jnp.max(tau)
    pos = tmax > 0
    x = jnp.where(pos, tau / jnp.where(pos, tmax, 1.0), 0.0) - TAUT_REL_TOL
    preloaded = design.preload > 0
    hard = jnp.where(preloaded, True, x > 0)
    soft = jnp.where(preloaded, jnp.ones_like(x), jax.nn.sigmoid(x / STATICS_TEMPERATURE))
    return straight_through(hard, soft)


# --------------------------------------------------------------------------------------------
# Stiffness and compliance
# --------------------------------------------------------------------------------------------
def stiffness_psi(design: Design, theta_L, delta, wrench, tau, mask=None):
    """Configuration stiffness ``K_psi`` (2, 2), N mm/rad^2, with all four terms (paper Eqs. 25-29).

    ``K_psi = hess U + d(J_qpsi^T tau)/dpsi |_tau - d(J_xpsi^T w)/dpsi |_w + k_w J~^T J~``;
    ``J~`` = the rows of ``J_qpsi`` of the wires with ``mask = 1`` (``None``: all, traditional).
    Symmetric when the wrench has no moment (every term is then a Hessian). Singular at the
    straight pose (``delta`` is not defined there): use :func:`stiffness_b` there.
    """
    w = as_wrench(wrench)
    psi = jnp.stack([jnp.asarray(theta_L), jnp.asarray(delta)]).astype(design.length.dtype)
    EI, L = design.backbone_EI, design.length
    hess_U = jnp.array([[EI / L, 0.0], [0.0, 0.0]], dtype=psi.dtype)
    wire_geo = jax.jacfwd(lambda p: J_qpsi(design, p[0], p[1]).T @ tau)(psi)
    load_geo = jax.jacfwd(lambda p: J_xpsi(design, p[0], p[1]).T @ w)(psi)
    Jq = J_qpsi(design, psi[0], psi[1])
    if mask is not None:
        Jq = Jq * mask[:, None]
    return hess_U + wire_geo - load_geo + design.wire_stiffness * Jq.T @ Jq


def _load_terms_b(design: Design, b, w):
    """``(J_xb (6, 2), d(J_xb^T w)/db (2, 2))`` at one pose, in closed form.

    ``J_xb^T w = [dp/du . f + omega_u . m, dp/dv . f + omega_v . m]`` (columns of
    :func:`~tension_zones.model.J_xb`). The force part is the Hessian of
    ``L (c (u f_x + v f_y) + s f_z)`` (``p . f``); the moment part differentiates ``omega_u . m``,
    ``omega_v . m``. Coefficients and their ``x2``-derivatives from
    :func:`~tension_zones.model._kinematics.bend_coeffs` (series at the straight pose). Equal to nested
    forward-mode differentiation of ``J_xb`` (tested), at about a third of the work.
    """
    u, v = b[0], b[1]
    L = design.length
    # kept: every entry below depends on them, and XLA:CPU would re-evaluate their sines and
    # cosines inside each (the 12 of J_xb, the 4 of the load term)
    c, c1, c2, s1, s2, g, g1 = keep(bend_coeffs(u * u + v * v, second=True), L)
    du, dv = J_xb_cols(L, u, v, (c, c1, s1, g))
    Jx = jnp.stack([jnp.stack(du), jnp.stack(dv)], axis=1)
    f0, f1, f2, m0, m1, m2 = (w[i] for i in range(6))
    uu, uv, vv = u * u, u * v, v * v
    a = u * f0 + v * f1
    h_uu = L * (2 * c1 * a + 4 * uu * c2 * a + 4 * u * c1 * f0 + 2 * s1 * f2 + 4 * uu * s2 * f2)
    h_uv = L * (4 * uv * c2 * a + 2 * c1 * (u * f1 + v * f0) + 4 * uv * s2 * f2)
    h_vv = L * (2 * c1 * a + 4 * vv * c2 * a + 4 * v * c1 * f1 + 2 * s1 * f2 + 4 * vv * s2 * f2)
    m_uu = -(2 * uv * u * g1 + g * v) * m0 - 2 * uv * v * g1 * m1 - 2 * uv * c1 * m2
    m_uv = -(2 * uv * v * g1 + g * u) * m0 - (2 * vv * v * g1 + 2 * g * v) * m1 - (2 * vv * c1 + c) * m2
    m_vu = (2 * uu * u * g1 + 2 * g * u) * m0 + (2 * uv * u * g1 + g * v) * m1 + (2 * uu * c1 + c) * m2
    m_vv = 2 * uv * u * g1 * m0 + (2 * uv * v * g1 + g * u) * m1 + 2 * uv * c1 * m2
    load_geo = jnp.stack([jnp.stack([h_uu + m_uu, h_uv + m_uv]), jnp.stack([h_uv + m_vu, h_vv + m_vv])])
    return Jx, load_geo


def _K_b(design: Design, load_geo, mask):
    Jq = J_qb(design)
    if mask is not None:
        Jq = Jq * mask[:, None]
    EI, L = design.backbone_EI, design.length
    return EI / L * jnp.eye(2, dtype=load_geo.dtype) - load_geo + design.wire_stiffness * Jq.T @ Jq


def stiffness_b(design: Design, b, wrench, mask=None):
    """Stiffness in bending-vector coordinates ``K_b`` (2, 2), N mm/rad^2; finite everywhere.

    The four terms of :func:`stiffness_psi` in ``b``: ``hess U = EI/L I``; the wire term vanishes
    (wire lengths are linear in ``b``); ``-d(J_xb^T w)/db``; ``k_w J~_qb^T J~_qb``.
    """
    return _K_b(design, _load_terms_b(design, b, as_wrench(wrench))[1], mask)


def _solve2(K, B):
    """``K^{-1} B`` for a 2x2 ``K``, and whether ``K`` is positive definite (det > 0, trace > 0).

    Guarded (double ``where``): a singular or indefinite ``K`` gives zeros and ``ok = False``.
    """
    det = K[0, 0] * K[1, 1] - K[0, 1] * K[1, 0]
    tr = K[0, 0] + K[1, 1]
    ok = (det > 1e3 * eps_of(K) * jnp.sum(K * K)) & (tr > 0)
    adj = jnp.array([[K[1, 1], -K[0, 1]], [-K[1, 0], K[0, 0]]])
    inv = jnp.where(ok, adj / jnp.where(ok, det, 1.0), 0.0)
    return inv @ B, ok


def _norm(x):
    """Euclidean norm of a short vector (an array or a list of scalars) with a zero (not NaN) gradient
    at ``x = 0`` (double ``where``). Summed elementwise: vmapped, no per-pose reduction op."""
    s = sum(v * v for v in x)
    nz = s > 0
    return jnp.where(nz, jnp.sqrt(jnp.where(nz, s, 1.0)), 0.0)


def _b_of(design, theta_L, delta):
    return psi_to_b(*(jnp.asarray(x, design.length.dtype) for x in (theta_L, delta)))


def compliance(design: Design, theta_L, delta, wrench, mask=None):
    """Task-space compliance ``C_x = J_xpsi K_psi^{-1} J_xpsi^T`` (6, 6) at one pose, and ``ok``.

    Evaluated as ``J_xb K_b^{-1} J_xb^T`` (equal at an equilibrium, finite at the straight pose).
    ``ok`` is False where ``K`` is not positive definite (the compliance is then zeros: flag it).
    ``mask`` (n,) 0/1 selects the wires of ``J~`` (``None``: all wires, traditional).
    """
    Jx, load_geo = _load_terms_b(design, _b_of(design, theta_L, delta), as_wrench(wrench))
    X, ok = _solve2(_K_b(design, load_geo, mask), Jx.T)
    return Jx @ X, ok


def compliance_pose(design: Design, theta_L, delta, wrench):
    """Per-pose tension-only statics and compliance (one pose; ``over_grid`` lifts it to a grid).

    Args: ``theta_L``, ``delta`` (rad); ``wrench`` (3,) or (6,), base frame (N, N mm).
    Returns a dict: ``deflection_mm_full``, ``deflection_mm_reduced`` (``|dx[:3]|``, mm),
    ``deflection_deg_full``, ``deflection_deg_reduced`` (``|dx[3:]|``, deg), ``dx = C_x w``;
    ``tensions`` (n,) N; ``n_taut_statics`` (int); ``feasible`` (bool). "reduced" uses the
    statics taut set, "full" all wires. Where the pose is infeasible (the wires would have to
    push) or a stiffness is not positive definite, the deflections and tensions are NaN. NaN in, NaN
    out: for a non-finite pose or wrench, or an invalid (traced) design, every value is NaN,
    ``n_taut_statics`` -1 and ``feasible`` False.
    """
    w = as_wrench(wrench)
    b = jnp.stack(keep(list(_b_of(design, theta_L, delta)), design.length))  # its sine and cosine, once per pose
    Jx, load_geo = _load_terms_b(design, b, w)
    rhs = Jx.T @ w - design.backbone_EI * b / design.length  # as in equilibrium_b
    sol = min_norm_tensions(J_qb(design).T, rhs, design.preload)
    mask = taut_mask(design, sol.tau)
    feas = sol.feasible
    out = {"tensions": jnp.where(feas, sol.tau, jnp.nan)}
    for mode, m in (("full", None), ("reduced", mask)):
        X, ok = _solve2(_K_b(design, load_geo, m), Jx.T @ w)
        dx = Jx @ X
        good = feas & ok
        out[f"deflection_mm_{mode}"] = jnp.where(good, _norm(dx[:3]), jnp.nan)
        out[f"deflection_deg_{mode}"] = jnp.where(good, jnp.degrees(_norm(dx[3:])), jnp.nan)
    out["n_taut_statics"] = jnp.sum(jax.lax.stop_gradient(mask)).astype(jnp.int32)
    out["feasible"] = feas
    return nan_where(design.invalid() | not_finite(theta_L, delta, w), out)


#: Jitted :func:`compliance_pose` (``design`` values and the wrench are traced: no recompile).
compliance_pose_jit = jax.jit(compliance_pose)
#: ``over_grid`` lift of :func:`compliance_pose`, jitted:
#: ``(design, theta_L (T,), delta (D,), wrench) -> dict``.
compliance_grid_jit = jax.jit(over_grid(compliance_pose))


def compliance_grid(design: Design, wrench=PAPER_WRENCH, theta_L_deg=None, delta_deg=None):
    """:func:`compliance_pose` over a grid; NumPy edge. Degrees in, dict of NumPy arrays out.

    Defaults: the paper's Sec. 6.2 grid (``theta_L`` = linspace(89, 45, 10) deg, ``delta`` = 0, 15,
    ..., 360 deg) and wrench ``[5 N, 0, 0, 0, 0, 0]``. Arrays have shape (n_theta, n_delta), and
    ``tensions`` (n_theta, n_delta, n). Also returns ``theta_L_deg`` and ``delta_deg``.
    """
    th = np.asarray(PAPER_THETA_L_DEG if theta_L_deg is None else theta_L_deg, dtype=float)
    de = np.asarray(PAPER_DELTA_DEG if delta_deg is None else delta_deg, dtype=float)
    for name, a in (("theta_L_deg", th), ("delta_deg", de)):
        if a.ndim != 1 or a.size == 0 or not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be a non-empty 1-D array of finite angles, got {a!r}")
    if np.any(th > 90.0) or np.any(th <= -90.0):
        raise ValueError(f"theta_L_deg must lie in (-90, 90] deg, got {th.tolist()}")
    out = compliance_grid_jit(design, jnp.radians(th), jnp.radians(de), as_wrench(wrench))
    res = {k: np.asarray(v) for k, v in out.items()}
    res["theta_L_deg"], res["delta_deg"] = th, de
    return res
