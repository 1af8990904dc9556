"""The loop's share thresholds against the project's own generator (tests/simulator.py).

    python benchmarks/thresholds.py [--quick] [--json OUT.json] [--no-readme]

A refit that passes every significance test (held-out and training drops, ``min_gain``) must also
explain a share of the held-out mean square's excess over the noise floor (``min_excess`` near the
floor, ``SECOND_LOOK_SHARE`` on a second look, the joint look's ``min_excess`` together). The share
guards against structure the library lacks, which a flexible effect explains in part, not against
noise (the chi-square tests do that), so its value rests on generated data: sets with known
undeclared effects, one and several segments, each library effect alone, pairs, none, and an
effect outside the library (a tracker drift along the acquisition) at several amplitudes. Every
refit that passed the other tests is labelled *true* (its effect is in the set) or *false*; the
threshold must lie above what false effects explain and below what true ones do. The structure
flag's ``EXCESS_RATIO`` likewise: above where complete models end, below where a drift leaves them. Written into
``benchmarks/README.md`` between the THRESHOLDS markers.
"""

from __future__ import annotations

import argparse
import inspect
import json
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from simulator import RobotTruth, Truth, write_robot_set, write_set

import tension_zones as tz
from tension_zones.calibration import calibrate, read_csv, read_opencr
from tension_zones.calibration._loop import EXCESS_RATIO, EXCESS_SCALE, SECOND_LOOK_SHARE, STRUCTURE_Z

MIN_EXCESS = inspect.signature(calibrate).parameters["min_excess"].default

#: one segment: each effect alone, pairs, none, and the drift outside the library (name, truth, effects in it)
ONE = [
    ("backlash", Truth(play=(0.2, 0.3, 0.15)), {"backlash"}),
    ("friction", Truth(friction=0.2), {"friction"}),
    ("wire_angle_offset", Truth(angle_offsets_deg=(4.0, -3.0, 5.0)), {"wire_angle_offset"}),
    ("wire_stiffness", Truth(stiffness_factors=(0.6, 1.0, 1.5)), {"wire_stiffness"}),
    ("preload", Truth(d_preload=(3.0, -1.5, 0.0)), {"preload"}),
    ("pretension", Truth(d_preload=(2.0, 2.0, 2.0)), {"pretension"}),
    ("tip_force", Truth(tip_force=(0.3, -0.4, -0.8)), {"tip_force"}),
    ("registration", Truth(rotation_deg=(1.0, -0.8, 1.5), translation=(0.4, -0.3, 0.5)), {"registration"}),
    ("geometry", Truth(d_length=0.4, d_radius=0.15), {"geometry"}),
    (
        "backlash+registration",
        Truth(play=(0.25, 0.25, 0.25), rotation_deg=(0.0, 1.5, 0.0), translation=(0.5, 0.0, -0.4)),
        {"backlash", "registration"},
    ),
    (
        "4w angles+friction",
        Truth(n_wires=4, angle_offsets_deg=(5.0, 0.0, -4.0, 3.0), friction=0.15),
        {"wire_angle_offset", "friction"},
    ),
    ("preload+drift 0.25", Truth(d_preload=(3.0, -1.5, 0.0), drift_mm=0.25), {"preload"}),
    ("none", Truth(), set()),
    *[(f"drift {a}", Truth(drift_mm=a), set()) for a in (0.1, 0.25, 0.5, 1.0)],
]
#: several segments (tests/simulator.py ROBOT: 3 + 4 wires), in an unregistered tracker frame
MANY = [
    ("robot backlash", RobotTruth(play=(0.3, 0.2, 0.4, 0.25, 0.3, 0.2, 0.35)), {"backlash"}),
    ("robot preload", RobotTruth(d_preload=(6.0, -3.0, 0.0, 4.0, 0.0, -5.0, 2.0)), {"preload"}),
    ("robot pretension", RobotTruth(d_preload=(6.0, 6.0, 6.0, -5.0, -5.0, -5.0, -5.0)), {"pretension"}),
    ("robot clearance", RobotTruth(clearance=(0.1, 0.3)), {"clearance"}),
    ("robot marker", RobotTruth(marker=(3.0, -2.0, 4.0)), {"marker"}),
    (
        "robot geometry+backlash",
        RobotTruth(d_length=(2.0, -3.0), d_radius=(0.3, -0.4), play=(0.3, 0.2, 0.4, 0.25, 0.3, 0.2, 0.35)),
        {"geometry", "backlash"},
    ),
    ("robot none", RobotTruth(), set()),
    *[(f"robot drift {a}", RobotTruth(drift_mm=a), set()) for a in (0.4, 1.0)],
]


def _calibrate_one(folder, name, truth, seed):
    csv, dj = write_set(folder, name.replace(" ", "_").replace("+", "_"), truth, 240, seed=seed)
    design = tz.Design.from_json(dj)
    return calibrate(read_csv(csv, design.n_wires, float(design.length)), design).to_json()


def _calibrate_many(folder, name, truth, seed):
    train_csv, _, design = write_robot_set(folder, name.replace(" ", "_").replace("+", "_"), truth, seed=seed)
    robot = tz.Robot.from_json(design)
    train = read_opencr(train_csv, n_wires=robot.n_wires)
    return calibrate(train, robot).to_json()


def refits(rep: dict, truth: set, label: str) -> list[dict]:
    """Every refit of a report whose held-out and training drops were significant (whatever its share),
    with the share it explained and the share it needed (``SECOND_LOOK_SHARE`` on a second look),
    labelled with whether its effect is in the set."""
    second = {(c["round"], c["name"]) for c in rep["candidates"] if c.get("second_look")}
    out = []
    for rd in rep["rounds"]:
        for t in rd["tried"]:
            needed = max(t["share_needed"], SECOND_LOOK_SHARE if (rd["round"], t["name"]) in second else 0.0)
            if t["sse_drop"] > t["needed"] and t["sse_drop_train"] > t["needed"] and needed > 0:
                out.append(
                    {
                        "set": label,
                        "outside": not truth,
                        "round": rd["round"],
                        "name": t["name"],
                        "true": t["name"] in truth,
                        "share": t["share_held_out"],
                        "needed": needed,
                        "ratio": rd["rmse_held_out_mm"] / rep["noise_floor_mm"],
                    }
                )
        jl = rd.get("joint_look")
        if jl and jl["added"] and jl["sse_drop"] > jl["needed"]:  # several effects that explain the share together
            out.append(
                {
                    "set": label,
                    "outside": not truth,
                    "round": rd["round"],
                    "name": " + ".join(jl["added"]),
                    "true": set(jl["added"]) <= truth,
                    "share": jl["share_held_out"],
                    "needed": jl["share_needed"],
                    "ratio": jl["rmse_before_mm"] / rep["noise_floor_mm"],
                }
            )
    return out


def _extreme(rows, fn):
    if not rows:
        return "-"
    r = fn(rows, key=lambda r: r["share"] / r["needed"])
    return f"{r['share'] / r['needed']:.2f} ({r['name']}, {r['set']}: {r['share']:.3f} of {r['needed']:.3f})"


def _final_ratio(rep: dict) -> float:
    return rep["rmse_after_mm"] / rep["noise_floor_mm"]


def _excess_ratio(reports, wrong) -> str:
    """The flag's ratio must lie above the final held-out error / floor of every complete model (a set
    named exactly, nothing outside the library: none may be flagged) and below that of the sets with a
    tracker drift outside the library (all should be)."""
    outside = {k: rep for k, (rep, truth) in reports.items() if "drift" in k}  # a tracker drift (the sets' names)
    complete = {k: rep for k, (rep, truth) in reports.items() if k not in wrong and k not in outside}

    def side(group, fn):
        k = fn(group, key=lambda k: _final_ratio(group[k]))
        flagged = sum(bool(r["unexplained_structure"]) for r in group.values())
        return f"{fn.__name__} {_final_ratio(group[k]):.3f} ({k}), flagged {flagged} of {len(group)}"

    return (
        f"`EXCESS_RATIO` = {EXCESS_RATIO:g} (structure flagged where the final held-out RMSE is more than "
        f"that many floors, with z > {STRUCTURE_Z:g}; or by the other structure tests). Final held-out / "
        f"floor: sets named exactly, nothing outside the library: {side(complete, max)}; a drift outside it: "
        f"{side(outside, min)}."
    )


def markdown(rows, reports, seeds) -> str:
    """Two sides of the share test: refits of an effect that is in the set must explain more than it
    needs (smallest share / needed), refits on sets whose structure is outside the library (only
    false effects) less (largest share / needed); a refit of a false effect beside the true one in
    an in-library set is told apart by the lower held-out error, not by the share."""
    lines = [
        (
            f"{len(reports)} generated sets (seeds {', '.join(map(str, seeds))}), {len(rows)} refits whose held-out "
            f"and training drops were significant. `min_excess` = {MIN_EXCESS}, `EXCESS_SCALE` = "
            f"{EXCESS_SCALE:g} (the share needed falls as 1 / ratio beyond that many noise floors), "
            f"`SECOND_LOOK_SHARE` = {SECOND_LOOK_SHARE}. Share explained / share needed:"
        ),
        "",
        "| held-out error | effects in the set: smallest | outside the library: largest |",
        "|---|---|---|",
    ]
    for title, part in (
        (f"within {EXCESS_SCALE:g} floors", [r for r in rows if r["ratio"] <= EXCESS_SCALE]),
        (f"beyond {EXCESS_SCALE:g} floors", [r for r in rows if r["ratio"] > EXCESS_SCALE]),
    ):
        lines.append(
            f"| {title} | {_extreme([r for r in part if r['true']], min)} | "
            f"{_extreme([r for r in part if r['outside']], max)} |"
        )
    wrong = {
        label: (rep, truth) for label, (rep, truth) in reports.items() if {e["name"] for e in rep["effects"]} != truth
    }
    lines += ["", _excess_ratio(reports, wrong)]
    lines += [
        "",
        (
            f"{len(reports) - len(wrong)} of {len(reports)} sets named exactly the effects they hold; "
            "the others (held-out error / noise floor at the end):"
        ),
        "",
        "| set | holds | named | held-out / floor |",
        "|---|---|---|---|",
    ]
    for label, (rep, truth) in wrong.items():
        named = ", ".join(e["name"] for e in rep["effects"]) or "nothing"
        lines.append(
            f"| {label} | {', '.join(sorted(truth)) or 'nothing of the library'} | {named} | "
            f"{rep['rmse_after_mm'] / rep['noise_floor_mm']:.2f} |"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="one seed, one segment only")
    ap.add_argument("--json", help="write every labelled refit here")
    ap.add_argument("--no-readme", action="store_true")
    args = ap.parse_args(argv)
    seeds = (1,) if args.quick else (1, 2)
    sets = [(f, *s) for s in ONE for f in (_calibrate_one,)]
    if not args.quick:
        sets += [(_calibrate_many, *s) for s in MANY]
    rows, reports = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            for fn, name, truth, effects in sets:
                label = f"{name}, seed {seed}"
                rep = fn(Path(tmp), name, truth, seed)
                reports[label] = (rep, effects)
                rows += refits(rep, effects, label)
                print(f"{label}: {', '.join(e['name'] for e in rep['effects']) or 'nothing'}", flush=True)
    md = markdown(rows, reports, seeds)
    print(md)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    if not args.no_readme:
        from _readme import write_section

        write_section("THRESHOLDS", md, "The loop's share thresholds on generated sets")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
