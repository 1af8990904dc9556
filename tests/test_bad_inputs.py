"""Bad inputs: one line, exit status 2, no traceback, nothing overwritten, nothing written.

Two tables, each row one bad input:

* ``CLI``: ``(id, argv, needle)``. ``argv`` is a list of strings in which ``{tmp}`` stands for the
  test's folder; the folder is first filled by :func:`_files` (existing outputs, good and bad input
  files; add a file there when a row needs one). A row passes when ``main(argv)`` returns 2, stderr
  is exactly one line containing ``needle``, no ``Traceback`` is printed, every file that existed
  before is byte for byte unchanged, and no file was added.
* ``API``: ``(id, call, needle)``; ``call`` is a function of no arguments that must raise a
  ``ValueError`` (or ``TypeError``) whose message is one line containing ``needle``.

Calibration rows go in the same tables (``["calibrate", ...]``).
"""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import SMALL_SCENARIO

import tension_zones as tz
from tension_zones.cli import main

GOOD_SCENARIO = {
    "n_wires": [3],
    "theta_L_deg": [30, 80, 50],
    "delta_deg": [0, 350, 50],
    "optimizer": {"starts": 1, "steps": 2},
}


#: A million designs of one chunk each (more than ``MAX_CHUNKS``).
SPACE_CHUNKS = {"n_wires": 3, "sample": {"method": "halton", "designs": 10**6}, "chunks": {"designs": 1}}
#: A million 16-wire designs on a fine grid: more estimated computing than ``MAX_WORK_S``.
SPACE_DAY = {
    "n_wires": 16,
    "sample": {"method": "halton", "designs": 10**6},
    "theta_L_deg": [0, 85, 0.5],
    "delta_deg": [0, 360, 1],
}


def _scaled(lines, columns, factor):
    """CSV lines with ``columns`` multiplied by ``factor``, as text."""
    head = lines[0].split(",")
    idx = [head.index(c) for c in columns]
    out = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        for i in idx:
            cells[i] = repr(float(cells[i]) * factor)
        out.append(",".join(cells))
    return "\n".join(out) + "\n"


def _files(tmp):
    """The inputs and existing outputs the rows refer to."""
    (tmp / "old.png").write_bytes(b"an earlier map")
    (tmp / "old.npz").write_bytes(b"an earlier sweep")
    (tmp / "run").mkdir()
    (tmp / "run" / "result.json").write_text('{"earlier": true}')
    (tmp / "full").mkdir()
    (tmp / "full" / "notes.txt").write_text("someone's notes")
    (tmp / "dir.png").mkdir()
    (tmp / "dir.npz").mkdir()
    (tmp / "file.txt").write_text("a file, not a folder")
    (tmp / "good.json").write_text(json.dumps(GOOD_SCENARIO))
    (tmp / "broken.json").write_text('{"n_wires": [3], ')
    (tmp / "list.json").write_text("[1, 2]")
    (tmp / "latin1.json").write_bytes(b'{"length_mm": 20, "note": "\xe9"}')
    (tmp / "scen_dir.json").mkdir()
    # strict JSON: duplicate keys, non-finite literals, deep nesting
    (tmp / "d3_dup.json").write_text('{"n_wires": 3, "length_mm": 20, "length_mm": 200, "pitch_radius_mm": 2}')
    (tmp / "scen_nan.json").write_text('{"n_wires": [3], "joint_uncertainty_mm": NaN}')
    (tmp / "scen_big.json").write_text('{"n_wires": [3], "length_mm": 1e400}')
    (tmp / "space_inf.json").write_text('{"n_wires": 3, "pitch_radius_mm": [1, Infinity]}')
    # explorations past the resource checks: too many chunks, a chunk beyond the memory, too long
    (tmp / "space_chunks.json").write_text(json.dumps(SPACE_CHUNKS))
    (tmp / "space_chunk_memory.json").write_text(json.dumps({"n_wires": 3, "chunks": {"poses": 10**9}}))
    (tmp / "space_day.json").write_text(json.dumps(SPACE_DAY))
    (tmp / "scen_deep.json").write_text('{"weights": ' * 40 + "1" + "}" * 40)
    (tmp / "scen_deeper.json").write_text("[" * 100_000 + "]" * 100_000)
    for name, change in {
        "unknown": {"colour": "red"},
        "n_str": {"n_wires": "3"},
        "n_two": {"n_wires": [2, 3]},
        "strict_str": {"strict_controllability": "yes"},
        "radius_order": {"pitch_radius_mm": [3.0, 1.0]},
        "theta_range": {"theta_L_deg": [0, 120, 5]},
        "nan_dq": {"joint_uncertainty_mm": float("nan")},
        "weights_key": {"weights": {"cost": 1}},
        "starts_zero": {"optimizer": {"starts": 0}},
        "load_short": {"load_N": [1, 2]},
        "arc_fixed": {"forbidden_arc_deg": [10, 50]},
        "seed_negative": {"optimizer": {"seed": -1}},
        "radius_half": {"length_mm": 20, "pitch_radius_mm": [0.5, 50]},
        "step_beyond": {"theta_L_deg": [5, 85, 100]},
    }.items():
        (tmp / f"{name}.json").write_text(json.dumps({**GOOD_SCENARIO, **change}, allow_nan=True))
    # several segments: a key twice in a segment, a bad segment of a space
    (tmp / "two_dup.json").write_text('{"segments": [{}, {"length_mm": 20, "length_mm": 30}]}')
    (tmp / "two_space.json").write_text(json.dumps({"segments": [{"n_wires": 4}, {"pitch_radius_mm": [3, 1]}]}))
    # calibration inputs, cut from the shipped examples
    design = json.loads(tz.example_path("synthetic/nominal_3w.design.json").read_text())
    (tmp / "d3.json").write_text(json.dumps(design))
    (tmp / "d3_nstr.json").write_text(json.dumps({**design, "n_wires": "3"}))
    seg = {"n_wires": 3, "length_mm": 60, "pitch_radius_mm": 4.5, "wire_angles_deg": [0, 120, 240]}
    (tmp / "route_seg0.json").write_text(json.dumps({"segments": [{**seg, "route_angles_deg": [[0], [1], [2]]}, seg]}))
    (tmp / "shared_hole.json").write_text(
        json.dumps(
            {"segments": [seg, {**seg, "wire_angles_deg": [40, 160, 280], "route_angles_deg": [[0], [160], [280]]}]}
        )
    )
    rows = tz.example_path("synthetic/nominal_3w.csv").read_text().splitlines()
    (tmp / "cal.csv").write_text("\n".join(rows[:81]) + "\n")
    (tmp / "short.csv").write_text("\n".join(rows[:15]) + "\n")
    cells = rows[5].split(",")
    cells[2] = "abc"
    (tmp / "nonnum.csv").write_text("\n".join(rows[:5] + [",".join(cells)] + rows[6:81]) + "\n")
    train = tz.example_path("ftdcr_v4/train.csv").read_text()
    (tmp / "opencr.csv").write_text("\n".join(train.splitlines()[:60]) + "\n")
    # recordings that cannot be millimetres of their robot
    (tmp / "cal_metres.csv").write_text(_scaled(rows[:81], ("px", "py", "pz"), 1e-3))
    (tmp / "cal_um.csv").write_text(_scaled(rows[:81], ("px", "py", "pz"), 1e3))
    (tmp / "cal_still.csv").write_text(_scaled(rows[:81], ("px", "py", "pz"), 0.0))
    lines = train.splitlines()[:130]
    (tmp / "opencr_x57.csv").write_text(_scaled(lines, [h for h in lines[0].split(",") if h.startswith("servo_")], 57))
    (tmp / "truncated.csv").write_text(train[:3000])
    (tmp / "ftdcr.json").write_text(tz.example_path("ftdcr_v4/design.json").read_text())
    (tmp / "report").mkdir()
    (tmp / "report" / "report.json").write_text('{"earlier": true}')
    (tmp / "data_dir").mkdir()


SWEEP = ["sweep", "--wires", "3", "--length", "20", "--pitch-radius", "2"]
COMPLIANCE = SWEEP + ["--compliance", "--wire-stiffness", "75", "--backbone-EI", "1200", "--load", "5,0,0"]
OPT = ["optimize", "--scenario"]

CAL = ["calibrate", "{tmp}/cal.csv", "--design", "{tmp}/d3.json"]

CLI = [
    # calibrate: data, design and output checked before the fit
    (
        "cal-opencr-without-format",
        ["calibrate", "{tmp}/opencr.csv", "--design", "{tmp}/d3.json", "--out", "{tmp}/o"],
        "looks like an OpenCR recording",
    ),
    (
        "cal-design-n-wires-string",
        ["calibrate", "{tmp}/cal.csv", "--design", "{tmp}/d3_nstr.json", "--out", "{tmp}/o"],
        "n_wires must be an integer of at least 3, got '3' (a string)",
    ),
    (
        "cal-data-is-folder",
        ["calibrate", "{tmp}/data_dir", "--design", "{tmp}/d3.json", "--out", "{tmp}/o"],
        "is a folder, not a file",
    ),
    (
        "cal-truncated-opencr",
        ["calibrate", "{tmp}/truncated.csv", "--format", "opencr", "--design", "{tmp}/ftdcr.json", "--out", "{tmp}/o"],
        "is the file truncated?",
    ),
    (
        "cal-non-numeric-cell",
        ["calibrate", "{tmp}/nonnum.csv", "--design", "{tmp}/d3.json", "--out", "{tmp}/o"],
        "'abc' is not a number",
    ),
    (
        "cal-missing-design",
        ["calibrate", "{tmp}/cal.csv", "--design", "{tmp}/nowhere.json", "--out", "{tmp}/o"],
        "does not exist",
    ),
    (
        "cal-missing-data",
        ["calibrate", "{tmp}/nowhere.csv", "--design", "{tmp}/d3.json", "--out", "{tmp}/o"],
        "nowhere.csv",
    ),
    ("cal-unknown-effect", CAL + ["--effects", "nonsense", "--out", "{tmp}/o"], "unknown effect 'nonsense'"),
    ("cal-unknown-added-effect", CAL + ["--effects", "+nonsense", "--out", "{tmp}/o"], "unknown effect 'nonsense'"),
    (
        "cal-effects-list-and-additions",
        CAL + ["--effects", "drift,+bending_friction", "--out", "{tmp}/o"],
        "either a list of effects or +NAME additions",
    ),
    ("cal-holdout-out-of-range", CAL + ["--holdout", "1.5", "--out", "{tmp}/o"], "--holdout must be between 0 and 1"),
    ("cal-negative-workers", CAL + ["--workers", "-1", "--out", "{tmp}/o"], "--workers must be 0 or more, got -1"),
    ("cal-workers-not-a-count", CAL + ["--workers", "two", "--out", "{tmp}/o"], "invalid int value: 'two'"),
    ("cal-unknown-format", CAL + ["--format", "xml", "--out", "{tmp}/o"], "invalid choice: 'xml'"),
    (
        "cal-too-few-samples",
        ["calibrate", "{tmp}/short.csv", "--design", "{tmp}/d3.json", "--out", "{tmp}/o"],
        "need at least 10",
    ),
    (
        "cal-positions-in-metres",
        ["calibrate", "{tmp}/cal_metres.csv", "--design", "{tmp}/d3.json", "--out", "{tmp}/o"],
        (
            "cal_metres.csv: the tip positions span 0.0103 mm (column 'px', their widest) for a robot 20 mm long, less than "
            "1% of it: are the positions in metres? Millimetres are expected (10.3 mm in millimetres)"
        ),
    ),
    (
        "cal-positions-in-micrometres",
        ["calibrate", "{tmp}/cal_um.csv", "--design", "{tmp}/d3.json", "--out", "{tmp}/o"],
        (
            "cal_um.csv: the tip positions span 1.03e+04 mm (column 'px', their widest) for a robot 20 mm long, but two tips "
            "of a robot that long are at most 40 mm apart (allowed 80 mm)"
        ),
    ),
    (
        "cal-tip-never-moves",
        ["calibrate", "{tmp}/cal_still.csv", "--design", "{tmp}/d3.json", "--out", "{tmp}/o"],
        "cal_still.csv: the tip never moves: the tip positions span 0 mm",
    ),
    (
        "cal-servo-scaled",
        ["calibrate", "{tmp}/opencr_x57.csv", "--format", "opencr", "--design", "{tmp}/ftdcr.json", "--out", "{tmp}/o"],
        (
            "opencr_x57.csv: column 'servo_4_mm', row 2: wire displacement 39.3466 mm, but wire 1 moves at most 28.3 mm "
            "(2 x pi x its pitch radii summed over the 1 segment(s) it crosses, 4.5 mm)"
        ),
    ),
    (
        "cal-validate-is-training",
        CAL + ["--validate", "{tmp}/cal.csv", "--out", "{tmp}/o"],
        (
            "validation file cal.csv: 80 of its 80 rows repeat rows of the training file cal.csv (same commands and tip "
            "positions; the same recording)"
        ),
    ),
    ("cal-existing-report", CAL + ["--out", "{tmp}/report"], "already holds a report"),
    ("cal-out-is-a-file", CAL + ["--out", "{tmp}/file.txt"], "is a file"),
    # strict JSON in every reader (design, scenario, space)
    (
        "json-design-duplicate-key",
        ["calibrate", "{tmp}/cal.csv", "--design", "{tmp}/d3_dup.json", "--out", "{tmp}/o"],
        "d3_dup.json': key 'length_mm' appears twice (JSON keys must be unique)",
    ),
    (
        "json-scenario-nan",
        OPT + ["{tmp}/scen_nan.json", "--out", "{tmp}/o"],
        "scen_nan.json': key 'joint_uncertainty_mm' is NaN; only finite numbers are allowed",
    ),
    (
        "json-scenario-overflow",
        OPT + ["{tmp}/scen_big.json", "--out", "{tmp}/o"],
        "key 'length_mm' is 1e400 (too large for a float)",
    ),
    (
        "json-space-infinity",
        ["explore", "--space", "{tmp}/space_inf.json", "--out", "{tmp}/o"],
        "space_inf.json': key 'pitch_radius_mm[1]' is Infinity",
    ),
    ("json-scenario-deep", OPT + ["{tmp}/scen_deep.json", "--out", "{tmp}/o"], "nests deeper than 32 levels"),
    # explore: the work said and capped before anything is written
    (
        "explore-too-many-chunks",
        ["explore", "--space", "{tmp}/space_chunks.json", "--out", "{tmp}/o"],
        (
            "exploring 1,000,000 designs x 2,610 poses = 2.61e+09 design-poses in 1,000,000 chunks: more than "
            '100,000 chunks (each is a file and an update of the manifest); raise "chunks" ("designs": the designs '
            "per chunk, now 1) or sample fewer designs, or pass --no-resource-check "
            "(explore(..., resource_check=False)) to run it anyway"
        ),
    ),
    (
        "explore-chunk-beyond-memory",
        ["explore", "--space", "{tmp}/space_chunk_memory.json", "--out", "{tmp}/o"],
        (
            "a chunk of 128 designs x 1,000,000,000 poses of 3 wires needs about 465 GB of memory (estimated), more "
            "than 50% of the"
        ),
    ),
    (
        "explore-a-day-of-work",
        ["explore", "--space", "{tmp}/space_day.json", "--out", "{tmp}/o"],
        (
            "exploring 1,000,000 designs x 61,731 poses = 6.17e+10 design-poses would take about 34 h of computing "
            "on 1 CPU process(es) (estimated at 2e+06 design-poses per second per process for 4 wires, fewer with "
            "more), more than 24 h; sample fewer designs or a coarser grid, run it on more processes "
            "(--distributed), or pass --no-resource-check (explore(..., resource_check=False)) to run it anyway"
        ),
    ),
    (
        "json-scenario-recursion",
        OPT + ["{tmp}/scen_deeper.json", "--out", "{tmp}/o"],
        "scen_deeper.json': nests deeper than 32 levels",
    ),
    # usage errors (argparse): one line too
    ("no-command", [], "the following arguments are required: COMMAND"),
    ("unknown-command", ["frobnicate"], "invalid choice: 'frobnicate'"),
    ("maps-wires-not-int", ["maps", "--wires", "three", "--out", "{tmp}/m.png"], "invalid int value"),
    ("maps-missing-out", ["maps", "--wires", "3"], "required: --out"),
    # maps
    ("maps-two-wires", ["maps", "--wires", "2", "--out", "{tmp}/m.png"], "n_wires must be at least 3"),
    ("maps-negative-wires", ["maps", "--wires", "-4", "--out", "{tmp}/m.png"], "n_wires must be at least 3"),
    ("maps-too-many-wires", ["maps", "--wires", "100000", "--out", "{tmp}/m.png"], "at most 256"),
    (
        "maps-angles-text",
        ["maps", "--wires", "3", "--angles", "0,x,2", "--out", "{tmp}/m.png"],
        "--angles must be comma-separated",
    ),
    ("maps-angles-count", ["maps", "--wires", "3", "--angles", "0,1", "--out", "{tmp}/m.png"], "--angles has 2 values"),
    (
        "maps-angles-nan",
        ["maps", "--wires", "3", "--angles", "0,nan,2", "--out", "{tmp}/m.png"],
        "--angles must be finite",
    ),
    (
        "maps-angles-coincident",
        ["maps", "--wires", "3", "--angles", "0,360,90", "--out", "{tmp}/m.png"],
        "coincident wires 1 and 2",
    ),
    ("maps-out-suffix", ["maps", "--wires", "3", "--out", "{tmp}/m.jpg"], "must end in .png"),
    ("maps-out-no-parent", ["maps", "--wires", "3", "--out", "{tmp}/nope/m.png"], "does not exist"),
    ("maps-out-parent-is-file", ["maps", "--wires", "3", "--out", "{tmp}/file.txt/m.png"], "is a file"),
    ("maps-out-is-folder", ["maps", "--wires", "3", "--out", "{tmp}/dir.png"], "is a folder"),
    ("maps-out-exists", ["maps", "--wires", "3", "--out", "{tmp}/old.png"], "pass --force"),
    # sweep
    (
        "sweep-negative-length",
        SWEEP[:4] + ["-1", "--pitch-radius", "2", "--out", "{tmp}/s.npz"],
        "length must be positive",
    ),
    ("sweep-nan-length", SWEEP[:4] + ["nan", "--pitch-radius", "2", "--out", "{tmp}/s.npz"], "length must be finite"),
    ("sweep-zero-radius", SWEEP[:6] + ["0", "--out", "{tmp}/s.npz"], "pitch_radius must be positive"),
    ("sweep-zero-dq", SWEEP + ["--dq", "0", "--out", "{tmp}/s.npz"], "--dq must be a positive number"),
    ("sweep-nan-dq", SWEEP + ["--dq", "nan", "--out", "{tmp}/s.npz"], "--dq must be a positive number"),
    (
        "sweep-negative-step",
        SWEEP + ["--theta-step", "-5", "--out", "{tmp}/s.npz"],
        "--theta-step must be a positive number",
    ),
    (
        "sweep-zero-delta-step",
        SWEEP + ["--delta-step", "0", "--out", "{tmp}/s.npz"],
        "--delta-step must be a positive number",
    ),
    (
        "sweep-theta-step-beyond-range",
        SWEEP + ["--theta-step", "86", "--out", "{tmp}/s.npz"],
        "--theta-step 86 leaves 1 grid point on 0..85 deg; it must be at most 85",
    ),
    (
        "sweep-delta-step-beyond-range",
        SWEEP + ["--delta-step", "400", "--out", "{tmp}/s.npz"],
        "--delta-step 400 leaves 1 grid point on 0..360 deg; it must be at most 360",
    ),
    (
        "sweep-radius-over-half-length",
        SWEEP[:6] + ["50", "--out", "{tmp}/s.npz"],
        (
            "--pitch-radius: pitch_radius 50 mm is more than half the length 20 mm: a wire that far out meets the "
            "centre of curvature before the segment bends 2 rad"
        ),
    ),
    (
        "sweep-absurd-length",
        SWEEP[:4] + ["1e308", "--pitch-radius", "2", "--out", "{tmp}/s.npz"],
        "--length: length must be at most 1e+06 mm (a kilometre), got 1e+308",
    ),
    ("sweep-grid-too-fine", SWEEP + ["--theta-step", "1e-6", "--out", "{tmp}/s.npz"], "sweeps at most 20,000,000"),
    (
        "sweep-too-many-wires",
        ["sweep", "--wires", "4096", "--length", "20", "--pitch-radius", "2", "--out", "{tmp}/s.npz"],
        "--wires must be at most 256",
    ),
    (
        "sweep-compliance-missing",
        SWEEP + ["--compliance", "--out", "{tmp}/s.npz"],
        "--compliance needs --wire-stiffness, --backbone-EI, --load",
    ),
    ("sweep-load-alone", SWEEP + ["--load", "1,2,3", "--out", "{tmp}/s.npz"], "go with --compliance"),
    ("maps-no-robot", ["maps", "--out", "{tmp}/m.png"], "maps needs --design FILE, or --wires for one segment"),
    (
        "maps-bend-of-a-segment",
        ["maps", "--wires", "3", "--bend", "30", "--out", "{tmp}/m.png"],
        "--bend is the other segments' bending in a robot's maps",
    ),
    (
        "maps-robot-bend-beyond",
        ["maps", "--design", "{tmp}/ftdcr.json", "--bend", "-5", "--out", "{tmp}/m.png"],
        "--bend must be a bending angle in (0, 180] degrees, got -5",
    ),
    ("sweep-no-robot", ["sweep", "--length", "20", "--out", "{tmp}/s.npz"], "sweep needs --design FILE, or --wires"),
    (
        "sweep-design-and-wires",
        ["sweep", "--design", "{tmp}/ftdcr.json", "--wires", "3", "--out", "{tmp}/s.npz"],
        "--wires: the --design file sets the robot",
    ),
    (
        "sweep-robot-compliance-no-load",
        ["sweep", "--design", "{tmp}/ftdcr.json", "--compliance", "--out", "{tmp}/s.npz"],
        "--compliance needs --load",
    ),
    (
        "sweep-design-compliance-preload",
        [
            "sweep",
            "--design",
            "{tmp}/ftdcr.json",
            "--compliance",
            "--load",
            "1,0,0",
            "--preload",
            "2",
            "--out",
            "{tmp}/s.npz",
        ],
        "--preload: the --design file sets the robot's stiffness and preload",
    ),
    (
        "sweep-robot-theta-step",
        ["sweep", "--design", "{tmp}/ftdcr.json", "--theta-step", "5", "--out", "{tmp}/s.npz"],
        "a robot of 3 segments takes --samples and --max-bend",
    ),
    (
        "sweep-robot-no-samples",
        ["sweep", "--design", "{tmp}/ftdcr.json", "--samples", "0", "--out", "{tmp}/s.npz"],
        "--samples must be 1 to",
    ),
    (
        "sweep-robot-bend-in-radians-or-beyond",
        ["sweep", "--design", "{tmp}/ftdcr.json", "--max-bend", "270", "--out", "{tmp}/s.npz"],
        "--max-bend must be a bending angle in (0, 180] degrees, got 270",
    ),
    (
        "sweep-segment-samples",
        SWEEP + ["--samples", "100", "--out", "{tmp}/s.npz"],
        "--samples and --max-bend sample a robot",
    ),
    ("sweep-load-text", COMPLIANCE[:-1] + ["1,x,3", "--out", "{tmp}/s.npz"], "--load must be"),
    ("sweep-load-short", COMPLIANCE[:-1] + ["1,2", "--out", "{tmp}/s.npz"], "--load must be 3 finite"),
    ("sweep-load-inf", COMPLIANCE[:-1] + ["inf,0,0", "--out", "{tmp}/s.npz"], "--load must be 3 finite"),
    (
        "sweep-negative-stiffness",
        SWEEP
        + [
            "--compliance",
            "--wire-stiffness",
            "-75",
            "--backbone-EI",
            "1200",
            "--load",
            "5,0,0",
            "--out",
            "{tmp}/s.npz",
        ],
        "--wire-stiffness: wire_stiffness must be positive",
    ),
    (
        "sweep-negative-preload",
        COMPLIANCE + ["--preload", "-1", "--out", "{tmp}/s.npz"],
        "--preload: preload must be non-negative",
    ),
    ("sweep-out-suffix", SWEEP + ["--out", "{tmp}/s.csv"], "must end in .npz"),
    ("sweep-out-is-folder", SWEEP + ["--out", "{tmp}/dir.npz"], "is a folder"),
    ("sweep-out-exists", SWEEP + ["--out", "{tmp}/old.npz"], "pass --force"),
    ("sweep-out-no-parent", SWEEP + ["--out", "{tmp}/nope/s.npz"], "does not exist"),
    # optimize
    ("opt-scenario-missing", OPT + ["{tmp}/none.json", "--out", "{tmp}/o"], "does not exist"),
    ("opt-scenario-folder", OPT + ["{tmp}/scen_dir.json", "--out", "{tmp}/o"], "is a folder"),
    ("opt-scenario-broken", OPT + ["{tmp}/broken.json", "--out", "{tmp}/o"], "is not valid JSON"),
    ("opt-scenario-list", OPT + ["{tmp}/list.json", "--out", "{tmp}/o"], "must be a JSON object"),
    ("opt-scenario-latin1", OPT + ["{tmp}/latin1.json", "--out", "{tmp}/o"], "is not UTF-8 text"),
    ("opt-unknown-key", OPT + ["{tmp}/unknown.json", "--out", "{tmp}/o"], "unknown scenario key"),
    ("opt-n-wires-string", OPT + ["{tmp}/n_str.json", "--out", "{tmp}/o"], "'n_wires'"),
    ("opt-n-wires-two", OPT + ["{tmp}/n_two.json", "--out", "{tmp}/o"], "integers from 3 to 16"),
    (
        "opt-strict-string",
        OPT + ["{tmp}/strict_str.json", "--out", "{tmp}/o"],
        "'strict_controllability': must be true or false",
    ),
    ("opt-radius-order", OPT + ["{tmp}/radius_order.json", "--out", "{tmp}/o"], "is larger than max"),
    ("opt-theta-range", OPT + ["{tmp}/theta_range.json", "--out", "{tmp}/o"], "must lie within"),
    ("opt-nan-dq", OPT + ["{tmp}/nan_dq.json", "--out", "{tmp}/o"], "'joint_uncertainty_mm'"),
    ("opt-weights-key", OPT + ["{tmp}/weights_key.json", "--out", "{tmp}/o"], "unknown sub-key"),
    ("opt-starts-zero", OPT + ["{tmp}/starts_zero.json", "--out", "{tmp}/o"], "'optimizer.starts'"),
    ("opt-load-short", OPT + ["{tmp}/load_short.json", "--out", "{tmp}/o"], "'load_N'"),
    ("opt-arc-needs-free", OPT + ["{tmp}/arc_fixed.json", "--out", "{tmp}/o"], "needs free_wire_angles"),
    (
        "opt-seed-negative",
        OPT + ["{tmp}/seed_negative.json", "--out", "{tmp}/o"],
        "scenario key 'optimizer.seed': must be a non-negative integer, got -1",
    ),
    (
        "cal-route-on-segment-0",
        ["calibrate", "{tmp}/cal.csv", "--design", "{tmp}/route_seg0.json", "--out", "{tmp}/o"],
        (
            "route_seg0.json': segment 0: route_angles_deg has no place on the first segment (it gives a wire's path "
            "through the segments before its own, and none lies before segment 0)"
        ),
    ),
    (
        "opt-radius-over-half-length",
        OPT + ["{tmp}/radius_half.json", "--out", "{tmp}/o"],
        "scenario key 'pitch_radius_mm': max 50 mm is more than half the length_mm 20 mm",
    ),
    (
        "opt-step-beyond-range",
        OPT + ["{tmp}/step_beyond.json", "--out", "{tmp}/o"],
        "scenario key 'theta_L_deg': step 100 is larger than the range 5..85: the grid would be 5 alone",
    ),
    (
        "cal-routing-shares-a-hole",
        ["calibrate", "{tmp}/cal.csv", "--design", "{tmp}/shared_hole.json", "--out", "{tmp}/o"],
        (
            "shared_hole.json': segment 1: its routing runs wire 1 of segment 1 through segment 0 in the hole of wire 1 "
            "of segment 0 (0 deg, radius 4.5 mm); each wire needs its own hole"
        ),
    ),
    (
        "opt-segment-duplicate-key",
        OPT + ["{tmp}/two_dup.json", "--out", "{tmp}/o"],
        "two_dup.json': key 'segments[1].length_mm' appears twice (JSON keys must be unique)",
    ),
    (
        "explore-segment-range",
        ["explore", "--space", "{tmp}/two_space.json", "--out", "{tmp}/o"],
        "space segments[1] key 'pitch_radius_mm': min 3.0 is larger than max 1.0",
    ),
    ("opt-out-is-file", OPT + ["{tmp}/good.json", "--out", "{tmp}/file.txt"], "must be a folder"),
    ("opt-out-holds-result", OPT + ["{tmp}/good.json", "--out", "{tmp}/run"], "already holds 'result.json'"),
    ("opt-out-no-parent", OPT + ["{tmp}/good.json", "--out", "{tmp}/nope/o"], "does not exist"),
    # reproduce
    ("reproduce-out-is-file", ["reproduce", "--out", "{tmp}/file.txt"], "must be a folder"),
    ("reproduce-out-not-empty", ["reproduce", "--out", "{tmp}/full"], "already holds 'notes.txt'"),
    ("reproduce-out-no-parent", ["reproduce", "--out", "{tmp}/nope/r"], "does not exist"),
]


def _snapshot(root):
    return {p: p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _run_cli(tmp_path, capsys, argv):
    _files(tmp_path)
    before = _snapshot(tmp_path)
    try:
        rc = main([a.replace("{tmp}", str(tmp_path)) for a in argv])
    except SystemExit as e:  # usage errors exit from argparse (one line, status 2)
        rc = e.code
    out, err = capsys.readouterr()
    return rc, out, err, before, _snapshot(tmp_path)


@pytest.mark.parametrize("argv, needle", [c[1:] for c in CLI], ids=[c[0] for c in CLI])
def test_cli_bad_input(tmp_path, capsys, argv, needle):
    rc, out, err, before, after = _run_cli(tmp_path, capsys, argv)
    assert rc == 2, (rc, err)
    assert err.count("\n") == 1 and err.startswith("tension-zones: error: "), err
    assert needle in err, err
    assert "Traceback" not in out + err
    assert after == before, "a file was written or changed"


def test_the_table_is_large_and_names_are_unique():
    assert len(CLI) >= 40 and len({c[0] for c in CLI}) == len(CLI)


@pytest.mark.skipif(
    hasattr(os, "geteuid") and os.geteuid() == 0,
    reason="root may write in a read-only folder (see the probe test below)",
)
@pytest.mark.parametrize(
    "argv",
    [
        ["maps", "--wires", "3", "--out", "{tmp}/ro/m.png"],
        SWEEP + ["--out", "{tmp}/ro/s.npz"],
        OPT + ["{tmp}/good.json", "--out", "{tmp}/ro/o"],
        ["reproduce", "--out", "{tmp}/ro"],
    ],
)
def test_read_only_folder(tmp_path, capsys, argv):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        rc, _out, err, before, after = _run_cli(tmp_path, capsys, argv)
    finally:
        ro.chmod(0o755)
    assert rc == 2 and err.count("\n") == 1 and "cannot write in the folder" in err, err
    assert after == before


@pytest.mark.parametrize(
    "argv",
    [
        ["maps", "--wires", "3", "--out", "{tmp}/m.png"],
        SWEEP + ["--out", "{tmp}/s.npz"],
        OPT + ["{tmp}/good.json", "--out", "{tmp}/o"],
        ["reproduce", "--out", "{tmp}/r"],
    ],
)
def test_an_unwritable_folder_is_found_before_any_work(tmp_path, capsys, monkeypatch, argv):
    """The write probe fails as on a read-only file system (also as root): one line, before any
    computation (the commands' work functions must not be reached)."""
    import importlib
    import tempfile

    def refuse(*a, **k):
        raise PermissionError(13, "Permission denied")

    def work(*a, **k):
        raise AssertionError("the computation started before --out was checked")

    for module, name in (
        ("analysis._sweep", "sweep_grid"),
        ("design._optimise", "optimize"),
        ("paper._reproduce", "reproduce"),
        ("model._zones", "tension_map"),
    ):
        monkeypatch.setattr(importlib.import_module(f"tension_zones.{module}"), name, work)
    monkeypatch.setattr(tempfile, "mkstemp", refuse)
    rc, _out, err, before, after = _run_cli(tmp_path, capsys, argv)
    assert rc == 2 and err.count("\n") == 1, err
    assert "cannot write in the folder" in err and "Permission denied" in err
    assert after == before


def test_force_overwrites_and_writes_atomically(tmp_path, capsys):
    _files(tmp_path)
    assert main(["maps", "--wires", "3", "--out", str(tmp_path / "old.png"), "--force", "--quiet"]) == 0
    assert (tmp_path / "old.png").read_bytes()[:4] == b"\x89PNG"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")], "a temporary file was left"


@pytest.mark.slow
def test_console_script_prints_one_line_without_traceback(tmp_path):
    _files(tmp_path)
    before = _snapshot(tmp_path)
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "tension_zones.cli",
            "sweep",
            "--wires",
            "3",
            "--length",
            "20",
            "--pitch-radius",
            "2",
            "--out",
            str(tmp_path / "old.npz"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "pass --force" in r.stderr
    assert "Traceback" not in r.stderr and _snapshot(tmp_path) == before


# ------------------------------------------------------------------------------------------------
# API
# ------------------------------------------------------------------------------------------------
def _from_dict(**change):
    return lambda: tz.Design.from_dict({"n_wires": 3, "length_mm": 20, "pitch_radius_mm": 2, **change})


def _sweep(**kw):
    from tension_zones.analysis._sweep import sweep_grid

    d = tz.Design(3, 20.0, 2.0)
    fn = kw.pop("fn", lambda design, t, e: {"p": tz.tip_pose(design, t, e)[0]})
    th = kw.pop("th", np.radians([10.0, 20.0]))
    return lambda: sweep_grid(fn, kw.pop("design", d), th, np.radians([0.0, 90.0]), quiet=True, **kw)


def _two_scenario(**change):
    """A scenario of two segments (the deflection term off), with keys changed."""
    return lambda: tz.parse_scenario({"segments": [{}, {}], "weights": {"deflection": 0.0}, **change})


def _nominal(rows=slice(0, 40), **change):
    """The first samples of the shipped nominal recording, with fields replaced."""
    import dataclasses

    data = tz.load_data(tz.example_path("synthetic/nominal_3w.csv"), n_wires=3)
    keep = np.zeros(data.n_samples, bool)
    keep[rows] = True
    data = data.subset(keep)
    return dataclasses.replace(data, **change)


API = [
    ("design-two-wires", lambda: tz.Design(2, 20.0, 2.0), "n_wires must be at least 3"),
    ("design-float-wires", lambda: tz.Design(3.0, 20.0, 2.0), "n_wires must be an integer"),
    ("design-negative-length", lambda: tz.Design(3, -20.0, 2.0), "length must be positive"),
    ("design-bool-length", lambda: tz.Design(3, True, 2.0), "length must be a number"),
    ("design-string-radius", lambda: tz.Design(3, 20.0, "2"), "pitch_radius must be a number"),
    ("design-inf-radius", lambda: tz.Design(3, 20.0, np.inf), "pitch_radius must be finite"),
    ("design-angles-count", lambda: tz.Design(3, 20.0, 2.0, wire_angles=[0.0, 1.0]), "wire_angles"),
    ("design-replace-preload", lambda: tz.Design(3, 20.0, 2.0).replace(preload=-1.0), "preload"),
    ("file-n-wires-string", _from_dict(n_wires="3"), "n_wires must be an integer of at least 3, got '3'"),
    ("file-n-wires-bool", _from_dict(n_wires=True), "(a boolean)"),
    ("file-n-wires-fraction", _from_dict(n_wires=3.5), "got 3.5"),
    ("file-length-string", _from_dict(length_mm="20"), "length_mm must be a number"),
    ("file-angles-entry", _from_dict(wire_angles_deg=[0, "a", 2]), "wire_angles_deg[1] must be a number"),
    ("file-angles-scalar", _from_dict(wire_angles_deg=90), "must be a list of numbers"),
    ("file-unknown-key", _from_dict(colour="red"), "unknown design key"),
    ("file-not-object", lambda: tz.Design.from_dict([1, 2]), "must hold a JSON object"),
    ("scenario-not-object", lambda: tz.parse_scenario([]), "must be a JSON object"),
    ("scenario-strict", lambda: tz.parse_scenario({"strict_controllability": 1}), "true or false"),
    ("scenario-min-spread", lambda: tz.parse_scenario({"min_spread": 2}), "'min_spread'"),
    ("scenario-grid-too-fine", lambda: tz.parse_scenario({"delta_deg": [0, 360, 1e-6]}), "too fine"),
    ("scenario-segments-empty", _two_scenario(segments=[]), "'segments': must be null or a non-empty list"),
    ("scenario-segments-object", _two_scenario(segments={"n_wires": 3}), "'segments': must be null or a non-empty"),
    ("scenario-segment-not-object", _two_scenario(segments=[{}, [3]]), "segments[1] must be a JSON object, got list"),
    (
        "scenario-segment-unknown-key",
        _two_scenario(segments=[{"colour": 1}, {}]),
        "unknown scenario segments[0] key(s) ['colour']",
    ),
    (
        "scenario-segment-range-length",
        _two_scenario(segments=[{}, {"pitch_radius_mm": [1, 2, 3]}]),
        "scenario segments[1] key 'pitch_radius_mm': must be [min, max], got [1, 2, 3]",
    ),
    (
        "scenario-segment-range-order",
        _two_scenario(segments=[{}, {"wire_stiffness_N_per_mm": [90, 60]}]),
        "scenario segments[1] key 'wire_stiffness_N_per_mm': min 90.0 is larger than max 60.0",
    ),
    (
        "scenario-segment-counts",
        _two_scenario(segments=[{"n_wires": [2, 3]}, {}]),
        "scenario segments[0] key 'n_wires': must be a list of integers from 3 to 16",
    ),
    (
        "scenario-segment-preload-length",
        _two_scenario(segments=[{}, {"preload_N": [0, 1, 2]}]),
        "scenario segments[1] key 'preload_N': must be [min, max], got [0, 1, 2]",
    ),
    (
        "scenario-one-segment-preload-range",
        _two_scenario(segments=[{"preload_N": [0, 1]}]),
        "scenario segments[0] key 'preload_N': must be a finite number, got [0, 1]",
    ),
    (
        "scenario-segment-outer-diameter",
        _two_scenario(segments=[{}, {"constraints": {"outer_diameter_mm": 1.0}}]),
        "scenario segments[1] key 'constraints': no pitch radius fits",
    ),
    (
        "scenario-segment-radius-over-half-length",
        _two_scenario(segments=[{}, {"length_mm": 4.0}]),
        "scenario segments[1] key 'pitch_radius_mm': max 3 mm is more than half the length_mm 4 mm",
    ),
    (
        "scenario-top-value-for-every-segment",
        _two_scenario(length_mm=-1.0),
        "scenario key 'length_mm': must be > 0.0, got -1.0",
    ),
    (
        "scenario-grid-of-several",
        _two_scenario(theta_L_deg=[5, 85, 5]),
        "scenario key 'theta_L_deg': is one segment's grid; several segments' workspace is configuration samples",
    ),
    (
        "scenario-samples-of-one",
        lambda: tz.parse_scenario({"samples": 64}),
        "scenario key 'samples': is for several segments; one segment's workspace is the theta_L_deg x delta_deg grid",
    ),
    ("scenario-samples-zero", _two_scenario(samples=0), "scenario key 'samples': must be an integer from 1 to 100000"),
    ("scenario-bend-over", _two_scenario(max_bend_deg=200), "scenario key 'max_bend_deg': must be <= 180.0, got 200"),
    (
        "scenario-free-angles-of-several",
        _two_scenario(free_wire_angles=True),
        "scenario key 'free_wire_angles': several segments' wires are evenly spaced and interleaved",
    ),
    (
        "evaluate-robot-of-another-length",
        lambda: tz.evaluate_design(_two_scenario()(), tz.Robot(tz.Design(3, 20.0, 2.0))),
        "the robot has 1 segment(s), the scenario 2",
    ),
    (
        "space-segment-empty-range",
        lambda: tz.parse_space({"segments": [{}, {"length_mm": [20, 20]}]}),
        "space segments[1] key 'length_mm': [20.0, 20.0] is an empty range",
    ),
    (
        "space-segment-unknown-key",
        lambda: tz.parse_space({"segments": [{}, {"pitch": 2}]}),
        "unknown space segments[1] key(s) ['pitch']",
    ),
    (
        "space-segment-radius-over-half-length",
        lambda: tz.parse_space({"segments": [{"length_mm": 4.0}, {}]}),
        "space segments[0] key 'pitch_radius_mm': max 3 mm is more than half the min length_mm 4 mm",
    ),
    (
        "space-offsets-of-several",
        lambda: tz.parse_space({"segments": [{}, {}], "wire_angle_offset_deg": 5.0}),
        "space key 'wire_angle_offset_deg': several segments' wires are evenly spaced and interleaved",
    ),
    (
        "space-load-of-too-many-wires",
        lambda: tz.parse_space({"segments": [{"n_wires": [4, 8]}, {"n_wires": 5}], "load_N": [1.0, 0.0, 0.0]}),
        (
            "space key 'load_N': a robot's statics enumerate 2^N sets of taut wires: at most 12 wires in all, the "
            "segments' counts give up to 13; set it to null or use fewer wires"
        ),
    ),
    (
        "scenario-deflection-of-too-many-wires",
        lambda: tz.parse_scenario({"segments": [{"n_wires": [7]}, {"n_wires": [6]}]}),
        "scenario key 'weights.deflection': a robot's statics enumerate 2^N sets of taut wires: at most 12 wires",
    ),
    (
        "space-grid-of-several",
        lambda: tz.parse_space({"segments": [{}, {}], "delta_deg": [0, 360, 5]}),
        "space key 'delta_deg': is one segment's grid",
    ),
    (
        "space-too-many-structures",
        lambda: tz.parse_space({"segments": [{"n_wires": list(range(3, 12))}] * 3}),
        "space key 'n_wires': 729 combinations of the segments' wire counts, each its own program: at most 64",
    ),
    ("grid-step-zero", lambda: tz.grid_deg(85.0, 0.0), "a grid step must be a positive number"),
    ("grid-reversed", lambda: tz.grid_deg(-5.0, 1.0), "start <= stop"),
    ("sweep-chunk", _sweep(chunk_size=0), "chunk_size must be a positive integer"),
    ("sweep-keep", _sweep(keep=["nope"]), "keep names unknown output"),
    ("sweep-2d-axis", _sweep(th=np.zeros((2, 2))), "1-D grids"),
    ("sweep-not-design", _sweep(design={"n_wires": 3}), "must be a tension_zones.Design"),
    ("sweep-not-dict", _sweep(fn=lambda design, t, e: t), "must return a dict"),
    (
        "measures-mask-shape",
        lambda: tz.pose_measures(tz.Design(4, 20.0, 2.0), 0.5, 0.1, 0.4, np.ones(3)),
        "mask must have shape (4,)",
    ),
    (
        "wrench-shape",
        lambda: tz.compliance_pose(tz.Design(3, 20.0, 2.0), 0.5, 0.1, np.ones(4)),
        "3 (force) or 6 (force, moment) components",
    ),
    (
        "wrench-nan",
        lambda: tz.compliance_pose(tz.Design(3, 20.0, 2.0), 0.5, 0.1, [np.nan, 0, 0]),
        "a wrench must be finite",
    ),
    (
        "compliance-grid-theta",
        lambda: tz.compliance_grid(tz.Design(3, 20.0, 2.0), theta_L_deg=[100.0]),
        "theta_L_deg must lie in (-90, 90]",
    ),
    ("compliance-grid-empty", lambda: tz.compliance_grid(tz.Design(3, 20.0, 2.0), delta_deg=[]), "non-empty 1-D array"),
    ("tension-map-psi-dot", lambda: tz.tension_map(tz.Design(3, 20.0, 2.0), psi_dot=[-1.0, 0.0]), "needs theta_L"),
    (
        "tension-score-psi-dot",
        lambda: tz.tension_score(tz.Design(3, 20.0, 2.0), 0.1, psi_dot=[1.0, 0.0]),
        "needs theta_L",
    ),
    ("explore-too-many-chunks", lambda: tz.explore(tz.parse_space(SPACE_CHUNKS)), "more than 100,000 chunks"),
    (
        "explore-a-day-of-work",
        lambda: tz.explore(tz.parse_space(SPACE_DAY)),
        "would take about 34 h of computing on 1 CPU process(es)",
    ),
    (
        "calibrate-workers",
        lambda: tz.calibrate(
            tz.load_data(tz.example_path("synthetic/nominal_3w.csv"), n_wires=3), tz.Design(3, 20.0, 2.0), workers=-1
        ),
        "workers must be a whole number, 0 or more, got -1",
    ),
    (
        "design-radius-over-half-length",
        lambda: tz.Design(3, 20.0, 50.0),
        "pitch_radius 50 mm is more than half the length 20 mm",
    ),
    ("design-absurd-length", lambda: tz.Design(3, 1e308, 2.0), "length must be at most 1e+06 mm (a kilometre)"),
    (
        "file-radius-over-half-length",
        _from_dict(pitch_radius_mm=50),
        "pitch_radius_mm 50 mm is more than half the length_mm 20 mm",
    ),
    (
        "space-radius-over-half-length",
        lambda: tz.parse_space({"length_mm": [20, 40], "pitch_radius_mm": [1, 15]}),
        "space key 'pitch_radius_mm': max 15 mm is more than half the min length_mm 20 mm",
    ),
    (
        "space-halton-too-many",
        lambda: tz.parse_space({"length_mm": [15, 25], "sample": {"method": "halton", "designs": 10**9}}),
        "space key 'sample.designs': 1e+09 designs for 3 wires, more than 1e+07: fewer designs",
    ),
    (
        "space-grid-too-many",
        lambda: tz.parse_space(
            {"length_mm": [15, 25], "pitch_radius_mm": [1, 3], "preload_N": [0, 5], "sample": {"points": 4000}}
        ),
        'the grid has 6.4e+10 designs for 3 wires, more than 1e+07: fewer points, or method "halton"',
    ),
    (
        "robot-routing-shares-a-hole",
        lambda: tz.Robot.from_dict(
            {
                "segments": [
                    {"n_wires": 3, "length_mm": 40, "pitch_radius_mm": 3},
                    {
                        "n_wires": 3,
                        "length_mm": 30,
                        "pitch_radius_mm": 3,
                        "wire_angles_deg": [60, 180, 300],
                        "route_angles_deg": [[60], [120], [300]],
                    },
                ]
            }
        ),
        (
            "segment 1: its routing runs wire 2 of segment 1 through segment 0 in the hole of wire 2 of segment 0 "
            "(120 deg, radius 3 mm)"
        ),
    ),
    (
        "metrics-theta-in-degrees",
        lambda: tz.pose_metrics(tz.Design(3, 20.0, 2.0), 60.0, 1.0, 0.4),
        "theta_L = 60 is beyond +-pi: radians are expected (np.radians(60) = 1.0472)",
    ),
    (
        "metrics-delta-in-degrees",
        lambda: tz.pose_metrics(tz.Design(3, 20.0, 2.0), 1.0, 66.0, 0.4),
        "delta = 66 is beyond +-2 pi: radians are expected (np.radians(66) = 1.15192)",
    ),
    (
        "measures-negative-dq",
        lambda: tz.pose_measures(tz.Design(3, 20.0, 2.0), 1.0, 0.5, -0.4),
        "dq must be non-negative (a bound on each joint's error, mm), got -0.4",
    ),
    (
        "calibrate-tip-never-moves",
        lambda: tz.calibrate(_nominal(p=np.zeros((40, 3))), tz.Design(3, 20.0, 2.0)),
        "the tip never moves: the tip positions span 0 mm (column 'px', their widest) for a robot 20 mm long",
    ),
    (
        "calibrate-validate-overlaps",
        lambda: tz.calibrate(_nominal(), tz.Design(3, 20.0, 2.0), validate=_nominal(rows=slice(20, 40))),
        "20 of its 20 rows repeat rows of the training file nominal_3w.csv",
    ),
    (
        "over-grid-mismatch",
        lambda: tz.over_grid(tz.pose_measures)(tz.Design(4, 20.0, 2.0), np.zeros(2), np.zeros(2), 0.4, np.ones(3)),
        "mask must have shape",
    ),
]


@pytest.mark.parametrize("call, needle", [c[1:] for c in API], ids=[c[0] for c in API])
def test_api_bad_input(call, needle):
    with pytest.raises((ValueError, TypeError)) as e:
        call()
    msg = str(e.value)
    assert needle in msg and "\n" not in msg, msg


def test_the_api_table_is_large():
    assert len(API) >= 30 and len({c[0] for c in API}) == len(API)


# ------------------------------------------------------------------------------------------------
# The plausibility checks pass every shipped recording
# ------------------------------------------------------------------------------------------------
RECORDINGS = [
    (tz.example_path(f"synthetic/{n}.csv"), tz.example_path(f"synthetic/{n}.design.json"), "model")
    for n in ("nominal_3w", "unknown_a_3w", "unknown_b_4w")
]
RECORDINGS += [
    (tz.example_path(f"ftdcr_v{v}/{n}.csv"), tz.example_path(f"ftdcr_v{v}/design.json"), "opencr")
    for v in (4, 6)
    for n in ("train", "tendon_pull")
]


@pytest.mark.parametrize("data, design, fmt", RECORDINGS, ids=lambda x: str(x).split("examples/")[-1])
def test_shipped_recordings_are_plausible(data, design, fmt):
    robot = tz.Robot.from_json(design)
    tz.load_data(data, fmt, n_wires=robot.n_wires).check_against(robot)


def test_the_shipped_validation_recording_is_a_separate_one():
    from tension_zones.calibration._data import check_validation

    robot = tz.Robot.from_json(tz.example_path("ftdcr_v4/design.json"))
    train = tz.load_data(tz.example_path("ftdcr_v4/train.csv"), "opencr", n_wires=9)
    val = tz.load_data(tz.example_path("ftdcr_v4/val.csv"), "opencr", n_wires=9, servo_ids=train.servo_ids)
    val.check_against(robot)
    check_validation(train, val)


def test_a_figure_not_computed_is_null_not_zero(tmp_path):
    """A deflection weight of 0 skips the statics: the worst deflection and the statics-infeasible
    count are NaN in the result and null in result.json, never 0."""
    from tension_zones._io import write_json
    from tension_zones.design._optimise import evaluate_design

    sc = tz.parse_scenario({**GOOD_SCENARIO, "n_wires": [4], "weights": {"deflection": 0.0}})
    row = evaluate_design(sc, tz.Design(4, 20.0, 2.0))
    assert np.isnan(row["worst_deflection_mm"]) and np.isnan(row["statics_infeasible_poses"])
    assert np.isfinite(row["worst_position_uncertainty_mm"])
    written = json.loads(write_json(tmp_path / "r.json", row).read_text())
    assert written["worst_deflection_mm"] is None and written["statics_infeasible_poses"] is None


def test_a_noise_floor_of_zero_does_not_divide():
    """Noiseless data (repeated samples identical): the held-out error against a floor of 0 is finite."""
    from tension_zones.calibration._loop import _excess

    ex = _excess(0.1, 0.1, {"floor_mm": 0.0, "pairs": 10}, 50)
    assert np.isfinite(ex["ratio_to_floor"]) and np.isfinite(ex["z"]) and ex["z"] > 0
    assert np.isfinite(_excess(0.0, 0.0, {"floor_mm": 0.0, "pairs": 10}, 50)["z"])


def test_a_space_with_every_field_fixed_is_one_design():
    space = tz.parse_space({"n_wires": 3, "pitch_radius_mm": 2.0})
    assert space.count(3) == 1 and space.columns(3)["pitch_radius_mm"].tolist() == [2.0]
    assert np.asarray(space.batch(3).pitch_radius).tolist() == [2.0]


def test_the_command_line_shows_a_warning_as_one_line(tmp_path, capsys, monkeypatch):
    import warnings

    from tension_zones import cli

    monkeypatch.setattr(
        cli, "cmd_maps", lambda args: warnings.warn("first line\nsecond line", UserWarning, stacklevel=1)
    )
    assert main(["maps", "--wires", "3", "--out", str(tmp_path / "m.png")]) == 0
    err = capsys.readouterr().err
    assert err == "tension-zones: warning: first line second line\n", err


def test_a_full_disk_names_the_file_and_leaves_nothing(tmp_path, monkeypatch, capsys):
    """A write that fails for want of space (``ENOSPC``, raised without a file name as NumPy's writers
    do) is one line naming the output, and leaves no file, hidden or not; the rerun works."""
    import errno

    from tension_zones.cli import main

    scenario = tmp_path / "s.scenario.json"
    scenario.write_text(json.dumps(SMALL_SCENARIO))  # (the optimiser's program of other tests)
    out = tmp_path / "o"

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    with monkeypatch.context() as m:
        m.setattr("pathlib.Path.write_text", full)
        assert main(["optimize", "--scenario", str(scenario), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"tension-zones: error: [Errno 28] No space left on device: {str(out / 'result.json')!r}"
    assert "\n" not in err and list(out.iterdir()) == []
    assert main(["optimize", "--scenario", str(scenario), "--out", str(out), "--quiet"]) == 0
