"""The XLA settings the package makes (no JAX import here: the lazy top-level package uses it too).

XLA's concurrency-optimised CPU scheduler can leave a computation waiting forever on the package's
large vmapped while loops (see :mod:`._config`), so it is turned off unless ``XLA_FLAGS`` already
says otherwise.

**A persistent compilation cache.** The calibration's programs take 5-15 s each to compile on a
laptop and the same robot is calibrated again and again, so compiled programs are kept on disk
(JAX's own persistent cache): the second ``tension-zones calibrate`` of a robot skips XLA's compile.
The folder is ``$TENSION_ZONES_CACHE`` if set (``0``/``off``: no cache), else
``$XDG_CACHE_HOME/tension-zones/jax`` (``~/.cache/tension-zones/jax``); a cache the user configured for
JAX (``JAX_COMPILATION_CACHE_DIR``) is left alone, and a folder that cannot be created means no cache.
"""

import functools
import os

_SCHEDULER = "--xla_cpu_enable_concurrency_optimized_scheduler"
_FUSION = "xla_cpu_use_fusion_emitters"


def with_scheduler_off(flags: str) -> str:
    """``flags`` (an ``XLA_FLAGS`` value) with the CPU scheduler turned off, unless it names the flag."""
    return flags if _SCHEDULER in flags else f"{flags} {_SCHEDULER}=false".strip()


_OFF = ("0", "false", "no", "off", "")


def cache_dir() -> str | None:
    """The compilation-cache folder the package would use (created), or None (off or not writable)."""
    env = os.environ.get("TENSION_ZONES_CACHE")
    if env is not None and env.strip().lower() in _OFF:
        return None
    path = env or os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"),
                               "tension-zones", "jax")
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:
        return None
    return path if os.access(path, os.W_OK) else None


def set_cache_env() -> None:
    """Before JAX is imported: point JAX's own switch at the cache (unless the user set one)."""
    if "JAX_COMPILATION_CACHE_DIR" not in os.environ and (path := cache_dir()):
        os.environ["JAX_COMPILATION_CACHE_DIR"] = path


@functools.cache
def _jaxlib_version() -> tuple:
    from importlib.metadata import version

    try:
        return tuple(int(p) for p in version("jaxlib").split(".")[:3] if p.isdigit())
    except (ImportError, ValueError):  # not installed as a distribution: assume an old one (no options)
        return (0,)


def fast_compile_options() -> dict:
    """XLA options for programs whose compile time outweighs their run time (the calibration's
    engine, the design optimiser, the paper's identification):
    ``jax.jit(..., compiler_options=fast_compile_options())``.

    XLA:CPU's MLIR fusion emitters (jaxlib 0.5.3 on; the first release with the switch) take much of
    the compile time of these large programs; the older emitters compile them faster and run them as
    fast. Measured on this 2-core machine, no compilation cache, each side twice, interleaved: the
    500-sample single-segment calibration (``unknown_a_3w``) 23.3 / 25.5 s -> 19.9 / 19.5 s (its
    first call, trace and compile of the constant-curvature program, 8.9 / 10.3 -> 7.3 / 6.0 s; the
    rod's 9.8 / 10.4 -> 7.6 / 8.8 s; a 41-iteration fit 0.61 / 0.66 -> 0.57 / 0.65 s); the FTDCR v4
    calibration 107.8 -> 111.9 s (once each: fits dominate there, no gain); the notebook 04
    optimisation's first call 33.6 / 27.9 -> 21.6 / 25.9 s; the identification's first call 10.2 / 10.5
    -> 8.8 / 7.6 s (a later call 0.15-0.17 s either way). Results equal to 1e-15. The sweeps keep
    XLA's defaults (their run time matters). JAX takes such options on top-level jits only; older
    jaxlibs do not know the switch (nor have those emitters): no options there.
    """
    return {_FUSION: False} if _jaxlib_version() >= (0, 5, 3) else {}


def fast_compile_flag() -> str:
    """The same switch for a whole process, as an ``XLA_FLAGS`` entry ("" where jaxlib lacks it): for
    work made of many small programs, such as the test suite, whose compile time is most of its time."""
    return f"--{_FUSION}=false" if fast_compile_options() else ""
