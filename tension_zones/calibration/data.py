"""Measurement sets (MODEL.md Sec. 6): reading, validation, bad-row handling, train/held-out split.

The edge of the calibration code: everything here is NumPy, and every problem is reported as one
line naming the column and the row (``row`` = 1-based data row, the header not counted).
"""

from __future__ import annotations

import csv
import dataclasses
import math
import re
from pathlib import Path

import numpy as np

FORCE_COLS = ("fx", "fy", "fz")
POS_COLS = ("px", "py", "pz")
ROT_COLS = ("rx", "ry", "rz")
#: Largest tip force accepted as physical (N): beyond it a single segment would be crushed.
MAX_FORCE_N = 1e3
#: More bad rows than this fraction (or a run of more than MAX_BAD_RUN) is not "isolated".
MAX_BAD_FRACTION = 0.05
MAX_BAD_RUN = 2


class DataError(ValueError):
    """A measurement set that cannot be used as it is (message: one line)."""


@dataclasses.dataclass(frozen=True)
class Dataset:
    """A measurement set in acquisition order. Arrays have the sample axis first.

    ``rot`` may be ``None`` (a format without orientations); ``dropped`` lists the rows removed by
    ``drop_bad`` as ``{"row", "sample", "column", "reason"}``.
    """

    sample: np.ndarray  # (N,) int
    q: np.ndarray  # (N, n) mm
    f: np.ndarray  # (N, 3) N
    p: np.ndarray  # (N, 3) mm
    rot: np.ndarray | None = None  # (N, 3) rad
    dropped: tuple = ()
    source: str = ""

    @property
    def n_samples(self) -> int:
        return int(self.q.shape[0])

    @property
    def n_wires(self) -> int:
        return int(self.q.shape[1])

    def split(self, holdout: float = 0.25):
        """Boolean masks ``(train, held_out)``: the first ``1 - holdout`` in acquisition order trains."""
        if not (0.0 < holdout < 1.0):
            raise DataError(f"--holdout must be between 0 and 1 (exclusive), got {holdout}")
        n = self.n_samples
        n_train = int(round(n * (1.0 - holdout)))
        if n_train < 10 or n - n_train < 10:
            raise DataError(
                f"holdout {holdout} leaves {n_train} training and {n - n_train} held-out samples; "
                "both need at least 10"
            )
        train = np.arange(n) < n_train
        return train, ~train


def _wire_columns(header: list[str]) -> list[str]:
    qs = sorted((c for c in header if re.fullmatch(r"q\d+", c)), key=lambda c: int(c[1:]))
    for i, c in enumerate(qs, start=1):
        if c != f"q{i}":
            raise DataError(f"wire columns must be q1..qn without gaps; found {', '.join(qs)}")
    return qs


def _bad_cells(col: str, values: np.ndarray, length: float | None):
    """(row index, reason) of every bad cell of one column."""
    bad = []
    finite = np.isfinite(values)
    for i in np.flatnonzero(~finite):
        bad.append((i, f"value {values[i]} is not finite"))
    v = np.where(finite, values, 0.0)
    if col.startswith("q") and length is not None:
        for i in np.flatnonzero(np.abs(v) >= length):
            bad.append((i, f"wire displacement {v[i]:g} mm is not smaller than the segment length "
                           f"{length:g} mm (non-physical)"))
    if col in FORCE_COLS:
        for i in np.flatnonzero(np.abs(v) > MAX_FORCE_N):
            bad.append((i, f"force {v[i]:g} N exceeds {MAX_FORCE_N:g} N (non-physical)"))
    return bad


def load_csv(path, n_wires: int | None = None, length: float | None = None,
             drop_bad: bool = False) -> Dataset:
    """Read and validate a measurement set.

    Args:
        path: the CSV file (columns of MODEL.md Sec. 6).
        n_wires: the design's wire count; the ``q`` columns must agree.
        length: the design's segment length (mm), for the physical-range check of ``q``.
        drop_bad: drop isolated bad rows (non-finite or non-physical values, repeated sample
            numbers) instead of failing; they are listed in ``Dataset.dropped``.

    Raises:
        DataError: one line naming the column and the row.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"data file {str(path)!r} does not exist")
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        raise DataError(f"data file {str(path)!r} is empty")
    header = [h.strip() for h in rows[0]]
    body = [r for r in rows[1:] if any(x.strip() for x in r)]
    qcols = _wire_columns(header)
    if not qcols:
        raise DataError(f"{path.name}: missing the wire columns q1..qn")
    if n_wires is not None and len(qcols) != n_wires:
        raise DataError(f"the design has {n_wires} wires but {path.name} has {len(qcols)} wire "
                        f"columns ({qcols[0]}..{qcols[-1]})")
    need = ["sample", *qcols, *FORCE_COLS, *POS_COLS, *ROT_COLS]
    for c in need:
        if c not in header:
            raise DataError(f"{path.name}: missing column {c!r} (have: {', '.join(header)})")
    if not body:
        raise DataError(f"{path.name} has no data rows")
    idx = {c: header.index(c) for c in need}
    cols: dict[str, np.ndarray] = {}
    for c in need:
        vals = np.empty(len(body))
        for i, r in enumerate(body):
            if idx[c] >= len(r):
                raise DataError(f"{path.name}: row {i + 1} has {len(r)} fields, column {c!r} is missing")
            try:
                vals[i] = float(r[idx[c]])
            except ValueError:
                raise DataError(f"{path.name}: column {c!r}, row {i + 1}: {r[idx[c]]!r} is not a number") from None
        cols[c] = vals

    bad: dict[int, tuple[str, str]] = {}
    for c in need:
        if c == "sample":
            continue
        for i, why in _bad_cells(c, cols[c], length):
            bad.setdefault(int(i), (c, why))
    rotn = np.linalg.norm(np.stack([cols[c] for c in ROT_COLS], 1), axis=1)
    for i in np.flatnonzero(np.isfinite(rotn) & (rotn > math.pi * (1 + 1e-6))):
        bad.setdefault(int(i), ("rx", f"rotation vector norm {rotn[i]:.4g} rad exceeds pi (non-physical)"))
    sample = cols["sample"]
    for i in np.flatnonzero(~np.isfinite(sample) | (sample != np.round(sample))):
        bad.setdefault(int(i), ("sample", f"value {sample[i]} is not an integer"))
    seen: dict[float, int] = {}
    for i, s in enumerate(sample):
        if s in seen and i not in bad:
            bad.setdefault(i, ("sample", f"sample number {s:g} repeats row {seen[s] + 1}"))
        seen.setdefault(s, i)

    if bad and not drop_bad:
        i = min(bad)
        c, why = bad[i]
        more = f" ({len(bad) - 1} more bad rows; --drop-bad drops isolated ones)" if len(bad) > 1 else ""
        raise DataError(f"{path.name}: column {c!r}, row {i + 1} (sample {_fmt(sample[i])}): {why}{more}")
    keep = np.ones(len(body), bool)
    keep[list(bad)] = False
    if bad:
        _check_isolated(path.name, sorted(bad), len(body))
    good = np.flatnonzero(keep)
    order = np.argsort(sample[good], kind="stable")
    if np.any(np.diff(order) < 0):
        i = good[int(np.flatnonzero(np.diff(order) < 0)[0]) + 1]
        raise DataError(f"{path.name}: column 'sample', row {i + 1}: samples must be in acquisition "
                        f"order (increasing), got {_fmt(sample[i])} after a larger number")
    dropped = tuple({"row": i + 1, "sample": _fmt(sample[i]), "column": bad[i][0], "reason": bad[i][1]}
                    for i in sorted(bad))

    def stack(cs):
        return np.stack([cols[c][good] for c in cs], axis=1)

    return Dataset(sample=sample[good].astype(np.int64), q=stack(qcols), f=stack(FORCE_COLS),
                   p=stack(POS_COLS), rot=stack(ROT_COLS), dropped=dropped, source=str(path))


def _fmt(x) -> str:
    return f"{x:g}" if np.isfinite(x) else str(x)


def _check_isolated(name: str, rows: list[int], n: int) -> None:
    if len(rows) > max(1, int(MAX_BAD_FRACTION * n)):
        raise DataError(f"{name}: {len(rows)} of {n} rows are bad (first: row {rows[0] + 1}); more than "
                        f"{MAX_BAD_FRACTION:.0%} is not isolated, fix the file")
    run = 1
    for a, b in zip(rows, rows[1:]):
        run = run + 1 if b == a + 1 else 1
        if run > MAX_BAD_RUN:
            raise DataError(f"{name}: rows {b - run + 2}..{b + 1} are all bad; a run of more than "
                            f"{MAX_BAD_RUN} is not isolated, fix the file")
