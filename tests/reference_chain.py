"""An independent per-configuration NumPy reference for the measures of a robot of several segments
(tension_zones/analysis/_chain.py): chained constant-curvature kinematics written afresh, Jacobians by
central differences, ``numpy.linalg.pinv`` and ``svd``, the tension zones from the wires' pull rates,
and the uncertainty bound from all ``2^N`` vertices of the wire uncertainty box."""

import itertools

import numpy as np


def _rotation(w):
    th = np.linalg.norm(w)
    K = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    if th < 1e-12:
        return np.eye(3) + K
    return np.eye(3) + np.sin(th) / th * K + (1 - np.cos(th)) / th**2 * K @ K


def _segment(L, b):
    """Tip position and rotation of one segment (tension_zones/MODEL.md Sec. 5), series near straight."""
    u, v = b
    phi = np.hypot(u, v)
    if phi > 1e-2:
        c, s = L * (1 - np.cos(phi)) / phi**2, L * np.sin(phi) / phi
    else:
        c = L * (0.5 - phi**2 / 24 + phi**4 / 720 - phi**6 / 40320)
        s = L * (1 - phi**2 / 6 + phi**4 / 120 - phi**6 / 5040)
    return np.array([c * u, c * v, s]), _rotation(np.array([-v, u, 0.0]))


def tip(lengths, B):
    p, R = np.zeros(3), np.eye(3)
    for L, b in zip(lengths, B):
        pj, Rj = _segment(L, b)
        p, R = p + R @ pj, R @ Rj
    return p, R


def J_xB(lengths, B, h=1e-6):
    """(6, 2S) by central differences: velocity, and the angular velocity ``vee(dR R^T)``."""
    B = np.asarray(B, float)
    x = B.ravel()
    _, R = tip(lengths, B)
    J = np.zeros((6, x.size))
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = h
        pp, Rp = tip(lengths, (x + e).reshape(B.shape))
        pm, Rm = tip(lengths, (x - e).reshape(B.shape))
        W = (Rp - Rm) / (2 * h) @ R.T
        J[:3, i] = (pp - pm) / (2 * h)
        J[3:, i] = [W[2, 1], W[0, 2], W[1, 0]]
    return J


def routing(route_angles, route_radii, crosses):
    N, S = route_angles.shape
    Jq = np.zeros((N, 2 * S))
    for k in range(N):
        for j in range(S):
            if crosses[k, j]:
                Jq[k, 2 * j : 2 * j + 2] = -route_radii[k, j] * np.array(
                    [np.cos(route_angles[k, j]), np.sin(route_angles[k, j])]
                )
    return Jq


def taut(Jq, route_radii, crosses, B):
    """Wires pulled in when every segment bends further in its own plane (``(1, 0)`` when straight)."""
    B = np.asarray(B, float)
    # straight where |b|^2 is 0 in floating point (the package's convention), subnormals included:
    # XLA:CPU flushes them to zero
    d = np.array([b / np.sqrt(b @ b) if b @ b >= np.finfo(float).tiny else (1.0, 0.0) for b in B])
    q_dot = Jq @ d.ravel()
    scale = np.sum(np.where(crosses, route_radii, 0.0), axis=1)
    return -q_dot / scale > 1e-9


def measures(lengths, route_angles, route_radii, crosses, B, dq):
    """Full and reduced measures at ``B`` (S, 2), keyed as ``config_metrics``."""
    S = len(lengths)
    Jq = routing(route_angles, route_radii, crosses)
    Jx = J_xB(lengths, B)
    mask = taut(Jq, route_radii, crosses, B).astype(float)
    N = Jq.shape[0]
    box = np.array(list(itertools.product([-1.0, 1.0], repeat=N))).T * dq
    r = min(3, 2 * S)
    out = {"n_taut": int(mask.sum())}
    for mode, m in (("full", np.ones(N)), ("reduced", mask)):
        J = Jx @ (np.linalg.pinv(Jq * m[:, None]) * m[None, :])
        for part, block in (("v", J[:3]), ("w", J[3:])):
            s = np.linalg.svd(block, compute_uv=False)
            out[f"kci_{part}_{mode}"] = s[r - 1] / s[0] if s[0] > 0 else 0.0
            out[f"sigma_min_{part}_{mode}"] = s[r - 1]
        out[f"dp_max_{mode}"] = np.max(np.linalg.norm(J[:3] @ box, axis=0))
        out[f"dw_max_{mode}"] = np.max(np.linalg.norm(J[3:] @ box, axis=0))
    return out


def compliance(lengths, EI, route_angles, route_radii, crosses, k_w, preload, B, w, h=1e-4):
    """Deflections of ``config_compliance`` by an independent route: tensions by SciPy's SLSQP on
    ``min ||tau||^2, A tau = rhs, tau >= preload``, the load term by central differences of
    ``J_xB^T w``, and ``numpy.linalg.solve``."""
    from scipy.optimize import minimize

    B = np.asarray(B, float)
    S = len(lengths)
    Jq = routing(route_angles, route_radii, crosses)
    Jx = J_xB(lengths, B)
    rhs = Jx.T @ w - (np.repeat(np.asarray(EI) / np.asarray(lengths), 2) * B.ravel())
    A = Jq.T
    res = minimize(
        lambda t: t @ t,
        np.maximum(np.linalg.lstsq(A, rhs, rcond=None)[0], preload),
        jac=lambda t: 2 * t,
        bounds=[(p, None) for p in preload],
        constraints=[{"type": "eq", "fun": lambda t: A @ t - rhs, "jac": lambda t: A}],
        method="SLSQP",
        options={"ftol": 1e-16, "maxiter": 500},
    )
    tau = res.x
    taut = (np.asarray(preload) > 0) | (tau > 1e-6 * tau.max())
    load = np.zeros((2 * S, 2 * S))
    for i in range(2 * S):
        e = np.zeros(2 * S)
        e[i] = h
        plus, minus = J_xB(lengths, B + e.reshape(S, 2), h), J_xB(lengths, B - e.reshape(S, 2), h)
        load[:, i] = (plus.T @ w - minus.T @ w) / (2 * h)
    hess_U = np.diag(np.repeat(np.asarray(EI) / np.asarray(lengths), 2))
    out = {"tensions": tau, "n_taut_statics": int(taut.sum())}
    for mode, m in (("full", np.ones(len(tau))), ("reduced", taut.astype(float))):
        K = hess_U - load + Jq.T @ ((np.asarray(k_w) * m)[:, None] * Jq)
        dx = Jx @ np.linalg.solve(K, Jx.T @ w)
        out[f"deflection_mm_{mode}"] = np.linalg.norm(dx[:3])
        out[f"deflection_deg_{mode}"] = np.degrees(np.linalg.norm(dx[3:]))
    return out
