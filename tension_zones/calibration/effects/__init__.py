"""The effect library: one small module per effect (see :mod:`._base` for what an effect is).

To add an effect, write a module with a frozen ``Effect`` subclass and list an instance in
``LIBRARY``; the loop scores, fits and reports it with no other change.
"""

from ._base import Effect
from .backbone import BackboneEI
from .backlash import Backlash, play
from .friction import Friction
from .geometry import Geometry
from .preload import Preload
from .registration import Registration
from .tip_force import TipForce
from .wire_angle_offset import WireAngleOffset
from .wire_stiffness import WireStiffness

#: Always fitted (the identifiable nominal parameters of the single-segment model).
NOMINAL = (BackboneEI(),)
#: Candidate effects, in the order they are listed in reports.
LIBRARY = (Backlash(), Friction(), WireAngleOffset(), WireStiffness(), Preload(), TipForce(),
           Registration(), Geometry())

__all__ = ["LIBRARY", "NOMINAL", "BackboneEI", "Backlash", "Effect", "Friction", "Geometry", "Preload",
           "Registration", "TipForce", "WireAngleOffset", "WireStiffness", "play"]
