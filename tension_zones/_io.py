"""Output files written so that an interrupted write loses nothing.

:func:`atomic_path` hands out a temporary name in the target's own folder (same file system, same
suffix, so writers that infer the format from the name still do); the finished file replaces the
target in one ``os.replace``. Until then the old file, if any, is untouched, and on any error or
interrupt the temporary file is removed. :func:`staged_folder` does the same for a folder's files:
they are made in a hidden staging folder and moved in together at the end. :func:`folder_lock` keeps
two processes from writing one folder at once.
"""

from __future__ import annotations

import contextlib
import glob
import json
import math
import os
import shutil
import socket
import tempfile
from pathlib import Path

#: The name's start of :func:`staged_folder`'s hidden stage.
STAGE_PREFIX = ".partial-"

#: This process's hidden temporaries being written: :func:`remove_temporaries` removes them where a
#: command is ended without unwinding (Ctrl-C inside a compiled program).
_IN_FLIGHT: set[Path] = set()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path):
    """``with atomic_path(p) as tmp: write(tmp)``: ``p`` appears, complete, when the block ends. The
    temporary ``.STEM.PID-HOST-*SUFFIX`` of a killed process is removed by the next write of ``p``."""
    path = Path(path)
    start = f".{path.stem}."
    _remove_stale(path.parent, start, path.suffix)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=start + _owner(os.getpid()), suffix=path.suffix)
    os.close(fd)
    try:
        with _in_flight(Path(tmp)):
            yield Path(tmp)
            os.chmod(tmp, 0o666 & ~_umask())  # mkstemp's 0600 would make outputs private
            os.replace(tmp, path)
    except OSError as e:  # a full disk, say: name the file the user asked for, not the hidden one
        if e.filename in (None, tmp):
            raise OSError(e.errno, e.strerror or str(e), str(path)) from e
        raise


@contextlib.contextmanager
def staged_folder(out, last=()):
    """``with staged_folder(folder) as stage: write files into stage``: the files appear in ``folder``
    (created if need be) when the block ends, ``last`` (the names that say the output is finished)
    after the others; on an error or interrupt none do, and the hidden ``.partial-PID-HOST-*`` stage
    is removed (one left by a killed process: by the next run in ``folder``)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    _remove_stale(out, STAGE_PREFIX)
    stage = Path(tempfile.mkdtemp(dir=out, prefix=STAGE_PREFIX + _owner(os.getpid())))
    try:
        with _in_flight(stage):
            yield stage
            names = sorted(p.name for p in stage.iterdir())
            for name in [n for n in names if n not in last] + [n for n in last if n in names]:
                os.replace(stage / name, out / name)
    except OSError as e:  # name the output the user asked for, not its place in the stage
        if isinstance(e.filename, str) and Path(e.filename).parent == stage:
            raise OSError(e.errno, e.strerror or str(e), str(out / Path(e.filename).name)) from e
        raise


def _owner(pid: int) -> str:
    """The part of a temporary's name that says whose it is: ``PID-HOST-``."""
    return f"{pid}-{socket.gethostname()}-"


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()


@contextlib.contextmanager
def _in_flight(tmp: Path):
    """Register ``tmp`` while the block runs; it is removed when the block ends, however it ends."""
    _IN_FLIGHT.add(tmp)
    try:
        yield
    finally:
        _IN_FLIGHT.discard(tmp)
        _remove(tmp)


def _remove_stale(folder: Path, start: str, end: str = "") -> None:
    """Remove the temporaries ``start + PID-HOST- ... + end`` in ``folder`` whose process, on this host,
    has gone (another host's cannot be checked from here: they stay, as :func:`folder_lock`'s do)."""
    for p in folder.glob(glob.escape(start) + "*" + glob.escape(end)):
        pid = p.name[len(start) :].split("-")[0]
        if pid.isdigit() and p.name.startswith(start + _owner(int(pid))) and not _alive(int(pid)):
            _remove(p)


def remove_temporaries() -> None:
    """Remove this process's temporaries still being written (before it ends without unwinding)."""
    for tmp in list(_IN_FLIGHT):
        _remove(tmp)


#: The lock file :func:`folder_lock` makes in a folder.
LOCK_NAME = ".lock"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


@contextlib.contextmanager
def folder_lock(folder, command: str):
    """Hold ``folder``'s lock (``.lock``: this process's id and host) while the block runs; raise a
    one-line ``ValueError`` where another live process holds it. A lock whose process has gone (killed)
    is taken over; one held on another host is not (its process cannot be checked from here)."""
    path = Path(folder) / LOCK_NAME
    me = f"{os.getpid()} {socket.gethostname()}"
    for _ in range(2):
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            try:
                pid, host = (path.read_text().split() + ["", ""])[:2]
            except FileNotFoundError:  # released meanwhile
                continue
            if host == socket.gethostname() and pid.isdigit() and not _alive(int(pid)):
                with contextlib.suppress(FileNotFoundError):
                    path.unlink()  # stale: its process was killed
                continue
            raise ValueError(
                f"{str(Path(folder))!r} is in use by another {command} (process {pid or '?'} on "
                f"{host or '?'}); wait for it to end or choose another folder (if no such process "
                f"runs, remove {str(path)!r})"
            ) from None
        with os.fdopen(fd, "w") as f:
            f.write(me + "\n")
        break
    else:
        raise ValueError(f"{str(Path(folder))!r}: could not take its lock {str(path)!r}")
    try:
        yield path
    finally:
        with contextlib.suppress(OSError):
            if path.read_text().strip() == me:
                path.unlink()


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
