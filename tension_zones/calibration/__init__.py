"""Closing the loop with measured data, for any robot (one segment or many).

* :mod:`._data` - one :class:`Dataset`, readers for the tension_zones/MODEL.md CSV and the OpenCR CSV;
* :mod:`.effects` - the effect library (one module per effect);
* :mod:`._model` - the robot as the loop sees it; :mod:`._problem` - a model plus effects as one
  parameter vector, fitted by the package's least-squares solver, compiled once;
* :mod:`._diagnose` - noise floor, structure tests, score tests;
* :mod:`._loop` - :func:`calibrate`; :mod:`._report` - report.json / report.md / plots;
  :mod:`._baselines` - black-box baselines for the report; :mod:`._hysteresis` - one command reached
  along two histories in a recording; :mod:`._design_file` - a calibrated robot as a design file.
"""

from ._data import READERS, DataError, Dataset, load_data, read_csv, read_opencr
from ._design_file import calibrated_design
from ._diagnose import home_memory, noise_floor, score_test, structure_test
from ._hysteresis import PathPairs, path_pairs
from ._loop import Result, calibrate, predict_report, rmse, rmse_aligned
from ._model import RobotModel, motion_direction
from ._problem import Problem, compilations
from ._report import write_report
from .effects import Effect

__all__ = [
    "READERS",
    "DataError",
    "Dataset",
    "Effect",
    "PathPairs",
    "Problem",
    "Result",
    "RobotModel",
    "calibrate",
    "calibrated_design",
    "compilations",
    "home_memory",
    "load_data",
    "motion_direction",
    "noise_floor",
    "path_pairs",
    "predict_report",
    "read_csv",
    "read_opencr",
    "rmse",
    "rmse_aligned",
    "score_test",
    "structure_test",
    "write_report",
]
