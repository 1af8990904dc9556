"""The effect library: one small module per effect (see :mod:`._base` for what an effect is).

To add an effect, write a module with a frozen ``Effect`` subclass and list an instance in
``LIBRARY``; the loop scores, fits and reports it with no other change.
"""

from ._base import Effect
from .backbone import BackboneEI
from .backlash import Backlash, play
from .bending_friction import BendingFriction
from .clearance import Clearance
from .compression import Compression
from .drift import Drift
from .friction import Friction
from .geometry import Geometry
from .gravity import Gravity
from .marker import Marker
from .offset import Offset
from .pattern_rotation import PatternRotation
from .preload import Preload
from .pretension import Pretension
from .registration import Registration
from .routing_twist import RoutingTwist
from .tip_force import TipForce
from .variable_curvature import VariableCurvature
from .wire_angle_offset import WireAngleOffset
from .wire_stiffness import WireStiffness

#: Every effect, in the order reports list them.
ALL = (
    BackboneEI(),
    PatternRotation(),
    Offset(),
    Registration(),
    Backlash(),
    Friction(),
    WireAngleOffset(),
    RoutingTwist(),
    WireStiffness(),
    Preload(),
    Pretension(),
    TipForce(),
    Gravity(),
    VariableCurvature(),
    Clearance(),
    Compression(),
    Drift(),
    BendingFriction(),
    Marker(),
    Geometry(),
)
#: Always fitted, by the frame of the data: positions in the robot's base frame (tension_zones/MODEL.md Sec. 6), or
#: in an unregistered tracker frame, whose origin and tilt are never known, nor which way each segment's
#: wires point (the registration leaves the turn about the axis to the patterns' rotations).
NOMINAL = {"base": ("backbone_EI",), "tracker": ("backbone_EI", "pattern_rotation", "offset", "registration")}
#: Not candidates either: in the base frame the offset is part of the registration.
EXCLUDED = {"base": ("offset",), "tracker": ()}
#: Candidates only where asked for (``library(frame, opt_in=...)``, the CLI's ``--effects +NAME``): a
#: model with the bending's memory solves the whole recording at every evaluation and measures the
#: play in the stiffness of the backbone and the taut wires, whose derivative in every parameter
#: (third derivatives of the energy) is most of its cost; every refit after it is named runs that
#: model, so a calibration that names it takes several times as long, for a small gain.
OPT_IN = ("bending_friction",)
BY_NAME = {e.name: e for e in ALL}


def library(frame: str = "base", opt_in=()) -> tuple[Effect, ...]:
    """The candidate effects for data in ``frame``: every effect that is not nominal there, the
    ``OPT_IN`` ones only if named in ``opt_in``."""
    unknown = [n for n in opt_in if n not in OPT_IN]
    if unknown:
        raise ValueError(f"{unknown[0]!r} is not an opt-in effect (those are: {', '.join(OPT_IN)})")
    return tuple(
        e for e in ALL if e.name not in NOMINAL[frame] + EXCLUDED[frame] and (e.name not in OPT_IN or e.name in opt_in)
    )


def nominal(frame: str = "base") -> tuple[Effect, ...]:
    return tuple(BY_NAME[n] for n in NOMINAL[frame])


__all__ = [
    "ALL",
    "BY_NAME",
    "NOMINAL",
    "OPT_IN",
    "BackboneEI",
    "Backlash",
    "BendingFriction",
    "Clearance",
    "Compression",
    "Drift",
    "Effect",
    "Friction",
    "Geometry",
    "Gravity",
    "Marker",
    "Offset",
    "PatternRotation",
    "Preload",
    "Pretension",
    "Registration",
    "RoutingTwist",
    "TipForce",
    "VariableCurvature",
    "WireAngleOffset",
    "WireStiffness",
    "library",
    "nominal",
    "play",
]
