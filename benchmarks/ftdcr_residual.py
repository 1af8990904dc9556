"""What is left on the FTDCR v4 robot: the shipped calibration's residual against history, time and motion.

    python benchmarks/ftdcr_residual.py

Predicts ``train.csv`` and ``val.csv`` with the final model of the shipped report
(``tension_zones/examples/ftdcr_v4/calibration.json``, :func:`~tension_zones.calibration.predict_report`)
and asks where the residual's dependence on the acquisition order comes from (the structure test's
``order`` item):

- **hysteresis and drift** (:func:`~tension_zones.calibration.home_memory`): at the home command (every
  wire within ``HOME_MM`` of zero) the measured tip should be in one place; how far it sits along the
  direction of the largest excursion of the ``BACK`` samples before is memory, a trend against time
  (creep, temperature, a tracker moving) is drift, both fitted together;
- **tracker latency**: the residual along the predicted direction of motion (a late tracker lags: a
  negative mean);
- the RMSE per pattern family, and how far the tip moves from home, measured against predicted.
Prints a Markdown summary.
"""

from __future__ import annotations

import _ftdcr  # (benchmarks/, the script's folder)
import numpy as np

from tension_zones.calibration import home_memory, predict_report, rmse
from tension_zones.calibration._data import pattern_family
from tension_zones.calibration._diagnose import previous_excursion

HOME_MM = 0.35
BACK = 15
DEFLECTION_MM = 40.0


def main():
    robot, report, tr, va = _ftdcr.load()
    print(f"model: {' + '.join(report['model']['active'])}")
    pred = {"train": predict_report(report, robot, tr), "val": predict_report(report, robot, va)}
    data = {"train": tr, "val": va}
    print("\n| file | family | samples | RMSE (mm) |\n|---|---|---:|---:|")
    for name, d in data.items():
        fam = np.array([pattern_family(g) for g in d.groups])
        for f in dict.fromkeys(fam):
            m = fam == f
            print(f"| {name} | {f} | {m.sum()} | {rmse(pred[name][m] - d.p[m]):.2f} |")
    both = tr.concat(va)  # val follows train on the recordings' clock
    r = both.p - np.concatenate([pred["train"], pred["val"]])
    h = home_memory(both, HOME_MM, BACK)
    res_along = np.sum(r[h["index"]] * h["direction"], axis=1)
    print(
        f"\nhome command (every wire within {HOME_MM} mm of zero): {h['n']} samples over {h['span']:.0f} min; "
        f"spread of the measured tip {h['spread_mm']:.2f} mm (RMS about the median); memory along the previous "
        f"excursion {h['along_mm']:.2f} +- {h['along_std_mm']:.2f} mm, the rest {h['across_mm']:.2f} mm RMS; "
        f"the model's residual there along it {res_along.mean():+.2f} mm, RMS {rmse(r[h['index']]):.2f} mm"
    )
    v, sv = h["drift_mm"], h["drift_std_mm"]
    print(
        "drift (fitted with the memory): "
        + ", ".join(f"{c} {a:+.3f} +- {b:.3f}" for c, a, b in zip("xyz", v, sv))
        + f" mm per minute, i.e. {np.abs(v).max() * h['span']:.2f} mm at most over the {h['span']:.0f} min"
    )
    vel = np.concatenate([np.gradient(pred["train"], axis=0), np.gradient(pred["val"], axis=0)])
    speed = np.linalg.norm(vel, axis=1)
    m = speed > 1.0
    a = np.sum(r[m] * vel[m] / speed[m, None], axis=1)
    print(
        f"latency: residual along the motion {a.mean():+.2f} mm (mean over {m.sum()} moving samples, "
        f"median step {np.median(speed[m]):.1f} mm per sample)"
    )
    # every wire paid out (the single-tendon pulls' ends): nothing holds the robot but its elasticity
    p_hat = np.concatenate([pred["train"], pred["val"]])
    home_p, home_hat = np.median(both.p[h["index"]], axis=0), np.median(p_hat[h["index"]], axis=0)
    slack = np.flatnonzero(both.q.min(axis=1) > 0.0)
    slack = slack[slack >= BACK]
    if len(slack):
        off = both.p[slack] - home_p
        cos = np.sum(off * previous_excursion(both.p, slack, home_p, BACK), axis=1) / np.linalg.norm(off, axis=1)
        print(
            f"every wire paid out: {len(slack)} samples; the measured tip {rmse(off):.2f} mm (RMS) from home, "
            f"toward the largest excursion of the {BACK} samples before (cosine median {np.median(cos):.2f}, "
            f"least {np.min(cos):.2f}); the model's {rmse(p_hat[slack] - home_hat):.2f} mm, its residual "
            f"there {rmse(r[slack]):.2f} mm RMS"
        )
    # how far the tip moves from home, measured against predicted (each from its own home tip), by family
    fam = np.concatenate([[pattern_family(g) for g in d.groups] for d in data.values()])
    dm = np.linalg.norm(both.p - home_p, axis=1)
    dp = np.linalg.norm(p_hat - home_hat, axis=1)
    big = dp > DEFLECTION_MM
    print(
        "deflection from home, measured / predicted (median over predicted deflections above "
        f"{DEFLECTION_MM:.0f} mm): "
        + ", ".join(
            f"{f} {np.median(dm[k] / dp[k]):.3f} ({k.sum()})"
            for f in dict.fromkeys(fam)
            if (k := big & (fam == f)).any()
        )
    )


if __name__ == "__main__":
    main()
