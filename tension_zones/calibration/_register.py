"""The global registration: the measurement frame found in closed form before the loop.

The loop's frame parameters (``offset``, ``pattern_rotation``, the ``registration`` effect) are fitted
by local steps from the identity, so a tracker mounted far from the robot's base (any rotation) would
land them in a wrong minimum. Before the loop, the rigid transform that best maps the nominal model's
predicted tips (base frame) onto the measured ones is found in closed form (Kabsch/Umeyama, a proper
rotation), and the recording is moved into the robot's base frame with it; the loop then fits the
small remainder by its local steps. Every step is equivariant (a rigid motion of the measurements moves the
transform with it and leaves the moved recording the same), so where the tracker is does not change
what the loop sees.

For a tracker-frame recording (origin and orientation unknown) the registration is always applied.
For a recording declared in the base frame it is applied only where the transform lies beyond what the
``registration`` effect reaches by its bounds (then the frame is plainly not the base frame, and the
registration joins the nominal parameters); nearer, the effect remains a candidate the loop can name.
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np

from .._numerics import rotvec_to_matrix
from ._data import Dataset

#: Fixed-point iterations between the transform and the data's pattern rotations (closed forms both).
ITERATIONS = 8
#: A registered nominal model that explains less than this share of the measured tip motion's
#: variance (its R^2 in the found frame) cannot fix the frame: the report says so. The rotation that
#: maps one point cloud onto another is well determined when the model's predictions carry most of the
#: motion; below half, what it gets wrong is as large as what it gets right.
MIN_EXPLAINED = 0.5


def kabsch(a, b, w=None) -> tuple[np.ndarray, np.ndarray]:
    """The proper rigid transform ``(R, t)`` minimising ``sum_i w_i |R a_i + t - b_i|^2``.

    ``a``, ``b`` (N, 3) corresponding points, ``w`` (N,) non-negative weights (default 1). Closed form
    (Kabsch/Umeyama): the SVD of the weighted cross-covariance, with the sign fixed so ``det R = +1``.
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    w = np.ones(len(a)) if w is None else np.asarray(w, float)
    w = w / w.sum()
    ca, cb = w @ a, w @ b
    H = ((a - ca) * w[:, None]).T @ (b - cb)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return R, cb - R @ ca


def rotation_vector(R) -> np.ndarray:
    """The rotation vectors (..., 3) (rad, angle in [0, pi]) of rotation matrices (..., 3, 3)."""
    R = np.asarray(R, float)
    c = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    axis = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    s2 = np.linalg.norm(axis, axis=-1)  # 2 sin(angle)
    angle = np.arctan2(s2 / 2.0, c)
    small, half = angle < 1e-8, angle > 3.0
    out = axis * np.where(small, 0.5, angle / np.where(small, 1.0, s2))[..., None]
    # near a half turn the skew part vanishes: the axis from the symmetric part, n n^T
    sym = (R + np.swapaxes(R, -1, -2)) / 2.0 - c[..., None, None] * np.eye(3)
    M = sym / np.where(half, 1.0 - c, 1.0)[..., None, None]
    k = np.argmax(np.diagonal(M, axis1=-2, axis2=-1), axis=-1)
    v = np.take_along_axis(M, k[..., None, None], axis=-1)[..., 0]
    v = v * np.sign(np.where(np.sum(v * axis, axis=-1) < 0, -1.0, 1.0))[..., None]  # the skew part's sign
    v = v / np.maximum(np.linalg.norm(v, axis=-1), 1e-300)[..., None]
    return np.where(half[..., None], angle[..., None] * v, out)


@dataclasses.dataclass(frozen=True)
class GlobalRegistration:
    """``p_measured = R p_base + t``: the measurement frame against the robot's base.

    ``rmse_mm``: the nominal model's tip error in that frame (the samples it was fitted on);
    ``explained``: the share of the measured tip motion's variance the registered nominal model explains;
    ``applied``: whether the loop runs on the recording moved into the base frame (:meth:`to_base`);
    ``reason``: why (or why not), one line.
    """

    R: np.ndarray
    t: np.ndarray
    rmse_mm: float
    explained: float
    applied: bool
    reason: str

    @property
    def trusted(self) -> bool:
        return self.explained >= MIN_EXPLAINED

    def to_base(self, data: Dataset) -> Dataset:
        """``data`` with its positions (and orientations) moved into the robot's base frame."""
        if not self.applied:
            return data
        p = (np.asarray(data.p) - self.t) @ self.R
        rot = None
        if data.rot is not None:
            rot = rotation_vector(self.R.T @ np.asarray(jax.vmap(rotvec_to_matrix)(np.asarray(data.rot, float))))
        return dataclasses.replace(data, p=p, rot=rot)

    def to_measured(self, p) -> np.ndarray:
        """Base-frame positions (N, 3) in the measurement frame."""
        return np.asarray(p) @ self.R.T + self.t if self.applied else np.asarray(p)

    def to_json(self) -> dict:
        return {
            "applied": self.applied,
            "reason": self.reason,
            "matrix": np.asarray(self.R).tolist(),
            "rotation_deg": np.degrees(rotation_vector(self.R)).tolist(),
            "angle_deg": float(np.degrees(np.linalg.norm(rotation_vector(self.R)))),
            "translation_mm": np.asarray(self.t).tolist(),
            "rmse_mm": self.rmse_mm,
            "explained": self.explained,
            "trusted": self.trusted,
        }

    @staticmethod
    def from_json(d: dict | None) -> GlobalRegistration | None:
        if not d or not d.get("applied"):
            return None
        R = np.asarray(d["matrix"], float)
        return GlobalRegistration(
            R=R,
            t=np.asarray(d["translation_mm"], float),
            rmse_mm=d["rmse_mm"],
            explained=d["explained"],
            applied=True,
            reason=d["reason"],
        )


def global_registration(predict, data: Dataset, rows, reach=None) -> GlobalRegistration:
    """The measurement frame of ``data`` against the robot's base (:class:`GlobalRegistration`).

    ``predict(data_in_base_frame)``: the nominal model's tip positions (N, 3) in the base frame (its
    nominal start values may depend on the data, e.g. the wire patterns' rotations: they are taken
    from the recording as moved by the transform of the iteration before, starting from the declared
    ones, so every iterate moves with the recording). ``rows`` (N,) bool: the samples to fit on (the
    training part). ``reach``: ``(max rotation-vector component (rad), max translation (mm))`` of the local
    registration, for a recording declared in the base frame (applied only beyond it); None for a
    tracker-frame recording (always applied).
    """
    rows = np.asarray(rows, bool)
    p = np.asarray(data.p, float)
    R, t = np.eye(3), np.zeros(3)
    P = predict(None)  # the declared start values: nothing taken from the recording yet
    for _ in range(ITERATIONS):
        R_new, t_new = kabsch(P[rows], p[rows])
        done = np.abs(R_new - R).max() < 1e-12 and np.abs(t_new - t).max() < 1e-9
        R, t = R_new, t_new
        if done:
            break
        moved = dataclasses.replace(data, p=(p - t) @ R)
        P = predict(moved)
    resid = P[rows] @ R.T + t - p[rows]
    sse = float(np.sum(resid**2))
    sst = float(np.sum((p[rows] - p[rows].mean(axis=0)) ** 2))
    explained = 1.0 - sse / sst if sst > 0 else 0.0
    rms = float(np.sqrt(sse / max(rows.sum(), 1)))
    w = rotation_vector(R)
    if reach is None:
        applied, reason = True, "tracker frame: always registered"
    else:
        beyond = bool(np.any(np.abs(w) > reach[0]) or np.any(np.abs(t) > reach[1]))
        applied = beyond and explained >= MIN_EXPLAINED
        reason = (
            "declared base frame, but the best frame is beyond the registration effect's reach "
            f"({np.degrees(np.linalg.norm(w)):.1f} deg, {np.linalg.norm(t):.1f} mm)"
            if applied
            else "declared base frame, within the registration effect's reach"
            if not beyond
            else "declared base frame; a far frame fits better, but the nominal model explains too "
            "little of the motion to trust it"
        )
    if not explained >= MIN_EXPLAINED:
        reason += (
            f"; the nominal model explains {100 * explained:.0f} % of the tip motion in the best frame "
            f"(tip error {rms:.2f} mm): check the design file and the data's units"
        )
    return GlobalRegistration(R=R, t=t, rmse_mm=rms, explained=explained, applied=applied, reason=reason)
