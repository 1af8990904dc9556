"""Per-wire preload (N) on top of the declared one: wire zero offsets and pretension.

A preload ``f`` is the same as a zero offset ``f / k_w`` of the wire's displacement (tension_zones/MODEL.md Sec. 5:
``s = dl - q + f_pre / k_w``), so this effect also covers encoder zero errors and a segment's
pretension.
"""

import dataclasses

import numpy as np

from ._base import Effect, replace, wire_labels


@dataclasses.dataclass(frozen=True)
class Preload(Effect):
    name = "preload"
    doc = "preload of each wire (N), equivalently a zero offset of its displacement"

    def size(self, model, phys0):
        return model.structure.n_wires

    def bounds(self, model, phys0):
        lim = 3.0 * np.asarray(phys0["wire_stiffness"], float)  # 3 mm of wire
        return -lim, lim

    def labels(self, model, phys0):
        return wire_labels("preload", "N", model)

    def report_values(self, theta, model, phys0):
        return np.asarray(phys0["preload"], float) + np.asarray(theta, float)

    def on_params(self, theta, phys, model, on):
        return replace(phys, preload=phys["preload"] + theta)
