"""The FTDCR v4 robot effect by effect, constant curvature against the rod model, side by side.

    python benchmarks/ftdcr_rod.py [--out FILE]

For every model the calibration loop accepted on the FTDCR v4 recordings (the ``steps`` of the shipped
report, ``tension_zones/examples/ftdcr_v4/calibration.json``), as the loop fits it: its held-out RMSE
fitted on the training groups, its validation RMSE refitted on every sample of ``train.csv`` (the loop's
final refit), with constant curvature, then with the rod model (each segment in 4 constant-curvature
pieces, the curvature freedom of every segment fitted as well: the ``variable_curvature`` effect)
started from the constant-curvature fit. Without a load (no tip force, no
weight) the rod is constant curvature, so those rows are the same by construction. Writes the table as
JSON (default ``tension_zones/examples/ftdcr_v4/rod_vs_cc.json``, which notebook 06 shows) and prints it
as Markdown (``benchmarks/README.md``).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import _ftdcr  # (benchmarks/, the script's folder)
import numpy as np

import tension_zones as tz
from tension_zones.calibration import rmse, rmse_aligned
from tension_zones.calibration._loop import _initial
from tension_zones.calibration._model import RobotModel, data_clock
from tension_zones.calibration._problem import Problem
from tension_zones.calibration.effects import library, nominal


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(tz.example_path("ftdcr_v4/calibration.json").with_name("rod_vs_cc.json")))
    a = ap.parse_args(argv)
    robot, report, train, val = _ftdcr.load()
    fit_rows, held = train.split(0.25)
    full = train.concat(val)
    pad = np.zeros(val.n_samples, bool)
    fit_rows, held, vmask = np.r_[fit_rows, pad], np.r_[held, pad], np.r_[np.zeros(train.n_samples, bool), ~pad]
    w, w_all = fit_rows.astype(float), (fit_rows | held).astype(float)
    nom = nominal(train.frame)
    pb = Problem(RobotModel.of(robot), robot, full, tuple(nom) + tuple(library(train.frame)), clock=data_clock(train))
    names = [b.name for b in nom]

    def errors(theta, theta_all, active):
        """Held out by the training groups' fit ``theta``, validation by the refit on every sample."""
        r, r_all = pb.residuals(theta, active), pb.residuals(theta_all, active)
        return {
            "held_out_mm": rmse(r[held]),
            "validate_mm": rmse(r_all[vmask]),
            "validate_aligned_mm": rmse_aligned(r_all[vmask]),
        }

    rows = []
    theta = _initial(pb, train, pb.null.copy(), names)
    for step in report["steps"]:
        active = names + list(step["effects"])
        t0 = time.perf_counter()
        theta = pb.fit(theta, active, w)
        cc = errors(theta, pb.fit(theta, active, w_all), active)
        t1 = time.perf_counter()
        rod_active = active + ["variable_curvature"]
        if pb.loaded(theta, active):
            th_rod = pb.fit(theta, rod_active, w)
            th_rod_all = pb.fit(th_rod, rod_active, w_all)
            rod = errors(th_rod, th_rod_all, rod_active)
            freedom = [
                round(float(v), 3)
                for v in pb.describe(th_rod_all, ["variable_curvature"])["variable_curvature"].values()
            ]
        else:
            rod, freedom = dict(cc), None  # no load: the rod is the constant-curvature segment
        rows.append(
            {
                "effects": step["effects"],
                "constant_curvature": cc,
                "rod": rod,
                "curvature_freedom": freedom,
                "seconds_cc": t1 - t0,
                "seconds_rod": time.perf_counter() - t1,
            }
        )
        print(
            f"{' + '.join(step['effects']) or 'nominal'}: cc {cc['held_out_mm']:.3f} / {cc['validate_mm']:.3f}, "
            f"rod {rod['held_out_mm']:.3f} / {rod['validate_mm']:.3f} mm, freedom {freedom}",
            flush=True,
        )
    Path(a.out).write_text(json.dumps({"pieces": 4, "rows": rows}, indent=1))
    print(
        "\n| model | held out, CC | held out, rod | val, CC | val, rod | val aligned, CC | val aligned, rod | curvature freedom |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---|")
    for r in rows:
        c, d = r["constant_curvature"], r["rod"]
        print(
            f"| {' + '.join(['nominal'] + r['effects'])} | {c['held_out_mm']:.2f} | {d['held_out_mm']:.2f} | "
            f"{c['validate_mm']:.2f} | {d['validate_mm']:.2f} | {c['validate_aligned_mm']:.2f} | "
            f"{d['validate_aligned_mm']:.2f} | {r['curvature_freedom'] or 'no load: the rod is CC'} |"
        )


if __name__ == "__main__":
    main()
