"""One trainer per run directory.

Two processes training into one directory would overwrite each other's checkpoints. A
run holds an advisory lock on ``OUT/.lock`` while it trains; the system lets it go when the
process ends, however it ends, so a killed run never leaves a stale lock behind. The file
holds the holder's process id, for the message. A process that holds a directory may take
it again (the parent of several starts goes on with the chosen one without letting go).
Where the system has no ``fcntl`` (Windows), runs are not locked.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

LOCK = ".lock"

_HELD: set[Path] = set()
"""The directories this process holds."""


class RunLockedError(ValueError):
    """Another process is training into the directory."""


@contextmanager
def held(out: str | Path) -> Iterator[None]:
    """Hold ``out``'s lock for the block (``out`` is made if missing); ``RunLockedError``
    where another process holds it."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    key = out.resolve()
    if key in _HELD:
        yield
        return
    with open(out / LOCK, "a+") as handle:
        if fcntl is not None:
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                handle.seek(0)
                holder = handle.read().strip()
                raise RunLockedError(f"{out} is being trained by another process{f' (pid {holder})' if holder else ''}: "
                                     "stop it before resuming, or choose another --out") from None
        handle.seek(0)
        handle.truncate()
        handle.write(f"{os.getpid()}\n")
        handle.flush()
        _HELD.add(key)
        try:
            yield
        finally:
            _HELD.discard(key)
            if fcntl is not None:
                fcntl.flock(handle, fcntl.LOCK_UN)
