"""tension-zones: pull-only (tendon) actuation analysis for continuum robots, in JAX.

Importing the package enables float64 in JAX and does nothing else: it imports nothing heavy (every
public name below is loaded from its sub-package on first use, PEP 562, so ``tension-zones --help``
and ``import tension_zones`` do not import JAX), and it leaves ``XLA_FLAGS`` and the file system
alone. The XLA settings and the compilation cache are applied when a sub-package first loads JAX,
before anything is compiled (see :mod:`tension_zones._config`).
"""

import importlib
import os
import sys

# float64 before any array is made: if JAX is not imported yet, its own switch (read when JAX is
# imported) is set here without importing it; if it is, the flag is set now (cheap: JAX is loaded).
# TENSION_ZONES_X64=0 leaves JAX's setting alone (see _config).
if os.environ.get("TENSION_ZONES_X64", "1").strip().lower() not in ("0", "false", "no", "off"):
    if "jax" in sys.modules:
        sys.modules["jax"].config.update("jax_enable_x64", True)
    else:
        os.environ.setdefault("JAX_ENABLE_X64", "1")

__version__ = "0.1.0"

#: Public name -> the sub-package that defines it (one place per concept; loaded on first use).
_WHERE = {
    **dict.fromkeys(
        (
            "DEFAULT_BACKBONE_EI",
            "DEFAULT_WIRE_STIFFNESS",
            "Design",
            "THETA_0",
            "J_qb",
            "J_qpsi",
            "J_xb",
            "J_xpsi",
            "J_xq",
            "b_to_psi",
            "jacobians",
            "over_grid",
            "psi_to_b",
            "tip_pose",
            "tip_pose_b",
            "wire_lengths",
            "wire_lengths_b",
            "PAPER_DELTA_DEG",
            "PAPER_THETA_L_DEG",
            "PAPER_WRENCH",
            "TensionSolution",
            "compliance",
            "compliance_grid",
            "compliance_pose",
            "compliance_pose_jit",
            "min_norm_tensions",
            "stiffness_b",
            "stiffness_psi",
            "taut_mask",
            "tensions",
            "BOUNDARY_TOL",
            "TEMPERATURE",
            "Sector",
            "TensionMap",
            "reduced_J_qpsi",
            "reduced_J_xq",
            "tension_map",
            "tension_mask",
            "tension_score",
        ),
        "model",
    ),
    **dict.fromkeys(("evaluate_design", "optimize", "spread", "Scenario", "load_scenario", "parse_scenario"), "design"),
    **dict.fromkeys(
        ("DEFAULT_DQ", "pose_measures", "pose_metrics", "zonogon_vertices", "grid_deg", "sweep_grid", "sweep_poses"),
        "analysis",
    ),
    **dict.fromkeys(("Load", "Robot", "equilibrium", "forward", "config_compliance", "segment_tension_map"), "model"),
    **dict.fromkeys(
        ("sweep_designs", "sweep_configs", "config_measures", "config_metrics", "config_samples"), "analysis"
    ),
    **dict.fromkeys(("Space", "explore", "explore_designs", "load_space", "parse_space", "pareto_front"), "design"),
    **dict.fromkeys(
        ("DataError", "Dataset", "calibrate", "load_data", "read_csv", "read_opencr", "write_report"), "calibration"
    ),
    **dict.fromkeys(("copy_examples", "example_path", "list_examples"), "_examples"),
}
_SUBPACKAGES = ("model", "analysis", "design", "paper", "calibration", "cli", "plots")

__all__ = list(_WHERE)


def __getattr__(name):
    if name in _WHERE:
        value = getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
        globals()[name] = value  # the next look-up is a plain attribute
        return value
    if name in _SUBPACKAGES:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
