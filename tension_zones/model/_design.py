"""A continuum segment's design: a frozen pytree whose only static field is the wire count.

Units: mm, N, N/mm, N mm^2, rad (MODEL.md, preamble). Every numeric field is a JAX array leaf, so
changing a value (a new pitch radius, other wire angles) never triggers a recompile; changing
``n_wires`` does, because it fixes array shapes.
"""

from __future__ import annotations

import dataclasses
import json
import math
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
_DATA_FIELDS = ("length", "pitch_radius", "wire_angles", "wire_stiffness", "backbone_EI", "preload")


def _is_concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


@dataclasses.dataclass(frozen=True, init=False, repr=False, eq=False)
class Design:
    """A single continuum segment with ``n_wires`` pull-only wires (MODEL.md Sec. 1).

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

    Invalid values raise ``ValueError`` naming the field and the value. Validation runs on concrete
    values only; pytree reconstruction inside ``jit``/``vmap`` bypasses it.
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
        values = dict(
            length=length,
            pitch_radius=pitch_radius,
            wire_stiffness=wire_stiffness,
            backbone_EI=backbone_EI,
            preload=preload,
        )
        if wire_angles is None:
            wire_angles = np.arange(n_wires) * (2.0 * np.pi / n_wires)
        values["wire_angles"] = wire_angles
        for name in _SCALARS:
            _check_scalar(name, values[name])
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

    @property
    def wire_angles_deg(self) -> np.ndarray:
        return np.degrees(np.asarray(self.wire_angles))

    def to_dict(self) -> dict[str, Any]:
        """The design-file form (MODEL.md Sec. 6): degrees and the file's key names."""
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
    def from_dict(cls, d: dict[str, Any]) -> Design:
        """Build from a design-file dictionary (MODEL.md Sec. 6); unknown keys are an error."""
        keys = {
            "n_wires": "n_wires",
            "length_mm": "length",
            "pitch_radius_mm": "pitch_radius",
            "wire_stiffness_N_per_mm": "wire_stiffness",
            "backbone_EI_Nmm2": "backbone_EI",
            "preload_N": "preload",
            "wire_angles_deg": "wire_angles",
        }
        if not isinstance(d, dict):
            raise ValueError(f"a design file must hold a JSON object, got {type(d).__name__}")
        unknown = sorted(set(d) - set(keys))
        if unknown:
            raise ValueError(f"unknown design key(s) {unknown}; known: {sorted(keys)}")
        for required in ("length_mm", "pitch_radius_mm"):
            if required not in d:
                raise ValueError(f"design is missing the key {required!r}")
        kw = {keys[k]: v for k, v in d.items()}
        angles = kw.get("wire_angles")
        if "n_wires" not in kw:
            if angles is None:
                raise ValueError("design needs 'n_wires' or 'wire_angles_deg'")
            kw["n_wires"] = len(angles)
        if angles is not None:
            _check_angles(angles, kw["n_wires"], field="wire_angles_deg")
            kw["wire_angles"] = np.radians(np.asarray(angles, dtype=float))
        return cls(**kw)

    @classmethod
    def from_json(cls, path) -> Design:
        return cls.from_dict(read_json(path, "design file"))

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


def read_json(path, what: str):
    """A JSON file's content; a missing or malformed file is a ValueError naming it (``what``)."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise ValueError(f"{what} {str(path)!r} does not exist") from None
    except IsADirectoryError:
        raise ValueError(f"{what} {str(path)!r} is a folder, not a file") from None
    except json.JSONDecodeError as e:
        raise ValueError(f"{what} {str(path)!r} is not valid JSON: {e}") from None


def _check_scalar(name: str, value) -> None:
    if not _is_concrete(value):
        return
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if arr.ndim != 0:
        raise ValueError(f"{name} must be a scalar, got shape {arr.shape}")
    v = float(arr)
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {v}")
    if name in ("length", "pitch_radius", "wire_stiffness") and v <= 0:
        raise ValueError(f"{name} must be positive, got {v}")
    if name in ("backbone_EI", "preload") and v < 0:
        raise ValueError(f"{name} must be non-negative, got {v}")


def _check_angles(angles, n_wires: int, field: str = "wire_angles") -> None:
    if not _is_concrete(angles):
        return
    try:
        a = np.asarray(angles, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{field} must be a list of numbers, got {angles!r}") from None
    if a.ndim != 1 or a.shape[0] != n_wires:
        raise ValueError(f"{field} must have n_wires = {n_wires} entries, got shape {a.shape}")
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
