"""``tension-zones reproduce``: the paper's figures and tables, one command.

Each section of the paper adds its own step to :data:`STEPS`; a step takes the output folder and the
summary dictionary (written to ``summary.json`` at the end) and returns the files it wrote.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def _tension_maps(out: Path, summary: dict, quiet: bool) -> list[Path]:
    """Paper Figs. 5 and 7: the three- and four-wire tension maps, with their sector tables."""
    import matplotlib.pyplot as plt

    from ..model._design import Design
    from ..model._zones import tension_map
    from ..plots import plot_tension_map

    written = []
    tables = {}
    for n, fig_no in ((3, 5), (4, 7)):
        tmap = tension_map(Design(n, 20.0, 2.0))
        fig, ax = plt.subplots(figsize=(6.4, 6.8))
        plot_tension_map(tmap, ax=ax, title=f"Fig. {fig_no}: tension map, {n} wires")
        path = out / f"fig{fig_no}_tension_map_{n}w.png"
        fig.savefig(path, dpi=130, bbox_inches="tight")
        plt.close(fig)
        written.append(path)
        tables[str(n)] = [{"delta_deg": str(s), "wires": list(s.wires)} for s in tmap.sectors]
    # one taut wire fraction of directions, the figure a designer reads off Figs. 5 and 7
    summary["tension_maps"] = {
        "sectors": tables,
        "one_taut_wire_fraction": {
            str(n): float(
                np.mean([len(tension_map(Design(n, 20.0, 2.0)).taut_at(d)) == 1 for d in np.arange(0.0, 360.0, 0.25)])
            )
            for n in (3, 4)
        },
    }
    return written


def _kinematics(out: Path, summary: dict, quiet: bool) -> list[Path]:
    from ._figures_kinematics import reproduce_kinematics

    return reproduce_kinematics(out, summary, quiet)


def _compliance(out: Path, summary: dict, quiet: bool) -> list[Path]:
    from ._figures_compliance import compliance_step

    return compliance_step(out, summary, quiet)


STEPS = [
    ("tension maps (Figs. 5, 7)", _tension_maps),
    ("kinematic conditioning and pose uncertainty (Sec. 6.1, Figs. 9-12)", _kinematics),
    ("compliance (Sec. 6.2: identification, Figs. 13-14, Tables 1-2)", _compliance),
]


def reproduce(out: Path, quiet: bool = False) -> dict:
    """Reproduce the paper's figures and tables into the folder ``out``.

    Runs :data:`STEPS` in order (tension maps, kinematic conditioning and pose uncertainty, compliance
    with the identification of the paper's unreported segment), writes each figure as a PNG and the
    numbers the paper reports beside ours in ``summary.json``; returns that summary. ``quiet``: no
    progress lines. What ``tension-zones reproduce --out DIR`` runs.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summary: dict = {}
    for name, step in STEPS:
        if not quiet:
            print(f"[reproduce] {name} ...", flush=True)
        for path in step(out, summary, quiet):
            if not quiet:
                print(f"  wrote {path}")
    from .._io import write_text

    write_text(out / "summary.json", json.dumps(summary, indent=2))
    if not quiet:
        print(f"  wrote {out / 'summary.json'}")
    return summary
