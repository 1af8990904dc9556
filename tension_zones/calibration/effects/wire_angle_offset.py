"""Wire angle offsets: each wire sits at ``alpha_k + d_k`` on the pitch circle (rad; reported in deg)."""

import dataclasses

import numpy as np

from ._base import Effect, n_wires, replace, wire_labels


@dataclasses.dataclass(frozen=True)
class WireAngleOffset(Effect):
    name = "wire_angle_offset"
    doc = "angular offset of each wire on the pitch circle"

    def size(self, phys0):
        return n_wires(phys0)

    def bounds(self, phys0):
        n = n_wires(phys0)
        return np.full(n, -0.6), np.full(n, 0.6)  # about +-34 deg: no wrapping, no wire swaps

    def labels(self, phys0):
        return wire_labels("angle_offset", "deg", phys0)

    def report_values(self, theta, phys0):
        return np.degrees(np.asarray(theta, float))

    def on_params(self, theta, phys):
        return replace(phys, wire_angles=phys["wire_angles"] + theta)
