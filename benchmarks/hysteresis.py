"""The bounds meet hardware: the same command reached along two histories, against the reduced and
the push-pull uncertainty bounds of the calibrated robot.

    python benchmarks/hysteresis.py [--no-readme]

**Pairs.** :func:`tension_zones.calibration.path_pairs`: each sample on the way back of an out-and-back
pattern against the way out interpolated at the same command (every wire within 0.05 mm); the
measured difference ``|p_back - p_out|`` holds the tracker's noise too (the calibration's floor is
given beside).

**Bounds.** At the sample's configuration (the calibrated robot's equilibrium at its command, constant
curvature, no load), the largest tip displacement over each wire's error within its identified play
(the backlash's full width ``c_k``: the change of a wire's effective displacement when its motion
reverses): ``dp_max_reduced`` (the taut wires only, the paper's bound) and ``dp_max_full`` (push-pull).

Robots: FTDCR v4 (train and validation recordings, the shipped calibration's robot and play) and FTDCR
v6 (its training recording; its calibration identifies no backlash, so its bounds are zero: the row
says what the measured differences are, against nothing).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import jax
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import tension_zones as tz
from tension_zones.analysis import config_metrics
from tension_zones.calibration import calibrated_design, path_pairs, read_opencr
from tension_zones.model import equilibrium


def measure(robot, play, data) -> dict:
    """Per pair (:func:`~tension_zones.calibration.path_pairs`): the measured difference, and the bounds
    at the back sample's configuration."""
    pairs = path_pairs(data)
    B = jax.jit(jax.vmap(lambda x: equilibrium(robot, x)))(pairs.q)
    m = jax.jit(jax.vmap(lambda c: config_metrics(robot, c, play)))(B)
    return {
        "measured": pairs.difference,
        "reduced": np.asarray(m["dp_max_reduced"]),
        "full": np.asarray(m["dp_max_full"]),
        "mismatch": pairs.mismatch,
    }


def row(name: str, r: dict, floor: float, play_note: str) -> str:
    meas = r["measured"]
    cells = [name, f"{meas.size}", f"{np.median(meas):.3f} / {np.percentile(meas, 90):.3f}"]
    cells.append(f"{np.median(r['mismatch']):.3f}")
    cells.append("-" if floor is None else f"{floor:.3f}")
    for mode in ("reduced", "full"):
        bound = r[mode]
        if np.all(bound == 0):
            cells.append("0 (no play identified)")
            continue
        inside = np.mean(meas <= bound)
        ratio = meas / bound
        cells.append(
            f"{np.median(bound):.3f}; {100 * inside:.0f} % inside; "
            f"ratio {np.median(ratio):.2f} / {np.percentile(ratio, 90):.2f}"
        )
    cells.append(play_note)
    return "| " + " | ".join(cells) + " |"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--no-readme", action="store_true", help="do not rewrite benchmarks/README.md")
    args = p.parse_args(argv)
    ex = tz.example_path
    rep = json.loads(ex("ftdcr_v4/calibration.json").read_text())
    v4 = tz.Robot.from_dict(calibrated_design(rep["parameters"], (3, 3, 3)))
    play = np.asarray(tz.Robot.calibrated_block(calibrated_design(rep["parameters"], (3, 3, 3)))["wire_play_mm"])
    v6 = tz.Robot.from_json(ex("ftdcr_v6/design.json"))
    rows = []
    for name, robot, dq, files, floor, note in (
        (
            "FTDCR v4",
            v4,
            play,
            ("ftdcr_v4/train.csv", "ftdcr_v4/val.csv"),
            rep["noise_floor_mm"],
            "shipped calibration: play 0.03-0.21 mm",
        ),
        (
            "FTDCR v6",
            v6,
            np.zeros(v6.n_wires),
            ("ftdcr_v6/train.csv",),
            None,
            "declared design; no backlash identified",
        ),
    ):
        train = read_opencr(ex(files[0]), n_wires=robot.n_wires)
        recordings = [train] + [read_opencr(ex(f), n_wires=robot.n_wires, servo_ids=train.servo_ids) for f in files[1:]]
        res = [measure(robot, dq, data) for data in recordings]
        merged = {k: np.concatenate([r[k] for r in res]) for k in res[0]}
        rows.append(row(name, merged, floor, note))
    md = "\n".join(
        [
            (
                "| robot | pairs | measured difference, median / 90th pct (mm) | command mismatch, median (mm) "
                "| noise floor (mm) | reduced bound: median (mm); pairs inside; measured / bound, median / 90th pct "
                "| push-pull bound: the same | play |"
            ),
            "|---|---|---|---|---|---|---|---|",
            *rows,
        ]
    )
    print(md)
    if not args.no_readme:
        from _readme import write_section

        write_section("HYSTERESIS", md, "The bounds meet hardware: one command, two histories")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
