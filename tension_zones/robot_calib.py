"""Calibrating a multi-segment robot from OpenCR recordings, with a validation file (issue 8).

The effect loop is :func:`robot_fit.forward_selection`: the training file's pattern groups are split
(every 4th group held out, :func:`robot_fit.group_holdout`); effects are tried in the candidate order
and kept only where the held-out RMSE on *training* data drops by more than ``min_gain``. The
validation file is never used for a decision: each accepted model (fitted on the training groups
only) is evaluated on it once, after the selection. Black-box baselines (k-nearest neighbours,
polynomial ridge; scikit-learn) choose their hyper-parameters on the same held-out training groups,
are refitted on all of the training file and evaluated on the validation file.

The report has the keys of the issue-6 report where they make sense (all held-out training RMSEs),
plus ``rmse_validate_mm`` and ``rmse_validate_aligned_mm`` (mean offset removed: the metric the
recording lab reports) and the validation error before and after each effect.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from . import robot_fit as rf
from .calibration.diagnose import GLITCH_SIGMAS, structure_test
from .model._robot import Robot
from .opencr import OpenCRData

#: Candidate effects, in the order they are tried (gravity last: its equilibrium needs the Hessian
#: of the chained pose, slow to compile): the order of ``benchmarks/ftdcr_v4.py``.
CANDIDATES = ("tendon_angles", "pretension", "slack", "hysteresis", "stiffness", "registration",
              "geometry", "gravity")
#: Relative held-out RMSE drop an effect must bring to be kept.
MIN_GAIN = 0.02
#: Structure left is claimed when a feature's permutation z-value (or the offset's) exceeds this,
#: or when the held-out RMSE exceeds the noise floor by ``EXCESS_RATIO``.
STRUCTURE_Z = 4.0
EXCESS_RATIO = 1.15
#: A parameter within this fraction of its range from a bound is flagged ``at_bound``.
BOUND_TOL = 0.01


# --------------------------------------------------------------------------------------------
# Diagnostics (NumPy, after the jitted model has run)
# --------------------------------------------------------------------------------------------
def noise_floor(data: OpenCRData) -> dict:
    """3-D noise RMSE from consecutive samples with the same command (the hold phases): their
    difference is tracker noise plus whatever the robot does at a constant command (creep), so the
    floor is an upper bound of the noise. ``floor_mm`` is None with fewer than 10 such pairs."""
    same = np.all(np.abs(np.diff(data.q, axis=0)) < 1e-9, axis=1)
    if same.sum() < 10:
        return {"floor_mm": None, "sigma_mm": None, "pairs": int(same.sum()),
                "method": f"not estimated: {int(same.sum())} pairs of consecutive samples with the same "
                          "command (10 needed), so tracker noise cannot be told from model error"}
    d = np.diff(data.p, axis=0)[same] / math.sqrt(2.0)
    mad = 1.4826 * np.median(np.abs(d), axis=0)
    keep = np.all(np.abs(d) <= GLITCH_SIGMAS * np.maximum(mad, 1e-12), axis=1)
    sig = np.sqrt(np.mean(d[keep] ** 2, axis=0))
    return {"floor_mm": float(np.sqrt(np.sum(sig**2))), "sigma_mm": sig.tolist(), "pairs": int(keep.sum()),
            "method": "consecutive samples with the same command (hold phases; includes creep)"}


def features(pred: np.ndarray) -> dict:
    """Inputs to look for structure in: bending direction and lateral offset of the predicted tip,
    direction of its last motion relative to the bending direction, and the sample order."""
    xy = pred[:, :2]
    direction = np.arctan2(xy[:, 1], xy[:, 0])
    step = np.diff(xy, axis=0, prepend=xy[:1])
    moving = np.linalg.norm(step, axis=1) > 1e-9
    idx = np.maximum.accumulate(np.where(moving, np.arange(len(step)), 0))
    motion = np.arctan2(step[idx, 1], step[idx, 0])
    rel = np.where(moving[idx], np.angle(np.exp(1j * (motion - direction))), 0.0)
    return {"bending_direction": direction, "bending": np.linalg.norm(xy, axis=1), "motion": rel,
            "order": np.arange(len(pred), dtype=float)}


def structure(resid: np.ndarray, pred: np.ndarray, noise: dict, rmse_held: float) -> tuple[bool, dict]:
    """Is the held-out residual still predictable from the inputs beyond noise?"""
    sigma = noise["sigma_mm"] or np.std(resid, axis=0)  # no floor: the offset test on the spread
    st = structure_test(resid, features(pred), np.asarray(sigma), n_perm=300)
    zs = [v["z"] for v in st.values()]
    excess = noise["floor_mm"] is not None and rmse_held > EXCESS_RATIO * noise["floor_mm"]
    st["excess_over_noise"] = {"ratio_to_floor": (rmse_held / noise["floor_mm"]
                                                  if noise["floor_mm"] else None), "flag": bool(excess)}
    return bool(max(zs) > STRUCTURE_Z or excess), st


# --------------------------------------------------------------------------------------------
# Parameters in report units
# --------------------------------------------------------------------------------------------
def _unit(block: rf.Param) -> tuple[float, str]:
    return (180.0 / np.pi, "deg") if block.unit == "rad" else (1.0, block.unit)


def describe(res: rf.FitResult) -> dict:
    """``{name: {value, std, unit, lo, hi, at_bound}}`` in report units (angles in degrees)."""
    out = {}
    for k, v in res.params.items():
        b = res.blocks[k]
        s, unit = _unit(b)
        v = np.ravel(v)
        tol = BOUND_TOL * (b.hi - b.lo)
        at = (v <= b.lo + tol) | (v >= b.hi - tol)
        out[k] = {"value": (v * s).tolist(), "std": (np.ravel(res.std[k]) * s).tolist(), "unit": unit,
                  "lo": b.lo * s, "hi": b.hi * s, "at_bound": at.tolist()}
    return out


def correlations(robot: Robot, res: rf.FitResult, Q, P, idx, top: int = 5) -> dict:
    """Identifiability: parameter correlations from the Gauss-Newton covariance ``(J'J)^-1`` (``J``
    the Jacobian of the fitted positions in physical parameters). ``max_abs`` near 1 means a pair
    trades off freely; ``pairs`` are the ``top`` largest ``|corr|`` with their parameter names."""
    import jax
    import jax.numpy as jnp

    names = [f"{k}[{i}]" for k, v in res.params.items() for i in range(np.size(v))]
    shapes = {k: np.shape(v) for k, v in res.params.items()}
    x0 = np.concatenate([np.ravel(v) for v in res.params.values()])

    def unflat(x):
        out, i = {}, 0
        for k, sh in shapes.items():
            n = int(np.prod(sh))
            out[k] = x[i:i + n].reshape(sh)
            i += n
        return out

    Qj, ix = jnp.asarray(Q, float), np.asarray(idx)
    J = np.asarray(jax.jacfwd(lambda x: rf.predict(robot, unflat(x), Qj)[ix].ravel())(jnp.asarray(x0)))
    A = J.T @ J
    cov = np.linalg.pinv(A + 1e-14 * np.trace(A) / len(A) * np.eye(len(A)))
    d = np.sqrt(np.maximum(np.diag(cov), 1e-300))
    C = cov / np.outer(d, d)
    iu = np.triu_indices(len(C), 1)
    order = np.argsort(-np.abs(C[iu]))[:top]
    pairs = [{"a": names[iu[0][o]], "b": names[iu[1][o]], "corr": float(C[iu][o])} for o in order]
    return {"max_abs": float(np.abs(C[iu]).max()) if len(iu[0]) else 0.0, "pairs": pairs}


def params_from_report(report: dict) -> dict:
    """The final model's parameters (model units, for ``robot_fit.predict``) from a report."""
    return {k: np.asarray(d["value"]) * (np.pi / 180.0 if d["unit"] == "deg" else 1.0)
            for k, d in report["parameters"].items()}


def _effect_params(res: rf.FitResult, effect: str, robot: Robot) -> dict:
    names = rf._effect_params(robot)[effect]
    d = describe(res)
    return {k: d[k]["value"] for k in names}, {k: d[k]["std"] for k in names}


# --------------------------------------------------------------------------------------------
# Black-box baselines
# --------------------------------------------------------------------------------------------
def baselines(train: OpenCRData, val: OpenCRData) -> dict | None:
    """k-NN and polynomial ridge on the commanded displacements (None without scikit-learn);
    hyper-parameters chosen on the held-out training groups, then refitted on all of train."""
    try:
        from sklearn.linear_model import Ridge
        from sklearn.neighbors import KNeighborsRegressor
        from sklearn.pipeline import make_pipeline
        from sklearn.preprocessing import PolynomialFeatures, StandardScaler
    except ImportError:
        return None
    fit_idx, held_idx = rf.group_holdout(train.patterns)
    grids = {
        "knn": [(f"k={k}", lambda k=k: KNeighborsRegressor(min(k, len(fit_idx)), weights="distance"))
                for k in (1, 3, 5, 10, 20)],
        "poly_ridge": [(f"degree={d}, alpha={a:g}",
                        lambda d=d, a=a: make_pipeline(StandardScaler(), PolynomialFeatures(d), Ridge(alpha=a)))
                       for d in (1, 2, 3, 4) for a in (1e-3, 1e-1, 10.0)],
    }
    out = {}
    for name, grid in grids.items():
        scores = [(rf.rmse(make().fit(train.q[fit_idx], train.p[fit_idx]).predict(train.q[held_idx]),
                           train.p[held_idx]), label, make) for label, make in grid]
        h, label, make = min(scores, key=lambda s: s[0])
        pv = make().fit(train.q, train.p).predict(val.q)
        out[name] = {"choice": label, "rmse_held_out_mm": h, "rmse_validate_mm": rf.rmse(pv, val.p),
                     "rmse_validate_aligned_mm": rf.rmse_aligned(pv, val.p), "predicted": pv}
    return out


# --------------------------------------------------------------------------------------------
# The loop
# --------------------------------------------------------------------------------------------
def _rounds(history: list, candidates) -> list[list]:
    """History rows (after ``base``) split into the passes of ``forward_selection``: the first
    pass tries every candidate once, each later pass the ones still dropped."""
    rows, out, todo = history[1:], [], list(candidates)
    while rows:
        out.append(rows[: len(todo)])
        rows = rows[len(todo):]
        todo = [r["effect"] for r in out[-1] if not r["kept"]]
    return out


def calibrate_robot(robot: Robot, train: OpenCRData, val: OpenCRData | None = None,
                    candidates=CANDIDATES, min_gain: float = MIN_GAIN, log=None) -> dict:
    """Run the effect loop on ``train`` and evaluate on ``val``; returns the report dict (the
    arrays for the plots under ``"_arrays"``)."""
    t0 = time.perf_counter()
    say = log or (lambda s: None)
    Q, P = train.q, train.p
    fit_idx, held_idx = rf.group_holdout(train.patterns)
    if len(held_idx) == 0 or len(fit_idx) == 0:
        raise ValueError(f"{len(set(train.patterns))} pattern group(s) in the training file: at least "
                         "4 are needed to hold out every 4th")
    a0 = rf.initial_segment_angles(robot, Q, P, train.labels)
    zero = {"segment_angle": np.zeros(robot.n_segments), "offset": np.zeros(3)}
    held = lambda pred: rf.rmse(pred[held_idx], P[held_idx])  # noqa: E731
    rmse_declared = held(np.asarray(rf.predict(robot, zero, Q)))
    say(f"declared design: held-out {rmse_declared:.3f} mm; trying {', '.join(candidates)}")
    _, hist = rf.forward_selection(robot, Q, P, train.patterns, list(candidates), min_gain=min_gain,
                                   init={"segment_angle": a0}, verbose=log is not None)

    def on_val(res):
        if val is None:
            return None, None, None
        pv = np.asarray(rf.predict(robot, res.params, val.q))
        return rf.rmse(pv, val.p), rf.rmse_aligned(pv, val.p), pv

    base = hist[0]
    last = on_val(base["fit"])  # (rmse, aligned, predicted) of the model of the moment on val
    steps = [{"name": "base", "rmse_held_out_mm": base["rmse_holdout_mm"], "rmse_validate_mm": last[0],
              "rmse_validate_aligned_mm": last[1]}]
    effects, candidates_out, rounds = [], [], []
    best, final = base["rmse_holdout_mm"], base["fit"]
    for rnd, rows in enumerate(_rounds(hist, candidates), start=1):
        tried = []
        for r in rows:
            score = best - r["rmse_holdout_mm"]  # held-out RMSE drop against the model of the moment
            candidates_out.append({"round": rnd, "name": r["effect"], "score": score})
            tried.append({"name": r["effect"], "rmse_held_out_mm": r["rmse_holdout_mm"], "kept": r["kept"]})
            if r["kept"]:
                best, final = r["rmse_holdout_mm"], r["fit"]
                last = on_val(final)
                v, va = last[:2]
                vals, stds = _effect_params(final, r["effect"], robot)
                effects.append({"name": r["effect"], "params": vals, "params_std": stds,
                                "rmse_after_mm": best, "rmse_validate_mm": v,
                                "rmse_validate_aligned_mm": va})
                steps.append({"name": r["effect"], "rmse_held_out_mm": best, "rmse_validate_mm": v,
                              "rmse_validate_aligned_mm": va})
        rounds.append({"round": rnd, "tried": tried})
    pred_tr = np.asarray(rf.predict(robot, final.params, Q))
    noise = noise_floor(train)
    resid = P[held_idx] - pred_tr[held_idx]
    unexplained, st = structure(resid, pred_tr[held_idx], noise, best)
    say("parameter correlations of the final model")
    corr = correlations(robot, final, Q, P, fit_idx)
    v, va, pv = last
    report = {
        "n_samples": len(train), "n_train": len(fit_idx), "n_held_out": len(held_idx),
        "holdout": "every 4th pattern group of the training file (in order of first appearance, "
                   "from the 4th); the validation file is only evaluated on",
        "held_out_groups": sorted(set(np.asarray(train.patterns, dtype=object)[held_idx])),
        "rmse_declared_mm": rmse_declared,
        "rmse_before_mm": base["rmse_holdout_mm"],
        "rmse_after_mm": best,
        "rmse_train_after_mm": final.rmse_fit_mm,
        "effects": effects,
        "candidates": candidates_out,
        "rounds": rounds,
        "min_gain": min_gain,
        "noise_floor_mm": noise["floor_mm"],
        "noise": noise,
        "unexplained_structure": unexplained,
        "structure": st,
        "parameters": describe(final),
        "correlations": corr,
        "initial_segment_angle_deg": np.degrees(a0).tolist(),
        "steps": steps,
    }
    if val is not None:
        report.update({"n_validate": len(val), "rmse_validate_mm": v, "rmse_validate_aligned_mm": va})
        bl = baselines(train, val)
        report["baselines"] = ({k: {kk: vv for kk, vv in b.items() if kk != "predicted"} for k, b in bl.items()}
                               if bl else None)
        report["_arrays"] = {"val_measured": val.p, "val_predicted": pv,
                             "val_baselines": {k: b["predicted"] for k, b in (bl or {}).items()}}
    report["seconds"] = time.perf_counter() - t0
    return report


# --------------------------------------------------------------------------------------------
# report.json, report.md and the plot
# --------------------------------------------------------------------------------------------
PLOT = "val_tip_paths.png"


def plot_val_paths(report: dict, path: Path) -> Path:
    """Measured vs predicted tip paths on the validation file: top view and x, y, z over samples."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    a = report["_arrays"]
    m, p = np.asarray(a["val_measured"]), np.asarray(a["val_predicted"])
    best = min(report["baselines"].items(), key=lambda kv: kv[1]["rmse_validate_mm"]) if report.get(
        "baselines") else None
    fig = plt.figure(figsize=(13, 6.5))
    ax = fig.add_subplot(1, 2, 1)
    ax.plot(m[:, 0], m[:, 1], ".-", color="k", lw=0.6, ms=2.5, label="measured")
    ax.plot(p[:, 0], p[:, 1], ".-", color="C3", lw=0.6, ms=2.5,
            label=f"model ({report['rmse_validate_mm']:.2f} mm RMSE)")
    if best:
        bp = np.asarray(a["val_baselines"][best[0]])
        ax.plot(bp[:, 0], bp[:, 1], "-", color="C0", lw=0.5, alpha=0.6,
                label=f"{best[0]} baseline ({best[1]['rmse_validate_mm']:.2f} mm)")
    ax.set_aspect("equal")
    ax.set_xlabel("tip x (mm)")
    ax.set_ylabel("tip y (mm)")
    ax.set_title("validation file, top view")
    ax.legend(fontsize=8, loc="best")
    for i, c in enumerate("xyz"):
        axi = fig.add_subplot(3, 2, 2 * i + 2)
        axi.plot(m[:, i], color="k", lw=0.8, label="measured")
        axi.plot(p[:, i], color="C3", lw=0.8, label="model")
        axi.set_ylabel(f"tip {c} (mm)")
        if i == 2:
            axi.set_xlabel("validation sample")
        if i == 0:
            axi.legend(fontsize=8, loc="upper right")
            axi.set_title("measured vs predicted, in acquisition order")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _f(x, nd=2):
    return "-" if x is None else f"{x:.{nd}f}"


def _vals(values, stds, unit) -> str:
    return ", ".join(f"{v:.3g} +- {s:.2g}" for v, s in zip(values, stds)) + (f" {unit}" if unit else "")


def markdown(report: dict) -> str:
    lines = [f"# Calibration report: `{Path(report['data']).name}`", ""]
    lines += [f"{report['n_samples']} training samples: {report['n_train']} fitted, {report['n_held_out']} held out "
              f"({report['holdout']}). Validation: "
              + (f"`{Path(report['validate']).name}`, {report['n_validate']} samples." if report.get("validate")
                 else "none.") + f" Design: `{Path(report['design']).name}`.", ""]
    lines += ["## Before and after (tip-position RMSE, mm)", "",
              "Each model is fitted on the training groups only; `validate` is evaluated after the selection.", "",
              "| model | held-out train | validate | validate, mean offset removed |", "| --- | ---: | ---: | ---: |",
              f"| declared design, nothing fitted | {_f(report['rmse_declared_mm'])} | | |"]
    acc = []
    for s in report["steps"]:
        acc.append(s["name"])
        name = "base (segment angles, offset)" if s["name"] == "base" else "+ " + " + ".join(acc[1:])
        lines.append(f"| {name} | {_f(s['rmse_held_out_mm'])} | {_f(s.get('rmse_validate_mm'))} | "
                     f"{_f(s.get('rmse_validate_aligned_mm'))} |")
    nf = report["noise_floor_mm"]
    lines += [f"| noise floor ({report['noise']['method']}) | {_f(nf, 3)} | | |", ""]
    if report.get("baselines"):
        lines += ["## Black-box baselines (trained on the same training file)", "",
                  "| baseline | chosen on held-out groups | held-out train | validate | validate aligned |",
                  "| --- | --- | ---: | ---: | ---: |"]
        for k, b in report["baselines"].items():
            lines.append(f"| {k} | {b['choice']} | {_f(b['rmse_held_out_mm'])} | {_f(b['rmse_validate_mm'])} | "
                         f"{_f(b['rmse_validate_aligned_mm'])} |")
        lines.append("")
    lines += [("## Effects tried (score = held-out RMSE drop, mm; kept above "
               f"{100 * report['min_gain']:.0f} %)"), ""]
    for rd in report["rounds"]:
        sc = [c for c in report["candidates"] if c["round"] == rd["round"]]
        lines.append(f"- pass {rd['round']}: " + ", ".join(
            f"{c['name']} {c['score']:+.2f}" + (" (kept)" if t["kept"] else "")
            for c, t in zip(sc, rd["tried"])))
    lines += ["", "## Final parameters (value +- linearised std)", "",
              "| parameter | values | bounds |", "| --- | --- | --- |"]
    for k, d in report["parameters"].items():
        flag = " **at a bound**" if any(d["at_bound"]) else ""
        lines.append(f"| {k} | {_vals(d['value'], d['std'], d['unit'])}{flag} | [{d['lo']:.3g}, {d['hi']:.3g}] |")
    c = report["correlations"]
    lines += ["", "Largest parameter correlations (Gauss-Newton; near 1 = a pair trades off freely): "
              + ", ".join(f"{p['a']} / {p['b']} {p['corr']:+.2f}" for p in c["pairs"]) + "."]
    lines += ["", f"Unexplained structure left in the held-out residual: "
              f"**{'yes' if report['unexplained_structure'] else 'no'}** "
              f"(z > {STRUCTURE_Z:g} against an input, or RMSE > {EXCESS_RATIO} x noise floor): "
              + ", ".join(f"{k} z = {v['z']:.1f}" for k, v in report["structure"].items() if "z" in v) + ".", ""]
    if report.get("plots"):
        lines += ["## Validation paths", ""] + [f"![{p}]({p})" for p in report["plots"]]
    return "\n".join(lines) + "\n"


def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return x


def write_report(report: dict, out_dir) -> dict:
    """``report.json``, ``report.md`` and (with a validation file) the tip-path plot."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report = dict(report)
    report["plots"] = [plot_val_paths(report, out / PLOT).name] if "_arrays" in report else []
    report.pop("_arrays", None)
    report = _jsonable(report)
    (out / "report.json").write_text(json.dumps(report, indent=1))
    (out / "report.md").write_text(markdown(report))
    return report
