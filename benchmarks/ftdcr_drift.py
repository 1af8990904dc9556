"""Is there a drift of the wires on the FTDCR v4 robot? A time profile of their common slack.

    python benchmarks/ftdcr_drift.py

The ``drift`` effect (one rate for every wire's length over the recording's time) lowers the FTDCR v4
held-out and validation errors when it is added. A drift is a function of time; this script asks whether the data say so.
Starting from the shipped report's final model it refits, on every sample of ``train.csv``:

- the model with the drift (its rate, and ``val.csv`` predicted with the drift held at the training
  file's end, as the calibration does);
- the model with a common slack of every wire per time bin instead (``BINS`` bins of equal length over
  ``train.csv``, the first at 0; ``val.csv`` takes the last bin's): a steady drift makes the bins' values
  grow in steps of equal size, a step where the patterns change points at the patterns, not the clock.
  The recording drives one kind of pattern after another (single tendons, then segments, then pairs),
  so the bins also say which patterns each holds;
- the model with a common slack per kind of pattern instead (single tendons at 0; each segment alone;
  each pair), and with that and the drift together: which of time and pattern the slack goes with;
- the model with a slack per kind of pattern for the wires of each segment: which wires carry it.

Nothing here feeds a decision of the loop.
"""

from __future__ import annotations

import dataclasses
import time

import _ftdcr  # (benchmarks/, the script's folder)
import jax.numpy as jnp
import numpy as np

from tension_zones.calibration import rmse
from tension_zones.calibration._model import RobotModel, data_clock
from tension_zones.calibration._problem import Problem
from tension_zones.calibration.effects import BY_NAME, Effect
from tension_zones.calibration.effects._base import replace

BINS = 8
ITERATIONS = 80


@dataclasses.dataclass(frozen=True)
class TimeBins(Effect):
    """A common slack of every wire (mm) per bin of the clock's span (the first bin's is 0)."""

    name = "time_bins"
    span: float = 1.0  # hours

    def size(self, model, phys0):
        return BINS - 1

    def on_inputs(self, theta, inputs, model, on):
        k = jnp.clip(jnp.floor(inputs["hours"] / self.span * BINS), 0, BINS - 1).astype(int)
        slack = jnp.concatenate([jnp.zeros(1, theta.dtype), theta])[k]
        return replace(inputs, q=inputs["q"] + slack[:, None])


KINDS = ("tendon", "seg1", "seg2", "seg3", "pair12", "pair13", "pair23")


def kind(label: str) -> str:
    """A pattern label's kind (``rep1_pair23_same_dir0`` -> ``pair23``; the single tendons: ``tendon``)."""
    k = label.split("_")[1]
    return "tendon" if k.startswith("tendon") else k


@dataclasses.dataclass(frozen=True)
class KindSlack(Effect):
    """A common slack of every wire (mm) per kind of pattern of ``train.csv`` (the single tendons' 0);
    ``index`` (N,): each sample's kind (``val.csv``'s samples: -1, no slack). ``per_segment``: one slack
    per kind for the wires of each segment instead (:class:`KindSlackBySegment`)."""

    name = "kind_slack"
    index: tuple = ()
    per_segment: bool = False

    def size(self, model, phys0):
        return (len(KINDS) - 1) * (model.structure.n_segments if self.per_segment else 1)

    def on_inputs(self, theta, inputs, model, on):
        n = inputs["q"].shape[0]
        idx = np.r_[self.index, np.full(n - len(self.index), -1)]
        table = theta.reshape(len(KINDS) - 1, -1)  # (kinds, segments or 1)
        zero = jnp.zeros((1, table.shape[1]), theta.dtype)
        slack = jnp.concatenate([zero, table, zero])[idx]  # (N, segments or 1)
        return replace(inputs, q=inputs["q"] + (slack[:, model.structure.owner] if self.per_segment else slack))


@dataclasses.dataclass(frozen=True)
class KindSlackBySegment(KindSlack):
    """:class:`KindSlack` with one slack per kind for the wires of each segment."""

    name = "kind_slack_seg"
    per_segment: bool = True


def main():
    robot, report, train, val = _ftdcr.load()
    m = report["model"]
    clock = data_clock(train)
    bins = TimeBins(span=clock[1])  # (the last sample's bin index is clipped to the last bin)
    index = tuple(KINDS.index(kind(g)) for g in train.groups) + (-1,) * val.n_samples
    blocks = tuple(BY_NAME[n] for n in m["blocks"] if n != "drift") + (
        BY_NAME["drift"],
        bins,
        KindSlack(index=index),
        KindSlackBySegment(index=index),
    )
    pb = Problem(RobotModel.of(robot), robot, train.concat(val), blocks, clock=clock)
    vmask = np.arange(train.n_samples + val.n_samples) >= train.n_samples
    sl = pb.spec.slices()
    theta0 = pb.null.copy()
    for name, block in zip(
        m["blocks"],
        np.split(
            np.asarray(m["theta"], float), np.cumsum([BY_NAME[n].size(pb.model, pb._phys_np) for n in m["blocks"]])[:-1]
        ),
    ):
        theta0[sl[name]] = block
    final = [a for a in m["active"] if a != "drift"]
    print(f"final model: {' + '.join(final)}; train.csv spans {clock[1] * 60:.1f} min", flush=True)
    for extra in ([], ["drift"], ["time_bins"], ["kind_slack"], ["kind_slack", "drift"], ["kind_slack_seg"]):
        t0 = time.perf_counter()
        th = pb.fit(theta0, final + extra, (~vmask).astype(float), max_iter=ITERATIONS)
        r = pb.residuals(th, final + extra)
        line = f"{' + '.join(['final'] + extra)}: train {rmse(r[~vmask]):.3f} mm, val {rmse(r[vmask]):.3f} mm"
        if "drift" in extra:
            line += f"; rate {th[sl['drift']][0]:.3f} mm/h"
        if "kind_slack" in extra:
            line = line.replace(", val", ", val (no slack)")
            line += "; common slack by kind (mm): " + ", ".join(
                f"{k} {v:+.3f}" for k, v in zip(KINDS, np.r_[0.0, th[sl["kind_slack"]]])
            )
        if extra == ["kind_slack_seg"]:
            line = line.replace(", val", ", val (no slack)")
            table = th[sl["kind_slack_seg"]].reshape(len(KINDS) - 1, -1)
            line += "; slack of each segment's wires by kind (mm): " + ", ".join(
                f"{k} " + " ".join(f"{v:+.3f}" for v in row) for k, row in zip(KINDS[1:], table)
            )
            line += "; preload (N): " + " ".join(f"{v:.1f}" for v in th[sl["preload"]])
        if extra == ["time_bins"]:
            width = clock[1] * 60 / BINS
            line += f"; common slack per {width:.1f}-min bin (mm): " + ", ".join(
                f"{v:+.3f}" for v in np.r_[0.0, th[sl["time_bins"]]]
            )
            hours = np.clip((train.timestamp - clock[0]) / 3600, 0, clock[1])
            k = np.minimum((hours / clock[1] * BINS).astype(int), BINS - 1)
            groups = np.array(train.groups)
            line += "\n  patterns per bin: " + "; ".join(
                f"{b}: " + ", ".join(sorted({kind(g) for g in groups[k == b]}, key=KINDS.index)) for b in range(BINS)
            )
        print(line + f" ({time.perf_counter() - t0:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
