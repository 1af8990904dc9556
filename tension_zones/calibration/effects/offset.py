"""Offset of the measurement frame's origin from the robot's base (mm): ``p_measured = p + t``.

Nominal for recordings in an unregistered tracker frame (where the tracker's origin is is never
known); a rotation of the tracker against the base is the candidate :mod:`.registration`, which leaves
the translation to this while it is part of the model.
"""

import dataclasses

import numpy as np

from ._base import Effect, replace


@dataclasses.dataclass(frozen=True)
class Offset(Effect):
    name = "offset"
    doc = "position of the robot's base in the measurement frame (mm)"

    def size(self, model, phys0):
        return 3

    def bounds(self, model, phys0):
        return np.full(3, -1e3), np.full(3, 1e3)

    def labels(self, model, phys0):
        return ["x_mm", "y_mm", "z_mm"]

    def on_outputs(self, theta, out, model, on):
        return replace(out, p=out["p"] + theta)
