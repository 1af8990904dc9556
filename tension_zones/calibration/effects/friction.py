"""Friction along the wire routing (capstan): the share of a wire's tension that reaches its segments.

``t_k = exp(d_k (mu_0 + mu_1 w_k))``: ``d_k`` the wire's last direction of motion (pulled in: -1, it
loses tension on the way; released: +1, friction holds it back), ``mu_0`` the routing before the robot
(friction coefficient times wrap angle), ``mu_1`` the friction coefficient per radian of bending
``w_k`` the wire wraps around in every segment it crosses: a distal wire's friction grows with the
bending of the proximal segments (see :mod:`tension_zones.model._equilibrium`).
"""

import dataclasses

import numpy as np

from ._base import Effect, replace


@dataclasses.dataclass(frozen=True)
class Friction(Effect):
    name = "friction"
    doc = "direction-dependent tension loss along the routing (capstan: routing, per radian of bending)"

    def size(self, model, phys0):
        return 2

    def bounds(self, model, phys0):
        return np.zeros(2), np.array([1.5, 1.5])

    def labels(self, model, phys0):
        return ["mu_routing", "mu_per_rad"]

    def on_params(self, theta, phys, model, on):
        return replace(phys, friction=phys["friction"] + theta)
