"""An exclusive lock across the processes of this machine, for files that several ``ebm-eval`` processes write."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path


@contextlib.contextmanager
def file_lock(path: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``path`` (created if missing) for the block; other holders wait.

    Where ``fcntl`` is missing (not POSIX) there is no lock: the writers' atomic renames still keep each file whole.

    :param path: the lock file.
    :return: a context manager.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as handle:
        try:
            import fcntl  # POSIX only: an optional dependency of the standard library
        except ImportError:  # pragma: no cover - not POSIX
            yield
            return
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


__all__ = ["file_lock"]
