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

import os

_SCHEDULER = "--xla_cpu_enable_concurrency_optimized_scheduler"


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
