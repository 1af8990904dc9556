"""Gravity: the robot's weight per unit length (N/mm, base frame), distributed along every segment.

Three components because the direction of gravity in the robot's base frame is not declared.
"""

import dataclasses

import numpy as np

from ._base import Effect, replace


@dataclasses.dataclass(frozen=True)
class Gravity(Effect):
    name = "gravity"
    doc = "the robot's weight per unit length, distributed along the backbone (N/mm, base frame)"

    def size(self, model, phys0):
        return 3

    def bounds(self, model, phys0):
        return np.full(3, -0.02), np.full(3, 0.02)  # 2 g/mm: heavier than a continuum robot gets

    def labels(self, model, phys0):
        return ["gx_N_per_mm", "gy_N_per_mm", "gz_N_per_mm"]

    def on_params(self, theta, phys, model, on):
        return replace(phys, gravity=phys["gravity"] + theta)
