"""A generic, chunked, shardable sweep engine for per-pose measures.

Any pure single-pose function ``fn(design, theta_L, delta, *args) -> dict[str, array]`` (e.g.
:func:`tension_zones.metrics.pose_metrics`) is swept over a workspace grid (:func:`sweep_grid`) or a
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
  device) with :mod:`jax.sharding`; the design and ``args`` are replicated. Each device runs the
  same ``chunk_size``-pose program and a pose always sits at the same position of its device's
  block (``index mod chunk_size``), so results are bit-for-bit identical on one device or many.
"""

from __future__ import annotations

import collections
import math
from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ..model._design import Design

#: Poses per chunk and device: 2^14 keeps the working set of the kinematic measures near 50 MB.
DEFAULT_CHUNK = 1 << 14


def default_chunk(n_wires: int) -> int:
    """Poses per chunk for a wire count: :data:`DEFAULT_CHUNK` up to 8 wires; above, where the
    measures take (n, n) pair terms per pose, smaller by ``(8 / n)^2`` (a power of two, at least
    256), so that the working set stays near its 8-wire size (64 wires at 2^14 poses: 2.6 GB)."""
    if n_wires <= 8:
        return DEFAULT_CHUNK
    return max(256, DEFAULT_CHUNK >> (2 * math.ceil(math.log2(n_wires / 8))))
#: Chunks dispatched at once: the CPU runtime runs independent programs concurrently, so a second
#: and third chunk in flight keep both cores busy (one program alone runs on about one core).
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


def _eval_chunk(fn, design, theta_L, delta, args):
    out = jax.vmap(lambda t, d: fn(design, t, d, *args))(theta_L, delta)
    if not isinstance(out, dict):
        raise TypeError(f"a swept function must return a dict of arrays, got {type(out).__name__}")
    return out


_eval_chunk_jit = jax.jit(_eval_chunk, static_argnums=0)


def _eval_grid_chunk(fn, layout, design, start, th_grid, de_grid, n_de, n_poses, args):
    """:func:`_eval_chunk` on grid poses ``start, start + 1, ...`` (row-major, ``delta`` fastest),
    generated on the device: no pose arrays cross from the host per chunk (a copy that competes with
    the computation for the cores). ``layout = (chunk, sharding)`` (static) fixes the chunk; the
    padding past the last pose repeats the last pose. The axis vectors come padded to the chunk
    size, so the program depends on no grid dimension."""
    chunk, sharding = layout
    i = jnp.minimum(start + jnp.arange(chunk, dtype=start.dtype), n_poses - 1)
    i = jax.lax.with_sharding_constraint(i, sharding)
    return _eval_chunk(fn, design, th_grid[i // n_de], de_grid[i % n_de], args)


_eval_grid_chunk_jit = jax.jit(_eval_grid_chunk, static_argnums=(0, 1))


def compiled_chunk_count() -> int:
    """How many chunk programs have been compiled so far (one per function, wire count, chunk size
    and kind: flat poses, or a grid whose poses are generated on the device)."""
    return _eval_chunk_jit._cache_size() + _eval_grid_chunk_jit._cache_size()


def _mesh(devices):
    devices = list(jax.local_devices() if devices is None else devices)
    if not devices:
        raise ValueError("devices must name at least one device")
    return Mesh(np.array(devices), ("poses",)), len(devices)


def _run(fn, design, n_poses, poses_of, args, chunk_size, devices, quiet, keep, desc, grid=None):
    """Core loop: evaluate ``fn`` on poses ``poses_of(start, stop)`` (host arrays) or, given
    ``grid = (theta_L, delta)`` with both axes no longer than a chunk, on that grid's poses generated
    on the device; results flat (N, ...)."""
    if not isinstance(design, Design):
        raise TypeError(f"design must be a tension_zones.Design, got {type(design).__name__}")
    if chunk_size is None:
        chunk_size = default_chunk(design.n_wires)
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)) or chunk_size < 1:
        raise ValueError(f"chunk_size must be a positive integer, got {chunk_size!r}")
    mesh, n_dev = _mesh(devices)
    chunk = int(chunk_size) * n_dev  # every device always gets chunk_size poses (see module doc)
    batch, replicated = NamedSharding(mesh, PartitionSpec("poses")), NamedSharding(mesh, PartitionSpec())
    dt = design.dtype
    design_d = jax.device_put(design, replicated)
    args_d = jax.device_put(jax.tree_util.tree_map(np.asarray, tuple(args)), replicated)

    if grid is not None and max(x.size for x in grid) > chunk:
        grid = None  # an axis longer than a chunk: the poses come from the host (poses_of)
    if grid is not None:
        # the grid's axes on the device once (padded to the chunk size: the program does not depend on
        # the grid's shape); each chunk is then only a start index
        th_g, de_g = (np.asarray(x, dt) for x in grid)
        th_g, de_g = (np.concatenate([x, np.zeros(chunk - x.size, dt)]) for x in (th_g, de_g))
        idx_t = np.int64 if n_poses + chunk >= 2**31 else np.int32
        grid_d = jax.device_put((th_g, de_g, idx_t(grid[1].size), idx_t(n_poses)), replicated)

    def launch(start):
        stop = min(start + chunk, n_poses)
        if grid is not None:
            th_g, de_g, n_de, n_all = grid_d
            res = _eval_grid_chunk_jit(fn, (chunk, batch), design_d, idx_t(start), th_g, de_g, n_de, n_all,
                                       args_d)
            return start, stop, res
        th, de = (np.asarray(x, dt) for x in poses_of(start, stop))
        if stop - start < chunk:  # pad with the first pose: one compiled shape for every chunk
            pad = chunk - (stop - start)
            th, de = np.concatenate([th, np.full(pad, th[0], dt)]), np.concatenate([de, np.full(pad, de[0], dt)])
        res = _eval_chunk_jit(fn, design_d, jax.device_put(th, batch), jax.device_put(de, batch), args_d)
        return start, stop, res

    results: dict[str, np.ndarray] = {}

    def store(start, stop, res):
        if not results:
            missing = sorted(set(keep or ()) - set(res))
            if missing:
                raise ValueError(f"keep names unknown output(s) {missing}; the function returns {sorted(res)}")
            # one block per dtype and shape, each output a row of it: a few large allocations, which
            # NumPy backs with huge pages, rather than one per output (4 KB first-touch page faults:
            # 8,000 instead of 900 for a 246k-pose kinematic sweep run after a NumPy job)
            groups = collections.defaultdict(list)
            for k, v in res.items():
                if keep is None or k in keep:
                    groups[(v.dtype, v.shape[1:])].append(k)
            for (dtype, shape), keys in groups.items():
                results.update(zip(keys, np.empty((len(keys), n_poses) + shape, dtype)))
        for k in results:
            results[k][start:stop] = np.asarray(res[k])[: stop - start]  # slice on the host: no dispatch

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


def _progress(total, desc, disable):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc or "sweep", unit="pose", unit_scale=True, disable=disable,
                leave=False, dynamic_ncols=True)


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
    return _run(fn, design, th.size, lambda a, b: (th[a:b], de[a:b]), args, chunk_size, devices,
                quiet, keep, desc)


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
