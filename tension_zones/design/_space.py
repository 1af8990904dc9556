"""Design spaces for exploration: the JSON a designer writes, parsed and validated.

A space gives each design field a fixed value, a range ``[min, max]`` or a list
``{"values": [...]}``, the wire counts (one compiled program each), how to sample (a full grid with
``points`` per range, or the first ``designs`` points of a Halton sequence) and the workspace grid
the designs are judged on. Every key has a default (:data:`DEFAULTS`); an unknown key, a range with
``min > max`` or ``min == max``, an empty list, a wire count below 3 raise ``ValueError`` naming the
key (the scenario file's helpers, :mod:`._scenario`). Units: mm, N, N/mm, N mm^2, degrees at the
edge (radians inside).
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
from typing import Any

import jax
import numpy as np

from ..analysis._samples import halton
from ..analysis._sweep import DEFAULT_DESIGN_CHUNK, DESIGN_POSE_CHUNK, positive_int
from ..model._design import (
    _DATA_FIELDS,
    DEFAULT_BACKBONE_EI,
    DEFAULT_WIRE_STIFFNESS,
    Design,
    _check_radius,
    read_json,
)
from ..model._robot import Robot
from ._layout import chain, interleaved_angles, with_numbers
from ._scenario import (
    SAMPLE_KEYS,
    _err,
    _grid,
    _merge,
    _num,
    _wire_counts,
    check_statics_wires,
    configurations,
    only_for,
    segment_entries,
    where_given,
    wires_label,
    with_defaults,
)

KIND = "space"
#: A robot's table column: the angle (deg) of each segment's first wire, the others evenly spaced from it.
FIRST_ANGLE = "first_wire_angle_deg"
#: The design fields a space can vary, by their design-file names (tension_zones/MODEL.md Sec. 6): the Design
#: field, the smallest value and whether it is excluded.
FIELDS = {
    "length_mm": ("length", 0.0, True),
    "pitch_radius_mm": ("pitch_radius", 0.0, True),
    "wire_stiffness_N_per_mm": ("wire_stiffness", 0.0, True),
    "backbone_EI_Nmm2": ("backbone_EI", 0.0, False),
    "preload_N": ("preload", 0.0, False),
}
OFFSET = "wire_angle_offset_deg"
#: Largest sample per wire count (a grid's size is the product of its levels).
MAX_DESIGNS = 10_000_000

#: Every space key and its default (the README's table documents them).
DEFAULTS: dict[str, Any] = {
    "n_wires": [3, 4],
    "length_mm": 20.0,
    "pitch_radius_mm": [0.5, 3.0],
    "wire_stiffness_N_per_mm": DEFAULT_WIRE_STIFFNESS,
    "backbone_EI_Nmm2": DEFAULT_BACKBONE_EI,
    "preload_N": 0.0,
    OFFSET: 0.0,
    "sample": {"method": "grid", "points": 5, "designs": 1000},
    "theta_L_deg": [0.0, 85.0, 5.0],
    "delta_deg": [0.0, 360.0, 2.5],
    "joint_uncertainty_mm": 0.4,
    "load_N": None,
    "chunks": {"designs": DEFAULT_DESIGN_CHUNK, "poses": DESIGN_POSE_CHUNK},
    "segments": None,
    "max_bend_deg": 90.0,
    "samples": 1000,
}
#: The keys a segment of several may set in its ``segments`` entry (the file's value where it does not).
SEGMENT_KEYS = ("n_wires", *FIELDS)
#: The keys of several segments: an exploration's identity holds them only when it has segments (a
#: one-segment exploration's is what it was before they existed, so that it still resumes).
ROBOT_KEYS = ("segments", *SAMPLE_KEYS)
#: The most combinations of the segments' wire counts (each its own batch and program) a space takes.
MAX_STRUCTURES = 64

DOC: dict[str, str] = {
    "n_wires": "wire count or list of counts (integers 3..16); each count is its own batch and program",
    "length_mm": 'backbone length L (mm): a number, [min, max] or {"values": [...]}; > 0',
    "pitch_radius_mm": "pitch radius r (mm), as length_mm; > 0",
    "wire_stiffness_N_per_mm": "wire stiffness k_w (N/mm), as length_mm; > 0 (matters with a load)",
    "backbone_EI_Nmm2": "backbone bending stiffness EI (N mm^2), as length_mm; >= 0 (matters with a load)",
    "preload_N": "wire preload f_min (N), as length_mm; >= 0 (matters with a load)",
    OFFSET: "each wire's angle from its evenly spaced place, (k-1) 360/n + offset_k (deg): a number "
    "(every wire, i.e. a rotation), or a range / values list sampled per wire (n dimensions); "
    "its span must stay below 360/n for the largest n",
    "sample": 'method "grid" (every combination, "points" levels per range) or "halton" (the first '
    '"designs" points of a Halton sequence per wire count, the same points for every count)',
    "theta_L_deg": "[min, max, step] of theta_L (deg) of the workspace grid, both ends included",
    "delta_deg": "[min, max, step] of the bending directions delta (deg), both ends included",
    "joint_uncertainty_mm": "joint-level uncertainty dq (mm) of the uncertainty bounds (paper Sec. 4)",
    "load_N": "null, or the tip force [fx, fy, fz] (N, base frame; or 6 wrench components) that adds "
    "the compliance statistics (paper Sec. 5-6.2)",
    "chunks": "designs (per compiled call: the unit of progress and resuming) and poses (per step of "
    "each design's loop); part of an exploration's identity",
    "segments": "null (one segment), or one object per segment, proximal first, with any of n_wires and "
    "the design fields above (a key left out takes the file's value); every combination of the "
    "segments' wire counts is its own batch and program",
    "max_bend_deg": "several segments: each segment's largest bending angle (deg) in the workspace's configurations",
    "samples": "several segments: the workspace, the first samples of a Halton sequence of configurations, "
    "each segment bent up to max_bend_deg in any direction",
}


@dataclasses.dataclass(frozen=True)
class Space:
    """A parsed, validated design space (radians inside). Build with :func:`parse_space`.

    ``fields`` maps each design-file key (and :data:`OFFSET`) to ``("fixed" | "range" | "values",
    numbers)``; ``raw`` is the file with every default filled in (an exploration's identity).
    Several segments: ``segments`` holds each segment's ``fields`` (``fields`` is segment 0's),
    ``n_wires`` the combinations of the segments' wire counts (tuples, proximal first), ``configs``
    (M, S, 2) the workspace's configurations (rad) in place of the grid.
    """

    n_wires: tuple  # the wire counts, or the combinations of the segments' (tuples)
    fields: dict
    method: str
    points: int
    designs: int
    theta_L: np.ndarray
    delta: np.ndarray
    dq: float
    load: np.ndarray | None
    designs_per_chunk: int
    poses_per_chunk: int
    raw: dict = dataclasses.field(repr=False, compare=False, default_factory=dict)
    segments: tuple[dict, ...] = ()
    configs: np.ndarray | None = dataclasses.field(default=None, repr=False, compare=False)

    @property
    def n_poses(self) -> int:
        """The workspace's poses (the grid's) or configurations."""
        return self.theta_L.size * self.delta.size if self.configs is None else len(self.configs)

    def _dims(self, n) -> list[tuple[str, str, tuple]]:
        """The sampled dimensions for ``n`` wires: ``(key, kind, numbers)``; the offsets last, one
        per wire, so that the leading dimensions are the same for every wire count. Several segments:
        each segment's in turn, ``key_j`` (j = 1 .. S), the same for every combination of counts."""
        if self.segments:
            return [
                (f"{key}_{j + 1}", kind, v)
                for j, seg in enumerate(self.segments)
                for key, (kind, v) in seg.items()
                if kind != "fixed"
            ]
        dims = [(k, kind, v) for k, (kind, v) in self.fields.items() if k != OFFSET and kind != "fixed"]
        kind, v = self.fields[OFFSET]
        return dims + ([(f"{OFFSET}_{k + 1}", kind, v) for k in range(n)] if kind != "fixed" else [])

    def count(self, n: int) -> int:
        """Designs sampled for ``n`` wires (one where every field is fixed)."""
        if not self._dims(n):
            return 1
        if self.method == "halton":
            return self.designs
        return math.prod(self.points if kind == "range" else len(v) for _, kind, v in self._dims(n))

    def _samples(self, n: int) -> dict[str, np.ndarray]:
        """Each sampled dimension's values over the designs for ``n`` wires, (N,)."""
        dims = self._dims(n)
        if not dims:  # every field fixed: one design
            return {}
        if self.method == "halton":
            u = halton(self.designs, len(dims))
            return {
                key: (
                    v[0] + u[:, j] * (v[1] - v[0])
                    if kind == "range"
                    else np.asarray(v)[np.minimum((u[:, j] * len(v)).astype(int), len(v) - 1)]
                )
                for j, (key, kind, v) in enumerate(dims)
            }
        levels = [
            np.linspace(v[0], v[1], self.points) if kind == "range" else np.asarray(v, float) for _, kind, v in dims
        ]
        index = np.unravel_index(np.arange(self.count(n)), [len(x) for x in levels])  # first slowest
        return {key: lv[i] for (key, _, _), lv, i in zip(dims, levels, index)}

    def column_names(self) -> list[str]:
        """The names of :meth:`columns`, in order."""
        if self.segments:
            per = [f"{key}_{j + 1}" for j in range(len(self.segments)) for key in (*SEGMENT_KEYS, FIRST_ANGLE)]
            return ["n_wires", *per, "pitch_radius_mm_max"]
        angles = [f"wire_angle_{k + 1}_deg" for k in range(max(self.n_wires))]
        return ["n_wires", *FIELDS, *angles]

    def columns(self, n) -> dict[str, np.ndarray]:
        """The designs for ``n`` wires as table columns (design-file names; ``wire_angle_k_deg`` for
        k = 1..max n_wires, NaN past n), (N,) each. Several segments (``n`` a combination): the total
        ``n_wires``, each segment's ``key_j`` and the angle of its first wire (the others evenly
        spaced from it), and the largest pitch radius."""
        if self.segments:
            return self._chain_columns(n)
        N, s = self.count(n), self._samples(n)
        cols = {"n_wires": np.full(N, n)}
        for key in FIELDS:
            kind, v = self.fields[key]
            cols[key] = s[key] if kind != "fixed" else np.full(N, v[0])
        kind, v = self.fields[OFFSET]
        for k in range(max(self.n_wires)):
            off = s[f"{OFFSET}_{k + 1}"] if kind != "fixed" and k < n else v[0]
            cols[f"wire_angle_{k + 1}_deg"] = np.full(N, k * 360.0 / n + off if k < n else np.nan)
        return cols

    def _chain_columns(self, counts) -> dict[str, np.ndarray]:
        N, s = self.count(counts), self._samples(counts)
        cols = {"n_wires": np.full(N, sum(counts))}
        for j, (seg, n, a) in enumerate(zip(self.segments, counts, interleaved_angles(counts))):
            cols[f"n_wires_{j + 1}"] = np.full(N, n)
            for key in FIELDS:
                kind, v = seg[key]
                cols[f"{key}_{j + 1}"] = s[f"{key}_{j + 1}"] if kind != "fixed" else np.full(N, v[0])
            cols[f"{FIRST_ANGLE}_{j + 1}"] = np.full(N, math.degrees(a[0]))
        cols["pitch_radius_mm_max"] = np.max([cols[f"pitch_radius_mm_{j + 1}"] for j in range(len(counts))], axis=0)
        return cols

    def batch(self, n):
        """The designs for ``n`` wires as one :class:`Design` whose leaves have a leading axis (N,)
        (``wire_angles`` (N, n)); NumPy leaves, valid by construction (checked at parsing). Several
        segments: the robots of the combination ``n`` as one :class:`Robot` with a leading axis."""
        if self.segments:
            return self._chain_batch(n)
        cols = self.columns(n)
        leaves = {field: np.asarray(cols[key], float) for key, (field, _, _) in FIELDS.items()}
        leaves["wire_angles"] = np.radians(np.stack([cols[f"wire_angle_{k + 1}_deg"] for k in range(n)], 1))
        template = jax.tree_util.tree_structure(Design(n, 2.0, 1.0))
        return jax.tree_util.tree_unflatten(template, [leaves[f] for f in _DATA_FIELDS])

    def _chain_batch(self, counts) -> Robot:
        """The robots of the combination ``counts`` (:mod:`._layout`), leaves with a leading axis (N,)."""
        cols = self.columns(counts)
        S = len(counts)
        fields = {
            field: np.stack([cols[f"{key}_{j + 1}"] for j in range(S)], 1) for key, (field, _, _) in FIELDS.items()
        }
        base = chain(counts, **{f: v[0] for f, v in fields.items()})
        robots = jax.vmap(lambda f: with_numbers(base, **f))(fields)
        return jax.tree_util.tree_map(np.asarray, robots)


def _field(key, v, lo=None, lo_open=False, kind=KIND):
    """A design field: a number, ``[min, max]`` (min < max) or ``{"values": [...]}`` (non-empty,
    no repeats) -> ``(kind, numbers)``; ``kind`` names the file (or segment) in an error."""

    def num(x):
        return _num(key, x, lo, lo_open=lo_open, kind=kind)

    if isinstance(v, dict):
        vals = _merge(key, v, {"values": None}, kind)["values"]
        if not isinstance(vals, (list, tuple)) or not vals:
            raise _err(key, f"values must be a non-empty list of numbers, got {vals!r}", kind)
        vals = tuple(num(x) for x in vals)
        if len(set(vals)) != len(vals):
            raise _err(key, f"values must not repeat, got {list(vals)}", kind)
        return "values", vals
    if isinstance(v, (list, tuple)):
        if len(v) != 2:
            raise _err(key, f'must be a number, [min, max] or {{"values": [...]}}, got {v!r}', kind)
        a, b = (num(x) for x in v)
        if a > b:
            raise _err(key, f"min {a} is larger than max {b}", kind)
        if a == b:
            raise _err(key, f"[{a}, {b}] is an empty range; give the number {a} to fix the value", kind)
        return "range", (a, b)
    return "fixed", (num(v),)


def _positive_int(key, v):
    return positive_int(f"{KIND} key {key!r}:", v)  # the message of _err(key, ..., KIND)


def _sample(given: Any) -> tuple[str, int, int]:
    s = _merge("sample", given, DEFAULTS["sample"], KIND)
    if s["method"] not in ("grid", "halton"):
        raise _err("sample.method", f'must be "grid" or "halton", got {s["method"]!r}', KIND)
    other = "designs" if s["method"] == "grid" else "points"
    if other in given:
        raise _err(
            f"sample.{other}",
            f"does not go with method {s['method']!r} (a grid takes "
            "'points' per range, a Halton sample a number of 'designs')",
            KIND,
        )
    points = _positive_int("sample.points", s["points"])
    if points < 2:
        raise _err("sample.points", "must be at least 2 (the two ends of each range)", KIND)
    return s["method"], points, _positive_int("sample.designs", s["designs"])


def _segment_fields(values: dict, where, kind: str = KIND) -> dict:
    """A segment's design fields (:data:`FIELDS`) from its keys in ``values``; ``where(key)`` is the
    ``kind`` that names a key in an error, ``kind`` the segment's. The largest radius must fit the
    shortest length: every design of the space is valid."""
    fields = {k: _field(k, values[k], lo, lo_open, where(k)) for k, (_, lo, lo_open) in FIELDS.items()}
    try:
        _check_radius(min(fields["length_mm"][1]), max(fields["pitch_radius_mm"][1]), names=("max", "min length_mm"))
    except ValueError as e:
        raise _err("pitch_radius_mm", str(e), kind) from None
    return fields


def _load(raw: dict):
    load = raw["load_N"]
    if load is None:
        return None
    if not isinstance(load, (list, tuple)) or len(load) not in (3, 6):
        raise _err("load_N", f"must be null, [fx, fy, fz] or six wrench components, got {load!r}", KIND)
    return np.array([_num("load_N", x, kind=KIND) for x in load])


def _shared(d: dict, raw: dict) -> dict:
    """The :class:`Space` fields every form has: sampling, dq, chunks and the identity ``raw``."""
    method, points, designs = _sample(d.get("sample", {}))
    chunks = raw["chunks"]
    return {
        "method": method,
        "points": points,
        "designs": designs,
        "dq": _num("joint_uncertainty_mm", raw["joint_uncertainty_mm"], 0.0, lo_open=True, kind=KIND),
        "designs_per_chunk": _positive_int("chunks.designs", chunks["designs"]),
        "poses_per_chunk": _positive_int("chunks.poses", chunks["poses"]),
        "raw": json.loads(json.dumps(raw)),  # as a manifest stores it (tuples become lists)
    }


def _one_segment(d: dict, raw: dict, entry) -> Space:
    """A space of one segment (``entry``: its ``segments`` entry, or ``None`` where the file has none)."""
    values, where = (raw, lambda key: KIND) if entry is None else (entry[0], where_given(KIND, 0, entry[1]))
    counts = _wire_counts("n_wires", values["n_wires"], where("n_wires"))
    fields = _segment_fields(values, where, KIND if entry is None else f"{KIND} segments[0]")
    fields[OFFSET] = _field(OFFSET, raw[OFFSET])
    kind, v = fields[OFFSET]
    if kind != "fixed" and max(v) - min(v) >= 360.0 / max(counts):
        raise _err(
            OFFSET,
            f"spans {max(v) - min(v):g} deg, must stay below 360/n = "
            f"{360.0 / max(counts):g} deg for {max(counts)} wires (wires would meet)",
            KIND,
        )
    if entry is None:  # the identity a one-segment exploration had before several segments
        raw = {k: v for k, v in raw.items() if k not in ROBOT_KEYS}
    return Space(
        n_wires=counts,
        fields=fields,
        theta_L=_grid("theta_L_deg", raw["theta_L_deg"], 0.0, 90.0, KIND),
        delta=_grid("delta_deg", raw["delta_deg"], -360.0, 720.0, KIND),
        load=_load(raw),
        **_shared(d, raw),
    )


def _several_segments(d: dict, raw: dict, entries) -> Space:
    """A space of several segments: each segment's fields, every combination of their wire counts,
    and the configurations; what one segment alone takes (wire offsets) refused."""
    if OFFSET in d:
        raise _err(OFFSET, "several segments' wires are evenly spaced and interleaved; leave it out", KIND)
    counts, segs = [], []
    for j, (values, entry) in enumerate(entries):
        where = where_given(KIND, j, entry)
        counts.append(_wire_counts("n_wires", values["n_wires"], where("n_wires")))
        segs.append(_segment_fields(values, where, f"{KIND} segments[{j}]"))
    if raw["load_N"] is not None:
        check_statics_wires(counts, "load_N", KIND, "set it to null")
    structures = tuple(itertools.product(*counts))
    if len(structures) > MAX_STRUCTURES:
        raise _err(
            "n_wires",
            f"{len(structures)} combinations of the segments' wire counts, each its own program: at most {MAX_STRUCTURES}",
            KIND,
        )
    empty = np.zeros(0)
    return Space(
        n_wires=structures,
        fields=segs[0],
        theta_L=empty,
        delta=empty,
        load=_load(raw),
        segments=tuple(segs),
        configs=configurations(raw, KIND),
        **_shared(d, raw),
    )


def _check_size(space: Space) -> None:
    """Refuse a sample of more than :data:`MAX_DESIGNS` designs for a wire count (or combination)."""
    for n in space.n_wires:
        count, wires = space.count(n), wires_label(n)
        if count <= MAX_DESIGNS:
            continue
        if space.method == "halton":
            raise _err(
                "sample.designs",
                f"{count:.3g} designs for {wires} wires, more than {MAX_DESIGNS:.0e}: fewer designs",
                KIND,
            )
        raise _err(
            "sample",
            f"the grid has {count:.3g} designs for {wires} wires, more than "
            f'{MAX_DESIGNS:.0e}: fewer points, or method "halton"',
            KIND,
        )


def parse_space(d: dict) -> Space:
    """Validate a space dictionary and fill in the defaults (one segment, or several: ``segments``)."""
    raw = with_defaults(d, DEFAULTS, KIND, "a design space", ("chunks",))
    entries = segment_entries(raw, SEGMENT_KEYS, KIND)
    several = entries is not None and len(entries) > 1
    only_for(d, several, KIND)
    space = _several_segments(d, raw, entries) if several else _one_segment(d, raw, entries and entries[0])
    _check_size(space)
    return space


def load_space(path) -> Space:
    return parse_space(read_json(path, "space file"))
