"""Design: scenario files and the design optimiser."""

from .. import _config  # noqa: F401  (float64 before any array is made)
from ._optimise import evaluate_design, optimize, spread, write_outputs
from ._scenario import DEFAULTS, Scenario, load_scenario, parse_scenario
