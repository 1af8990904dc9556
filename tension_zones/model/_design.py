"""A continuum segment's design: a frozen pytree whose only static field is the wire count.

Units: mm, N, N/mm, N mm^2, rad (tension_zones/MODEL.md, preamble). Every numeric field is a JAX array leaf, so
changing a value (a new pitch radius, other wire angles) never triggers a recompile; changing
``n_wires`` does, because it fixes array shapes.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import warnings
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

#: Default backbone bending stiffness (N mm^2): a 0.8 mm nitinol rod (E = 60 GPa, I = pi d^4/64).
DEFAULT_BACKBONE_EI = 1200.0
#: Default wire stiffness (N/mm): the paper's "generic median cable stiffness" (Sec. 6.2.2).
DEFAULT_WIRE_STIFFNESS = 75.0

_SCALARS = ("length", "pitch_radius", "wire_stiffness", "backbone_EI", "preload")
#: The largest length and pitch radius taken (mm): a kilometre is beyond any continuum robot, and far
#: larger values overflow the measures' squares and products into meaningless numbers.
MAX_SIZE_MM = 1e6
#: The largest pitch radius, as a fraction of the length. Bent by ``theta``, a segment's centre of
#: curvature is ``L / theta`` from its backbone; a wire on the inside stays short of it only while
#: ``r < L / theta``, so ``r <= L / 2`` leaves bends up to 2 rad (115 deg), past the 90 deg of the
#: workspace grids.
MAX_RADIUS_PER_LENGTH = 0.5
_DATA_FIELDS = ("length", "pitch_radius", "wire_angles", "wire_stiffness", "backbone_EI", "preload")


def _is_concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


@dataclasses.dataclass(frozen=True, init=False, repr=False, eq=False)
class Design:
    """A single continuum segment with ``n_wires`` pull-only wires (tension_zones/MODEL.md Sec. 1).

    Args:
        n_wires: number of wires (static; at least 3: pull-only wires need three to bend the
            segment in every direction).
        length: backbone length ``L`` (mm), > 0.
        pitch_radius: radius ``r`` of the wires' pitch circle (mm), > 0.
        wire_angles: ``(n_wires,)`` angles ``alpha_k`` (rad) of the wires about ``z_b`` from ``x_b``;
            ``None`` = evenly spaced from 0, ``alpha_k = (k - 1) 2 pi / n``.
        wire_stiffness: axial stiffness ``k_w`` of each wire (N/mm), > 0.
        backbone_EI: bending stiffness of the backbone (N mm^2), >= 0.
        preload: wire preload ``f_min`` (N), >= 0.

    Invalid values raise ``ValueError`` naming the field and the value. That check needs concrete
    values: a design built inside ``jit``/``vmap`` (traced values) or rebuilt from its leaves is not
    checked when built. Its values are checked where they are used instead: :meth:`invalid` is the
    same rule on traced values, and every measure (``pose_measures``, ``pose_metrics``,
    ``compliance_pose``, ``tension_score``, ``tension_mask``) is NaN (counts -1, flags False) for an
    invalid design, as for NaN inputs: never a plausible number.
    """

    n_wires: int
    length: jax.Array
    pitch_radius: jax.Array
    wire_angles: jax.Array
    wire_stiffness: jax.Array
    backbone_EI: jax.Array
    preload: jax.Array

    def __init__(
        self,
        n_wires: int,
        length,
        pitch_radius,
        wire_angles=None,
        wire_stiffness=DEFAULT_WIRE_STIFFNESS,
        backbone_EI=DEFAULT_BACKBONE_EI,
        preload=0.0,
        *,
        dtype=None,
    ):
        if isinstance(n_wires, bool) or not isinstance(n_wires, (int, np.integer)):
            raise ValueError(f"n_wires must be an integer, got {n_wires!r}")
        n_wires = int(n_wires)
        if n_wires < 3:
            raise ValueError(
                f"n_wires must be at least 3 (pull-only wires cannot bend the segment in every "
                f"direction with fewer), got {n_wires}"
            )
        dtype = jnp.dtype(dtype) if dtype is not None else jnp.result_type(float)
        values = {
            "length": length,
            "pitch_radius": pitch_radius,
            "wire_stiffness": wire_stiffness,
            "backbone_EI": backbone_EI,
            "preload": preload,
        }
        if wire_angles is None:
            wire_angles = np.arange(n_wires) * (2.0 * np.pi / n_wires)
        values["wire_angles"] = wire_angles
        for name in _SCALARS:
            _check_scalar(name, values[name])
        _check_radius(values["length"], values["pitch_radius"])
        _check_angles(values["wire_angles"], n_wires)
        object.__setattr__(self, "n_wires", n_wires)
        for name in _DATA_FIELDS:
            object.__setattr__(self, name, jnp.asarray(values[name], dtype=dtype))

    # -- pytree protocol (registered below); unflatten bypasses __init__ so tracers are fine --
    def _tree_flatten(self):
        return tuple(getattr(self, f) for f in _DATA_FIELDS), self.n_wires

    @classmethod
    def _tree_unflatten(cls, n_wires, leaves):
        obj = object.__new__(cls)
        object.__setattr__(obj, "n_wires", n_wires)
        for name, leaf in zip(_DATA_FIELDS, leaves):
            object.__setattr__(obj, name, leaf)
        return obj

    # -- conveniences --------------------------------------------------------------------------
    @property
    def dtype(self):
        return self.length.dtype

    def replace(self, **changes) -> Design:
        """A copy with some fields changed (validated like the constructor)."""
        kw = {f: getattr(self, f) for f in ("n_wires",) + _DATA_FIELDS}
        kw.update(changes)
        if "n_wires" in changes and "wire_angles" not in changes:
            kw["wire_angles"] = None
        return Design(**kw, dtype=self.dtype)

    def astype(self, dtype) -> Design:
        """The same design with every leaf cast to ``dtype`` (e.g. ``jnp.float32``)."""
        return jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype), self)

    def invalid(self) -> jax.Array:
        """Whether a value is outside its domain (the constructor's rule, on traced values too):
        ``length``, ``pitch_radius``, ``wire_stiffness`` not finite and positive, ``backbone_EI`` or
        ``preload`` not finite and non-negative, or a wire angle not finite. A boolean scalar (one
        per design of a ``vmap``-ed family); coincident wires are left to the constructor."""
        positive = (self.length, self.pitch_radius, self.wire_stiffness)
        pos = [jnp.isfinite(x) & (x > 0) for x in positive]
        nonneg = [jnp.isfinite(x) & (x >= 0) for x in (self.backbone_EI, self.preload)]
        ok = functools.reduce(jnp.logical_and, pos + nonneg)
        return ~(ok & jnp.all(jnp.isfinite(self.wire_angles), axis=-1))

    @property
    def wire_angles_deg(self) -> np.ndarray:
        return np.degrees(np.asarray(self.wire_angles))

    def to_dict(self) -> dict[str, Any]:
        """The design-file form (tension_zones/MODEL.md Sec. 6): degrees and the file's key names."""
        return {
            "n_wires": self.n_wires,
            "length_mm": float(self.length),
            "pitch_radius_mm": float(self.pitch_radius),
            "wire_stiffness_N_per_mm": float(self.wire_stiffness),
            "backbone_EI_Nmm2": float(self.backbone_EI),
            "preload_N": float(self.preload),
            "wire_angles_deg": [float(a) for a in self.wire_angles_deg],
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any], warn_missing: bool = False) -> Design:
        """Build from a design-file dictionary (tension_zones/MODEL.md Sec. 6).

        Every error is one ``ValueError`` line naming the file's key and what it expects (an unknown
        key, a string, a bool or a fractional ``n_wires``, an entry of the wrong type). Keys that
        are left out take the constructor's defaults; with ``warn_missing=True`` a
        :class:`MissingDesignKeyWarning` names the physical ones among them
        (:data:`PHYSICAL_KEYS`, see :func:`missing_physical_keys`): a calibration would otherwise
        start from, and may "find", a default it was never told.
        """
        if not isinstance(d, dict):
            raise ValueError(f"a design file must hold a JSON object, got {type(d).__name__}")
        unknown = sorted(set(d) - set(_FILE_KEYS))
        if unknown:
            raise ValueError(f"unknown design key(s) {unknown}; known: {sorted(_FILE_KEYS)}")
        for required in ("length_mm", "pitch_radius_mm"):
            if required not in d:
                raise ValueError(f"design is missing the key {required!r}")
        for key, value in d.items():
            if key == "n_wires":
                _check_count(value)
            elif key == "wire_angles_deg":
                _check_number_list(key, value)
            else:
                _check_scalar(key, value, _FILE_KEYS[key])
        kw = {_FILE_KEYS[k]: v for k, v in d.items()}
        angles = kw.get("wire_angles")
        if "n_wires" not in kw:
            if angles is None:
                raise ValueError("design needs 'n_wires' or 'wire_angles_deg'")
            kw["n_wires"] = len(angles)
        if angles is not None:
            _check_angles(angles, kw["n_wires"], field="wire_angles_deg")
            kw["wire_angles"] = np.radians(np.asarray(angles, dtype=float))
        _check_radius(d["length_mm"], d["pitch_radius_mm"], names=("pitch_radius_mm", "length_mm"))
        design = cls(**kw)
        missing = missing_physical_keys(d) if warn_missing else []
        if missing:
            used = {
                "wire_stiffness_N_per_mm": design.wire_stiffness,
                "backbone_EI_Nmm2": design.backbone_EI,
                "preload_N": design.preload,
            }
            named = ", ".join(f"{k!r} (default {float(used[k]):g} used)" for k in missing)
            warnings.warn(f"design leaves out {named}", MissingDesignKeyWarning, stacklevel=2)
        return design

    @classmethod
    def from_json(cls, path, warn_missing: bool = False) -> Design:
        """:meth:`from_dict` of a JSON file; errors name the file."""
        d = read_json(path, "design file")
        try:
            return cls.from_dict(d, warn_missing=warn_missing)
        except ValueError as e:
            raise ValueError(f"design file {str(path)!r}: {e}") from None

    def __repr__(self) -> str:
        if not all(_is_concrete(getattr(self, f)) for f in _DATA_FIELDS):
            return f"Design(n_wires={self.n_wires}, <traced>)"
        try:
            ang = ", ".join(f"{a:.6g}" for a in self.wire_angles_deg)
            return (
                f"Design(n_wires={self.n_wires}, length={float(self.length):g} mm, "
                f"pitch_radius={float(self.pitch_radius):g} mm, wire_angles=[{ang}] deg, "
                f"wire_stiffness={float(self.wire_stiffness):g} N/mm, "
                f"backbone_EI={float(self.backbone_EI):g} N mm^2, preload={float(self.preload):g} N)"
            )
        except (TypeError, ValueError):  # batched leaves (a vmapped family of designs)
            return f"Design(n_wires={self.n_wires}, batched)"


jax.tree_util.register_pytree_node(Design, Design._tree_flatten, Design._tree_unflatten)

#: Design-file keys (tension_zones/MODEL.md Sec. 6) -> :class:`Design` fields.
_FILE_KEYS = {
    "n_wires": "n_wires",
    "length_mm": "length",
    "pitch_radius_mm": "pitch_radius",
    "wire_stiffness_N_per_mm": "wire_stiffness",
    "backbone_EI_Nmm2": "backbone_EI",
    "preload_N": "preload",
    "wire_angles_deg": "wire_angles",
}
#: The physical keys a design file may leave out (they then take the defaults): what a calibration
#: must be told rather than assume.
PHYSICAL_KEYS = ("wire_stiffness_N_per_mm", "backbone_EI_Nmm2", "preload_N")


class MissingDesignKeyWarning(UserWarning):
    """A design file left out a physical key (:data:`PHYSICAL_KEYS`) and its default was used."""


def missing_physical_keys(d: dict[str, Any]) -> list[str]:
    """The keys of :data:`PHYSICAL_KEYS` a design-file dictionary leaves out (defaults taken)."""
    return [k for k in PHYSICAL_KEYS if k not in d]


#: Deepest nesting a JSON input may have: a robot design file needs four levels; deeper is not an
#: input of this package (and would otherwise exhaust the parser's recursion).
MAX_JSON_DEPTH = 32


class _BadJSON(ValueError):
    """A JSON text that parses but is refused (duplicate key, non-finite number)."""


class _NonFinite:
    """Stands for a ``NaN``/``Infinity`` literal (or a number that overflows) until its key is known."""

    def __init__(self, text: str):
        self.text = text


class _Repeated(dict):
    """An object whose key ``repeated`` appears twice, until its place is known (:func:`_check_tree`)."""

    repeated: str


def _unique_keys(pairs):
    seen = {}
    for k, v in pairs:
        if k in seen:
            out = _Repeated(seen)
            out.repeated = k
            return out
        seen[k] = v
    return seen


def _finite_float(text: str):
    v = float(text)
    return v if math.isfinite(v) else _NonFinite(f"{text} (too large for a float)")


def _finite_int(text: str):
    if len(text.lstrip("-")) > 308:  # beyond any float (and Python's digit limit for int())
        return _NonFinite(f"{text[:12]}... (too large for a float)")
    return int(text)


def _check_tree(value, where: str = "", depth: int = 1) -> None:
    """Refuse nesting deeper than :data:`MAX_JSON_DEPTH` and the non-finite stand-ins, naming the key."""
    if isinstance(value, _NonFinite):
        raise _BadJSON(f"key {where or '(top level)'!r} is {value.text}; only finite numbers are allowed")
    if isinstance(value, _Repeated):
        key = f"{where}.{value.repeated}" if where else value.repeated
        raise _BadJSON(f"key {key!r} appears twice (JSON keys must be unique)")
    if not isinstance(value, (dict, list)):
        return
    if depth > MAX_JSON_DEPTH:
        raise _BadJSON(f"nests deeper than {MAX_JSON_DEPTH} levels (at key {where!r})")
    items = value.items() if isinstance(value, dict) else enumerate(value)
    for k, v in items:
        _check_tree(v, f"{where}[{k}]" if isinstance(k, int) else f"{where}.{k}" if where else k, depth + 1)


def read_json(path, what: str):
    """A JSON file's content, strictly: every user-written JSON file is read here.

    A missing, unreadable or malformed file, a key that appears twice in an object, a ``NaN`` or
    ``Infinity`` literal (or a number too large for a float) and nesting deeper than
    :data:`MAX_JSON_DEPTH` levels are one-line ValueErrors naming the file (``what``) and the key.
    A UTF-8 byte-order mark is allowed.
    """
    path = Path(path)
    name = f"{what} {str(path)!r}"
    try:
        text = path.read_text(encoding="utf-8-sig")
        value = json.loads(
            text,
            object_pairs_hook=_unique_keys,
            parse_constant=_NonFinite,
            parse_float=_finite_float,
            parse_int=_finite_int,
        )
        _check_tree(value)
        return value
    except FileNotFoundError:
        raise ValueError(f"{name} does not exist") from None
    except IsADirectoryError:
        raise ValueError(f"{name} is a folder, not a file") from None
    except UnicodeDecodeError as e:
        raise ValueError(f"{name} is not UTF-8 text (byte {e.start})") from None
    except json.JSONDecodeError as e:
        raise ValueError(f"{name} is not valid JSON: {e}") from None
    except _BadJSON as e:
        raise ValueError(f"{name}: {e}") from None
    except RecursionError:
        raise ValueError(f"{name}: nests deeper than {MAX_JSON_DEPTH} levels") from None


def _what(value) -> str:
    """A value for an error message, with its JSON type where the type is the problem."""
    if value is None:
        return "null"
    kind = {bool: "a boolean", str: "a string", list: "a list", dict: "an object"}.get(type(value))
    return f"{value!r} ({kind})" if kind else repr(value)


def _check_count(value) -> None:
    """``n_wires`` from a file: an integer (not a bool, string or fractional number)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        msg = f"n_wires must be an integer of at least 3, got {_what(value)}"
        raise ValueError(msg)


def _check_number_list(key: str, value) -> None:
    """A list of numbers from a file (no strings, booleans, nulls or nested lists)."""
    if not isinstance(value, (list, tuple)):
        msg = f"{key} must be a list of numbers, got {_what(value)}"
        raise ValueError(msg)
    for i, v in enumerate(value):
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            msg = f"{key}[{i}] must be a number, got {_what(v)}"
            raise ValueError(msg)


def _check_scalar(name: str, value, field: str | None = None) -> None:
    """A scalar ``field`` (default: ``name``) in its domain; messages say ``name`` (a file key)."""
    if not _is_concrete(value):
        return
    field = field or name
    if isinstance(value, (bool, np.bool_, str, type(None), list, tuple, dict)):
        msg = f"{name} must be a number, got {_what(value)}"
        raise ValueError(msg)
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if arr.ndim != 0:
        raise ValueError(f"{name} must be a scalar, got shape {arr.shape}")
    v = float(arr)
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {v}")
    if field in ("length", "pitch_radius", "wire_stiffness") and v <= 0:
        raise ValueError(f"{name} must be positive, got {v}")
    if field in ("length", "pitch_radius") and v > MAX_SIZE_MM:
        raise ValueError(f"{name} must be at most {MAX_SIZE_MM:g} mm (a kilometre), got {v:g}")
    if field in ("backbone_EI", "preload") and v < 0:
        raise ValueError(f"{name} must be non-negative, got {v}")


def _check_radius(length, pitch_radius, names=("pitch_radius", "length")) -> None:
    """The pitch radius at most :data:`MAX_RADIUS_PER_LENGTH` of the length (concrete values only)."""
    if not (_is_concrete(length) and _is_concrete(pitch_radius)):
        return
    r, L = float(np.asarray(pitch_radius)), float(np.asarray(length))
    if r > MAX_RADIUS_PER_LENGTH * L:
        raise ValueError(
            f"{names[0]} {r:g} mm is more than half the {names[1]} {L:g} mm: a wire that far out meets "
            f"the centre of curvature before the segment bends {1 / MAX_RADIUS_PER_LENGTH:g} rad"
        )


def _check_angles(angles, n_wires: int, field: str = "wire_angles") -> None:
    if not _is_concrete(angles):
        return
    try:
        a = np.asarray(angles, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{field} must be a list of numbers, got {angles!r}") from None
    if a.ndim != 1 or a.shape[0] != n_wires:
        got = f"{a.shape[0]} entries" if a.ndim == 1 else f"shape {a.shape}"
        raise ValueError(f"{field} must have n_wires = {n_wires} entries, got {got}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{field} must be finite, got {a.tolist()}")
    full = 360.0 if field.endswith("deg") else 2 * np.pi
    wrapped = np.mod(a, full)
    diff = np.abs(wrapped[:, None] - wrapped[None, :])
    diff = np.minimum(diff, full - diff)
    i, j = np.triu_indices(n_wires, k=1)
    close = diff[i, j] <= 1e-9 * full
    if np.any(close):
        k = int(np.argmax(close))
        raise ValueError(
            f"{field} has coincident wires {i[k] + 1} and {j[k] + 1} "
            f"(both at {a[i[k]]:g}{' deg' if full == 360.0 else ' rad'})"
        )
