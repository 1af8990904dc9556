"""tension-zones: pull-only (tendon) actuation analysis for continuum robots, in JAX.

Importing the package enables float64 in JAX (see :mod:`tension_zones._config`).
"""

from . import _config  # noqa: F401  (must run before any array is made)
from .design import DEFAULT_BACKBONE_EI, DEFAULT_WIRE_STIFFNESS, Design
from .kinematics import (
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
from .zones import (
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

from .calib import (  # noqa: E402  (issue 6: calibration)
    DataError,
    Dataset,
    SegmentModel,
    calibrate,
    equilibrium,
    load_csv,
    write_report,
)

__version__ = "0.1.0"

__all__ = [
    "BOUNDARY_TOL",
    "DataError",
    "Dataset",
    "SegmentModel",
    "calibrate",
    "equilibrium",
    "load_csv",
    "write_report",
    "DEFAULT_BACKBONE_EI",
    "DEFAULT_WIRE_STIFFNESS",
    "TEMPERATURE",
    "THETA_0",
    "Design",
    "J_qb",
    "J_qpsi",
    "J_xb",
    "J_xpsi",
    "J_xq",
    "Sector",
    "TensionMap",
    "b_to_psi",
    "jacobians",
    "over_grid",
    "psi_to_b",
    "reduced_J_qpsi",
    "reduced_J_xq",
    "tension_map",
    "tension_mask",
    "tension_score",
    "tip_pose",
    "tip_pose_b",
    "wire_lengths",
    "wire_lengths_b",
]
