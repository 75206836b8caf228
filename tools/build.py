"""Configure and build the C side with CMake presets (incremental: a no-op build takes < 1 s).

Host presets: debug (ASan + UBSan, tests), release. Cross targets (`armctl build --target T`):
aarch64 (static Linux controller, LCM built for the target), cortex-m4, cortex-m7, cortex-m3
(bare-metal golden-vector images for QEMU's mps2 boards). See CMakePresets.json and cmake/.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from tools.paths import REPO, build_dir

PRESETS = ("debug", "release")
CROSS_PRESETS = ("aarch64", "cortex-m4", "cortex-m7", "cortex-m3")
# `armctl build --target T`: T -> preset ("host" is the release build of this machine).
TARGETS = {"host": "release", **{p: p for p in CROSS_PRESETS}}
# Cross compilers and the Debian packages that bring them (tools/apt-packages.txt lists them).
_COMPILERS = {
    "aarch64": ("aarch64-linux-gnu-gcc", "gcc-aarch64-linux-gnu"),
    "cortex-m4": ("arm-none-eabi-gcc", "gcc-arm-none-eabi libnewlib-arm-none-eabi"),
    "cortex-m7": ("arm-none-eabi-gcc", "gcc-arm-none-eabi libnewlib-arm-none-eabi"),
    "cortex-m3": ("arm-none-eabi-gcc", "gcc-arm-none-eabi libnewlib-arm-none-eabi"),
}


class ToolchainMissing(RuntimeError):
    pass


def toolchain_missing(preset: str) -> str | None:
    """None if the preset's compiler is installed, else what to install."""
    if preset not in _COMPILERS:
        return None
    exe, pkgs = _COMPILERS[preset]
    if shutil.which(exe) is None:
        return f"{exe} not found: apt-get install {pkgs} (tools/armctl installs them when run as root)"
    return None


def build(preset: str = "release", quiet: bool = True) -> None:
    if preset not in PRESETS + CROSS_PRESETS:
        raise ValueError(f"preset '{preset}': expected one of {', '.join(PRESETS + CROSS_PRESETS)}")
    missing = toolchain_missing(preset)
    if missing:
        raise ToolchainMissing(f"armctl: build ({preset}): {missing}")
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
        lines = r.stdout.strip().splitlines()
        # The Cortex-M images print their memory and stack report (firmware/port/cortex_m).
        report = [ln for ln in lines if ln.startswith(f"{preset}: ")]
        for ln in report:
            print(ln)
        if lines and lines[-1] not in report:
            print(lines[-1])


def qemu_aarch64() -> Path:
    """A qemu-aarch64 that can run the cross-compiled controller on the UDP bus (QEMU >= 8 for
    setsockopt(IP_MULTICAST_IF)): fetched once from Debian's backports into build/deps/qemu."""
    out = REPO / "build" / "deps" / "qemu"
    exe = out / "qemu-aarch64"
    if not exe.exists():
        subprocess.run([sys.executable, str(REPO / "cmake" / "fetch_aarch64_deps.py"), "--qemu", "--out", str(out)],
                       check=True, stdout=subprocess.DEVNULL)
    return exe
