"""A candidate effect for FTDCR v4, tried through ``calibrate(library=...)`` before it joins the library.

    python benchmarks/ftdcr_clearance.py

**Hole clearance.** A wire under tension hugs the side of each disk's hole nearest the centre of
curvature, so its path through a bent piece is shorter than the pitch-radius arc by about ``c |theta|``
(``c`` the clearance, ``theta`` the piece's bending angle), whatever the wire's angle: the wires of a
distal segment slacken as the proximal segments they cross bend, in any direction. Constant-curvature
routing (MODEL.md) has no such term, and it would show where several segments bend at once: the
validation file's all-segment patterns bend less than the model says (``benchmarks/README.md``, *The
FTDCR v4 robot*). Here it is an input stage, each wire's command shifted by
``c_own |theta_own| + c_prox sum |theta_proximal|`` with the bending the commands ask for (the declared
routing matrix's least-squares inverse: rigid, taut wires), not the solved one: the model's equilibrium
stays linear in the wires' stretch. A version in the library would put it in the model, with the solved
bending, and in the tests' generator.

Runs the loop on ``train.csv`` with the library and this effect as one more candidate (no worker: the
effect is defined in this script), ``val.csv`` only predicted, and prints the outcome (numbers in
``benchmarks/README.md``).
"""

from __future__ import annotations

import dataclasses
import json
import time

import _ftdcr  # (benchmarks/, the script's folder)
import jax.numpy as jnp
import numpy as np

from tension_zones.calibration import calibrate
from tension_zones.calibration._model import RobotModel
from tension_zones.calibration.effects import library
from tension_zones.calibration.effects._base import Effect, replace
from tension_zones.model._equilibrium import _guarded_norm, routing_matrix


@dataclasses.dataclass(frozen=True)
class HoleClearance(Effect):
    """Commands shifted by ``c_own |theta_own| + c_prox sum |theta_proximal|`` (mm per rad), ``theta``
    the commanded bending of each segment (``inverse`` (2S, N) the declared routing's inverse,
    ``own``/``prox`` (N, S) which segments each wire ends in / crosses before; nested tuples: hashable)."""

    inverse: tuple = ()
    own: tuple = ()
    prox: tuple = ()
    name = "clearance"
    doc = "wire path shortened by c |bending| in every piece it crosses (mm per rad): own segment, proximal ones"

    @classmethod
    def for_robot(cls, robot):
        model = RobotModel.of(robot)
        phys = model.physical(robot)
        crosses = np.asarray(model.structure.crosses, float)  # (N, S)
        A = np.asarray(routing_matrix(phys["route_angles"], phys["route_radii"], model.structure.crosses))
        owner = np.asarray(model.structure.owner)
        own = (owner[:, None] == np.arange(crosses.shape[1])[None, :]).astype(float)
        as_tuple = lambda a: tuple(map(tuple, np.asarray(a, float)))
        return cls(as_tuple(np.linalg.pinv(A)), as_tuple(own), as_tuple(crosses - own))

    def size(self, model, phys0):
        return 2

    def bounds(self, model, phys0):
        return np.full(2, -2.0), np.full(2, 2.0)

    def labels(self, model, phys0):
        return ["c_own_mm_per_rad", "c_prox_mm_per_rad"]

    def on_inputs(self, theta, inputs, model, on):
        q = inputs["q"]
        b = (q @ jnp.asarray(self.inverse).T).reshape(q.shape[0], -1, 2)  # (samples, S, 2)
        n = _guarded_norm(b)  # |theta| per segment (rad), a finite gradient at 0
        shift = theta[0] * n @ jnp.asarray(self.own).T + theta[1] * n @ jnp.asarray(self.prox).T
        return replace(inputs, q=q + shift)


def main():
    robot, report, train, val = _ftdcr.load()
    effect = HoleClearance.for_robot(robot)
    t0 = time.perf_counter()
    res = calibrate(train, robot, validate=val, library=tuple(library(train.frame)) + (effect,), workers=0)
    rep = res.to_json()
    fam = rep["steps"][-1].get("rmse_by_family_mm", {})
    print(json.dumps({"effects": [e["name"] for e in rep["effects"]], "held_out_mm": rep["rmse_after_mm"],
                      "validate_mm": rep["rmse_validate_mm"], "clearance": rep["parameters"]["fitted"].get("clearance"),
                      "by_family_mm": fam, "seconds": time.perf_counter() - t0}, indent=1))
    print("\nWith the shipped report (no clearance): held out "
          f"{report['rmse_after_mm']:.3f} mm, validation {report['rmse_validate_mm']:.3f} mm.")


if __name__ == "__main__":
    main()
