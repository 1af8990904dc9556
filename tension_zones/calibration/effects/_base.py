"""What an effect is: a few parameters and a transformation of the model's parameters, inputs or outputs.

An effect never branches on values and is written for the whole batch (inputs have the sample axis
first), so the loop compiles one model with every effect present and switches effects on and off with
a mask: adding, removing or refitting an effect never recompiles. ``null`` parameters mean "no
effect"; the score test differentiates there. Every effect is defined for any robot: per wire, per
segment or global, as its physics says (``model.structure`` has the wire counts; wires are numbered
segment by segment, proximal first).

Hooks (traced): ``on_params(theta, phys, model, on)`` changes the physical parameters (the dict of
:meth:`~tension_zones.model.Robot.params`), ``on_inputs(theta, inputs, model, on)`` the per-sample
inputs (``q``, ``f``, ``direction``, ``reset``), ``on_outputs(theta, out, model, on)`` the predicted tip
(``out["p"]`` (N, 3) in the measurement frame, ``out["R"]`` (N, 3, 3)). ``on`` maps every effect's name
to a traced 0/1: whether it is part of the model being evaluated (for an effect whose parameters
overlap another's, e.g. per-wire angles and a per-segment rotation of the pattern).
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import jax.numpy as jnp
import numpy as np


@dataclasses.dataclass(frozen=True)
class Effect:
    """Base class: subclasses set ``name`` and ``doc`` and override ``size`` and the hooks they need."""

    name = "effect"
    #: one line for the report: what the effect is physically
    doc = ""
    #: True for an effect that switches the model's solver when it is on (its parameters have no
    #: sensitivity while it is off): the score test then evaluates the Jacobian with it on, at null
    scored_on = False
    #: True for an effect with no sensitivity unless the model carries a load (tip force or weight):
    #: the loop does not score it while the model has none (its score would be exactly 0)
    needs_load = False
    #: True for an effect whose state depends on the samples before (a hysteresis of the solved
    #: bending): while it is on, the model's ``with_memory`` variant predicts the whole recording
    memory = False
    #: True for an effect of the clock rather than the path (a drift): besides the loop's tests, it must
    #: predict the recording's later samples when fitted on its earlier ones (``Fits.later``), since
    #: held-out groups interleaved with its training samples only test an interpolation
    of_time = False
    #: The name of an effect whose parameters include this one's as a special case (a per-segment
    #: value of a per-wire one): where both refits pass, the larger is kept only if its extra
    #: parameters buy a significant drop over this one (a nested chi-square test, ``_loop``)
    special_case_of: ClassVar[str | None] = None

    # -- parameters (concrete NumPy, from the model and its declared physical parameters) ----------
    def size(self, model, phys0) -> int:
        raise NotImplementedError

    def null(self, model, phys0) -> np.ndarray:
        return np.zeros(self.size(model, phys0))

    def pieces_for(self, model) -> int:
        """Constant-curvature pieces per segment that ``model`` needs while the effect is on (the rod
        model); 1: none. More than 1: the calibration then runs a second program, the model's
        ``with_pieces`` variant."""
        return 1

    def start(self, model, phys0) -> np.ndarray:
        """Where a refit that adds the effect starts (default: ``null``, where it was scored)."""
        return self.null(model, phys0)

    def bounds(self, model, phys0) -> tuple[np.ndarray, np.ndarray]:
        n = self.size(model, phys0)
        return np.full(n, -np.inf), np.full(n, np.inf)

    def labels(self, model, phys0) -> list[str]:
        """One name (with unit) per parameter, for the report."""
        return [f"{self.name}[{i}]" for i in range(self.size(model, phys0))]

    def report_values(self, theta, model, phys0) -> np.ndarray:
        """Parameters in the units of :meth:`labels` (default: as fitted). Elementwise in ``theta``."""
        return np.asarray(theta, float)

    # -- hooks (traced; theta is this effect's slice of the parameter vector) ---------------------
    def on_params(self, theta, phys, model, on):
        return phys

    def on_inputs(self, theta, inputs, model, on):
        return inputs

    def on_outputs(self, theta, out, model, on):
        return out


def wire_labels(prefix: str, unit: str, model) -> list[str]:
    return [f"{prefix}_{k + 1}_{unit}" for k in range(model.structure.n_wires)]


def segment_labels(prefix: str, unit: str, model) -> list[str]:
    S = model.structure.n_segments
    return [f"{prefix}_{unit}"] if S == 1 else [f"{prefix}_{j + 1}_{unit}" for j in range(S)]


def segment_pitch_radii(model, phys0) -> np.ndarray:
    """(S,) each segment's pitch radius: the mean radius of its own wires in it."""
    st = model.structure
    rr = np.asarray(phys0["route_radii"])
    return np.array([rr[st.owner == j, j].mean() for j in range(st.n_segments)])


def replace(d: dict, **changes) -> dict:
    out = dict(d)
    out.update(changes)
    return out


def per_owner(model, values):
    """A per-segment array (S,) as each wire's value (N,) (its owner segment's)."""
    return jnp.asarray(values)[model.structure.owner]
