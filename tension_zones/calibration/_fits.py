"""The loop's fits and held-out errors, run on the main process and on worker processes.

The fits within one round of the loop (:mod:`._loop`) are independent of each other: the candidates'
short refits, their full refits, the backward step's refits without each earlier effect, and at the
end the refits of every accepted model on all samples. :class:`Fits` is what one such fit does (the
same code wherever it runs); :class:`Runner` runs a list of them on the main process and on worker
processes.

**Why processes.** XLA:CPU runs one call of the calibration engine on about one core, so on a machine
with more cores the others idle through the loop.
Threads cannot use it: two Python threads executing the engine at once deadlocked
(``benchmarks/README.md``). Each worker is a process with its own copy of the :class:`Problem` (model,
robot, data and blocks, pickled once at the start) and its own compiled programs. The main process
hands the list's fits to the workers from the front and takes them itself from the back (the ones no
worker has started), so no core idles while a worker compiles or a fit is long. Results are bit for
bit the ones of a run without workers: the same program on the same inputs, and the loop's decisions
look at the list's results in the list's order.

**Warm-up.** A worker's first job is to compile the programs the loop may need: the rod's (the
variable-curvature effect's, ``Effect.pieces_for``) first, then the constant-curvature one (which the main
process compiles meanwhile: with the cache on, the worker loads it), then the final refit's on every
sample (where the loop's fits run on their own rows, :meth:`Problem._fit_rows`). With the compilation
cache on (``tension_zones._xla``), before the main process first runs the rod or the final refit it
waits for the worker's job if that has started (and cancels it if not), and loads the worker's
program instead of compiling its own (a compile is a large part of a small calibration). Without a
worker (a small recording), a spare core still compiles the rod's program where the first round will
score it for sure (the model carries a load from the start): the main process traces and lowers it,
then XLA compiles it on a thread (:meth:`Problem.compile_ahead`) while the main process traces,
compiles and fits the constant-curvature model, which shortens the run's wall time. Likewise the final refit's
program, once the first fit has run, where it is another (:meth:`Runner.ahead`). Only programs the
loop will run: a compile still running at the end is waited for.

**Where workers are started.** Python's ``spawn`` starts a worker by importing the calling program's
main module again: a script whose top level calls :func:`calibrate` without an
``if __name__ == "__main__":`` guard would run again in every worker. So by default (``workers=None``)
workers are used only where that cannot happen: an interactive session or notebook, ``python -c``,
``python -m``, the ``tension-zones`` command; and only for problems large enough to win back a
worker's start (``MIN_WORK``). ``TENSION_ZONES_WORKERS`` (a count) overrides the default; a script
with the guard passes ``workers=`` itself.
"""

from __future__ import annotations

import contextlib
import os
import sys

import numpy as np

from .._resources import cores

#: Worker processes by default: one per core beyond the first, at most this many (a round has 4-10
#: independent fits, and each worker holds its own programs: ~0.7 GB for the FTDCR v4 robot).
MAX_WORKERS = 4
#: ... for problems of at least this many samples x segments: a worker costs a process start and
#: loading its programs, which a small problem's fits do not win back (a worker shortens the FTDCR v4
#: calibration, 2063 samples x 3 segments, and lengthens the 500-sample single-segment one;
#: benchmarks/README.md).
MIN_WORK = 1024
#: A calibration's peak memory per process (the main one and each worker) is about
#: ``MEMORY_BASE + MEMORY_PER_SAMPLE x samples x segments`` bytes: the compiled programs, then the
#: Jacobians, the fits' intermediates and the structure test's shuffles, which grow with the samples.
#: Fitted to the peak resident memory of single-segment recordings of 1000 to 8000 samples, the
#: steepest slope between them kept.
MEMORY_BASE = 0.75e9
MEMORY_PER_SAMPLE = 126e3
#: The loop's short refits, in Levenberg-Marquardt passes.
SCREEN_ITERATIONS = 6
#: An effect of the clock is judged on the recording's last this share (acquisition order), fitted
#: before it: the share the hold-out of an unlabelled recording takes from its tail.
LATER_SHARE = 0.25
#: In robust mode a held-out sample beyond this many noise sigmas (3-D) is a glitch for decisions.
GLITCH_C = 8.0


def rmse(r) -> float:
    """Tip-position RMSE (mm) of residuals (M, 3): ``sqrt(mean |r|^2)``."""
    r = np.asarray(r)
    return float(np.sqrt(np.mean(np.sum(r**2, axis=1)))) if len(r) else float("nan")


def glitch_weights(r, sigma) -> np.ndarray:
    """0 for the rows (M, 3) of ``r`` that robust mode takes for tracker glitches, 1 for the others."""
    n = np.linalg.norm(r, axis=1)
    c = max(GLITCH_C * float(np.mean(sigma)), 5.0 * float(np.median(n)))
    return np.where(n <= c, 1.0, 0.0)


class Fits:
    """The fits of one calibration: a :class:`Problem`, its training and held-out samples (boolean
    (N,) masks over the problem's samples) and the loss (least squares, or ``robust``: a Huber loss
    whose threshold follows the residual's scale, and held-out errors without glitches). ``sigma``
    (3,), the noise per axis in mm, is set by the loop once it is known."""

    def __init__(self, pb, train, held, robust: bool = False):
        self.pb, self.train, self.held, self.robust = pb, np.asarray(train), np.asarray(held), robust
        self.w_train = self.train.astype(float)
        self.w_all = (self.train | self.held).astype(float)
        self.held_idx = np.flatnonzero(self.held)
        # the later samples: the last LATER_SHARE of the data file in acquisition order
        rows = np.flatnonzero(self.train | self.held)
        cut = rows[min(round((1.0 - LATER_SHARE) * len(rows)), len(rows) - 1)]
        self.w_early = (self.train & (np.arange(len(self.train)) < cut)).astype(float)
        self.late_idx = np.flatnonzero(self.held & (np.arange(len(self.held)) >= cut))
        self.sigma: np.ndarray | None = None

    def fit(self, theta0, active, weights=None, max_iter: int = 40) -> np.ndarray:
        """The blocks ``active`` fitted from ``theta0`` (P,) on ``weights`` (default: the training part)."""
        pb, weights = self.pb, self.w_train if weights is None else weights
        if not self.robust:
            return pb.fit(theta0, active, weights, max_iter=max_iter)
        th, mask = theta0, weights > 0
        for _ in range(2):  # the Huber threshold follows the residual's scale (3.5 noise sigmas at least)
            r = pb.residuals(th, active)[mask]
            scale = np.median(np.linalg.norm(r, axis=1)) / 1.54  # median of a 3-D chi is 1.54 sigma
            c = max(2.5 * scale, 3.5 * (float(np.mean(self.sigma)) if self.sigma is not None else scale))
            th = pb.fit(th, active, weights, huber_c=c, max_iter=max_iter)
        return th

    def decision_error(self, r, mask) -> float:
        """The RMSE used for decisions: robust mode leaves tracker glitches out."""
        if not self.robust:
            return rmse(r[mask])
        return rmse(r[mask][glitch_weights(r[mask], self.sigma) > 0])

    def held_error(self, theta, active):
        """(plain RMSE, the error used for decisions, residuals (N, 3)) on the held-out part."""
        r = self.pb.residuals(theta, active)
        return rmse(r[self.held]), self.decision_error(r, self.held), r

    def held_only(self, theta, active):
        """(plain RMSE, the error used for decisions) on the held-out part, evaluating only its samples
        (a short refit's or a removal's verdict needs no others)."""
        rh = self.pb.residuals(theta, active, samples=self.held_idx)
        return rmse(rh), self.decision_error(rh, np.ones(len(rh), bool))

    # -- the loop's jobs: each a fit and what the loop needs of it -----------------------------------

    def screen(self, theta0, active):
        """A short refit (``SCREEN_ITERATIONS`` passes, least squares) and its held-out error."""
        th = self.pb.fit(theta0, active, self.w_train, max_iter=SCREEN_ITERATIONS)
        return self.held_only(th, active)[1]

    def refit(self, theta0, active):
        """A full refit on the training part: (theta, plain held-out RMSE, decision error, residuals)."""
        th = self.fit(theta0, active)
        return (th, *self.held_error(th, active))

    def refit_held_only(self, theta0, active):
        """A full refit on the training part: (theta, plain held-out RMSE, decision error)."""
        th = self.fit(theta0, active)
        return (th, *self.held_only(th, active))

    def later(self, theta0, active, theta_base, base_active):
        """An effect of the clock judged as it is used, on samples after those it was fitted on: the
        models ``active`` (from ``theta0``) and ``base_active`` (from ``theta_base``) fitted on the
        training samples before the recording's last ``LATER_SHARE``, then evaluated on the held-out
        samples in it. Returns (sum of squares with, without, their count)."""
        if len(self.late_idx) == 0:
            return 0.0, 0.0, 0
        th1 = self.fit(theta0, active, self.w_early)
        th0 = self.fit(theta_base, base_active, self.w_early)
        sse = [
            float(np.sum(self.pb.residuals(th, a, samples=self.late_idx) ** 2))
            for th, a in ((th1, active), (th0, base_active))
        ]
        return sse[0], sse[1], len(self.late_idx)

    def refit_all(self, theta0, active, residuals: bool = True):
        """A refit on every sample of the data file: (theta, residuals (N, 3) or None)."""
        th = self.fit(theta0, active, self.w_all)
        return th, (self.pb.residuals(th, active) if residuals else None)

    def warm(self, active, part: str) -> None:
        """Compile (or load) the program of the model made of the blocks ``active`` fitted on the
        training part (``part = "train"``) or on every sample (``"all"``), with the shape the loop's fits
        will have (a process's first fit fixes the shape of its later evaluations, as the loop's first
        fit does: the first must be a ``"train"`` one)."""
        self.pb.fit(self.pb.null, active, self.w_train if part == "train" else self.w_all, max_iter=0)

    def ahead(self, active, part: str):
        """Start compiling the program :meth:`warm` would make, on a thread of this process, without
        running it (:meth:`Problem.compile_ahead`): the thread, or None."""
        return self.pb.compile_ahead(active, self.w_train if part == "train" else self.w_all)


# -- worker processes ---------------------------------------------------------------------------------

_WORKER: Fits | None = None


def _start(problem_args, train, held, robust) -> None:
    """A worker's initializer: its own :class:`Problem` and :class:`Fits`."""
    global _WORKER
    from ._problem import Problem

    _WORKER = Fits(Problem(*problem_args), train, held, robust)


def _job(method, sigma, args):
    _WORKER.sigma = sigma
    return getattr(_WORKER, method)(*args)


def worker_count(workers=None, work: int | None = None) -> int:
    """The number of worker processes: ``workers`` (checked), or for None ``TENSION_ZONES_WORKERS`` if
    set, else one per core beyond the first (at most ``MAX_WORKERS``) where starting them is safe (see
    the module) and the problem is large enough (``work``, its samples x segments, at least
    ``MIN_WORK``), else 0. A count asked for is capped at one per core beyond the first (at least
    one): a fit runs on about one core, so more only share the cores, each with its own programs."""
    cap = max(cores() - 1, 1)
    if workers is not None:
        if isinstance(workers, bool) or not isinstance(workers, int | np.integer) or workers < 0:
            raise ValueError(f"workers must be a whole number, 0 or more, got {workers!r}")
        return min(int(workers), cap)
    env = os.environ.get("TENSION_ZONES_WORKERS", "").strip()
    if env:
        if not env.isdigit():
            raise ValueError(f"TENSION_ZONES_WORKERS must be a whole number, 0 or more, got {env!r}")
        return min(int(env), cap)
    if work is not None and work < MIN_WORK:
        return 0
    main = sys.modules.get("__main__")
    script = getattr(main, "__file__", None) is not None and getattr(main, "__spec__", None) is None
    if script and os.path.basename(sys.argv[0] or "") != "tension-zones":
        return 0  # a plain script: spawn would run its top level again in every worker
    return max(0, min(cores() - 1, MAX_WORKERS))


def peak_memory(work: int, workers: int = 0) -> float:
    """Estimated peak memory (bytes) of a calibration of ``work`` samples x segments (the validation
    file's samples too) with ``workers`` worker processes (``MEMORY_BASE``)."""
    return (1 + workers) * (MEMORY_BASE + MEMORY_PER_SAMPLE * work)


def spare_core() -> bool:
    """Whether this process may use more than one core."""
    return cores() > 1


class Runner:
    """Runs :class:`Fits` jobs for the loop: on the main process's ``fits`` alone (``workers = 0``),
    or there and on ``workers`` processes, each holding the problem ``problem_args`` (the
    :class:`Problem` constructor's arguments). ``warm``: ``{name: (active, part)}``, the programs a
    worker compiles first, in this order (:meth:`Fits.warm`). Use as a context manager (the workers
    end with it)."""

    def __init__(self, fits: Fits, workers: int = 0, problem_args=None, warm=None):
        self.fits, self.pool, self._warm, self._warm_args = fits, None, {}, dict(warm or {})
        self._threads: list = []
        if workers > 0:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            self.pool = ProcessPoolExecutor(
                workers,
                mp_context=multiprocessing.get_context("spawn"),
                initializer=_start,
                initargs=(problem_args, fits.train, fits.held, fits.robust),
            )
            self._warm = {
                k: self.pool.submit(_job, "warm", None, (list(a), part)) for k, (a, part) in (warm or {}).items()
            }

    def __enter__(self):
        return self

    def __exit__(self, kind, *exc):
        self.close(abort=kind is not None)

    def close(self, abort: bool = False) -> None:
        """End the workers. ``abort`` (an error or Ctrl-C): without waiting for the compiles on threads
        or the workers' jobs (a worker's fit may run for minutes, and the interpreter's exit would wait
        for it), the workers are killed."""
        if not abort:
            for t in self._threads:  # no compile may outlive the calibration (nor run at interpreter exit)
                t.join()
        self._threads = []
        if self.pool is not None:
            procs = list((getattr(self.pool, "_processes", None) or {}).values()) if abort else []
            for p in procs:
                p.kill()
            self.pool.shutdown(wait=False, cancel_futures=True)
            self.pool = None

    def ahead(self, name: str) -> None:
        """Without workers, on a machine with a spare core: start compiling the program ``name`` of
        ``warm`` on a thread now (:meth:`Fits.ahead`; the loop asks only for programs it will run).
        With workers, the workers' warm-up does it."""
        if self.pool is None and spare_core() and name in self._warm_args:
            active, part = self._warm_args[name]
            if (t := self.fits.ahead(list(active), part)) is not None:
                self._threads.append(t)

    def warmed(self, name: str) -> None:
        """Before the main process first runs the program ``name`` of ``warm``: where a worker is
        compiling it and the main process can load it (the compilation cache is on), wait for it; where
        no worker has started it, the main process compiles its own (and no worker starts it now)."""
        from .._xla import cache_dir

        f = self._warm.pop(name, None)
        if f is None or self.pool is None or cache_dir() is None or f.cancel():
            return
        with contextlib.suppress(Exception):  # a worker that failed: the main process compiles its own
            f.result()

    def map(self, method: str, jobs: list) -> list:
        """``getattr(fits, method)(*args)`` for every ``args`` in ``jobs`` (each ``(theta0, active, ...)``),
        results in their order. The workers start with the costliest (:meth:`Problem.cost` of the job's
        ``active``: the rod's fits cost several of the constant-curvature model's), so that the
        longest job does not start last."""
        if self.pool is None or len(jobs) < 2:
            return [self._local(method, a) for a in jobs]
        from concurrent.futures.process import BrokenProcessPool

        cost = [self.fits.pb.cost(a[1]) for a in jobs]
        order = sorted(range(len(jobs)), key=lambda i: -cost[i])
        try:
            futures = {i: self.pool.submit(_job, method, self.fits.sigma, tuple(jobs[i])) for i in order}
        except (BrokenProcessPool, RuntimeError):
            self.close()
            return [self._local(method, a) for a in jobs]
        out, mine = [None] * len(jobs), set()
        for i in reversed(order):  # the main process works from the back
            if not futures[i].cancel():
                break  # a worker has this one, and every one before it
            out[i] = self._local(method, jobs[i])
            mine.add(i)
        for i in order:
            if i in mine:
                continue
            try:
                out[i] = futures[i].result()
            except BrokenProcessPool:  # a worker died (killed, out of memory): the main process goes on
                self.close()
                out[i] = self._local(method, jobs[i])
        return out

    def _local(self, method, args):
        return getattr(self.fits, method)(*args)
