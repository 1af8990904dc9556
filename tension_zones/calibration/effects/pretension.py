"""One preload (N) shared by a segment's wires, on top of the declared ones: the tension a segment is
set to at its zero command.

It is :mod:`.preload` with one value per segment instead of one per wire. A robot whose makers
pretension each segment at home engages a wire at the same command whichever wire it is; where most
wires are slack in most samples (single-tendon pulls, the others paid out) a wire's own zero offset
is set by few samples, and a per-segment value carries to the wires the held-out part pulls
(tension_zones/MODEL.md Sec. 5: a preload ``f`` is a zero offset ``f / k_w``). Per-wire deviations on
top of it are the preload effect's.
"""

import dataclasses

import numpy as np

from ._base import Effect, per_owner, replace, segment_labels


@dataclasses.dataclass(frozen=True)
class Pretension(Effect):
    name = "pretension"
    doc = "one preload shared by each segment's wires (N), equivalently a common zero offset"
    special_case_of = "preload"

    def size(self, model, phys0):
        return model.structure.n_segments

    def bounds(self, model, phys0):
        # 3 mm of the segment's stiffest wire, as the preload's per wire
        k, owner = np.asarray(phys0["wire_stiffness"], float), model.structure.owner
        lim = 3.0 * np.array([k[owner == j].max() for j in range(model.structure.n_segments)])
        return -lim, lim

    def labels(self, model, phys0):
        return segment_labels("pretension", "N", model)

    def on_params(self, theta, phys, model, on):
        return replace(phys, preload=phys["preload"] + per_owner(model, theta))
