"""The calibration loop: fit the nominal model, trace the held-out residual to an effect, add it, repeat.

For any robot (one segment or many) and any reader:

1. Split the data (:meth:`Dataset.split`: the tail of the acquisition order, or whole pattern groups
   for labelled recordings). Fit the nominal parameters on the training part.
2. Score every candidate effect on the *held-out* residual (:func:`._diagnose.score_test`: the
   residual projected on the effect's parameter sensitivities, after what the fitted parameters can
   explain; a z-value).
3. Refit the significant candidates on the training part (where more than ``TRIES_PER_ROUND`` are
   significant, or the rod's is one of several, a short refit of each first, then full refits of the
   best of those whose short refit lowered the held-out error by a quarter of the drop the refit
   needs);
   a refit counts when its held-out error drops significantly: the drop of the held-out sum of
   squares, in units of the current residual's per-axis variance (at least the noise variance), must
   exceed the chi-square quantile of the effect's parameter count at ``alpha``, the held-out RMSE
   must fall by at least ``min_gain``, the drop of the mean square must be a fair share of its excess
   over the noise floor (``min_excess`` near the noise floor, less far above it: see
   ``EXCESS_SCALE``), and the training part must gain significantly too (the same chi-square test on
   its sum of squares: an effect that barely improves the part it was fitted on but happens to
   improve the held-out part explains a coincidence, not the robot). Of those, the
   one with the lowest held-out error is kept (effects overlap: a registration explains
   part of almost anything, the true effect all of it), unless a special case of it passed too
   (``Effect.special_case_of``: a per-segment pretension of the per-wire preload) and the larger's
   drop over it is short of the chi-square quantile of its extra parameters: then the special case
   (nested models; the extra parameters fit noise). Then a backward step: an earlier effect
   whose removal no longer raises the held-out error significantly (same test) was only standing in
   for the new one, and is removed.
4. Repeat until no candidate helps (where no score is significant but the held-out error is more
   than ``EXCESS_RATIO`` times the noise floor and its residual is not noise, every positive score gets a
   second look: short refits, then the tests above, with at least ``SECOND_LOOK_SHARE`` of the excess to
   explain: a score is first order); test the final held-out residual for structure left. Where it
   has structure left and a round kept one of two refits the test cannot tell apart (held-out sums
   of squares within the chi-square quantile of one parameter), a *look-ahead*: the loop goes on
   from that round's runner-up (the earliest such round's) as well; that branch is given up as soon
   as its held-out error is above the first branch's after the same round, and kept if it ends with
   a held-out sum of squares lower by more than that quantile. Where it ends more than
   ``EXCESS_SCALE`` noise floors above the floor with structure left, and its last round kept nothing
   though a refit passed every test but the share, a *joint look*: the loop goes on from that refit
   with refits that need no share of their own (every other test stands), and keeps what that path
   adds only if together it explains the share one effect would need there (``_share_needed``), with
   a significant drop for all its parameters. Far above the floor the excess is the sum of many
   missing effects, and several small real ones can each fall short of the share (on FTDCR v4 the
   wires' drift, the geometry and the routing twist, one after the other; together they pass, and the
   error falls with them). Report the
   error before and after. A validation file is only predicted, after every decision: its samples
   ride along in the same compiled program (a second recording, weight zero) and are never looked at
   before the selection is over.
5. Refit the chosen model on every sample of the data file, the held-out part too (the hold-out has
   made its decisions; what it was kept out for is done, as in cross-validation's final refit): the
   reported parameters, their deviations and the prediction of a validation file are this fit's, the
   held-out errors and the structure test the training part's fit's, which never saw those samples.
   Where a validation file is given, every accepted model of the effect-by-effect steps is refitted
   so too (on FTDCR v4 the same effects are chosen and the validation error is lower). Where the
   loop's fits run on their own rows (large recordings:
   :meth:`Problem._fit_rows`), this refit has more rows and runs one more program.

The fits of one step that do not depend on each other (a round's short and full refits, the backward
step's, the final ones) run on worker processes too where there are spare cores (:mod:`._fits`); the
decisions read their results in the same order, so the report is the same.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time
from collections.abc import Callable
from typing import NamedTuple

import jax
import numpy as np

from ..model import Design, Robot
from ._baselines import baselines
from ._caveats import bound_lines, caveats, knife_edges
from ._data import Dataset, check_validation, pattern_family
from ._diagnose import _norm_isf, chi2_quantile, features, noise_floor, score_test, structure_test
from ._fits import Fits, Runner, glitch_weights, rmse, worker_count
from ._model import RobotModel, data_clock
from ._problem import Problem, correlations, parameter_std, physical
from ._register import GlobalRegistration, global_registration, kabsch, rotation_vector
from ._rounds import Added, BranchEnd, JointLook, LookAhead, Nested, Refit, Removal, Round, Score
from .effects import library as default_library
from .effects import nominal as default_nominal

#: Structure left is claimed when a feature's permutation z-value (or the offset's) exceeds this.
STRUCTURE_Z = 4.0
#: ... or when the held-out RMSE exceeds the noise floor by this factor with an F-type z > STRUCTURE_Z:
#: between where the generator's complete models end and where its sets with a tracker drift outside
#: the library do (``benchmarks/thresholds.py``).
EXCESS_RATIO = 1.15
#: Significant candidates refitted fully per round; the lowest held-out error wins. Where more are
#: significant, each first gets a short refit (``SCREEN_ITERATIONS``) and the best of those that
#: lowered the held-out error go on.
TRIES_PER_ROUND = 4
#: A candidate refitted on a second look (no score significant, the held-out residual above the noise
#: floor and not noise: see the loop) must explain at least this share of the held-out mean square's excess
#: over the floor: the bulk of what is missing (the rod beside a preload: 100 %), not a part of a large
#: residual, which is what structure from outside the library lets a flexible effect explain (a 1 mm
#: tracker drift: 12 % by a preload).
SECOND_LOOK_SHARE = 0.5
#: A candidate must explain ``min_excess`` of the held-out mean square's excess over the noise floor
#: while the model is within this many noise floors of it, and a share falling as ``1 / ratio``
#: beyond: far above the noise the excess is the sum of many missing effects, of which one real
#: effect explains only its part.
EXCESS_SCALE = 4.0
#: ... but never less than this. The share guards against structure the library lacks, not against
#: noise (the chi-square tests do that): on the generator's sets whose structure lies outside the
#: library (a tracker drift along the acquisition, 1.5 to 11 noise floors; ``benchmarks/thresholds.py``)
#: a library effect's refit explained up to 15 % of the excess, at any distance from the floor.
MIN_SHARE = 0.2


@dataclasses.dataclass
class Result:
    """Everything the report needs. ``theta_*`` are full parameter vectors of ``problem``; boolean
    masks are over its samples (training data, then the validation file's if one was given)."""

    problem: Problem
    train: np.ndarray
    held: np.ndarray
    val: np.ndarray
    holdout: str
    noise: dict
    theta_declared: np.ndarray
    theta_before: np.ndarray
    #: the chosen model as the loop fitted it (training part): the held-out errors are its
    theta_selected: np.ndarray
    #: the chosen model refitted on every sample of the data file: parameters, validation
    theta_after: np.ndarray
    std_after: np.ndarray
    nominal: list
    active: list
    effects: list[Added]
    candidates: list
    rounds: list[Round]
    steps: list
    structure: dict
    rmse: dict
    unexplained_structure: bool
    robust: bool
    correlations: dict
    at_bound: list
    features: dict
    baselines: dict | None
    seconds: float
    #: the measurement frame found before the loop (:mod:`._register`); the problem's data are moved
    #: into the base frame by it where it was applied
    registration: GlobalRegistration | None = None

    @property
    def data(self) -> Dataset:
        return self.problem.data

    def predicted(self, theta=None, active=None) -> np.ndarray:
        """Predicted tip positions (N, 3) of every sample, by default of the final model."""
        theta = self.theta_after if theta is None else theta
        return self.problem.predict(theta, self.active if active is None else active)

    def to_json(self) -> dict:
        """The ``report.json`` content."""
        pb = self.problem
        out = {
            "data": pb.data.source,
            "frame": pb.data.frame,
            "global_registration": None if self.registration is None else self.registration.to_json(),
            "measurement_frame": measurement_frame(pb, self.theta_after, self.active, self.registration),
            "n_samples": int((self.train | self.held).sum()),
            "n_train": int(self.train.sum()),
            "n_held_out": int(self.held.sum()),
            "holdout": self.holdout,
            "dropped_rows": len(pb.data.dropped),
            "dropped": list(pb.data.dropped),
            "robust": self.robust,
            "rmse_declared_mm": self.rmse["declared"],
            "rmse_before_mm": self.rmse["before"],
            "rmse_after_mm": self.rmse["after"],
            "rmse_train_after_mm": self.rmse["train_after"],
            "rmse_refit_mm": self.rmse["refit"],
            "noise_floor_mm": self.noise["floor_mm"],
            "noise": self.noise,
            "nominal_parameters": list(self.nominal),
            "effects": [e.to_dict() for e in self.effects],
            "candidates": [c.to_dict() for c in self.candidates],
            "rounds": [rd.to_dict() for rd in self.rounds],
            "steps": self.steps,
            "unexplained_structure": self.unexplained_structure,
            "structure": self.structure,
            "parameters": {
                **final_parameters(pb, self.theta_after, self.active),
                "std": pb.describe_std(self.theta_after, self.active, self.std_after),
                "at_bound": self.at_bound,
            },
            "correlations": self.correlations,
            "model": {
                "blocks": [b.name for b in pb.spec.blocks],
                "active": list(self.active),
                "theta": np.asarray(self.theta_after).tolist(),
                "clock": pb.clock,
            },
            "seconds": self.seconds,
        }
        out["knife_edges"] = knife_edges(out["rounds"])
        out["bound_warnings"] = bound_lines(
            self.at_bound, pb.describe(self.theta_after, self.active), pb.describe(self.theta_declared, self.active)
        )
        out["warnings"] = caveats(out)
        if self.val.any():
            out.update(
                n_validate=int(self.val.sum()),
                rmse_validate_mm=self.rmse["validate"],
                rmse_validate_aligned_mm=self.rmse["validate_aligned"],
                baselines=self.baselines,
            )
        return out


@dataclasses.dataclass
class _Branch:
    """The loop's state: the model so far and how it came about (a look-ahead goes on from a copy)."""

    theta: np.ndarray
    err: float  # the held-out error the decisions use
    plain: float  # the held-out RMSE
    active: list
    effects: list[Added] = dataclasses.field(default_factory=list)
    candidates: list = dataclasses.field(default_factory=list)
    rounds: list[Round] = dataclasses.field(default_factory=list)
    models: list = dataclasses.field(default_factory=list)  # every accepted model, for the validation steps
    rnd: int = 0
    trail: list = dataclasses.field(default_factory=list)  # ``err`` after each round
    behind: int = 0  # the round after which a look-ahead's branch fell behind the other (0: it did not)
    #: the joint look's path: refits need not explain a share of the excess on their own (the module's
    #: docstring, step 4)
    relaxed: bool = False
    #: the last round's, where it kept nothing but a refit passed every test but the share (the joint
    #: look's start)
    shortfall: _Fork | None = None


class _Fork(NamedTuple):
    """Where another branch may go on from: a round's branch before its record, its refits, the one to
    keep instead, and the round's record so far."""

    before: _Branch
    tried: list[Refit]
    name: str
    info: Round


def final_parameters(pb: Problem, theta, active) -> dict:
    """The physical parameters after every fitted effect, plus each fitted block in report units."""
    phys = physical(pb.spec, np.asarray(theta, np.float64), pb.on(active), pb.phys0)
    phys = jax.tree_util.tree_map(lambda x: np.asarray(x).tolist(), phys)
    phys["route_angles_deg"] = np.degrees(phys.pop("route_angles")).tolist()
    return {"physical": phys, "fitted": pb.describe(theta, active)}


def rmse_aligned(r) -> float:
    """RMSE after removing the mean offset (the metric the OpenCR lab reports)."""
    r = np.asarray(r)
    return rmse(r - r.mean(axis=0))


#: A length below any tracker's resolution (mm): stands for a noise floor or error of exactly 0.
TINY_MM = 1e-9


def _excess(plain: float, err: float, noise: dict, m: int) -> dict:
    """The held-out error (plain RMSE ``plain``, the decisions' ``err``; ``m`` samples) against the noise
    floor: their ratio, and the mean square's log-ratio as an F-type z-value, since the floor is itself
    estimated (from ``noise["pairs"]`` pairs of three axes) and can be off by chance. A floor (or error)
    of 0, noiseless data, counts as :data:`TINY_MM`: finite figures, far above the floor."""
    floor = max(noise["floor_mm"], TINY_MM)
    log_ratio = math.log(max(err, TINY_MM) ** 2 / (floor**2))
    sd = math.sqrt(2.0 / (3 * m) + 2.0 / (3 * max(noise["pairs"], 1)))
    return {"ratio_to_floor": plain / floor, "z": log_ratio / sd}


def _flagged(structure: dict) -> bool:
    """Whether a held-out residual's :func:`structure_test` (with its ``"excess_over_noise"``, an
    :func:`_excess`) says the model lacks something: structure along an input, an offset, or an error
    clearly above the noise floor."""
    ex = structure["excess_over_noise"]
    return bool(
        any(v["z"] > STRUCTURE_Z for k, v in structure.items() if k != "excess_over_noise")
        or (ex["ratio_to_floor"] > EXCESS_RATIO and ex["z"] > STRUCTURE_Z)
    )


@dataclasses.dataclass(frozen=True)
class _Loop:
    """What the loop's steps share: the problem and its fits, the data's parts (boolean masks over the
    problem's samples), the noise and the decisions' thresholds; ``say`` reports progress."""

    pb: Problem
    model: RobotModel
    fits: Fits
    run: Runner
    train: np.ndarray
    held: np.ndarray
    noise: dict
    sigma: np.ndarray
    held_feats: dict
    cand_names: list
    nominal_names: list
    blocks: dict  # name -> effect, every block of the problem
    alpha: float
    min_gain: float
    min_excess: float
    max_rounds: int
    robust: bool
    say: Callable[[str], None]

    sl: dict  # name -> the block's parameters in theta
    m: int  # held-out samples
    m_train: int

    @property
    def resolution(self) -> float:
        # two held-out errors closer than this (their sum-of-squares difference, in ``unit_of``) are a
        # tie: the test of one parameter cannot tell them apart
        return chi2_quantile(self.alpha, 1)

    def unit_of(self, e):
        # held-out SSE changes are in units of the per-axis variance of the current residual (at
        # least the noise): structure the model lacks must not make a chance improvement look significant
        return max(float(np.mean(self.sigma**2)), e**2 / 3.0)

    def one_round(self, st: _Branch, ties: list[_Fork] | None) -> bool:
        """One round of the loop on branch ``st``: score, refit, keep the best, backward step.
        Returns whether an effect was kept (the loop goes on). A near tie is recorded in ``ties``
        (the look-ahead's start: the module's docstring, step 4)."""
        st.rnd += 1
        st.shortfall = None
        scored = self.score(st)
        if scored is None:
            return False
        scores, r, z_crit = scored
        scores, chosen = self.screen(st, scores, r, z_crit)
        st.candidates.extend(scores)
        chosen = chosen[:TRIES_PER_ROUND]
        tried = self.refit(st, chosen, r)
        m, unit = self.m, self.unit_of(st.err)
        good = sorted((t for t in tried if t.significant), key=lambda t: t.err)
        good, nested = self.simplest(good, unit)
        info = Round(
            round=st.rnd, z_critical=z_crit, rmse_held_out_mm=st.plain, rmse_train_mm=rmse(r[self.train]), nested=nested
        )
        short = sorted((t for t in tried if t.short_of_share), key=lambda t: t.err)
        if not good and short:  # the joint look may go on from here (step 4)
            st.shortfall = _Fork(copy.deepcopy(st), copy.deepcopy(tried), short[0].name, info)
        if ties is not None and len(good) > 1 and (good[1].err ** 2 - good[0].err ** 2) * m / unit < self.resolution:
            # the test cannot tell the two apart: the look-ahead may go on from the runner-up
            ties.append(_Fork(copy.deepcopy(st), copy.deepcopy(tried), good[1].name, info))
        return self.keep(st, tried, good[0] if good else None, info)

    def simplest(self, good: list[Refit], unit: float) -> tuple[list[Refit], Nested | None]:
        """``good`` (significant refits, lowest error first) with a special case of the best first
        where the best's extra parameters do not buy a significant drop over it (a nested chi-square
        test at the loop's level), and the record of that choice (None where the order stands)."""
        if not good:
            return good, None
        best = good[0]
        for t in good[1:]:
            if self.blocks[t.name].special_case_of != best.name:
                continue
            extra = _size(self.sl[best.name]) - _size(self.sl[t.name])
            drop, need = (t.err**2 - best.err**2) * self.m / unit, chi2_quantile(self.alpha, max(extra, 1))
            if drop < need:
                return [t] + [g for g in good if g is not t], Nested(t.name, best.name, drop, need, extra)
        return good, None

    def score(self, st: _Branch) -> tuple | None:
        """The score test of every candidate not in ``st``'s model on its held-out residual. Returns the
        scores (highest first), the residual (every sample) and the round's critical z-value, or None
        where no candidate is left to score."""
        pb, sl, P, blocks, sigma = self.pb, self.sl, self.pb.null.size, self.blocks, self.sigma
        rnd, theta, active = st.rnd, st.theta, st.active
        remaining = [n for n in self.cand_names if n not in active]
        # an effect with no sensitivity without a load is not scored while the model has none (its
        # score would be 0; for the variable curvature this also spares the rod's program)
        unloaded = not pb.loaded(theta, active)
        idle = [n for n in remaining if getattr(blocks[n], "needs_load", False) and unloaded]
        remaining = [n for n in remaining if n not in idle]
        if not remaining:
            return None
        # effects that switch the solver are scored with their solver on (at null: the same model)
        switched = [n for n in remaining if getattr(blocks[n], "scored_on", False)]
        # a memory's (the samples before) is scored in a program of its own: the rod's with it
        # would solve every sample for every score, not only the held-out ones
        recalled = [n for n in switched if getattr(blocks[n], "memory", False)]
        switched = [n for n in switched if n not in recalled]
        r = pb.residuals(theta, active)
        if switched:
            self.run.warmed("rod")  # a worker compiling the rod's program: load it rather than compile it
        # the score test needs the held-out samples only (the rod's Jacobian costs ~7x the model's)
        r_held, J_held = pb.jacobian(theta, active + switched, samples=np.flatnonzero(self.held))
        for name in recalled:
            J_held[..., sl[name]] = pb.jacobian(theta, active + [name], samples=np.flatnonzero(self.held))[1][
                ..., sl[name]
            ]
        active_cols = np.concatenate([np.arange(P)[sl[n]] for n in active])
        wts = glitch_weights(r_held, sigma) if self.robust else None
        # the score test's null is "what is left is noise"; far above the noise floor, what is left is
        # mostly model error, and a candidate must explain more of it than its parameter count would by
        # chance: the residual's own per-axis scale replaces the noise's there
        kept_h = r_held if wts is None else r_held[wts > 0]
        sigma_score = np.maximum(sigma, np.sqrt(np.mean(kept_h**2, axis=0)))
        scores = []
        for name in remaining:
            s = score_test(r_held, J_held, active_cols, np.arange(P)[sl[name]], sigma_score, wts)
            explained = math.sqrt(max(s["explained_mm2"], 0.0))
            scores.append(Score(round=rnd, name=name, score=s["score"], dof=s["dof"], explained_rmse_mm=explained))
        scores.sort(key=lambda c: -c.score)
        scores += [Score(rnd, n, 0.0, _size(sl[n]), 0.0, not_scored="the model has no load") for n in idle]
        z_crit = _norm_isf(self.alpha / max(len(remaining) + len(idle), 1))  # every candidate of the round
        self.say(f"round {rnd}: " + ", ".join(f"{s.name} {s.score:.1f}" for s in scores))
        return scores, r, z_crit

    def screen(self, st: _Branch, scores: list[Score], r: np.ndarray, z_crit: float) -> tuple:
        """The candidates of a round that go on to full refits, best first: the significant ones, or on
        a second look every positive score; where many (or the rod's among several), only the best of
        those whose short refit lowered the held-out error enough. Returns the round's scores with
        what the screen added to them, and those candidates."""
        pb, sl, m, alpha, theta, active, err = self.pb, self.sl, self.m, self.alpha, st.theta, st.active, st.err
        significant = [s for s in scores if s.score > z_crit]
        # the score test is first order: an effect whose parameters act nonlinearly once the others
        # are refitted with it (the rod's curvature freedom beside a preload: score 3.0 against a
        # critical 3.7, yet a short refit takes the held-out error to the noise floor) can explain
        # far more than its score says. Where no score is significant but the held-out error is more
        # than ``EXCESS_RATIO`` times the noise floor and its residual not noise (the final flag's
        # test: structure along an input, an offset, or a clear excess), every candidate with a
        # positive score gets a short refit, and the refits' tests below decide, with a larger share
        # of the excess to explain (``SECOND_LOOK_SHARE``). Not only the best scores: an effect that
        # the one before it has partly absorbed scores low (the hole clearance after friction: 1.96,
        # eighth, and its refit took the held-out error from 7x the noise floor to the floor).
        # (Closer to the floor, what is left is too little
        # to name: a rod of four pieces fitted to a generator's of six, at 1.05x the floor, left
        # structure that a geometry change took half of: the model's own discretisation.)
        excess = _excess(st.plain, err, self.noise, m)
        second_look = (
            not significant
            and excess["ratio_to_floor"] > EXCESS_RATIO
            and _flagged({**structure_test(r[self.held], self.held_feats, self.sigma), "excess_over_noise": excess})
        )
        if second_look:
            significant = [
                dataclasses.replace(s, second_look=True) for s in scores if s.score > 0 and s.not_scored is None
            ]
        unit = self.unit_of(err)
        if (
            second_look
            or len(significant) > TRIES_PER_ROUND
            or (len(significant) > 1 and any(self.blocks[s.name].pieces_for(self.model) > 1 for s in significant))
        ):
            # screen: a short refit of every significant candidate, then the full refits of the best
            # (also where fewer are significant but one of them is the rod's, whose full refit costs
            # as much as several of the others')
            jobs = [(_reset(theta, sl[s.name], pb.start), active + [s.name]) for s in significant]
            done = self.run.map("screen", jobs)
            self.say("  screened: " + ", ".join(f"{s.name} {e:.4f}" for s, e in zip(significant, done)))
            # a candidate whose short refit does not lower the held-out error by a quarter of the drop
            # the refit's test needs is unlikely to pass it (near the optimum a few Levenberg-Marquardt
            # steps take most of the gain): it goes no further. On FTDCR v4 this spares seven full
            # refits (three of them the rod's, the costliest), each of which fails its test when run;
            # every candidate screened out there has a higher held-out error after its short refit
            # than without it
            screened = [_screened(s, e, (err**2 - e**2) * m / unit, alpha) for s, e in zip(significant, done)]
            by_name = {s.name: s for s in screened}
            scores = [by_name.get(c.name, c) for c in scores]
            ranked = sorted(((e, s) for s, e in zip(screened, done) if not s.screened_out), key=lambda p: p[0])
            significant = [s for _, s in ranked]
        return scores, significant

    def refit(self, st: _Branch, chosen: list, r: np.ndarray) -> list[Refit]:
        """The full refits of the ``chosen`` candidates on ``st``'s model and their tests (the module's
        docstring, step 3). Returns a record of each, with its parameters and decision error."""
        pb, sl, m, alpha, theta, active, err = self.pb, self.sl, self.m, self.alpha, st.theta, st.active, st.err
        train, sigma, floor, unit = self.train, self.sigma, self.noise["floor_mm"], self.unit_of(err)
        decision_error = self.fits.decision_error
        tried = []
        jobs = [(_reset(theta, sl[s.name], pb.start), active + [s.name]) for s in chosen]
        # an effect of the clock must also predict the later samples from the earlier ones
        timed = [i for i, s in enumerate(chosen) if getattr(self.blocks[s.name], "of_time", False)]
        done = self.run.map("refit", jobs) + self.run.map("later", [(*jobs[i], theta, active) for i in timed])
        later = dict(zip(timed, done[len(jobs) :]))
        for i, (s, (th_new, plain_new, err_new, r_new)) in enumerate(zip(chosen, done)):
            drop = (err**2 - err_new**2) * m / unit
            need = chi2_quantile(alpha, max(s.dof, 1))
            # the training part's gain, tested the same way: not a share of the held-out gain, since the
            # parts' mixes of motions differ (on FTDCR v4 the single-tendon pulls are a third of the
            # training excess and a sixth of the held-out one, and no effect but the preload moves them)
            tr0, tr1 = decision_error(r, train), decision_error(r_new, train)
            drop_train = (tr0**2 - tr1**2) * self.m_train / max(float(np.mean(sigma**2)), tr0**2 / 3.0)
            share, share_train = _share(err, err_new, floor), _share(tr0, tr1, floor)
            share_needed = 0.0 if st.relaxed else _share_needed(self.min_excess, err, floor)
            tests = (
                drop > need
                and err_new < (1.0 - self.min_gain) * err
                and drop_train > need
                and (not s.second_look or share >= SECOND_LOOK_SHARE)
            )
            drop_later = n_late = None
            if i in later:  # the later held-out samples' drop, fitted on the earlier training ones
                sse_with, sse_without, n_late = later[i]
                drop_later = (sse_without - sse_with) / unit
                tests = tests and drop_later > need
            ok = tests and share >= share_needed
            refit = Refit(
                name=s.name, rmse_held_out_mm=plain_new, rmse_train_mm=rmse(r_new[train]),
                share_held_out=share, share_needed=share_needed, share_train=share_train,
                sse_drop=drop, sse_drop_train=drop_train, sse_drop_later=drop_later, n_later=n_late,
                needed=need, significant=bool(ok), short_of_share=bool(tests and not ok),
                theta=th_new, err=err_new, score=s.score,
            )  # fmt: skip
            tried.append(refit)
            self.say(
                f"  refit {s.name}: held-out {plain_new:.4f} mm (drop {drop:.1f}, needed {need:.1f})"
                f"{' significant' if ok else ' short of the share' if tests else ''}"
            )
        return tried

    def keep(self, st: _Branch, tried: list[Refit], accepted: Refit | None, info: Round) -> bool:
        """Keep the refit ``accepted`` (one of ``tried``, or None) in ``st``, then the backward step;
        record the round. Returns whether an effect was kept."""
        removed = []
        if accepted is not None:
            st.theta, st.err, st.plain = accepted.theta, accepted.err, accepted.rmse_held_out_mm
            st.active.append(accepted.name)
            st.effects.append(Added(accepted.name, accepted.rmse_held_out_mm, accepted.score))
            self.say(f"  kept {accepted.name}")
            # backward step: an earlier effect that only stood in for the one just added goes
            # (the refits without each earlier effect run at once; the first that passes is taken)
            sl = self.sl
            earlier = [e.name for e in st.effects if e.name != accepted.name]
            jobs = [(_reset(st.theta, sl[e], self.pb.null), [a for a in st.active if a != e]) for e in earlier]
            for e, (_, rest), (th_wo, plain_wo, err_wo) in zip(earlier, jobs, self.run.map("refit_held_only", jobs)):
                rise = (err_wo**2 - st.err**2) * self.m / self.unit_of(st.err)
                need = chi2_quantile(self.alpha, _size(sl[e]))
                self.say(f"  without {e}: held-out {plain_wo:.4f} mm (rise {rise:.1f}, needed {need:.1f})")
                if rise < need:
                    st.theta, st.err, st.plain, st.active = th_wo, err_wo, plain_wo, rest
                    st.effects = [x for x in st.effects if x.name != e]
                    removed.append(Removal(name=e, rmse_held_out_mm=plain_wo, sse_rise=rise, needed=need))
                    self.say(f"  removed {e}")
                    break
            st.models.append((list(st.active), st.theta.copy()))
        name = None if accepted is None else accepted.name
        marked = tuple(dataclasses.replace(t, accepted=t.name == name) for t in tried)
        st.rounds.append(dataclasses.replace(info, tried=marked, accepted=name, removed=tuple(removed)))
        st.trail.append(st.err)
        return accepted is not None

    def select(self, st: _Branch, ties: list[_Fork] | None, ahead_of: list | None = None) -> _Branch:
        """Rounds on ``st`` until one keeps nothing; with ``ahead_of`` (another branch's ``trail``),
        only while ``st`` is not behind it after the same round (``st.behind`` then says where)."""
        start = st.rnd
        while st.rnd < self.max_rounds and self.one_round(st, ties):
            if ahead_of and st.rnd > start and st.err > ahead_of[min(st.rnd, len(ahead_of)) - 1]:
                st.behind = st.rnd
                break
        return st

    def ending(self, st: _Branch) -> tuple:
        """The held-out error of a branch's model and the structure left in its residual: the plain
        RMSE, the decisions' error, the residual (every sample) and the structure test."""
        plain_e, err_e, r_e = self.fits.held_error(st.theta, st.active)
        structure = structure_test(r_e[self.held], self.held_feats, self.sigma)
        structure["excess_over_noise"] = _excess(plain_e, err_e, self.noise, self.m)
        return plain_e, err_e, r_e, structure

    def look_ahead(self, st: _Branch, end: tuple, ties: list[_Fork]) -> tuple:
        """The look-ahead (the module's docstring, step 4) from the first near tie in ``ties``: the
        loop goes on from that round's runner-up too. Returns the branch kept and its ``ending``."""
        # the loop ended with structure left, and a round had a near tie. Go
        # on from its runner-up too, and keep that branch if it ends significantly lower. (The loop
        # only adds and removes, it never swaps: a tip force taken for the weight in a tie under
        # constant curvature leaves the rod nothing to explain, 1.10x the floor with structure left,
        # where the weight's branch ends at 1.00x with the three effects the robot has.) The branch
        # is given up as soon as it is behind after a round (on FTDCR v4 after its first: the
        # weight's branch there ends 0.003 mm above the tip force's, and running it out costs rounds)
        n_nominal, resolution = len(self.nominal_names), self.resolution
        before, tried_t, runner, info = ties[0]
        k = info.round
        self.say(f"look-ahead: round {k} again, with {runner}")
        first = next(t.name for t in st.rounds[k - 1].tried if t.accepted)
        self.keep(before, tried_t, next(t for t in tried_t if t.name == runner), info)
        alt = self.select(before, None, ahead_of=st.trail)
        mine = BranchEnd(first, st.active[n_nominal:], end[0], unexplained_structure=_flagged(end[3]))
        if alt.behind:
            other = BranchEnd(runner, alt.active[n_nominal:], alt.plain, behind_after_round=alt.behind)
            la = LookAhead((mine, other), needed=resolution, kept=first)
            self.say(f"  {runner}: behind after round {alt.behind} ({alt.plain:.4f} mm held out): given up")
        else:
            end_alt = self.ending(alt)
            other = BranchEnd(runner, alt.active[n_nominal:], end_alt[0], unexplained_structure=_flagged(end_alt[3]))
            drop = (end[1] ** 2 - end_alt[1] ** 2) * self.m / self.unit_of(end[1])
            la = LookAhead((mine, other), needed=resolution, kept=first, sse_drop=drop)
            if drop > resolution:
                st, end, la = alt, end_alt, dataclasses.replace(la, kept=runner)
            self.say(
                f"  {runner}: held-out {end_alt[0]:.4f} mm against {end[0]:.4f} mm (drop "
                f"{drop:.1f}, needed {resolution:.1f}): kept the branch of {la.kept}"
            )
        st.rounds[k - 1] = dataclasses.replace(st.rounds[k - 1], look_ahead=la)
        return st, end

    def joint_look(self, st: _Branch, end: tuple) -> tuple:
        """The joint look (the module's docstring, step 4): from the last round of ``st``, which kept
        nothing though a refit passed every test but the share, go on with refits that need no share
        of their own, and keep what that path adds only if it explains the share together, at least
        ``min_excess`` of the excess (a significant drop for all its parameters too). Returns the
        branch kept and its ``ending``."""
        assert st.shortfall is not None
        before, tried_j, first, info = st.shortfall
        k = info.round
        self.say(f"joint look: round {k} again, with {first}")
        before.relaxed = True
        self.keep(before, tried_j, next(t for t in tried_j if t.name == first), info)
        alt = self.select(before, None)
        end_alt = self.ending(alt)
        added = [a for a in alt.active if a not in st.active]
        dof = sum(int(self.sl[a].stop - self.sl[a].start) for a in added)
        share = _share(end[1], end_alt[1], self.noise["floor_mm"])
        drop = (end[1] ** 2 - end_alt[1] ** 2) * self.m / self.unit_of(end[1])
        need = chi2_quantile(self.alpha, max(dof, 1))
        share_needed = _share_needed(self.min_excess, end[1], self.noise["floor_mm"])  # as for one effect
        ok = bool(added) and share >= share_needed and drop > need
        jl = JointLook(
            first=first,
            effects=alt.active[len(self.nominal_names) :],
            added=added,
            removed=[a for a in st.active if a not in alt.active],
            rmse_held_out_mm=end_alt[0],
            rmse_before_mm=end[0],
            share_held_out=share,
            share_needed=share_needed,
            sse_drop=drop,
            needed=need,
            kept=ok,
        )
        self.say(
            f"  joint look: {' + '.join(added) or 'nothing'}: held-out {end_alt[0]:.4f} mm against "
            f"{end[0]:.4f} mm, {100 * share:.1f} % of the excess (needed {100 * share_needed:.0f} %)"
            f"{': kept' if ok else ''}"
        )
        if ok:
            st, end = alt, end_alt
        st.rounds[k - 1] = dataclasses.replace(st.rounds[k - 1], joint_look=jl)
        return st, end


@dataclasses.dataclass(frozen=True)
class _Prepared:
    """The loop's problem before the first fit: the recording moved into the robot's base frame (where
    the global registration applied), with the validation file's samples after the data file's."""

    data: Dataset
    full: Dataset
    robot: Robot
    model: RobotModel
    pb: Problem
    blocks: tuple  # nominal, then candidate effects
    library: tuple
    nominal_names: list
    train: np.ndarray
    held: np.ndarray
    val: np.ndarray
    n_fit: int  # the data file's samples
    reg: GlobalRegistration | None
    theta_decl: np.ndarray
    noise: dict | None  # None where the data have no repeats: from the first fit's residual then
    sigma: np.ndarray | None
    n_workers: int
    rod: list  # the candidates that need the rod's program


def _prepare(data, robot, validate, model, library, nominal, holdout, register, workers, say) -> _Prepared:
    """Check the recordings, split the data, register them (:mod:`._register`), build the problem and
    estimate the noise (``calibrate``'s arguments)."""
    robot = Robot(robot) if isinstance(robot, Design) else robot
    data.check_against(robot)
    if validate is not None:
        validate.check_against(robot, moving=False)
        check_validation(data, validate)
    n_workers = worker_count(
        workers, (data.n_samples + (0 if validate is None else validate.n_samples)) * robot.n_segments
    )
    library = default_library(data.frame) if library is None else tuple(library)
    nominal = default_nominal(data.frame) if nominal is None else tuple(nominal)
    # constant curvature; the rod variant (segments in pieces) only while an effect needs it (Problem)
    model = model or RobotModel.of(robot)
    phys0 = model.physical(robot)
    library = tuple(b for b in library if b.size(model, phys0) > 0)  # e.g. no twist between segments of one
    train, held = data.split(holdout)
    n_fit = data.n_samples
    blocks = tuple(nominal) + tuple(library)
    # the drift's clock is the data file's: a validation file takes the drift at its nearest end
    clock = data_clock(data)
    reg = None
    if register:
        recorded = data if validate is None else data.concat(validate)
        reg = _register(
            Problem(model, robot, recorded, blocks, clock=clock), data, train, [b.name for b in nominal], library
        )
        say(f"global registration: {reg.reason}")
    if reg is not None and reg.applied:  # the loop runs in the robot's base frame
        data = reg.to_base(data)
        validate = None if validate is None else reg.to_base(validate)
        if data.frame == "base":  # a recording declared in the base frame but far from it
            nominal = tuple(nominal) + tuple(b for b in library if b.name == "registration")
            library = tuple(b for b in library if b.name != "registration")
    full = data if validate is None else data.concat(validate)
    val = np.arange(full.n_samples) >= n_fit
    train = np.r_[train, np.zeros(full.n_samples - n_fit, bool)]
    held = np.r_[held, np.zeros(full.n_samples - n_fit, bool)]
    pb = Problem(model, robot, full, blocks, clock=clock)
    theta_decl = pb.null.copy()
    try:
        noise = noise_floor(data)
    except ValueError:
        noise = None
    sigma = None if noise is None else np.asarray(noise["sigma_mm"])
    rod = [b.name for b in library if b.pieces_for(model) > 1]
    nominal_names = [b.name for b in nominal]
    return _Prepared(
        data=data, full=full, robot=robot, model=model, pb=pb, blocks=blocks, library=library,
        nominal_names=nominal_names, train=train, held=held, val=val, n_fit=n_fit, reg=reg, theta_decl=theta_decl,
        noise=noise, sigma=sigma, n_workers=n_workers, rod=rod,
    )  # fmt: skip


def _nominal_fit(pp: _Prepared, fits: Fits, run: Runner, say, **thresholds) -> tuple:
    """The first fit (the nominal model) and the context of the loop's steps. Returns the context, the
    loop's first branch and what the report needs of the start (declared and nominal errors, features)."""
    pb, data, nominal_names, sigma, noise = pp.pb, pp.data, pp.nominal_names, pp.sigma, pp.noise
    # without a worker, a spare core compiles on a thread what the loop will run: the rod's program
    # where the first round scores it for sure (the model carries a load from the start: known tip
    # forces, a declared weight), the final refit's once the first fit has fixed the fits' rows
    if pp.rod and pb.loaded(pp.theta_decl, nominal_names):
        run.ahead("rod")
    active = list(nominal_names)
    theta = fits.fit(_initial(pb, data, pp.theta_decl, nominal_names), active)
    run.ahead("final")
    theta_before = theta.copy()
    r_decl = pb.residuals(pp.theta_decl, [])  # after the first fit: in its program (Problem._evaluate)
    if noise is None:
        noise = noise_floor(data, pb.residuals(theta, active)[: pp.n_fit])
        sigma = np.asarray(noise["sigma_mm"])
    assert sigma is not None  # (given with the noise: _prepare)
    sigma = np.maximum(sigma, 1e-9)
    fits.sigma = sigma
    rmse_before, err, _ = fits.held_error(theta, active)
    plain = rmse_before  # the current model's held-out RMSE (err: the one decisions use)
    # the inputs the structure test looks along (from the nominal fit: the same for every model)
    feats = features(pp.full, _base_frame_prediction(pb, theta_before, nominal_names))
    say(
        f"declared {rmse(r_decl[pp.held]):.4f} mm, nominal fit {rmse_before:.4f} mm, "
        f"noise floor {noise['floor_mm']:.4f} mm"
    )
    main = _Branch(theta=theta, err=err, plain=plain, active=list(active), models=[(list(active), theta.copy())])
    cand_names = [b.name for b in pp.library]
    max_rounds = thresholds.pop("max_rounds")
    cx = _Loop(
        pb=pb,
        model=pp.model,
        fits=fits,
        run=run,
        train=pp.train,
        held=pp.held,
        noise=noise,
        sigma=sigma,
        held_feats={k: v[pp.held] for k, v in feats.items()},
        cand_names=cand_names,
        nominal_names=nominal_names,
        blocks={b.name: b for b in pb.spec.blocks},
        sl=pb.spec.slices(),
        m=int(pp.held.sum()),
        m_train=int(pp.train.sum()),
        max_rounds=2 * len(cand_names) if max_rounds is None else max_rounds,  # add/remove cannot cycle
        say=say,
        **thresholds,
    )
    start = {"theta_before": theta_before, "r_decl": r_decl, "rmse_before": rmse_before, "features": feats}
    return cx, main, start


def _result(cx: _Loop, pp: _Prepared, start: dict, st: _Branch, end: tuple, holdout: float, t0: float) -> Result:
    """The selection is over (branch ``st``, its ``ending``): refit the chosen model on every sample of
    the data file (step 5), predict the validation file for every accepted model, and report."""
    pb, run, say, train, held, val, full = cx.pb, cx.run, cx.say, pp.train, pp.held, pp.val, pp.full
    theta, active, effects, models = st.theta, st.active, st.effects, st.models
    # the selection is over: the structure left, on the held-out residual of the model fitted
    # without those samples
    plain_after, _, r_after, structure = end
    # the final model: refitted on every sample of the data file (step 5 above); its effects'
    # parameters (later effects refit earlier ones), deviations, identifiability
    w_all = cx.fits.w_all
    # (with the refits of the validation steps' models, below, at once)
    jobs = [(theta, active, False)] + [(th, act, True) for act, th in models[:-1]] * bool(val.any())
    run.warmed("final")
    done = run.map("refit_all", jobs)
    theta_sel, theta = theta, done[0][0]
    r_final, J_final = pb.jacobian(theta, active)
    free = pb.mask(active)
    std = parameter_std(J_final, r_final, free, w_all)
    effects = [
        dataclasses.replace(
            e, params=pb.describe(theta, [e.name])[e.name], params_std=pb.describe_std(theta, [e.name], std)[e.name]
        )
        for e in effects
    ]
    corr = correlations(J_final, free, w_all, pb.labels(active))
    rmse_d = {
        "declared": rmse(start["r_decl"][held]),
        "before": start["rmse_before"],
        "after": plain_after,
        "train_after": rmse(r_after[train]),
        "refit": rmse(r_final[train | held]),
    }
    steps = []
    families = None if full.groups is None else np.array([pattern_family(g) for g in full.groups])
    for i, (act, th) in enumerate(models):  # the validation file, predicted only now, for every accepted model
        last = i == len(models) - 1  # the selected model: its residuals are r_after, its refit r_final
        rr = r_after if last else pb.residuals(th, act)
        # the validation file by the model refitted on every sample, as the final one (the last is it)
        rv = rr if not val.any() else r_final if last else done[1 + i][1]
        step = {
            "effects": act[len(cx.nominal_names) :],
            "rmse_held_out_mm": rmse(rr[held]),
            "rmse_validate_mm": rmse(rv[val]) if val.any() else None,
            "rmse_validate_aligned_mm": rmse_aligned(rv[val]) if val.any() else None,
        }
        if families is not None:  # per pattern family (same direction, S-curve, spiral, ...)
            step["rmse_by_family_mm"] = {
                part: {f: rmse(r[mask & (families == f)]) for f in dict.fromkeys(families[mask])}
                for part, mask, r in (("held_out", held, rr), ("validate", val, rv))
                if mask.any()
            }
        steps.append(step)
    bl = None
    if val.any():
        rmse_d["validate"], rmse_d["validate_aligned"] = rmse(r_final[val]), rmse_aligned(r_final[val])
        bl = baselines(full, train, held, val)
        say(f"validation RMSE {rmse_d['validate']:.3f} mm (mean offset removed {rmse_d['validate_aligned']:.3f} mm)")
    return Result(
        problem=pb,
        train=train,
        held=held,
        val=val,
        holdout=pp.data.split_description(holdout),
        noise=cx.noise,
        theta_declared=pp.theta_decl,
        theta_before=start["theta_before"],
        theta_selected=theta_sel,
        theta_after=theta,
        std_after=std,
        nominal=cx.nominal_names,
        active=active,
        effects=effects,
        candidates=st.candidates,
        rounds=st.rounds,
        steps=steps,
        structure=structure,
        rmse=rmse_d,
        # structure left, or the held-out error clearly above the noise floor (``ending``: ``_excess``)
        unexplained_structure=_flagged(structure),
        robust=cx.robust,
        correlations=corr,
        at_bound=pb.at_bounds(theta, active),
        features=start["features"],
        baselines=bl,
        seconds=time.perf_counter() - t0,
        registration=pp.reg,
    )


def calibrate(
    data: Dataset,
    robot,
    validate: Dataset | None = None,
    model=None,
    library=None,
    nominal=None,
    holdout: float = 0.25,
    robust: bool = False,
    alpha: float = 1e-3,
    min_gain: float = 0.01,
    min_excess: float = 0.25,
    max_rounds: int | None = None,
    log=None,
    workers: int | None = None,
    register: bool = True,
) -> Result:
    """Run the loop on a recording of ``robot`` (a :class:`Robot`, or a :class:`Design` for one segment).

    ``validate``: a second recording of the same robot, only predicted after the selection.
    ``library`` / ``nominal``: candidate and always-fitted effects (defaults by the data's frame,
    :func:`.effects.library`). ``log`` (callable taking a str) reports progress. ``workers``: processes
    that run the loop's independent fits alongside this one (:mod:`._fits`; None: one per spare core
    where starting them is safe and the recording is large enough, ``TENSION_ZONES_WORKERS`` if set);
    the result is the same with any. ``register``: move the recording into the robot's base frame
    first (:mod:`._register`); False takes its frame as it is, for the frame parameters' local fits.
    """
    t0 = time.perf_counter()
    say = log or (lambda s: None)
    pp = _prepare(data, robot, validate, model, library, nominal, holdout, register, workers, say)
    fits = Fits(pp.pb, pp.train, pp.held, robust)
    fits.sigma = pp.sigma
    # the workers compile the rod's program first (the main process needs it last), then the model's,
    # then the final refit's
    warm = {"rod": (pp.nominal_names + pp.rod[:1], "train")} if pp.rod else {}
    warm.update(model=(pp.nominal_names, "train"), final=(pp.nominal_names, "all"))
    with Runner(fits, pp.n_workers, (pp.model, pp.robot, pp.full, pp.blocks, pp.pb.clock), warm) as run:
        cx, main, start = _nominal_fit(
            pp, fits, run, say, alpha=alpha, min_gain=min_gain, min_excess=min_excess, max_rounds=max_rounds,
            robust=robust,
        )  # fmt: skip
        ties: list[_Fork] = []
        st = cx.select(main, ties)
        end = cx.ending(st)
        if ties and _flagged(end[3]):  # the look-ahead (step 4)
            st, end = cx.look_ahead(st, end, ties)
        if (
            st.shortfall is not None
            and _flagged(end[3])
            and end[3]["excess_over_noise"]["ratio_to_floor"] > EXCESS_SCALE
        ):
            st, end = cx.joint_look(st, end)  # the joint look (step 4)
        return _result(cx, pp, start, st, end, holdout, t0)


def _size(block: slice) -> int:
    return int(block.stop - block.start)


def _screened(s: Score, rmse_mm: float, drop: float, alpha: float) -> Score:
    """``s`` with its short refit's held-out RMSE and SSE ``drop``: it goes no further where the drop
    is under a quarter of what the full refit's test needs (``_Loop.screen``)."""
    needed = 0.25 * chi2_quantile(alpha, max(s.dof, 1))
    return dataclasses.replace(
        s, screened_rmse_mm=rmse_mm, screened_drop=drop, screened_needed=needed, screened_out=bool(drop < needed)
    )


def _share_needed(min_excess: float, err: float, floor: float) -> float:
    """The share of the excess a refit (or the joint look's path) at held-out error ``err`` must
    explain: ``min_excess`` within ``EXCESS_SCALE`` noise floors, falling as ``1 / ratio`` beyond, never
    below ``MIN_SHARE`` (nor above ``min_excess``)."""
    return min(min_excess, max(MIN_SHARE, min_excess * EXCESS_SCALE * floor / err))


def _share(before: float, after: float, floor: float) -> float:
    """The fraction of a mean square's excess over the noise floor (RMSE ``before``) that a change to
    RMSE ``after`` removes."""
    excess = before**2 - floor**2
    return (before**2 - after**2) / excess if excess > 0 else 0.0


def _reset(theta, block: slice, values) -> np.ndarray:
    """A copy of ``theta`` with one block's parameters set from ``values`` (P,): ``Problem.start`` for a
    refit that adds the block's effect, ``Problem.null`` for one that removes it."""
    th = np.array(theta, float)
    th[block] = values[block]
    return th


def _register(pb: Problem, data: Dataset, rows, nominal, library) -> GlobalRegistration:
    """The data file's frame against the robot's base (:mod:`._register`), from the nominal model at
    its declared values and the start values the data give (the patterns' rotations), on ``rows``."""
    reg_block = next((b for b in library if b.name == "registration"), None)
    reach = None
    if data.frame == "base":
        if reg_block is None:  # no registration to reach the frame: the data are taken as declared
            return GlobalRegistration(
                R=np.eye(3),
                t=np.zeros(3),
                rmse_mm=float("nan"),
                explained=float("nan"),
                applied=False,
                reason="declared base frame",
            )
        hi = reg_block.bounds(pb.model, pb._phys_np)[1]
        reach = (float(hi[0]), float(hi[3]))

    w = np.zeros(pb.n)
    w[: len(rows)] = rows
    pb.fit(pb.null, nominal, w, max_iter=0)  # the loop's fits' program (rows), not one of every sample

    def predict(moved):
        theta = pb.null if moved is None else _initial(pb, moved, pb.null, nominal)
        return _base_frame_prediction(pb, theta, nominal)[: data.n_samples]  # (a validation file follows)

    return global_registration(predict, data, rows, reach)


def _initial(pb: Problem, data: Dataset, theta, nominal) -> np.ndarray:
    """Starting values of the nominal parameters that the data can give directly (the wire patterns'
    rotations, where they are nominal), so the nominal fit starts in the right basin."""
    theta = theta.copy()
    if "pattern_rotation" in nominal:
        sl = pb.spec.slices()["pattern_rotation"]
        theta[sl] = initial_pattern_rotation(pb.model.structure, pb._phys_np, data)
    return theta


def initial_pattern_rotation(structure, phys0, data: Dataset) -> np.ndarray:
    """Each segment's wire-pattern rotation (S,) from the data's linear response: regressing the tip's
    lateral position on the commands, pulling wire ``k`` moves the tip toward the wire's angle (with
    the default routing, every segment it crosses bends that way); per segment, the circular mean of
    (that direction - the declared angle). No labels needed."""
    X = np.c_[np.ones(data.n_samples), data.q]
    coef, *_ = np.linalg.lstsq(X, data.p[:, :2], rcond=None)
    M = -coef[1:]  # (N, 2): tip motion per mm of pull
    own = np.asarray(phys0["route_angles"])[np.arange(structure.n_wires), structure.owner]
    dirs = np.arctan2(M[:, 1], M[:, 0]) - own
    weight = np.linalg.norm(M, axis=1)
    out = np.zeros(structure.n_segments)
    for j in range(structure.n_segments):
        k = structure.owner == j
        z = np.sum(weight[k] * np.exp(1j * dirs[k]))
        out[j] = np.angle(z) if abs(z) > 0 else 0.0
    return out


def _base_frame_prediction(pb: Problem, theta, active, frame=("registration", "offset", "marker")) -> np.ndarray:
    """The model's prediction in the robot's base frame (the blocks ``frame`` at null): where the tip
    is, for the residual's features."""
    th = np.asarray(theta).copy()
    sl = pb.spec.slices()
    for name in frame:
        if name in sl:
            th[sl[name]] = pb.null[sl[name]]
    return pb.predict(th, [a for a in active if a not in frame])


def measurement_frame(pb: Problem, theta, active, reg: GlobalRegistration | None) -> dict:
    """The measurement frame against the robot's base, ``p_measured = R p_base + t``: the global
    registration composed with the fitted frame blocks (offset, registration; a common turn about the
    robot's axis is the patterns' rotation's, not in ``R``), from the model's predictions with and
    without those blocks (a rigid map between them, exact). Rotation vector (deg), translation (mm) and
    the robot's axis in the measurement frame."""
    base = _base_frame_prediction(pb, theta, active, frame=("registration", "offset"))
    R, t = kabsch(base, pb.predict(theta, active))
    if reg is not None and reg.applied:
        R, t = reg.R @ R, reg.R @ t + reg.t
    # (rounded far below any tracker's resolution: the same model evaluated over other samples, e.g.
    # with a validation file, differs in the last bits)
    return {
        "rotation_deg": np.round(np.degrees(rotation_vector(R)), 9).tolist(),
        "translation_mm": np.round(t, 9).tolist(),
        "axis": np.round(R[:, 2], 12).tolist(),
    }


def predict_report(report: dict, robot, data: Dataset) -> np.ndarray:
    """The tip positions (N, 3) a calibration report's final model predicts for ``data`` (a recording
    of ``robot``, e.g. new commands or a validation file; path-dependent state starts afresh)."""
    from .effects import BY_NAME

    robot = Robot(robot) if isinstance(robot, Design) else robot
    m = report["model"]
    clock = m.get("clock")
    pb = Problem(
        RobotModel.of(robot),
        robot,
        data,
        tuple(BY_NAME[n] for n in m["blocks"]),
        clock=None if clock is None else tuple(clock),
    )
    p = pb.predict(np.asarray(m["theta"], float), m["active"])
    reg = GlobalRegistration.from_json(report.get("global_registration"))
    return p if reg is None else reg.to_measured(p)
