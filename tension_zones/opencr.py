"""Reader for the OpenCR lab's tendon-robot recordings (e.g. FTDCR v4 system identification).

Format: a CSV with ``timestamp`` (s), ``pattern_label``, one ``servo_<id>_mm`` column per tendon
(displacement at the actuator, mm, *positive = pulled in*) and ``tip_x, tip_y, tip_z`` (mm, motion
capture). Labels such as ``rep1_tendon4_id2_pull`` say that tendon index 4 is driven by servo 2;
tendon ``i`` belongs to segment ``i // n_per_segment`` (proximal first), tendon ``i % n`` within it.

Returned wire displacements follow MODEL.md Sec. 5: ``q = -servo_mm`` (negative = pulled in),
columns in tendon order (segment 0's tendons first), i.e. the wire order of a
:class:`~tension_zones.multisegment.Robot`.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import re
from pathlib import Path

import numpy as np

_SERVO = re.compile(r"^servo_(\d+)_mm$")
_TENDON = re.compile(r"tendon(\d+)_id(\d+)")
TIP = ("tip_x", "tip_y", "tip_z")


@dataclasses.dataclass(frozen=True)
class OpenCRData:
    """One recording: ``q`` (T, N) mm in MODEL.md's sign convention, tendon order; ``p`` (T, 3) mm;
    ``timestamp`` (T,) s; ``labels`` (T,) pattern labels; ``servo_ids`` (N,) the servo of each tendon."""

    timestamp: np.ndarray
    labels: tuple[str, ...]
    q: np.ndarray
    p: np.ndarray
    servo_ids: tuple[int, ...]

    def __len__(self) -> int:
        return len(self.labels)

    @property
    def patterns(self) -> tuple[str, ...]:
        """Each row's pattern group: the label without its ``_hold`` suffix."""
        return tuple(re.sub(r"_hold$", "", s) for s in self.labels)

    def subset(self, idx) -> OpenCRData:
        idx = np.asarray(idx)
        labels = tuple(np.asarray(self.labels, dtype=object)[idx])
        return OpenCRData(self.timestamp[idx], labels, self.q[idx], self.p[idx], self.servo_ids)


def servo_map_from_labels(labels) -> dict[int, int]:
    """``{tendon index: servo id}`` from labels like ``..._tendon4_id2_...``; contradictions raise."""
    out: dict[int, int] = {}
    for row, lab in enumerate(labels, start=2):
        for t, s in _TENDON.findall(lab):
            t, s = int(t), int(s)
            if out.get(t, s) != s:
                raise ValueError(
                    f"pattern_label row {row}: tendon {t} is driven by servo {s} here but by servo "
                    f"{out[t]} earlier ({lab!r})"
                )
            out[t] = s
    return out


def read_opencr(path, servo_ids=None, n_wires: int | None = None) -> OpenCRData:
    """Read an OpenCR CSV. ``servo_ids`` (tendon order) overrides the mapping in the labels (needed
    for files without single-tendon labels, e.g. a validation set); ``n_wires`` checks the count.

    Errors are one-line ``ValueError``s naming the column and the (1-based, header = 1) row.
    """
    path = Path(path)
    try:
        with path.open(newline="") as fh:
            rows = list(csv.reader(fh))
    except FileNotFoundError:
        raise ValueError(f"data file {str(path)!r} does not exist") from None
    if not rows:
        raise ValueError(f"{path.name}: empty file")
    header = [h.strip() for h in rows[0]]
    servo_cols = {int(m.group(1)): i for i, h in enumerate(header) if (m := _SERVO.match(h))}
    for col in ("timestamp", "pattern_label", *TIP):
        if col not in header:
            raise ValueError(f"{path.name}: missing column {col!r}")
    if not servo_cols:
        raise ValueError(f"{path.name}: no servo_<id>_mm columns")
    dup = [h for h in set(header) if header.count(h) > 1]
    if dup:
        raise ValueError(f"{path.name}: duplicate column {sorted(dup)[0]!r}")
    body = rows[1:]
    if not body:
        raise ValueError(f"{path.name}: no data rows")
    labels = []
    for r, row in enumerate(body, start=2):
        if len(row) != len(header):
            raise ValueError(f"{path.name}: row {r} has {len(row)} fields, the header {len(header)}")
        labels.append(row[header.index("pattern_label")].strip())

    if servo_ids is None:
        m = servo_map_from_labels(labels)
        n = len(servo_cols)
        missing = [t for t in range(n) if t not in m]
        if missing:
            raise ValueError(
                f"{path.name}: no 'tendon<i>_id<servo>' pattern label for tendon {missing[0]}; "
                f"pass servo_ids (tendon order)"
            )
        servo_ids = [m[t] for t in range(n)]
    servo_ids = tuple(int(s) for s in servo_ids)
    if len(set(servo_ids)) != len(servo_ids):
        raise ValueError(f"servo_ids {list(servo_ids)} repeat a servo")
    for s in servo_ids:
        if s not in servo_cols:
            raise ValueError(f"{path.name}: missing column 'servo_{s}_mm'")
    extra = sorted(set(servo_cols) - set(servo_ids))
    if extra:
        raise ValueError(f"{path.name}: column 'servo_{extra[0]}_mm' drives no tendon of the mapping")
    if n_wires is not None and len(servo_ids) != n_wires:
        raise ValueError(
            f"{path.name}: {len(servo_ids)} servo columns but the design has {n_wires} wires"
        )

    def column(name, idx):
        out = np.empty(len(body))
        for r, row in enumerate(body):
            try:
                v = float(row[idx])
            except ValueError:
                raise ValueError(
                    f"{path.name}: column {name!r}, row {r + 2}: not a number ({row[idx]!r})"
                ) from None
            if not math.isfinite(v):
                raise ValueError(f"{path.name}: column {name!r}, row {r + 2}: non-finite value {v}")
            out[r] = v
        return out

    t = column("timestamp", header.index("timestamp"))
    back = np.nonzero(np.diff(t) <= 0)[0]
    if back.size:
        raise ValueError(
            f"{path.name}: column 'timestamp', row {back[0] + 3}: not after the previous row "
            f"(samples must be in acquisition order)"
        )
    servo_mm = np.stack([column(f"servo_{s}_mm", servo_cols[s]) for s in servo_ids], axis=1)
    p = np.stack([column(c, header.index(c)) for c in TIP], axis=1)
    return OpenCRData(t, tuple(labels), -servo_mm, p, servo_ids)
