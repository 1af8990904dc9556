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

from ..design import Design
from ..kinematics import tip_pose_b, wire_lengths_b

#: Damped-Newton iterations: a 2-D piecewise-quadratic problem converges in a handful; the rest is margin.
NEWTON_ITERS = 16
#: Step sizes tried by the line search (all evaluated at once: no value-dependent branching).
_STEPS = 2.0 ** -np.arange(12)


def _design_of(phys) -> Design:
    """A Design pytree carrying traced geometry (only length, radius and angles are read)."""
    n = phys["wire_angles"].shape[0]
    leaves = (phys["length"], phys["pitch_radius"], phys["wire_angles"],
              jnp.mean(phys["wire_stiffness"]), phys["EI"], jnp.mean(phys["preload"]))
    return jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(Design(n, 1.0, 1.0)), leaves)


def energy(b, phys, q, f, tension):
    """``V(b)`` for one sample (N mm)."""
    design = _design_of(phys)
    k = phys["wire_stiffness"]
    s = (wire_lengths_b(design, b) - phys["length"]) - q + phys["preload"] / k
    wires = 0.5 * jnp.sum(tension * k * jnp.maximum(s, 0.0) ** 2)
    p, _ = tip_pose_b(design, b)
    return 0.5 * phys["EI"] * jnp.dot(b, b) / phys["length"] + wires - jnp.dot(f, p)


def _newton(V, b0, iters=NEWTON_ITERS):
    """Damped Newton on V with the (generalised) Hessian made positive definite."""
    grad, hess = jax.grad(V), jax.hessian(V)
    steps = jnp.asarray(_STEPS, b0.dtype)

    def step(b, _):
        g, H = grad(b), hess(b)
        H = 0.5 * (H + H.T)
        half_tr = 0.5 * (H[0, 0] + H[1, 1])
        det = H[0, 0] * H[1, 1] - H[0, 1] ** 2
        lam_min = half_tr - jnp.sqrt(jnp.maximum(half_tr**2 - det, 0.0))
        # shift the spectrum so the smallest eigenvalue is at least 1e-6 of the largest scale
        floor = 1e-6 * jnp.maximum(jnp.abs(half_tr), 1.0)
        H = H + jnp.maximum(floor - lam_min, 0.0) * jnp.eye(2, dtype=H.dtype)
        d = -jnp.linalg.solve(H, g)
        v0 = V(b)
        vs = jax.vmap(lambda t: V(b + t * d))(steps)
        # Armijo with a round-off allowance, so converged steps are not rejected by noise in V
        ok = vs <= v0 + 1e-4 * steps * jnp.dot(g, d) + 1e-13 * (1.0 + jnp.abs(v0))
        t = jnp.where(jnp.any(ok), steps[jnp.argmax(ok)], 0.0)
        return b + t * d, None

    b, _ = jax.lax.scan(step, b0, None, length=iters)
    return b


def equilibrium(phys, q, f, tension):
    """Equilibrium bending vector ``b*`` (2,) of one sample; implicitly differentiable."""
    V = lambda b: energy(b, phys, q, f, tension)  # noqa: E731
    b0 = jnp.zeros(2, dtype=jnp.result_type(phys["length"], q, float))

    def tangent_solve(g, y):
        return jnp.linalg.solve(jax.jacobian(g)(y), y)

    return jax.lax.custom_root(jax.grad(V), b0, lambda F, x0: _newton(V, x0), tangent_solve)


def tip_position(phys, q, f, tension):
    """Tip position (3,) of one sample at equilibrium (mm)."""
    b = equilibrium(phys, q, f, tension)
    return tip_pose_b(_design_of(phys), b)[0]


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
