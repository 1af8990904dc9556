"""The shipped FTDCR v4 example, as the benchmarks on it read it."""

from __future__ import annotations

import json

import tension_zones as tz
from tension_zones.calibration import read_opencr


def load():
    """``(robot, report, train, val)``: the design, the shipped calibration report (a dict), and the two
    recordings (``val.csv`` with ``train.csv``'s servo order)."""
    robot = tz.Robot.from_json(tz.example_path("ftdcr_v4/design.json"))
    report = json.loads(tz.example_path("ftdcr_v4/calibration.json").read_text())
    train = read_opencr(tz.example_path("ftdcr_v4/train.csv"), n_wires=robot.n_wires)
    val = read_opencr(tz.example_path("ftdcr_v4/val.csv"), n_wires=robot.n_wires, servo_ids=train.servo_ids)
    return robot, report, train, val
