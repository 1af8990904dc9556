"""The XLA flag the package sets (no JAX import here: the lazy top-level package uses it too).

XLA's concurrency-optimised CPU scheduler can leave a computation waiting forever on the package's
large vmapped while loops (see :mod:`._config`), so it is turned off unless ``XLA_FLAGS`` already
says otherwise.
"""

_SCHEDULER = "--xla_cpu_enable_concurrency_optimized_scheduler"


def with_scheduler_off(flags: str) -> str:
    """``flags`` (an ``XLA_FLAGS`` value) with the CPU scheduler turned off, unless it names the flag."""
    return flags if _SCHEDULER in flags else f"{flags} {_SCHEDULER}=false".strip()
