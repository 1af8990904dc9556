"""Marker offset: the tracked point sits at ``m`` (mm) from the tip's centre, in the tip frame."""

import dataclasses

import jax.numpy as jnp
import numpy as np

from ._base import Effect, replace


@dataclasses.dataclass(frozen=True)
class Marker(Effect):
    name = "marker"
    doc = "offset of the tracked point from the tip's centre (tip frame)"

    def size(self, model, phys0):
        return 3

    def bounds(self, model, phys0):
        return np.full(3, -25.0), np.full(3, 25.0)

    def labels(self, model, phys0):
        return ["mx_mm", "my_mm", "mz_mm"]

    def on_outputs(self, theta, out, model, on):
        # out["R"] is the tip's orientation in the measurement frame (a registration turns it too),
        # so the order of this and the registration does not matter
        return replace(out, p=out["p"] + jnp.einsum("nij,j->ni", out["R"], theta))
