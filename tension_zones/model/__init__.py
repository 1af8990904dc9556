"""The model: a segment (:class:`Design`) and a robot of one or more segments (:class:`Robot`).

Constant-curvature kinematics written once per segment (``_kinematics``) and chained (``_robot``);
tension zones and masks (``_zones``); tension-only statics and compliance (``_statics``).
"""

from .. import _config  # noqa: F401  (float64 before any array is made)
from ._design import DEFAULT_BACKBONE_EI, DEFAULT_WIRE_STIFFNESS, Design, read_json
from ._kinematics import (
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
from ._statics import (
    PAPER_DELTA_DEG,
    PAPER_THETA_L_DEG,
    PAPER_WRENCH,
    TensionSolution,
    as_wrench,
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
from ._zones import (
    BOUNDARY_TOL,
    TEMPERATURE,
    Sector,
    TensionMap,
    mask_from_score,
    reduced_J_qpsi,
    reduced_J_xq,
    tension_map,
    tension_mask,
    tension_score,
)
