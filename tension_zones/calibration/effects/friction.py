"""Friction along the wire routing (capstan): the tension decays over every disk a wire crosses.

The share of wire ``k``'s tension that acts on a piece of the backbone (a segment, or a piece of one in
the rod model) is ``exp(d_k (mu_0 + mu_1 w))``: ``d_k`` the wire's last direction of motion (pulled
in: -1, it loses tension on the way; released: +1, friction holds it back), ``mu_0`` the routing
before the robot (friction coefficient times wrap angle), ``mu_1`` the friction coefficient per
radian of bending ``w`` the wire has wrapped around before that piece: a pulled wire bends its
proximal pieces more than its distal ones, and a distal wire loses tension to the bending of the
proximal segments it crosses (see :mod:`tension_zones.model._equilibrium`, where the non-conservative
force is solved for).
"""

import dataclasses

import numpy as np

from ._base import Effect, replace


@dataclasses.dataclass(frozen=True)
class Friction(Effect):
    name = "friction"
    doc = "direction-dependent tension loss over the routing and every disk (capstan: routing, per radian of bending)"

    def size(self, model, phys0):
        return 2

    def bounds(self, model, phys0):
        return np.zeros(2), np.array([1.5, 1.5])

    def labels(self, model, phys0):
        return ["mu_routing", "mu_per_rad"]

    def on_params(self, theta, phys, model, on):
        return replace(phys, friction=phys["friction"] + theta)
