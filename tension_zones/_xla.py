"""The XLA settings the package makes (no JAX import at module level: the lazy top-level package
and the test suite's ``conftest.py`` read it before JAX is loaded).

:func:`apply_settings` is applied by :mod:`._config` when a sub-package first loads JAX, before
anything is compiled; ``import tension_zones`` alone applies nothing.

**XLA's CPU scheduler.** XLA's concurrency-optimised CPU scheduler can leave a computation waiting
forever on the package's large vmapped while loops, so it is turned off unless ``XLA_FLAGS`` already
names the flag (``--xla_cpu_enable_concurrency_optimized_scheduler=true`` keeps it on).

**A persistent compilation cache.** The calibration's programs are large and the same robot is
calibrated again and again, so compiled programs are kept on disk (JAX's own persistent cache): the
second ``tension-zones calibrate`` of a robot skips XLA's compile. The folder is
``$TENSION_ZONES_CACHE`` if set (``0``/``off``: no cache), else ``$XDG_CACHE_HOME/tension-zones/jax``
(``~/.cache/tension-zones/jax``); JAX creates it at its first compile. A cache the user configured
for JAX (``JAX_COMPILATION_CACHE_DIR``) is left alone, and a folder that cannot be created means no
cache. Deleting the folder is safe: it only costs the next run its compile.
"""

import functools
import os
from pathlib import Path
from typing import Any

_SCHEDULER = "--xla_cpu_enable_concurrency_optimized_scheduler"
#: The name of a thread that compiles a program ahead of its use (``calibration/_problem.py``,
#: ``engine_ahead``): the command line ends its process without the interpreter's shutdown while one
#: runs (``cli._exit``).
COMPILE_THREAD = "tension-zones-compile"
_FUSION = "xla_cpu_use_fusion_emitters"
_LLVM_LEVEL = "xla_backend_optimization_level"


def with_scheduler_off(flags: str) -> str:
    """``flags`` (an ``XLA_FLAGS`` value) with the CPU scheduler turned off, unless it names the flag."""
    return flags if _SCHEDULER in flags else f"{flags} {_SCHEDULER}=false".strip()


_OFF = ("0", "false", "no", "off", "")


def _creatable(path: Path) -> bool:
    """Whether ``path`` is a writable folder or could be made as one (nothing is created)."""
    path = path.absolute()
    while not path.exists():
        if path.parent == path:
            return False
        path = path.parent
    return path.is_dir() and os.access(path, os.W_OK | os.X_OK)


def cache_dir(create: bool = True) -> str | None:
    """The compilation-cache folder the package uses, or None (turned off or not writable).
    ``create=False`` makes nothing: the folder is only checked to be writable or creatable."""
    env = os.environ.get("TENSION_ZONES_CACHE")
    if env is not None and env.strip().lower() in _OFF:
        return None
    path = env or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "tension-zones", "jax"
    )
    if not create:
        return path if _creatable(Path(path)) else None
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:
        return None
    return path if os.access(path, os.W_OK) else None


def apply_settings() -> None:
    """The package's XLA settings (see the module's docstring), for a process that has imported JAX
    and compiled nothing yet: the CPU scheduler off in ``XLA_FLAGS`` (XLA reads the variable when JAX
    creates its CPU client), and JAX's compilation cache pointed at :func:`cache_dir` unless the user
    configured one. Idempotent."""
    import jax

    os.environ["XLA_FLAGS"] = with_scheduler_off(os.environ.get("XLA_FLAGS", ""))
    configured = jax.config.jax_compilation_cache_dir  # type: ignore[attr-defined]
    mine = configured is None and "JAX_COMPILATION_CACHE_DIR" not in os.environ
    if mine and (path := cache_dir(create=False)):
        jax.config.update("jax_compilation_cache_dir", path)


@functools.cache
def _jaxlib_version() -> tuple:
    from importlib.metadata import version

    try:
        return tuple(int(p) for p in version("jaxlib").split(".")[:3] if p.isdigit())
    except (ImportError, ValueError):  # not installed as a distribution: assume an old one (no options)
        return (0,)


def fast_compile_options(optimise: bool = True) -> dict:
    """XLA options for programs whose compile time outweighs their run time (the calibration's
    engine, the design optimiser, the paper's identification):
    ``jax.jit(..., compiler_options=fast_compile_options())``. ``optimise=False``: LLVM level 0 as
    well, for a program that runs too little to pay for LLVM's optimisation (the caller measured it:
    ``calibration/_problem.py``, ``_optimised``).

    XLA:CPU's MLIR fusion emitters (jaxlib 0.5.3 on, the first release with the switch) take much of
    the compile time of these large programs; the older emitters compile them faster and run them as
    fast, with the same results to rounding. The sweeps keep XLA's defaults (their run time matters).
    JAX takes such options on top-level jits only; older jaxlibs do not know the switch (nor have
    those emitters): no fusion option there.

    LLVM's optimisation level is pinned at XLA's default (3): these programs run long (a calibration's
    fits), so a process-wide lower level meant for many small programs (the test suite's:
    ``tests/conftest.py``) must not reach them; level 0 compiles them faster but slows their fits by
    more than it saves.
    """
    opts = {_LLVM_LEVEL: 3 if optimise else 0}
    if _jaxlib_version() >= (0, 5, 3):
        opts[_FUSION] = False
    return opts


def fast_compile_flag() -> str:
    """The same switch for a whole process, as an ``XLA_FLAGS`` entry ("" where jaxlib lacks it): for
    work made of many small programs, such as the test suite, whose compile time is most of its time."""
    return f"--{_FUSION}=false" if _FUSION in fast_compile_options() else ""


# -- programs kept on disk before tracing ------------------------------------------------------------
# JAX's cache skips XLA's compile but not the tracing and lowering that compute its key, which for
# the calibration's programs (an equilibrium solve differentiated inside a least-squares loop) are a
# large part of a run. ``jax.export`` keeps the lowered program itself (its versioned serialisation,
# which needs ``flatbuffers``), so a later process loads it and only JAX's cache lookup remains; the
# results are the same bit for bit.


@functools.cache
def _sources_digest() -> str:
    """SHA-256 of the package's Python sources: a program stored by other code is never reused."""
    import hashlib
    from pathlib import Path

    root = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for p in sorted(root.rglob("*.py")):
        h.update(str(p.relative_to(root)).encode() + b"\0" + p.read_bytes())
    return h.hexdigest()


def classes_digest(classes) -> str | None:
    """SHA-256 of the source files of ``classes`` (and their bases) outside the package, "" if all are
    inside it, None if one has no file (defined in a notebook or ``__main__``: not storable)."""
    import hashlib
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parent
    h, files = hashlib.sha256(), set()
    for cls in classes:
        for c in cls.__mro__:
            if c.__module__ == "builtins":
                continue
            path = getattr(sys.modules.get(c.__module__), "__file__", None)
            if path is None or c.__module__ == "__main__":
                return None
            p = Path(path).resolve()
            if root not in p.parents:
                files.add(p)
    for p in sorted(files):
        h.update(p.read_bytes())
    return h.hexdigest() if files else ""


def shapes_key(args) -> tuple:
    """What a jitted program of ``args`` is compiled for: their tree (static fields included) and each
    leaf's shape and type. A key of a process's own table of programs, beside their static
    configuration."""
    import jax
    import jax.numpy as jnp

    leaves, tree = jax.tree_util.tree_flatten(args)
    return tree, tuple((jnp.shape(a), jnp.result_type(a)) for a in leaves)


def stored_program(fn, args: tuple, key: str, compiler_options: dict | None = None):
    """A callable equal to the jitted ``fn`` on arguments with the shapes and dtypes of ``args``,
    kept on disk in ``cache_dir()/programs`` (exported after the first trace, loaded by later
    processes). ``key`` names what the arguments do not: ``fn``'s static configuration (its identity
    and whatever it closes over that the package's sources do not fix). Without a cache folder, or if
    exporting or loading fails, ``fn`` itself (traced as usual)."""
    import hashlib
    from pathlib import Path

    import jax

    folder = cache_dir()
    if folder is None:
        return fn
    try:
        from jax import export
    except ImportError:  # pragma: no cover  (an old JAX)
        return fn
    leaves, tree = jax.tree_util.tree_flatten(args)
    # (an array's own shape and type: a jnp.asarray of a NumPy one would compile a small program)
    arrays = (a if hasattr(a, "dtype") and hasattr(a, "shape") else jax.numpy.asarray(a) for a in leaves)
    avals = ";".join(f"{a.shape}{a.dtype}{getattr(a, 'weak_type', False)}" for a in arrays)
    x64 = jax.config.jax_enable_x64  # type: ignore[attr-defined]
    ident = "|".join(
        [
            _sources_digest(),
            jax.__version__,
            ".".join(map(str, _jaxlib_version())),
            jax.default_backend(),
            str(x64),
            str(tree),
            avals,
            key,
            repr(sorted((compiler_options or {}).items())),
        ]
    )
    path = Path(folder) / "programs" / f"{hashlib.sha256(ident.encode()).hexdigest()}.jaxexport"
    opts: dict[str, Any] = {"compiler_options": compiler_options} if compiler_options else {}
    if (exp := _read_program(path)) is not None:
        return jax.jit(exp.call, **opts)
    try:
        exp = export.export(fn)(*args)
        blob = exp.serialize() if hasattr(exp, "serialize") else export.serialize(exp)  # type: ignore[attr-defined]  # (JAX < 0.4.31)
    except Exception:  # noqa: BLE001  (a program JAX cannot export or serialise: traced as usual)
        return fn
    _write_atomic(path, blob)
    return jax.jit(exp.call, **opts)


def _read_program(path):
    """The exported program stored at ``path``, or None (none there, or a damaged or foreign file,
    which is then exported again over it)."""
    from jax import export

    try:
        return export.deserialize(bytearray(path.read_bytes()))
    except Exception:  # noqa: BLE001
        return None


def _write_atomic(path: Path, blob: bytes | bytearray) -> None:
    """Write ``blob`` to ``path``, atomically (a concurrent reader sees the old file or the new one:
    :func:`tension_zones._io.atomic_path`); a folder that cannot be written keeps nothing."""
    from ._io import atomic_path

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            tmp.write_bytes(blob)
    except OSError:
        return
