"""What is left on the FTDCR v4 robot: the shipped calibration's residual against history, time and motion.

    python benchmarks/ftdcr_residual.py

Predicts ``train.csv`` and ``val.csv`` with the final model of the shipped report
(``tension_zones/examples/ftdcr_v4/calibration.json``, :func:`~tension_zones.calibration.predict_report`)
and asks where the residual's dependence on the acquisition order comes from (the structure test's
``order`` item):

- **hysteresis**: at the home command (every wire within ``HOME_MM`` of zero) the measured tip should be
  one place; its spread, and its component along the direction of the largest excursion of the
  ``BACK`` samples before, say how much the robot remembers of where it came from;
- **drift** (creep, temperature, a tracker moving): the home tip with that memory removed, against time;
- **tracker latency**: the residual along the predicted direction of motion (a late tracker lags: a
  negative mean);
- and the RMSE per pattern family.
Prints a Markdown summary (the numbers in ``benchmarks/README.md``, *What is left on the FTDCR v4*).
"""

from __future__ import annotations

import json

import numpy as np

import tension_zones as tz
from tension_zones.calibration import predict_report, read_opencr, rmse
from tension_zones.calibration._data import pattern_family

HOME_MM = 0.35
BACK = 15


def main():
    robot = tz.Robot.from_json(tz.example_path("ftdcr_v4/design.json"))
    report = json.loads(tz.example_path("ftdcr_v4/calibration.json").read_text())
    tr = read_opencr(tz.example_path("ftdcr_v4/train.csv"), n_wires=robot.n_wires)
    va = read_opencr(tz.example_path("ftdcr_v4/val.csv"), n_wires=robot.n_wires, servo_ids=tr.servo_ids)
    print(f"model: {' + '.join(report['model']['active'])}")
    pred = {"train": predict_report(report, robot, tr), "val": predict_report(report, robot, va)}
    data = {"train": tr, "val": va}
    print("\n| file | family | samples | RMSE (mm) |\n|---|---|---:|---:|")
    for name, d in data.items():
        fam = np.array([pattern_family(g) for g in d.groups])
        for f in dict.fromkeys(fam):
            m = fam == f
            print(f"| {name} | {f} | {m.sum()} | {rmse(pred[name][m] - d.p[m]):.2f} |")
    q = np.concatenate([tr.q, va.q])
    p = np.concatenate([tr.p, va.p])
    r = p - np.concatenate([pred["train"], pred["val"]])
    stamps = np.concatenate([tr.timestamp, va.timestamp])  # the recordings' clock (s): val follows train
    minutes = (stamps - stamps[0]) / 60.0
    home = np.nonzero(np.abs(q).max(axis=1) < HOME_MM)[0]
    home = home[home >= BACK]
    c = np.median(p[home], axis=0)
    u, lat = [], []
    for i in home:
        back = p[i - BACK:i, :2] - c[:2]
        k = np.argmax(np.linalg.norm(back, axis=1))
        u.append(back[k] / np.linalg.norm(back[k]))
        lat.append(p[i, :2] - c[:2])
    u, lat = np.array(u), np.array(lat)
    along = np.sum(lat * u, axis=1)
    across = u[:, 0] * lat[:, 1] - u[:, 1] * lat[:, 0]
    rest = lat - along[:, None] * u
    slope = [np.polyfit(minutes[home], rest[:, j], 1)[0] for j in range(2)]
    res_along = np.sum(r[home, :2] * u, axis=1)
    print(f"\nhome command (every wire within {HOME_MM} mm of zero): {len(home)} samples over "
          f"{minutes[home[-1]] - minutes[home[0]]:.0f} min; lateral spread of the measured tip {rmse(lat):.2f} mm "
          f"(RMS about the median); along the previous excursion {along.mean():+.2f} mm (mean), across it "
          f"{across.mean():+.2f} mm; the model's residual there along it {res_along.mean():+.2f} mm, RMS "
          f"{rmse(r[home]):.2f} mm")
    print(f"drift: the home tip with that memory removed moves {slope[0]:+.3f} / {slope[1]:+.3f} mm per minute "
          f"(x / y), {abs(slope[0]) * (minutes[-1] - minutes[0]):.2f} / {abs(slope[1]) * (minutes[-1] - minutes[0]):.2f} mm "
          f"over the {minutes[-1] - minutes[0]:.0f} min of both files; scatter {rmse(rest):.2f} mm")
    vel = np.concatenate([np.gradient(pred["train"], axis=0), np.gradient(pred["val"], axis=0)])
    speed = np.linalg.norm(vel, axis=1)
    m = speed > 1.0
    a = np.sum(r[m] * vel[m] / speed[m, None], axis=1)
    print(f"latency: residual along the motion {a.mean():+.2f} mm (mean over {m.sum()} moving samples, "
          f"median step {np.median(speed[m]):.1f} mm per sample)")


if __name__ == "__main__":
    main()
