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
from ._scenario import _err, _grid, _merge, _num, _wire_counts, with_defaults

KIND = "space"
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
}

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
}


@dataclasses.dataclass(frozen=True)
class Space:
    """A parsed, validated design space (radians inside). Build with :func:`parse_space`.

    ``fields`` maps each design-file key (and :data:`OFFSET`) to ``("fixed" | "range" | "values",
    numbers)``; ``raw`` is the file with every default filled in (an exploration's identity).
    """

    n_wires: tuple[int, ...]
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

    def _dims(self, n: int) -> list[tuple[str, str, tuple]]:
        """The sampled dimensions for ``n`` wires: ``(key, kind, numbers)``; the offsets last, one
        per wire, so that the leading dimensions are the same for every wire count."""
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
        angles = [f"wire_angle_{k + 1}_deg" for k in range(max(self.n_wires))]
        return ["n_wires", *FIELDS, *angles]

    def columns(self, n: int) -> dict[str, np.ndarray]:
        """The designs for ``n`` wires as table columns (design-file names; ``wire_angle_k_deg`` for
        k = 1..max n_wires, NaN past n), (N,) each."""
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

    def batch(self, n: int) -> Design:
        """The designs for ``n`` wires as one :class:`Design` whose leaves have a leading axis (N,)
        (``wire_angles`` (N, n)); NumPy leaves, valid by construction (checked at parsing)."""
        cols = self.columns(n)
        leaves = {field: np.asarray(cols[key], float) for key, (field, _, _) in FIELDS.items()}
        leaves["wire_angles"] = np.radians(np.stack([cols[f"wire_angle_{k + 1}_deg"] for k in range(n)], 1))
        template = jax.tree_util.tree_structure(Design(n, 2.0, 1.0))
        return jax.tree_util.tree_unflatten(template, [leaves[f] for f in _DATA_FIELDS])


def _field(key, v, lo=None, lo_open=False):
    """A design field: a number, ``[min, max]`` (min < max) or ``{"values": [...]}`` (non-empty,
    no repeats) -> ``(kind, numbers)``."""

    def num(x):
        return _num(key, x, lo, lo_open=lo_open, kind=KIND)

    if isinstance(v, dict):
        vals = _merge(key, v, {"values": None}, KIND)["values"]
        if not isinstance(vals, (list, tuple)) or not vals:
            raise _err(key, f"values must be a non-empty list of numbers, got {vals!r}", KIND)
        vals = tuple(num(x) for x in vals)
        if len(set(vals)) != len(vals):
            raise _err(key, f"values must not repeat, got {list(vals)}", KIND)
        return "values", vals
    if isinstance(v, (list, tuple)):
        if len(v) != 2:
            raise _err(key, f'must be a number, [min, max] or {{"values": [...]}}, got {v!r}', KIND)
        a, b = (num(x) for x in v)
        if a > b:
            raise _err(key, f"min {a} is larger than max {b}", KIND)
        if a == b:
            raise _err(key, f"[{a}, {b}] is an empty range; give the number {a} to fix the value", KIND)
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


def parse_space(d: dict) -> Space:
    """Validate a space dictionary and fill in the defaults."""
    raw = with_defaults(d, DEFAULTS, KIND, "a design space", ("chunks",))

    counts = _wire_counts("n_wires", raw["n_wires"], KIND)
    fields = {k: _field(k, raw[k], lo, lo_open) for k, (_, lo, lo_open) in FIELDS.items()}
    fields[OFFSET] = _field(OFFSET, raw[OFFSET])
    kind, v = fields[OFFSET]
    if kind != "fixed" and max(v) - min(v) >= 360.0 / max(counts):
        raise _err(
            OFFSET,
            f"spans {max(v) - min(v):g} deg, must stay below 360/n = "
            f"{360.0 / max(counts):g} deg for {max(counts)} wires (wires would meet)",
            KIND,
        )
    try:  # the largest radius against the shortest length: every design of the space is valid
        _check_radius(min(fields["length_mm"][1]), max(fields["pitch_radius_mm"][1]), names=("max", "min length_mm"))
    except ValueError as e:
        raise _err("pitch_radius_mm", str(e), KIND) from None
    method, points, designs = _sample(d.get("sample", {}))
    load = raw["load_N"]
    if load is not None:
        if not isinstance(load, (list, tuple)) or len(load) not in (3, 6):
            raise _err("load_N", f"must be null, [fx, fy, fz] or six wrench components, got {load!r}", KIND)
        load = np.array([_num("load_N", x, kind=KIND) for x in load])
    chunks = raw["chunks"]
    space = Space(
        n_wires=counts,
        fields=fields,
        method=method,
        points=points,
        designs=designs,
        theta_L=_grid("theta_L_deg", raw["theta_L_deg"], 0.0, 90.0, KIND),
        delta=_grid("delta_deg", raw["delta_deg"], -360.0, 720.0, KIND),
        dq=_num("joint_uncertainty_mm", raw["joint_uncertainty_mm"], 0.0, lo_open=True, kind=KIND),
        load=load,
        designs_per_chunk=_positive_int("chunks.designs", chunks["designs"]),
        poses_per_chunk=_positive_int("chunks.poses", chunks["poses"]),
        raw=json.loads(json.dumps(raw)),  # as a manifest stores it (tuples become lists)
    )
    for n in counts:
        if space.count(n) > MAX_DESIGNS:
            if method == "halton":
                raise _err(
                    "sample.designs",
                    f"{space.count(n):.3g} designs for {n} wires, more than {MAX_DESIGNS:.0e}: fewer designs",
                    KIND,
                )
            raise _err(
                "sample",
                f"the grid has {space.count(n):.3g} designs for {n} wires, more than "
                f'{MAX_DESIGNS:.0e}: fewer points, or method "halton"',
                KIND,
            )
    return space


def load_space(path) -> Space:
    return parse_space(read_json(path, "space file"))
