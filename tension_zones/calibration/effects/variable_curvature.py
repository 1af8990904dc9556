"""Variable curvature: each segment bends as an elastic rod, its curvature varying along it.

Constant curvature is exact under tendon loads alone; a distributed weight, a tip force or friction
make a real backbone bend more near its base than near its tip. The calibration model then solves
every segment as ``m`` constant-curvature pieces (the rod model of
:mod:`tension_zones.model._equilibrium`), and this effect's parameter per segment, the *curvature
freedom* ``r`` in ``[0, 1]``, says how freely the pieces may differ: 0 (null) pins them to their
segment's mean bending (constant curvature), 1 is the elastic rod. Its score at 0 is the rod's
first-order variation, so a set whose curvature is not constant is named as such rather than
absorbed by geometry or a registration. Without any load in the model the rod is the
constant-curvature segment and the effect scores nothing, so the loop does not score it then. While
the effect is off the calibration runs the constant-curvature program, which costs a fraction of the
rod's; the rod's program is compiled the first time the effect is scored or fitted.
"""

import dataclasses

import numpy as np

from ._base import Effect, replace


@dataclasses.dataclass(frozen=True)
class VariableCurvature(Effect):
    name = "variable_curvature"
    doc = (
        "curvature varying along each segment as in an elastic rod under the loads (0 = constant "
        "curvature, 1 = elastic rod)"
    )
    scored_on = True
    needs_load = True

    def size(self, model, phys0):
        return model.structure.n_segments

    def pieces_for(self, model):
        # The tip error against the Kirchhoff rod (tests/reference_rod.py) of a bent 60 mm segment
        # falls as 1/m^2: under a lateral weight of 0.003 N/mm 0.040 / 0.018 mm with m = 4 / 6, with a
        # 0.4 N lateral tip force as well 0.20 / 0.090 mm (docs/pages/model-reference.md), against a tracker's
        # 0.05 mm. On one or two segments 6 pieces make a rod fit's pass about 1.6x as long, which
        # such a calibration affords. Three segments keep 4: there the loop scores the rod every
        # round, and 6 pieces would take the calibration over its time budget
        return 6 if model.structure.n_segments <= 2 else 4

    def bounds(self, model, phys0):
        n = self.size(model, phys0)
        return np.zeros(n), np.ones(n)

    def start(self, model, phys0):
        # a refit starts from the elastic rod: from 0, the profile of the error in ``r`` can rise
        # before it falls (the other parameters must move with it), and the solver then holds ``r``
        # on its bound. A single rod segment under its weight: 6 iterations from 0 left the held-out
        # error at 0.1274 mm, from 1 took it to 0.0856 mm, where 40 from 0 end too
        return np.ones(self.size(model, phys0))

    def labels(self, model, phys0):
        S = model.structure.n_segments
        return ["curvature_freedom"] if S == 1 else [f"curvature_freedom_{j + 1}" for j in range(S)]

    def on_params(self, theta, phys, model, on):
        return replace(phys, curvature_freedom=phys["curvature_freedom"] + theta)
