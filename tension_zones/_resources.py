"""What the machine has, against what a command will need: checked before the work starts.

The commands estimate their peak memory from the sizes of their inputs (each estimate is a formula
beside the code it bounds) and refuse, in one line naming the estimate and what to do, where it is
more than :data:`MEMORY_SHARE` of the machine's memory.
"""

from __future__ import annotations

import os

#: The share of the machine's memory a command may plan to use: the rest is for the other programs
#: and for the estimates' own error.
MEMORY_SHARE = 0.5


def cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # (not Linux)
        return os.cpu_count() or 1


def machine_memory() -> int | None:
    """The machine's physical memory in bytes, or None where the system does not say."""
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def gb(n_bytes: float) -> str:
    """Bytes for a message: ``"12.5 GB"``, or ``"930 MB"`` below a gigabyte."""
    return f"{n_bytes / 1e9:.3g} GB" if n_bytes >= 1e9 else f"{n_bytes / 1e6:.3g} MB"


def check_memory(need: float, what: str, advice: str) -> None:
    """Raise a one-line ``ValueError`` where ``need`` bytes (an estimate for ``what``) exceed
    :data:`MEMORY_SHARE` of the machine's memory; ``advice`` says what to do instead."""
    have = machine_memory()
    if have is not None and need > MEMORY_SHARE * have:
        raise ValueError(
            f"{what} needs about {gb(need)} of memory (estimated), more than "
            f"{MEMORY_SHARE:.0%} of the {gb(have)} of memory here; {advice}"
        )
