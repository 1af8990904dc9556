"""The project's own generator of measurement sets with undeclared effects (test code only).

Its own code path on purpose: NumPy physics, SciPy's BFGS for the equilibrium (the library uses a
damped Newton in JAX with implicit derivatives), a Python loop for path-dependent effects (the
library scans), its own formulas for every effect (e.g. a single segment's friction as a linear tension
factor where the library uses a capstan exponential, registration through SciPy's Rotation). A set is returned as the
CSV text of tension_zones/MODEL.md Sec. 6 plus the declared design, and can be written to files.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
from scipy.optimize import minimize, root
from scipy.spatial.transform import Rotation

DECLARED = {
    "length_mm": 20.0,
    "pitch_radius_mm": 2.0,
    "wire_stiffness_N_per_mm": 75.0,
    "backbone_EI_Nmm2": 1200.0,
    "preload_N": 2.0,
}


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
    """Tip position of a constant-curvature segment (tension_zones/MODEL.md Sec. 5), own implementation."""
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
    lines = [",".join(header)] + [",".join([str(int(r[0]))] + [f"{x:.6f}" for x in r[1:]]) for r in rows]
    csv_path.write_text("\n".join(lines) + "\n")
    design_path.write_text(json.dumps(design))
    return csv_path, design_path


# =============================================================================================
# Robots of one or more segments, recorded the way the OpenCR lab records (labelled patterns,
# servo ids shuffled, an unregistered tracker frame). Own code path again: positions from SciPy's
# rotations, the weight integrated by Gauss-Legendre quadrature, the load's gradient by finite
# differences, SciPy's BFGS for the equilibrium, friction (the capstan's decay over every piece, which
# is not conservative) by a fixed point of BFGS solves with its force frozen, path-dependent effects as
# Python loops.
# =============================================================================================
ROBOT = {
    "segments": [
        {
            "length_mm": 45.0,
            "n_wires": 3,
            "pitch_radius_mm": 3.5,
            "wire_angles_deg": [10.0, 130.0, 250.0],
            "backbone_EI_Nmm2": 1500.0,
            "wire_stiffness_N_per_mm": 30.0,
            "preload_N": 0.0,
        },
        {
            "length_mm": 70.0,
            "n_wires": 4,
            "pitch_radius_mm": 5.0,
            "wire_angles_deg": [45.0, 135.0, 215.0, 315.0],
            "backbone_EI_Nmm2": 3000.0,
            "wire_stiffness_N_per_mm": 80.0,
            "preload_N": 0.0,
        },
    ]
}


@dataclasses.dataclass
class RobotTruth:
    """A robot (a ``{"segments": [...]}`` design) and what its design file does not declare.

    ``pattern_rotation_deg``, ``translation``, a rotation about the robot's axis and ``EI_factors`` are
    what tracker recordings always have (the nominal parameters of such data); the rest, a tilt of the
    tracker (``registration_deg`` about x and y) included, are effects (all zero = none).
    """

    design: dict = dataclasses.field(default_factory=lambda: ROBOT)
    pattern_rotation_deg: tuple = (12.0, -20.0)  # per segment
    registration_deg: tuple = (0.0, 0.0, 4.0)  # tracker <- base rotation vector (a tilt is an effect)
    translation: tuple = (2.0, -3.0, 5.0)  # mm
    EI_factors: tuple = (1.2, 0.8)  # per segment
    play: tuple = ()  # per wire, mm
    friction: tuple = (0.0, 0.0)  # (routing, per rad of bending): capstan, decaying over every piece
    angle_offsets_deg: tuple = ()  # per wire
    stiffness_factors: tuple = ()  # per wire
    d_preload: tuple = ()  # per wire, N
    tip_force: tuple = (0.0, 0.0, 0.0)  # N, base frame
    gravity: tuple = (0.0, 0.0, 0.0)  # N/mm, base frame
    marker: tuple = (0.0, 0.0, 0.0)  # mm, tip frame
    d_length: tuple = ()  # per segment, mm
    d_radius: tuple = ()  # per segment, mm
    twist_deg: tuple = ()  # per pair of neighbouring segments: turn of segment j's disks against j + 1's
    clearance: tuple = (0.0, 0.0)  # mm per rad of bending: a wire's path shortened in its own segment, the ones before
    drift_mm: float = 0.0  # outside the library: a slow tracker drift along the acquisition
    wire_drift: float = 0.0  # mm per hour: every wire lengthens at this rate on the recordings' clock
    bending_friction: tuple = ()  # per segment, N mm: Coulomb friction of the bending (hysteresis)
    compression: tuple = ()  # per segment, mm/N: the backbone's axial compliance under the wires' tension
    noise: float = 0.05
    pieces: int = 1  # constant-curvature pieces per segment: 1, constant curvature; many, an elastic rod


def _rodrigues(w):
    """Rotation matrix of the rotation vector ``w`` (NumPy, axis-angle form)."""
    th = np.linalg.norm(w)
    if th < 1e-12:
        return np.eye(3)
    k = w / th
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(th) * K + (1.0 - np.cos(th)) * (K @ K)


def _arc(L, b, s):
    """Position and rotation at arc length s of a segment of length L and bending vector b."""
    u, v = b
    phi = np.hypot(u, v) * s / L
    rot = _rodrigues(np.array([-v, u, 0.0]) * s / L)
    if phi < 1e-9:
        return np.array([0.0, 0.0, s]), rot
    sig = np.arctan2(v, u)
    rho = s / phi
    return np.array(
        [rho * (1 - np.cos(phi)) * np.cos(sig), rho * (1 - np.cos(phi)) * np.sin(sig), rho * np.sin(phi)]
    ), rot


_GL = np.polynomial.legendre.leggauss(8)


def _arc_points(L, b, s):
    """Positions (len(s), 3) at arc lengths ``s`` of a segment (the weight's quadrature points)."""
    phi = np.hypot(*b) * s / L
    if np.hypot(*b) < 1e-9:
        return np.stack([0 * s, 0 * s, s], axis=1)
    sig = np.arctan2(b[1], b[0])
    rho = s / phi
    return np.stack(
        [rho * (1 - np.cos(phi)) * np.cos(sig), rho * (1 - np.cos(phi)) * np.sin(sig), rho * np.sin(phi)], axis=1
    )


class _Robot:
    """The simulated robot's physical numbers, per segment and per wire."""

    def __init__(self, truth: RobotTruth):
        segs = truth.design["segments"]
        self.S = len(segs)
        self.n = [s["n_wires"] for s in segs]
        self.N = sum(self.n)
        self.owner = np.repeat(np.arange(self.S), self.n)
        per = lambda v, d: np.full(self.N if d == "w" else self.S, 0.0) if len(v) == 0 else np.asarray(v, float)
        L_seg = np.array([s["length_mm"] for s in segs]) + per(truth.d_length, "s")
        r_seg = np.array([s["pitch_radius_mm"] for s in segs])
        alpha = np.radians(np.concatenate([s["wire_angles_deg"] for s in segs]))
        self.alpha = (
            alpha
            + np.radians(np.asarray(truth.pattern_rotation_deg))[self.owner]
            + np.radians(per(truth.angle_offsets_deg, "w"))
        )
        radius = r_seg[self.owner][:, None] + per(truth.d_radius, "s")[None, :]  # (N, S): wire k in segment j
        EI = np.array([s["backbone_EI_Nmm2"] for s in segs]) * np.asarray(truth.EI_factors, float)
        k0 = np.array([s["wire_stiffness_N_per_mm"] for s in segs])[self.owner]
        self.k = k0 * (per(truth.stiffness_factors, "w") if len(truth.stiffness_factors) else 1.0)
        self.pre = np.array([s["preload_N"] for s in segs])[self.owner] + per(truth.d_preload, "w")
        self.f = np.asarray(truth.tip_force, float)
        self.g = np.asarray(truth.gravity, float)
        self.mu = np.asarray(truth.friction, float)
        # the chain is made of pieces (m per segment, each of constant curvature; m = 1: the segments)
        m = int(truth.pieces)
        self.S = self.S * m  # from here on: pieces
        self.L = np.repeat(L_seg / m, m)
        self.EI = np.repeat(EI, m)
        self.radius = np.repeat(radius, m, axis=1)
        self.crossed = (self.owner + 1) * m  # pieces each wire runs through
        twist = np.radians(np.asarray(truth.twist_deg, float)) if len(truth.twist_deg) else np.zeros(len(segs) - 1)
        # wire length changes are linear in the bending vectors: dl = A x (own assembly of the rows)
        self.A = np.zeros((self.N, 2 * self.S))
        for k in range(self.N):
            for j in range(self.crossed[k]):
                a = self.alpha[k] + twist[j // m : self.owner[k]].sum()  # turned by the disks' twists on the way
                self.A[k, 2 * j : 2 * j + 2] = -self.radius[k, j] * np.array([np.cos(a), np.sin(a)])
        self.loaded = bool(np.any(self.f) or np.any(self.g))
        # hole clearance: wire k's path shortened by C[k, j] |x_j| in every piece j it crosses
        cl = np.asarray(truth.clearance, float)
        self.C = np.zeros((self.N, self.S))
        for k in range(self.N):
            for j in range(self.crossed[k]):
                self.C[k, j] = cl[0] if j // m == self.owner[k] else cl[1]
        # the backbone's compression: piece j shortens by a_j times the tension of the wires through it
        self.a = np.repeat(np.asarray(truth.compression, float) / m, m) if len(truth.compression) else np.zeros(self.S)
        self.X = np.zeros((self.N, self.S))
        for k in range(self.N):
            self.X[k, : self.crossed[k]] = 1.0

    def compression(self, s0, k=None):
        """The pieces' shortening ``e`` (S,) for the rigid backbone's stretch ``s0``: the minimum over
        ``e`` of ``sum_k k_k max(s0 - X e, 0)^2 / 2 + sum_j e_j^2 / (2 a_j)``, by active sets in ``e``
        (the set of taut wires, iterated until it stays); ``k`` the wires' stiffness (default their own)."""
        k = self.k if k is None else k
        live = self.a > 0
        e = np.zeros(self.S)
        if not live.any():
            return e
        taut = s0 > 0
        for _ in range(50):
            Xl = self.X[:, live]
            W = k * taut
            M = np.diag(1.0 / self.a[live]) + Xl.T @ (W[:, None] * Xl)
            e[live] = np.linalg.solve(M, Xl.T @ (W * s0))
            new = s0 - self.X @ e > 0
            if np.array_equal(new, taut):
                break
            taut = new
        return e

    def stretch(self, x, q, short=None, k=None):
        """Each wire's stretch (N,): the routing's length change, less the clearance's shortening
        (``short``, frozen, or else at ``x``) and the backbone's compression under wires of stiffness
        ``k`` (default their own)."""
        if short is None:
            short = self.C @ np.hypot(*x.reshape(self.S, 2).T)
        s0 = self.A @ x - q + self.pre / self.k - short
        return s0 - self.X @ self.compression(s0, k)

    def chain(self, B, lengths=None):
        """Disk poses along the chain (lists of S + 1) and the weight's quadrature points; ``lengths``
        (S,): the pieces' (compressed) lengths, default their own."""
        p, R = np.zeros(3), np.eye(3)
        ps, Rs, pts, wts = [p], [R], [], []
        L = self.L if lengths is None else lengths
        for j in range(self.S):
            s = 0.5 * L[j] * (_GL[0] + 1.0)
            pts.append(p + _arc_points(L[j], B[j], s) @ R.T)
            wts.append(0.5 * L[j] * _GL[1])
            pj, Rj = _arc(L[j], B[j], L[j])
            p, R = p + R @ pj, R @ Rj
            ps.append(p)
            Rs.append(R)
        return ps, Rs, np.concatenate(pts), np.concatenate(wts)

    def load(self, X):
        """The load's potential for a batch of configurations ``X`` (K, 2S), vectorised over K and the
        pieces (the load's gradient is taken by central differences of it); the chain's composition
        piece by piece."""
        K = X.shape[0]
        B = X.reshape(K, self.S, 2)
        u, v = B[..., 0], B[..., 1]  # (K, S)
        phi, sig = np.hypot(u, v), np.arctan2(v, u)
        L = np.asarray(self.L, float)
        s = np.concatenate([0.5 * L[:, None] * (_GL[0] + 1.0), L[:, None]], axis=1)  # (S, 9): quadrature, end disk
        ph = phi[:, :, None] * s / L[:, None]  # (K, S, 9)
        small = ph < 1e-6
        safe = np.where(small, 1.0, ph)
        lat = np.where(small, s * ph / 2, s * (1 - np.cos(ph)) / safe)  # rho (1 - cos)
        ax = np.where(small, s * np.ones_like(ph), s * np.sin(ph) / safe)
        local = np.stack([lat * np.cos(sig)[..., None], lat * np.sin(sig)[..., None], ax], axis=-1)  # (K, S, 9, 3)
        # each piece's rotation, Rodrigues about the unit axis (kx, ky, 0): I + sin K + (1 - cos) K^2
        bent = phi > 1e-12
        kx = np.where(bent, -v / np.where(bent, phi, 1.0), 0.0)
        ky = np.where(bent, u / np.where(bent, phi, 1.0), 0.0)
        Kx = np.zeros((K, self.S, 3, 3))
        Kx[..., 0, 2], Kx[..., 1, 2], Kx[..., 2, 0], Kx[..., 2, 1] = ky, -kx, -ky, kx
        Rj = np.eye(3) + np.sin(phi)[..., None, None] * Kx + (1 - np.cos(phi))[..., None, None] * (Kx @ Kx)
        w = 0.5 * L[:, None] * _GL[1]  # (S, 8) the weight's quadrature weights
        p, R, M = np.zeros((K, 3)), np.tile(np.eye(3), (K, 1, 1)), np.zeros((K, 3))
        for j in range(self.S):
            world = p[:, None, :] + local[:, j] @ R.transpose(0, 2, 1)
            M += w[j] @ world[:, :-1]
            p, R = world[:, -1], R @ Rj[:, j]
        return -(p @ self.f) - (M @ self.g)

    def energy(self, x, q, t, short=0.0):
        """``V`` and its gradient with the clearance's shortening ``short`` frozen and the wires at
        stiffness ``t k`` (in the backbone's compression too; the wires' moment arms are the routing's
        ``A`` either way)."""
        kt = t * self.k
        s = self.stretch(x, q, short, kt)
        E = np.repeat(self.EI / self.L, 2)
        tau = kt * np.maximum(s, 0.0)
        e = self.a * (self.X.T @ tau)  # the backbone's shortening stores e^2 / (2 a)
        V = 0.5 * np.sum(E * x * x) + 0.5 * np.sum(kt * np.maximum(s, 0.0) ** 2) + 0.5 * np.sum(e * (self.X.T @ tau))
        g = E * x + self.A.T @ tau
        if self.loaded:
            h, n = 1e-6, len(x)
            vals = self.load(np.concatenate([x[None], x + h * np.eye(n), x - h * np.eye(n)]))
            V += vals[0]
            g = g + (vals[1 : n + 1] - vals[n + 1 :]) / (2 * h)
        return V, g

    def factors(self, x, direction):
        """Each wire's tension factor in every piece it crosses (N, S), the capstan's ``exp(d (mu_0 +
        mu_1 w))`` with ``w`` the bending wrapped before the piece's middle (an explicit loop). 1 where
        the wire does not run."""
        wrap = np.hypot(*x.reshape(self.S, 2).T)
        T = np.ones((self.N, self.S))
        for k in range(self.N):
            for j in range(self.crossed[k]):
                T[k, j] = np.exp(direction[k] * (self.mu[0] + self.mu[1] * (wrap[:j].sum() + 0.5 * wrap[j])))
        return T

    def force(self, x, q, direction):
        """The generalised force with friction (2S,): each wire's tension times its factor in every
        piece it crosses."""
        short = self.C @ np.hypot(*x.reshape(self.S, 2).T)
        _, g = self.energy(x, q, np.ones(self.N), short)  # backbone, load, and the wires at factor 1
        tau = self.k * np.maximum(self.stretch(x, q, short), 0.0)
        T = self.factors(x, direction)
        return g + (self.A * np.repeat(T - 1.0, 2, axis=1)).T @ tau

    def equilibrium(self, q, direction, x0):
        """Friction and the clearance are not conservative: the root of the force, found by MINPACK's
        hybrid method from the first minimum, or else by a fixed point of BFGS minimisations of the
        energy with each wire's mean tension factor, the clearance's shortening and, as a constant
        force, the rest of the friction force, all updated from the solution until the force itself
        vanishes."""
        t, rest, x = np.ones(self.N), np.zeros(2 * self.S), x0
        nonconservative = bool(np.any(self.mu) and np.any(direction)) or bool(np.any(self.C))
        for it in range(100):
            # gtol 1e-6: the tip within 1e-6 mm of a 1e-10 solve (checked), at half the cost (1e-8 with
            # friction, whose fixed point needs the force to 1e-7); started from the elastic part's
            # inverse Hessian (backbone and taut wires): BFGS then needs only the load's curvature
            short = self.C @ np.hypot(*x.reshape(self.S, 2).T)
            s = self.stretch(x, q, short)
            H = np.diag(np.repeat(self.EI / self.L, 2)) + self.A.T @ ((t * self.k * (s > 0))[:, None] * self.A)
            Hi = np.linalg.inv(H)

            def fun(y, t=t, rest=rest, short=short):
                V, g = self.energy(y, q, t, short)
                return V + rest @ y, g + rest

            x = minimize(
                fun,
                x,
                jac=True,
                method="BFGS",
                options={"gtol": 1e-8 if nonconservative else 1e-6, "hess_inv0": 0.5 * (Hi + Hi.T)},
            ).x
            if not nonconservative:
                break
            if it == 0:
                # MINPACK's hybrid method on the force itself, from the first solve: a handful of force
                # evaluations where the fixed point below takes dozens of BFGS solves; the fixed point
                # goes on where it does not converge (a wire going slack on the way, say)
                sol = root(self.force, x, args=(q, direction), method="hybr", options={"xtol": 1e-13})
                if np.max(np.abs(self.force(sol.x, q, direction))) < 1e-9:
                    return sol.x
            T = self.factors(x, direction)
            t = np.array([T[k, : self.crossed[k]].mean() for k in range(self.N)])
            # the rest of the force beyond that energy's gradient, frozen (sum_k tau_k (T_k - t_k) a_k
            # for a rigid backbone)
            rest = self.force(x, q, direction) - self.energy(x, q, t, self.C @ np.hypot(*x.reshape(self.S, 2).T))[1]
            if np.max(np.abs(self.force(x, q, direction))) < 1e-7:
                break
        return x


def robot_patterns(design: dict, rng, val: bool = False, servos=None, steps: int = 10):
    """(label, Q block) pairs, tension_zones/MODEL.md sign (negative = pulled in), commands from the *declared*
    kinematics: training = single-wire pulls (the others paid out) and each segment bent out and
    back in six directions, each ending in a hold (repeated commands); validation = every segment
    bent together, each in its own direction."""
    from tension_zones.model import Robot

    robot = Robot.from_dict(design)
    Jq = np.asarray(robot.J_qB())
    S, N = robot.n_segments, robot.n_wires
    t = np.r_[np.linspace(0.0, 1.0, steps), np.linspace(1.0, 0.0, steps)[1:]][:, None]
    out = []
    if not val:
        for k in range(N):
            q = np.full((len(t), N), 0.8)
            q[:, k] = -2.0 * t[:, 0]
            out.append((f"rep1_tendon{k}_id{servos[k]}_pull", np.r_[q, q[-1:].repeat(3, 0)]))
    for d in range(0, 360, 60):
        for j in [None] if val else range(S):
            B = np.zeros((len(t), S, 2))
            for jj in range(S) if j is None else [j]:
                a = np.radians(d + 100 * jj)
                B[:, jj] = 0.45 * t * np.array([np.cos(a), np.sin(a)])
            q = B.reshape(len(t), -1) @ Jq.T + 0.05 * rng.normal(size=(len(t), N))
            out.append((f"rep1_{'all' if val else f'seg{j}'}_dir{d}", np.r_[q, q[-1:].repeat(3, 0)]))
    return out


def _stick(rob, x, q, direction, prev, h):
    """The bending friction's step: the previous bending ``prev`` kept, piece by piece, unless the
    elastic moment pulling it back to the equilibrium ``x`` (the backbone's and the taut wires'
    stiffness there, each wire at its mean friction factor, times their difference) exceeds ``h``;
    then the bending where that moment is ``h``."""
    taut = rob.stretch(x, q) > 1e-9  # the solve's round-off: a wire at its slack length is slack
    T = rob.factors(x, direction)
    t = np.array([T[k, : rob.crossed[k]].mean() for k in range(rob.N)])
    K = np.diag(np.repeat(rob.EI / rob.L, 2)) + rob.A.T @ ((t * rob.k * taut)[:, None] * rob.A)
    mom = (K @ (prev - x)).reshape(-1, 2)
    size = np.linalg.norm(mom, axis=1)
    if np.all(size <= h):
        return prev
    mom = mom * np.where(size > h, h / np.where(size > h, size, 1.0), 1.0)[:, None]
    return x + np.linalg.solve(K, mom.reshape(-1))


def simulate_robot(truth: RobotTruth, patterns, seed: int = 0, hours=None):
    """Measured tip positions (T, 3) in the tracker frame for the patterns' commands, in order;
    ``hours`` (T,): each sample's time on the wires' drift clock (default 0)."""
    rng = np.random.default_rng(seed)
    rob = _Robot(truth)
    Q = np.concatenate([q for _, q in patterns])
    play = np.zeros(rob.N) if len(truth.play) == 0 else np.asarray(truth.play, float)
    R_reg = Rotation.from_rotvec(np.radians(truth.registration_deg))
    q_eff, last_dir, x = Q[0].copy(), np.zeros(rob.N), np.zeros(2 * rob.S)
    xb = x  # the bending with the bending's friction (its memory)
    friction_h = (
        np.repeat(np.asarray(truth.bending_friction, float), truth.pieces)
        if len(truth.bending_friction)
        else np.zeros(rob.S)
    )
    P = np.empty((len(Q), 3))
    for i in range(len(Q)):
        if i > 0:
            dq = Q[i] - Q[i - 1]
            last_dir = np.where(dq > 0, 1.0, np.where(dq < 0, -1.0, last_dir))
        for k in range(rob.N):  # play
            if Q[i, k] > q_eff[k] + play[k] / 2:
                q_eff[k] = Q[i, k] - play[k] / 2
            elif Q[i, k] < q_eff[k] - play[k] / 2:
                q_eff[k] = Q[i, k] + play[k] / 2
        q_now = q_eff + truth.wire_drift * (0.0 if hours is None else hours[i])
        x = rob.equilibrium(q_now, last_dir, x)
        xb = x if i == 0 or not np.any(friction_h) else _stick(rob, x, q_now, last_dir, xb, friction_h)
        e = rob.a * (rob.X.T @ (rob.k * np.maximum(rob.stretch(xb, q_now), 0.0)))  # the backbone's shortening
        ps, Rs, _, _ = rob.chain(xb.reshape(rob.S, 2), rob.L - e)
        P[i] = R_reg.apply(ps[-1] + Rs[-1] @ np.asarray(truth.marker, float)) + np.asarray(truth.translation)
    s = np.arange(len(Q)) / len(Q)
    P[:, 0] += truth.drift_mm * np.sin(2 * np.pi * 1.5 * s)
    P[:, 2] += truth.drift_mm * np.cos(2 * np.pi * 1.5 * s)
    return P + rng.normal(0.0, truth.noise, P.shape)


def write_robot_set(folder, name: str, truth: RobotTruth, seed: int = 0, val: bool = True, steps: int = 10):
    """``NAME_train.csv`` (and ``NAME_val.csv``) in the OpenCR format, servo columns in id order
    with servo ids shuffled against the tendons, and ``NAME.design.json`` (the declared design);
    ``steps``: samples per half pattern (out, back).
    Returns the paths ``(train, val or None, design)``."""
    folder = Path(folder)
    rng = np.random.default_rng(seed)
    N = sum(s["n_wires"] for s in truth.design["segments"])
    servos = [int(s) for s in rng.permutation(N) + 1]  # servo driving each tendon

    def write(path, pats, t0):
        Q = np.concatenate([q for _, q in pats])
        times = t0 + 0.5 * np.arange(len(Q))  # s; the drift's clock starts with the training file
        P = simulate_robot(truth, pats, seed=int(rng.integers(1 << 30)), hours=(times - 100.0) / 3600.0)
        labels = [lab for lab, q in pats for _ in range(len(q))]
        order = sorted(servos)
        lines = ["timestamp,pattern_label," + ",".join(f"servo_{s}_mm" for s in order) + ",tip_x,tip_y,tip_z"]
        for i, (lab, q, p) in enumerate(zip(labels, Q, P)):
            vals = [-q[servos.index(s)] for s in order] + list(p)  # the lab's sign: positive = pulled in
            lines.append(f"{times[i]:.2f},{lab}," + ",".join(f"{v:.6f}" for v in vals))
        path.write_text("\n".join(lines) + "\n")
        return path

    train = write(folder / f"{name}_train.csv", robot_patterns(truth.design, rng, servos=servos, steps=steps), 100.0)
    v = (
        write(folder / f"{name}_val.csv", robot_patterns(truth.design, rng, val=True, steps=steps), 5000.0)
        if val
        else None
    )
    design = folder / f"{name}.design.json"
    design.write_text(json.dumps(truth.design))
    return train, v, design
