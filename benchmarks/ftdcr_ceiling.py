"""How far the effect library can take the FTDCR v4 robot on its validation file.

    python benchmarks/ftdcr_ceiling.py

Starts from the shipped report's final model (``tension_zones/examples/ftdcr_v4/calibration.json``:
its effects and parameters) and refits it, alone, with each library effect it does not hold, and with
all of them at once, three ways:

- on the loop's training groups (``Dataset.split``: every fourth pattern group held out), as the loop
  decides: the held-out error, and the share of the final model's held-out excess over the noise floor
  that the effect explains (the loop adds an effect only where it explains at least a quarter of it
  near the noise floor, less in proportion further above: 11.3 % here, beside a significant drop),
  i.e. what the loop's evidence says;
- on every sample of ``train.csv`` (what the loop's final refit does; ``val.csv`` is only predicted):
  the validation error a user would get had the loop added that effect as well;
- on ``train.csv`` and ``val.csv`` together (one set of parameters for the one robot): ``val.csv`` is
  then no validation at all, but its error says how close that model can come to both recordings at
  once, i.e. whether a validation target is within the model's reach (each refit: at most
  ``ITERATIONS`` Levenberg-Marquardt passes from the final model).

The rod (``variable_curvature``) is left out: with the one load this robot has it moves nothing by
more than 0.13 mm (``benchmarks/ftdcr_rod.py``). Prints a Markdown table (``benchmarks/README.md``).
Nothing here feeds a decision of the loop.
"""

from __future__ import annotations

import json
import time

import _ftdcr  # (benchmarks/, the script's folder)
import numpy as np

from tension_zones.calibration import rmse
from tension_zones.calibration._data import pattern_family
from tension_zones.calibration._model import RobotModel, data_clock
from tension_zones.calibration._problem import Problem
from tension_zones.calibration.effects import BY_NAME

#: Iterations of each refit (the loop's default is 40; these start from the final model, not from null).
ITERATIONS = 80


def main():
    robot, report, train, val = _ftdcr.load()
    m = report["model"]
    pb = Problem(
        RobotModel.of(robot), robot, train.concat(val), tuple(BY_NAME[n] for n in m["blocks"]), clock=data_clock(train)
    )
    vmask = np.arange(train.n_samples + val.n_samples) >= train.n_samples
    w_train, w_both = (~vmask).astype(float), np.ones(vmask.size)
    fit_rows, held_rows = (np.r_[mask, np.zeros(val.n_samples, bool)] for mask in train.split())
    floor = report["noise_floor_mm"]
    fam = np.array([pattern_family(g) for g in val.groups])
    theta0, final = np.asarray(m["theta"], float), list(m["active"])
    extra = [n for n in m["blocks"] if n not in final and n != "variable_curvature"]
    print(f"final model: {' + '.join(final)}", flush=True)
    rows = []
    for add in [None] + [[e] for e in extra] + [extra]:
        active = final + (add or [])
        t0 = time.perf_counter()
        held = rmse(
            pb.residuals(pb.fit(theta0, active, fit_rows.astype(float), max_iter=ITERATIONS), active)[held_rows]
        )
        held_final = held if add is None else rows[0]["held_out_mm"]
        th = pb.fit(theta0, active, w_train, max_iter=ITERATIONS)
        r = pb.residuals(th, active)
        th_both = pb.fit(th, active, w_both, max_iter=ITERATIONS)
        r_both = pb.residuals(th_both, active)
        name = "final" if not add else f"final + {add[0]}" if len(add) == 1 else "final + all of them"
        rv, rv_both = r[vmask], r_both[vmask]
        row = {
            "model": name,
            "held_out_mm": held,
            "held_out_share": (held_final**2 - held**2) / (held_final**2 - floor**2),
            "train_mm": rmse(r[~vmask]),
            "validate_mm": rmse(rv),
            "validate_in_fit_mm": rmse(rv_both),
            "train_in_joint_fit_mm": rmse(r_both[~vmask]),
            "by_family_mm": {f: [rmse(rv[fam == f]), rmse(rv_both[fam == f])] for f in dict.fromkeys(fam)},
            "seconds": time.perf_counter() - t0,
        }
        rows.append(row)
        print(json.dumps(row), flush=True)
    print(
        "\n| model | held out (share of the excess) | train (fitted on train) | val (predicted) | "
        "val (fitted on train + val) | train (fitted on train + val) |\n|---|---:|---:|---:|---:|---:|"
    )
    for r in rows:
        print(
            f"| {r['model']} | {r['held_out_mm']:.2f} ({100 * r['held_out_share']:+.1f} %) | {r['train_mm']:.2f} | "
            f"{r['validate_mm']:.2f} | {r['validate_in_fit_mm']:.2f} | {r['train_in_joint_fit_mm']:.2f} |"
        )
    print(
        "\nThe final model by family of val.csv (predicted / fitted on train + val): "
        + ", ".join(f"{f} {a:.2f} / {b:.2f} mm" for f, (a, b) in rows[0]["by_family_mm"].items())
    )


if __name__ == "__main__":
    main()
