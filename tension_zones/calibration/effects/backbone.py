"""Nominal parameter: the backbone's bending stiffness ``EI`` (always fitted, never a candidate).

Fitted as a log factor on the declared value: it is the least certain number of a design (a nitinol
rod's modulus spans 40-75 GPa) and, with the wire stiffness fixed, it sets how far the backbone
resists the wires (the ratio ``EI / (L k r^2)``), which every sample sees.
"""

import dataclasses

import jax.numpy as jnp
import numpy as np

from ._base import Effect, replace


@dataclasses.dataclass(frozen=True)
class BackboneEI(Effect):
    name = "backbone_EI"
    doc = "backbone bending stiffness EI (log factor on the declared value)"

    def size(self, phys0):
        return 1

    def bounds(self, phys0):
        return np.array([-np.log(20.0)]), np.array([np.log(20.0)])

    def labels(self, phys0):
        return ["EI_Nmm2"]

    def report_values(self, theta, phys0):
        return float(phys0["EI"]) * np.exp(np.asarray(theta, float))

    def on_params(self, theta, phys):
        return replace(phys, EI=phys["EI"] * jnp.exp(theta[0]))
