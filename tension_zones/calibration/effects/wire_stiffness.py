"""Per-wire stiffness: ``k_k = k exp(e_k)`` (a log factor, so stiffness stays positive)."""

import dataclasses

import jax.numpy as jnp
import numpy as np

from ._base import Effect, replace, wire_labels


@dataclasses.dataclass(frozen=True)
class WireStiffness(Effect):
    name = "wire_stiffness"
    doc = "axial stiffness of each wire (N/mm)"

    def size(self, model, phys0):
        return model.structure.n_wires

    def bounds(self, model, phys0):
        n = self.size(model, phys0)
        return np.full(n, -np.log(10.0)), np.full(n, np.log(10.0))

    def labels(self, model, phys0):
        return wire_labels("stiffness", "N_per_mm", model)

    def report_values(self, theta, model, phys0):
        return np.asarray(phys0["wire_stiffness"], float) * np.exp(np.asarray(theta, float))

    def on_params(self, theta, phys, model, on):
        return replace(phys, wire_stiffness=phys["wire_stiffness"] * jnp.exp(theta))
