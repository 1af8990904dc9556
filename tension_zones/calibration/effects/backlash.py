"""Backlash: per-wire play ``c_k`` (mm, full width) between actuator and wire (a play operator).

The wire's effective displacement follows the command only once the play is taken up:
``q_eff[t] = clamp(q_eff[t-1], q[t] - c/2, q[t] + c/2)``, started at ``q_eff = q`` where a recording
starts. The state depends on the path, so it is a ``lax.scan`` over the acquisition order.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from ._base import Effect, replace, wire_labels


def play(q, c, reset=None):
    """Play operator over a sequence: ``q`` (N, n) commanded, ``c`` (n,) play, ``reset`` (N,) 0/1 where
    a recording starts -> effective (N, n).

    Written with ``where`` (not ``clip``) so that at ``c = 0`` the derivative with respect to ``c``
    is the one-sided ``-/+ 1/2`` of the direction of motion (what the score test needs).
    """
    h = 0.5 * c
    reset = jnp.zeros(q.shape[0], q.dtype) if reset is None else jnp.asarray(reset, q.dtype)

    def step(prev, xs):
        qt, rt = xs
        prev = jnp.where(rt > 0, qt, prev)
        cur = jnp.where(qt - h > prev, qt - h, jnp.where(qt + h < prev, qt + h, prev))
        return cur, cur

    _, out = jax.lax.scan(step, q[0], (q, reset))
    return out


@dataclasses.dataclass(frozen=True)
class Backlash(Effect):
    name = "backlash"
    doc = "per-wire play between actuator and wire (mm)"

    def size(self, model, phys0):
        return model.structure.n_wires

    def bounds(self, model, phys0):
        n = self.size(model, phys0)
        return np.zeros(n), np.full(n, 2.0)

    def labels(self, model, phys0):
        return wire_labels("play", "mm", model)

    def on_inputs(self, theta, inputs, model, on):
        return replace(inputs, q=play(inputs["q"], theta, inputs["reset"]))
