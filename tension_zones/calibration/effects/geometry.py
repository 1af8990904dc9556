"""Geometry errors: segment length ``L + dL`` and pitch radius ``r + dr`` (mm)."""

import dataclasses

import numpy as np

from ._base import Effect, replace


@dataclasses.dataclass(frozen=True)
class Geometry(Effect):
    name = "geometry"
    doc = "errors of the segment length and the wires' pitch radius (mm)"

    def size(self, phys0):
        return 2

    def bounds(self, phys0):
        L, r = float(phys0["length"]), float(phys0["pitch_radius"])
        return np.array([-0.5 * L, -0.6 * r]), np.array([0.5 * L, 0.6 * r])

    def labels(self, phys0):
        return ["length_mm", "pitch_radius_mm"]

    def report_values(self, theta, phys0):
        t = np.asarray(theta, float)
        return np.array([float(phys0["length"]) + t[0], float(phys0["pitch_radius"]) + t[1]])

    def on_params(self, theta, phys):
        return replace(phys, length=phys["length"] + theta[0], pitch_radius=phys["pitch_radius"] + theta[1])
