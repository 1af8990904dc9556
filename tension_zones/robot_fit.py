"""Calibrating a multi-segment robot from tip-position measurements, effect by effect.

The model maps commanded wire displacements ``q`` (T, N) (MODEL.md sign: negative = pulled in, in
acquisition order) to measured tip positions (T, 3):

1. wire offsets: ``q_k -> q_k - e_k`` where ``e_k = pretension_j + slack_k`` (mm of wire; the
   preload ``k_w e`` in N when positive, a deadband when negative);
2. hysteresis: a play (backlash) operator of half-width ``h_j`` per segment on each wire, run in
   acquisition order with ``lax.scan`` (friction along the routing makes the wire lag the servo by
   a direction-dependent amount);
3. the robot with fitted wire angles, stiffness, geometry; equilibrium (``multisegment``) under an
   optional gravity line load;
4. the marker: the tip pose plus a tip-frame offset, seen through a rigid registration.

Every effect is a named set of *bounded* physical parameters (``EFFECTS``); a fit takes a list of
effect names. Parameters map to an unbounded vector through ``c + w tanh(z)``; the fit is a
Levenberg-Marquardt least-squares with Jacobians by forward-mode autodiff (implicit differentiation
through the equilibrium). Uncertainty: the Gauss-Newton covariance ``s^2 (J^T J)^-1`` in physical
units (``s^2`` the residual variance; consecutive samples are correlated and the model is not
exact, so it is optimistic; a parameter sitting at its bound is reported but its std is not
meaningful).
"""

from __future__ import annotations

import dataclasses
import re

import jax
import jax.numpy as jnp
import numpy as np

from ._numerics import rotvec_to_matrix
from .model._robot import Load, Robot, _design_with, equilibrium, tip_pose


# --------------------------------------------------------------------------------------------
# Effects: name -> bounded parameters
# --------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Param:
    """A parameter block: ``shape`` from the robot, bounds ``lo < hi``, initial value."""

    shape: tuple[int, ...]
    lo: float
    hi: float
    init: float = 0.0
    unit: str = ""


def _effect_params(robot: Robot) -> dict[str, dict[str, Param]]:
    S, N = robot.n_segments, robot.n_wires
    nfree = N - S  # per-tendon deviations: the first wire of each segment takes minus their sum
    deg = np.pi / 180
    return {
        # per-segment rotation of the wire pattern and a base-frame position offset
        "base": {
            "segment_angle": Param((S,), -180 * deg, 180 * deg, 0.0, "rad"),
            "offset": Param((3,), -40.0, 40.0, 0.0, "mm"),
        },
        "tendon_angles": {"tendon_angle": Param((nfree,), -25 * deg, 25 * deg, 0.0, "rad")},
        "pretension": {"pretension": Param((S,), -3.0, 3.0, 0.0, "mm")},
        "slack": {"slack": Param((nfree,), -2.0, 2.0, 0.0, "mm")},
        "hysteresis": {"play": Param((S,), 0.0, 1.5, 0.05, "mm")},
        "stiffness": {"log_EI_scale": Param((S,), -3.0, 3.0, 0.0, "")},
        "registration": {
            "rotation": Param((3,), -0.3, 0.3, 0.0, "rad"),
            "marker": Param((3,), -25.0, 25.0, 0.0, "mm"),
        },
        "gravity": {"gravity": Param((3,), -4e-3, 4e-3, 0.0, "N/mm")},
        "geometry": {"log_radius_scale": Param((S,), -0.4, 0.4, 0.0, "")},
    }


def effect_names(robot: Robot) -> tuple[str, ...]:
    return tuple(_effect_params(robot))


def _blocks(robot: Robot, effects) -> dict[str, Param]:
    lib = _effect_params(robot)
    out = dict(lib["base"])
    for e in effects:
        if e not in lib:
            raise ValueError(f"unknown effect {e!r}; known: {sorted(lib)}")
        if e != "base":
            out.update(lib[e])
    return out


def _expand_deviations(dev, robot: Robot):
    """(N - S,) free deviations -> (N,) with zero sum per segment."""
    out, i = [], 0
    for n in robot.n_wires_per_segment:
        d = dev[i : i + n - 1]
        out.append(jnp.concatenate([-jnp.sum(d, keepdims=True), d]))
        i += n - 1
    return jnp.concatenate(out)


# --------------------------------------------------------------------------------------------
# The model
# --------------------------------------------------------------------------------------------
def _get(params, name, robot, shape_default):
    return params.get(name, jnp.zeros(shape_default, robot.route_angles.dtype))


def play(q, h):
    """Play (backlash) operator over time: ``y_t = clip(y_{t-1}, q_t - h, q_t + h)``, ``y_0 = q_0``.
    ``q`` (T, N), ``h`` (N,) >= 0."""

    def step(y, qt):
        y = jnp.clip(y, qt - h, qt + h)
        return y, y

    _, ys = jax.lax.scan(step, q[0], q)
    return ys


def calibrated_robot(robot: Robot, params) -> Robot:
    """The robot with the fitted angles, stiffness and geometry applied."""
    S, N = robot.n_segments, robot.n_wires
    owner = robot.owner
    seg_a = _get(params, "segment_angle", robot, (S,))
    dev = _expand_deviations(_get(params, "tendon_angle", robot, (N - S,)), robot)
    angles = robot.wire_angles + seg_a[owner] + dev
    ei = jnp.exp(_get(params, "log_EI_scale", robot, (S,)))
    rs = jnp.exp(_get(params, "log_radius_scale", robot, (S,)))
    segs, i = [], 0
    for j, seg in enumerate(robot.segments):
        n = seg.n_wires
        segs.append(
            _design_with(
                seg,
                wire_angles=angles[i : i + n],
                backbone_EI=seg.backbone_EI * ei[j],
                pitch_radius=seg.pitch_radius * rs[j],
            )
        )
        i += n
    route_a = jnp.tile(angles[:, None], (1, S))
    route_r = robot.route_radii * rs[None, :]
    return Robot._tree_unflatten(None, (tuple(segs), route_a, route_r))


def effective_q(robot: Robot, params, Q):
    """Wire offsets and play applied to the commanded displacements (T, N)."""
    S, N = robot.n_segments, robot.n_wires
    owner = robot.owner
    e = _get(params, "pretension", robot, (S,))[owner] + _expand_deviations(
        _get(params, "slack", robot, (N - S,)), robot
    )
    Q = jnp.asarray(Q) - e[None, :]
    if "play" in params:
        Q = play(Q, params["play"][owner])
    return Q


def predict(robot: Robot, params, Q):
    """Predicted marker positions (T, 3) for commanded displacements ``Q`` (T, N) in acquisition order."""
    rob = calibrated_robot(robot, params)
    Qe = effective_q(robot, params, Q)
    dt = robot.route_angles.dtype
    if "gravity" in params:
        load = Load(jnp.zeros(3, dt), params["gravity"])
        B = jax.vmap(lambda q: equilibrium(rob, q, load))(Qe)
    else:
        B = jax.vmap(lambda q: equilibrium(rob, q))(Qe)
    p, R = jax.vmap(lambda b: tip_pose(rob, b))(B)
    if "marker" in params:
        p = p + R @ params["marker"]
    if "rotation" in params:
        p = p @ rotvec_to_matrix(params["rotation"]).T
    return p + params["offset"]


# --------------------------------------------------------------------------------------------
# Fitting
# --------------------------------------------------------------------------------------------
@dataclasses.dataclass
class FitResult:
    effects: tuple[str, ...]
    params: dict[str, np.ndarray]
    std: dict[str, np.ndarray]
    rmse_fit_mm: float
    n_iter: int
    blocks: dict[str, Param]

    def table(self) -> str:
        rows = []
        for k, v in self.params.items():
            u = self.blocks[k].unit
            scale = 180 / np.pi if u == "rad" else 1.0
            unit = "deg" if u == "rad" else u
            vals = ", ".join(
                f"{a * scale:.3g}±{s * scale:.2g}" for a, s in zip(np.ravel(v), np.ravel(self.std[k]))
            )
            rows.append(f"{k:>16} [{unit}]: {vals}")
        return "\n".join(rows)


def _to_z(blocks, params):
    zs = []
    for k, b in blocks.items():
        c, w = 0.5 * (b.lo + b.hi), 0.5 * (b.hi - b.lo)
        v = np.broadcast_to(np.asarray(params.get(k, b.init), float), b.shape)
        zs.append(np.arctanh(np.clip((v - c) / w, -0.999, 0.999)).ravel())
    return np.concatenate(zs)


def _from_z(blocks, z):
    out, i = {}, 0
    for k, b in blocks.items():
        n = int(np.prod(b.shape))
        c, w = 0.5 * (b.lo + b.hi), 0.5 * (b.hi - b.lo)
        out[k] = (c + w * jnp.tanh(z[i : i + n])).reshape(b.shape)
        i += n
    return out


def _unflatten_phys(blocks, x):
    out, i = {}, 0
    for k, b in blocks.items():
        n = int(np.prod(b.shape))
        out[k] = x[i : i + n].reshape(b.shape)
        i += n
    return out


def fit(robot: Robot, Q, P, effects=(), fit_idx=None, init=None, max_iter=30, verbose=False):
    """Fit the parameters of ``effects`` (plus ``base``) to measured tip positions.

    ``Q`` (T, N) commanded displacements in acquisition order (the whole sequence is simulated, so
    path-dependent effects see every sample), ``P`` (T, 3) measured positions, ``fit_idx`` the
    samples whose residuals are fitted (default all). ``init`` a dict of starting values.
    """
    Q, P = jnp.asarray(Q, float), jnp.asarray(P, float)
    fit_idx = np.arange(len(P)) if fit_idx is None else np.asarray(fit_idx)
    blocks = _blocks(robot, effects)
    z = jnp.asarray(_to_z(blocks, init or {}))

    @jax.jit
    def resid(z):
        return (predict(robot, _from_z(blocks, z), Q)[fit_idx] - P[fit_idx]).ravel()

    jac = jax.jit(jax.jacfwd(resid))
    r = resid(z)
    cost = float(r @ r)
    lam = 1e-3
    it = 0
    for it in range(1, max_iter + 1):
        J = np.asarray(jac(z))
        g = J.T @ np.asarray(r)
        A = J.T @ J
        improved = False
        for _ in range(10):
            step = np.linalg.solve(A + lam * np.diag(np.diag(A) + 1e-9), -g)
            z_new = z + step
            r_new = resid(z_new)
            c_new = float(r_new @ r_new)
            if np.isfinite(c_new) and c_new < cost:
                improved = True
                break
            lam *= 10
        if not improved:
            break
        rel = (cost - c_new) / cost
        z, r, cost, lam = z_new, r_new, c_new, max(lam / 10, 1e-9)
        if verbose:
            print(f"  iter {it}: rmse {np.sqrt(cost / (len(r) / 3)):.3f} mm", flush=True)
        if rel < 1e-6:
            break
    params = _from_z(blocks, z)
    std = _std_from_jacobian(blocks, z, np.asarray(jac(z)), np.asarray(r))
    return FitResult(
        tuple(effects),
        {k: np.asarray(v) for k, v in params.items()},
        std,
        float(np.sqrt(cost / len(fit_idx))),
        it,
        blocks,
    )


def _std_from_jacobian(blocks, z, Jz, r):
    """Gauss-Newton standard deviations in physical units: ``s^2 (J^T J)^-1`` with ``J`` the
    Jacobian in physical parameters (chain rule through ``c + w tanh(z)``). A tiny relative ridge
    keeps the inverse finite: a parameter the data cannot see gets a huge std, never a small one."""
    w = np.concatenate([np.full(int(np.prod(b.shape)), 0.5 * (b.hi - b.lo)) for b in blocks.values()])
    d = w * (1.0 - np.tanh(np.asarray(z)) ** 2)
    J = Jz / np.maximum(d, 1e-300)[None, :]
    A = J.T @ J
    s2 = float(r @ r) / max(len(r) - J.shape[1], 1)
    ridge = 1e-14 * np.trace(A) / len(A)
    cov = s2 * np.linalg.inv(A + ridge * np.eye(len(A)))
    return {k: np.asarray(v) for k, v in _unflatten_phys(blocks, np.sqrt(np.abs(np.diag(cov)))).items()}


def initial_segment_angles(robot: Robot, Q, P, labels):
    """Starting values of ``segment_angle`` from single-tendon pulls (labels ``..._tendon<i>_...``):
    pulling wire ``k`` alone bends every segment it crosses toward its angle, so the tip moves
    toward it. Per segment, the circular mean of (tip direction - nominal wire angle); 0 where a
    segment has no such pull."""
    Q, P = np.asarray(Q), np.asarray(P)
    nominal = np.asarray(robot.wire_angles)
    owner = robot.owner
    sums = np.zeros(robot.n_segments, complex)
    for k in range(robot.n_wires):
        rows = [i for i, lab in enumerate(labels) if re.search(rf"_tendon{k}_id\d+_pull$", lab)]
        if len(rows) < 2:
            continue
        rows = np.asarray(rows)
        i_max = rows[np.argmin(Q[rows, k])]  # most pulled in (negative = pulled)
        d = P[i_max, :2] - P[rows[0], :2]
        if np.hypot(*d) > 0:
            sums[owner[k]] += np.exp(1j * (np.arctan2(d[1], d[0]) - nominal[k]))
    return np.where(np.abs(sums) > 0, np.angle(sums), 0.0)


# --------------------------------------------------------------------------------------------
# Metrics and selection
# --------------------------------------------------------------------------------------------
def rmse(pred, meas) -> float:
    """Tip-position RMSE (mm): sqrt(mean |p - p_meas|^2)."""
    d = np.asarray(pred) - np.asarray(meas)
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))


def rmse_aligned(pred, meas) -> float:
    """RMSE after removing the mean offset (the metric the OpenCR lab reports)."""
    d = np.asarray(pred) - np.asarray(meas)
    d = d - d.mean(axis=0)
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))


def group_holdout(groups, every: int = 4, offset: int = 3):
    """Split sample indices by whole pattern groups: every ``every``-th group (in order of first
    appearance, starting at ``offset``) is held out. Returns ``(fit_idx, held_idx)``."""
    order = list(dict.fromkeys(groups))
    held_groups = set(order[offset::every])
    held = np.array([g in held_groups for g in groups])
    return np.nonzero(~held)[0], np.nonzero(held)[0]


def forward_selection(robot, Q, P, groups, candidates, min_gain=0.02, init=None, max_passes=2,
                      verbose=False):
    """Add effects one at a time in the given order; keep one only if the held-out RMSE (whole
    pattern groups of the training data) drops by more than ``min_gain`` (relative). Effects
    dropped in one pass are tried again in the next (another effect may have unmasked them), until
    a pass keeps nothing or ``max_passes`` is reached.

    Returns ``(kept effects, history)``, history rows ``{effect, kept, rmse_holdout_mm, fit}``.
    """
    fit_idx, held_idx = group_holdout(groups)
    kept: list[str] = []
    res = fit(robot, Q, P, kept, fit_idx, init=init)
    best = rmse(predict(robot, res.params, Q)[held_idx], P[held_idx])
    hist = [dict(effect="base", kept=True, rmse_holdout_mm=best, fit=res)]
    if verbose:
        print(f"base: held-out {best:.3f} mm", flush=True)
    todo = list(candidates)
    for _ in range(max_passes):
        added = False
        for e in list(todo):
            trial = fit(robot, Q, P, kept + [e], fit_idx, init=res.params)
            h = rmse(predict(robot, trial.params, Q)[held_idx], P[held_idx])
            keep = h < best * (1 - min_gain)
            hist.append(dict(effect=e, kept=keep, rmse_holdout_mm=h, fit=trial))
            if verbose:
                print(f"+{e}: held-out {h:.3f} mm -> {'kept' if keep else 'dropped'}", flush=True)
            if keep:
                kept.append(e)
                todo.remove(e)
                res, best, added = trial, h, True
        if not added or not todo:
            break
    return kept, hist
