"""Backlash: per-wire play ``c_k`` (mm) between actuator and wire (a play operator along the path).

The wire's effective displacement follows the command only once the play is taken up:
``q_eff[t] = clamp(q_eff[t-1], q[t] - c/2, q[t] + c/2)``, started at ``q_eff[0] = q[0]``. The state
depends on the path, so it is a ``lax.scan`` over the acquisition order.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from ._base import Effect, n_wires, replace, wire_labels


def play(q, c):
    """Play operator over a sequence: ``q`` (N, n) commanded, ``c`` (n,) play -> effective (N, n).

    Written with ``where`` (not ``clip``) so that at ``c = 0`` the derivative with respect to ``c``
    is the one-sided ``-/+ 1/2`` of the direction of motion (what the score test needs).
    """
    h = 0.5 * c

    def step(prev, qt):
        cur = jnp.where(qt - h > prev, qt - h, jnp.where(qt + h < prev, qt + h, prev))
        return cur, cur

    _, out = jax.lax.scan(step, q[0], q)
    return out


@dataclasses.dataclass(frozen=True)
class Backlash(Effect):
    name = "backlash"
    doc = "per-wire play between actuator and wire (mm)"

    def size(self, phys0):
        return n_wires(phys0)

    def bounds(self, phys0):
        n = n_wires(phys0)
        return np.zeros(n), np.full(n, 2.0)

    def labels(self, phys0):
        return wire_labels("play", "mm", phys0)

    def on_inputs(self, theta, inputs):
        return replace(inputs, q=play(inputs["q"], theta))
