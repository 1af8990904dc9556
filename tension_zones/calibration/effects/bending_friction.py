"""Friction of the bending (hysteresis): each segment's bending sticks until the elastic moment that
pulls it back to equilibrium exceeds a friction moment ``h_j`` (N mm; the wires rubbing in the disks'
holes, the disks on the backbone).

The state depends on the path: the model then predicts the whole recording in acquisition order
(:func:`tension_zones.model._equilibrium.bending_memory`, a play operator in moment space on each
sample's equilibrium). Where a segment's wires are taut the wires' stiffness makes the play small;
where they are all slack (a pull's end, the others paid out) only the backbone holds the bending and
the segment keeps much of its last shape. Its parameters have no sensitivity without the memory, so
it is scored with it on (``scored_on``); while it is off the calibration runs the model without it.
"""

import dataclasses

import numpy as np

from ._base import Effect, replace, segment_labels


@dataclasses.dataclass(frozen=True)
class BendingFriction(Effect):
    name = "bending_friction"
    doc = "friction moment resisting each segment's change of bending (hysteresis; N mm)"
    scored_on = True
    memory = True

    def size(self, model, phys0):
        return model.structure.n_segments

    def bounds(self, model, phys0):
        # up to the moment that bends the declared segment by 1 rad (a real backbone may be several
        # times stiffer than declared: FTDCR v4's is fitted at 5-10x)
        EI, L = np.asarray(phys0["EI"], float), np.asarray(phys0["length"], float)
        return np.zeros(EI.shape[0]), EI / L

    def labels(self, model, phys0):
        return segment_labels("bending_friction", "Nmm", model)

    def on_params(self, theta, phys, model, on):
        return replace(phys, bending_friction=phys["bending_friction"] + theta)
