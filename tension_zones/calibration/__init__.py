"""Closing the loop with measured data (issue 6): forward model, calibration, residual diagnosis.

* :mod:`.forward` - the kinetostatic single-segment model (MODEL.md Sec. 5), implicit derivatives;
* :mod:`.data` - measurement sets (MODEL.md Sec. 6) with validation;
* :mod:`.effects` - the effect library (one module per effect);
* :mod:`.model` - a model plus effects as one parameter vector; bounded robust Levenberg-Marquardt;
* :mod:`.diagnose` - noise floor, structure tests, score tests;
* :mod:`.loop` - :func:`calibrate`; :mod:`.report` - report.json / report.md / plots.
"""

from .data import DataError, Dataset, load_csv
from .diagnose import noise_floor, score_test, structure_test
from .effects import LIBRARY, NOMINAL, Effect
from .forward import SegmentModel, equilibrium, motion_direction, tip_position
from .loop import Result, calibrate
from .model import Problem
from .report import write_report

__all__ = ["LIBRARY", "NOMINAL", "DataError", "Dataset", "Effect", "Problem", "Result", "SegmentModel",
           "calibrate", "equilibrium", "load_csv", "motion_direction", "noise_floor", "score_test",
           "structure_test", "tip_position", "write_report"]
