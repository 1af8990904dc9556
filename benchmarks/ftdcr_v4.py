"""FTDCR v4 (real robot): calibrate on train.csv effect by effect, evaluate on val.csv.

    PYTHONPATH=. python benchmarks/ftdcr_v4.py [--data DIR] [--out results.json]

Effects are added in a fixed order and kept only where the held-out RMSE on *training* data
(every 4th pattern group of train.csv) drops by more than 2 %. val.csv is only evaluated on.
Black-box baselines (k-nearest neighbours, polynomial ridge) are trained on the same train.csv,
their hyper-parameters chosen on the same held-out groups.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from tension_zones import robot_fit as rf
from tension_zones.model._robot import Robot
from tension_zones.opencr import read_opencr

HERE = Path(__file__).resolve().parent
DATA = HERE.parent.parent / "shared" / "data" / "opencr_ftdcr_v4"
DESIGN = HERE.parent / "tension_zones" / "examples" / "ftdcr_v4.design.json"
# gravity last: its equilibrium needs the Hessian of the chained pose (slow to compile)
CANDIDATES = ["tendon_angles", "pretension", "slack", "hysteresis", "stiffness", "registration",
              "geometry", "gravity"]


def baselines(tr, va):
    """KNN and polynomial ridge on the commanded displacements; hyper-parameters by group holdout."""
    from sklearn.linear_model import Ridge
    from sklearn.neighbors import KNeighborsRegressor
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import PolynomialFeatures, StandardScaler

    fit_idx, held_idx = rf.group_holdout(tr.patterns)
    models = {
        "knn": [(f"k={k}", lambda k=k: KNeighborsRegressor(k, weights="distance")) for k in (1, 3, 5, 10, 20)],
        "poly_ridge": [
            (f"deg={d}, alpha={a:g}",
             lambda d=d, a=a: make_pipeline(StandardScaler(), PolynomialFeatures(d), Ridge(alpha=a)))
            for d in (1, 2, 3, 4) for a in (1e-3, 1e-1, 10.0)
        ],
    }
    out = {}
    for name, grid in models.items():
        scores = []
        for label, make in grid:
            m = make().fit(tr.q[fit_idx], tr.p[fit_idx])
            scores.append((rf.rmse(m.predict(tr.q[held_idx]), tr.p[held_idx]), label, make))
        h, label, make = min(scores, key=lambda s: s[0])
        m = make().fit(tr.q, tr.p)
        pv = m.predict(va.q)
        out[name] = dict(choice=label, rmse_holdout_mm=h, rmse_val_mm=rf.rmse(pv, va.p),
                         rmse_val_aligned_mm=rf.rmse_aligned(pv, va.p))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=str(DATA))
    ap.add_argument("--design", default=str(DESIGN))
    ap.add_argument("--out", default=None)
    ap.add_argument("--effects", default=",".join(CANDIDATES), help="candidate order, comma-separated")
    args = ap.parse_args(argv)
    t0 = time.time()
    tr = read_opencr(Path(args.data) / "train.csv")
    va = read_opencr(Path(args.data) / "val.csv", servo_ids=tr.servo_ids)
    robot = Robot.from_json(args.design)

    base = baselines(tr, va)
    a0 = rf.initial_segment_angles(robot, tr.q, tr.p, tr.labels)
    _, hist = rf.forward_selection(robot, tr.q, tr.p, tr.patterns, args.effects.split(","),
                                      init={"segment_angle": a0}, verbose=True)

    # refit every accepted model on all of train.csv, then evaluate once on val.csv
    rows, effects, prev = [], [], {"segment_angle": a0}
    for h in hist:
        if h["effect"] != "base":
            if not h["kept"]:
                rows.append(dict(effect=h["effect"], kept=False, rmse_holdout_mm=h["rmse_holdout_mm"]))
                continue
            effects.append(h["effect"])
        res = rf.fit(robot, tr.q, tr.p, effects, init=prev)
        prev = res.params
        pv = rf.predict(robot, res.params, va.q)
        rows.append(dict(effect=h["effect"], kept=True, rmse_holdout_mm=h["rmse_holdout_mm"],
                         rmse_train_mm=res.rmse_fit_mm, rmse_val_mm=rf.rmse(pv, va.p),
                         rmse_val_aligned_mm=rf.rmse_aligned(pv, va.p)))
    final = res

    print("\nFTDCR v4: effects added in order (kept only if the held-out train RMSE drops > 2 %)")
    print(f"{'effect':<16}{'kept':>6}{'holdout':>10}{'train':>9}{'val':>9}{'val aligned':>13}   (mm)")
    for r in rows:
        if r["kept"]:
            print(f"{'+' + r['effect']:<16}{'yes':>6}{r['rmse_holdout_mm']:>10.2f}{r['rmse_train_mm']:>9.2f}"
                  f"{r['rmse_val_mm']:>9.2f}{r['rmse_val_aligned_mm']:>13.2f}")
        else:
            print(f"{'+' + r['effect']:<16}{'no':>6}{r['rmse_holdout_mm']:>10.2f}{'-':>9}{'-':>9}{'-':>13}")
    print("\nblack-box baselines (trained on train.csv)")
    for name, b in base.items():
        print(f"{name:<16}{b['choice']:>22}  holdout {b['rmse_holdout_mm']:.2f}  val {b['rmse_val_mm']:.2f}"
              f"  val aligned {b['rmse_val_aligned_mm']:.2f}")
    print(f"\nfinal model ({', '.join(['base'] + effects)}), fitted on all of train.csv:")
    print(final.table())
    print(f"\ntotal time {time.time() - t0:.0f} s")
    if args.out:
        Path(args.out).write_text(json.dumps(dict(
            rows=rows, baselines=base, effects=["base"] + effects,
            parameters={k: np.asarray(v).tolist() for k, v in final.params.items()},
            std={k: np.asarray(v).tolist() for k, v in final.std.items()}), indent=2))


if __name__ == "__main__":
    main()
