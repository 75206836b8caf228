"""Write the output files so that a failed run leaves no partial header behind.

All files are written into a temporary directory beside DIR (same filesystem, so rename is
atomic), then each is moved into DIR with os.replace. Any failure before the moves leaves DIR as
it was; other files already in DIR (e.g. the robot-model header) are never touched.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path


def write_atomically(out_dir: Path, files: dict[str, str]) -> None:
    out_dir = out_dir.resolve()
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.synth-", dir=out_dir.parent))
    try:
        for name, text in files.items():
            with open(tmp / name, "w", encoding="utf-8") as fh:
                fh.write(text)
                fh.flush()
                os.fsync(fh.fileno())
        out_dir.mkdir(exist_ok=True)
        # The manifest goes last: a reader that sees the new manifest also sees the new headers.
        order = sorted(files, key=lambda n: n.endswith(".json"))
        for name in order:
            os.replace(tmp / name, out_dir / name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
