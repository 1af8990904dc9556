"""Registration: the rigid transform from the robot's base frame to the tracker's frame.

``p_tracker = R(w) p + t`` with the rotation vector ``w`` (rad; reported in deg) and ``t`` (mm).
"""

import dataclasses

import jax
import numpy as np

from ..._numerics import rotvec_to_matrix
from ._base import Effect


@dataclasses.dataclass(frozen=True)
class Registration(Effect):
    name = "registration"
    doc = "rigid transform between tracker and base (rotation vector, translation)"

    def size(self, phys0):
        return 6

    def bounds(self, phys0):
        return np.r_[np.full(3, -0.8), np.full(3, -100.0)], np.r_[np.full(3, 0.8), np.full(3, 100.0)]

    def labels(self, phys0):
        return ["rot_x_deg", "rot_y_deg", "rot_z_deg", "tx_mm", "ty_mm", "tz_mm"]

    def report_values(self, theta, phys0):
        t = np.asarray(theta, float)
        return np.r_[np.degrees(t[:3]), t[3:]]

    def on_outputs(self, theta, pos):
        R = rotvec_to_matrix(theta[:3])
        return jax.numpy.einsum("ij,nj->ni", R, pos) + theta[3:]
