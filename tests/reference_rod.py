"""Independent reference solver: the static Kirchhoff rod of a tendon-driven continuum robot.

Test code only: plain NumPy/SciPy, its own code path, no import of ``tension_zones``. It is the
yardstick for the package's rod model (see ``tests/test_reference_rod.py`` for its own checks).

Model (Rucker & Webster, "Statics and Dynamics of Continuum Robots With General Tendon Routing and
External Loading", IEEE T-RO 27(6), 2011, specialised):

* **Kirchhoff rod**: inextensible and unshearable (``v = e3`` in the body frame), straight in its
  reference state (``u* = 0``), linear elastic ``m_b = R K u`` with ``K = diag(EI, EI, GJ)``.
  The backbone's axial compression and shear are therefore not modelled (no axial strain).
* **Tendons** are routed *straight*: tendon ``k`` sits at the constant body-frame offset
  ``r_k = rho_k (cos alpha_k, sin alpha_k, 0)`` from the backbone in every segment it crosses and
  ends at the end disk of its own segment (segment ``j``'s tendons run through segments ``0..j``).
  Frictionless routing, so the tension ``tau_k`` is constant along the tendon.
* **Loads**: a distributed force per length ``f_j`` (N/mm, base frame, e.g. self-weight) on each
  segment; point forces / moments (base frame) at each segment's end disk, the last one being the
  tip load.

Formulation. Instead of the backbone's own internal loads (which jump at every termination disk and
carry Rucker & Webster's distributed tendon loads), the state carries the *resultant of the external
loads distal to the cut*,

    N(s) = int_s^L f ds' + sum_{disks beyond s} F_d,
    M(s) = int_s^L (p(s') - p(s)) x f ds' + sum_{disks beyond s} [(p_d - p(s)) x F_d + M_d],

i.e. the force and moment that the proximal material (backbone *and* the tendons crossing the cut)
exerts on the distal part. Tendon-disk contact forces and tendon termination forces are internal to
that free body, so ``N' = -f``, ``M' = -p' x N`` (no distributed moment), ``N(L) = F_tip``,
``M(L) = M_tip``, and at an intermediate disk ``N``, ``M`` jump by that disk's external load only.
Cutting a tendon at ``s`` exposes its tension ``tau_k t_k`` (``t_k`` its unit tangent) acting at
``p + R r_k``, so the backbone carries

    m_b = M - sum_{k crossing s} tau_k (R r_k) x t_k,      n_b = N - sum_k tau_k t_k,

and the constitutive law ``R K u = m_b`` gives the curvature ``u``. Two tendon models:

* ``tendons="full"`` (default, Rucker & Webster): ``t_k = R (e3 + u x r_k) / |e3 + u x r_k|``, the
  true tangent of the routed tendon. Bending alone leaves ``t_k = R e3`` exactly; twist ``u_z`` tilts
  it, which adds the tendon torsional stiffness ``sum tau_k rho_k^2`` (``u`` is then found by a
  pointwise Newton solve).
* ``tendons="point"``: ``t_k = R e3`` (the tendon stays parallel to the backbone), i.e. each tendon
  acts as a body-frame moment ``tau_k r_k x (-e3)`` plus an axial compression. Identical to "full"
  when the rod does not twist (all planar cases).

For tendon tensions alone, the body moment ``sum tau_k r_k x (-e3)`` is constant in each segment, so
each segment is a constant-curvature arc with curvature vector (toward the pulled tendons)
``kappa (cos sigma, sin sigma) = sum_k tau_k rho_k (cos alpha_k, sin alpha_k) / EI``.

The boundary-value problem is solved with ``scipy.integrate.solve_bvp``; the segments are stacked as
separate state blocks on a common normalised abscissa ``x in [0, 1]`` (``s = s_j + x L_j``), joined
by continuity conditions, so the discontinuous curvature at the disks sits exactly at block ends.
State per segment: ``p`` (3), ``R`` (9, row-major), ``N`` (3), ``M`` (3). Boundary conditions
``p(0) = 0``, ``R(0) = I``, continuity of ``p, R`` and the load jumps at the disks,
``N(L) = F_tip``, ``M(L) = M_tip``. Start: the tendon-only (piecewise constant-curvature) shape with
its load resultants; coarse solves under load continuation, then refinement to ``tol``.

API: :func:`solve_segment` (one segment), :func:`solve_rod` (segments in series, :class:`Segment`)
-> :class:`RodSolution` (backbone curve, frames, loads, curvature, ``tip_position``,
``tip_rotation``, ``residuals()``); :func:`constant_curvature_tip` (tension_zones/MODEL.md Sec. 1 closed form)
and :func:`planar_shooting` (a second code path, planar elastica by shooting) for the tests.

Units: mm, N, N/mm, N mm, N mm^2, rad.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.integrate import solve_bvp, solve_ivp

NY = 18  # states per segment
E3 = np.array([0.0, 0.0, 1.0])


@dataclasses.dataclass(frozen=True)
class Segment:
    """One segment: ``length`` (mm), ``EI`` (N mm^2), ``GJ`` (N mm^2, default ``EI / (1 + nu)``
    with ``nu = 0.3``, a solid round rod), and its tendons: ``angles`` (rad, about the body z axis
    from the body x axis), ``radius`` (mm, scalar or one per tendon), ``tensions`` (N, >= 0)."""

    length: float
    EI: float
    angles: tuple = ()
    radius: float | tuple = 0.0
    tensions: tuple = ()
    GJ: float | None = None

    def offsets(self) -> np.ndarray:
        """Body-frame tendon offsets (n, 3)."""
        a = np.asarray(self.angles, float).reshape(-1)
        rho = np.broadcast_to(np.asarray(self.radius, float), a.shape)
        return np.stack([rho * np.cos(a), rho * np.sin(a), np.zeros_like(a)], axis=1)

    def tension_array(self) -> np.ndarray:
        t = np.asarray(self.tensions, float).reshape(-1)
        if t.shape != np.asarray(self.angles, float).reshape(-1).shape:
            raise ValueError("one tension per tendon angle")
        return t

    def stiffness(self) -> np.ndarray:
        gj = self.EI / 1.3 if self.GJ is None else self.GJ
        return np.array([self.EI, self.EI, gj], float)


@dataclasses.dataclass
class RodSolution:
    """A solved rod. Arrays along the backbone are sampled on ``s`` (mm from the base, the disks
    appear twice: once at the end of a segment and once at the start of the next).

    ``p`` (m, 3) backbone points, ``R`` (m, 3, 3) body frames (columns: body axes in the base
    frame), ``N`` / ``M`` (m, 3) resultant external force / moment distal to the cut (base frame,
    see the module docstring), ``u`` (m, 3) body-frame curvature, ``m_backbone`` / ``n_backbone``
    (m, 3) the backbone's own internal moment / force (base frame)."""

    s: np.ndarray
    p: np.ndarray
    R: np.ndarray
    N: np.ndarray
    M: np.ndarray
    u: np.ndarray
    m_backbone: np.ndarray
    n_backbone: np.ndarray
    segment_ends: np.ndarray
    bvp: object
    problem: _Problem

    @property
    def tip_position(self) -> np.ndarray:
        return self.p[-1]

    @property
    def tip_rotation(self) -> np.ndarray:
        return self.R[-1]

    def at(self, s) -> dict:
        """Interpolated state (solve_bvp's C1 cubic interpolant) at arc lengths ``s`` (mm); at a
        disk the distal segment's value is returned."""
        s = np.atleast_1d(np.asarray(s, float))
        return self.problem.unpack_at(self.bvp.sol, s)

    def residuals(self, n_per_segment: int = 400) -> dict:
        """Equilibrium checks of the solution.

        ``ode``: max over a dense grid of ``|y'(x) - f(x, y)| / (1 + |f|)`` from the interpolant
        (the quantity solve_bvp controls at interval midpoints, here everywhere);
        ``bc``: max boundary/continuity residual; ``orthogonality``: max ``|R^T R - I|``;
        ``constitutive``: max ``|R K u - m_b|`` (N mm)."""
        pr = self.problem
        x = np.linspace(0.0, 1.0, n_per_segment)
        y = self.bvp.sol(x)
        dy = self.bvp.sol(x, 1)
        f = pr.rhs(x, y)
        ode = np.max(np.abs(dy - f) / (1.0 + np.abs(f)))
        bc = np.max(np.abs(pr.bc(self.bvp.y[:, 0], self.bvp.y[:, -1])))
        Rt = np.einsum("mji,mjk->mik", self.R, self.R)
        ortho = np.max(np.abs(Rt - np.eye(3)))
        K = np.concatenate([np.tile(seg.stiffness(), (n, 1)) for seg, n in zip(pr.segments, pr.counts)])
        cons = np.max(np.abs(np.einsum("mij,mj->mi", self.R, K * self.u) - self.m_backbone))
        return {"ode": float(ode), "bc": float(bc), "orthogonality": float(ortho), "constitutive": float(cons)}


class _Problem:
    """The stacked BVP."""

    def __init__(self, segments, weight, disk_forces, disk_moments, tendons):
        if tendons not in ("full", "point"):
            raise ValueError("tendons must be 'full' or 'point'")
        self.segments = list(segments)
        S = len(self.segments)
        if S == 0:
            raise ValueError("at least one segment")
        self.S = S
        self.tendons = tendons
        self.L = np.array([seg.length for seg in self.segments], float)
        self.s0 = np.concatenate([[0.0], np.cumsum(self.L)[:-1]])
        w = np.asarray(weight, float)
        self.f = np.broadcast_to(w, (S, 3)).copy()
        self.Fd = np.asarray(disk_forces, float).reshape(S, 3)
        self.Md = np.asarray(disk_moments, float).reshape(S, 3)
        self.K = np.stack([seg.stiffness() for seg in self.segments])
        # tendons crossing segment j: those of segments j..S-1
        self.cross_r = []
        self.cross_tau = []
        for j in range(S):
            rs = [self.segments[i].offsets() for i in range(j, S)]
            ts = [self.segments[i].tension_array() for i in range(j, S)]
            self.cross_r.append(np.concatenate(rs) if rs else np.zeros((0, 3)))
            self.cross_tau.append(np.concatenate(ts) if ts else np.zeros(0))
        # every other block runs distal-to-proximal, so that each joint's continuity conditions
        # sit at one end of the abscissa (separated boundary conditions: no fill-in in the
        # collocation system's sparse LU)
        self.dirs = np.array([1 if j % 2 == 0 else -1 for j in range(S)])
        self.counts = None

    def block_x(self, j, xloc):
        """Abscissa of block j for the local coordinate xloc = (s - s_j) / L_j."""
        return xloc if self.dirs[j] > 0 else 1.0 - xloc

    def ends(self, j, ya, yb):
        """(proximal, distal) end states of block j as (18, 1) columns."""
        a, b = ya[NY * j : NY * (j + 1), None], yb[NY * j : NY * (j + 1), None]
        return (a, b) if self.dirs[j] > 0 else (b, a)

    # -- pieces ------------------------------------------------------------------------------
    @staticmethod
    def split(yj):
        p = yj[0:3]
        R = yj[3:12].reshape(3, 3, -1)  # R[i, k, m]
        N = yj[12:15]
        M = yj[15:18]
        return p, R, N, M

    def curvature(self, j, R, M):
        """Body curvature u (3, m) of segment j from the frame R (3, 3, m) and the moment M (3, m)."""
        K = self.K[j]
        c = np.einsum("ikm,im->km", R, M)  # R^T M, body frame
        r = self.cross_r[j]
        tau = self.cross_tau[j]
        # point model: sum tau r x e3, constant
        rxe3 = np.cross(r, E3) if len(r) else np.zeros((0, 3))
        t0 = (tau[:, None] * rxe3).sum(axis=0) if len(r) else np.zeros(3)
        u = (c - t0[:, None]) / K[:, None]
        if self.tendons == "point" or len(r) == 0 or not np.any(tau):
            return u
        # full model: K u + sum_k tau_k r_k x a_k/|a_k| = c with a_k = e3 + u x r_k
        #   = (-u_z r_ky, u_z r_kx, beta_k), beta_k = 1 + u_x r_ky - u_y r_kx, so
        #   r_k x a_k/|a_k| = (r_ky w_k, -r_kx w_k, rho_k^2 u_z / |a_k|), w_k = beta_k / |a_k|.
        # w_k = 1 - O(u_z^2 rho^2) and 1/|a_k| = 1 - O(u rho): a fixed-point iteration on them
        # contracts by ~ tau rho^3 |u| / GJ << 1 (a few iterations to round-off).
        rx, ry = r[:, 0, None], r[:, 1, None]
        rho2 = rx**2 + ry**2
        tau = tau[:, None]
        for _ in range(50):
            beta = 1.0 + u[0] * ry - u[1] * rx
            na = np.sqrt(beta**2 + rho2 * u[2] ** 2)
            w = beta / na
            un = np.stack(
                [
                    (c[0] - (tau * ry * w).sum(0)) / K[0],
                    (c[1] + (tau * rx * w).sum(0)) / K[1],
                    c[2] / (K[2] + (tau * rho2 / na).sum(0)),
                ]
            )
            du = np.max(np.abs(un - u))
            u = un
            if du < 1e-14 * (1e-3 + np.max(np.abs(u))):
                break
        return u

    def tendon_tangents(self, j, R, u):
        """Unit tendon tangents (n, 3, m) in the base frame, and the body offsets (n, 3)."""
        r = self.cross_r[j]
        if self.tendons == "point":
            a = np.broadcast_to(E3[None, :, None], (len(r), 3, u.shape[1]))
        else:
            a = E3[None, :, None] + np.cross(u.T[None, :, :], r[:, None, :], axis=-1).transpose(0, 2, 1)
            a = a / np.linalg.norm(a, axis=1, keepdims=True)
        return np.einsum("ikm,nkm->nim", R, a), r

    # -- BVP ---------------------------------------------------------------------------------
    def rhs(self, x, y):
        out = np.empty_like(y)
        for j in range(self.S):
            yj = y[NY * j : NY * (j + 1)]
            _, R, N, M = self.split(yj)
            u = self.curvature(j, R, M)
            L = self.L[j] * self.dirs[j]
            t = R[:, 2, :]  # R e3
            dR = _R_uhat(R, u)
            o = out[NY * j : NY * (j + 1)]
            o[0:3] = L * t
            o[3:12] = L * dR.reshape(9, -1)
            o[12:15] = -L * self.f[j][:, None]
            o[15:18] = -L * np.cross(t.T, N.T).T
        return out

    def bc(self, ya, yb):
        res = []
        p0, R0, _, _ = self.split(self.ends(0, ya, yb)[0])
        res += [p0[:, 0], (R0[:, :, 0] - np.eye(3)).ravel()]
        for j in range(self.S - 1):
            # end of j == start of j+1, except the external load applied at disk j
            pa, Ra, Na, Ma = self.split(self.ends(j, ya, yb)[1])
            pb, Rb, Nb, Mb = self.split(self.ends(j + 1, ya, yb)[0])
            res += [
                pa[:, 0] - pb[:, 0],
                (Ra - Rb)[:, :, 0].ravel(),
                Na[:, 0] - (Nb[:, 0] + self.Fd[j]),
                Ma[:, 0] - (Mb[:, 0] + self.Md[j]),
            ]
        _, _, NL, ML = self.split(self.ends(self.S - 1, ya, yb)[1])
        res += [NL[:, 0] - self.Fd[-1], ML[:, 0] - self.Md[-1]]
        return np.concatenate(res)

    # -- initial guess -----------------------------------------------------------------------
    def initial_guess(self, x):
        """Tendon-only shape (piecewise constant curvature, integrated as an IVP), with N and M the
        external-load resultants evaluated on that shape."""
        y = np.zeros((NY * self.S, len(x)))
        p_start, R_start = np.zeros(3), np.eye(3)
        shapes = []
        for j in range(self.S):
            r, tau = self.cross_r[j], self.cross_tau[j]
            mom = (tau[:, None] * np.cross(r, -E3)).sum(axis=0) if len(r) else np.zeros(3)
            u = mom / self.K[j]
            L = self.L[j]
            # closed form of the arc: R(x) = R0 exp(x L uhat), p = p0 + R0 int_0^{xL} exp(s uhat) e3
            Rs, ps = [], []
            for xi in x:
                E, G = _exp_so3_and_left(u * L * xi)
                Rs.append(R_start @ E)
                ps.append(p_start + L * xi * R_start @ (G @ E3))
            Rs, ps = np.array(Rs), np.array(ps)
            shapes.append((ps, Rs))
            p_start, R_start = ps[-1], Rs[-1]
        # resultants by quadrature from the tip
        N_next, M_next, p_next = np.zeros(3), np.zeros(3), shapes[-1][0][-1]
        for j in reversed(range(self.S)):
            ps, Rs = shapes[j]
            L = self.L[j]
            pe = ps[-1]
            # carry the distal resultant to this segment's end point, add the disk load
            N_end = N_next + self.Fd[j]
            M_end = M_next + np.cross(p_next - pe, N_next) + self.Md[j]
            Ns = N_end[None, :] + self.f[j][None, :] * L * (1 - x)[:, None]
            # moment of the distributed load distal within the segment about p(x):
            # int (p(x') - p(x)) x f dx' L = (P1(x) - p(x)(1 - x) L) x f, P1 = int_x^1 p dx' L
            cum = _cumtrapz_rev(ps, x) * L
            Md = np.cross(cum - ps * ((1 - x) * L)[:, None], self.f[j][None, :])
            Ms = M_end[None, :] + np.cross(pe[None, :] - ps, N_end[None, :]) + Md
            yj = y[NY * j : NY * (j + 1)]
            yj[0:3] = ps.T
            yj[3:12] = Rs.reshape(len(x), 9).T
            yj[12:15] = Ns.T
            yj[15:18] = Ms.T
            if self.dirs[j] < 0:  # x is symmetric: the value at 1 - x_i is the mirrored column
                yj[:] = yj[:, ::-1]
            N_next, M_next, p_next = Ns[0], Ms[0], ps[0]
        return y

    def unpack_at(self, sol, s):
        """Evaluate the interpolant at arc lengths s (distal segment at a disk)."""
        ends = np.cumsum(self.L)
        j = np.clip(np.searchsorted(ends, s, side="right"), 0, self.S - 1)
        x = np.array([self.block_x(jj, xl) for jj, xl in zip(j, (s - self.s0[j]) / self.L[j])])
        Y = sol(np.clip(x, 0, 1))
        rows = np.arange(len(s))
        y = np.stack([Y[NY * jj : NY * (jj + 1), i] for i, jj in zip(rows, j)], axis=1)
        p, R, N, M = self.split(y)
        return {"p": p.T, "R": R.transpose(2, 0, 1), "N": N.T, "M": M.T}


def _hat(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _R_uhat(R, u):
    """R @ hat(u), batched: R (3, 3, m), u (3, m)."""
    z = np.zeros_like(u[0])
    U = np.array([[z, -u[2], u[1]], [u[2], z, -u[0]], [-u[1], u[0], z]])
    return np.einsum("ikm,klm->ilm", R, U)


def _exp_so3_and_left(w):
    """exp(hat(w)) and (1/1) int_0^1 exp(t hat(w)) dt (the SO(3) left Jacobian)."""
    th = np.linalg.norm(w)
    W = _hat(w)
    if th < 1e-8:
        return np.eye(3) + W + W @ W / 2, np.eye(3) + W / 2 + W @ W / 6
    a = np.sin(th) / th
    b = (1 - np.cos(th)) / th**2
    c = (th - np.sin(th)) / th**3
    return np.eye(3) + a * W + b * W @ W, np.eye(3) + b * W + c * W @ W


def _cumtrapz_rev(v, x):
    """int_x^1 v dx' by the trapezoid rule, v (m, 3)."""
    dx = np.diff(x)[:, None]
    seg = 0.5 * (v[1:] + v[:-1]) * dx
    out = np.zeros_like(v)
    out[:-1] = np.cumsum(seg[::-1], axis=0)[::-1]
    return out


def solve_rod(
    segments,
    weight=(0.0, 0.0, 0.0),
    tip_force=(0.0, 0.0, 0.0),
    tip_moment=(0.0, 0.0, 0.0),
    disk_forces=None,
    disk_moments=None,
    tendons: str = "full",
    tol: float = 1e-8,
    n_nodes: int = 41,
    max_nodes: int = 20000,
    n_out: int = 101,
) -> RodSolution:
    """Solve the static rod.

    ``segments``: list of :class:`Segment` (proximal first). ``weight``: distributed force per
    length (N/mm, base frame), one 3-vector for all segments or (S, 3). ``tip_force`` /
    ``tip_moment``: at the robot's tip (base frame). ``disk_forces`` / ``disk_moments``: (S, 3)
    point loads at each segment's end disk (added to the tip load for the last). ``tendons``:
    ``"full"`` or ``"point"`` (module docstring). ``tol``: solve_bvp's relative collocation
    tolerance (the mesh is refined until it is met; in the tests 1e-8 puts the tip within
    1e-9 mm of the exact solution, and each factor 10 tighter costs about twice the time). ``n_out``: output points per segment.

    Raises ``RuntimeError`` if solve_bvp does not converge."""
    segments = list(segments)
    S = len(segments)
    Fd = np.zeros((S, 3)) if disk_forces is None else np.array(disk_forces, float).reshape(S, 3)
    Md = np.zeros((S, 3)) if disk_moments is None else np.array(disk_moments, float).reshape(S, 3)
    Fd[-1] += np.asarray(tip_force, float)
    Md[-1] += np.asarray(tip_moment, float)
    w = np.broadcast_to(np.asarray(weight, float), (S, 3))

    x = np.linspace(0.0, 1.0, n_nodes)
    # coarse solves (tol 1e-3, few nodes) under load continuation: the full load first, else
    # ramped up; then the coarse solution is refined to ``tol`` (solve_bvp only ever adds nodes,
    # so a far-off start must not be iterated at the fine tolerance)
    coarse = None
    for ramp in ([1.0], [0.25, 0.5, 0.75, 1.0], np.linspace(0.1, 1.0, 10)):
        guess = None
        for lam in ramp:
            pr = _Problem(segments, lam * w, lam * Fd, lam * Md, tendons)
            xg, yg = (x, pr.initial_guess(x)) if guess is None else guess
            res = solve_bvp(pr.rhs, pr.bc, xg, yg, tol=max(tol, 1e-3), max_nodes=1000)
            if res.status != 0:
                break
            guess = (res.x, res.y)
        else:
            coarse = guess
            break
    if coarse is None:
        raise RuntimeError(f"solve_bvp did not converge under load continuation: {res.message}")
    res = solve_bvp(pr.rhs, pr.bc, *coarse, tol=tol, bc_tol=tol, max_nodes=max_nodes)
    if res.status != 0:
        raise RuntimeError(f"solve_bvp did not reach tol={tol}: {res.message}")
    pr.counts = [n_out] * S
    return _package(pr, res, n_out)


def _package(pr: _Problem, res, n_out: int) -> RodSolution:
    xo = np.linspace(0.0, 1.0, n_out)
    s_all, p_all, R_all, N_all, M_all, u_all, mb_all, nb_all = ([] for _ in range(8))
    for j in range(pr.S):
        yj = res.sol(pr.block_x(j, xo))[NY * j : NY * (j + 1)]
        p, R, N, M = pr.split(yj)
        u = pr.curvature(j, R, M)
        t, r = pr.tendon_tangents(j, R, u)
        tau = pr.cross_tau[j]
        rw = np.einsum("ikm,nk->nim", R, r)  # R r_k
        mb = M - np.einsum("n,nim->im", tau, np.cross(rw, t, axis=1))
        nb = N - np.einsum("n,nim->im", tau, t)
        s_all.append(pr.s0[j] + xo * pr.L[j])
        p_all.append(p.T)
        R_all.append(R.transpose(2, 0, 1))
        N_all.append(N.T)
        M_all.append(M.T)
        u_all.append(u.T)
        mb_all.append(mb.T)
        nb_all.append(nb.T)
    cat = np.concatenate
    return RodSolution(
        s=cat(s_all),
        p=cat(p_all),
        R=cat(R_all),
        N=cat(N_all),
        M=cat(M_all),
        u=cat(u_all),
        m_backbone=cat(mb_all),
        n_backbone=cat(nb_all),
        segment_ends=np.cumsum(pr.L),
        bvp=res,
        problem=pr,
    )


def solve_segment(
    length,
    EI,
    angles,
    radius,
    tensions,
    weight=(0.0, 0.0, 0.0),
    tip_force=(0.0, 0.0, 0.0),
    GJ=None,
    **kw,
) -> RodSolution:
    """One segment: ``len(angles)`` tendons at ``angles`` (rad) on ``radius`` (mm) with
    ``tensions`` (N); see :func:`solve_rod` for the rest."""
    seg = Segment(float(length), float(EI), tuple(np.atleast_1d(angles)), radius, tuple(np.atleast_1d(tensions)), GJ)
    return solve_rod([seg], weight=weight, tip_force=tip_force, **kw)


# ------------------------------------------------------------------------------------------
# Closed forms and a second, planar code path (for the tests)
# ------------------------------------------------------------------------------------------
def constant_curvature_tip(length, bend, direction):
    """tension_zones/MODEL.md Sec. 1 / 5: tip position and rotation of an arc of bending angle ``bend`` (rad)
    toward base-frame direction ``direction`` (sigma, rad): ``delta = -sigma``,
    ``p = (L/phi) [cos d (1 - cos phi), -sin d (1 - cos phi), sin phi]``,
    ``R = Rz(-d) Ry(phi) Rz(d)``."""
    phi, d = float(bend), -float(direction)
    if abs(phi) < 1e-12:
        p = np.array([0.0, 0.0, length])
    else:
        p = (length / phi) * np.array([np.cos(d) * (1 - np.cos(phi)), -np.sin(d) * (1 - np.cos(phi)), np.sin(phi)])

    def Rz(a):
        return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])

    Ry = np.array([[np.cos(phi), 0, np.sin(phi)], [0, 1.0, 0], [-np.sin(phi), 0, np.cos(phi)]])
    return p, Rz(-d) @ Ry @ Rz(d)


def planar_shooting(lengths, EIs, tendon_moments, weight_xz, tip_force_xz, rtol=1e-12):
    """A second code path for loads in the x-z plane: the planar elastica by shooting.

    Segments in series with lengths ``lengths``, stiffness ``EIs`` and a constant tendon moment
    ``tendon_moments[j]`` (N mm, about the body y axis: positive bends toward +x; the sum of the
    moments of all tendons crossing segment j); ``weight_xz`` (N/mm) and ``tip_force_xz`` (N) in
    the x-z plane. Unknown: the base moment; integrated base-to-tip with ``solve_ivp`` and
    ``brentq`` until the tip moment vanishes. Returns the tip (x, z) and the tip angle (rad, from
    z toward x)."""
    from scipy.optimize import root_scalar

    lengths = np.asarray(lengths, float)
    wx, wz = weight_xz
    Fx, Fz = tip_force_xz
    Ltot = lengths.sum()
    # N(0) = total external force; dN/ds = -w
    N0x, N0z = Fx + wx * Ltot, Fz + wz * Ltot

    def shoot(My0):
        # state: x, z, theta, My (external resultant moment about +y)
        y = np.array([0.0, 0.0, 0.0, My0])
        s0 = 0.0
        for L, EI, tm in zip(lengths, EIs, tendon_moments):

            def f(s, y, EI=EI, tm=tm):
                th, My = y[2], y[3]
                Nx = N0x - wx * s
                Nz = N0z - wz * s
                tx, tz = np.sin(th), np.cos(th)
                # M' = -t x N, y component: -(tz Nx - tx Nz)
                return [tx, tz, (My + tm) / EI, -(tz * Nx - tx * Nz)]

            sol = solve_ivp(f, (s0, s0 + L), y, rtol=rtol, atol=1e-13, method="DOP853")
            y = sol.y[:, -1]
            s0 += L
        return y

    # secant iteration on the base moment, from the straight rod's value
    m0 = wx * Ltot**2 / 2 + Fx * Ltot
    res = root_scalar(
        lambda m: shoot(m)[3],
        x0=m0,
        x1=m0 + 1e-3 * (abs(m0) + 1.0),
        method="secant",
        xtol=1e-13,
        rtol=1e-15,
        maxiter=100,
    )
    if not res.converged:
        raise RuntimeError("planar shooting did not converge")
    My0 = res.root
    x, z, th, _ = shoot(My0)
    return np.array([x, z]), th
