"""The calibration loop's records: its rounds and the decisions taken in them, as frozen dataclasses.

Each has ``to_dict()``, its form in ``report.json`` (``Result.to_json``): the keys in the order the
report lists them, a field that does not apply left out.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np


@dataclasses.dataclass(frozen=True)
class Score:
    """A candidate's score test in a round (the loop's docstring, step 2), and its short refit where
    the round screened it (step 3)."""

    round: int
    name: str
    score: float  # z-value (0 where not scored)
    dof: int
    explained_rmse_mm: float
    not_scored: str | None = None  # why it was not scored
    second_look: bool = False  # a candidate of the round's second look
    #: the short refit: its held-out RMSE, the held-out sum of squares' drop (in units of the
    #: residual's variance), the drop it needed to go on, and whether it went no further
    screened_rmse_mm: float | None = None
    screened_drop: float | None = None
    screened_needed: float | None = None
    screened_out: bool | None = None

    def to_dict(self) -> dict:
        out = {k: getattr(self, k) for k in ("round", "name", "score", "dof", "explained_rmse_mm")}
        if self.not_scored is not None:
            out["not_scored"] = self.not_scored
        if self.second_look:
            out["second_look"] = True
        if self.screened_rmse_mm is not None:
            out.update(
                screened_rmse_mm=self.screened_rmse_mm,
                screened_drop=self.screened_drop,
                screened_needed=self.screened_needed,
                screened_out=self.screened_out,
            )
        return out


@dataclasses.dataclass(frozen=True)
class Added:
    """An effect the loop kept (``Result.effects``): the held-out RMSE once it was in and its score; in
    the final result its parameters and their standard deviations (the refit on every sample,
    :meth:`Problem.describe` form)."""

    name: str
    rmse_after_mm: float
    score: float
    params: dict | None = None
    params_std: dict | None = None

    def to_dict(self) -> dict:
        out = {"name": self.name, "rmse_after_mm": self.rmse_after_mm, "score": self.score}
        if self.params is not None:
            out.update(params=self.params, params_std=self.params_std)
        return out

    def __getitem__(self, key: str):
        """``effect["name"]``, as when effects were dicts: deprecated, read the attribute."""
        warnings.warn(
            f"Result.effects holds records: read effect.{key}, not effect[{key!r}] (indexing by key is "
            "deprecated and will be removed)",
            DeprecationWarning,
            stacklevel=2,
        )
        if key not in self.to_dict():
            raise KeyError(key)
        return getattr(self, key)


@dataclasses.dataclass(frozen=True)
class Refit:
    """A candidate's full refit in a round, and its tests (the loop's docstring, step 3)."""

    name: str
    rmse_held_out_mm: float
    rmse_train_mm: float
    share_held_out: float  # of the held-out mean square's excess over the noise floor
    share_needed: float
    share_train: float
    sse_drop: float  # the held-out sum of squares' drop, in units of the residual's variance
    sse_drop_train: float
    needed: float  # the chi-square quantile the drops must exceed
    significant: bool  # passed every test
    short_of_share: bool  # passed every test but the share
    theta: np.ndarray  # (P,) the refitted parameters (not reported)
    err: float  # the held-out error the decisions use (not reported)
    score: float  # the candidate's score (not reported)
    #: an effect of the clock: the later held-out samples' drop, fitted on the earlier training ones
    sse_drop_later: float | None = None
    n_later: int | None = None
    accepted: bool = False  # kept in its round

    def to_dict(self) -> dict:
        out = {
            k: getattr(self, k)
            for k in (
                "name",
                "rmse_held_out_mm",
                "rmse_train_mm",
                "share_held_out",
                "share_needed",
                "share_train",
                "sse_drop",
                "sse_drop_train",
            )
        }
        if self.sse_drop_later is not None:
            out.update(sse_drop_later=self.sse_drop_later, n_later=self.n_later)
        out.update(
            needed=self.needed, significant=self.significant, short_of_share=self.short_of_share, accepted=self.accepted
        )
        return out


@dataclasses.dataclass(frozen=True)
class Removal:
    """The backward step's removal of an earlier effect that only stood in for the one just kept."""

    name: str
    rmse_held_out_mm: float  # without it
    sse_rise: float  # the held-out sum of squares' rise without it, in units of the residual's variance
    needed: float

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True)
class BranchEnd:
    """Where one branch of a look-ahead ended: its first effect, its effects, its held-out error, and
    either whether structure was left or the round after which it fell behind."""

    first: str
    effects: list[str]
    rmse_held_out_mm: float
    unexplained_structure: bool | None = None
    behind_after_round: int | None = None

    def to_dict(self) -> dict:
        out = {"first": self.first, "effects": list(self.effects), "rmse_held_out_mm": self.rmse_held_out_mm}
        if self.unexplained_structure is not None:
            out["unexplained_structure"] = self.unexplained_structure
        if self.behind_after_round is not None:
            out["behind_after_round"] = self.behind_after_round
        return out


@dataclasses.dataclass(frozen=True)
class LookAhead:
    """The look-ahead from a round's near tie (the loop's docstring, step 4): the round's choice and its
    runner-up, each run out, and the one kept."""

    branches: tuple[BranchEnd, BranchEnd]
    needed: float  # the drop the runner-up's branch needed (the test's resolution)
    kept: str  # the first effect of the branch kept
    sse_drop: float | None = None  # the runner-up branch's drop, where it was run to its end

    def to_dict(self) -> dict:
        out = {"branches": [b.to_dict() for b in self.branches], "needed": self.needed, "kept": self.kept}
        if self.sse_drop is not None:
            out["sse_drop"] = self.sse_drop
        return out


@dataclasses.dataclass(frozen=True)
class JointLook:
    """The joint look from a round whose best refit fell short of the share alone (the loop's
    docstring, step 4): what its path added, and whether together it explains the share."""

    first: str
    effects: list[str]
    added: list[str]
    removed: list[str]
    rmse_held_out_mm: float
    rmse_before_mm: float
    share_held_out: float
    share_needed: float
    sse_drop: float
    needed: float
    kept: bool

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True)
class Nested:
    """A round's lowest refit ``over`` passed over for ``kept``, a special case of it: the drop of the
    larger over the smaller, in units of the residual's variance, short of the chi-square quantile
    for its extra parameters."""

    kept: str
    over: str
    sse_drop: float
    needed: float
    extra: int  # the larger effect's extra parameters

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True)
class Round:
    """One round of the loop: the model's errors at its start, the refits tried, the effect kept (or
    None) and removed, and a look-ahead or joint look that went on from it."""

    round: int
    z_critical: float  # the round's critical score
    rmse_held_out_mm: float  # at the round's start
    rmse_train_mm: float
    tried: tuple[Refit, ...] = ()
    accepted: str | None = None
    removed: tuple[Removal, ...] = ()
    look_ahead: LookAhead | None = None
    joint_look: JointLook | None = None
    nested: Nested | None = None

    def to_dict(self) -> dict:
        out = {
            "round": self.round,
            "z_critical": self.z_critical,
            "rmse_held_out_mm": self.rmse_held_out_mm,
            "rmse_train_mm": self.rmse_train_mm,
            "tried": [t.to_dict() for t in self.tried],
            "accepted": self.accepted,
            "removed": [r.to_dict() for r in self.removed],
        }
        if self.look_ahead is not None:
            out["look_ahead"] = self.look_ahead.to_dict()
        if self.joint_look is not None:
            out["joint_look"] = self.joint_look.to_dict()
        if self.nested is not None:
            out["nested"] = self.nested.to_dict()
        return out
