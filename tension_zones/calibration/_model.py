"""The robot as the calibration loop sees it: declared parameters, per-sample inputs, predictions.

A *model* is any hashable object with

* ``physical(robot) -> phys``: the declared physical parameters, a dict pytree;
* ``inputs(data) -> inputs``: per-sample arrays (sample axis first) derived from a ``Dataset``
  (``inputs(data, clock)`` where the calibration passes the fit data's clock: :func:`elapsed_hours`);
* ``predict(phys, inputs) -> {"p": (N, 3), "R": (N, 3, 3)}``: the tip for every sample;
* ``structure``: the static wire counts (:class:`~tension_zones.model.Structure`) the effects read;
* optionally ``start(n, dtype) -> state`` and ``predict(phys, inputs, state=state)``, which then also
  returns ``"state"``: a per-sample state (sample axis first) from which a prediction for nearby
  parameters is cheaper (the fits pass it from one pass to the next: :func:`tension_zones._lsq.levenberg_marquardt`).

:class:`RobotModel` is the package's: the equilibrium of :mod:`tension_zones.model._equilibrium`
for any number of segments, one ``vmap`` over the samples.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from ..model import Robot, Structure
from ..model._equilibrium import (
    bending_memory,
    cold_state,
    compressed_lengths,
    elastic_stiffness,
    solve_warm,
)
from ..model._robot import chain_tip
from ._data import Dataset


@jax.jit
def motion_direction(q, reset=None):
    """Last direction of motion of each wire, (N, n): +1 released, -1 pulled in, 0 not yet moved.

    A stationary sample keeps the previous direction (that is what friction and backlash remember);
    ``reset`` (N,) 0/1 restarts it where a recording starts.
    """
    q = jnp.asarray(q)
    reset = jnp.zeros(q.shape[0], q.dtype) if reset is None else jnp.asarray(reset, q.dtype)
    dq = jnp.diff(q, axis=0, prepend=q[:1])

    def step(prev, xs):
        d, r = xs
        prev = jnp.where(r > 0, 0.0, prev)
        cur = jnp.where(d > 0, 1.0, jnp.where(d < 0, -1.0, prev))
        cur = jnp.where(r > 0, 0.0, cur)
        return cur, cur

    _, out = jax.lax.scan(step, jnp.zeros(q.shape[1], q.dtype), (dq, reset))
    return out


def data_clock(data: Dataset):
    """The drift's clock of a recording the model is fitted on: ``(origin, span)``, its first timestamp
    (s) and its length (hours); None without timestamps."""
    if data.timestamp is None:
        return None
    t = np.asarray(data.timestamp, float)
    return float(t[0]), float((t[-1] - t[0]) / 3600.0)


def elapsed_hours(data: Dataset, clock=None) -> np.ndarray:
    """(N,) hours on ``clock`` (:func:`data_clock` of the fit data; default: ``data``'s own), held
    within its span: the drift effect's time. A recording before or after the fit data (a validation
    file, new commands) takes the drift at the nearest end of the fitted time, never a trend
    extrapolated; one without timestamps the drift at the end. Zeros without a clock."""
    clock = data_clock(data) if clock is None else clock
    if clock is None:
        return np.zeros(data.n_samples)
    origin, span = clock
    if data.timestamp is None:
        return np.full(data.n_samples, span)
    return np.clip((np.asarray(data.timestamp, float) - origin) / 3600.0, 0.0, span)


@jax.jit
def _declared(robot: Robot) -> dict:
    """``robot.params()`` with no curvature freedom (see :class:`RobotModel`): one small program (run
    eagerly, its operations would be compiled one at a time, some 15 of them, in every process)."""
    phys = robot.params()
    phys["curvature_freedom"] = jnp.zeros_like(phys["curvature_freedom"])
    phys["bending_friction"] = jnp.zeros_like(phys["EI"])  # none declared: an effect (bending_friction)
    phys["axial_compliance"] = jnp.zeros_like(phys["EI"])  # none declared: an effect (compression)
    return phys


@dataclasses.dataclass(frozen=True)
class RobotModel:
    """Any robot of the package (one segment or many) for the loop; hashable (only its wire counts and
    the pieces per segment: 1, constant curvature; more, the rod model). The declared
    ``curvature_freedom`` is 0 here: a model in pieces is constant curvature until the
    ``variable_curvature`` effect frees it. With ``memory`` the bending's friction
    (``phys["bending_friction"]``, :func:`~tension_zones.model._equilibrium.bending_memory`) acts
    along the acquisition order: each prediction is then of the whole recording (``path``)."""

    structure: Structure
    memory: bool = False

    @classmethod
    def of(cls, robot: Robot, pieces: int = 1) -> RobotModel:
        return cls(Structure(robot.n_wires_per_segment, pieces))

    def with_pieces(self, pieces: int) -> RobotModel:
        """The same robot solved with ``pieces`` per segment (the calibration's rod variant)."""
        return dataclasses.replace(self, structure=dataclasses.replace(self.structure, pieces=int(pieces)))

    def with_memory(self) -> RobotModel:
        """The same robot with the bending's friction: a prediction depends on the samples before."""
        return dataclasses.replace(self, memory=True)

    @property
    def path(self) -> bool:
        """Whether a sample's prediction depends on the samples before it (then :meth:`predict` takes
        the whole recording, in order)."""
        return self.memory

    def physical(self, robot: Robot) -> dict:
        if robot.n_wires_per_segment != self.structure.n_wires_per_segment:
            raise ValueError(
                f"the robot has wire counts {robot.n_wires_per_segment}, the model {self.structure.n_wires_per_segment}"
            )
        return _declared(robot)

    def inputs(self, data: Dataset, clock=None) -> dict:
        """Per-sample inputs; ``clock``: the drift's (:func:`elapsed_hours`)."""
        if data.n_wires != self.structure.n_wires:
            raise ValueError(f"the data have {data.n_wires} wire columns, the robot {self.structure.n_wires} wires")
        q = jnp.asarray(data.q)
        reset = jnp.asarray(data.reset, q.dtype)
        return {
            "q": q,
            "f": jnp.asarray(data.f),
            "direction": motion_direction(q, reset),
            "reset": reset,
            "hours": jnp.asarray(elapsed_hours(data, clock), q.dtype),
        }

    @staticmethod
    def loaded(phys, inputs):
        """Whether the robot carries a load (a known or fitted tip force, or a weight): a bool scalar
        for all samples. Unloaded, the solve takes its cheap path and the rod is constant curvature."""
        return jnp.any(inputs["f"] != 0) | jnp.any(phys["gravity"] != 0)

    def start(self, n: int, dtype=float):
        """The equilibria's cold start for ``n`` samples (:func:`~tension_zones.model._equilibrium.cold_state`)."""
        x, HL = cold_state(self.structure, dtype)
        return jnp.broadcast_to(x, (n,) + x.shape), jnp.broadcast_to(HL, (n,) + HL.shape)

    def predict(self, phys, inputs, state=None):
        """Tip positions and orientations for all samples (one vmap over the equilibrium). With
        ``state`` (:meth:`start`, or a previous prediction's ``"state"``: each sample's equilibrium
        and the load curvature its solve learnt) the solves start there, and the result has the new
        ``"state"`` too: a fit's next pass, at nearby parameters, then takes fewer Newton iterations
        (about half as many as a cold solve; the learnt curvature is part of the gain, the
        equilibrium alone gives less)."""
        st = self.structure
        loaded = self.loaded(phys, inputs)  # one flag for all samples (outside the vmap)
        s0 = self.start(inputs["q"].shape[0], inputs["q"].dtype) if state is None else state
        B, s1 = jax.vmap(lambda q, f, d, s: solve_warm(phys, st, q, f, d, s, loaded=loaded))(
            inputs["q"], inputs["f"], inputs["direction"], s0
        )
        if self.memory:
            K = jax.vmap(lambda q, f, d, b: elastic_stiffness(phys, st, q, f, d, b, loaded))(
                inputs["q"], inputs["f"], inputs["direction"], B
            )
            h = jnp.repeat(phys["bending_friction"], st.pieces)
            B = bending_memory(B.reshape(B.shape[0], -1), K, h, inputs["reset"]).reshape(B.shape)
        lengths = jax.vmap(lambda q, f, d, b: compressed_lengths(phys, st, q, f, d, b))(
            inputs["q"], inputs["f"], inputs["direction"], B
        )
        p, R = jax.vmap(chain_tip)(lengths, B)
        return {"p": p, "R": R} if state is None else {"p": p, "R": R, "state": s1}
