"""Output folders checked before the work: a command that would fail to write its results after
minutes of work fails at once instead, naming the option and the path."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


class OutDirError(ValueError):
    pass


def check_out_dir(path: Path, option: str = "--out") -> None:
    """Proves `path` can be a folder of results: a probe file written and removed in it (as
    root, permission bits do not say whether a read-only mount takes writes). Folders it had to
    create for the probe are removed again: a refused command leaves nothing behind."""
    if path.exists() and not path.is_dir():
        raise OutDirError(f"{option} {path}: is a file, not a folder")
    created = [a for a in [path, *path.parents] if not a.exists()]
    try:
        path.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".armctl-probe-", dir=path)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise OutDirError(f"{option} {path}: cannot write there ({exc.strerror or exc})") from None
    finally:
        for d in created:  # deepest first
            try:
                d.rmdir()
            except OSError:
                break


def check_out_file(path: Path, option: str = "--out") -> None:
    """The folder a results file goes to is writable, and the file itself is not a folder."""
    if path.is_dir():
        raise OutDirError(f"{option} {path}: is a folder; give a file name")
    check_out_dir(path.parent, option)
