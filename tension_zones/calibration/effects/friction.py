"""Friction along the wire routing: the tension reaching the segment depends on the direction of motion.

Capstan-like: pulling a wire in (it last moved toward the actuator) loses a factor ``exp(-mu)`` of its
tension on the way to the segment; releasing it gains ``exp(+mu)`` (friction holds the wire back).
One coefficient for all wires (``mu`` = friction coefficient times wrap angle of the routing). The
direction is the wire's last direction of motion (a stationary wire keeps it), from the inputs.
"""

import dataclasses

import jax.numpy as jnp
import numpy as np

from ._base import Effect, replace


@dataclasses.dataclass(frozen=True)
class Friction(Effect):
    name = "friction"
    doc = "direction-dependent tension loss along the wire (capstan exponent mu)"

    def size(self, phys0):
        return 1

    def bounds(self, phys0):
        return np.array([0.0]), np.array([1.5])

    def labels(self, phys0):
        return ["mu"]

    def on_inputs(self, theta, inputs):
        return replace(inputs, tension=inputs["tension"] * jnp.exp(theta[0] * inputs["direction"]))
