"""Design-optimisation scenarios: the JSON a designer writes, parsed, defaulted and validated.

Every key has a documented default (:data:`DEFAULTS`); an unknown key or a value out of range raises
``ValueError`` naming it. Units: mm, N, N/mm, degrees (converted to radians here, at the edge).
"""

from __future__ import annotations

import copy
import dataclasses
import math
from typing import Any

import numpy as np

from ..model._design import DEFAULT_BACKBONE_EI, _check_radius, read_json

#: Every scenario key, its default and its meaning (design/README.md's table lists them, tested).
DEFAULTS: dict[str, Any] = {
    "length_mm": 20.0,
    "backbone_EI_Nmm2": DEFAULT_BACKBONE_EI,
    "n_wires": [3, 4],
    "pitch_radius_mm": [0.5, 3.0],
    "wire_stiffness_N_per_mm": [55.0, 105.0],
    "free_wire_angles": False,
    "joint_uncertainty_mm": 0.4,
    "theta_L_deg": [5.0, 85.0, 5.0],
    "delta_deg": [0.0, 360.0, 10.0],
    "load_N": [5.0, 0.0, 0.0],
    "preload_N": 0.0,
    "weights": {"position_uncertainty": 1.0, "deflection": 1.0, "wire_count": 0.05},
    "constraints": {
        "outer_diameter_mm": None,
        "wire_diameter_mm": 0.3,
        "min_wall_mm": 0.2,
        "min_wire_gap_mm": 0.2,
    },
    "min_spread": 0.25,
    "strict_controllability": False,
    "forbidden_arc_deg": None,
    "optimizer": {"starts": 4, "steps": 300, "learning_rate": 0.05, "sharpness": 30.0, "seed": 0},
    "segments": None,
    "max_bend_deg": 90.0,
    "samples": 256,
}

DOC: dict[str, str] = {
    "length_mm": "backbone length L (mm), > 0",
    "backbone_EI_Nmm2": "backbone bending stiffness (N mm^2), >= 0",
    "n_wires": "candidate wire counts (list of integers >= 3); each is optimised, the best reported",
    "pitch_radius_mm": "[min, max] pitch radius r (mm); min == max fixes it",
    "wire_stiffness_N_per_mm": "[min, max] wire stiffness k_w (N/mm); min == max fixes it",
    "free_wire_angles": "false: evenly spaced wires; true: every wire angle is a design variable",
    "joint_uncertainty_mm": "joint-level uncertainty dq (mm) of the pose-uncertainty bound (paper Sec. 4)",
    "theta_L_deg": "[min, max, step] of theta_L (deg) the task needs, both ends included",
    "delta_deg": "[min, max, step] of the bending directions delta (deg) the task needs",
    "load_N": "[fx, fy, fz] tip force (N, base frame) for the compliance term (paper Sec. 6.2)",
    "preload_N": "wire preload f_min (N), >= 0; with several segments also [min, max] (a variable)",
    "weights": "objective weights: position_uncertainty (per mm of worst dp_max), deflection "
    "(per mm of worst reduced deflection), wire_count (per wire)",
    "constraints": "outer_diameter_mm (null = no limit), wire_diameter_mm, min_wall_mm (wire hole to "
    "outer wall), min_wire_gap_mm (between neighbouring wire holes)",
    "min_spread": "controllability: at every task pose the smallest singular value of the taut wires' "
    "unit vectors [cos delta_k, sin delta_k] must be at least this (0..1)",
    "strict_controllability": "false: controllability lost only on single directions (zero "
    "width, e.g. exactly along a wire of four even wires) is reported, "
    "not a violation; true: every direction counts",
    "forbidden_arc_deg": "null, or [start, end] (deg, counter-clockwise from x_b) of an arc no wire "
    "may occupy (e.g. a tool channel); needs free_wire_angles",
    "optimizer": "starts (random restarts), steps (Adam steps per start), learning_rate, sharpness "
    "(of the log-sum-exp worst-case surrogate, relative), seed",
    "segments": "null (one segment), or one object per segment, proximal first, with any of n_wires, "
    "length_mm, pitch_radius_mm, wire_stiffness_N_per_mm, backbone_EI_Nmm2, preload_N and constraints "
    "(a key left out takes the file's value)",
    "max_bend_deg": "several segments: each segment's largest bending angle (deg) in the task's configurations",
    "samples": "several segments: the task's configurations, the first samples of a Halton sequence, "
    "each segment bent up to max_bend_deg in any direction",
}

#: The keys a segment of several may set in its ``segments`` entry (the file's value where it does not).
SEGMENT_KEYS = (
    "n_wires",
    "length_mm",
    "pitch_radius_mm",
    "wire_stiffness_N_per_mm",
    "backbone_EI_Nmm2",
    "preload_N",
    "constraints",
)
#: The task's keys: one segment's grid of poses, several segments' configuration samples.
GRID_KEYS, SAMPLE_KEYS = ("theta_L_deg", "delta_deg"), ("max_bend_deg", "samples")
#: The most configurations a task of several segments takes.
MAX_SAMPLES = 100_000


@dataclasses.dataclass(frozen=True)
class Scenario:
    """A parsed, validated scenario (radians inside). Build with :func:`load_scenario`.

    Several segments: ``segments`` holds each segment's own scenario (its wire counts, length,
    ranges, preload and constraints; the task, weights and optimiser settings are this one's, whose
    segment fields are segment 0's), and ``configs`` (M, S, 2) the task's configurations (rad).
    """

    length: float
    backbone_EI: float
    n_wires: tuple[int, ...]
    pitch_radius: tuple[float, float]
    wire_stiffness: tuple[float, float]
    free_wire_angles: bool
    dq: float
    theta_L: np.ndarray
    delta: np.ndarray
    load: np.ndarray
    preload: float
    w_position: float
    w_deflection: float
    w_wires: float
    outer_diameter: float | None
    wire_diameter: float
    min_wall: float
    min_wire_gap: float
    min_spread: float
    strict_controllability: bool
    forbidden_arc: tuple[float, float] | None
    starts: int
    steps: int
    learning_rate: float
    sharpness: float
    seed: int
    raw: dict = dataclasses.field(repr=False, compare=False, default_factory=dict)
    preload_range: tuple[float, float] | None = None
    segments: tuple[Scenario, ...] = ()
    configs: np.ndarray | None = dataclasses.field(default=None, repr=False, compare=False)

    def r_bounds(self, n: int, angle: float | None = None) -> tuple[float, float]:
        """Pitch-radius bounds for ``n`` evenly spaced wires after the geometric constraints.

        Upper: the wire hole plus the wall fits inside the outer diameter,
        ``r + d_w/2 + wall <= OD/2``. Lower: neighbouring holes keep the gap,
        ``2 r sin(angle/2) >= d_w + gap`` for the smallest ``angle`` (rad) between two holes
        (default ``2 pi / n``, evenly spaced; free angles use the same bound on the closest pair).
        """
        lo, hi = self.pitch_radius
        if self.outer_diameter is not None:
            hi = min(hi, 0.5 * self.outer_diameter - self.min_wall - 0.5 * self.wire_diameter)
        chord = 2.0 * math.sin(math.pi / n if angle is None else 0.5 * angle)
        lo = max(lo, (self.wire_diameter + self.min_wire_gap) / chord if chord > 0 else math.inf)
        return lo, hi


def wires_label(n) -> str:
    """A wire count, or a combination of them per segment as ``"4+3"`` (proximal first)."""
    return str(n) if isinstance(n, (int, np.integer)) else "+".join(map(str, n))


def _err(key: str, msg: str, kind: str = "scenario") -> ValueError:
    """The one-line error naming a key; ``kind`` says which file (a scenario, an exploration space)."""
    return ValueError(f"{kind} key {key!r}: {msg}")


def _num(key, v, lo=None, hi=None, lo_open=False, kind="scenario"):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise _err(key, f"must be a finite number, got {v!r}", kind)
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise _err(key, f"must be {'>' if lo_open else '>='} {lo}, got {v}", kind)
    if hi is not None and v > hi:
        raise _err(key, f"must be <= {hi}, got {v}", kind)
    return float(v)


def _range(key, v, lo_open=True, kind="scenario"):
    if not isinstance(v, (list, tuple)) or len(v) != 2:
        raise _err(key, f"must be [min, max], got {v!r}", kind)
    a, b = (_num(key, x, 0.0, lo_open=lo_open, kind=kind) for x in v)
    if a > b:
        raise _err(key, f"min {a} is larger than max {b}", kind)
    return a, b


def _grid(key, v, lo, hi, kind="scenario"):
    if not isinstance(v, (list, tuple)) or len(v) != 3:
        raise _err(key, f"must be [min, max, step], got {v!r}", kind)
    a, b, s = (_num(key, x, kind=kind) for x in v)
    if s <= 0:
        raise _err(key, f"step must be positive, got {s}", kind)
    if a > b:
        raise _err(key, f"min {a} is larger than max {b}", kind)
    if a < lo or b > hi:
        raise _err(key, f"must lie within [{lo}, {hi}] deg, got [{a}, {b}]", kind)
    if a < b and s > b - a:
        raise _err(key, f"step {s:g} is larger than the range {a:g}..{b:g}: the grid would be {a:g} alone", kind)
    n = int(math.floor((b - a) / s + 1e-9)) + 1
    if n > 100_000:
        raise _err(key, f"grid of {n} values is too fine", kind)
    return np.radians(a + s * np.arange(n))


def _wire_counts(key, v, kind="scenario") -> tuple[int, ...]:
    """A wire count or a list of them (3 to 16), sorted, without repeats."""
    counts = [v] if isinstance(v, int) and not isinstance(v, bool) else v
    if (
        not isinstance(counts, (list, tuple))
        or not counts
        or any(isinstance(c, bool) or not isinstance(c, int) or c < 3 or c > 16 for c in counts)
    ):
        raise _err(key, f"must be a list of integers from 3 to 16, got {v!r}", kind)
    return tuple(sorted(set(counts)))


def _merge(key, given, default, kind="scenario"):
    if not isinstance(given, dict):
        raise _err(key, f"must be an object, got {given!r}", kind)
    unknown = sorted(set(given) - set(default))
    if unknown:
        raise _err(key, f"unknown sub-key(s) {unknown}; known: {sorted(default)}", kind)
    return {**default, **given}


def with_defaults(d, defaults: dict, kind: str, what: str, objects=()) -> dict:
    """A file's top-level object ``d`` over a deep copy of ``defaults``: an object (a ValueError, like
    every bad file: the command line reports it in one line), no unknown key, the keys ``objects``
    merged into their default objects (:func:`_merge`), the others copied."""
    if not isinstance(d, dict):
        raise ValueError(f"{what} must be a JSON object, got {type(d).__name__}")
    unknown = sorted(set(d) - set(defaults))
    if unknown:
        raise ValueError(f"unknown {kind} key(s) {unknown}; known: {sorted(defaults)}")
    out = copy.deepcopy(defaults)
    for k, v in d.items():
        out[k] = _merge(k, v, defaults[k], kind) if k in objects else copy.deepcopy(v)
    return out


def segment_entries(s: dict, keys, kind: str, objects=()) -> list[tuple[dict, dict]] | None:
    """A file's ``segments`` (``s``: its keys with the defaults filled in): ``None`` for one segment
    written without it, else per segment ``(values, entry)``: the file's values of ``keys``
    overridden by the segment's ``entry`` (its own keys only; ``objects`` merged key by key)."""
    entries = s["segments"]
    if entries is None:
        return None
    if not isinstance(entries, list) or not entries:
        raise _err("segments", f"must be null or a non-empty list of segment objects, got {entries!r}", kind)
    shared = {k: s[k] for k in keys}
    out = []
    for j, entry in enumerate(entries):
        values = with_defaults(entry, shared, f"{kind} segments[{j}]", f"segments[{j}]", objects)
        out.append((values, entry))
    return out


def where_given(kind: str, j: int, entry: dict):
    """Which file a segment's key came from, for its error: the segment's entry or the file's top."""
    return lambda key: f"{kind} segments[{j}]" if key in entry else kind


def _preload(v, kind: str, several: bool):
    """``preload_N``: a number, or with several segments ``[min, max]`` (a variable) ->
    ``(lower, range or None)``."""
    if several and isinstance(v, (list, tuple)):
        lo, hi = _range("preload_N", v, lo_open=False, kind=kind)
        return lo, (lo, hi)
    return _num("preload_N", v, 0.0, kind=kind), None


def _segment_fields(s: dict, where, several: bool = False) -> dict:
    """The segment's :class:`Scenario` fields from its keys in ``s``; ``where(key)`` is the ``kind``
    that names a key in an error."""
    c, w = s["constraints"], where("constraints")
    od = c["outer_diameter_mm"]
    preload, preload_range = _preload(s["preload_N"], where("preload_N"), several)
    return {
        "length": _num("length_mm", s["length_mm"], 0.0, lo_open=True, kind=where("length_mm")),
        "backbone_EI": _num("backbone_EI_Nmm2", s["backbone_EI_Nmm2"], 0.0, kind=where("backbone_EI_Nmm2")),
        "n_wires": _wire_counts("n_wires", s["n_wires"], where("n_wires")),
        "pitch_radius": _range("pitch_radius_mm", s["pitch_radius_mm"], kind=where("pitch_radius_mm")),
        "wire_stiffness": _range(
            "wire_stiffness_N_per_mm", s["wire_stiffness_N_per_mm"], kind=where("wire_stiffness_N_per_mm")
        ),
        "preload": preload,
        "preload_range": preload_range,
        "outer_diameter": None if od is None else _num("constraints.outer_diameter_mm", od, 0.0, lo_open=True, kind=w),
        "wire_diameter": _num("constraints.wire_diameter_mm", c["wire_diameter_mm"], 0.0, kind=w),
        "min_wall": _num("constraints.min_wall_mm", c["min_wall_mm"], 0.0, kind=w),
        "min_wire_gap": _num("constraints.min_wire_gap_mm", c["min_wire_gap_mm"], 0.0, kind=w),
    }


def _forbidden_arc(s: dict):
    """``forbidden_arc_deg``: null or ``(start, end)`` rad with ``0 < end - start < 2 pi``."""
    arc = s["forbidden_arc_deg"]
    if arc is None:
        return None
    if not isinstance(arc, (list, tuple)) or len(arc) != 2:
        raise _err("forbidden_arc_deg", f"must be null or [start, end], got {arc!r}")
    a0, a1 = (_num("forbidden_arc_deg", x) for x in arc)
    width = (a1 - a0) % 360.0
    if not 0 < width < 360:
        raise _err("forbidden_arc_deg", f"must span between 0 and 360 deg, got {arc!r}")
    if not s["free_wire_angles"]:
        raise _err("forbidden_arc_deg", "needs free_wire_angles: true")
    return math.radians(a0), math.radians(a0 + width)


def _task_fields(s: dict) -> dict:
    """The task's, weights' and optimiser's :class:`Scenario` fields (shared by every segment)."""
    w = s["weights"]
    o = s["optimizer"]
    for k in ("free_wire_angles", "strict_controllability"):
        if not isinstance(s[k], bool):
            raise _err(k, f"must be true or false, got {s[k]!r}")
    arc = _forbidden_arc(s)
    for k in ("starts", "steps", "seed"):
        if isinstance(o[k], bool) or not isinstance(o[k], int) or o[k] < (0 if k == "seed" else 1):
            kind = "a non-negative" if k == "seed" else "a positive"
            raise _err(f"optimizer.{k}", f"must be {kind} integer, got {o[k]!r}")
    load = s["load_N"]
    if not isinstance(load, (list, tuple)) or len(load) != 3:
        raise _err("load_N", f"must be [fx, fy, fz], got {load!r}")
    return {
        "free_wire_angles": s["free_wire_angles"],
        "dq": _num("joint_uncertainty_mm", s["joint_uncertainty_mm"], 0.0, lo_open=True),
        "theta_L": _grid("theta_L_deg", s["theta_L_deg"], 0.0, 90.0),
        "delta": _grid("delta_deg", s["delta_deg"], -360.0, 720.0),
        "load": np.array([_num("load_N", x) for x in load]),
        "w_position": _num("weights.position_uncertainty", w["position_uncertainty"], 0.0),
        "w_deflection": _num("weights.deflection", w["deflection"], 0.0),
        "w_wires": _num("weights.wire_count", w["wire_count"], 0.0),
        "min_spread": _num("min_spread", s["min_spread"], 0.0, 1.0),
        "strict_controllability": s["strict_controllability"],
        "forbidden_arc": arc,
        "starts": o["starts"],
        "steps": o["steps"],
        "learning_rate": _num("optimizer.learning_rate", o["learning_rate"], 0.0, lo_open=True),
        "sharpness": _num("optimizer.sharpness", o["sharpness"], 0.0, lo_open=True),
        "seed": o["seed"],
    }


def _checked(scen: Scenario, kind: str = "scenario") -> Scenario:
    """``scen`` once its pitch radii fit its length and its constraints leave room for a wire count."""
    try:
        _check_radius(scen.length, scen.pitch_radius[1], names=("max", "length_mm"))
    except ValueError as e:
        raise _err("pitch_radius_mm", str(e), kind) from None
    if all(scen.r_bounds(n)[0] > scen.r_bounds(n)[1] for n in scen.n_wires):
        n = scen.n_wires[0]
        lo, hi = scen.r_bounds(n)
        raise _err(
            "constraints",
            f"no pitch radius fits: {n} wires need r >= {lo:.3g} mm for the "
            f"wire gap but the outer diameter allows r <= {hi:.3g} mm",
            kind,
        )
    return scen


def only_for(d: dict, several: bool, kind: str = "scenario") -> None:
    """Refuse the workspace keys of the other form: the grid for several segments, samples for one."""
    for key in GRID_KEYS if several else SAMPLE_KEYS:
        if key in d:
            what = (
                "is one segment's grid; several segments' workspace is configuration samples (max_bend_deg, samples)"
                if several
                else "is for several segments; one segment's workspace is the theta_L_deg x delta_deg grid"
            )
            raise _err(key, what, kind)


def configurations(s: dict, kind: str = "scenario") -> np.ndarray:
    """Several segments' workspace: the first ``samples`` Halton configurations, each segment bent up
    to ``max_bend_deg`` (:func:`~tension_zones.analysis.config_samples`), (M, S, 2) rad."""
    from ..analysis._samples import config_samples

    bend = _num("max_bend_deg", s["max_bend_deg"], 0.0, 180.0, lo_open=True, kind=kind)
    n = s["samples"]
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_SAMPLES:
        raise _err("samples", f"must be an integer from 1 to {MAX_SAMPLES}, got {n!r}", kind)
    return config_samples(len(s["segments"]), n, bend)


def _several(s: dict) -> None:
    """Refuse what the optimiser does for one segment only: free wire angles."""
    if s["free_wire_angles"]:
        raise _err("free_wire_angles", "several segments' wires are evenly spaced and interleaved; set it to false")


def for_robot(d: dict, robot, play=None) -> dict:
    """The scenario dictionary ``d`` starting from a given robot (``optimize --design``): each segment's
    values the scenario leaves out (in its ``segments`` entry and at the top level) are the robot's, a
    range of one value (fixed): its wire count, length, pitch radius, wire stiffness, backbone EI and
    preload. The joint uncertainty, where the scenario leaves it out, is the largest of ``play`` (mm,
    per wire: a calibrated robot's identified play, a bound for every wire). ``robot``: a
    :class:`~tension_zones.model.Robot` (or a one-segment ``Design``)."""
    segs = list(getattr(robot, "segments", [robot]))
    entries = d.get("segments")
    if entries is None:
        entries = [{} for _ in segs]
    elif not isinstance(entries, list) or len(entries) != len(segs):
        got = (
            (f"{len(entries)} entries" if len(entries) != 1 else "1 entry")
            if isinstance(entries, list)
            else repr(entries)
        )
        raise _err(
            "segments", f"has {got}; the design file has {len(segs)} segment(s): one entry each, or leave it out"
        )
    out = {**d, "segments": [_with_segment(e, seg, d) if isinstance(e, dict) else e for e, seg in zip(entries, segs)]}
    if "joint_uncertainty_mm" not in d and play is not None and max(play, default=0.0) > 0:
        out["joint_uncertainty_mm"] = float(max(play))
    return out


def _with_segment(entry: dict, seg, top: dict) -> dict:
    """A ``segments`` entry with the design's segment ``seg`` (a ``Design``) filling the keys neither it
    nor the file's top level ``top`` gives."""
    own = {
        "n_wires": [int(seg.n_wires)],
        "length_mm": float(seg.length),
        "pitch_radius_mm": [float(seg.pitch_radius)] * 2,
        "wire_stiffness_N_per_mm": [float(seg.wire_stiffness)] * 2,
        "backbone_EI_Nmm2": float(seg.backbone_EI),
        "preload_N": float(seg.preload),
    }
    return {**{k: v for k, v in own.items() if k not in top}, **entry}


def parse_scenario(d: dict, robot=None, play=None) -> Scenario:
    """Validate a scenario dictionary and fill in the defaults (one segment, or several: ``segments``);
    with ``robot``, starting from it (:func:`for_robot`)."""
    if robot is not None:
        d = for_robot(d, robot, play)
    s = with_defaults(d, DEFAULTS, "scenario", "a scenario", [k for k, v in DEFAULTS.items() if isinstance(v, dict)])
    entries = segment_entries(s, SEGMENT_KEYS, "scenario", ("constraints",))
    several = entries is not None and len(entries) > 1
    only_for(d, several)
    task = _task_fields(s)
    if entries is None:
        return _checked(Scenario(**_segment_fields(s, lambda key: "scenario"), **task, raw=s))
    if not several:
        fields = _segment_fields(entries[0][0], where_given("scenario", 0, entries[0][1]))
        return _checked(Scenario(**fields, **task, raw=s), "scenario segments[0]")
    _several(s)
    configs = configurations(s)
    segments = tuple(
        _checked(
            Scenario(**_segment_fields(values, where_given("scenario", j, entry), True), **task, raw=s),
            f"scenario segments[{j}]",
        )
        for j, (values, entry) in enumerate(entries)
    )
    if task["w_deflection"] > 0:
        check_statics_wires([seg.n_wires for seg in segments], "weights.deflection", "scenario", "set it to 0")
    return dataclasses.replace(segments[0], segments=segments, configs=configs)


def check_statics_wires(counts, key: str, kind: str, instead: str) -> None:
    """Refuse, naming ``key``, segments' wire counts (one sequence of choices per segment) whose largest
    robot has more wires than a robot's statics take (``MAX_CHAIN_WIRES``: the tensions enumerate
    ``2^N`` free sets)."""
    from ..model._chain_statics import MAX_CHAIN_WIRES

    most = sum(max(c) for c in counts)
    if most > MAX_CHAIN_WIRES:
        raise _err(
            key,
            f"a robot's statics enumerate 2^N sets of taut wires: at most {MAX_CHAIN_WIRES} wires in all, the "
            f"segments' counts give up to {most}; {instead} or use fewer wires",
            kind,
        )


def load_scenario(path, robot=None, play=None) -> Scenario:
    """:func:`parse_scenario` of a scenario file."""
    return parse_scenario(read_json(path, "scenario file"), robot, play)
