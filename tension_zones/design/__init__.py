"""Design: scenario files and the design optimiser."""

from ._optimise import evaluate_design, optimize, spread, write_outputs
from ._scenario import DEFAULTS, Scenario, load_scenario, parse_scenario
from ._explore import STATS, explore, explore_designs, pareto_front, write_front  # issue 16
from ._space import Space, halton, load_space, parse_space  # issue 16
