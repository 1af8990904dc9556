"""Design: scenario files and the design optimiser; design spaces and their exploration."""

from .. import _config  # noqa: F401  (float64 before any array is made)
from ._explore import STATS, explore, explore_designs, pareto_front
from ._optimise import evaluate_design, optimize, spread
from ._scenario import DEFAULTS, Scenario, load_scenario, parse_scenario
from ._space import Space, halton, load_space, parse_space

__all__ = [
    "DEFAULTS",
    "STATS",
    "Scenario",
    "Space",
    "evaluate_design",
    "explore",
    "explore_designs",
    "halton",
    "load_scenario",
    "load_space",
    "optimize",
    "pareto_front",
    "parse_scenario",
    "parse_space",
    "spread",
]
