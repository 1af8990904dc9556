"""The bounds meet hardware: the same command reached along two histories, against the reduced and
the push-pull uncertainty bounds of the calibrated robot.

    python benchmarks/hysteresis.py [--no-readme] [--forced DIR]

**Pairs** (:func:`tension_zones.calibration.path_pairs`): within one pattern of a recording, a
sample against the way to it interpolated at the closest command, where every wire's command agrees
within two servo steps (0.031 mm; the recordings' commands are whole steps of 0.01534 mm) and every
wire that moved in between last moved the other way (``motion_direction``). The measured difference
``|p_a - p_b|`` is raw (the tracker's noise in it: the calibration's noise floor is given beside);
"mismatch" is how far the calibrated robot moves its tip between the pair's two commands.

**Bounds.** At the pair's configuration, the calibrated robot's equilibrium at the sample's command
(``tension_zones.model.equilibrium`` of the robot in its ``calibrated.design.json`` under the weight
of its ``calibrated`` block; constant curvature, no tip force), the largest tip displacement over
each wire's error within its identified play (the backlash's full width): ``dp_max_reduced`` (the
taut wires only, the paper's bound) and ``dp_max_full`` (push-pull). A ratio ``inf``: the
percentile falls among pairs where no taut wire has play (a reduced bound of 0).

Robots: FTDCR v4 (train and validation recordings, the shipped calibration) and FTDCR v6 (its
training recording, the shipped calibration: no backlash identified, so no play; and a calibration
of the same recording with backlash always fitted, run here unless ``--forced DIR`` holds its
``report.json``). Pattern families, where the bound is above the noise floor: the single-tendon
pulls (the other tendons released) and the bending patterns (segments, pairs, all three).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import tempfile
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import tension_zones as tz
from tension_zones.analysis import config_metrics
from tension_zones.calibration import calibrate, calibrated_design, path_pairs, read_opencr, write_report
from tension_zones.model import Load, equilibrium, forward

ROBOTS = {"FTDCR v4": ("ftdcr_v4", ("train.csv", "val.csv")), "FTDCR v6": ("ftdcr_v6", ("train.csv",))}


def recordings(folder: str, files, n_wires: int):
    """The recordings of a robot, the later ones read with the first one's servo map."""
    first = read_opencr(tz.example_path(f"{folder}/{files[0]}"), n_wires=n_wires)
    more = [
        read_opencr(tz.example_path(f"{folder}/{f}"), n_wires=n_wires, servo_ids=first.servo_ids) for f in files[1:]
    ]
    return [first, *more]


def calibrated(design: dict):
    """``(robot, play (N,), load)`` of a calibrated design dict (no play identified: zeros)."""
    robot = tz.Robot.from_dict(design)
    block = tz.Robot.calibrated_block(design)
    play = np.asarray(block.get("wire_play_mm", np.zeros(robot.n_wires)), float)
    g = jnp.asarray(block.get("gravity_N_per_mm", [0.0, 0.0, 0.0]), float)
    return robot, play, Load(jnp.zeros(3), g)


def measure(robot, play, load, data) -> dict:
    """Per pair of ``data``: family, measured difference, mismatch, and both bounds."""
    pairs = path_pairs(data)
    tip = jax.jit(jax.vmap(lambda q: forward(robot, q, load)[0]))
    B = jax.jit(jax.vmap(lambda q: equilibrium(robot, q, load)))(jnp.asarray(pairs.q))
    m = jax.jit(jax.vmap(lambda b: config_metrics(robot, b, play)))(B)
    groups = np.asarray(data.groups, dtype=object)[pairs.back]
    return {
        "pull": np.array([re.search(r"tendon\d+_id\d+_pull", g) is not None for g in groups], bool),
        "measured": pairs.difference,
        "mismatch": np.linalg.norm(np.asarray(tip(jnp.asarray(pairs.q)) - tip(jnp.asarray(pairs.q_out))), axis=1),
        "reduced": np.asarray(m["dp_max_reduced"]),
        "full": np.asarray(m["dp_max_full"]),
    }


def measure_robot(design: dict, folder: str, files) -> dict:
    """:func:`measure` over a robot's recordings, concatenated."""
    robot, play, load = calibrated(design)
    res = [measure(robot, play, load, d) for d in recordings(folder, files, robot.n_wires)]
    return {k: np.concatenate([r[k] for r in res]) for k in res[0]}


def forced_backlash(out: Path) -> dict:
    """FTDCR v6's training recording calibrated with backlash always fitted (the other effects as the
    CLI's defaults): its report (``out/report.json``, written here unless it is there)."""
    path = out / "report.json"
    if not path.exists():
        from tension_zones.calibration.effects import BY_NAME, library, nominal

        design = tz.example_path("ftdcr_v6/design.json")
        robot = tz.Robot.from_json(design)
        data = read_opencr(tz.example_path("ftdcr_v6/train.csv"), n_wires=robot.n_wires)
        lib = tuple(e for e in library(data.frame) if e.name != "backlash")
        res = calibrate(data, robot, nominal=nominal(data.frame) + (BY_NAME["backlash"],), library=lib)
        write_report(res, out, design=str(design))
    return json.loads(path.read_text())


def _ratio_90(ratio) -> float:
    """The 90th percentile of measured / bound, ``inf`` where it falls among pairs with no bound."""
    with np.errstate(invalid="ignore"):
        q = float(np.percentile(ratio, 90))
    return np.inf if np.isnan(q) else q


def _stats(r: dict, mode: str) -> str:
    bound, meas = r[mode], r["measured"]
    if np.all(bound == 0):
        return "0 (no play)"
    ratio = np.where(bound > 0, meas / np.where(bound > 0, bound, 1.0), np.inf)
    return (
        f"{np.median(bound):.2f}; {100 * np.mean(meas <= bound):.0f} %; {np.median(ratio):.2f} / {_ratio_90(ratio):.2f}"
    )


def rows(label: str, floor: float, r: dict) -> list[str]:
    """The table's rows of one robot: all pairs, then each pattern family where the bound is above the
    noise (a bound below it says nothing family by family)."""
    out = []
    families = (("tendon pulls", r["pull"]), ("bending", ~r["pull"])) if np.median(r["reduced"]) > floor else ()
    for name, keep in (("all", np.ones_like(r["pull"])), *families):
        sub = {k: v[keep] for k, v in r.items()}
        if sub["measured"].size == 0:
            continue
        meas = sub["measured"]
        cells = [f"{label}: {name}", f"{meas.size} ({np.sum(meas > 2 * floor)})"]
        cells.append(f"{np.median(meas):.2f} / {np.percentile(meas, 90):.2f}")
        cells += [f"{sub['mismatch'].max():.2f}", _stats(sub, "reduced"), _stats(sub, "full")]
        out.append("| " + " | ".join(cells) + " |")
    return out


def table(results) -> str:
    """``results``: (label, noise floor, per-pair dict) per robot."""
    head = [
        (
            "| robot (noise floor, mm): patterns | pairs (> 2 floors) | measured (mm): median / 90th pct "
            "| mismatch, max (mm) | reduced bound (mm): median; pairs inside; measured / bound: median / 90th pct "
            "| push-pull: the same |"
        ),
        "|---|---|---|---|---|---|",
    ]
    return "\n".join(head + [line for res in results for line in rows(*res)])


def measure_all(forced_dir: Path) -> list[tuple[str, float, dict]]:
    """Every robot's pairs and bounds; FTDCR v6 with its shipped calibration and the forced one."""
    out = []
    for name, (folder, files) in ROBOTS.items():
        report = json.loads(tz.example_path(f"{folder}/calibration.json").read_text())
        design = json.loads(tz.example_path(f"{folder}/calibrated.design.json").read_text())
        floor = report["noise_floor_mm"]
        out.append((f"{name} ({floor:.2f})", floor, measure_robot(design, folder, files)))
    forced = forced_backlash(forced_dir)
    design = calibrated_design(forced["parameters"], (3, 3, 3))
    floor = forced["noise_floor_mm"]
    out.append((f"FTDCR v6, backlash forced ({floor:.2f})", floor, measure_robot(design, *ROBOTS["FTDCR v6"])))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--no-readme", action="store_true", help="do not rewrite benchmarks/README.md")
    p.add_argument("--forced", help="folder of the forced-backlash calibration's report.json (made if missing)")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        md = table(measure_all(Path(args.forced or Path(tmp) / "forced")))
    print(md)
    if not args.no_readme:
        from _readme import write_section

        write_section("HYSTERESIS", md, "The bounds meet hardware: one command, two histories")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
