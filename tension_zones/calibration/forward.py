"""Kinetostatic forward model of one segment (MODEL.md Sec. 5).

Commanded wire displacements ``q`` and a known tip force ``f`` give the equilibrium bending
``b* = argmin_b V(b)``,

    V(b) = EI |b|^2 / (2 L) + sum_k (t_k k_k / 2) max(s_k, 0)^2 - f . p(b),
    s_k  = (l_k(b) - L) - q_k + f_pre,k / k_k,

with per-wire stiffness ``k_k``, per-wire preload ``f_pre,k`` and a per-sample tension factor
``t_k`` (1 without friction; the friction effect sets it). ``max(s, 0)^2`` is only C1, so the solve
is a damped Newton method on the generalised Hessian with a branch-free backtracking line search;
derivatives come from the implicit function theorem on ``grad V(b*) = 0`` (``lax.custom_root``),
never from unrolling the iterations.

Physical parameters are a plain dict pytree (``phys``): ``length``, ``pitch_radius``, ``EI`` (scalars),
``wire_angles``, ``wire_stiffness``, ``preload`` (each ``(n,)``). Per-sample inputs are a dict of
arrays with a leading sample axis: ``q`` (N, n), ``f`` (N, 3), ``tension`` (N, n) and ``direction``
(N, n), the wire's last direction of motion (+1 released, -1 pulled in, 0 not moved yet).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from ..model._design import Design
from .._numerics import sinc_sq, versinc_sq

#: Damped-Newton iterations: a 2-D piecewise-quadratic problem converges in a handful; the rest is margin.
NEWTON_ITERS = 16
#: Step sizes tried by the line search (all evaluated at once: no value-dependent branching).
_STEPS = 2.0 ** -np.arange(10)


def _position(b, L):
    """Tip position of MODEL.md Sec. 5 (the same formula as ``tip_pose_b``, without the rotation)."""
    phi2 = b[0] * b[0] + b[1] * b[1]
    k = L * versinc_sq(phi2)
    return jnp.stack([k * b[0], k * b[1], L * sinc_sq(phi2)])


class _Terms:
    """The pieces of ``V`` for one sample, with gradient and generalised Hessian written out
    (autodiff only for the small load term): a smaller program compiles much faster."""

    def __init__(self, phys, q, f, tension):
        a = phys["wire_angles"]
        self.A = phys["pitch_radius"] * jnp.stack([jnp.cos(a), jnp.sin(a)], axis=1)  # (n, 2)
        self.c = -q + phys["preload"] / phys["wire_stiffness"]  # s = c - A b
        self.kt = tension * phys["wire_stiffness"]
        self.ei = phys["EI"] / phys["length"]
        self.L, self.f = phys["length"], f

    def load(self, b):
        return jnp.dot(self.f, _position(b, self.L))

    def value(self, b):
        s = self.c - self.A @ b
        return 0.5 * self.ei * jnp.dot(b, b) + 0.5 * jnp.sum(self.kt * jnp.maximum(s, 0.0) ** 2) - self.load(b)

    def grad(self, b):
        s = self.c - self.A @ b
        return self.ei * b - self.A.T @ (self.kt * jnp.maximum(s, 0.0)) - jax.grad(self.load)(b)

    def hess(self, b):
        taut = (self.c - self.A @ b > 0).astype(b.dtype)
        H = self.ei * jnp.eye(2, dtype=b.dtype) + (self.A.T * (self.kt * taut)) @ self.A
        return H - jax.hessian(self.load)(b)


def energy(b, phys, q, f, tension):
    """``V(b)`` for one sample (N mm)."""
    return _Terms(phys, q, f, tension).value(b)


def _newton(t: _Terms, b0, iters=NEWTON_ITERS):
    """Damped Newton on V with the (generalised) Hessian made positive definite."""
    steps = jnp.asarray(_STEPS, b0.dtype)

    def step(b, _):
        g, H = t.grad(b), t.hess(b)
        H = 0.5 * (H + H.T)
        half_tr = 0.5 * (H[0, 0] + H[1, 1])
        det = H[0, 0] * H[1, 1] - H[0, 1] ** 2
        lam_min = half_tr - jnp.sqrt(jnp.maximum(half_tr**2 - det, 0.0))
        # shift the spectrum so the smallest eigenvalue is at least 1e-6 of the largest scale
        floor = 1e-6 * jnp.maximum(jnp.abs(half_tr), 1.0)
        H = H + jnp.maximum(floor - lam_min, 0.0) * jnp.eye(2, dtype=H.dtype)
        d = -jnp.linalg.solve(H, g)
        v0 = t.value(b)
        vs = jax.vmap(lambda s: t.value(b + s * d))(steps)
        # Armijo with a round-off allowance, so converged steps are not rejected by noise in V
        ok = vs <= v0 + 1e-4 * steps * jnp.dot(g, d) + 1e-13 * (1.0 + jnp.abs(v0))
        step_size = jnp.where(jnp.any(ok), steps[jnp.argmax(ok)], 0.0)
        return b + step_size * d, None

    b, _ = jax.lax.scan(step, b0, None, length=iters)
    return b


def equilibrium(phys, q, f, tension):
    """Equilibrium bending vector ``b*`` (2,) of one sample; implicitly differentiable."""
    b0 = jnp.zeros(2, dtype=jnp.result_type(phys["length"], q, float))

    def grad_V(b):
        return _Terms(phys, q, f, tension).grad(b)

    def solve(_, x0):
        return _newton(_Terms(phys, q, f, tension), x0)

    def tangent_solve(g, y):
        return jnp.linalg.solve(jax.jacobian(g)(y), y)

    return jax.lax.custom_root(grad_V, b0, solve, tangent_solve)


def tip_position(phys, q, f, tension):
    """Tip position (3,) of one sample at equilibrium (mm)."""
    return _position(equilibrium(phys, q, f, tension), phys["length"])


def motion_direction(q):
    """Last direction of motion of each wire, (N, n): +1 released, -1 pulled in, 0 not yet moved.

    A stationary sample keeps the previous direction (that is what friction and backlash remember).
    """
    q = jnp.asarray(q)
    dq = jnp.diff(q, axis=0, prepend=q[:1])

    def step(prev, d):
        cur = jnp.where(d > 0, 1.0, jnp.where(d < 0, -1.0, prev))
        return cur, cur

    _, out = jax.lax.scan(step, jnp.zeros(q.shape[1], q.dtype), dq)
    return out


@dataclasses.dataclass(frozen=True)
class SegmentModel:
    """The single-segment model as the calibration loop sees it (see :mod:`.model`)."""

    n_wires: int

    def physical(self, design: Design) -> dict:
        n = self.n_wires
        if design.n_wires != n:
            raise ValueError(f"design has {design.n_wires} wires, the model {n}")
        ones = jnp.ones(n)
        return {
            "length": jnp.asarray(design.length),
            "pitch_radius": jnp.asarray(design.pitch_radius),
            "EI": jnp.asarray(design.backbone_EI),
            "wire_angles": jnp.asarray(design.wire_angles),
            "wire_stiffness": design.wire_stiffness * ones,
            "preload": design.preload * ones,
        }

    def inputs(self, data) -> dict:
        q = jnp.asarray(data.q)
        return {
            "q": q,
            "f": jnp.asarray(data.f),
            "tension": jnp.ones_like(q),
            "direction": motion_direction(q),
        }

    def predict(self, phys, inputs):
        """Tip positions (N, 3) for all samples (one vmap over the equilibrium)."""
        return jax.vmap(tip_position, in_axes=(None, 0, 0, 0))(
            phys, inputs["q"], inputs["f"], inputs["tension"]
        )

    def wire_layout(self, phys):
        """Unit vectors of the wires' moment arms (n, 2): used to express motion in bending space."""
        a = phys["wire_angles"]
        return jnp.stack([jnp.cos(a), jnp.sin(a)], axis=1)
