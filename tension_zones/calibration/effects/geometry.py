"""Geometry errors of each segment: length ``L_j + dL_j`` and pitch radius ``r + dr_j`` (mm) of every
wire in its disks."""

import dataclasses

import jax.numpy as jnp
import numpy as np

from ._base import Effect, replace, segment_labels, segment_pitch_radii


@dataclasses.dataclass(frozen=True)
class Geometry(Effect):
    name = "geometry"
    doc = "errors of each segment's length and of the wires' pitch radius in its disks (mm)"

    def size(self, model, phys0):
        return 2 * model.structure.n_segments

    def bounds(self, model, phys0):
        L, r = np.asarray(phys0["length"], float), segment_pitch_radii(model, phys0)
        return np.r_[-0.5 * L, -0.6 * r], np.r_[0.5 * L, 0.6 * r]

    def labels(self, model, phys0):
        return segment_labels("length", "mm", model) + segment_labels("pitch_radius", "mm", model)

    def report_values(self, theta, model, phys0):
        t = np.asarray(theta, float)
        return np.r_[np.asarray(phys0["length"], float), segment_pitch_radii(model, phys0)] + t

    def on_params(self, theta, phys, model, on):
        S = model.structure.n_segments
        dr = jnp.where(jnp.asarray(model.structure.crosses), theta[None, S:], 0.0)
        return replace(phys, length=phys["length"] + theta[:S], route_radii=phys["route_radii"] + dr)
