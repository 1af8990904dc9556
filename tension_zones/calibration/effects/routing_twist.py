"""Twist of the routing between segments: each segment's disks turned about the backbone against its
distal neighbour's (rad; reported in deg).

A wire owned by segment ``o`` runs through a proximal segment ``j < o`` at its own angle turned by
``tau_j + ... + tau_{o-1}``, ``tau_i`` the turn of segment ``i``'s disks against segment ``i + 1``'s
(an assembly offset of the disks, or a backbone twisted between them). A wire's angle in its own
segment is the pattern's (``pattern_rotation``, ``wire_angle_offset``), so the twist is seen only
through the wires that cross segments they do not end in: ``S - 1`` parameters, none for one segment
(the loop then does not offer it).
"""

import dataclasses

import jax.numpy as jnp
import numpy as np

from ._base import Effect, replace


def twist_matrix(structure) -> np.ndarray:
    """``(N, S, S - 1)``: 1 where wire ``k`` crossing segment ``j`` is turned by ``tau_i`` (``j <= i < owner(k)``)."""
    S = structure.n_segments
    own = np.asarray(structure.owner)[:, None, None]
    j = np.arange(S)[None, :, None]
    i = np.arange(S - 1)[None, None, :]
    return ((j <= i) & (i < own)).astype(float)


@dataclasses.dataclass(frozen=True)
class RoutingTwist(Effect):
    name = "routing_twist"
    doc = "turn of each segment's disks against the next one's, seen by the wires crossing it"

    def size(self, model, phys0):
        return model.structure.n_segments - 1

    def bounds(self, model, phys0):
        n = self.size(model, phys0)
        return np.full(n, -0.6), np.full(n, 0.6)  # about +-34 deg: no wire swaps

    def labels(self, model, phys0):
        S = model.structure.n_segments
        return [f"twist_{j + 1}_{j + 2}_deg" for j in range(S - 1)]

    def report_values(self, theta, model, phys0):
        return np.degrees(np.asarray(theta, float))

    def on_params(self, theta, phys, model, on):
        M = jnp.asarray(twist_matrix(model.structure), theta.dtype)
        return replace(phys, route_angles=phys["route_angles"] + M @ theta)
