"""tools/apt-packages.txt (every command's: the build, software in the loop, the demo) and each
command's own list tools/apt-packages-NEED.txt (installed when the command first needs it,
tools/build/packages.py; `armctl test` installs them all), installed with --no-install-recommends,
bring every file that the presets, targets and tests take from the system, proved on this machine
without a second one: each such file is owned (dpkg -S) by a package that apt would install for the
base list and the need's list on an empty machine (apt-get -s with an empty dpkg status: Depends
and Pre-Depends, alternatives resolved as apt resolves them, never Recommends). A package that only
a Recommends brings (the aarch64 C library was one), or that only another need's list brings (the
demo would then fail on a new machine), fails here, naming the file and its package."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from functools import cache
from pathlib import Path

import pytest

from gen.lib.paths import REPO
from tools.build.packages import NEEDS, listed

APT_LIST = REPO / "tools" / "apt-packages.txt"

ARM_M4 = ["-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard"]


def _print_file(cc: str, name: str, *flags: str) -> str:
    """The file the compiler would link for `name` (as the build does), or '' if it has none."""
    exe = shutil.which(cc)
    if exe is None:
        return ""
    r = subprocess.run([exe, *flags, f"-print-file-name={name}"], capture_output=True, text=True)
    path = r.stdout.strip()
    return os.path.normpath(path) if os.path.isabs(path) else ""


def _program(name: str) -> str:
    return shutil.which(name, path="/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin") or ""


def _library(soname: str) -> str:
    r = subprocess.run(["/sbin/ldconfig", "-p"], capture_output=True, text=True)
    m = re.search(rf"^\s*{re.escape(soname)} \(libc6,x86-64\) => (\S+)$", r.stdout, re.M)
    return m.group(1) if m else ""


# (the list it must come from: None, every command's; else the need's; what needs it; the file).
# Found the way the build or test finds it, so a file from somewhere else (a pip package,
# /usr/local) does not count.
REQUIRED: list[tuple[str | None, str, str]] = [
    (None, "every build: CMake, Ninja", _program("cmake")),
    (None, "every build: Ninja", _program("ninja")),
    (None, "every build: the compiler cache the arm folders share", _program("ccache")),
    (None, "host C build: the C library to link (libc6-dev)", _print_file("gcc", "crt1.o")),
    (None, "host C build: libc.so", _print_file("gcc", "libc.so")),
    (None, "host C++ tests and benchmark: libstdc++", _print_file("g++", "libstdc++.so")),
    (None, "host tests: the Eigen reference and benchmark", "/usr/include/eigen3/Eigen/Dense"),
    (None, "the wheel's liblcm (controller, logger): glib", _library("libglib-2.0.so.0")),
    ("aarch64", "aarch64 target: crt1.o", _print_file("aarch64-linux-gnu-gcc", "crt1.o")),
    ("aarch64", "aarch64 target: crti.o", _print_file("aarch64-linux-gnu-gcc", "crti.o")),
    ("aarch64", "aarch64 target: static libc", _print_file("aarch64-linux-gnu-gcc", "libc.a")),
    ("aarch64", "aarch64 target: static libm", _print_file("aarch64-linux-gnu-gcc", "libm.a")),
    ("aarch64", "aarch64 target: libgcc", _print_file("aarch64-linux-gnu-gcc", "libgcc.a")),
    ("cortex-m", "Cortex-M targets: newlib-nano libc", _print_file("arm-none-eabi-gcc", "libc_nano.a", *ARM_M4)),
    ("cortex-m", "Cortex-M targets: nano.specs", _print_file("arm-none-eabi-gcc", "nano.specs", *ARM_M4)),
    ("cortex-m", "Cortex-M targets: nosys.specs", _print_file("arm-none-eabi-gcc", "nosys.specs", *ARM_M4)),
    ("cortex-m", "Cortex-M targets: libgcc", _print_file("arm-none-eabi-gcc", "libgcc.a", *ARM_M4)),
    ("cortex-m", "Cortex-M targets: size report", _program("arm-none-eabi-size")),
    ("cortex-m", "Cortex-M tests: QEMU's mps2 boards", _program("qemu-system-arm")),
    ("vm", "the VM (SocketCAN): QEMU", _program("qemu-system-x86_64")),
    ("vm", "the VM: its BIOS", "/usr/share/seabios/bios-256k.bin"),
    ("vm", "the VM: its VGA BIOS", "/usr/share/seabios/vgabios-stdvga.bin"),
    ("vm", "the VM: -kernel boot ROM", "/usr/share/qemu/linuxboot_dma.bin"),
    ("vm", "the VM: kvmvapic ROM", "/usr/share/qemu/kvmvapic.bin"),
    ("vm", "the VM's initramfs: a static busybox", "/bin/busybox"),
    ("test", "the VM test: candump", _program("candump")),
    ("test", "the VM test: cansend", _program("cansend")),
    (None, "the VM: iproute2 (vcan set-up; multicast routes)", _program("ip")),
    ("timing", "armctl timing: cyclictest", _program("cyclictest")),
    ("bench", "armctl bench step: valgrind's callgrind", _program("valgrind")),
    ("bench", "armctl bench step: callgrind's tool", "/usr/libexec/valgrind/callgrind-amd64-linux"),
    (None, "test_study: pgrep, pkill", _program("pgrep")),
    ("fuzz", "armctl fuzz: clang", _program("clang")),
    ("fuzz", "armctl fuzz: libFuzzer's runtime", _print_file("clang", "libclang_rt.fuzzer-x86_64.a")),
    ("fuzz", "armctl fuzz: ASan's runtime", _print_file("clang", "libclang_rt.asan-x86_64.a")),
    (None, "armctl's venv from Debian's Python: ensurepip", "/usr/lib/python3.11/ensurepip/__init__.py"),
    (None, "armctl render: the EGL loader MuJoCo's context opens", _library("libEGL.so.1")),
    (None, "armctl render: Mesa's EGL", _library("libEGL_mesa.so.0")),
    (None, "armctl render: Mesa's EGL, found by the loader", "/usr/share/glvnd/egl_vendor.d/50_mesa.json"),
    (None, "armctl render: Mesa's software rasteriser (the EGL device without a GPU)",
     "/usr/lib/x86_64-linux-gnu/dri/swrast_dri.so"),
    (None, "armctl render: OpenGL for PyOpenGL on EGL", _library("libOpenGL.so.0")),
    ("test", "test_report_html: headless Chromium", _program("chromium-headless-shell")),
    ("docs", "the user guide's diagrams: Graphviz's dot (tools/commands/docs_hooks.py)", _program("dot")),
]


def listed_packages(every: bool = False) -> list[str]:
    """The base list's packages, and with every=True every need's too."""
    return listed(None) + ([p for n in NEEDS for p in listed(n)] if every else [])


@cache
def closure(every: bool = False) -> frozenset[str]:
    """What `apt-get install --no-install-recommends` of the base list (every=True: and every need's)
    installs on a machine with nothing installed: apt's own resolution against an empty dpkg status
    file. (One resolve takes 6-9 s here: the base list alone, then all of them, not a need at a time.)"""
    empty = Path(os.environ.get("TMPDIR", "/tmp")) / f"armctl-empty-dpkg-status-{os.getpid()}"
    empty.write_text("")
    try:
        r = subprocess.run(["apt-get", "install", "-s", "--no-install-recommends", "-o",
                            f"Dir::State::status={empty}", *listed_packages(every)], capture_output=True, text=True,
                           env={**os.environ, "LC_ALL": "C"})
    finally:
        empty.unlink(missing_ok=True)
    assert r.returncode == 0, f"apt-get -s cannot resolve the lists: {r.stderr[-2000:]}"
    return frozenset(m.split(":")[0] for m in re.findall(r"^Inst (\S+)", r.stdout, re.M))


def owner(path: str) -> str | None:
    """The Debian package that installed path (merged /usr: also tried without and with /usr)."""
    real = os.path.realpath(path)
    candidates = dict.fromkeys([path, real, *(p.removeprefix("/usr") for p in (path, real) if p.startswith("/usr/"))])
    for cand in candidates:
        r = subprocess.run(["dpkg", "-S", cand], capture_output=True, text=True)
        if r.returncode == 0:
            for line in r.stdout.splitlines():  # "pkg[:arch][, pkg2]: /path"
                pkgs, _, p = line.rpartition(": ")
                if p == cand:
                    return pkgs.split(",")[0].split(":")[0].strip()
    return None


pytestmark = pytest.mark.skipif(shutil.which("dpkg") is None or shutil.which("apt-get") is None,
                                reason="not a Debian machine: tools/apt-packages*.txt do not apply")


@pytest.mark.parametrize("every", [False, True], ids=["base", "every list"])
def test_the_list_resolves_without_recommends_and_names_real_packages(every: bool) -> None:
    """Every listed package is one apt installs on an empty machine (a package that is installed
    here but that apt cannot resolve there, a virtual or a vanished name, fails)."""
    got = closure(every)
    for pkg in listed_packages(every):
        assert pkg in got, f"{pkg}: apt-get -s on an empty machine does not install it"
    assert len(got) > len(listed_packages(every))


def test_every_list_exists_and_no_package_is_in_two() -> None:
    """A need's list beside the base one for each need tools/build/packages.py names, and each
    package in one list: the base list holds nothing a need installs at first use."""
    lists = sorted(p.name for p in (REPO / "tools").glob("apt-packages*.txt"))
    assert lists == sorted(["apt-packages.txt", *(f"apt-packages-{n}.txt" for n in NEEDS)])
    seen: dict[str, str] = {}
    for need in [None, *NEEDS]:
        for pkg in listed(need):
            assert pkg not in seen, f"{pkg} is in the {seen[pkg]} list and the {need or 'base'} list"
            seen[pkg] = need or "base"


@pytest.mark.parametrize(("need", "what", "path"), REQUIRED, ids=[w for _, w, _ in REQUIRED])
def test_every_needed_file_comes_from_the_list(need: str | None, what: str, path: str) -> None:
    assert path and os.path.exists(path), f"{what}: not found on this machine ({path or 'no such file'})"
    pkg = owner(path)
    assert pkg is not None, f"{what}: {path} belongs to no Debian package (installed by hand?)"
    where = "tools/apt-packages.txt" + (" and every tools/apt-packages-NEED.txt" if need else "")
    assert pkg in closure(need is not None), (
        f"{what}: {path} comes from Debian package '{pkg}', which `apt-get install --no-install-recommends` "
        f"of {where} does not install: add it to {'tools/apt-packages-' + need + '.txt' if need else where}")


def test_the_vm_kernel_package_is_in_the_archive() -> None:
    """The VM boots Debian's kernel, downloaded (never installed) by `apt-get download` of the
    package linux-image-amd64 names: that name must resolve in this machine's apt sources."""
    from tools.vm.image import kernel_package_name

    pkg = kernel_package_name()
    r = subprocess.run(["apt-cache", "policy", pkg], capture_output=True, text=True)
    assert re.search(r"Candidate: (?!\(none\))\S+", r.stdout), f"{pkg}: no candidate in the apt sources: {r.stdout}"
