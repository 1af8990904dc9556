"""Drift: every wire's effective length changes at one rate over the recording's time (mm per hour).

Thermal expansion of the structure and creep of the wires and the backbone lengthen or shorten the
wires against the backbone slowly and together: ``q_eff = q + v t``, ``t`` the time since the data's
first timestamp (hours), ``v`` one rate for all wires (a per-wire constant part is the preload's). It
explains a residual ordered in time (the report's ``order`` structure) that the robot's path does not
(backlash and friction are functions of the path, this of the clock). A calibration with a
validation file shares the clock (the files are concatenated: their timestamps must be on one
clock); its clock is held within the fit data's span (:func:`~tension_zones.calibration._model.elapsed_hours`):
a later recording takes the drift at the fit data's end, never a trend extrapolated.

A candidate like any other; without timestamps it is 0 and never scored above 0.
"""

import dataclasses

import numpy as np

from ._base import Effect, replace


@dataclasses.dataclass(frozen=True)
class Drift(Effect):
    name = "drift"
    doc = "all wires' lengths drift at one rate over time (thermal expansion, creep), mm per hour"
    of_time = True

    def size(self, model, phys0):
        return 1

    def bounds(self, model, phys0):
        return np.array([-5.0]), np.array([5.0])

    def labels(self, model, phys0):
        return ["wire_drift_mm_per_h"]

    def on_inputs(self, theta, inputs, model, on):
        return replace(inputs, q=inputs["q"] + inputs["hours"][:, None] * theta[0])
