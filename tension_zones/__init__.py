"""tension-zones: pull-only (tendon) actuation analysis for continuum robots, in JAX.

Importing the package enables float64 in JAX (see :mod:`tension_zones._config`).
"""

from . import _config  # noqa: F401  (must run before any array is made)
from .model import DEFAULT_BACKBONE_EI, DEFAULT_WIRE_STIFFNESS, Design
from .model import (
    THETA_0,
    J_qb,
    J_qpsi,
    J_xb,
    J_xpsi,
    J_xq,
    b_to_psi,
    jacobians,
    over_grid,
    psi_to_b,
    tip_pose,
    tip_pose_b,
    wire_lengths,
    wire_lengths_b,
)
from .design import evaluate_design, optimize, spread
from .design import Scenario, load_scenario, parse_scenario
from .analysis import DEFAULT_DQ, pose_measures, pose_metrics, zonogon_vertices
from .analysis import grid_deg, sweep_grid, sweep_poses
from .analysis import sweep_designs  # issue 16
from .design import Space, explore, explore_designs, load_space, parse_space, pareto_front  # issue 16
from .model import (
    PAPER_DELTA_DEG,
    PAPER_THETA_L_DEG,
    PAPER_WRENCH,
    TensionSolution,
    compliance,
    compliance_grid,
    compliance_pose,
    compliance_pose_jit,
    min_norm_tensions,
    stiffness_b,
    stiffness_psi,
    taut_mask,
    tensions,
)
from .model import (
    BOUNDARY_TOL,
    TEMPERATURE,
    Sector,
    TensionMap,
    reduced_J_qpsi,
    reduced_J_xq,
    tension_map,
    tension_mask,
    tension_score,
)

from .calibration import (  # noqa: E402
    DataError,
    Dataset,
    calibrate,
    load_data,
    read_csv,
    read_opencr,
    write_report,
)
from .model import Load, Robot, equilibrium, forward  # noqa: E402
from ._examples import copy_examples, example_path, list_examples  # noqa: E402

__version__ = "0.1.0"

__all__ = [
    "BOUNDARY_TOL",
    "DataError",
    "Dataset",
    "calibrate",
    "copy_examples",
    "example_path",
    "list_examples",
    "equilibrium",
    "forward",
    "Load",
    "Robot",
    "read_csv",
    "read_opencr",
    "load_data",
    "write_report",
    "DEFAULT_BACKBONE_EI",
    "DEFAULT_DQ",
    "DEFAULT_WIRE_STIFFNESS",
    "Design",
    "J_qb",
    "J_qpsi",
    "J_xb",
    "J_xpsi",
    "J_xq",
    "PAPER_DELTA_DEG",
    "PAPER_THETA_L_DEG",
    "PAPER_WRENCH",
    "Sector",
    "TEMPERATURE",
    "THETA_0",
    "TensionMap",
    "TensionSolution",
    "b_to_psi",
    "grid_deg",
    "compliance",
    "evaluate_design",
    "load_scenario",
    "optimize",
    "parse_scenario",
    "Scenario",
    "spread",
    "compliance_grid",
    "compliance_pose",
    "compliance_pose_jit",
    "jacobians",
    "min_norm_tensions",
    "over_grid",
    "pose_measures",
    "pose_metrics",
    "psi_to_b",
    "reduced_J_qpsi",
    "reduced_J_xq",
    "sweep_grid",
    "sweep_poses",
    "stiffness_b",
    "stiffness_psi",
    "taut_mask",
    "tension_map",
    "tension_mask",
    "tension_score",
    "tensions",
    "tip_pose",
    "tip_pose_b",
    "wire_lengths",
    "wire_lengths_b",
    "zonogon_vertices",
    # issue 16: design-space exploration
    "Space",
    "explore",
    "explore_designs",
    "load_space",
    "parse_space",
    "pareto_front",
    "sweep_designs",
]
