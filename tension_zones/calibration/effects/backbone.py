"""Backbone bending stiffness ``EI`` of each segment (a log factor on the declared value).

Nominal (always fitted): it is the least certain number of a design (a nitinol rod's modulus spans
40-75 GPa) and, with the wire stiffness fixed, it sets how far the backbone resists the wires (the
ratio ``EI / (L k r^2)``), which every sample sees.
"""

import dataclasses

import jax.numpy as jnp
import numpy as np

from ._base import Effect, replace, segment_labels


@dataclasses.dataclass(frozen=True)
class BackboneEI(Effect):
    name = "backbone_EI"
    doc = "backbone bending stiffness EI of each segment (log factor on the declared value)"

    def size(self, model, phys0):
        return model.structure.n_segments

    def bounds(self, model, phys0):
        n = self.size(model, phys0)
        return np.full(n, -np.log(20.0)), np.full(n, np.log(20.0))

    def labels(self, model, phys0):
        return segment_labels("EI", "Nmm2", model)

    def report_values(self, theta, model, phys0):
        return np.asarray(phys0["EI"], float) * np.exp(np.asarray(theta, float))

    def on_params(self, theta, phys, model, on):
        return replace(phys, EI=phys["EI"] * jnp.exp(theta))
