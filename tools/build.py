"""Configure and build the C side with CMake presets (incremental: a no-op build takes < 1 s)."""

from __future__ import annotations

import subprocess
import sys

from tools.paths import REPO, build_dir

PRESETS = ("debug", "release")


def build(preset: str = "release", quiet: bool = True) -> None:
    if preset not in PRESETS:
        raise ValueError(f"preset '{preset}': expected one of {', '.join(PRESETS)}")
    out = subprocess.DEVNULL if quiet else None
    py = f"-DARM_PYTHON={sys.executable}"
    if not (build_dir(preset) / "CMakeCache.txt").exists():
        subprocess.run(["cmake", "--preset", preset, py], cwd=REPO, check=True, stdout=out)
    r = subprocess.run(["cmake", "--build", "--preset", preset], cwd=REPO, stdout=subprocess.PIPE,
                       stderr=subprocess.STDOUT, text=True)
    if r.returncode != 0:
        print(r.stdout, file=sys.stderr)
        raise SystemExit(f"armctl: build ({preset}) failed")
    if not quiet:
        print(r.stdout.strip().splitlines()[-1] if r.stdout.strip() else "up to date")
