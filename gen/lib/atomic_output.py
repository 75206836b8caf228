"""The project's one way to write output: each file appears whole or not at all, and a failed
write (a full disk, a read-only mount, any OSError) leaves no temporary file behind and says
which path and why in one line. gen/, host_sim/ and tools/ all use it (gen/lib: the library
layer below them)."""

from __future__ import annotations

import functools
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any, Callable


class OutputError(OSError):
    """An output could not be written; str() is one line naming the path and the reason.

    An OSError, so the commands that already turn an OSError into a one-line error keep doing so;
    built from (errno, message, path) only, so it pickles (a study's runs may be on workers)."""

    def __str__(self) -> str:
        return str(self.strerror)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


# mkstemp makes its file 0600; an output is as readable as any file this process creates.
_FILE_MODE = 0o666 & ~_umask()


def _failed(path: Path, exc: OSError) -> OutputError:
    reason = exc.strerror or str(exc) or type(exc).__name__
    return OutputError(exc.errno, f"cannot write {path}: {reason}", str(path))


def _write_synced(path: Path, data: bytes) -> None:
    with open(path, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())  # ENOSPC can surface only here (delayed allocation): before the rename


def write_bytes_atomic(path: Path, data: bytes) -> None:
    """The temporary file sits beside `path` (same filesystem: the rename is atomic)."""
    tmp: Path | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=f".{path.name}.tmp.", dir=path.parent)
        os.fchmod(fd, _FILE_MODE)
        os.close(fd)
        tmp = Path(name)
        _write_synced(tmp, data)
        os.replace(tmp, path)
    except OSError as exc:
        if tmp is not None:
            tmp.unlink(missing_ok=True)
        raise _failed(path, exc) from None


def write_text_atomic(path: Path, text: str) -> None:
    write_bytes_atomic(path, text.encode("utf-8"))


def write_json_atomic(path: Path, data: Any) -> None:
    write_text_atomic(path, json.dumps(data, indent=2) + "\n")


def write_files_atomically(out_dir: Path, files: dict[str, str]) -> None:
    """Write every file into a temp dir inside out_dir, then move each into place.

    Inside, not beside: out_dir may be a mount point, and a rename cannot cross filesystems. Any
    failure before the moves leaves out_dir as it was (removed again if this call made it);
    other files already in out_dir are never touched, nor is a file whose content is already the
    same (its time stays: the build's restat then rebuilds nothing downstream of it). JSON files
    move last: a reader that sees the new manifest also sees the files it describes."""
    out_dir = out_dir.resolve()
    made = [d for d in (out_dir, *out_dir.parents) if not d.exists()]
    tmp: Path | None = None
    failed = out_dir  # the name the user asked for, never our temporary one
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=".tmp-", dir=out_dir))
        changed = {}
        for name, text in files.items():
            failed = out_dir / name
            data = text.encode("utf-8")
            try:
                if (out_dir / name).read_bytes() == data:
                    continue
            except OSError:
                pass
            _write_synced(tmp / name, data)
            changed[name] = text
        for name in sorted(changed, key=lambda n: n.endswith(".json")):
            failed = out_dir / name
            os.replace(tmp / name, out_dir / name)
    except OSError as exc:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
            tmp = None
        for d in made:  # deepest first; stops at the first that is not empty
            try:
                d.rmdir()
            except OSError:
                break
        raise _failed(failed, exc) from None
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)


def exit_on_output_error(prog: str) -> Callable[[Callable[[list[str] | None], int]], Callable[[list[str] | None], int]]:
    """For a generator's main: an unwritable output is one line (`prog: cannot write PATH: reason`)
    and exit 1, not a traceback in the middle of a build's log."""

    def decorate(main: Callable[[list[str] | None], int]) -> Callable[[list[str] | None], int]:
        @functools.wraps(main)
        def wrapped(argv: list[str] | None = None) -> int:
            try:
                return main(argv)
            except OutputError as exc:
                print(f"{prog}: {exc}", file=sys.stderr)
                return 1

        return wrapped

    return decorate
