"""Rotation of each segment's wire pattern about the backbone (rad; reported in deg).

Every wire a segment owns sits ``gamma_j`` further round than declared, everywhere along its routing.
Nominal for recordings in an unregistered tracker frame (which way a segment's first wire points is
then unknown); a candidate otherwise.
"""

import dataclasses

import numpy as np

from ._base import Effect, per_owner, replace, segment_labels


@dataclasses.dataclass(frozen=True)
class PatternRotation(Effect):
    name = "pattern_rotation"
    doc = "rotation of each segment's wire pattern about the backbone"

    def size(self, model, phys0):
        return model.structure.n_segments

    def bounds(self, model, phys0):
        n = self.size(model, phys0)
        return np.full(n, -np.pi), np.full(n, np.pi)

    def labels(self, model, phys0):
        return segment_labels("rotation", "deg", model)

    def report_values(self, theta, model, phys0):
        return np.degrees(np.asarray(theta, float))

    def on_params(self, theta, phys, model, on):
        return replace(phys, route_angles=phys["route_angles"] + per_owner(model, theta)[:, None])
