"""The calibration loop: fit the nominal model, diagnose the held-out residual, add effects that help.

1. Fit the nominal parameters on the training part (the first ``1 - holdout`` in acquisition order).
2. Score every candidate effect on the *held-out* residual (:func:`.diagnose.score_test`).
3. Refit the best-scoring significant candidates (up to ``TRIES_PER_ROUND``) on the training part;
   a refit counts when its held-out error drops significantly: the drop of the held-out sum of
   squares, in units of the current residual's per-axis variance (at least the noise variance), must
   exceed the chi-square quantile of the effect's parameter count at ``alpha``, the held-out RMSE
   must fall by at least ``min_gain``, and the drop of the mean square must be at least
   ``min_excess`` of its excess over the noise floor (a real effect explains much of what it
   targets; structure from outside the library lets any flexible effect win a little by chance). Of those, the one with the lowest held-out error is kept
   (effects overlap: a registration explains part of almost anything, the true effect all of it).
   Then a backward step: an earlier effect whose removal no longer raises the held-out error
   significantly (same test) was only standing in for the new one, and is removed.
4. Repeat until no candidate helps; then test the final held-out residual for structure left.
"""

from __future__ import annotations

import dataclasses
import math
import time

import jax
import numpy as np

from .data import Dataset
from .diagnose import chi2_quantile, features, noise_floor, score_test, structure_test
from .effects import LIBRARY, NOMINAL
from .forward import SegmentModel
from .model import Problem, parameter_std

#: Structure left is claimed when a feature's permutation z-value (or the offset's) exceeds this.
STRUCTURE_Z = 4.0
#: ... or when the held-out RMSE exceeds the noise floor by this factor with an F-type z > STRUCTURE_Z.
EXCESS_RATIO = 1.15
#: Significant candidates refitted per round (best scores first); the lowest held-out error wins.
TRIES_PER_ROUND = 4


@dataclasses.dataclass
class Result:
    """Everything the report needs. ``theta_*`` are full parameter vectors of ``problem``."""

    problem: Problem
    train: np.ndarray
    held: np.ndarray
    noise: dict
    theta_declared: np.ndarray
    theta_before: np.ndarray
    theta_after: np.ndarray
    std_after: np.ndarray
    active: list
    effects: list
    candidates: list
    rounds: list
    structure: dict
    rmse: dict
    unexplained_structure: bool
    robust: bool
    seconds: float
    nominal: list = dataclasses.field(default_factory=list)

    def to_json(self) -> dict:
        """The ``report.json`` content (keys of issue 6, plus the evidence)."""
        pb = self.problem
        return {
            "data": pb.data.source,
            "n_samples": pb.data.n_samples,
            "n_train": int(self.train.sum()),
            "n_held_out": int(self.held.sum()),
            "dropped_rows": len(pb.data.dropped),
            "dropped": list(pb.data.dropped),
            "robust": self.robust,
            "rmse_declared_mm": self.rmse["declared"],
            "rmse_before_mm": self.rmse["before"],
            "rmse_after_mm": self.rmse["after"],
            "rmse_train_after_mm": self.rmse["train_after"],
            "noise_floor_mm": self.noise["floor_mm"],
            "noise": self.noise,
            "nominal_parameters": list(self.nominal),
            "effects": self.effects,
            "candidates": self.candidates,
            "rounds": self.rounds,
            "unexplained_structure": self.unexplained_structure,
            "structure": self.structure,
            "parameters": {**final_parameters(pb, self.theta_after, self.active),
                           "std": pb.describe_std(self.theta_after, self.active, self.std_after)},
            "seconds": self.seconds,
        }


def final_parameters(pb: Problem, theta, active) -> dict:
    """The physical parameters after every fitted effect, plus each fitted block in report units."""
    parts = pb.spec.slices()
    phys = pb.phys0
    for b in pb.spec.blocks:
        phys = b.on_params(np.asarray(theta)[parts[b.name]], phys)
    phys = jax.tree_util.tree_map(lambda x: np.asarray(x).tolist(), phys)
    if "wire_angles" in phys:
        phys["wire_angles_deg"] = np.degrees(phys.pop("wire_angles")).tolist()
    return {"physical": phys, "fitted": pb.describe(theta, active)}


def _rmse(r, mask) -> float:
    return float(np.sqrt(np.mean(np.sum(r[mask] ** 2, axis=1))))


def calibrate(data: Dataset, design, model=None, library=LIBRARY, nominal=NOMINAL,
              holdout: float = 0.25, robust: bool = False, alpha: float = 1e-3,
              min_gain: float = 0.01, min_excess: float = 0.25, max_rounds: int | None = None,
              log=None) -> Result:
    """Run the loop on one measurement set. ``log`` (callable taking a str) reports progress."""
    t0 = time.perf_counter()
    say = log or (lambda s: None)
    model = model or SegmentModel(data.n_wires)
    pb = Problem(model, design, data, tuple(nominal) + tuple(library))
    train, held = data.split(holdout)
    w_train = train.astype(float)
    cand_names = [b.name for b in library]
    nominal_names = [b.name for b in nominal]
    sl = pb.spec.slices()

    theta_decl = pb.null.copy()
    r_decl = pb.residuals(theta_decl)
    try:
        noise = noise_floor(data)
    except ValueError:
        noise = None
    sigma = None if noise is None else np.asarray(noise["sigma_mm"])

    def fit(theta0, active):
        if not robust:
            return pb.fit(theta0, active, w_train)
        th = theta0
        for _ in range(2):  # the Huber threshold follows the residual's scale (3.5 noise sigmas at least)
            r = pb.residuals(th)[train]
            scale = np.median(np.linalg.norm(r, axis=1)) / 1.54  # median of a 3-D chi is 1.54 sigma
            c = max(2.5 * scale, 3.5 * (float(np.mean(sigma)) if sigma is not None else scale))
            th = pb.fit(th, active, w_train, huber_c=c)
        return th

    def held_error(theta):
        """(plain RMSE, the error used for decisions, residuals): robust mode ignores glitches."""
        r = pb.residuals(theta)
        plain = _rmse(r, held)
        if not robust:
            return plain, plain, r
        kept = _glitch_weights(r[held], sigma) > 0
        n = np.linalg.norm(r[held], axis=1)
        return plain, float(np.sqrt(np.mean(n[kept] ** 2))), r

    active = list(nominal_names)
    theta = fit(theta_decl, active)
    theta_before = theta.copy()
    if noise is None:
        noise = noise_floor(data, pb.residuals(theta))
        sigma = np.asarray(noise["sigma_mm"])
    sigma = np.maximum(sigma, 1e-9)
    rmse_before, err, r = held_error(theta)
    say(f"declared {_rmse(r_decl, held):.4f} mm, nominal fit {rmse_before:.4f} mm, "
        f"noise floor {noise['floor_mm']:.4f} mm")
    effects, candidates, rounds = [], [], []
    rnd = 0
    max_rounds = 2 * len(cand_names) if max_rounds is None else max_rounds  # add/remove cannot cycle
    while rnd < max_rounds:
        rnd += 1
        remaining = [n for n in cand_names if n not in active]
        if not remaining:
            break
        r, J = pb.jacobian(theta)
        active_cols = np.concatenate([np.arange(pb.null.size)[sl[n]] for n in active])
        wts = None
        if robust:
            wts = _glitch_weights(r[held], sigma)
        scores = []
        for name in remaining:
            s = score_test(r[held], J[held], active_cols, np.arange(pb.null.size)[sl[name]], sigma, wts)
            scores.append({"round": rnd, "name": name, "score": s["score"], "dof": s["dof"],
                           "explained_rmse_mm": math.sqrt(max(s["explained_mm2"], 0.0))})
        scores.sort(key=lambda d: -d["score"])
        candidates.extend(scores)
        z_crit = _z_crit(alpha / max(len(remaining), 1))
        say(f"round {rnd}: " + ", ".join(f"{s['name']} {s['score']:.1f}" for s in scores))
        tried = []
        for s in [s for s in scores if s["score"] > z_crit][:TRIES_PER_ROUND]:
            th0 = theta.copy()
            th0[sl[s["name"]]] = pb.null[sl[s["name"]]]
            th_new = fit(th0, active + [s["name"]])
            plain_new, err_new, _ = held_error(th_new)
            m = int(held.sum())
            # held-out SSE drop in units of the per-axis variance of the current residual (at least
            # the noise): structure the model lacks must not make a chance improvement look significant
            unit = max(float(np.mean(sigma**2)), err**2 / 3.0)
            drop = (err**2 - err_new**2) * m / unit
            need = chi2_quantile(alpha, max(s["dof"], 1))
            # and it must explain a fair share of the error above the noise floor: structure from outside
            # the library lets any flexible effect win a little by chance, a real effect wins much
            excess = max(err**2 - noise["floor_mm"] ** 2, 0.0)
            ok = (drop > need and err_new < (1.0 - min_gain) * err
                  and err**2 - err_new**2 >= min_excess * excess)
            tried.append({"name": s["name"], "rmse_held_out_mm": plain_new, "sse_drop": drop,
                          "needed": need, "significant": bool(ok), "theta": th_new, "err": err_new,
                          "score": s["score"]})
            say(f"  refit {s['name']}: held-out {plain_new:.4f} mm (drop {drop:.1f}, needed {need:.1f})"
                f"{' significant' if ok else ''}")
        good = [t for t in tried if t["significant"]]
        accepted = min(good, key=lambda t: t["err"]) if good else None
        if accepted is not None:
            theta, err = accepted["theta"], accepted["err"]
            active.append(accepted["name"])
            effects.append({"name": accepted["name"],
                            "params": pb.describe(theta, [accepted["name"]])[accepted["name"]],
                            "rmse_after_mm": accepted["rmse_held_out_mm"], "score": accepted["score"]})
            say(f"  kept {accepted['name']}")
        for t in tried:
            t.pop("theta"), t.pop("err"), t.pop("score")
            t["accepted"] = accepted is not None and t["name"] == accepted["name"]
        accepted = None if accepted is None else accepted["name"]
        removed = []
        if accepted is not None:
            # backward step: an earlier effect that only stood in for the one just added goes
            for e in [e for e in effects if e["name"] != accepted]:
                th0 = theta.copy()
                th0[sl[e["name"]]] = pb.null[sl[e["name"]]]
                rest = [a for a in active if a != e["name"]]
                th_wo = fit(th0, rest)
                plain_wo, err_wo, _ = held_error(th_wo)
                unit = max(float(np.mean(sigma**2)), err**2 / 3.0)
                rise = (err_wo**2 - err**2) * int(held.sum()) / unit
                need = chi2_quantile(alpha, int(sl[e["name"]].stop - sl[e["name"]].start))
                say(f"  without {e['name']}: held-out {plain_wo:.4f} mm (rise {rise:.1f}, needed {need:.1f})")
                if rise < need:
                    theta, err, active = th_wo, err_wo, rest
                    effects = [x for x in effects if x["name"] != e["name"]]
                    removed.append({"name": e["name"], "rmse_held_out_mm": plain_wo, "sse_rise": rise,
                                    "needed": need})
                    say(f"  removed {e['name']}")
                    break
        rounds.append({"round": rnd, "z_critical": z_crit, "tried": tried, "accepted": accepted,
                       "removed": removed})
        if accepted is None:
            break

    # effect parameters as finally fitted (later effects refit earlier ones), with linearised deviations
    r_after, J_after = pb.jacobian(theta)
    std = parameter_std(J_after, r_after, pb.mask(active), w_train)
    for e in effects:
        e["params"] = pb.describe(theta, [e["name"]])[e["name"]]
        e["params_std"] = pb.describe_std(theta, [e["name"]], std)[e["name"]]
    feats = features(data, pb.predict(theta_decl))
    held_feats = {k: v[held] for k, v in feats.items()}
    structure = structure_test(r_after[held], held_feats, sigma)
    m = int(held.sum())
    plain_after, err_after, _ = held_error(theta)
    # the held-out mean square against the noise estimate: an F-type comparison, since the floor is
    # itself estimated (from noise["pairs"] pairs of three axes) and can be off by chance
    log_ratio = math.log(err_after**2 / (noise["floor_mm"] ** 2))
    sd = math.sqrt(2.0 / (3 * m) + 2.0 / (3 * max(noise["pairs"], 1)))
    excess = {"ratio_to_floor": plain_after / noise["floor_mm"], "z": log_ratio / sd}
    structure["excess_over_noise"] = excess
    unexplained = bool(
        any(v["z"] > STRUCTURE_Z for k, v in structure.items() if k != "excess_over_noise")
        or (excess["ratio_to_floor"] > EXCESS_RATIO and excess["z"] > STRUCTURE_Z)
    )
    rmse = {"declared": _rmse(r_decl, held), "before": rmse_before, "after": plain_after,
            "train_after": _rmse(r_after, train)}
    return Result(problem=pb, train=train, held=held, noise=noise, theta_declared=theta_decl,
                  theta_before=theta_before, theta_after=theta, std_after=std, active=active, effects=effects,
                  candidates=candidates, rounds=rounds, structure=structure, rmse=rmse,
                  unexplained_structure=unexplained, robust=robust,
                  seconds=time.perf_counter() - t0, nominal=nominal_names)


#: In robust mode a held-out sample beyond this many noise sigmas (3-D) is a glitch for decisions.
GLITCH_C = 8.0


def _glitch_weights(r, sigma):
    n = np.linalg.norm(r, axis=1)
    c = max(GLITCH_C * float(np.mean(sigma)), 5.0 * float(np.median(n)))
    return np.where(n <= c, 1.0, 0.0)


def _z_crit(p: float) -> float:
    from .diagnose import _norm_isf

    return _norm_isf(p)

