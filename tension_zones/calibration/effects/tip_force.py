"""An unknown constant tip force (N, base frame) added to the known one, e.g. a tool's weight."""

import dataclasses

import numpy as np

from ._base import Effect, replace


@dataclasses.dataclass(frozen=True)
class TipForce(Effect):
    name = "tip_force"
    doc = "constant unknown tip force (N, base frame)"

    def size(self, model, phys0):
        return 3

    def bounds(self, model, phys0):
        return np.full(3, -20.0), np.full(3, 20.0)

    def labels(self, model, phys0):
        return ["fx_N", "fy_N", "fz_N"]

    def on_inputs(self, theta, inputs, model, on):
        return replace(inputs, f=inputs["f"] + theta)
