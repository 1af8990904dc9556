"""Measured data: one :class:`Dataset`, read from the tension_zones/MODEL.md Sec. 6 CSV or the OpenCR lab's CSV.

The edge of the calibration code: everything here is NumPy, and every problem is one line naming the
file, the column and the row (``row`` = 1-based data row, the header not counted). Both readers share
the table parsing (UTF-8 with or without a byte-order mark; comma, semicolon or tab delimiters), the
bad-cell rules and ``drop_bad`` (isolated bad rows are dropped and listed instead of failing).

Formats (the full description with examples is in ``docs/pages/formats.md``):

* ``model`` (tension_zones/MODEL.md Sec. 6): ``sample, q1..qn, fx, fy, fz, px, py, pz, rx, ry, rz``; positions in
  the robot's base frame; ``q`` in mm, negative = pulled in.
* ``opencr`` (the OpenCR lab's recordings): ``timestamp, pattern_label, servo_<id>_mm..., tip_x,
  tip_y, tip_z``; servo displacements positive = pulled in (converted to tension_zones/MODEL.md's sign), positions
  in the motion-capture frame; labels such as ``rep1_tendon4_id2_pull`` map servos to tendons.
"""

from __future__ import annotations

import csv
import dataclasses
import itertools
import math
import re
from pathlib import Path

import numpy as np

FORCE_COLS = ("fx", "fy", "fz")
POS_COLS = ("px", "py", "pz")
ROT_COLS = ("rx", "ry", "rz")
TIP_COLS = ("tip_x", "tip_y", "tip_z")
#: Largest tip force accepted as physical (N).
MAX_FORCE_N = 1e3
#: More bad rows than this fraction (or a run of more than MAX_BAD_RUN) is not "isolated".
MAX_BAD_FRACTION = 0.05
MAX_BAD_RUN = 2
#: A tracker glitch: a sample whose position jumps away from both neighbours while they agree and its
#: commands do not. Its second difference (the sample against its neighbours' midpoint) exceeds
#: ``GLITCH_MEDIANS`` times the recording's median one and ``GLITCH_NEIGHBOURS`` times the neighbours'
#: own distance (so a jump to a new pattern is not one), while its commands' second difference is at
#: most their neighbours' distance over ``GLITCH_NEIGHBOURS`` (so a reversal of the motion is not one). For noise alone the second difference is a 3-D
#: chi of sigma sqrt(3/2): 20 medians is about 31 sigma, beyond any chance. Isolated only: where more
#: than ``GLITCH_SHARE`` of the samples qualify, it is the recording's motion, and nothing is dropped.
GLITCH_MEDIANS = 20.0
GLITCH_NEIGHBOURS = 3.0
GLITCH_SHARE = 0.02
#: Plausibility of a recording against its robot (:meth:`Dataset.check_against`), total length ``L``.
#: The tip of an inextensible backbone stays within ``L`` of the base, so two tip positions are at
#: most ``2 L`` apart; a spread above ``MAX_SPREAD_PER_LENGTH L`` (twice that: a marker beyond the
#: tip, registration error) is not millimetres of this robot.
MAX_SPREAD_PER_LENGTH = 4.0
#: A tip that moves less than 1 % of ``L`` bends the robot by about 0.02 rad: nothing to calibrate
#: on, and the signature of positions in metres (a thousandth of the millimetres).
MIN_SPREAD_PER_LENGTH = 0.01
#: A wire shortens by ``r theta`` in each segment it crosses (``r`` its pitch radius there,
#: ``theta`` <= pi the segment's bend: a half turn, more than a continuum segment reaches); allowed:
#: this many times ``pi sum r`` (wire stretch, slack taken up).
MAX_WIRE_TRAVEL_FACTOR = 2.0
#: Positions and commands compared to this many decimals (1 um) when looking for shared rows.
SHARED_DECIMALS = 3
#: A validation file sharing more than this fraction of its rows with the training file is refused.
MAX_SHARED_FRACTION = 0.1
_SERVO = re.compile(r"^servo_(\d+)_mm$")
_TENDON = re.compile(r"tendon(\d+)_id(\d+)")


class DataError(ValueError):
    """Data that cannot be used as they are (message: one line)."""


@dataclasses.dataclass(frozen=True)
class Dataset:
    """Measurements in acquisition order; arrays have the sample axis first.

    ``q`` (N, n) commanded wire displacements (mm, tension_zones/MODEL.md sign: negative = pulled in); ``f`` (N, 3)
    known tip force (N, base frame); ``p`` (N, 3) measured tip position (mm); ``rot`` (N, 3) measured
    orientation (rotation vector, rad) or ``None``. ``frame``: ``"base"`` (positions in the robot's
    base frame, wire angles as designed) or ``"tracker"`` (an unregistered tracker frame, the wire
    pattern's orientation unknown: the calibration then fits both as nominal parameters).
    ``groups``: each sample's pattern group (labelled recordings) or ``None``; ``session`` (N,): the
    recording each sample belongs to (path-dependent state, e.g. backlash, restarts where it
    changes). ``dropped`` lists the rows removed by ``drop_bad`` as ``{"row", "sample", "column",
    "reason"}``.
    """

    sample: np.ndarray
    q: np.ndarray
    f: np.ndarray
    p: np.ndarray
    rot: np.ndarray | None = None
    frame: str = "base"
    groups: tuple | None = None
    session: np.ndarray | None = None
    timestamp: np.ndarray | None = None
    servo_ids: tuple | None = None
    dropped: tuple = ()
    source: str = ""

    def __post_init__(self):
        if self.session is None:
            object.__setattr__(self, "session", np.zeros(len(self.q), np.int64))

    @property
    def n_samples(self) -> int:
        return int(self.q.shape[0])

    @property
    def n_wires(self) -> int:
        return int(self.q.shape[1])

    @property
    def reset(self) -> np.ndarray:
        """(N,) True where a recording starts (path-dependent state restarts there)."""
        s = np.asarray(self.session)
        return np.concatenate([[True], s[1:] != s[:-1]])

    def _label(self, i: int) -> str:
        """Sample ``i`` as the file names it: its sample number, or its data row (OpenCR)."""
        return f"row {self.sample[i]}" if self.frame == "tracker" else f"sample {self.sample[i]}"

    def _wire_column(self, k: int) -> str:
        return f"servo_{self.servo_ids[k]}_mm" if self.servo_ids is not None else f"q{k + 1}"

    def check_against(self, robot, moving: bool = True) -> None:
        """Refuse data that cannot be millimetres of ``robot`` (a :class:`~tension_zones.model.Robot`);
        with ``moving``, also a tip that never moves (data to fit on: a validation file may hold a robot
        whose slack wires leave it still).

        With ``L`` the robot's total length (see the module's constants for the arguments):

        * the tip positions' spread (the largest side of their bounding box, from the 0.5th to the
          99.5th percentile so that a few tracker glitches do not count) at least
          ``MIN_SPREAD_PER_LENGTH L`` (a tip that never moves, or positions in metres) and at most
          ``MAX_SPREAD_PER_LENGTH L`` (not the tip's distance from the base: a tracker far from the
          base is a frame the calibration registers);
        * every wire's commanded displacement at most ``MAX_WIRE_TRAVEL_FACTOR pi sum_j r_kj``, its
          pitch radii summed over the segments it crosses (geometry allows ``pi sum_j r_kj``).

        Raises:
            DataError: one line with the numbers (file, column and sample for a wire).
        """
        name = Path(self.source).name or "the data"
        L = float(np.sum(np.asarray(robot.lengths)))
        cols = POS_COLS if self.frame == "base" else TIP_COLS
        side = np.abs(np.percentile(self.p, 99.5, axis=0) - np.percentile(self.p, 0.5, axis=0))
        a = int(np.argmax(side))
        spread, lo, hi = float(side[a]), MIN_SPREAD_PER_LENGTH * L, MAX_SPREAD_PER_LENGTH * L
        what = f"the tip positions span {spread:.3g} mm (column {cols[a]!r}, their widest) for a robot {L:g} mm long"
        if spread < lo <= 1000 * spread <= hi:
            raise DataError(
                f"{name}: {what}, less than {MIN_SPREAD_PER_LENGTH:.0%} of it: are the positions in "
                f"metres? Millimetres are expected ({1000 * spread:.3g} mm in millimetres)"
            )
        if spread < lo and moving:
            raise DataError(
                f"{name}: the tip never moves: {what}, less than {MIN_SPREAD_PER_LENGTH:.0%} of it ({lo:.3g} mm)"
            )
        if spread > hi:
            raise DataError(
                f"{name}: {what}, but two tips of a robot that long are at most {2 * L:g} mm apart "
                f"(allowed {hi:g} mm): are the positions in millimetres?"
            )
        radii = np.where(robot.crosses, np.asarray(robot.route_radii), 0.0)
        bound = MAX_WIRE_TRAVEL_FACTOR * math.pi * radii.sum(axis=1)
        over = np.abs(self.q) > bound[None, :]
        if np.any(over):
            i, k = (int(x) for x in np.argwhere(over)[0])
            n_seg = int(np.sum(robot.crosses[k]))
            raise DataError(
                f"{name}: column {self._wire_column(k)!r}, {self._label(i)}: wire displacement "
                f"{self.q[i, k]:g} mm, but wire {k + 1} moves at most {bound[k]:.3g} mm ({MAX_WIRE_TRAVEL_FACTOR:g} "
                f"x pi x its pitch radii summed over the {n_seg} segment(s) it crosses, "
                f"{radii[k].sum():g} mm): are the commands in millimetres?"
            )

    def split(self, holdout: float = 0.25):
        """Boolean masks ``(train, held_out)``: the split belongs to the data.

        Recordings made of labelled patterns hold out whole pattern groups: every ``k``-th group in
        order of first appearance, from the ``k``-th (``k = round(1 / holdout)``), so that a held-out
        sample is never next to a training sample of the same motion. Otherwise the tail of the
        acquisition order (the last ``holdout`` fraction).
        """
        if not (0.0 < holdout < 1.0):
            raise DataError(f"--holdout must be between 0 and 1 (exclusive), got {holdout}")
        n = self.n_samples
        if self.groups is not None:
            k = max(int(round(1.0 / holdout)), 2)
            order = list(dict.fromkeys(self.groups))
            if len(order) < k:
                raise DataError(
                    f"{Path(self.source).name}: {len(order)} pattern group(s); holding out every "
                    f"{k}th group (holdout {holdout}) needs at least {k}"
                )
            held_groups = set(order[k - 1 :: k])
            held = np.array([g in held_groups for g in self.groups])
            what = f"every {k}th pattern group"
        else:
            n_train = int(round(n * (1.0 - holdout)))
            held = np.arange(n) >= n_train
            what = f"the last {holdout:g} of the acquisition order"
        n_held = int(held.sum())
        if n - n_held < 10 or n_held < 10:
            raise DataError(
                f"holdout {holdout} ({what}) leaves {n - n_held} training and {n_held} held-out "
                "samples; both need at least 10"
            )
        return ~held, held

    def split_description(self, holdout: float = 0.25) -> str:
        if self.groups is not None:
            k = max(int(round(1.0 / holdout)), 2)
            return (
                f"every {k}th pattern group (in order of first appearance, from the {k}th); whole "
                "groups, so no held-out sample is next to a training sample of the same motion"
            )
        return f"the last {holdout:g} of the acquisition order"

    def concat(self, other: Dataset) -> Dataset:
        """This recording followed by ``other`` as a second session (path-dependent state restarts)."""
        if other.n_wires != self.n_wires or other.frame != self.frame:
            raise DataError(
                f"{Path(other.source).name} does not match {Path(self.source).name} "
                f"({other.n_wires} vs {self.n_wires} wires, frame {other.frame} vs {self.frame})"
            )
        cat = lambda a, b: None if a is None or b is None else np.concatenate([a, b])
        groups = None if self.groups is None or other.groups is None else tuple(self.groups) + tuple(other.groups)
        return dataclasses.replace(
            self,
            sample=np.concatenate([self.sample, other.sample]),
            q=np.concatenate([self.q, other.q]),
            f=np.concatenate([self.f, other.f]),
            p=np.concatenate([self.p, other.p]),
            rot=cat(self.rot, other.rot),
            groups=groups,
            session=np.concatenate(
                [np.asarray(self.session), np.asarray(other.session) + np.asarray(self.session).max() + 1]
            ),
            timestamp=cat(self.timestamp, other.timestamp),
            dropped=self.dropped + other.dropped,
        )

    def subset(self, mask) -> Dataset:
        idx = np.flatnonzero(np.asarray(mask))
        take = lambda a: None if a is None else np.asarray(a)[idx]
        return dataclasses.replace(
            self,
            sample=self.sample[idx],
            q=self.q[idx],
            f=self.f[idx],
            p=self.p[idx],
            rot=take(self.rot),
            groups=None if self.groups is None else tuple(np.asarray(self.groups, dtype=object)[idx]),
            session=np.asarray(self.session)[idx],
            timestamp=take(self.timestamp),
        )


# --------------------------------------------------------------------------------------------
# The shared table layer
# --------------------------------------------------------------------------------------------
def _read_table(path) -> tuple[Path, list[str], list[list[str]]]:
    """Header and non-blank rows of a delimited text file; one-line errors for what is not one."""
    path = Path(path)
    if path.is_dir():
        raise DataError(f"data file {str(path)!r} is a folder, not a file")
    if not path.exists():
        raise DataError(f"data file {str(path)!r} does not exist")
    try:
        text = path.read_text(encoding="utf-8-sig")  # a byte-order mark is not part of the first name
    except UnicodeDecodeError as e:
        raise DataError(f"{path.name}: not UTF-8 text (byte {e.start}); save it as UTF-8 CSV") from None
    except OSError as e:
        raise DataError(f"data file {str(path)!r} cannot be read: {e.strerror}") from None
    lines = text.splitlines()
    if not lines or not lines[0].strip():
        raise DataError(f"{path.name} is empty (no header line)")
    first = lines[0]
    delim = max((",", ";", "\t"), key=first.count)
    if first.count(delim) == 0:
        raise DataError(
            f"{path.name}: the header has a single column ({first.strip()[:40]!r}); expected "
            "comma-, semicolon- or tab-separated columns"
        )
    rows = list(csv.reader(lines, delimiter=delim))
    header = [h.strip() for h in rows[0]]
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise DataError(f"{path.name}: duplicate column {dup[0]!r}")
    body = [r for r in rows[1:] if any(x.strip() for x in r)]
    if not body:
        raise DataError(f"{path.name} has no data rows")
    return path, header, body


def _number(cell: str):
    """``(value, reason)``: the cell's number, or NaN and why it is not one."""
    s = cell.strip()
    if not s:
        return math.nan, "is blank"
    try:
        return float(s), None
    except ValueError:
        if re.fullmatch(r"[+-]?\d+,\d+", s):
            return math.nan, f"{s!r} uses a decimal comma (write {s.replace(',', '.')!r})"
        return math.nan, f"{s!r} is not a number"


def _columns(name: str, header: list[str], body: list[list[str]], cols) -> tuple[dict, dict]:
    """Numeric arrays of ``cols`` and ``{row index: (column, reason)}`` of every bad cell (first per row)."""
    idx = {c: header.index(c) for c in cols}
    out = {c: np.empty(len(body)) for c in cols}
    bad: dict[int, tuple[str, str]] = {}
    for i, r in enumerate(body):
        if len(r) != len(header):
            col = header[len(r)] if len(r) < len(header) else header[-1]
            bad[i] = (col, f"the row has {len(r)} fields, the header {len(header)}")
        for c in cols:
            v, why = _number(r[idx[c]]) if idx[c] < len(r) else (math.nan, "is missing")
            if why is None and not math.isfinite(v):
                why = f"value {v} is not finite"
            if why is not None:
                bad.setdefault(i, (c, why))
            out[c][i] = v
    return out, bad


def _resolve_bad(name: str, bad: dict, n: int, drop_bad: bool, sample_of) -> tuple:
    """Fail on the first bad row (unless ``drop_bad``), or check the bad rows are isolated; returns the
    ``dropped`` entries."""
    if bad and not drop_bad:
        i = min(bad)
        c, why = bad[i]
        more = (
            f" ({len(bad) - 1} more bad rows; --drop-bad drops isolated ones)"
            if len(bad) > 1
            else " (--drop-bad drops isolated bad rows)"
        )
        raise DataError(f"{name}: column {c!r}, row {i + 1}{sample_of(i)}: {why}{more}")
    rows = sorted(bad)
    if len(rows) > max(1, int(MAX_BAD_FRACTION * n)):
        raise DataError(
            f"{name}: {len(rows)} of {n} rows are bad (first: row {rows[0] + 1}, column "
            f"{bad[rows[0]][0]!r}: {bad[rows[0]][1]}); more than {MAX_BAD_FRACTION:.0%} is not "
            "isolated, fix the file"
        )
    run = 1
    for a, b in itertools.pairwise(rows):
        run = run + 1 if b == a + 1 else 1
        if run > MAX_BAD_RUN:
            raise DataError(
                f"{name}: rows {b - run + 2}..{b + 1} are all bad; a run of more than "
                f"{MAX_BAD_RUN} is not isolated, fix the file"
            )
    return tuple({"row": i + 1, "column": bad[i][0], "reason": bad[i][1]} for i in rows)


def _second_difference(x):
    """Each interior sample's distance from its neighbours' midpoint, and the neighbours' distance."""
    return (np.linalg.norm(x[1:-1] - (x[:-2] + x[2:]) / 2.0, axis=1), np.linalg.norm(x[2:] - x[:-2], axis=1))


def glitches(p, q, cols) -> dict:
    """Tracker glitches in positions ``p`` (N, 3) commanded by ``q`` (N, n), in acquisition order (see
    ``GLITCH_MEDIANS``): ``{index: (column, reason)}`` with ``cols`` the position columns' names."""
    p, q = np.asarray(p, float), np.asarray(q, float)
    if len(p) < 5:
        return {}
    with np.errstate(over="ignore", invalid="ignore"):
        dev = p[1:-1] - (p[:-2] + p[2:]) / 2.0
        size, span = _second_difference(p)
        q_size, q_span = _second_difference(q)
        scale = float(np.median(size[np.isfinite(size)])) if np.isfinite(size).any() else 0.0
        hit = (
            (size > GLITCH_MEDIANS * max(scale, 1e-12))
            & (size > GLITCH_NEIGHBOURS * span)
            & (GLITCH_NEIGHBOURS * q_size <= q_span)
        )
    idx = np.flatnonzero(hit)
    if len(idx) > max(1, GLITCH_SHARE * len(p)):
        return {}
    out = {}
    for k in idx:
        c = int(np.argmax(np.abs(np.nan_to_num(dev[k], posinf=np.inf))))
        why = (
            f"tracker glitch: {size[k]:.4g} mm from its neighbours' midpoint, "
            f"{size[k] / max(scale, 1e-12):.3g} times the recording's median"
        )
        out[int(k) + 1] = (cols[c], why)
    return out


def _drop_glitches(good, p, q, cols, row_of) -> tuple[np.ndarray, tuple]:
    """``good`` (K,) row indices without the rows whose positions ``p`` (K, 3) are glitches (commands
    ``q``), and their ``dropped`` entries (``row_of(i)``: the entry's row and sample for row index ``i``)."""
    found = glitches(p, q, cols)
    entries = tuple({**row_of(good[k]), "column": c, "reason": why} for k, (c, why) in found.items())
    return np.delete(good, list(found)), entries


def _fmt(x) -> str:
    return f"{x:g}" if np.isfinite(x) else str(x)


# --------------------------------------------------------------------------------------------
# tension_zones/MODEL.md Sec. 6
# --------------------------------------------------------------------------------------------
def _wire_columns(name: str, header: list[str]) -> list[str]:
    qs = sorted((c for c in header if re.fullmatch(r"q\d+", c)), key=lambda c: int(c[1:]))
    for i, c in enumerate(qs, start=1):
        if c != f"q{i}":
            raise DataError(f"{name}: wire columns must be q1..qn without gaps; found {', '.join(qs)}")
    return qs


def pattern_family(label: str) -> str:
    """The family of a pattern label: its words without the repetition, direction, hold and numbers
    (``rep1_all3_same_dir60_hold`` -> ``all_same``, ``rep2_seg1_dir120`` -> ``seg``,
    ``rep1_tendon4_id2_pull`` -> ``tendon_id_pull``); a label of numbers only is its own family."""
    words = [w for w in str(label).split("_") if not re.fullmatch(r"rep\d+|dir-?\d+(\.\d+)?|hold\d*", w)]
    fam = "_".join(w for w in (re.sub(r"\d+", "", w) for w in words) if w)
    return fam or str(label)


def read_csv(path, n_wires: int | None = None, length: float | None = None, drop_bad: bool = False) -> Dataset:
    """Read and validate a tension_zones/MODEL.md Sec. 6 measurement set (positions in the base frame).

    Args:
        path: the CSV file.
        n_wires: the design's wire count; the ``q`` columns must agree.
        length: the robot's length (mm), for the physical-range check of ``q``.
        drop_bad: drop isolated bad rows (blank, non-numeric, non-finite or non-physical cells,
            repeated sample numbers, short rows) instead of failing; they are listed in
            ``Dataset.dropped``.
    Raises:
        DataError: one line naming the file, column and row.
    """
    path, header, body = _read_table(path)
    name = path.name
    if any(_SERVO.match(h) for h in header) or "pattern_label" in header:
        raise DataError(
            f"{name} looks like an OpenCR recording (servo_<id>_mm / pattern_label columns): use --format opencr"
        )
    qcols = _wire_columns(name, header)
    if not qcols:
        raise DataError(f"{name}: missing the wire columns q1..qn (header: {', '.join(header)})")
    if n_wires is not None and len(qcols) != n_wires:
        raise DataError(
            f"the design has {n_wires} wires but {name} has {len(qcols)} wire columns ({qcols[0]}..{qcols[-1]})"
        )
    need = ["sample", *qcols, *FORCE_COLS, *POS_COLS, *ROT_COLS]
    for c in need:
        if c not in header:
            raise DataError(f"{name}: missing column {c!r} (have: {', '.join(header)})")
    cols, bad = _columns(name, header, body, need)
    v = {c: np.where(np.isfinite(x), x, 0.0) for c, x in cols.items()}
    for c in qcols:
        if length is not None:
            for i in np.flatnonzero(np.abs(v[c]) >= length):
                bad.setdefault(
                    int(i),
                    (
                        c,
                        (
                            f"wire displacement {v[c][i]:g} mm is not smaller than the robot's "
                            f"length {length:g} mm (non-physical)"
                        ),
                    ),
                )
    for c in FORCE_COLS:
        for i in np.flatnonzero(np.abs(v[c]) > MAX_FORCE_N):
            bad.setdefault(int(i), (c, f"force {v[c][i]:g} N exceeds {MAX_FORCE_N:g} N (non-physical)"))
    rotn = np.linalg.norm(np.stack([v[c] for c in ROT_COLS], 1), axis=1)
    for i in np.flatnonzero(rotn > math.pi * (1 + 1e-6)):
        bad.setdefault(int(i), ("rx", f"rotation vector norm {rotn[i]:.4g} rad exceeds pi (non-physical)"))
    sample = cols["sample"]
    for i in np.flatnonzero(np.isfinite(sample) & (sample != np.round(sample))):
        bad.setdefault(int(i), ("sample", f"value {sample[i]} is not an integer"))
    seen: dict[float, int] = {}
    for row, s in enumerate(sample):
        if row in bad:
            continue
        if s in seen:
            bad[row] = ("sample", f"sample number {s:g} repeats row {seen[s] + 1}")
        seen.setdefault(s, row)
    dropped = _resolve_bad(name, bad, len(body), drop_bad, lambda i: f" (sample {_fmt(sample[i])})")
    keep = np.ones(len(body), bool)
    keep[list(bad)] = False
    good = np.flatnonzero(keep)
    back = np.flatnonzero(np.diff(sample[good]) <= 0)
    if back.size:
        i = good[back[0] + 1]
        raise DataError(
            f"{name}: column 'sample', row {i + 1}: samples must be in acquisition order "
            f"(increasing), got {_fmt(sample[i])} after {_fmt(sample[good[back[0]]])}"
        )
    for d in dropped:
        d["sample"] = _fmt(sample[d["row"] - 1])
    good, more = _drop_glitches(
        good,
        np.stack([cols[c][good] for c in POS_COLS], axis=1),
        np.stack([cols[c][good] for c in qcols], axis=1),
        POS_COLS,
        lambda i: {"row": int(i) + 1, "sample": _fmt(sample[i])},
    )
    dropped = tuple(dropped) + more
    stack = lambda cs: np.stack([cols[c][good] for c in cs], axis=1)
    return Dataset(
        sample=sample[good].astype(np.int64),
        q=stack(qcols),
        f=stack(FORCE_COLS),
        p=stack(POS_COLS),
        rot=stack(ROT_COLS),
        frame="base",
        dropped=dropped,
        source=str(path),
    )


# --------------------------------------------------------------------------------------------
# OpenCR recordings
# --------------------------------------------------------------------------------------------
def servo_map_from_labels(name: str, labels) -> dict[int, int]:
    """``{tendon index: servo id}`` from labels like ``..._tendon4_id2_...``; contradictions are errors."""
    out: dict[int, int] = {}
    for row, lab in enumerate(labels, start=1):
        for t, s in _TENDON.findall(lab):
            t, s = int(t), int(s)
            if out.get(t, s) != s:
                raise DataError(
                    f"{name}: column 'pattern_label', row {row}: tendon {t} is driven by servo {s} "
                    f"here but by servo {out[t]} earlier ({lab!r})"
                )
            out[t] = s
    return out


def read_opencr(path, n_wires: int | None = None, servo_ids=None, drop_bad: bool = False) -> Dataset:
    """Read an OpenCR recording (positions in the motion-capture frame, ``frame="tracker"``).

    Servos map to tendons by the labels of the single-tendon pulls (``rep1_tendon4_id2_pull``:
    tendon 4 is driven by servo 2); ``servo_ids`` (tendon order) gives the map instead (a validation
    file takes its training file's). Tendon ``i`` belongs to segment ``i // n`` (proximal first) for
    ``n`` tendons per segment: the wire order of a :class:`~tension_zones.model.Robot`. Returned
    ``q = -servo_mm`` (tension_zones/MODEL.md sign), no tip force, ``groups`` = the labels without ``_hold``.
    """
    path, header, body = _read_table(path)
    name = path.name
    servo_cols = {int(m.group(1)): h for h in header if (m := _SERVO.match(h))}
    if not servo_cols and any(re.fullmatch(r"q\d+", h) for h in header):
        raise DataError(
            f"{name} looks like a tension_zones/MODEL.md measurement set (q1..qn columns): use --format model"
        )
    for col in ("timestamp", "pattern_label", *TIP_COLS):
        if col not in header:
            raise DataError(
                f"{name}: missing column {col!r} (an OpenCR recording has timestamp, pattern_label, "
                "servo_<id>_mm and tip_x, tip_y, tip_z)"
            )
    if not servo_cols:
        raise DataError(f"{name}: no servo_<id>_mm columns")
    li = header.index("pattern_label")
    labels = [r[li].strip() if li < len(r) else "" for r in body]
    if servo_ids is None:
        servo_of = servo_map_from_labels(name, labels)
        missing = [t for t in range(len(servo_cols)) if t not in servo_of]
        if missing:
            raise DataError(
                f"{name}: no pattern label 'tendon{missing[0]}_id<servo>' says which servo drives "
                f"tendon {missing[0]}: the map comes from the single-tendon pulls' labels (is the file "
                "truncated?); a validation file takes its training file's map"
            )
        servo_ids = [servo_of[t] for t in range(len(servo_cols))]
    servo_ids = tuple(int(s) for s in servo_ids)
    if len(set(servo_ids)) != len(servo_ids):
        raise DataError(f"{name}: the servo map {list(servo_ids)} repeats a servo")
    for s in servo_ids:
        if s not in servo_cols:
            raise DataError(f"{name}: missing column 'servo_{s}_mm'")
    extra = sorted(set(servo_cols) - set(servo_ids))
    if extra:
        raise DataError(f"{name}: column 'servo_{extra[0]}_mm' drives no tendon of the servo map")
    if n_wires is not None and len(servo_ids) != n_wires:
        raise DataError(f"{name}: {len(servo_ids)} servo columns but the design has {n_wires} wires")
    scols = [servo_cols[s] for s in servo_ids]
    cols, bad = _columns(name, header, body, ["timestamp", *scols, *TIP_COLS])
    for i, lab in enumerate(labels):
        if not lab:
            bad.setdefault(i, ("pattern_label", "is blank"))
    t = cols["timestamp"]
    last = -math.inf
    for i in range(len(body)):
        if i in bad:
            continue
        if t[i] <= last:
            bad[i] = (
                "timestamp",
                (f"{_fmt(t[i])} is not after the previous row's {_fmt(last)} (samples must be in acquisition order)"),
            )
        else:
            last = t[i]
    dropped = _resolve_bad(name, bad, len(body), drop_bad, lambda i: "")
    for d in dropped:
        d["sample"] = str(d["row"])
    good = np.flatnonzero(~np.isin(np.arange(len(body)), list(bad)))
    good, more = _drop_glitches(
        good,
        np.stack([cols[c][good] for c in TIP_COLS], axis=1),
        np.stack([cols[c][good] for c in scols], axis=1),
        TIP_COLS,
        lambda i: {"row": int(i) + 1, "sample": str(int(i) + 1)},
    )
    dropped = tuple(dropped) + more
    q = -np.stack([cols[c][good] for c in scols], axis=1)
    p = np.stack([cols[c][good] for c in TIP_COLS], axis=1)
    labs = tuple(labels[i] for i in good)
    return Dataset(
        sample=good.astype(np.int64) + 1,
        q=q,
        f=np.zeros((len(good), 3)),
        p=p,
        rot=None,
        frame="tracker",
        groups=tuple(re.sub(r"_hold$", "", s) for s in labs),
        timestamp=t[good],
        servo_ids=servo_ids,
        dropped=dropped,
        source=str(path),
    )


def shared_rows(train: Dataset, other: Dataset) -> int:
    """How many samples of ``other`` repeat one of ``train`` (the same commands and the same tip position,
    to :data:`SHARED_DECIMALS` decimals): independent recordings share none."""

    def rows(d):
        return np.round(np.concatenate([d.q, d.p], axis=1), SHARED_DECIMALS)

    if other.n_wires != train.n_wires:
        return 0
    seen = {r.tobytes() for r in rows(train) + 0.0}  # + 0.0: -0.0 and 0.0 alike
    return sum(r.tobytes() in seen for r in rows(other) + 0.0)


def check_validation(train: Dataset, validate: Dataset) -> None:
    """Refuse a validation recording that shares more than :data:`MAX_SHARED_FRACTION` of its samples
    with the training one (:func:`shared_rows`): predicting it would not validate anything."""
    k = shared_rows(train, validate)
    if k > MAX_SHARED_FRACTION * validate.n_samples:
        same = "; the same recording" if k == validate.n_samples == train.n_samples else ""
        raise DataError(
            f"validation file {Path(validate.source).name}: {k} of its {validate.n_samples} rows repeat "
            f"rows of the training file {Path(train.source).name} (same commands and tip positions"
            f"{same}); a validation must be a separate recording"
        )


#: ``--format`` -> reader. A reader takes ``(path, n_wires=, drop_bad=)`` (and may take more keywords).
READERS = {"model": read_csv, "opencr": read_opencr}


def load_data(path, format: str = "model", **kw) -> Dataset:
    """Read ``path`` with the reader of ``format`` (``"model"`` or ``"opencr"``)."""
    if format not in READERS:
        raise DataError(f"unknown data format {format!r}; known: {', '.join(READERS)}")
    return READERS[format](path, **kw)
