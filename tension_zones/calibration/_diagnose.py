"""Residual diagnosis: the noise floor, structure against the inputs, and the score test of effects.

All NumPy (small arrays, after the jitted model has run).

* **Noise floor.** Consecutive samples with the same command and the same load are repeats: the
  difference of their measurements is pure noise (``var = 2 sigma^2`` per axis), whatever the model
  lacks. Pairs whose difference is gross (beyond 5 robust sigmas: a tracker glitch) are left out.
  Without at least 10 such pairs: second differences of the final residual along the acquisition
  order (``(r[i-1] - 2 r[i] + r[i+1]) / sqrt(6)``; removes any structure that is locally linear).
  The floor is the 3-D RMSE of pure noise, ``sqrt(sum of the three axis variances)``.
* **Structure.** For each input feature (bending direction, bending angle, direction of motion,
  load, sample order), a k-nearest-neighbour leave-one-out smoother predicts the held-out residual
  from that feature alone; its prediction error is compared with that of residuals shuffled across
  samples (a permutation test). A mean offset is tested separately (a chi-square on the mean).
* **Score test.** At the current fit, the held-out residual is projected on the sensitivities of a
  candidate effect's parameters (``jax.jacfwd`` at the effect's null values) after removing what the
  already-fitted parameters can explain; ``S = r' P r / sigma^2`` is chi-square with as many degrees
  of freedom as the effect has parameters when the effect is absent. The score is its z-value.
* **Hysteresis or drift** (:func:`home_memory`, from the measurements alone). Where the structure
  test finds the residual ordered in time, the robot either remembers its path or drifts. At the home
  command the tip should be in one place: the part of its spread along the previous excursion is
  memory, a trend against time is drift (both fitted together).
"""

from __future__ import annotations

import math

import numpy as np

from ._data import Dataset
from ._fits import rmse

GLITCH_SIGMAS = 5.0


def chi2_quantile(p_upper: float, dof: int) -> float:
    """Upper quantile of chi-square (Wilson-Hilferty; good to a few % for dof >= 1)."""
    z = _norm_isf(p_upper)
    a = 2.0 / (9.0 * dof)
    return dof * max(1.0 - a + z * math.sqrt(a), 0.0) ** 3


def chi2_z(stat: float, dof: int) -> float:
    """z-value of a chi-square statistic (Wilson-Hilferty)."""
    a = 2.0 / (9.0 * dof)
    return ((max(stat, 0.0) / dof) ** (1.0 / 3.0) - (1.0 - a)) / math.sqrt(a)


def _norm_isf(p: float) -> float:
    lo, hi = -10.0, 10.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if 0.5 * math.erfc(mid / math.sqrt(2.0)) > p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _trimmed_sigma(d: np.ndarray) -> tuple[np.ndarray, int]:
    """Per-axis sigma of zero-mean noise samples ``d`` (M, 3), leaving out gross values."""
    mad = 1.4826 * np.median(np.abs(d), axis=0)
    keep = np.all(np.abs(d) <= GLITCH_SIGMAS * np.maximum(mad, 1e-12), axis=1)
    return np.sqrt(np.mean(d[keep] ** 2, axis=0)), int(keep.sum())


def noise_floor(data: Dataset, residual: np.ndarray | None = None) -> dict:
    """Noise per axis and the 3-D RMSE floor (mm), with the method and number of pairs used."""
    same = np.all(data.q[1:] == data.q[:-1], axis=1) & np.all(data.f[1:] == data.f[:-1], axis=1)
    if same.sum() >= 10:
        d = (data.p[1:] - data.p[:-1])[same] / math.sqrt(2.0)
        sig, used = _trimmed_sigma(d)
        method = "repeated samples (same command and load, consecutive)"
    else:
        if residual is None:
            raise ValueError("noise floor: no repeated samples, a residual is needed")
        d = (residual[:-2] - 2 * residual[1:-1] + residual[2:]) / math.sqrt(6.0)
        sig, used = _trimmed_sigma(d)
        method = "second differences of the residual along the acquisition order"
    return {"sigma_mm": sig.tolist(), "floor_mm": float(np.sqrt(np.sum(sig**2))), "method": method, "pairs": used}


# ---------------------------------------------------------------------------------------------
# Features of each sample (model-agnostic: from the declared model's predicted positions)
# ---------------------------------------------------------------------------------------------
def features(data: Dataset, pred_declared: np.ndarray) -> dict:
    """Per-sample inputs to look for structure in (each (N,) or (N, d)).

    ``bending_direction`` (rad) and ``bending`` (lateral tip offset, mm) of the declared model's
    prediction; ``motion`` = angle between the tip's last direction of motion (commanded, declared
    model) and the bending direction (0: bending further, pi: straightening); ``load`` (N, 3);
    ``order`` = sample index.
    """
    xy = pred_declared[:, :2]
    direction = np.arctan2(xy[:, 1], xy[:, 0])
    step = np.diff(pred_declared[:, :2], axis=0, prepend=pred_declared[:1, :2])
    moving = np.linalg.norm(step, axis=1) > 1e-9
    idx = np.maximum.accumulate(np.where(moving, np.arange(len(step)), 0))
    last = step[idx]
    motion_dir = np.where(moving[idx], np.arctan2(last[:, 1], last[:, 0]), np.nan)
    rel = np.angle(np.exp(1j * (motion_dir - direction)))
    rel = np.where(np.isfinite(rel), rel, 0.0)
    return {
        "bending_direction": direction,
        "bending": np.linalg.norm(xy, axis=1),
        "motion": rel,
        "load": np.asarray(data.f),
        "order": np.arange(data.n_samples, dtype=float),
    }


_CIRCULAR = ("bending_direction", "motion")


def _embed(name: str, x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, float)
    if name in _CIRCULAR:
        return np.stack([np.cos(x), np.sin(x)], axis=1)
    x = x.reshape(len(x), -1)
    s = np.std(x, axis=0)
    return (x - x.mean(axis=0)) / np.where(s > 0, s, 1.0)


def _knn(X: np.ndarray, k: int, rng) -> np.ndarray:
    """The ``k`` nearest neighbours (M, k) of each row of ``X`` (M, D), itself excluded, in any order
    (the smoother averages them); computed in blocks of rows, so memory stays near 2**22 distances
    whatever M (a whole M x M matrix would be 0.8 GB for 10,000 held-out samples, its tie-breaking
    noise as much again)."""
    m = len(X)
    rows = max(1, 2**22 // max(m, 1))
    out = np.empty((m, k), dtype=np.intp)
    for i in range(0, m, rows):
        d2 = np.sum((X[i : i + rows, None, :] - X[None, :, :]) ** 2, axis=-1)
        d2[np.arange(len(d2)), np.arange(i, i + len(d2))] = np.inf
        # ties (e.g. all unloaded samples) broken at random, not by index: an index order would smuggle
        # the acquisition order into another feature (drawn block by block: the same stream as whole)
        out[i : i + rows] = np.argpartition(d2 + 1e-12 * rng.random(d2.shape), k - 1, axis=1)[:, :k]
    return out


def _loo_sse(rr: np.ndarray, nb: np.ndarray):
    """Sum of squared leave-one-out k-NN smoother residuals of ``rr`` (..., M, 3), ``nb`` (M, k) each
    sample's neighbours (themselves excluded): (...). The neighbours are summed a column at a time
    (a (..., M, k, 3) gather costs several times more memory traffic)."""
    smooth = np.zeros_like(rr)
    for j in range(nb.shape[1]):
        smooth += rr[..., nb[:, j], :]
    return np.sum((rr - smooth / nb.shape[1]) ** 2, axis=(-2, -1))


def structure_test(
    resid: np.ndarray, feats: dict, sigma: np.ndarray, n_perm: int = 1000, seed: int = 0, k: int | None = None
) -> dict:
    """Is the residual (M, 3) predictable from each feature beyond noise?

    Returns ``{feature: {"explained": fraction of the residual's variance a leave-one-out k-NN smoother
    predicts, "z": its z-value against residuals shuffled across samples}}`` and ``"mean"``
    (the offset's chi-square z-value given ``sigma`` per axis).
    """
    m = resid.shape[0]
    k = k or int(np.clip(round(np.sqrt(m)), 5, 20))
    rng = np.random.default_rng(seed)
    # winsorise gross values so a tracker glitch cannot make or hide structure
    mad = 1.4826 * np.median(np.abs(resid - np.median(resid, axis=0)), axis=0)
    lim = GLITCH_SIGMAS * np.maximum(mad, 1e-12)
    med = np.median(resid, axis=0)
    r = np.clip(resid, med - lim, med + lim)
    r = r - r.mean(axis=0)
    total = np.sum(r**2)
    perms = np.stack([rng.permutation(m) for _ in range(n_perm)])
    # the shuffles' statistics in batches of about 2**20 residual values (NumPy calls per batch instead
    # of per shuffle)
    batch = max(1, 2**20 // (m * 3))
    out = {}
    for name, x in feats.items():
        nb = _knn(_embed(name, x), k, rng)
        stat = _loo_sse(r, nb)
        null = np.concatenate([_loo_sse(r[perms[i : i + batch]], nb) for i in range(0, n_perm, batch)])
        sd = max(float(np.std(null)), 1e-300)
        out[name] = {"explained": float(1.0 - stat / total), "z": float((np.mean(null) - stat) / sd)}
    mean = resid.mean(axis=0)
    s = float(np.sum(mean**2 / (np.asarray(sigma) ** 2 / m)))
    out["mean"] = {"offset_mm": mean.tolist(), "z": chi2_z(s, 3)}
    return out


def score_test(
    r_h: np.ndarray,
    J_h: np.ndarray,
    active_cols: np.ndarray,
    cand_cols: np.ndarray,
    sigma: np.ndarray,
    weights: np.ndarray | None = None,
) -> dict:
    """Score (Lagrange-multiplier) test of a candidate on held-out residuals.

    Args:
        r_h: (M, 3) residuals; J_h: (M, 3, P) their sensitivities; active_cols / cand_cols: column
        indices of the fitted and the candidate parameters; sigma: (3,) noise per axis;
        weights: optional (M,) robust weights.
    Returns ``{"score": z, "stat": S, "dof": d, "explained_mm2": r'Pr / M}``.
    """
    w = np.ones(len(r_h)) if weights is None else np.asarray(weights)
    sw = np.sqrt(w)[:, None] / np.asarray(sigma)[None, :]  # whiten per axis
    r = (r_h * sw).ravel()
    Jw = J_h * sw[:, :, None]
    JA = Jw[:, :, active_cols].reshape(-1, len(active_cols))
    JE = Jw[:, :, cand_cols].reshape(-1, len(cand_cols))
    if JA.shape[1]:
        # an orthonormal basis of what the fitted parameters can explain (rank-revealing)
        UA, sA, _ = np.linalg.svd(JA, full_matrices=False)
        QA = UA[:, sA > 1e-8 * max(sA.max(initial=0.0), 1e-300)]
        JE = JE - QA @ (QA.T @ JE)
        r = r - QA @ (QA.T @ r)
    U, s, _ = np.linalg.svd(JE, full_matrices=False)
    rank = int(np.sum(s > 1e-8 * max(s.max(initial=0.0), 1e-300)))
    if rank == 0:
        return {"score": 0.0, "stat": 0.0, "dof": 0, "explained_mm2": 0.0}
    proj = U[:, :rank].T @ r
    stat = float(proj @ proj)
    expl = float(np.sum(((U[:, :rank] @ proj).reshape(-1, 3) * np.asarray(sigma)) ** 2) / len(r_h))
    return {"score": chi2_z(stat, rank), "stat": stat, "dof": rank, "explained_mm2": expl}


def previous_excursion(p, index, centre, back: int) -> np.ndarray:
    """(K, 3) unit directions: for each sample of ``index`` (K,) (at least ``back`` into ``p`` (N, 3),
    mm), the direction from ``centre`` (3,) of the largest excursion of the ``back`` tips before it,
    where a memory of the path would leave the robot."""
    u = np.empty((len(index), 3))
    for j, i in enumerate(index):  # (a few dozen samples: a loop over them, not over poses)
        exc = p[i - back : i] - centre
        e = exc[np.argmax(np.linalg.norm(exc, axis=1))]
        u[j] = e / max(np.linalg.norm(e), 1e-12)
    return u


def home_memory(data: Dataset, home_mm: float = 0.35, back: int = 15) -> dict:
    """Hysteresis against drift, from a recording alone (no model).

    Home samples: every wire within ``home_mm`` (mm) of its zero command, with at least ``back`` samples
    of the same session before them. Their measured tips ``p_i`` (mm) are fitted (linear least squares)
    as ``p_i = c + m u_i + v t_i + e_i``: ``u_i`` the direction (unit, 3-D) of the largest excursion from
    the home tips' median in the ``back`` samples before, ``m`` the memory of the path (mm), ``v`` (3,)
    the drift per unit of ``t`` (minutes where the data have timestamps, else samples), ``c`` (3,) the
    home position. Fitted together, so that a drift is not taken for memory nor the other way round.

    Returns ``n``, ``index`` (K,) the home samples, ``direction`` (K, 3) the ``u_i``, ``spread_mm`` (RMS
    of the home tips about their median), ``along_mm`` (``m``), ``across_mm`` (RMS of ``e``),
    ``drift_mm`` (``v``) per ``time_unit``, their linearised standard deviations ``along_std_mm`` and
    ``drift_std_mm`` (3,) (from the scatter of ``e``), and ``span`` (the recording's length in that unit).
    """
    q, p = np.asarray(data.q, float), np.asarray(data.p, float)
    timed = data.timestamp is not None
    t = (
        (np.asarray(data.timestamp, float) - float(data.timestamp[0])) / 60.0
        if data.timestamp is not None
        else np.arange(len(q), dtype=float)
    )
    session = np.zeros(len(q), int) if data.session is None else np.asarray(data.session)
    start = np.r_[0, np.flatnonzero(np.diff(session)) + 1]  # each session's first sample
    first = start[np.searchsorted(start, np.arange(len(q)), side="right") - 1]
    home = np.flatnonzero((np.abs(q).max(axis=1) < home_mm) & (np.arange(len(q)) - first >= back))
    if len(home) < 8:
        raise ValueError(
            f"{len(home)} home samples (every wire within {home_mm} mm of zero, {back} samples "
            "into a session): too few to tell memory from drift"
        )
    centre = np.median(p[home], axis=0)
    u = previous_excursion(p, home, centre, back)
    # unknowns (c, m, v): 7; rows: 3 per home sample
    K, eye = len(home), np.eye(3)
    A = np.concatenate([np.tile(eye, (K, 1)), u.reshape(-1, 1), np.kron(t[home][:, None], eye)], axis=1)
    sol, *_ = np.linalg.lstsq(A, p[home].reshape(-1), rcond=None)
    e = p[home].reshape(-1) - A @ sol
    std = np.sqrt(np.diag(np.linalg.pinv(A.T @ A)) * (e @ e) / max(A.shape[0] - A.shape[1], 1))
    return {
        "n": K,
        "index": home,
        "direction": u,
        "spread_mm": rmse(p[home] - centre),
        "along_mm": float(sol[3]),
        "along_std_mm": float(std[3]),
        "across_mm": float(np.sqrt(np.mean(e**2) * 3)),
        "drift_mm": sol[4:7],
        "drift_std_mm": std[4:7],
        "time_unit": "minute" if timed else "sample",
        "span": float(t[-1] - t[0]),
    }
