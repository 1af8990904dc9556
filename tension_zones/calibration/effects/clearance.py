"""Hole clearance: a wire's path through a bent segment shortened by the play in the disks' holes.

A wire under tension hugs the side of each disk's hole nearest the centre of curvature, so its path
through a segment bent by ``theta`` is shorter than the pitch-radius arc by about ``c |theta|``,
whatever the wire's angle (``c`` the clearance): a segment's wires slacken as it bends, and a distal
segment's wires as the proximal segments they cross bend, in any direction. Two parameters, mm per
rad of the *solved* bending (the equilibrium's, :mod:`tension_zones.model._equilibrium`): ``c_own``
(the segment a wire ends in) and ``c_proximal`` (the segments it crosses before it; none on a
one-segment robot). Bounded at zero: a hole cannot lengthen the path.

On FTDCR v4 the patterns of ``val.csv`` bend all three segments at once and reach less than
constant-curvature routing says, more so the more segments bend together; ``benchmarks/README.md``
gives what this effect does there.
"""

import dataclasses

import jax.numpy as jnp
import numpy as np

from ._base import Effect, replace


@dataclasses.dataclass(frozen=True)
class Clearance(Effect):
    name = "clearance"
    doc = "wire paths shortened by c |bending| of their own segment and of the proximal ones they cross (mm/rad)"

    def size(self, model, phys0):
        return 1 if model.structure.n_segments == 1 else 2

    def bounds(self, model, phys0):
        n = self.size(model, phys0)
        return np.zeros(n), np.ones(n)  # 1 mm per rad: a fifth of a 4.5 mm pitch radius

    def labels(self, model, phys0):
        return ["c_own_mm_per_rad", "c_proximal_mm_per_rad"][: self.size(model, phys0)]

    def on_params(self, theta, phys, model, on):
        c = jnp.zeros(2, theta.dtype).at[: theta.shape[0]].set(theta)
        return replace(phys, clearance=phys["clearance"] + c)
