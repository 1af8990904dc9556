"""The project's own generator of measurement sets with undeclared effects (test code only).

Its own code path on purpose: NumPy physics, SciPy's BFGS for the equilibrium (the library uses a
damped Newton in JAX with implicit derivatives), a Python loop for path-dependent effects (the
library scans), its own formulas for every effect (e.g. friction as a linear tension factor where the
library uses a capstan exponential, registration through SciPy's Rotation). A set is returned as the
CSV text of MODEL.md Sec. 6 plus the declared design, and can be written to files.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

DECLARED = {"length_mm": 20.0, "pitch_radius_mm": 2.0, "wire_stiffness_N_per_mm": 75.0,
            "backbone_EI_Nmm2": 1200.0, "preload_N": 2.0}


@dataclasses.dataclass
class Truth:
    """The simulated robot: the declared design plus undeclared effects (all zero = declared)."""

    n_wires: int = 3
    d_length: float = 0.0  # mm
    d_radius: float = 0.0  # mm
    angle_offsets_deg: tuple = ()  # per wire
    stiffness_factors: tuple = ()  # per wire, multiplies k
    d_preload: tuple = ()  # per wire, N
    play: tuple = ()  # per wire, mm (backlash)
    friction: float = 0.0  # tension factor 1 -/+ friction when pulling/releasing
    tip_force: tuple = (0.0, 0.0, 0.0)  # N
    rotation_deg: tuple = (0.0, 0.0, 0.0)  # tracker <- base, rotation vector in degrees
    translation: tuple = (0.0, 0.0, 0.0)  # mm
    drift_mm: float = 0.0  # outside the library: a periodic tracker drift along the acquisition
    noise: float = 0.05  # mm per axis
    glitches: int = 0  # gross tracker outliers


def _per_wire(v, n, default):
    return np.full(n, default, float) if len(v) == 0 else np.asarray(v, float)


def position(b, L):
    """Tip position of a constant-curvature segment (MODEL.md Sec. 5), own implementation."""
    phi = np.hypot(b[0], b[1])
    if phi < 1e-6:
        k = L * (0.5 - phi**2 / 24.0)
        s = L * (1.0 - phi**2 / 6.0)
    else:
        k = L * (1.0 - np.cos(phi)) / phi**2
        s = L * np.sin(phi) / phi
    return np.array([k * b[0], k * b[1], s])


def _equilibrium(q, f, tension, L, r, alpha, k, pre, EI, b0):
    a = np.stack([np.cos(alpha), np.sin(alpha)], axis=1)

    def V(b):
        s = -r * (a @ b) - q + pre / k
        return EI * (b @ b) / (2 * L) + 0.5 * np.sum(tension * k * np.maximum(s, 0.0) ** 2) - f @ position(b, L)

    def grad(b):
        s = -r * (a @ b) - q + pre / k
        g = EI * b / L - r * a.T @ (tension * k * np.maximum(s, 0.0))
        h = 1e-6
        gl = np.array([(f @ position(b + h * e, L) - f @ position(b - h * e, L)) / (2 * h) for e in np.eye(2)])
        return g - gl

    res = minimize(V, b0, jac=grad, method="BFGS", options={"gtol": 1e-9, "maxiter": 500})
    return res.x


def trajectory(n_samples: int, rng, max_bend=0.75, step=0.045):
    """Commanded bending path: straight runs between random waypoints, dwells with and without loads."""
    bs, loads = [], []
    b = np.zeros(2)
    while len(bs) < n_samples:
        target = rng.uniform(0.15, max_bend) * np.array([np.cos(t := rng.uniform(0, 2 * np.pi)), np.sin(t)])
        m = max(int(np.linalg.norm(target - b) / step), 1)
        for s in range(1, m + 1):
            bs.append(b + (target - b) * s / m)
            loads.append(np.zeros(3))
        b = target
        for _ in range(rng.integers(3, 9)):  # dwell: repeats, some with a hung load
            bs.append(b.copy())
            loaded = rng.random() < 0.35
            loads.append(rng.normal(0, 0.7, 3).clip(-1.5, 1.5) if loaded else np.zeros(3))
    return np.array(bs[:n_samples]), np.array(loads[:n_samples])


def simulate(truth: Truth, n_samples: int = 240, seed: int = 0):
    """``(rows, header, design_dict)``: a measurement set of ``truth`` in acquisition order."""
    rng = np.random.default_rng(seed)
    n = truth.n_wires
    alpha0 = np.arange(n) * 2 * np.pi / n
    r0, L0 = DECLARED["pitch_radius_mm"], DECLARED["length_mm"]
    b_cmd, f = trajectory(n_samples, rng)
    a0 = np.stack([np.cos(alpha0), np.sin(alpha0)], axis=1)
    q = np.round(-r0 * b_cmd @ a0.T, 6)  # the controller's commands from the declared kinematics

    L, r = L0 + truth.d_length, r0 + truth.d_radius
    alpha = alpha0 + np.radians(_per_wire(truth.angle_offsets_deg, n, 0.0))
    k = DECLARED["wire_stiffness_N_per_mm"] * _per_wire(truth.stiffness_factors, n, 1.0)
    pre = DECLARED["preload_N"] + _per_wire(truth.d_preload, n, 0.0)
    play = _per_wire(truth.play, n, 0.0)
    EI = DECLARED["backbone_EI_Nmm2"]
    R = Rotation.from_rotvec(np.radians(truth.rotation_deg))

    q_eff = q[0].copy()
    last_dir = np.zeros(n)
    b = np.zeros(2)
    P = np.empty((n_samples, 3))
    for i in range(n_samples):
        if i > 0:
            dq = q[i] - q[i - 1]
            last_dir = np.where(dq > 0, 1.0, np.where(dq < 0, -1.0, last_dir))
        for j in range(n):  # play: the wire follows once the slack on one side is taken up
            if q[i, j] > q_eff[j] + play[j] / 2:
                q_eff[j] = q[i, j] - play[j] / 2
            elif q[i, j] < q_eff[j] - play[j] / 2:
                q_eff[j] = q[i, j] + play[j] / 2
        tension = 1.0 + truth.friction * last_dir
        b = _equilibrium(q_eff, f[i] + np.asarray(truth.tip_force), tension, L, r, alpha, k, pre, EI, b)
        P[i] = R.apply(position(b, L)) + np.asarray(truth.translation)
    t = np.arange(n_samples) / n_samples
    P[:, 0] += truth.drift_mm * np.sin(2 * np.pi * 3 * t)
    P[:, 1] += truth.drift_mm * np.cos(2 * np.pi * 3 * t)
    P += rng.normal(0.0, truth.noise, P.shape)
    if truth.glitches:
        idx = rng.choice(np.arange(5, n_samples), truth.glitches, replace=False)
        P[idx] += rng.choice([-1, 1], (truth.glitches, 3)) * rng.uniform(3.0, 6.0, (truth.glitches, 3))
    rot = rng.normal(0.0, 0.005, (n_samples, 3))  # orientation is validated, not fitted
    header = ["sample", *[f"q{j + 1}" for j in range(n)], "fx", "fy", "fz", "px", "py", "pz", "rx", "ry", "rz"]
    rows = np.column_stack([np.arange(n_samples), q, f, P, rot])
    design = dict(n_wires=n, **DECLARED, wire_angles_deg=np.degrees(alpha0).tolist())
    return rows, header, design


def write_set(folder, name: str, truth: Truth, n_samples: int = 240, seed: int = 0):
    """Write ``NAME.csv`` and ``NAME.design.json``; return their paths."""
    rows, header, design = simulate(truth, n_samples, seed)
    folder = Path(folder)
    csv_path, design_path = folder / f"{name}.csv", folder / f"{name}.design.json"
    lines = [",".join(header)] + [
        ",".join([str(int(r[0]))] + [f"{x:.6f}" for x in r[1:]]) for r in rows
    ]
    csv_path.write_text("\n".join(lines) + "\n")
    design_path.write_text(json.dumps(design))
    return csv_path, design_path
