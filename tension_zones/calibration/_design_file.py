"""A calibrated robot as a design file (``calibrated.design.json``): what the design tools read.

The fitted physical parameters (tension_zones/MODEL.md Sec. 5, chained) become a robot design file
(:meth:`tension_zones.model.Robot.from_dict`): per segment its length, backbone EI, its own wires'
angles and pitch radius, and how each wire crosses the proximal segments (``route_angles_deg``,
``route_radii_mm``: the routing twist, the fitted radii). A segment of a design file has one pitch
radius, wire stiffness and preload; the per-wire values the calibration found go, exactly, into the
file's ``calibrated`` block with what the design measures can use of the identified effects: each
wire's play where backlash was identified (mm: the wire displacement uncertainty of ``sweep``), the routing friction, the
weight and the holes' clearance. The segment's own numbers are the means of its wires' (a preload
at least 0).
"""

from __future__ import annotations

from typing import Any

import numpy as np


def _play(fitted: dict, n_wires: int) -> list[float]:
    """Each wire's play (mm): the backlash effect's ``play_k_mm``."""
    params = fitted.get("backlash", {})
    return [float(params.get(f"play_{k + 1}_mm", 0.0)) for k in range(n_wires)]


def calibrated_design(parameters: dict, n_wires_per_segment, report: str = "report.json") -> dict[str, Any]:
    """The design-file dict of a calibrated robot from a report's ``parameters`` (``physical`` and
    ``fitted``, as ``report.json`` holds them) and the robot's wire counts (proximal first)."""
    phys, fitted = parameters["physical"], parameters.get("fitted", {})
    ra, rr = np.asarray(phys["route_angles_deg"], float), np.asarray(phys["route_radii"], float)
    k_w, pre = np.asarray(phys["wire_stiffness"], float), np.asarray(phys["preload"], float)
    segments, k0 = [], 0
    for j, n in enumerate(n_wires_per_segment):
        rows = slice(k0, k0 + n)
        seg: dict[str, Any] = {
            "n_wires": int(n),
            "length_mm": float(phys["length"][j]),
            "pitch_radius_mm": float(np.mean(rr[rows, j])),
            "wire_angles_deg": ra[rows, j].tolist(),
            "wire_stiffness_N_per_mm": float(np.mean(k_w[rows])),
            "backbone_EI_Nmm2": float(phys["EI"][j]),
            "preload_N": max(float(np.mean(pre[rows])), 0.0),
        }
        if j:
            seg["route_angles_deg"] = ra[rows, :j].tolist()
            seg["route_radii_mm"] = rr[rows, :j].tolist()
        segments.append(seg)
        k0 += n
    calibrated = {
        **({"wire_play_mm": _play(fitted, k0)} if "backlash" in fitted else {}),
        "preload_N": pre.tolist(),
        "wire_stiffness_N_per_mm": k_w.tolist(),
        "friction": [float(x) for x in phys.get("friction", [0.0, 0.0])],
        "gravity_N_per_mm": [float(x) for x in phys.get("gravity", [0.0, 0.0, 0.0])],
        "clearance_mm_per_rad": [float(x) for x in phys.get("clearance", [0.0, 0.0])],
        "report": report,
    }
    return {"segments": segments, "calibrated": calibrated}
