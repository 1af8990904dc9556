"""Per-wire preload error ``f_pre,k = f_pre + d_k`` (N).

A preload difference between wires is the same as a zero offset of that wire's displacement
(``d_k / k``), so this effect also covers encoder zero errors.
"""

import dataclasses

import numpy as np

from ._base import Effect, n_wires, replace, wire_labels


@dataclasses.dataclass(frozen=True)
class Preload(Effect):
    name = "preload"
    doc = "preload of each wire (N)"

    def size(self, phys0):
        return n_wires(phys0)

    def bounds(self, phys0):
        n = n_wires(phys0)
        return np.full(n, -20.0), np.full(n, 20.0)

    def labels(self, phys0):
        return wire_labels("preload", "N", phys0)

    def report_values(self, theta, phys0):
        return np.asarray(phys0["preload"], float) + np.asarray(theta, float)

    def on_params(self, theta, phys):
        return replace(phys, preload=phys["preload"] + theta)
