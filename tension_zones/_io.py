"""Output files written so that an interrupted write loses nothing.

:func:`atomic_path` hands out a temporary name in the target's own folder (same file system, same
suffix, so writers that infer the format from the name still do); the finished file replaces the
target in one ``os.replace``. Until then the old file, if any, is untouched, and on any error or
interrupt the temporary file is removed.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
from pathlib import Path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path):
    """``with atomic_path(p) as tmp: write(tmp)``: ``p`` appears, complete, when the block ends."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=path.suffix)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp's 0600 would make outputs private
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)


def write_text(path, text: str) -> Path:
    """``Path(path).write_text(text)``, atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return Path(path)


def save_figure(fig, path, **savefig_kw) -> Path:
    """``fig.savefig(path, **savefig_kw)``, atomically (the temporary file keeps ``path``'s suffix,
    from which Matplotlib takes the format). A path without a suffix and no ``format`` is saved as
    Matplotlib saves it (it appends its default format's suffix)."""
    path = Path(path)
    if not path.suffix and "format" not in savefig_kw:
        fig.savefig(path, **savefig_kw)
        return path
    with atomic_path(path) as tmp:
        fig.savefig(tmp, **savefig_kw)
    return path


def _null_for_nan(x):
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _null_for_nan(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_null_for_nan(v) for v in x]
    return x


def write_json(path, value, indent: int = 2) -> Path:
    """``value`` as strict JSON, atomically: a non-finite float (a figure not computed, NaN) is ``null``."""
    return write_text(path, json.dumps(_null_for_nan(value), indent=indent, allow_nan=False))
