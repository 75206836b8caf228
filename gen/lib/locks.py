"""Locks where two armctl commands share a file: an flock on a lock file, held for the block and
released when it ends or its process dies (so a killed command never leaves a stale lock).

Used for a build folder (tools/build/__init__.py), the kept tuning (tools/study/__init__.py) and a study's --out.
"""

from __future__ import annotations

import fcntl
import os
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


class LockHeld(RuntimeError):
    """The lock is taken by another process (or thread) and the caller did not wait."""


@contextmanager
def flocked(path: Path, *, wait: bool = True, waiting: str | None = None,
            timeout_s: float | None = None) -> Iterator[None]:
    """An exclusive lock on `path` (created if need be) for the block. Taken: wait (printing
    `waiting` once, if given; at most timeout_s, if given) or, with wait=False or past timeout_s,
    raise LockHeld."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if not wait:
                raise LockHeld(str(path)) from None
            if waiting:
                print(waiting, file=sys.stderr)
            if timeout_s is None:
                fcntl.flock(fd, fcntl.LOCK_EX)
            else:
                _take_within(fd, path, timeout_s)
        yield
    finally:
        os.close(fd)  # releases the flock


def _take_within(fd: int, path: Path, timeout_s: float) -> None:
    """flock has no timeout of its own: try until it is taken or timeout_s have passed."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return
        except BlockingIOError:
            if time.monotonic() > deadline:
                raise LockHeld(str(path)) from None
            time.sleep(0.1)
