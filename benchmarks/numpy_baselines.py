"""Independent NumPy/SciPy implementations the benchmarks compare the JAX path against.

Written from tension_zones/MODEL.md (Sec. 1-4) without importing tension_zones, the way a MATLAB-style user would:
* :func:`measures_loop`: one pose at a time, ``numpy.linalg.pinv``/``svd`` and the paper's literal
  ``Q`` matrix of all ``3^n`` joint-error vectors (Eqs. 17-19);
* :func:`measures_vectorised`: the same numbers, batched over poses with stacked ``numpy.linalg``
  calls and the ``2^n`` sign vertices;
* :func:`compliance_scipy_loop`: the compliance sweep per pose: the tension distribution with
  ``scipy.optimize.minimize`` (SLSQP), as the paper did with MATLAB's interior-point solver, then the
  stiffness and deflection with NumPy.
"""

from __future__ import annotations

import itertools

import numpy as np

TOL = 1e-9


def jacobians(L, r, alpha, theta_L, delta):
    """J_xpsi (6, 2) and J_qpsi (n, 2) at one pose (tension_zones/MODEL.md Sec. 1)."""
    T = theta_L - np.pi / 2
    s, c = np.sin(theta_L), np.cos(theta_L)
    A = T * c - s + 1
    sd, cd = np.sin(delta), np.cos(delta)
    Jv = L * np.array(
        [[cd * A / T**2, -sd * (s - 1) / T], [-sd * A / T**2, -cd * (s - 1) / T], [(T * s + c) / T**2, 0.0]]
    )
    Jw = np.array([[-sd, cd * c], [-cd, -sd * c], [0.0, -1 + s]])
    dk = delta + alpha
    Jq = r * np.stack([np.cos(dk), -T * np.sin(dk)], axis=1)
    return np.vstack([Jv, Jw]), Jq


def _sv(M):
    s = np.append(np.linalg.svd(M, compute_uv=False), 0.0)  # one taut wire: one column
    s1, s2 = s[0], s[1]
    return s1, (s2 if s2 > max(M.shape) * np.finfo(float).eps * s1 else 0.0)


def measures_loop(L, r, alpha, thetas, deltas, dq):
    """Per-pose loop over the grid; returns a dict of (n_theta, n_delta) arrays, reduced Jacobian."""
    n = len(alpha)
    Q = dq * np.array(list(itertools.product((-1.0, 0.0, 1.0), repeat=n))).T  # (n, 3^n)
    out = {
        k: np.zeros((len(thetas), len(deltas)))
        for k in ("kci_v", "kci_w", "sigma_min_v", "sigma_min_w", "dp_max", "dw_max")
    }
    for i, th in enumerate(thetas):
        for j, de in enumerate(deltas):
            Jx, Jq = jacobians(L, r, alpha, th, de)
            taut = np.cos(de + alpha) > TOL
            P = np.linalg.pinv(Jq[taut])
            Jxq = Jx @ P
            for part, rows in (("v", slice(0, 3)), ("w", slice(3, 6))):
                s1, s2 = _sv(Jxq[rows])
                out[f"kci_{part}"][i, j] = s2 / s1 if s1 > 0 else 0.0
                out[f"sigma_min_{part}"][i, j] = s2
            dx = Jxq @ Q[taut]
            out["dp_max"][i, j] = np.max(np.linalg.norm(dx[:3], axis=0))
            out["dw_max"][i, j] = np.max(np.linalg.norm(dx[3:], axis=0))
    return out


def measures_vectorised(L, r, alpha, thetas, deltas, dq):
    """The same measures, batched over all poses with stacked numpy.linalg calls."""
    n = len(alpha)
    th, de = (x.ravel() for x in np.meshgrid(thetas, deltas, indexing="ij"))
    T = th - np.pi / 2
    s, c = np.sin(th), np.cos(th)
    A = T * c - s + 1
    sd, cd = np.sin(de), np.cos(de)
    z = np.zeros_like(T)
    Jv = L * np.stack(
        [
            np.stack([cd * A / T**2, -sd * (s - 1) / T], -1),
            np.stack([-sd * A / T**2, -cd * (s - 1) / T], -1),
            np.stack([(T * s + c) / T**2, z], -1),
        ],
        1,
    )
    Jw = np.stack([np.stack([-sd, cd * c], -1), np.stack([-cd, -sd * c], -1), np.stack([z, -1 + s], -1)], 1)
    dk = de[:, None] + alpha[None, :]
    taut = np.cos(dk) > TOL
    Jq = r * np.stack([np.cos(dk), -T[:, None] * np.sin(dk)], -1) * taut[..., None]
    P = np.linalg.pinv(Jq)  # (N, 2, n)
    out = {}
    for part, Jx in (("v", Jv), ("w", Jw)):
        M = Jx @ P
        sv = np.linalg.svd(M, compute_uv=False)
        s1 = sv[:, 0]
        s2 = np.where(sv[:, 1] > max(3, n) * np.finfo(float).eps * s1, sv[:, 1], 0.0)
        out[f"kci_{part}"] = np.where(s1 > 0, s2 / np.where(s1 > 0, s1, 1), 0.0)
        out[f"sigma_min_{part}"] = s2
    signs = dq * np.array(list(itertools.product((-1.0, 1.0), repeat=n))).T  # (n, 2^n)
    dpsi = P @ signs  # slack columns of P are zero, so their sign does not matter
    out["dp_max"] = np.max(np.linalg.norm(Jv @ dpsi, axis=1), axis=1)
    out["dw_max"] = np.max(np.linalg.norm(Jw @ dpsi, axis=1), axis=1)
    return {k: v.reshape(len(thetas), len(deltas)) for k, v in out.items()}


def _slsqp_tensions(Jq, rhs, f_min):
    """min ||tau||^2 s.t. J_qpsi^T tau = rhs, tau >= f_min: one SLSQP call."""
    from scipy.optimize import minimize

    n = Jq.shape[0]
    res = minimize(
        lambda t: t @ t,
        np.full(n, f_min + 1.0),
        jac=lambda t: 2 * t,
        constraints=[{"type": "eq", "fun": lambda t: Jq.T @ t - rhs, "jac": lambda t: Jq.T}],
        bounds=[(f_min, None)] * n,
        method="SLSQP",
        options={"ftol": 1e-12, "maxiter": 200},
    )
    return res.x


def compliance_scipy_loop(L, r, alpha, EI, k_w, thetas, deltas, wrench, f_min=0.0, h=1e-6, stiffness=True):
    """Per pose (tension_zones/MODEL.md Sec. 4; paper Eqs. 23-31 in psi): the tensions by SLSQP, then
    ``K_psi = hess U + d(J_qpsi^T tau)/dpsi - d(J_xpsi^T w)/dpsi + k_w J~^T J~`` (the two derivative
    terms by central differences of the analytic Jacobians) and the deflection ``dx = J_xpsi
    K^{-1} J_xpsi^T w`` for all wires ("full") and the taut ones (``tau_k > 1e-6 max tau``, "reduced").

    Returns a dict of (n_theta, n_delta) arrays ``deflection_mm_<mode>``, ``deflection_deg_<mode>`` and
    ``tensions`` (n_theta, n_delta, n). ``stiffness=False``: the tensions only.
    """
    n = len(alpha)
    shape = (len(thetas), len(deltas))
    out = {f"deflection_{u}_{m}": np.zeros(shape) for u in ("mm", "deg") for m in ("full", "reduced")}
    out["tensions"] = np.zeros(shape + (n,))
    hess_U = np.array([[EI / L, 0.0], [0.0, 0.0]])
    for i, th in enumerate(thetas):
        for j, de in enumerate(deltas):
            Jx, Jq = jacobians(L, r, alpha, th, de)
            rhs = Jx.T @ wrench - np.array([EI * (th - np.pi / 2) / L, 0.0])
            tau = out["tensions"][i, j] = _slsqp_tensions(Jq, rhs, f_min)
            if not stiffness:
                continue
            geo = np.zeros((2, 2))  # d(J_qpsi^T tau - J_xpsi^T w)/dpsi, column by column
            for k, e in enumerate(np.eye(2) * h):
                Jx_p, Jq_p = jacobians(L, r, alpha, th + e[0], de + e[1])
                Jx_m, Jq_m = jacobians(L, r, alpha, th - e[0], de - e[1])
                geo[:, k] = ((Jq_p - Jq_m).T @ tau - (Jx_p - Jx_m).T @ wrench) / (2 * h)
            for mode, mask in (("full", np.ones(n)), ("reduced", tau > 1e-6 * tau.max())):
                Jt = Jq * mask[:, None]
                K = hess_U + geo + k_w * Jt.T @ Jt
                dx = Jx @ np.linalg.solve(K, Jx.T @ wrench)
                out[f"deflection_mm_{mode}"][i, j] = np.linalg.norm(dx[:3])
                out[f"deflection_deg_{mode}"][i, j] = np.degrees(np.linalg.norm(dx[3:]))
    return out
