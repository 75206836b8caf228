"""Write a set of output files so that a failed run leaves nothing half-written."""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path


def write_files_atomically(out_dir: Path, files: dict[str, str]) -> None:
    """Write every file into a temp dir beside out_dir, then move each into place with os.replace.

    Each file appears whole or not at all; a failure before the moves leaves out_dir untouched.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".tmp-", dir=out_dir))
    try:
        for name, text in files.items():
            (tmp / name).write_text(text)
        for name in files:
            os.replace(tmp / name, out_dir / name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
