"""Design-space exploration: many designs x a workspace grid -> per-design statistics.

For every design of a :class:`~tension_zones.design.Space` (one batch and one compiled program per
wire count), the workspace statistics of :data:`STATS` over the space's grid, computed by
:func:`~tension_zones.analysis.sweep_designs` (chunked over designs and poses, bounded memory,
several processes with ``jax.distributed``). With an output folder the exploration is resumable:
each chunk of designs is saved as it arrives and ``manifest.json`` lists the chunks done; run the
same exploration into the same folder and only the missing chunks are computed. The table (one row
per design: its fields and its statistics) goes to ``table.npz`` and ``table.csv``; the Pareto front
of any two or three columns is :func:`pareto_front`.
"""

from __future__ import annotations

import contextlib
import csv
import json
from collections.abc import Callable, Sequence
from pathlib import Path

import jax
import numpy as np

from .._io import LOCK_NAME, atomic_path, folder_lock
from ..analysis._chain import config_metrics
from ..analysis._metrics import DEFAULT_DQ, pose_metrics
from ..analysis._sweep import DEFAULT_DESIGN_CHUNK, DESIGN_POSE_CHUNK, chunk_devices, sweep_designs
from ..model._chain_statics import config_compliance
from ..model._design import Design, read_json
from ..model._robot import Robot
from ..model._statics import as_wrench, compliance_pose
from ._optimise import chain_spread
from ._scenario import wires_label
from ._space import Space

FORMAT = "tension-zones exploration 1"


# --------------------------------------------------------------------------------------------
# The statistics
# --------------------------------------------------------------------------------------------
def _kinematic_pose(design: Design, theta_L, delta, dq):
    """:func:`~tension_zones.pose_metrics` at one pose, and whether it is controllable: at least two
    wires taut, so that the taut wires alone span both configuration directions (tension_zones/MODEL.md Sec. 2; with
    one, the reduced Jacobian has rank 1)."""
    m = pose_metrics(design, theta_L, delta, dq)
    return {**m, "controllable": m["n_taut"] >= 2}


def _kinematic_config(robot: Robot, B, dq):
    """:func:`~tension_zones.analysis.config_metrics` at one configuration ``B`` (S, 2), and whether it
    is controllable: the taut wires span all ``2S`` bending directions (:func:`~._optimise.chain_spread`
    above :data:`SPAN_TOL`; for one segment, two taut wires)."""
    return {**config_metrics(robot, B, dq), "controllable": chain_spread(robot, B) > SPAN_TOL}


#: The smallest singular value of the taut wires' unit directions above which they span (rank 2S).
SPAN_TOL = 1e-9


def _loaded_pose(design: Design, theta_L, delta, dq, wrench):
    """:func:`_kinematic_pose` and the tension-only statics under ``wrench`` (tension_zones/MODEL.md Sec. 4)."""
    return {**_kinematic_pose(design, theta_L, delta, dq), **compliance_pose(design, theta_L, delta, wrench)}


def _loaded_config(robot: Robot, B, dq, wrench):
    """:func:`_kinematic_config` and the robot's tension-only statics under ``wrench``
    (:func:`~tension_zones.model.config_compliance`: pull-only tensions over the whole chain)."""
    return {**_kinematic_config(robot, B, dq), **config_compliance(robot, B, wrench)}


def _stats(loaded: bool) -> tuple[tuple[str, str, str], ...]:
    """``(column, per-pose output, reduction)``: worst (the largest uncertainty or deflection, the
    smallest KCI) and mean of each measure, full and reduced; the controllable fraction; with a load
    the deflections over the poses the wires can hold (NaN elsewhere) and the fraction they can."""
    out = []
    for measure, worst in (("dp_max", "max"), ("dw_max", "max"), ("kci_v", "min"), ("kci_w", "min")):
        for mode in ("full", "reduced"):
            out += [
                (f"{measure}_{mode}_worst", f"{measure}_{mode}", worst),
                (f"{measure}_{mode}_mean", f"{measure}_{mode}", "mean"),
            ]
    out.append(("controllable_fraction", "controllable", "mean"))
    if loaded:
        for measure in ("deflection_mm", "deflection_deg"):
            for mode in ("full", "reduced"):
                out += [
                    (f"{measure}_{mode}_worst", f"{measure}_{mode}", "nanmax"),
                    (f"{measure}_{mode}_mean", f"{measure}_{mode}", "nanmean"),
                ]
        out.append(("statics_feasible_fraction", "feasible", "mean"))
    return tuple(out)


#: Every statistic's column name (those after ``controllable_fraction`` only with a load).
STATS = tuple(s[0] for s in _stats(True))
#: Units of the statistics (by prefix).
UNITS = {
    "dp_max": "mm",
    "dw_max": "rad",
    "kci": "1",
    "deflection_mm": "mm",
    "deflection_deg": "deg",
    "controllable": "1",
    "statics": "1",
}


def sense(column: str) -> str:
    """Whether a column is better small (``"min"``: uncertainties, deflections, design fields) or
    large (``"max"``: KCI, the fractions)."""
    return "max" if column.startswith("kci") or column.endswith("_fraction") else "min"


def objective(column: str) -> tuple[str, str]:
    """``"name"``, ``"min:name"`` or ``"max:name"`` -> ``(name, "min" | "max")`` (bare: :func:`sense`)."""
    prefix, _, name = column.rpartition(":")
    if prefix not in ("", "min", "max"):
        raise ValueError(f"front column {column!r}: the prefix must be 'min:' or 'max:'")
    return name, prefix or sense(name)


def explore_designs(
    designs: Design | Robot,
    theta_L,
    delta,
    dq=DEFAULT_DQ,
    load=None,
    *,
    designs_per_chunk: int = DEFAULT_DESIGN_CHUNK,
    poses_per_chunk: int = DESIGN_POSE_CHUNK,
    quiet: bool = False,
    desc: str | None = None,
    done: dict[int, np.ndarray] | None = None,
    on_chunk: Callable[[int, np.ndarray], None] | None = None,
) -> dict[str, np.ndarray] | None:
    """The workspace statistics (:data:`STATS`) of a batch of designs over a grid, or of robots over
    configurations, in memory.

    Args:
        designs: one wire count's designs, a :class:`Design` whose leaves have a leading axis (N,);
            or robots of one structure, a :class:`Robot` likewise.
        theta_L, delta: the grid's axes (rad); robots: the configurations ``B`` (M, S, 2) and ``None``.
        dq: joint-level uncertainty (mm), traced.
        load: ``None`` or the tip force (3,) / wrench (6,) (N, N mm, base frame), traced: adds the
            compliance statistics.
        designs_per_chunk, poses_per_chunk, quiet, desc, done, on_chunk: see
            :func:`~tension_zones.analysis.sweep_designs`.

    Returns ``{column: (N,)}`` on process 0 (``None`` on the others). Each column equals the NumPy
    reduction of :func:`~tension_zones.sweep_grid`'s (a robot's: ``sweep_configs``') arrays for that
    design (tested to 1e-12).
    """
    args = (np.float64(dq),) if load is None else (np.float64(dq), np.asarray(as_wrench(load)))
    if isinstance(designs, Robot):
        fn: Callable = _kinematic_config if load is None else _loaded_config
    else:
        fn = _kinematic_pose if load is None else _loaded_pose
    return sweep_designs(
        fn,
        designs,
        theta_L,
        delta,
        *args,
        stats=_stats(load is not None),
        designs_per_chunk=designs_per_chunk,
        poses_per_chunk=poses_per_chunk,
        quiet=quiet,
        desc=desc,
        done=done,
        on_chunk=on_chunk,
    )


# --------------------------------------------------------------------------------------------
# The work and memory of an exploration, said and checked before it starts
# --------------------------------------------------------------------------------------------
#: The memory of one compiled chunk, per local device, is about ``chunks.poses x (POSE_BYTES +
#: POSE_BYTES_N2 x n^2)`` bytes for ``n`` wires (the designs are mapped one after the other: the
#: poses of one step are what is held at once; XLA's memory analysis of the program, 3 to 16 wires,
#: with and without a load, kept above it), plus ``chunks.designs x DESIGN_BYTES`` on the host (the
#: chunk's designs and results, with room).
POSE_BYTES, POSE_BYTES_N2, DESIGN_BYTES = 330, 15, 1024
#: A robot's chunk holds about ``chunks.poses x (CONFIG_BYTES + CONFIG_BYTES_N3 x N^3)`` bytes for ``N``
#: wires in all (the exact bound's pair terms beyond ``BOX_VERTICES_MAX`` wires, less up to it; XLA's
#: memory analysis, two and three segments of 3 to 8 wires each, kept above it).
CONFIG_BYTES, CONFIG_BYTES_N3 = 4000, 30
#: With a load, ``CONFIG_BYTES_STATICS + CONFIG_BYTES_SET x 2^N`` bytes more per configuration (the
#: tensions' 2^N free sets, ``model.config_compliance``, whose residuals fuse with their minimum; XLA's
#: memory analysis, 3+3 to 3+3+3+3 wires, kept above it).
CONFIG_BYTES_STATICS, CONFIG_BYTES_SET = 4000, 12


def chunk_memory(space: Space, n) -> int:
    """Estimated peak memory (bytes) of one chunk of ``n``-wire designs of ``space`` (see ``POSE_BYTES``;
    several segments: ``n`` a combination of counts, see ``CONFIG_BYTES``)."""
    devices = len(chunk_devices(bool(space.segments)))
    if space.segments:
        N = sum(n)
        per_pose = (
            CONFIG_BYTES
            + CONFIG_BYTES_N3 * N**3
            + (0 if space.load is None else CONFIG_BYTES_STATICS + CONFIG_BYTES_SET * 2**N)
        )
    else:
        per_pose = POSE_BYTES + POSE_BYTES_N2 * n * n
    return devices * space.poses_per_chunk * per_pose + space.designs_per_chunk * DESIGN_BYTES


#: The most chunks an exploration takes with the resource checks on: each chunk is a file of its own
#: and an update of the manifest, which lists every chunk done (rewritten whole each time).
MAX_CHUNKS = 100_000
#: Design-poses per second of one CPU process at 4 wires, kinematic and with a load (the CPU rates of
#: benchmarks/README.md, "Design-space exploration"); a pose costs about n / 4 times as much for n wires
#: (measured from 3 to 16). The basis of the work estimate (:func:`work_seconds`), off CPUs none.
RATE_KINEMATIC, RATE_LOADED, RATE_WIRES = 2e6, 6e5, 4
#: Design-configurations per second of one CPU process for a robot of ``RATE_CHAIN_WIRES`` wires in all
#: (benchmarks/README.md, "Robots": two segments of 3 + 3 wires); a configuration costs at most about
#: ``(N / RATE_CHAIN_WIRES)^3`` times as much for ``N`` wires (the exact bound's pair terms, ``O(N^3)``;
#: up to ``BOX_VERTICES_MAX`` wires the box's vertices, which cost less: the same table).
RATE_CHAIN, RATE_CHAIN_WIRES = 5e4, 6
#: A load's statics add about ``LOAD_UNITS + LOAD_UNITS_SETS x 2^N N / (2^6 6)`` configurations' worth
#: of that rate (the tensions' 2^N free sets of N wires; explorations of 3+3 to 3+3+3+3 wires, kept
#: above them).
LOAD_UNITS, LOAD_UNITS_SETS = 0.5, 0.25
#: The most computing an exploration takes with the resource checks on, in estimated seconds (a day).
MAX_WORK_S = 86_400
#: How an exploration's refusals say they can be overridden.
OVERRIDE = "or pass --no-resource-check (explore(..., resource_check=False)) to run it anyway"


def work_seconds(space: Space) -> float | None:
    """The estimated computing time of exploring ``space`` (seconds), from the CPU rates
    (``RATE_KINEMATIC``) shared by the run's processes; None off CPUs (no rate to go by)."""
    if jax.default_backend() != "cpu":
        return None
    if space.segments:
        cost = lambda n: _chain_cost(sum(n), space.load is not None) / RATE_CHAIN
    else:
        rate = RATE_KINEMATIC if space.load is None else RATE_LOADED
        cost = lambda n: max(n, RATE_WIRES) / RATE_WIRES / rate
    evals = sum(space.count(n) * space.n_poses * cost(n) for n in space.n_wires)
    return evals / jax.process_count()


def _chain_cost(N: int, loaded: bool) -> float:
    """A robot configuration's cost against one of ``RATE_CHAIN_WIRES`` wires, kinematic: ``(N/6)^3``
    (the exact bound); with a load ``LOAD_UNITS + LOAD_UNITS_SETS x 2^N N / (2^6 6)`` more (the
    statics: the tensions' free sets)."""
    r = max(N, RATE_CHAIN_WIRES)
    cost = (r / RATE_CHAIN_WIRES) ** 3
    sets = (2**r * r) / (2**RATE_CHAIN_WIRES * RATE_CHAIN_WIRES)
    return cost + LOAD_UNITS + LOAD_UNITS_SETS * sets if loaded else cost


def about(seconds: float) -> str:
    """A duration for a message, in the largest unit it fills one and a half times: ``"25 h"``."""
    for unit, size in (("days", 86_400), ("h", 3_600), ("min", 60)):
        if seconds >= 1.5 * size:
            return f"{_rounded(seconds / size)} {unit}"
    return f"{_rounded(seconds)} s"


def _rounded(x: float) -> str:
    return f"{x:.2g}" if x < 100 else f"{x:,.0f}"


def _check_work(space: Space, what: str, chunks: int, seconds: float | None) -> None:
    """Raise a one-line ``ValueError`` where the exploration is larger than the resource checks take:
    more than ``MAX_CHUNKS`` chunks, or more than ``MAX_WORK_S`` of estimated computing."""
    if chunks > MAX_CHUNKS:
        raise ValueError(
            f"{what} in {chunks:,} chunks: more than {MAX_CHUNKS:,} chunks (each is a file and an update of the "
            f'manifest); raise "chunks" ("designs": the designs per chunk, now {space.designs_per_chunk:,}) or '
            f"sample fewer designs, {OVERRIDE}"
        )
    if seconds is not None and seconds > MAX_WORK_S:
        raise ValueError(
            f"{what} would take about {about(seconds)} of computing on {jax.process_count()} CPU process(es) "
            f"(estimated at {_rate_words(space)}), more than {about(MAX_WORK_S)}; sample fewer designs or a "
            f"coarser grid, run it on more processes (--distributed), {OVERRIDE}"
        )


def _rate_words(space: Space) -> str:
    """The rate a work estimate rests on, for a message."""
    if space.segments:
        return f"{RATE_CHAIN:.2g} design-configurations per second per process for {RATE_CHAIN_WIRES} wires, fewer with more"
    rate = RATE_KINEMATIC if space.load is None else RATE_LOADED
    return f"{rate:.2g} design-poses per second per process for {RATE_WIRES} wires, fewer with more"


def plan(space: Space, resource_check: bool = True) -> str:
    """The work of exploring ``space``, in one line: the designs x poses, the chunks, the memory of
    one chunk and the estimated computing time. With ``resource_check``, raises a one-line
    ``ValueError`` where a chunk's memory estimate (:func:`chunk_memory`) is more than the machine has
    (``tension_zones._resources``), or the work more than ``MAX_CHUNKS`` chunks or ``MAX_WORK_S``."""
    from .._resources import check_memory, gb

    n = max(space.n_wires, key=lambda k: chunk_memory(space, k))
    memory = chunk_memory(space, n)
    poses = "configurations" if space.segments else "poses"
    designs = sum(space.count(k) for k in space.n_wires)
    chunks = sum(-(-space.count(k) // space.designs_per_chunk) for k in space.n_wires)
    seconds = work_seconds(space)
    what = f"exploring {designs:,} designs x {space.n_poses:,} {poses} = {designs * space.n_poses:.3g} design-{poses}"
    if resource_check:
        check_memory(
            memory,
            f"a chunk of {space.designs_per_chunk:,} designs x {space.poses_per_chunk:,} {poses} of {wires_label(n)} wires",
            f'lower the space\'s "chunks" ("poses": the poses per step), {OVERRIDE}',
        )
        _check_work(space, what, chunks, seconds)
    time = "" if seconds is None else f"; about {about(seconds)} of computing, estimated"
    return f"{what} in {chunks:,} chunk(s) (about {gb(memory)} of memory per chunk{time})"


# --------------------------------------------------------------------------------------------
# The output folder: manifest, chunk files, table
# --------------------------------------------------------------------------------------------
def _write_atomic(path: Path, write: Callable[[Path], None]) -> None:
    """``write(tmp)`` through :func:`~tension_zones._io.atomic_path`: a file is either complete or absent."""
    with atomic_path(path) as tmp:
        write(tmp)


def _first_difference(a: dict, b: dict) -> str | None:
    for k in sorted(set(a) | set(b)):
        if a.get(k) != b.get(k):
            return k
    return None


class _Store:
    """An exploration's folder (process 0 only): ``manifest.json`` (what is explored, which chunks
    are done), ``chunks/`` (one ``.npy`` per chunk of designs), and at the end the table."""

    def __init__(self, out, space: Space, columns: Sequence[str], log):
        self.out = Path(out)
        self.manifest_path = self.out / "manifest.json"
        ident = {"format": FORMAT, "space": space.raw, "columns": list(columns)}
        if self.out.exists() and not self.out.is_dir():
            raise ValueError(f"the output folder {str(self.out)!r} is a file")
        fresh = not self.out.exists()
        self._lock = contextlib.ExitStack()  # held until :meth:`release`: one exploration per folder
        try:
            self.out.mkdir(parents=True, exist_ok=True)
            self._lock.enter_context(folder_lock(self.out, "explore"))
        except OSError as e:
            if fresh:
                with contextlib.suppress(OSError):
                    self.out.rmdir()
            raise ValueError(f"cannot write the output folder {str(self.out)!r}: {e.strerror or e}") from None
        try:
            self._open(space, ident, log)
        except BaseException:
            self.release()
            raise

    def release(self) -> None:
        """Give the folder's lock back."""
        self._lock.close()

    def _open(self, space: Space, ident: dict, log) -> None:
        if self.manifest_path.exists():
            self.manifest = read_json(self.manifest_path, "exploration manifest")
            old = {k: self.manifest.get(k) for k in ident}
            if old != ident:
                key = _first_difference(old["space"] or {}, ident["space"]) if old["format"] == FORMAT else None  # type: ignore[arg-type]
                what = f"space key {key!r} differs" if key else "another format or statistics"
                raise ValueError(
                    f"{str(self.out)!r} holds another exploration ({what}); refusing to "
                    "mix them: choose a new output folder"
                )
            done = sum(len(v) for v in self.manifest["done"].values())
            if log:
                log(
                    f"resuming the exploration in {str(self.out)!r}: {done} of "
                    f"{self.manifest['chunks_total']} chunks done"
                )
        elif any(p.name != LOCK_NAME for p in self.out.iterdir()):
            raise ValueError(
                f"the output folder {str(self.out)!r} is not empty and holds no exploration; refusing to overwrite it"
            )
        else:
            self.manifest = {
                **ident,
                "done": {wires_label(n): [] for n in space.n_wires},
                "chunks_total": sum(-(-space.count(n) // space.designs_per_chunk) for n in space.n_wires),
                "complete": False,
            }
            try:  # an unwritable folder fails here, before any computation
                (self.out / "chunks").mkdir(parents=True, exist_ok=True)
                self._save_manifest()
            except OSError as e:
                raise ValueError(f"cannot write the output folder {str(self.out)!r}: {e.strerror or e}") from None

    def _chunk_path(self, n, c: int) -> Path:
        return self.out / "chunks" / f"n{wires_label(n)}_{c:06d}.npy"

    def _save_manifest(self) -> None:
        _write_atomic(self.manifest_path, lambda p: p.write_text(json.dumps(self.manifest, indent=1)))  # type: ignore[arg-type,return-value]

    def done(self, n: int) -> dict[int, np.ndarray]:
        """The chunks of ``n`` wires the manifest lists as done, read back (a listed chunk whose file
        has gone is computed again)."""
        paths = {c: self._chunk_path(n, c) for c in self.manifest["done"][wires_label(n)]}
        return {c: np.load(p) for c, p in paths.items() if p.exists()}

    def save(self, n: int, c: int, rows: np.ndarray) -> None:
        """One chunk's rows: the file first, then the manifest (a crash between leaves a file that
        the manifest does not list, computed again on resuming: nothing is lost or counted twice)."""
        _write_atomic(self._chunk_path(n, c), lambda p: np.save(p, rows))
        done = self.manifest["done"][wires_label(n)]
        if c not in done:
            done.append(c)
        self._save_manifest()

    def finish(self, table: dict[str, np.ndarray]) -> list[Path]:
        paths = [self.out / "table.npz", self.out / "table.csv"]
        _write_atomic(paths[0], lambda p: np.savez(p, **table))  # type: ignore[arg-type]
        _write_atomic(paths[1], lambda p: write_csv(table, p))
        self.manifest["complete"] = True
        self._save_manifest()
        return paths


def write_csv(table: dict[str, np.ndarray], path) -> None:
    """A table (columns of equal length) as CSV: a header line, then one row per design."""
    keys = list(table)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(keys)
        for row in zip(*(table[k].tolist() for k in keys)):
            w.writerow(row)


def _open_store(out, space: Space, columns, log) -> _Store | None:
    """The store on process 0; every process learns whether it could be opened (one broadcast), so
    that a refused folder stops all of them instead of leaving the others waiting."""
    store, error = None, None
    if jax.process_index() == 0:
        try:
            store = _Store(out, space, columns, log)
        except (ValueError, OSError) as e:
            error = e
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        ok = bool(multihost_utils.broadcast_one_to_all(np.int32(error is None)))
        if not ok and error is None:
            raise ValueError("process 0 could not open the output folder (see its error)")
    if error is not None:
        raise error
    return store


def explore(
    space: Space, out=None, *, quiet: bool = False, log=None, resource_check: bool = True
) -> dict[str, np.ndarray] | None:
    """Explore a design space: every design's workspace statistics, as one table.

    Args:
        space: from :func:`~tension_zones.load_space` / :func:`~tension_zones.parse_space`.
        out: ``None`` (in memory only) or a folder: a new or empty one, or one holding this same
            exploration, which is then resumed (a folder holding anything else is refused).
        quiet: no progress bar.
        log: called with one line when an exploration is resumed (e.g. ``print``).
        resource_check: refuse, before anything is written, an exploration larger than the machine or
            the checks take (:func:`plan`); False runs it anyway.

    Returns the table ``{column: (N,)}`` (rows: the designs of each wire count in turn; columns:
    ``design``, ``n_wires``, the design fields, ``wire_angle_k_deg``, then :data:`STATS`) on
    process 0, ``None`` on the other processes of a ``jax.distributed`` run. With ``out``, also
    ``manifest.json``, ``chunks/``, ``table.npz`` and ``table.csv`` there (process 0 writes).
    """
    columns = [s[0] for s in _stats(space.load is not None)]
    plan(space, resource_check)  # too large for the machine or the checks: refused before anything is written
    store = None if out is None else _open_store(out, space, columns, log)
    try:
        return _explore(space, store, quiet)
    finally:
        if store is not None:
            store.release()


def _explore(space: Space, store: _Store | None, quiet: bool):
    first = jax.process_index() == 0
    parts = []
    for n in space.n_wires:
        done = store.done(n) if store is not None else None
        on_chunk = (lambda c, rows, n=n: store.save(n, c, rows)) if store is not None else None
        theta_L, delta = (space.configs, None) if space.segments else (space.theta_L, space.delta)
        stats = explore_designs(
            space.batch(n),
            theta_L,
            delta,
            space.dq,
            space.load,
            designs_per_chunk=space.designs_per_chunk,
            poses_per_chunk=space.poses_per_chunk,
            quiet=quiet,
            desc=f"{wires_label(n)} wires",
            done=done,
            on_chunk=on_chunk,
        )
        if first:
            parts.append({**space.columns(n), **stats})  # type: ignore[dict-item]  # (the first process has them)
    if not first:
        return None
    table = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    table = {"design": np.arange(len(table["n_wires"])), **table}
    if store is not None:
        store.finish(table)
    return table


# --------------------------------------------------------------------------------------------
# Pareto front
# --------------------------------------------------------------------------------------------
def _objectives(columns: Sequence[str], known) -> list[tuple[str, float]]:
    """``(column, sign)`` with sign -1 for a column to maximise (:func:`objective`); two or three
    columns, each one of ``known``."""
    if not 2 <= len(columns) <= 3:
        raise ValueError(f"a Pareto front takes two or three columns, got {len(columns)}: {list(columns)}")
    out = []
    for c in columns:
        name, best = objective(c)
        if name not in known:
            raise ValueError(f"front column {name!r} is not a column of the table; columns: {list(known)}")
        out.append((name, -1.0 if best == "max" else 1.0))
    return out


def table_columns(space: Space) -> list[str]:
    """The columns of :func:`explore`'s table for ``space``, in order."""
    stats = [c for c, _, _ in _stats(space.load is not None)]
    return ["design", *space.column_names(), *stats]


def check_front(space: Space, columns: Sequence[str]) -> None:
    """Raise ``ValueError`` (naming it) for a front column the exploration of ``space`` will not have."""
    _objectives(columns, table_columns(space))


def pareto_front(table: dict[str, np.ndarray], columns: Sequence[str]) -> np.ndarray:
    """Which designs are on the Pareto front of two or three columns, (N,) bool.

    A design is on the front when no other design is at least as good in every column and better in
    one (designs with equal values share their fate). Each column is minimised or maximised as
    :func:`sense` says, unless written ``"min:name"`` / ``"max:name"``. Designs with a NaN in these
    columns are not on it.
    """
    obj = _objectives(columns, list(table))
    X = np.stack([s * np.asarray(table[c], float) for c, s in obj], axis=1)  # all minimised
    ok = np.flatnonzero(np.all(np.isfinite(X), axis=1))
    order = ok[np.lexsort(X[ok].T[::-1])]
    Xs = X[order]
    new = np.ones(len(order), bool)  # the first of each run of equal points
    new[1:] = np.any(Xs[1:] != Xs[:-1], axis=1)
    on = np.zeros(len(X), bool)
    on[order] = _undominated(Xs[new])[np.cumsum(new) - 1]
    return on


def _undominated(U):
    """For distinct points sorted lexicographically (every column minimised): which no other point
    dominates. Only an earlier point can dominate one, and, the points being distinct, an earlier
    point at least as good in the other columns does. Two columns: one pass with the running minimum
    of the second. Three: blocks of points against the front so far and against each other
    (vectorised; whatever dominates a point is on the front or dominated by a front member)."""
    if U.shape[1] == 2:
        best = np.minimum.accumulate(np.concatenate([[np.inf], U[:-1, 1]]))
        return U[:, 1] < best
    keep = np.zeros(len(U), bool)
    front = U[:0]
    for start in range(0, len(U), 128):
        B = U[start : start + 128]
        beaten = np.zeros(len(B), bool)
        for other in (front, B):  # [i, j]: other j dominates point i
            le, lt = other[None] <= B[:, None], other[None] < B[:, None]
            beaten |= np.any(np.all(le, axis=2) & np.any(lt, axis=2), axis=1)
        keep[start : start + len(B)] = ~beaten
        front = np.concatenate([front, B[~beaten]])
    return keep


def default_front(space: Space) -> list[str]:
    """Size against performance: the pitch radius (smaller is more compact), the worst reduced
    position uncertainty, and the worst reduced deflection with a load or else the controllable
    fraction. (The statistics alone mostly improve together with a larger radius and stiffer
    wires, so a front of statistics only often holds one design per wire count.)"""
    third = "deflection_mm_reduced_worst" if space.load is not None else "controllable_fraction"
    return ["pitch_radius_mm_max" if space.segments else "pitch_radius_mm", "dp_max_reduced_worst", third]


def structure_groups(table: dict[str, np.ndarray]) -> list[tuple[str, np.ndarray]]:
    """``[(label, rows)]``: the designs of each wire count (several segments: each combination of the
    segments' counts, ``"4+3"``), in order, ``rows`` (N,) bool."""
    per = sorted(k for k in table if k.startswith("n_wires_"))
    keys = np.stack([np.asarray(table[k]) for k in per or ["n_wires"]], axis=1)
    return [
        (wires_label(tuple(u) if per else u[0]), np.all(keys == u, axis=1)) for u in np.unique(keys, axis=0).tolist()
    ]


def summary(table: dict[str, np.ndarray], seconds: float, columns: Sequence[str]) -> str:
    """One line: what was explored and how the front looks."""
    on = pareto_front(table, columns)
    groups = structure_groups(table)
    share = ", ".join(f"{label} wires: {int(np.sum(on & rows))}" for label, rows in groups)
    return (
        f"explored {table['n_wires'].size} designs ({', '.join(label for label, _ in groups)} wires) in "
        f"{seconds:.1f} s; Pareto front of {' vs '.join(columns)}: {int(on.sum())} designs ({share})"
    )
