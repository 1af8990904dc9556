"""What an effect is: a few parameters and a transformation of the model's params, inputs or outputs.

An effect never branches on values and is written for the whole batch (inputs have the sample axis
first), so the loop can compile one model with every effect present and switch effects on and off
with a mask: adding an effect to a fit never recompiles. ``null`` parameters mean "no effect"; the
score test differentiates at the null.
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class Effect:
    """Base class: subclasses set ``name`` and override ``size`` and one of the three hooks."""

    name = "effect"
    #: one line for the report: what the effect is physically
    doc = ""

    # -- parameters (concrete NumPy, read once from the declared physical parameters) --------------
    def size(self, phys0) -> int:
        raise NotImplementedError

    def null(self, phys0) -> np.ndarray:
        return np.zeros(self.size(phys0))

    def bounds(self, phys0) -> tuple[np.ndarray, np.ndarray]:
        n = self.size(phys0)
        return np.full(n, -np.inf), np.full(n, np.inf)

    def labels(self, phys0) -> list[str]:
        """One name (with unit) per parameter, for the report."""
        n = self.size(phys0)
        return [f"{self.name}[{i}]" for i in range(n)]

    def report_values(self, theta, phys0) -> np.ndarray:
        """Parameters in the units of :meth:`labels` (default: as fitted)."""
        return np.asarray(theta, float)

    # -- hooks (traced; theta is this effect's slice of the parameter vector) ---------------------
    def on_params(self, theta, phys):
        return phys

    def on_inputs(self, theta, inputs):
        return inputs

    def on_outputs(self, theta, pos):
        return pos


def n_wires(phys0) -> int:
    return int(np.shape(phys0["wire_angles"])[0])


def wire_labels(prefix: str, unit: str, phys0) -> list[str]:
    return [f"{prefix}_{k + 1}_{unit}" for k in range(n_wires(phys0))]


def replace(d: dict, **changes) -> dict:
    out = dict(d)
    out.update(changes)
    return out

