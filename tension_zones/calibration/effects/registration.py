"""Registration: the rigid transform from the robot's base frame to the measurement frame.

``p_measured = R(w) p + t`` with the rotation vector ``w`` (rad; reported in deg) and ``t`` (mm); the
tip orientation turns with it. Nominal for recordings in an unregistered tracker frame.

Without a load, a rotation about the robot's axis and a common rotation of every segment's wire
pattern move the tip alike: while :mod:`.pattern_rotation` is part of the model, the registration
leaves that axis (``w_z``) to it, and while :mod:`.offset` is, the translation to that, so that no
parameter is a free direction of the fit.
"""

import dataclasses

import jax.numpy as jnp
import numpy as np

from ..._numerics import rotvec_to_matrix
from ._base import Effect, replace


@dataclasses.dataclass(frozen=True)
class Registration(Effect):
    name = "registration"
    doc = "rigid transform between the measurement frame and the robot's base (rotation vector, translation)"

    def size(self, model, phys0):
        return 6

    def bounds(self, model, phys0):
        return np.r_[np.full(3, -0.8), np.full(3, -1e3)], np.r_[np.full(3, 0.8), np.full(3, 1e3)]

    def labels(self, model, phys0):
        return ["rot_x_deg", "rot_y_deg", "rot_z_deg", "tx_mm", "ty_mm", "tz_mm"]

    def report_values(self, theta, model, phys0):
        t = np.asarray(theta, float)
        return np.r_[np.degrees(t[:3]), t[3:]]

    def on_outputs(self, theta, out, model, on):
        w = theta[:3] * jnp.stack([1.0, 1.0, 1.0 - on.get("pattern_rotation", 0.0)])
        R = rotvec_to_matrix(w)
        t = theta[3:] * (1.0 - on.get("offset", 0.0))
        return replace(out, p=jnp.einsum("ij,nj->ni", R, out["p"]) + t, R=jnp.einsum("ij,njk->nik", R, out["R"]))
