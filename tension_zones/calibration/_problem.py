"""A model with effects as one flat parameter vector, fitted by the package's one least-squares solver.

Effects (:mod:`.effects`) transform the physical parameters, then the inputs, then the predicted
tip. Every block (nominal parameters and every candidate) is always present in the compiled function;
a 0/1 mask over the parameter vector says which are free and a 0/1 per block which are part of the
model being evaluated; the rest stay at their null values. So one compilation serves the whole loop:
new values, another active set or another data set of similar size never recompile. An effect that
needs the segments in pieces (``Effect.pieces_for``, the rod model) runs, while it is on, a second
program: the model's ``with_pieces`` variant, compiled the first time it is used and never again, so
a calibration that never needs the rod never pays for it.
"""

from __future__ import annotations

import dataclasses
import threading
from concurrent.futures import Future
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .._lsq import levenberg_marquardt
from .._xla import COMPILE_THREAD, classes_digest, fast_compile_options, shapes_key, stored_program


@dataclasses.dataclass(frozen=True)
class Spec:
    """The static part: a model and its blocks (nominal first), with their sizes."""

    model: Any  # a model: RobotModel or any object with its interface (``predict``, ...)
    blocks: tuple
    sizes: tuple

    @property
    def offsets(self):
        return tuple(int(x) for x in np.cumsum((0,) + self.sizes)[:-1])

    def slices(self):
        return {b.name: slice(o, o + s) for b, o, s in zip(self.blocks, self.offsets, self.sizes)}


def _split(spec: Spec, theta):
    return [theta[o : o + s] for o, s in zip(spec.offsets, spec.sizes)]


def _named(spec: Spec, on):
    """The blocks' on-flags ``on`` (B,) by block name."""
    return {b.name: on[i] for i, b in enumerate(spec.blocks)}


def stages(spec: Spec, theta, on, phys0, inputs):
    """The physical parameters and the per-sample inputs after every block's ``on_params`` and
    ``on_inputs`` (``on`` (B,) 0/1 over the blocks), with the blocks' parameter slices and on-flags."""
    parts, on = _split(spec, theta), _named(spec, on)
    phys = _on_params(spec, parts, on, phys0)
    for blk, th in zip(spec.blocks, parts):
        inputs = blk.on_inputs(th, inputs, spec.model, on)
    return phys, inputs, parts, on


def _on_params(spec: Spec, parts, on, phys):
    for blk, th in zip(spec.blocks, parts):
        phys = blk.on_params(th, phys, spec.model, on)
    return phys


def _has_path(model) -> bool:
    """Whether ``model`` predicts a sample from the samples before it (a memory, ``RobotModel.path``):
    it then solves every sample, whatever rows are asked for."""
    return bool(getattr(model, "path", False))


def predict_theta(spec: Spec, theta, on, phys0, inputs, rows=None, state=None):
    """The tip (``{"p", "R"}``, sample axis first) for the parameter vector ``theta`` and the blocks
    ``on`` (B,) 0/1, all blocks applied in stages (parameters, inputs, outputs); ``rows`` (K,): only
    those samples (after the input stage, which may depend on the whole sequence, e.g. backlash).
    ``state``: the model's warm start for those samples (``_model``), then ``"state"`` is in the result."""
    phys, inputs, parts, on = stages(spec, theta, on, phys0, inputs)
    path = _has_path(spec.model)  # a prediction that needs the samples before it: all, then rows
    if rows is not None and not path:
        inputs = jax.tree_util.tree_map(lambda a: a[rows], inputs)
    out = spec.model.predict(phys, inputs) if state is None else spec.model.predict(phys, inputs, state=state)
    if rows is not None and path:
        out = {k: (v if k == "state" else v[rows]) for k, v in out.items()}
    for blk, th in zip(spec.blocks, parts):
        out = blk.on_outputs(th, out, spec.model, on)
    return out


def _engine(spec, theta0, free, on, rows, w, c, lo, hi, phys0, inputs, y, max_iter, cols, n_cols):
    """The one compiled function of the loop: a fit of the free parameters (``max_iter = 0`` only
    evaluates, so predictions and score tests need no compilation of their own), then the residuals
    (K, 3) and their Jacobian (K, 3, C) at the result. ``rows`` (K,): the samples the model is
    evaluated on (all of them, or a fit's own: see :meth:`Problem.fit`); path-dependent inputs are
    formed on the whole recording first. ``w`` (K,) their weights. ``cols`` (C,): the parameters
    differentiated (all, or a fit's free ones, padded). See
    :func:`tension_zones._lsq.levenberg_marquardt`. A model with a warm start (``start``, see
    ``_model``) starts every pass from the last accepted one's state."""
    warm = hasattr(spec.model, "start")

    def fun(th, s):
        out = predict_theta(spec, th, on, phys0, inputs, rows, state=s if warm else None)
        return out["p"] - y[rows], out["state"] if warm else s

    n_state = y.shape[0] if _has_path(spec.model) else rows.shape[0]  # a path model solves all
    state = spec.model.start(n_state, y.dtype) if warm else ()
    return levenberg_marquardt(
        fun,
        theta0,
        free,
        w,
        c,
        lo,
        hi,
        max_iter,
        tol=FIT_TOL,
        rows=(rows.shape[0], y.shape[1]),
        cols=cols,
        n_cols=n_cols,
        state=state,
    )


#: The engine's programs in this process, by model (``Spec``) and the arguments' shapes: a callable, or
#: the ``Future`` of one being compiled on a thread (:func:`engine_ahead`).
_PROGRAMS: dict = {}


def _key(spec, args):
    return (spec, *shapes_key(args))


def _optimised(spec) -> bool:
    """Whether the engine's program for ``spec`` is worth LLVM's optimisation (level 3, else 0).

    Not the rod variant of a one-segment robot. The loop scores the rod in its first round (a few
    short fits) and on one segment rarely fits it further, so its program's compile (about half as
    long at level 0, and competing for a core with the constant-curvature one's) outweighs its run:
    level 0 shortens a calibration from an empty cache, every result the same, and costs only where
    the rod is named and refitted. The constant-curvature program stays at level 3 (at level 0 it was
    slower on the larger sets), and so do two segments' rods, which are fitted further."""
    structure = getattr(spec.model, "structure", None)
    return not (getattr(structure, "pieces", 1) > 1 and getattr(structure, "n_segments", 0) == 1)


def _program(spec, args):
    """The engine's program for ``spec`` and arguments like ``args`` (jitted, not yet compiled)."""
    opts = fast_compile_options(_optimised(spec))
    fn = jax.jit(partial(_engine, spec), compiler_options=opts)
    classes = [type(spec.model)] + [type(b) for b in spec.blocks]
    if (outside := classes_digest(classes)) is not None:
        fn = stored_program(fn, args, f"calibration engine|{spec!r}|{outside}|{FIT_TOL!r}", opts)
    return fn


def engine(spec, *args):
    """:func:`_engine`, compiled once per model and shapes (``fast_compile_options``) and kept on disk
    before tracing (``_xla.stored_program``: a later process skips its trace). The stored
    program's key holds the spec (its repr: the model's static structure and the blocks) and the
    sources of any block or model class defined outside the package; one defined where it has no
    file (a notebook) is traced in every process. A program being compiled on a thread
    (:func:`engine_ahead`) is waited for."""
    key = _key(spec, args)
    fn = _PROGRAMS.get(key)
    if isinstance(fn, Future):
        fn = fn.result()
    if fn is None:
        fn = _PROGRAMS[key] = _program(spec, args)
    return fn(*args)


def engine_ahead(spec, *args) -> threading.Thread | None:
    """Start compiling :func:`engine`'s program for ``spec`` and arguments like ``args``, without
    running it: traced and lowered here, compiled by XLA on a thread (which holds no GIL, so a second
    core compiles while this one goes on: with the rod's program of a loaded single-segment set
    lowered first, the constant-curvature one is traced while the rod compiles). The thread that calls
    :func:`engine` with them later waits for it. Nothing is run on the thread: calls of the engine from
    two threads at once deadlocked XLA:CPU. Returns the thread, or None where the program exists
    already. The interpreter's exit waits for the thread (not a daemon: a thread inside XLA's compiler
    when the interpreter finalises aborts the process, status 134); the command line, which must stop
    within seconds of Ctrl-C, ends its process without that exit (``cli._exit``)."""
    key = _key(spec, args)
    if key in _PROGRAMS:
        return None
    fn = _program(spec, args)  # (a jitted function either way: stored or traced as usual)
    lowered = fn.lower(*args)
    fut = _PROGRAMS[key] = Future()

    def work():
        try:
            fut.set_result(lowered.compile())  # a Compiled executable: callable on these types
            _PROGRAMS[key] = fut.result()
        except BaseException:  # noqa: BLE001  (the caller compiles its own)
            _PROGRAMS[key] = fn
            fut.set_result(fn)

    t = threading.Thread(target=work, name=COMPILE_THREAD)
    t.start()
    return t


@partial(jax.jit, static_argnums=0)
def physical(spec: Spec, theta, on, phys0):
    """The physical parameters after every block's ``on_params`` (``on`` (B,) 0/1 over the blocks), as
    one small program (eagerly, the blocks' stages dispatch and compile one operation at a time)."""
    return _on_params(spec, _split(spec, theta), _named(spec, on), phys0)


@partial(jax.jit, static_argnums=0)
def _loaded(spec, theta, on, phys0, inputs):
    """The model's ``loaded`` flag after every block's stages: one small program (run eagerly, the
    stages dispatched and compiled some 30 single operations at every round of the loop)."""
    phys, inputs, _, _ = stages(spec, theta, on, phys0, inputs)
    return spec.model.loaded(phys, inputs)


def compilations() -> int:
    """How many programs the engine has made in this process (compiled, or loaded from the cache; a
    test counts them): one per model and shape (the fits' rows; the columns are data), and one more for the rod
    variant where an effect needs it."""
    return len(_PROGRAMS)


#: A fit stops when an accepted step lowers the cost by less than this, relative. The loop's decisions
#: resolve 1 % of the held-out RMSE; on the FTDCR v4 robot a tighter 1e-7 makes the same decisions
#: in every round, the held-out and validation RMSE within 0.006 mm, but runs most of the rod's full
#: refits to their iteration limit.
FIT_TOL = 1e-5

#: Fits of a recording of at least this many (padded) samples that weigh at most this share of them
#: evaluate only the weighted ones (evaluations then run that program in pieces of the samples:
#: :meth:`Problem._evaluate`). Every fit pass costs its rows, and a loop has at most two row counts
#: either way (its training fits', its refits' on every sample of the data file): the refits of
#: FTDCR v4 with its validation file (1620 of 2063 samples) run on 1664 rows, not 2176.
FIT_ROWS_MIN = 1024
FIT_ROWS_SHARE = 0.9

#: Sample counts are padded up to a multiple of this (padding repeats the last sample at zero weight,
#: after the real ones, so path-dependent state is untouched): sets of similar size share one program
#: (e.g. the shipped 400- and 500-sample sets of one robot), for at most 127 rows evaluated in vain.
PAD = 128
#: A fit's own rows (:meth:`Problem._fit_rows`) are padded to a multiple of this: one calibration
#: has one such count, and every fit iteration pays for the padding.
FIT_PAD = 64


def _pad(data):
    """The data set with every per-sample array padded (a ``Dataset`` stays a ``Dataset``)."""
    n = data.n_samples
    extra = (-n) % PAD

    def rep(a):
        return np.concatenate([a, np.repeat(a[-1:], extra, axis=0)])

    changes = {
        f.name: rep(np.asarray(getattr(data, f.name)))
        for f in dataclasses.fields(data)
        if isinstance(getattr(data, f.name), np.ndarray) and getattr(data, f.name).shape[:1] == (n,)
    }
    if data.groups is not None:
        changes["groups"] = tuple(data.groups) + (data.groups[-1],) * extra
    return dataclasses.replace(data, **changes)


class Problem:
    """A model, its blocks and one data set, ready to fit: the NumPy edge around the jitted core."""

    def __init__(self, model, robot, data, blocks, clock=None):
        self.model = model
        self.data = data
        self.n = data.n_samples
        padded = _pad(data)
        self.phys0 = model.physical(robot)
        phys_np = jax.tree_util.tree_map(np.asarray, self.phys0)
        sizes = tuple(int(b.size(model, phys_np)) for b in blocks)
        self.spec = Spec(model=model, blocks=tuple(blocks), sizes=sizes)
        self.inputs = model.inputs(padded) if clock is None else model.inputs(padded, clock)
        self.clock = clock
        self.y = jnp.asarray(padded.p)
        self.n_padded = padded.n_samples
        self.null = np.concatenate([b.null(model, phys_np) for b in blocks])
        self.start = np.concatenate([b.start(model, phys_np) for b in blocks])  # a refit's, per effect
        self.lo = np.concatenate([b.bounds(model, phys_np)[0] for b in blocks])
        self.hi = np.concatenate([b.bounds(model, phys_np)[1] for b in blocks])
        self._phys_np = phys_np
        self._specs = {(1, False): self.spec}
        self._rows = None  # the rows of the fits' own program, once one has run

    def spec_for(self, active) -> Spec:
        """The program for the model made of ``active``: the model itself, or its variant in pieces
        where an active block needs them (``Effect.pieces_for``), with the memory of the samples
        before where one needs it (``Effect.memory``); the parameter vector is the same."""
        pieces = max((b.pieces_for(self.model) for b in self.spec.blocks if b.name in active), default=1)
        own = getattr(getattr(self.model, "structure", None), "pieces", 1)
        pieces = pieces if pieces > own and hasattr(self.model, "with_pieces") else 1
        memory = any(getattr(b, "memory", False) for b in self.spec.blocks if b.name in active) and hasattr(
            self.model, "with_memory"
        )
        if (pieces, memory) not in self._specs:
            model = self.model.with_pieces(pieces) if pieces > 1 else self.model
            model = model.with_memory() if memory else model
            self._specs[pieces, memory] = dataclasses.replace(self.spec, model=model)
        return self._specs[pieces, memory]

    def cost(self, active) -> float:
        """The relative cost of a fit of the model made of ``active``: its segments' pieces (the rod's
        program costs several times the constant-curvature one's)."""
        return float(getattr(getattr(self.spec_for(active).model, "structure", None), "pieces", 1))

    def loaded(self, theta, active) -> bool:
        """Whether the model made of ``active`` at ``theta`` carries a load (the model's ``loaded``;
        True for a model that does not say)."""
        if not hasattr(self.model, "loaded"):
            return True
        return bool(_loaded(self.spec, np.asarray(theta, np.float64), self.on(active), self.phys0, self.inputs))

    @property
    def names(self):
        return [b.name for b in self.spec.blocks]

    def mask(self, active) -> np.ndarray:
        """0/1 over the parameter vector: the blocks named in ``active`` are free."""
        m = np.zeros(self.null.shape[0])
        sl = self.spec.slices()
        for name in active:
            m[sl[name]] = 1.0
        return m

    def on(self, active) -> np.ndarray:
        return np.array([1.0 if b.name in active else 0.0 for b in self.spec.blocks])

    def _args(self, theta0, active, free, rows, w, huber_c, max_iter, cols, n_cols):
        # NumPy arrays straight into the program (a jnp.asarray of each compiled a small program of
        # its own at its first use in a process)
        f, i = np.float64, np.int64
        return (
            self.spec_for(active),
            np.asarray(theta0, f),
            np.asarray(free, f),
            np.asarray(self.on(active), f),
            np.asarray(rows, i),
            np.asarray(w, f),
            np.asarray(huber_c, f),
            np.asarray(self.lo, f),
            np.asarray(self.hi, f),
            self.phys0,
            self.inputs,
            self.y,
            np.asarray(max_iter, i),
            np.asarray(cols, i),
            np.asarray(n_cols, i),
        )

    def _call(self, *args):
        return tuple(np.asarray(x) for x in engine(*self._args(*args)))

    def compile_ahead(self, active, weights) -> threading.Thread | None:
        """Start compiling, on a thread, the program that fits of the model made of ``active`` on
        ``weights`` (N,) and the evaluations after them will run (:func:`engine_ahead`); before the
        process's first fit (which fixes the evaluations' row count) ``weights`` must be the first
        fit's. Returns the thread, or None."""
        w = np.zeros(self.n_padded)
        w[: self.n] = weights
        rows, w = self._fit_rows(w, active)
        free = self.mask(active)
        cols, n_cols = self._fit_cols(free)
        return engine_ahead(*self._args(self.null, active, free, rows, w, np.inf, 0, cols, n_cols))

    def _fit(self, theta0, active, free, weights, huber_c, max_iter) -> np.ndarray:
        theta0 = np.clip(np.asarray(theta0, float), self.lo, self.hi)
        w = np.zeros(self.n_padded)
        w[: self.n] = weights  # padded samples never count
        rows, w = self._fit_rows(w, active)
        cols, n_cols = self._fit_cols(free)
        if not self._path(active):
            self._rows = self._rows or len(rows)  # evaluations from now on run this program
        return self._call(theta0, active, free, rows, w, huber_c, max_iter, cols, n_cols)[0]

    def _evaluate(self, theta, active, jacobian=True, samples=None):
        """Residuals (N, 3) and, with ``jacobian``, their Jacobian (N, 3, P) at ``theta``: before any
        fit, one call of the program over every sample; once a fit has run, calls of the fits'
        program (their rows: :meth:`_fit_rows`) over pieces of the samples, so that a calibration
        compiles one program per model and row count. Every column is differentiated, or none for
        the residuals alone (the engine's column count is data: ``_lsq``'s ``n_cols``). ``samples``
        (K,): only those (path-dependent inputs are still formed over the whole recording), (K, 3)
        and (K, 3, P). A model with memory (:meth:`_path`) runs on every sample in one call."""
        theta = np.clip(np.asarray(theta, float), self.lo, self.hi)
        P, d = self.null.shape[0], self.y.shape[1]
        k = self.n_padded if self._path(active) else (self._rows or self.n_padded)
        if samples is None:
            want = np.arange(self.n)
            rows = np.minimum(np.arange(-(-self.n_padded // k) * k), self.n_padded - 1).reshape(-1, k)
        else:  # the samples asked for, padded with the last of them
            want = np.asarray(samples, int)
            rows = np.r_[want, np.full(-len(want) % k, want[-1])].reshape(-1, k)
        r = np.empty((rows.size, d))
        J = np.empty((rows.size, d, P)) if jacobian else None
        for i, rw in enumerate(rows):
            out = self._call(theta, active, np.zeros(P), rw, np.zeros(k), np.inf, 0, np.arange(P), P if jacobian else 0)
            r[i * k : (i + 1) * k] = out[3]
            if jacobian:
                J[i * k : (i + 1) * k] = out[4]
        return r[: len(want)], (J[: len(want)] if jacobian else None)

    def _path(self, active) -> bool:
        """Whether the model made of ``active`` predicts a sample from the samples before it (a memory:
        ``Effect.memory``): it then solves every sample whatever rows are asked for."""
        return _has_path(self.spec_for(active).model)

    def _fit_rows(self, w, active=()) -> tuple[np.ndarray, np.ndarray]:
        """The samples a fit evaluates: all, or on a large recording of which the fit weighs at most
        ``FIT_ROWS_SHARE`` (a hold-out, a validation file), only its weighted ones (padded to ``FIT_PAD``
        with the last at weight 0): each iteration then costs their share. Once a fit has run, a fit
        of no more rows pads to that fit's count (the same program). A model with memory solves every
        sample anyway: all rows, one program for its fits and evaluations. Returns the rows and their
        weights."""
        if self._path(active):
            return np.arange(self.n_padded), w
        live = np.flatnonzero(w > 0)
        k = len(live) + (-len(live)) % FIT_PAD
        if self._rows and len(live) <= self._rows:
            k = self._rows  # fewer rows than the program has: pad, rather than compile another
        if self.n_padded < FIT_ROWS_MIN or k > FIT_ROWS_SHARE * self.n_padded or not len(live):
            return np.arange(self.n_padded), w
        return np.r_[live, np.full(k - len(live), live[-1])], np.r_[w[live], np.zeros(k - len(live))]

    def _fit_cols(self, free) -> tuple[np.ndarray, int]:
        """The parameters a fit differentiates: every parameter, the free ones first, and how many
        are free (the engine pushes forward only those columns' groups: ``_lsq``'s ``n_cols``)."""
        live = np.asarray(free) > 0
        return np.r_[np.flatnonzero(live), np.flatnonzero(~live)], int(live.sum())

    def jacobian(self, theta, active, samples=None):
        """Residuals (N, 3) and Jacobian (N, 3, P) at ``theta`` of the model made of ``active``; with
        ``samples`` (K,) only those samples' (K, 3), (K, 3, P)."""
        return self._evaluate(theta, active, samples=samples)

    def residuals(self, theta, active, samples=None) -> np.ndarray:
        """Residuals (N, 3) (prediction - measurement); with ``samples`` (K,) only those, (K, 3)."""
        return self._evaluate(theta, active, jacobian=False, samples=samples)[0]

    def predict(self, theta, active) -> np.ndarray:
        return self.residuals(theta, active) + np.asarray(self.y)[: self.n]

    def fit(self, theta0, active, weights, huber_c=np.inf, max_iter=40) -> np.ndarray:
        """Fit the blocks named in ``active`` (the others stay where ``theta0`` has them)."""
        return self._fit(theta0, active, self.mask(active), weights, huber_c, max_iter)

    def labels(self, names) -> list[str]:
        """``block.label`` of every parameter of the named blocks, in vector order."""
        out = []
        for b in self.spec.blocks:
            if b.name in names:
                out += [f"{b.name}.{lab}" for lab in b.labels(self.model, self._phys_np)]
        return out

    def describe(self, theta, names) -> dict:
        """``{block: {label: value}}`` in report units, for the named blocks."""
        out = {}
        sl = self.spec.slices()
        for b in self.spec.blocks:
            if b.name in names:
                vals = b.report_values(np.asarray(theta)[sl[b.name]], self.model, self._phys_np)
                out[b.name] = {k: float(v) for k, v in zip(b.labels(self.model, self._phys_np), np.ravel(vals))}
        return out

    def describe_std(self, theta, names, std) -> dict:
        """Standard deviations ``std`` (P,) of the parameters, in report units (each block's report
        transform is elementwise, so its slope converts them)."""
        out = {}
        sl = self.spec.slices()
        theta = np.asarray(theta, float)
        for b in self.spec.blocks:
            if b.name in names:
                th, sd = theta[sl[b.name]], np.asarray(std)[sl[b.name]]
                h = 1e-6 * np.maximum(np.abs(th), 1.0)
                slope = (
                    np.ravel(b.report_values(th + h, self.model, self._phys_np))
                    - np.ravel(b.report_values(th - h, self.model, self._phys_np))
                ) / (2 * h)
                out[b.name] = {
                    k: (float(v) if np.isfinite(v) else None)
                    for k, v in zip(b.labels(self.model, self._phys_np), np.abs(slope) * sd)
                }
        return out

    def at_bounds(self, theta, names, tol: float = 0.01) -> list[str]:
        """Labels of the named blocks' parameters within ``tol`` of their range from a bound (a bound
        that is also the null value, e.g. a play of 0, does not count)."""
        out = []
        lab = self.labels(names)
        cols = np.flatnonzero(self.mask(names))
        for c, name in zip(cols, lab):
            lo, hi, v = self.lo[c], self.hi[c], float(theta[c])
            span = hi - lo
            if not np.isfinite(span):
                continue
            near = (v <= lo + tol * span and lo != self.null[c]) or (v >= hi - tol * span and hi != self.null[c])
            if near:
                out.append(name)
        return out


def parameter_std(J, r, free, weights) -> np.ndarray:
    """Linearised standard deviations (P,) of the free parameters (0 for the others).

    ``cov = s^2 (J' W J)^-1`` over the free columns, ``s^2`` the residual variance per axis with the
    degrees of freedom of the fit; a pseudo-inverse so a pair that trades off shows large deviations
    instead of failing. Consecutive samples are correlated and the model is never exact, so these are
    optimistic.
    """
    cols = np.flatnonzero(np.asarray(free) > 0)
    w = np.asarray(weights, float)
    Jf = (J[:, :, cols] * np.sqrt(w)[:, None, None]).reshape(-1, len(cols))
    rw = (r * np.sqrt(w)[:, None]).ravel()
    dof = max(int(3 * np.count_nonzero(w)) - len(cols), 1)
    s2 = float(rw @ rw) / dof
    std = np.zeros(J.shape[-1])
    std[cols] = np.sqrt(np.maximum(np.diag(np.linalg.pinv(Jf.T @ Jf)) * s2, 0.0))
    dead = cols[np.abs(Jf).max(axis=0, initial=0.0) == 0]  # a parameter the model ignores (see effects)
    std[dead] = np.nan
    return std


def correlations(J, free, weights, labels, top: int = 5) -> dict:
    """Identifiability: correlations of the free parameters from the Gauss-Newton covariance
    ``(J' W J)^-1``. ``max_abs`` near 1 means a pair trades off freely; ``pairs`` are the ``top``
    largest ``|corr|`` with the parameters' labels (``labels`` of the free columns, in order)."""
    cols = np.flatnonzero(np.asarray(free) > 0)
    w = np.asarray(weights, float)
    Jf = (J[:, :, cols] * np.sqrt(w)[:, None, None]).reshape(-1, len(cols))
    live = np.abs(Jf).max(axis=0, initial=0.0) > 0  # parameters the model ignores have no correlation
    Jf, labels = Jf[:, live], [lab for lab, ok in zip(labels, live) if ok]
    A = Jf.T @ Jf
    cov = np.linalg.pinv(A + 1e-14 * np.trace(A) / max(len(A), 1) * np.eye(len(A)))
    d = np.sqrt(np.maximum(np.diag(cov), 1e-300))
    C = cov / np.outer(d, d)
    iu = np.triu_indices(len(C), 1)
    if not len(iu[0]):
        return {"max_abs": 0.0, "pairs": []}
    order = np.argsort(-np.abs(C[iu]))[:top]
    pairs = [{"a": labels[iu[0][o]], "b": labels[iu[1][o]], "corr": float(C[iu][o])} for o in order]
    return {"max_abs": float(np.abs(C[iu]).max()), "pairs": pairs}
