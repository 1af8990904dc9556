"""Tension-only statics and compliance of a robot of any number of segments (tension_zones/MODEL.md
Sec. 4, chained; the one-segment forms are :mod:`._statics`).

At a configuration ``B`` (S, 2) under a tip wrench ``w = [f; m]`` (base frame, N and N mm) the wires'
tensions hold the robot: ``J_qB^T tau = J_xB^T w - grad U``, ``U = sum_j EI_j |b_j|^2 / (2 L_j)``, with
pull-only wires ``tau_k >= f_min,k`` (each wire's preload). Of the tensions that do, the minimum-norm
one is taken (the QP of :func:`~._statics.min_norm_tensions`, here with ``2S`` equations). A distal
wire crosses the proximal segments, so its tension acts on each of them. The stiffness in ``B``:

    K = blockdiag(EI_j / L_j I_2) - d(J_xB^T w)/dB |_w + sum_k k_k m_k a_k a_k^T

(``a_k`` wire ``k``'s row of ``J_qB``, constant: the tensions' own geometric term vanishes; ``m`` the
taut wires for "reduced", all for "full"), and the tip's deflection ``dx = J_xB K^{-1} J_xB^T w``.
"""

from __future__ import annotations

import itertools

import jax
import jax.numpy as jnp
import numpy as np

from .._numerics import eps_of, nan_where, not_finite, straight_through
from ._robot import Robot
from ._statics import (
    KKT_TOL,
    STATICS_TEMPERATURE,
    TAUT_REL_TOL,
    TensionSolution,
    as_wrench,
    compliance_pose,
    kkt_residual,
)

#: The free sets of the tension QP are enumerated (``2^N``): robots of up to this many wires.
MAX_CHAIN_WIRES = 12


def _subsets(n: int) -> np.ndarray:
    """Every 0/1 free set of ``n`` wires, (2^n, n)."""
    return np.array(list(itertools.product((0.0, 1.0), repeat=n)))


def _set_tensions(A, rhs, f_min, free):
    """The minimum-norm tensions with the wires of ``free`` (N,) 0/1 above their bound and the rest at
    it: ``tau = f_min + free (A^T lam - f_min)``, ``lam = pinv(A_F A_F^T) (rhs - A (f_min (1 - free)))``;
    and ``lam``."""
    AF = A * free[None, :]
    lam = jnp.linalg.pinv(AF @ AF.T, hermitian=True) @ (rhs - A @ (f_min * (1.0 - free)))
    return jnp.where(free > 0, AF.T @ lam, f_min), lam


def _set_forms(A, f_min, sets):
    """Every free set's tensions and pulls as affine functions of ``rhs``: for set ``s`` (of ``sets``
    (K, N)) ``tau_s = Mt_s rhs + ct_s``, ``A^T lam_s = Mp_s rhs + cp_s`` and the primal residual
    ``A tau_s - rhs = MA_s rhs + cA_s`` (:func:`_set_tensions`). They depend on ``A`` and ``f_min``
    alone, so vmapped over configurations of one robot they are formed once per batch, and each
    configuration tries every set by matrix products."""
    AF = A[None] * sets[:, None, :]
    P = jnp.linalg.pinv(AF @ jnp.swapaxes(AF, 1, 2), hermitian=True)  # (K, m, m)
    c = (f_min[None, :] * (1.0 - sets)) @ A.T  # (K, m): A f_min on the wires at their bound
    Mp = jnp.einsum("mn,kml->knl", A, P)  # A^T P_s (K, N, m)
    cp = -jnp.einsum("knl,kl->kn", Mp, c)
    Mt = Mp * sets[:, :, None]
    ct = jnp.where(sets > 0, cp, f_min[None, :])
    MA = jnp.einsum("mn,knl->kml", A, Mt) - jnp.eye(A.shape[0], dtype=A.dtype)[None]
    return Mt, ct, Mp, cp, MA, ct @ A.T


def _set_residuals(A, rhs, f_min, sets):
    """:func:`~._statics.kkt_residual` of every free set's tensions (K,), written over the sets at once
    (that function vmapped over them, on its scalars, costs several times as much; the tests hold
    the two equal)."""
    Mt, ct, Mp, cp, MA, cA = _set_forms(A, f_min, sets)
    tau, pull = Mt @ rhs + ct, Mp @ rhs + cp  # (K, N)
    primal = jnp.linalg.norm(MA @ rhs + cA, axis=1)
    station = jnp.max(jnp.abs(tau - jnp.maximum(f_min[None, :], pull)), axis=1)
    norm_A = jnp.linalg.norm(A)
    max_tau = jnp.maximum(jnp.max(jnp.abs(tau), axis=1), jnp.max(f_min))
    return (primal + station * norm_A) / (jnp.linalg.norm(rhs) + norm_A * max_tau + jnp.finfo(A.dtype).tiny)


def chain_min_norm_tensions(A, rhs, f_min) -> TensionSolution:
    """Exact ``min ||tau||^2 s.t. A tau = rhs, tau >= f_min`` for ``A`` (m, N), ``f_min`` (N,).

    The strictly convex QP's KKT point is unique: every free set is tried (a static enumeration of the
    ``2^N``, :func:`_set_residuals`) and the one whose tensions meet the KKT conditions is kept; its
    closed form carries the gradient, the choice of set does not. ``feasible`` False: no set does
    (the wires would push).
    """
    n = A.shape[1]
    if n > MAX_CHAIN_WIRES:
        raise ValueError(f"a robot's tensions enumerate 2^N free sets: at most {MAX_CHAIN_WIRES} wires, got {n}")
    sets = jnp.asarray(_subsets(n), A.dtype)
    f_min = jnp.broadcast_to(jnp.asarray(f_min, A.dtype), (n,))
    A0, rhs0, f0 = (jax.lax.stop_gradient(x) for x in (A, rhs, f_min))  # the choice carries no gradient
    res = _set_residuals(A0, rhs0, f0, sets)
    free = sets[jnp.argmin(jnp.where(jnp.isnan(res), jnp.inf, res))]
    tau, lam = _set_tensions(A, rhs, f_min, free)
    res = kkt_residual(A, rhs, f_min, tau, lam)
    return TensionSolution(tau, lam, res <= KKT_TOL, res)


def chain_equilibrium(robot: Robot, B, w):
    """``(A, rhs)`` of ``A tau = rhs``: ``A = J_qB^T`` (2S, N), ``rhs = J_xB^T w - grad U`` (2S,)."""
    grad_U = (robot.backbone_EI / robot.lengths)[:, None] * B
    return robot.J_qB().T, robot.J_xB(B).T @ w - grad_U.reshape(-1)


def chain_taut_mask(robot: Robot, tau):
    """The statics taut set (N,) 0/1 with a straight-through gradient: a preloaded wire is always taut,
    another where ``tau_k > 1e-6 max_j tau_j`` (tension_zones/MODEL.md Sec. 4)."""
    tmax = jnp.max(tau)
    pos = tmax > 0
    x = jnp.where(pos, tau / jnp.where(pos, tmax, 1.0), 0.0) - TAUT_REL_TOL
    preloaded = robot.preload > 0
    hard = preloaded | (x > 0)
    soft = jnp.where(preloaded, 1.0, jax.nn.sigmoid(x / STATICS_TEMPERATURE))
    return straight_through(hard, soft)


def chain_stiffness(robot: Robot, B, w, mask=None):
    """The configuration stiffness ``K`` (2S, 2S) at ``B`` under ``w`` (module docstring); ``mask``
    (N,) 0/1 keeps the taut wires' axial stiffness (``None``: all wires)."""
    S = robot.n_segments
    hess_U = jnp.diag(jnp.repeat(robot.backbone_EI / robot.lengths, 2))
    load_geo = jax.jacfwd(lambda x: robot.J_xB(x).T @ w)(B).reshape(2 * S, 2 * S)
    k = robot.wire_stiffness * (1.0 if mask is None else mask)
    Jq = robot.J_qB()
    return hess_U - load_geo + Jq.T @ (k[:, None] * Jq)


def _solve(K, rhs):
    """``K^{-1} rhs`` and whether ``K``'s symmetric part is positive definite (zeros where it is not)."""
    lo = jnp.linalg.eigvalsh(0.5 * (K + K.T))[0]
    ok = lo > 1e3 * eps_of(K) * jnp.linalg.norm(K)
    x = jnp.linalg.solve(jnp.where(ok, K, jnp.eye(K.shape[0], dtype=K.dtype)), rhs)
    return jnp.where(ok, x, 0.0), ok


def _deflections(robot: Robot, B, w, sol, mask) -> dict:
    Jx = robot.J_xB(B)
    out = {}
    for mode, m in (("full", None), ("reduced", mask)):
        X, ok = _solve(chain_stiffness(robot, B, w, m), Jx.T @ w)
        dx = Jx @ X
        good = sol.feasible & ok
        out[f"deflection_mm_{mode}"] = jnp.where(good, jnp.linalg.norm(dx[:3]), jnp.nan)
        out[f"deflection_deg_{mode}"] = jnp.where(good, jnp.degrees(jnp.linalg.norm(dx[3:])), jnp.nan)
    return out


def config_compliance(robot: Robot, B, wrench, general: bool = False) -> dict:
    """Tension-only statics and compliance of a robot at one configuration, as
    :func:`~._statics.compliance_pose`: ``deflection_mm_full``, ``deflection_mm_reduced`` (mm),
    ``deflection_deg_full``, ``deflection_deg_reduced`` (deg), ``tensions`` (N,) N,
    ``n_taut_statics``, ``feasible``; NaN (and -1, False) for a non-finite configuration or wrench.

    ``B`` (S, 2) rad; ``wrench`` (3,) or (6,) base frame. A one-segment robot is the segment's own
    :func:`~._statics.compliance_pose` (``general=True``: the chain formulas, the same numbers).
    """
    w = as_wrench(wrench)
    B = jnp.asarray(B, robot.route_angles.dtype)
    if robot.n_segments == 1 and not general:
        from ._kinematics import b_to_psi

        theta_L, delta = b_to_psi(B[0])
        return compliance_pose(robot.segments[0], theta_L, delta, w)
    bad = not_finite(B, w)
    Bs = jnp.where(bad, 0.0, B)  # the solve on a finite stand-in; NaN written over it below
    A, rhs = chain_equilibrium(robot, Bs, w)
    sol = chain_min_norm_tensions(A, rhs, robot.preload)
    mask = chain_taut_mask(robot, sol.tau)
    out = {"tensions": jnp.where(sol.feasible, sol.tau, jnp.nan), **_deflections(robot, Bs, w, sol, mask)}
    out["n_taut_statics"] = jnp.sum(jax.lax.stop_gradient(mask)).astype(jnp.int32)
    out["feasible"] = sol.feasible
    return nan_where(bad, out)
