"""Compression of the backbone: the wires' tension shortens each segment's backbone, and with it the
path of every wire that crosses the segment.

Every taut wire pushes its end disk toward the base, so a segment's backbone carries the tension of
all the wires that cross it, its own and the distal segments'. It shortens by ``a_j`` (its axial
compliance ``L / EA``, um per N) times that tension, and every wire through it is slackened by as
much (:func:`tension_zones.model._equilibrium._relax`): one wire pulled alone loses a little;
when all segments bend together, the proximal backbone carries every wire's tension and the distal
wires lose most. The segments' shortening moves the tip as well. One parameter per segment. Bounded
by the wires' own compliance (``1 / k``): a backbone that gives more than a wire does not hold it.

A 1 mm rod of 50 GPa, 60 mm long, has ``a = 1.5`` um/N.
"""

import dataclasses

import numpy as np

from ._base import Effect, replace, segment_labels

#: um per mm: the parameters are in um/N, the model's ``axial_compliance`` in mm/N
_UM = 1e-3


@dataclasses.dataclass(frozen=True)
class Compression(Effect):
    name = "compression"
    doc = "each segment's backbone shortened by the tension of the wires crossing it, and their paths with it (um/N)"

    def size(self, model, phys0):
        return model.structure.n_segments

    def bounds(self, model, phys0):
        # from none at all (a rigid backbone) to the wires' own compliance; the parameter is the
        # change from the declared compliance (none today: RobotModel declares 0)
        declared = np.asarray(phys0["axial_compliance"], float) / _UM
        return -declared, np.full(declared.shape[0], 1.0 / _UM / float(np.min(phys0["wire_stiffness"]))) - declared

    def labels(self, model, phys0):
        return segment_labels("compliance", "um_per_N", model)

    def on_params(self, theta, phys, model, on):
        return replace(phys, axial_compliance=phys["axial_compliance"] + _UM * theta)
