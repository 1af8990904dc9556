"""Wire angle errors: each wire sits at ``alpha_k + d_k`` on the pitch circle, everywhere along its
routing (rad; reported in deg).

Where the pattern's rotation is also part of the model, the offsets are each segment's deviations
from it (zero mean per segment), so that the two never explain the same thing.
"""

import dataclasses

import jax.numpy as jnp
import numpy as np

from ._base import Effect, replace, wire_labels


@dataclasses.dataclass(frozen=True)
class WireAngleOffset(Effect):
    name = "wire_angle_offset"
    doc = "angular offset of each wire on the pitch circle"

    def size(self, model, phys0):
        return model.structure.n_wires

    def bounds(self, model, phys0):
        n = self.size(model, phys0)
        return np.full(n, -0.6), np.full(n, 0.6)  # about +-34 deg: no wrapping, no wire swaps

    def labels(self, model, phys0):
        return wire_labels("angle_offset", "deg", model)

    def report_values(self, theta, model, phys0):
        return np.degrees(np.asarray(theta, float))

    def on_params(self, theta, phys, model, on):
        owner = model.structure.owner
        S = model.structure.n_segments
        onehot = jnp.asarray(owner[:, None] == np.arange(S)[None, :], theta.dtype)  # (N, S)
        mean = (onehot.T @ theta) / onehot.sum(axis=0)
        d = theta - on.get("pattern_rotation", 0.0) * (onehot @ mean)
        return replace(phys, route_angles=phys["route_angles"] + d[:, None])
