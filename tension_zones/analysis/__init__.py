"""Analysis: single-pose performance measures and the sweep engine that evaluates them over grids."""

from ._metrics import DEFAULT_DQ, MEASURES, pose_measures, pose_metrics, zonogon_vertices
from ._sweep import compiled_chunk_count, grid_deg, sweep_grid, sweep_poses
from ._sweep import REDUCTIONS, sweep_designs  # issue 16
