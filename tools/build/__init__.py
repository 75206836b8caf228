"""Configure and build the C side with CMake presets (incremental: a no-op build takes < 1 s).

Host presets: debug (ASan + UBSan, tests), release. Cross targets (`armctl build --target T`):
aarch64 (static Linux controller, LCM built for the target), cortex-m4, cortex-m7, cortex-m3
(bare-metal golden-vector images for QEMU's mps2 boards). See CMakePresets.json and cmake/.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from gen.lib.atomic_output import write_json_atomic
from gen.lib.locks import flocked
from gen.lib.paths import REPO, build_dir, controller_binary

PRESETS = ("debug", "release")
CROSS_PRESETS = ("aarch64", "cortex-m4", "cortex-m7", "cortex-m3")
# `armctl build --target T`: T -> preset ("host" is the release build of this machine).
TARGETS = {"host": "release", **{p: p for p in CROSS_PRESETS}}
# Cross compilers and the Debian packages that bring them (tools/apt-packages-aarch64.txt and
# -cortex-m.txt list them: installed by the first build that needs them, tools/build/packages.py).
_COMPILERS = {
    "aarch64": ("aarch64-linux-gnu-gcc", "gcc-aarch64-linux-gnu"),
    "cortex-m4": ("arm-none-eabi-gcc", "gcc-arm-none-eabi libnewlib-arm-none-eabi"),
    "cortex-m7": ("arm-none-eabi-gcc", "gcc-arm-none-eabi libnewlib-arm-none-eabi"),
    "cortex-m3": ("arm-none-eabi-gcc", "gcc-arm-none-eabi libnewlib-arm-none-eabi"),
}


class BuildError(RuntimeError):
    """A build that cannot be done; the message says why and what to do."""


class ToolchainMissing(BuildError):
    pass


def toolchain_missing(preset: str) -> str | None:
    """None if the preset's compiler is installed, else what to install."""
    if preset not in _COMPILERS:
        return None
    exe, pkgs = _COMPILERS[preset]
    if shutil.which(exe) is None:
        return f"{exe} not found: apt-get install {pkgs} (tools/armctl installs them when run as root)"
    return None


# Written after a successful configure; a build directory without it, or with another
# fingerprint, is configured again from scratch (`cmake --fresh`).
STAMP = ".armctl-configured.json"


class ConfigureFailed(BuildError):
    pass


def _first_line(argv: list[str]) -> str:
    """The first line a tool prints (its version), asked once per process for each version of the
    executable (its inode and mtime): every run of a study builds (a no-op), and asking cmake and
    both compilers cost 20 ms of a 150 ms run."""
    exe = shutil.which(argv[0])
    try:
        st = os.stat(os.path.realpath(exe)) if exe else None
    except OSError:
        st = None
    if st is None:  # not found: asked every time (it may be installed meanwhile)
        return _ask_first_line.__wrapped__(tuple(argv), None)
    return _ask_first_line(tuple(argv), (st.st_ino, st.st_mtime_ns, st.st_size))


@functools.lru_cache(maxsize=64)
def _ask_first_line(argv: tuple[str, ...], version: tuple[int, int, int] | None) -> str:
    try:
        r = subprocess.run(list(argv), capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"unavailable ({exc})"
    return (r.stdout.strip().splitlines() or [""])[0]


def _file_digest(path: Path) -> str:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()[:16]
    except OSError:
        return "missing"


def configure_fingerprint(preset: str, cache: dict[str, str] | None = None) -> dict[str, str]:
    """What a configured build directory depends on besides its sources (CMake itself re-runs
    for changed CMakeLists): the checkout's location, the machine, the preset and its toolchain
    file, the compilers, CMake and the Python that generates code. Any change means the cached
    configuration (compiler paths, found libraries, ...) may be wrong for this machine."""
    presets = json.loads((REPO / "CMakePresets.json").read_text())["configurePresets"]
    entry = next(p for p in presets if p["name"] == preset)
    toolchain = entry.get("toolchainFile", "").replace("${sourceDir}", str(REPO))
    exe = _COMPILERS.get(preset, (os.environ.get("CC") or "cc", ""))[0]
    compilers = [exe] if preset in _COMPILERS else [exe, os.environ.get("CXX") or "c++"]
    fp = {
        "source_dir": str(REPO),
        "machine": _machine_id(),
        "preset": json.dumps(entry, sort_keys=True),
        "toolchain_file": _file_digest(Path(toolchain)) if toolchain else "",
        "cmake": _first_line(["cmake", "--version"]),
        "python": sys.executable,
        # the compiler launcher (CMakeLists.txt): a folder configured with ccache cannot build without it
        "ccache": os.path.realpath(ccache) if (ccache := shutil.which("ccache")) else "missing",
        **{f"cache:{k}": v for k, v in sorted((cache or {}).items())},
    }
    for c in compilers:
        path = shutil.which(c)
        fp[f"compiler:{c}"] = f"{os.path.realpath(path)} {_first_line([path, '--version'])}" if path else "missing"
    return fp


def _machine_id() -> str:
    for p in (Path("/etc/machine-id"), Path("/var/lib/dbus/machine-id")):
        try:
            return p.read_text().strip()
        except OSError:
            continue
    return platform.node()


def ensure_configured(preset: str, bdir: Path, quiet: bool = True, cache: dict[str, str] | None = None) -> None:
    """Configure the preset in bdir unless a successful configure of this very fingerprint is
    recorded there. A failed or foreign configure is redone from scratch, and a failure shows
    CMake's own output."""
    stamp = bdir / STAMP
    want = configure_fingerprint(preset, cache)
    try:
        have = json.loads(stamp.read_text())
    except (OSError, ValueError):
        have = None
    if have == want and (bdir / "build.ninja").exists():
        return
    if have is not None or (bdir / "CMakeCache.txt").exists():
        changed = sorted(k for k in want if have is None or have.get(k) != want[k])
        why = (f"configured with a different {', '.join(changed)}" if have is not None
               else "no record of a successful configure")
        print(f"armctl: build ({preset}): configuring {bdir} again ({why})", file=sys.stderr)
    stamp.unlink(missing_ok=True)
    defs = [f"-D{k}={v}" for k, v in sorted({"ARM_PYTHON": sys.executable, **(cache or {})}.items())]
    r = subprocess.run(["cmake", "--preset", preset, "-B", str(bdir), "--fresh", *defs], cwd=REPO,
                       stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if r.returncode != 0:
        print(r.stdout, file=sys.stderr)
        raise ConfigureFailed(f"armctl: build ({preset}): configure failed (CMake's output above); "
                              "fix that and re-run: the next build configures again")
    if not quiet:
        tail = [ln for ln in r.stdout.splitlines() if ln.startswith("-- Build files")]
        print("\n".join(tail))
    write_json_atomic(stamp, want)


# Build folders the caller brought up to date just before, on this very tree (os.pathsep between
# them): a command run there does not check them again. The qemu VM's commands set it (the host
# built the tree they share over 9p, where a check is cmake and compiler --version in an emulated
# machine and ninja's stat of every file: tens of seconds a command). The folder must still hold
# a successful configure and the controller.
PREBUILT_ENV = "ARMCTL_PREBUILT"


def prebuilt(bdir: Path) -> bool:
    listed = {Path(p).resolve() for p in os.environ.get(PREBUILT_ENV, "").split(os.pathsep) if p}
    if bdir.resolve() not in listed:
        return False
    if not (bdir / STAMP).exists() or not controller_binary(bdir).exists():
        raise BuildError(f"armctl: build: {bdir} is in {PREBUILT_ENV} but not built (no configure record "
                         "or no controller): build it first")
    return True


LOCK = ".armctl-build.lock"  # in the build folder: flocked for a configure and build
_held = threading.local()     # the build folders this thread holds (a lock taken again is held)
_in_process: dict[Path, threading.Lock] = {}  # threads of this process queue here, silently
_in_process_lock = threading.Lock()


@contextmanager
def build_lock(bdir: Path) -> Iterator[None]:
    """One builder per build folder, across processes and threads: two ninjas or two configures
    in one folder corrupt it ("file truncated" at the link). Re-entrant within a thread."""
    held: set[Path] = _held.__dict__.setdefault("paths", set())
    key = bdir.resolve()
    if key in held:
        yield
        return
    with _in_process_lock:
        mine = _in_process.setdefault(key, threading.Lock())
    with mine, flocked(bdir / LOCK, waiting=f"armctl: build: waiting for another build in {bdir}"):
        held.add(key)
        try:
            yield
        finally:
            held.discard(key)


def build(preset: str = "release", quiet: bool = True, bdir: Path | None = None,
          cache: dict[str, str] | None = None, targets: list[str] | None = None) -> None:
    """Configure (when needed) and build a preset, in build/<preset> unless bdir is given;
    cache: CMake cache variables (-D) of this build, part of its configure fingerprint;
    targets: only these (and what they need), else everything."""
    if preset not in PRESETS + CROSS_PRESETS:
        raise ValueError(f"preset '{preset}': expected one of {', '.join(PRESETS + CROSS_PRESETS)}")
    if preset in _COMPILERS:  # its cross compiler (and QEMU for its runs), installed at first need
        from tools.build.packages import ensure

        ensure("aarch64" if preset == "aarch64" else "cortex-m")
    missing = toolchain_missing(preset)
    if missing:
        raise ToolchainMissing(f"armctl: build ({preset}): {missing}")
    bdir = bdir or build_dir(preset)
    if prebuilt(bdir):
        return
    with build_lock(bdir):
        fresh = not (bdir / "build.ninja").exists()
        ensure_configured(preset, bdir, quiet, cache)
        r = _ninja(["cmake", "--build", str(bdir), *(["--target", *targets] if targets else [])],
                   f"build {bdir.relative_to(REPO) if bdir.is_relative_to(REPO) else bdir}" if fresh else None)
    if r.returncode != 0:
        print(r.stdout, file=sys.stderr)
        raise BuildError(f"armctl: build ({preset}) failed (the compiler's output above)")
    if not quiet:
        lines = r.stdout.strip().splitlines()
        # The Cortex-M images print their memory and stack report (firmware/port/cortex_m).
        report = [ln for ln in lines if ln.startswith(f"{preset}: ")]
        for ln in report:
            print(ln)
        if lines and lines[-1] not in report:
            print(lines[-1])


NINJA_STEP = re.compile(r"^\[(\d+)/(\d+)\] ")


def _ninja(argv: list[str], progress: str | None) -> subprocess.CompletedProcess[str]:
    """The build's output, kept for a failure; progress: the label of a bar of ninja's [k/N] steps
    (a new build folder: a first build of an arm takes a minute or more)."""
    if progress is None:
        return subprocess.run(argv, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    from tqdm import tqdm

    lines: list[str] = []
    with subprocess.Popen(argv, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) as p, \
            tqdm(desc=progress, unit="step", leave=False) as bar:
        assert p.stdout is not None
        for line in p.stdout:
            lines.append(line)
            m = NINJA_STEP.match(line)
            if m:
                bar.total = int(m.group(2))
                bar.n = int(m.group(1))
                bar.refresh()
    return subprocess.CompletedProcess(argv, p.returncode, "".join(lines))


def qemu_aarch64() -> Path:
    """A qemu-aarch64 that can run the cross-compiled controller on the UDP bus (QEMU >= 8 for
    setsockopt(IP_MULTICAST_IF)): fetched once from Debian's backports into build/deps/qemu."""
    out = REPO / "build" / "deps" / "qemu"
    exe = out / "qemu-aarch64"
    if not exe.exists():
        subprocess.run([sys.executable, str(REPO / "cmake" / "fetch_aarch64_deps.py"), "--qemu", "--out", str(out)],
                       check=True, stdout=subprocess.DEVNULL)
    return exe
