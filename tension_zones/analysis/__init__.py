"""Analysis: single-pose (one segment) and single-configuration (a robot) performance measures and the sweep engine that evaluates them over grids."""

from .. import _config  # noqa: F401  (float64 before any array is made)
from ._chain import config_measures, config_metrics, zonotope_max_sq
from ._metrics import DEFAULT_DQ, MEASURES, pose_measures, pose_metrics, zonogon_vertices
from ._samples import config_samples, halton
from ._sweep import (
    REDUCTIONS,
    compiled_chunk_count,
    grid_deg,
    sweep_configs,
    sweep_designs,
    sweep_grid,
    sweep_poses,
)

__all__ = [
    "DEFAULT_DQ",
    "MEASURES",
    "REDUCTIONS",
    "compiled_chunk_count",
    "config_measures",
    "config_metrics",
    "config_samples",
    "grid_deg",
    "halton",
    "pose_measures",
    "pose_metrics",
    "sweep_configs",
    "sweep_designs",
    "sweep_grid",
    "sweep_poses",
    "zonogon_vertices",
    "zonotope_max_sq",
]
