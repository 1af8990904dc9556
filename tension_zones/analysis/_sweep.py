"""A generic, chunked, shardable sweep engine for per-pose measures.

Any pure single-pose function ``fn(design, theta_L, delta, *args) -> dict[str, array]`` (e.g.
:func:`tension_zones.analysis.pose_metrics`) is swept over a workspace grid (:func:`sweep_grid`) or a
flat list of poses (:func:`sweep_poses`):

* **bounded memory**: poses are evaluated in fixed-size chunks by one compiled ``vmap`` (every
  chunk, the last and a small sweep's only one included, is padded to ``chunk_size`` poses per
  device, so there is exactly one compilation per function, wire count and chunk size, whatever
  the grid; :func:`sweep_grid` generates its poses on the device from the two axis vectors, padded
  to a chunk, unless an axis is longer than a chunk); only the results live on the host,
  preallocated once, one block per dtype with each output a row of it (``keep=`` drops the outputs
  you do not need). A 10^7-pose sweep of the 17 kinematic measures takes about 1.3 GB of results.
* **no recompiles when only values change**: the design's numbers and the extra ``args`` are traced
  arguments; ``fn`` is a static argument (pass the same function object to reuse the compiled code).
* **progress**: a ``tqdm`` bar on sweeps of more than one chunk, unless ``quiet``.
* **several devices**: the pose axis of each chunk is sharded over ``devices`` (default: every local
  device; a robot's, one CPU device: :func:`chunk_devices`) with :mod:`jax.sharding`; the design and ``args``
  are replicated. Each device runs the same ``chunk_size``-pose program and a pose always sits at the
  same position of its device's block (``index mod chunk_size``), so results are bit-for-bit
  identical on one device or many.
"""

from __future__ import annotations

import collections
import contextlib
import functools
import math
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from .._numerics import mask_table, shared_mask_table, uses_mask_table
from ..model._design import Design
from ..model._robot import Robot

#: Poses per chunk and device: 2^14 keeps the working set of the kinematic measures near 50 MB.
DEFAULT_CHUNK = 1 << 14


def default_chunk(n_wires: int) -> int:
    """Poses per chunk for a wire count: :data:`DEFAULT_CHUNK` up to 8 wires; above, where the
    measures take (n, n) pair terms per pose, smaller by ``(8 / n)^2`` (a power of two, at least
    256), so that the working set stays near its 8-wire size (64 wires at 2^14 poses: 2.6 GB)."""
    if n_wires <= 8:
        return DEFAULT_CHUNK
    return max(256, DEFAULT_CHUNK >> (2 * math.ceil(math.log2(n_wires / 8))))


#: Configurations per chunk of a robot's sweep (:func:`sweep_configs`): its exact bounds take
#: (N^2 / 2, N) pair terms per configuration, so a chunk is smaller than a segment's. A function
#: whose working set is known may say otherwise (:func:`robot_chunk`).
ROBOT_CHUNK = 1 << 11


def robot_chunk(fn: Callable, robot: Robot) -> int:
    """The default chunk of :func:`sweep_configs` for ``fn``: ``fn.chunk_size(robot)`` where ``fn``
    has one (a measure that knows its working set, e.g. :func:`~._chain.config_metrics`), else
    :data:`ROBOT_CHUNK`."""
    rule = getattr(fn, "chunk_size", None)
    return int(rule(robot)) if callable(rule) else ROBOT_CHUNK


#: Chunks dispatched at once: the CPU runtime runs independent programs concurrently, so the cores
#: stay busy while an earlier chunk's results are copied out and the next one is launched (a short
#: chunk's program alone leaves them partly idle; a long one's already fills them).
IN_FLIGHT = 3


def grid_deg(stop: float, step: float, start: float = 0.0) -> np.ndarray:
    """``start, start + step, ...`` up to ``stop`` **inclusive** (degrees), as the paper's grids.

    ``grid_deg(85, 5)`` is 0, 5, ..., 85 (18 values); ``grid_deg(360, 2.5)`` is 0, ..., 360 (145).
    """
    return start + step * np.arange(grid_size(stop, step, start), dtype=float)


def grid_size(stop: float, step: float, start: float = 0.0) -> int:
    """The number of values of :func:`grid_deg` (checked without building the grid)."""
    if not (math.isfinite(step) and step > 0):
        raise ValueError(f"a grid step must be a positive number of degrees, got {step}")
    if not (math.isfinite(start) and math.isfinite(stop)) or stop < start:
        raise ValueError(f"a grid needs start <= stop, got {start} .. {stop}")
    return int(math.floor((stop - start) / step + 1e-9)) + 1


def _eval_chunk(fn, subject, poses, args, tables=None):
    """``fn(subject, *pose, *args)`` vmapped over a chunk's poses (a tuple of arrays, one row a pose);
    ``tables``: a robot's routing matrix and its :func:`~tension_zones._numerics.mask_table`, made once
    for the whole sweep (:func:`_robot_tables`)."""
    with shared_mask_table(*tables) if tables is not None else contextlib.nullcontext():
        out = jax.vmap(lambda *pose: fn(subject, *pose, *args))(*poses)
    if not isinstance(out, dict):
        raise TypeError(f"a swept function must return a dict of arrays, got {type(out).__name__}")
    return out


_eval_chunk_jit = jax.jit(_eval_chunk, static_argnums=0)


@jax.jit
def _robot_tables(robot: Robot):
    """A robot's ``J_qB`` and the pseudo-inverse of its rows for every mask of taut wires: what a
    chunk's reduced Jacobians are looked up in (``Robot.J_xq``), made once per sweep."""
    A = robot.J_qB()
    return A, mask_table(A)


def _grid_index(start, chunk, n_poses):
    """Flat indices ``start, ..., start + chunk - 1`` into a grid's poses; past the last pose, the
    last pose again (padding), and whether each index is a real pose."""
    i = start + jnp.arange(chunk, dtype=start.dtype)
    return jnp.minimum(i, n_poses - 1), i < n_poses


def _grid_poses(i, th_grid, de_grid, n_de):
    """The poses ``(theta_L, delta)`` at flat indices ``i`` of a row-major grid (``delta`` fastest)."""
    return th_grid[i // n_de], de_grid[i % n_de]


def _pad_axes(grid, size, dtype):
    """The grid's two axis vectors, each zero-padded to ``size``: the program sees no grid shape."""
    return tuple(np.concatenate([np.asarray(x, dtype), np.zeros(size - len(x), dtype)]) for x in grid)


def _eval_grid_chunk(fn, layout, design, start, th_grid, de_grid, n_de, n_poses, args):
    """:func:`_eval_chunk` on grid poses ``start, start + 1, ...`` (row-major, ``delta`` fastest),
    generated on the device: no pose arrays cross from the host per chunk (a copy that competes with
    the computation for the cores). ``layout = (chunk, sharding)`` (static) fixes the chunk; the
    padding past the last pose repeats the last pose. The axis vectors come padded to the chunk
    size, so the program depends on no grid dimension."""
    chunk, sharding = layout
    i = jax.lax.with_sharding_constraint(_grid_index(start, chunk, n_poses)[0], sharding)
    return _eval_chunk(fn, design, _grid_poses(i, th_grid, de_grid, n_de), args)


_eval_grid_chunk_jit = jax.jit(_eval_grid_chunk, static_argnums=(0, 1))


def compiled_chunk_count() -> int:
    """How many chunk programs have been compiled so far (one per function, wire count, chunk size
    and kind: flat poses, a grid whose poses are generated on the device, or per-design statistics
    of :func:`sweep_designs`, also one per set of statistics), with a robot's shared table's."""
    jits: list[Any] = [_eval_chunk_jit, _eval_grid_chunk_jit, _designs_chunk_jit, _robot_tables]  # (their own counts)
    return sum(f._cache_size() for f in jits)


def _mesh(devices, subject):
    """The mesh a chunk's poses are sharded over (:func:`chunk_devices`)."""
    devices = chunk_devices(isinstance(subject, Robot), devices)
    return Mesh(np.array(devices), ("poses",)), len(devices)


def chunk_devices(robot: bool, devices=None) -> list:
    """The devices a chunk runs on: ``devices`` (default: every local device). A robot's chunk runs on
    one CPU device: XLA:CPU deadlocks running a three-segment robot's measures over several host
    devices (``--xla_force_host_platform_device_count``), where one device gains nothing (one program
    runs at a time, on the cores it can use)."""
    given = devices is not None
    devices = list(jax.local_devices() if devices is None else devices)
    if not devices:
        raise ValueError("devices must name at least one device")
    if robot and len(devices) > 1 and all(d.platform == "cpu" for d in devices):
        if given:
            raise ValueError(
                f"a robot's sweep runs on one CPU device, got {len(devices)}: XLA:CPU deadlocks sharding it "
                "over host devices; pass devices=[one] or leave devices out"
            )
        devices = devices[:1]
    return devices


def _subject_dtype(subject) -> np.dtype:
    """The float dtype of a Design or a Robot (a robot's routing carries its segments' dtype)."""
    if isinstance(subject, Design):
        return subject.dtype
    if isinstance(subject, Robot):
        return np.dtype(subject.route_angles.dtype)
    raise TypeError(f"design must be a tension_zones.Design or Robot, got {type(subject).__name__}")


def _run(fn, design, n_poses, poses_of, args, chunk_size, devices, quiet, keep, desc, grid=None):
    """Core loop: evaluate ``fn`` on poses ``poses_of(start, stop)`` (a tuple of host arrays, one row a
    pose) or, given ``grid = (theta_L, delta)`` with both axes no longer than a chunk, on that grid's
    poses generated on the device; results flat (N, ...). ``design`` is a Design or a Robot."""
    dt = _subject_dtype(design)
    if chunk_size is None:
        chunk_size = default_chunk(design.n_wires) if isinstance(design, Design) else robot_chunk(fn, design)
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)) or chunk_size < 1:
        raise ValueError(f"chunk_size must be a positive integer, got {chunk_size!r}")
    mesh, n_dev = _mesh(devices, design)
    chunk = int(chunk_size) * n_dev  # every device always gets chunk_size poses (see module doc)
    batch, replicated = NamedSharding(mesh, PartitionSpec("poses")), NamedSharding(mesh, PartitionSpec())
    design_d = jax.device_put(design, replicated)
    share = isinstance(design, Robot) and grid is None and uses_mask_table(design.n_wires, chunk)
    tables = _robot_tables(design_d) if share else None
    args_d = jax.device_put(jax.tree_util.tree_map(np.asarray, tuple(args)), replicated)

    if grid is not None and max(x.size for x in grid) > chunk:
        grid = None  # an axis longer than a chunk: the poses come from the host (poses_of)
    if grid is not None:
        # the grid's axes on the device once (padded to the chunk size: the program does not depend on
        # the grid's shape); each chunk is then only a start index
        th_g, de_g = _pad_axes(grid, chunk, dt)
        idx_t = np.int64 if n_poses + chunk >= 2**31 else np.int32
        grid_d = jax.device_put((th_g, de_g, idx_t(grid[1].size), idx_t(n_poses)), replicated)

    def launch(start):
        stop = min(start + chunk, n_poses)
        if grid is not None:
            th_g, de_g, n_de, n_all = grid_d
            res = _eval_grid_chunk_jit(fn, (chunk, batch), design_d, idx_t(start), th_g, de_g, n_de, n_all, args_d)
            return start, stop, res
        poses = [np.asarray(x, dt) for x in poses_of(start, stop)]
        if stop - start < chunk:  # pad with the first pose: one compiled shape for every chunk
            poses = [np.concatenate([x, np.repeat(x[:1], chunk - (stop - start), axis=0)]) for x in poses]
        res = _eval_chunk_jit(fn, design_d, tuple(jax.device_put(x, batch) for x in poses), args_d, tables)
        return start, stop, res

    results: dict[str, np.ndarray] = {}

    def store(start, stop, res):
        if not results:
            missing = sorted(set(keep or ()) - set(res))
            if missing:
                raise ValueError(f"keep names unknown output(s) {missing}; the function returns {sorted(res)}")
            # one block per dtype and shape, each output a row of it: a few large allocations, which
            # NumPy backs with huge pages, rather than one per output (whose 4 KB pages would each
            # fault on first touch: many times as many page faults on a large sweep)
            groups = collections.defaultdict(list)
            for k, v in res.items():
                if keep is None or k in keep:
                    groups[(v.dtype, v.shape[1:])].append(k)
            for (dtype, shape), keys in groups.items():
                results.update(zip(keys, np.empty((len(keys), n_poses) + shape, dtype)))
        for k, out in results.items():
            out[start:stop] = np.asarray(res[k])[: stop - start]  # slice on the host: no dispatch

    starts = range(0, n_poses, chunk)
    with _progress(n_poses, desc, disable=quiet or len(starts) < 2) as bar:
        pending = collections.deque()
        for start in starts:
            # dispatched asynchronously: up to IN_FLIGHT chunks run while the oldest is copied out
            pending.append(launch(start))
            if len(pending) >= IN_FLIGHT:
                _store_oldest(pending, store, bar)
        while pending:
            _store_oldest(pending, store, bar)
    return results


def _store_oldest(pending, store, bar):
    start, stop, res = pending.popleft()
    store(start, stop, res)
    bar.update(stop - start)


def _progress(total, desc, disable, unit="pose", initial=0):
    from tqdm import tqdm

    return tqdm(
        total=total,
        desc=desc or "sweep",
        unit=unit,
        unit_scale=True,
        disable=disable,
        leave=False,
        dynamic_ncols=True,
        initial=initial,
    )


def sweep_poses(
    fn: Callable,
    design: Design,
    theta_L,
    delta,
    *args,
    chunk_size: int | None = None,
    devices: Sequence | None = None,
    quiet: bool = False,
    keep: Sequence[str] | None = None,
    desc: str | None = None,
) -> dict[str, np.ndarray]:
    """Evaluate ``fn(design, theta_L[i], delta[i], *args)`` for every pose ``i``.

    Args:
        fn: pure single-pose function returning a dict of arrays (same shapes at every pose).
        design: the segment (its values are traced: new values reuse the compiled code).
        theta_L, delta: (N,) poses in rad.
        *args: extra arguments shared by all poses (traced, e.g. ``dq``).
        chunk_size: poses per device and compiled call (a chunk is ``chunk_size`` x devices);
            ``None``: :func:`default_chunk` of the wire count.
        devices: devices to shard each chunk's pose axis over (default: all local devices).
        quiet: no progress bar.
        keep: names of the outputs to keep (default: all).

    Returns a dict of NumPy arrays ``(N, ...)``.
    """
    th = np.asarray(theta_L, dtype=float)
    de = np.asarray(delta, dtype=float)
    if th.ndim != 1 or th.shape != de.shape:
        raise ValueError(f"theta_L and delta must be 1-D of equal length, got {th.shape} and {de.shape}")
    return _run(fn, design, th.size, lambda a, b: (th[a:b], de[a:b]), args, chunk_size, devices, quiet, keep, desc)


def sweep_configs(
    fn: Callable,
    robot: Robot,
    B,
    *args,
    chunk_size: int | None = None,
    devices: Sequence | None = None,
    quiet: bool = False,
    keep: Sequence[str] | None = None,
    desc: str | None = None,
) -> dict[str, np.ndarray]:
    """Evaluate ``fn(robot, B[i], *args)`` for every configuration ``i`` of a robot.

    Args:
        fn: pure single-configuration function returning a dict of arrays, e.g.
            :func:`tension_zones.analysis.config_metrics`.
        robot: the robot (its numbers are traced: new values reuse the compiled code).
        B: (M, S, 2) configurations, rad (e.g. :func:`tension_zones.analysis.config_samples`).
        chunk_size: configurations per device and compiled call (default :func:`robot_chunk`); the
            other arguments as :func:`sweep_poses`.

    Returns a dict of NumPy arrays ``(M, ...)``.
    """
    if not isinstance(robot, Robot):
        raise TypeError(f"robot must be a tension_zones.Robot, got {type(robot).__name__}")
    B = np.asarray(B, dtype=float)
    if B.ndim != 3 or B.shape[1:] != (robot.n_segments, 2):
        raise ValueError(f"B must have shape (M, {robot.n_segments}, 2) for this robot, got {B.shape}")
    return _run(fn, robot, B.shape[0], lambda a, b: (B[a:b],), args, chunk_size, devices, quiet, keep, desc or "sweep")


def sweep_grid(
    fn: Callable,
    design: Design,
    theta_L,
    delta,
    *args,
    chunk_size: int | None = None,
    devices: Sequence | None = None,
    quiet: bool = False,
    keep: Sequence[str] | None = None,
    desc: str | None = None,
) -> dict[str, np.ndarray]:
    """Evaluate ``fn`` on the grid ``theta_L (n_theta,) x delta (n_delta,)`` (rad).

    Same arguments as :func:`sweep_poses`; returns arrays ``(n_theta, n_delta, ...)``. The flat pose
    list is never built: each chunk's poses are generated on the device from its index range
    (row-major, ``delta`` fastest).
    """
    th = np.asarray(theta_L, dtype=float)
    de = np.asarray(delta, dtype=float)
    if th.ndim != 1 or de.ndim != 1:
        raise ValueError(f"theta_L and delta must be 1-D grids, got shapes {th.shape} and {de.shape}")
    nt, nd = th.size, de.size

    def poses_of(a, b):  # used only when an axis is longer than a chunk
        idx = np.arange(a, b)
        return th[idx // nd], de[idx % nd]

    flat = _run(fn, design, nt * nd, poses_of, args, chunk_size, devices, quiet, keep, desc, grid=(th, de))
    return {k: v.reshape((nt, nd) + v.shape[1:]) for k, v in flat.items()}


# ------------------------------------------------------------------------------------------------
# Many designs at once: per-design statistics over one grid
# ------------------------------------------------------------------------------------------------
#: Designs per compiled call of :func:`sweep_designs`: the unit of progress, of the work a process
#: takes and of what a resumed exploration keeps (a small amount of work on the paper's grid).
DEFAULT_DESIGN_CHUNK = 128
#: Poses per step of each design's loop in :func:`sweep_designs`. Not a power of two: at 128, 256,
#: 512 and 1024 poses the kinematic measures cost markedly more CPU per pose than at 896, 1000,
#: 1320 or 1344 (strides that are multiples of 4 KB alias in the caches). 1320 holds the paper's 18 x 145 grid in two steps with 1% padding.
DESIGN_POSE_CHUNK = 1320
#: Reductions over a design's poses, with NumPy's meaning: ``max``, ``min``, ``mean`` (a NaN pose makes
#: the result NaN), ``nanmax``, ``nanmean`` (over the non-NaN poses; NaN when there is none).
REDUCTIONS = ("max", "min", "mean", "nanmax", "nanmean")
_IDENTITY = {"max": -np.inf, "nanmax": -np.inf, "min": np.inf, "mean": 0.0, "nanmean": 0.0}


def _reduce_step(op, acc, x, real):
    """One step's poses into the running ``(value, count)`` of reduction ``op``; ``real`` marks the
    poses that are not padding."""
    value, count = acc
    x = x.astype(value.dtype)
    use = real & ~jnp.isnan(x) if op.startswith("nan") else real
    x = jnp.where(use, x, _IDENTITY[op])
    if op.endswith("max"):
        value = jnp.maximum(value, jnp.max(x))
    elif op == "min":
        value = jnp.minimum(value, jnp.min(x))
    else:
        value = value + jnp.sum(x)
    return value, count + jnp.sum(use, dtype=value.dtype)


def _reduce_final(op, acc):
    value, count = acc
    some = count > 0
    if op.endswith("mean"):
        value = value / jnp.where(some, count, 1.0)
    return jnp.where(some, value, jnp.nan)


def _poses_at(source, i):
    """The poses at flat indices ``i`` of a workspace on the device: a grid ``(theta_L, delta,
    n_delta)`` (row-major, ``delta`` fastest) or configuration samples ``(B,)`` (M, S, 2)."""
    if len(source) == 1:
        return (source[0][i],)
    return _grid_poses(i, *source)


def _design_stats(fn, stats, chunk, design, source, n_poses, args):
    """Statistics of ``fn`` over every pose of the workspace ``source`` (:func:`_poses_at`) for **one**
    design or robot, (S,).

    The poses are generated on the device ``chunk`` at a time (as :func:`_eval_grid_chunk` does) and
    reduced as they come, so the working set is one step's poses whatever the workspace; the number
    of steps is a traced value, so a workspace of another size is the same program. ``stats``
    (static): ``(name, output, reduction)`` triples.
    """
    dt = _subject_dtype(design)

    def step(c, acc):
        i, real = _grid_index(c * chunk, chunk, n_poses)
        out = _eval_chunk(fn, design, _poses_at(source, i), args)
        return tuple(_reduce_step(op, a, out[key], real) for (_, key, op), a in zip(stats, acc))

    init = tuple((jnp.asarray(_IDENTITY[op], dt), jnp.zeros((), dt)) for _, _, op in stats)
    acc = jax.lax.fori_loop(0, (n_poses + chunk - 1) // chunk, step, init)
    return jnp.stack([_reduce_final(op, a) for (_, _, op), a in zip(stats, acc)])


def _designs_chunk(fn, stats, layout, designs, source, n_poses, args):
    """:func:`_design_stats` for each design (or robot) of a batch (leading axis), (D, S).

    ``layout = (chunk, mesh)`` (static): poses per step, and the local devices, over which the
    designs are split (``shard_map``: one program for all of them, each device mapping over its
    share). Mapped over the designs (a loop inside the program), not vmapped: inside the map each
    design is unbatched, so the fusion barrier of :func:`~tension_zones._numerics.keep` (anchored on
    the design's length) stays a barrier; vmapped over designs it becomes a select and the kinematic
    measures run several times slower. Poses are vmapped.
    """
    chunk, mesh = layout

    def local(designs, source, n_poses, args):
        return jax.lax.map(lambda d: _design_stats(fn, stats, chunk, d, source, n_poses, args), designs)

    split, whole = PartitionSpec("designs"), PartitionSpec()
    # each device's designs are independent (no collectives), so the varying-axis check is off: the
    # loops' carries start replicated and become per-device
    return jax.shard_map(local, mesh=mesh, in_specs=(split, whole, whole, whole), out_specs=split, check_vma=False)(
        designs, source, n_poses, args
    )


_designs_chunk_jit = jax.jit(_designs_chunk, static_argnums=(0, 1, 2))


def _structure(subject):
    """A design's wire count, or a robot's wire counts per segment (tuple): what a program depends on."""
    return subject.n_wires if isinstance(subject, Design) else subject.n_wires_per_segment


@functools.lru_cache(maxsize=64)
def _output_shapes(fn, structure, dtype, arg_specs):
    """``{output: shape}`` of ``fn`` at one pose (traced once per function, structure (:func:`_structure`)
    and argument shapes: tracing the kinematic measures costs more than exploring a few designs)."""
    if isinstance(structure, tuple):  # a robot and one configuration B (S, 2)
        subject = Robot([Design(n, 2.0, 1.0, dtype=dtype) for n in structure])
        pose = (jax.ShapeDtypeStruct((len(structure), 2), dtype),)
    else:  # a design and one pose (theta_L, delta)
        subject = Design(structure, 2.0, 1.0, dtype=dtype)
        pose = (jax.ShapeDtypeStruct((), dtype),) * 2
    spec = jax.tree_util.tree_map(lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype), subject)
    args = tuple(jax.ShapeDtypeStruct(shape, dt) for shape, dt in arg_specs)
    out = jax.eval_shape(lambda d, p, a: fn(d, *p, *a), spec, pose, args)
    return {k: v.shape for k, v in out.items()}


def _check_stats(fn, design, args, stats):
    """``stats`` as a tuple of ``(name, output, reduction)``, checked against ``fn``'s outputs."""
    stats = tuple(tuple(s) for s in stats)
    if not stats or any(len(s) != 3 for s in stats):
        raise ValueError("stats must be a non-empty list of (name, output, reduction) triples")
    names = [s[0] for s in stats]
    if len(set(names)) != len(names):
        raise ValueError(f"stats names must be unique, got {names}")
    arg_specs = tuple((np.shape(a), str(np.asarray(a).dtype)) for a in args)
    shapes = _output_shapes(fn, _structure(design), str(_subject_dtype(design)), arg_specs)
    for name, key, op in stats:
        if op not in REDUCTIONS:
            raise ValueError(f"stat {name!r}: unknown reduction {op!r}; known: {list(REDUCTIONS)}")
        if key not in shapes:
            raise ValueError(f"stat {name!r}: the function has no output {key!r}; it returns {sorted(shapes)}")
        if shapes[key] != ():
            raise ValueError(f"stat {name!r}: output {key!r} is not a scalar per pose (shape {shapes[key]})")
    return stats


def positive_int(name: str, v) -> int:
    """``v`` as an ``int`` if it is a positive integer (Python or NumPy; a bool is not), else the
    one-line ``ValueError`` "``name`` must be a positive integer, got ``v``"."""
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
        raise ValueError(f"{name} must be a positive integer, got {v!r}")
    return int(v)


def _gather(chunk_id, arr):
    """Every process's ``(chunk id, results)`` of this round, on every process (JAX collectives)."""
    from jax.experimental import multihost_utils

    ids, arrs = multihost_utils.process_allgather((np.array([chunk_id]), arr))
    return [int(i) for i in np.asarray(ids).reshape(-1)], np.asarray(arrs)


def _done_everywhere(is_done):
    """Process 0's record of the chunks already done, the same on every process."""
    if jax.process_count() == 1:
        return is_done
    from jax.experimental import multihost_utils

    return np.asarray(multihost_utils.broadcast_one_to_all(is_done.astype(np.int32))).astype(bool)


def _batch_and_grid(designs, theta_L, delta) -> tuple[Design, np.ndarray, np.ndarray]:
    """A batch of designs (NumPy leaves with a leading axis) and a grid's axes (non-empty, 1-D), checked."""
    if not isinstance(designs, Design) or np.ndim(designs.length) != 1:
        raise TypeError("designs must be a tension_zones.Design whose leaves have a leading axis (a batch of designs)")
    th, de = (np.asarray(x, dtype=float) for x in (theta_L, delta))
    if th.ndim != 1 or de.ndim != 1 or th.size == 0 or de.size == 0:
        raise ValueError(f"theta_L and delta must be non-empty 1-D grids, got shapes {th.shape} and {de.shape}")
    return jax.tree_util.tree_map(np.asarray, designs), th, de


def _batch_and_workspace(designs, theta_L, delta) -> tuple:
    """A batch, its workspace as :func:`_workspace`'s ``source`` and its number of poses, checked: a
    batch of designs and a grid's axes, or of robots (NumPy leaves with a leading axis) and
    configurations ``theta_L = B`` (M, S, 2) with ``delta = None``."""
    if not isinstance(designs, Robot):
        designs, th, de = _batch_and_grid(designs, theta_L, delta)
        return designs, (th, de), th.size * de.size
    if np.ndim(designs.route_angles) != 3:
        raise TypeError("robots must be a tension_zones.Robot whose leaves have a leading axis (a batch of robots)")
    B = np.asarray(theta_L, dtype=float)
    if delta is not None or B.ndim != 3 or B.shape[0] == 0 or B.shape[1:] != (designs.n_segments, 2):
        raise ValueError(
            f"a batch of robots takes its configurations B (M >= 1, {designs.n_segments}, 2) as theta_L and "
            f"None as delta, got {B.shape} and {type(delta).__name__}"
        )
    return jax.tree_util.tree_map(np.asarray, designs), (B,), B.shape[0]


def _resumed(done, n_designs: int, D: int, S: int) -> tuple[np.ndarray, np.ndarray]:
    """The results table (n_designs, S), NaN but for the rows of ``done`` (chunk index -> its rows),
    and which of the chunks of ``D`` designs are done."""
    results, is_done = np.full((n_designs, S), np.nan), np.zeros(-(-n_designs // D), bool)
    for c, rows in (done or {}).items():
        a, b = c * D, min(c * D + D, n_designs)
        if not 0 <= c < is_done.size or np.shape(rows) != (b - a, S):
            raise ValueError(f"done chunk {c}: expected {b - a} x {S} results, got shape {np.shape(rows)}")
        results[a:b], is_done[c] = rows, True
    return results, is_done


def _workspace(source, P: int, dt, idx_t) -> tuple:
    """A workspace's arrays for the device (:func:`_poses_at`), padded to whole steps of ``P`` poses:
    a grid's axes ``source = (theta_L, delta)`` and its number of directions, or the samples
    ``source = (B,)`` (zeros past the last)."""
    if len(source) == 1:
        (B,) = source
        return (np.concatenate([B.astype(dt), np.zeros((P * -(-len(B) // P) - len(B),) + B.shape[1:], dt)]),)
    th, de = source
    return (*_pad_axes((th, de), P * -(-max(th.size, de.size) // P), dt), idx_t(de.size))


def _placement(designs, source, n_poses: int, D: int, P: int, args) -> tuple:
    """Where the chunks run: the mesh of the process's local devices (:func:`chunk_devices`: for a
    batch of robots, one CPU device), a chunk's ``D`` designs padded to split evenly over them, the
    sharding that splits them, and what every chunk shares (the workspace ``source`` padded to whole
    steps of ``P`` poses, :func:`_workspace`, its ``n_poses``, ``args``), on every device."""
    dt, idx_t = _subject_dtype(designs), np.int64 if n_poses + P >= 2**31 else np.int32
    mesh = Mesh(np.array(chunk_devices(isinstance(designs, Robot))), ("designs",))
    padded = mesh.size * -(-D // mesh.size)
    split, whole = NamedSharding(mesh, PartitionSpec("designs")), NamedSharding(mesh, PartitionSpec())
    shared = jax.device_put((_workspace(source, P, dt, idx_t), idx_t(n_poses), tuple(args)), whole)
    return mesh, padded, split, shared


def _in_flight(n_rounds: int, launch: Callable, collect: Callable) -> None:
    """``launch(k)`` for every round ``k``, at most :data:`IN_FLIGHT` at once, each one's result passed
    to ``collect`` in order once that many are running (the rest at the end)."""
    queue: collections.deque[tuple[int, Any]] = collections.deque()
    for k in range(n_rounds):
        queue.append(launch(k))
        if len(queue) >= IN_FLIGHT:
            collect(*queue.popleft())
    while queue:
        collect(*queue.popleft())


def sweep_designs(
    fn: Callable,
    designs: Design | Robot,
    theta_L,
    delta,
    *args,
    stats: Sequence[tuple[str, str, str]],
    designs_per_chunk: int = DEFAULT_DESIGN_CHUNK,
    poses_per_chunk: int = DESIGN_POSE_CHUNK,
    quiet: bool = False,
    desc: str | None = None,
    done: dict[int, np.ndarray] | None = None,
    on_chunk: Callable[[int, np.ndarray], None] | None = None,
) -> dict[str, np.ndarray] | None:
    """Per-design statistics of ``fn`` over the grid ``theta_L x delta`` for a batch of designs, or
    over configurations for a batch of robots.

    For each design ``d`` of ``designs`` (a :class:`Design` whose leaves have a leading axis of N
    designs, one wire count) and each ``(name, output, reduction)`` of ``stats``:
    ``reduction`` (see :data:`REDUCTIONS`) of ``fn(d, theta_L, delta, *args)[output]`` over the
    grid's poses. Equal to reducing :func:`sweep_grid`'s arrays with NumPy, design by design. For a
    batch of robots (a :class:`Robot` with a leading axis, one structure) ``theta_L`` is the
    configurations ``B`` (M, S, 2) rad and ``delta`` is ``None``: ``fn(robot, B_i, *args)``, equal to
    reducing :func:`sweep_configs`' arrays robot by robot.

    * **bounded memory**: designs go ``designs_per_chunk`` to a compiled call (the last chunk padded
      with its last design), and each design's poses ``poses_per_chunk`` at a time, reduced as they
      come: the working set depends on neither N nor the grid; the host keeps N x S results.
    * **no recompiles when only values change**: the designs' numbers, the grid's (or the
      configurations') values *and size* and ``args`` are traced; one program per function,
      statistics, wire count (robot structure) and chunk sizes.
    * **cores and devices**: up to :data:`IN_FLIGHT` chunks run at once; each chunk's designs are
      split over the process's local devices by one program (a chunk is padded to a multiple of
      their number; results do not depend on it).
    * **processes and hosts**: after ``jax.distributed.initialize(...)`` the same call on every
      process splits the chunks between the processes (process ``p`` takes every P-th chunk still
      to do); each round's results are gathered with ``multihost_utils.process_allgather``.
      Results and ``on_chunk`` calls happen on process 0; the other processes return ``None``.
      Every chunk runs the same program on the same designs, so the table is bit for bit the
      one-process table.
    * **resuming**: ``done`` maps chunk indices (chunk ``c`` = designs ``c D .. c D + D - 1``) to
      their rows, known on process 0 (e.g. read back from files): those are not computed again.
      ``on_chunk(c, rows)`` is called on process 0 as each chunk's rows arrive (e.g. to save them).

    Args:
        fn: pure single-pose function ``fn(design, theta_L, delta, *args) -> dict`` of scalars (a
            robot's: ``fn(robot, B, *args)``).
        designs: the batch (leaves with a leading axis of N).
        theta_L, delta: the grid's axes (rad), 1-D; robots: ``B`` (M, S, 2) and ``None``.
        *args: extra arguments shared by every pose and design (traced).
        stats: ``(name, output, reduction)`` triples.

    Returns ``{name: (N,) array}`` on process 0, ``None`` on the other processes.
    """
    designs, source, n_poses = _batch_and_workspace(designs, theta_L, delta)
    D = positive_int("designs_per_chunk", designs_per_chunk)
    P = positive_int("poses_per_chunk", poses_per_chunk)
    stats = _check_stats(fn, designs, args, stats)
    n_designs, S = jax.tree_util.tree_leaves(designs)[0].shape[0], len(stats)
    n_chunks = -(-n_designs // D)
    first = jax.process_index() == 0
    nproc = jax.process_count()

    results: Any
    results, is_done = _resumed(done, n_designs, D, S) if first else (None, np.zeros(n_chunks, bool))
    pending = np.flatnonzero(~_done_everywhere(is_done))
    mine = pending[jax.process_index() :: nproc]
    n_rounds = -(-pending.size // nproc)  # the same on every process: the collectives line up

    mesh, padded, split, shared = _placement(designs, source, n_poses, D, P, args)

    def launch(k):  # this process's k-th chunk, dispatched asynchronously
        if k >= mine.size:
            return -1, None
        c = int(mine[k])
        rows = np.minimum(np.arange(c * D, c * D + padded), n_designs - 1)  # pad: the last design
        batch = jax.device_put(jax.tree_util.tree_map(lambda x: x[rows], designs), split)
        return c, _designs_chunk_jit(fn, stats, (P, mesh), batch, *shared)

    def collect(chunk, res, bar):  # this round's chunks of every process, into the results
        arr = np.full((D, S), np.nan) if res is None else np.asarray(res)[:D]
        ids, arrs = _gather(chunk, arr) if nproc > 1 else ([chunk], arr[None])
        for c, rows in zip(ids, arrs):
            if c < 0 or not first:
                continue
            a, b = c * D, min(c * D + D, n_designs)
            results[a:b] = rows[: b - a]
            if on_chunk is not None:
                on_chunk(c, results[a:b])
            bar.update(b - a)

    initial = n_designs - int(np.sum(np.minimum(pending * D + D, n_designs) - pending * D))
    with _progress(
        n_designs, desc or "designs", quiet or not first or pending.size < 2, unit="design", initial=initial
    ) as bar:
        _in_flight(n_rounds, launch, functools.partial(collect, bar=bar))
    if not first:
        return None
    return {name: results[:, j] for j, (name, _, _) in enumerate(stats)}
