"""tools/apt-packages.txt (and tools/apt-packages-test.txt, which `armctl test` alone installs),
installed with --no-install-recommends, brings every file that the
presets, targets and tests take from the system, proved on this machine without a second one:
each such file is owned (dpkg -S) by a package that apt would install for the list on an empty
machine (apt-get -s with an empty dpkg status: Depends and Pre-Depends, alternatives resolved as
apt resolves them, never Recommends). A package that only a Recommends brings (the aarch64 C
library was one) fails here, naming the file and its package."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from functools import cache
from pathlib import Path

import pytest

from gen.lib.paths import REPO

APT_LIST = REPO / "tools" / "apt-packages.txt"
APT_TEST_LIST = REPO / "tools" / "apt-packages-test.txt"

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


# (what needs it, the file). Found the way the build or test finds it, so a file from somewhere
# else (a pip package, /usr/local) does not count.
REQUIRED: list[tuple[str, str]] = [
    ("every build: CMake, Ninja", _program("cmake")),
    ("every build: Ninja", _program("ninja")),
    ("every build: the compiler cache the arm folders share", _program("ccache")),
    ("host C build: the C library to link (libc6-dev)", _print_file("gcc", "crt1.o")),
    ("host C build: libc.so", _print_file("gcc", "libc.so")),
    ("host C++ tests and benchmark: libstdc++", _print_file("g++", "libstdc++.so")),
    ("host tests: the Eigen reference and benchmark", "/usr/include/eigen3/Eigen/Dense"),
    ("the wheel's liblcm (controller, logger): glib", _library("libglib-2.0.so.0")),
    ("aarch64 target: crt1.o", _print_file("aarch64-linux-gnu-gcc", "crt1.o")),
    ("aarch64 target: crti.o", _print_file("aarch64-linux-gnu-gcc", "crti.o")),
    ("aarch64 target: static libc", _print_file("aarch64-linux-gnu-gcc", "libc.a")),
    ("aarch64 target: static libm", _print_file("aarch64-linux-gnu-gcc", "libm.a")),
    ("aarch64 target: libgcc", _print_file("aarch64-linux-gnu-gcc", "libgcc.a")),
    ("Cortex-M targets: newlib-nano libc", _print_file("arm-none-eabi-gcc", "libc_nano.a", *ARM_M4)),
    ("Cortex-M targets: nano.specs", _print_file("arm-none-eabi-gcc", "nano.specs", *ARM_M4)),
    ("Cortex-M targets: nosys.specs", _print_file("arm-none-eabi-gcc", "nosys.specs", *ARM_M4)),
    ("Cortex-M targets: libgcc", _print_file("arm-none-eabi-gcc", "libgcc.a", *ARM_M4)),
    ("Cortex-M targets: size report", _program("arm-none-eabi-size")),
    ("Cortex-M tests: QEMU's mps2 boards", _program("qemu-system-arm")),
    ("the VM (SocketCAN): QEMU", _program("qemu-system-x86_64")),
    ("the VM: its BIOS", "/usr/share/seabios/bios-256k.bin"),
    ("the VM: its VGA BIOS", "/usr/share/seabios/vgabios-stdvga.bin"),
    ("the VM: -kernel boot ROM", "/usr/share/qemu/linuxboot_dma.bin"),
    ("the VM: kvmvapic ROM", "/usr/share/qemu/kvmvapic.bin"),
    ("the VM's initramfs: a static busybox", "/bin/busybox"),
    ("the VM test: candump", _program("candump")),
    ("the VM test: cansend", _program("cansend")),
    ("the VM: iproute2 (vcan set-up; multicast routes)", _program("ip")),
    ("armctl timing: cyclictest", _program("cyclictest")),
    ("armctl bench step: valgrind's callgrind", _program("valgrind")),
    ("armctl bench step: callgrind's tool", "/usr/libexec/valgrind/callgrind-amd64-linux"),
    ("test_study: pgrep, pkill", _program("pgrep")),
    ("armctl fuzz: clang", _program("clang")),
    ("armctl fuzz: libFuzzer's runtime", _print_file("clang", "libclang_rt.fuzzer-x86_64.a")),
    ("armctl fuzz: ASan's runtime", _print_file("clang", "libclang_rt.asan-x86_64.a")),
    ("armctl's venv from Debian's Python: ensurepip", "/usr/lib/python3.11/ensurepip/__init__.py"),
    ("armctl render: the EGL loader MuJoCo's context opens", _library("libEGL.so.1")),
    ("armctl render: Mesa's EGL", _library("libEGL_mesa.so.0")),
    ("armctl render: Mesa's EGL, found by the loader", "/usr/share/glvnd/egl_vendor.d/50_mesa.json"),
    ("armctl render: Mesa's software rasteriser (the EGL device without a GPU)",
     "/usr/lib/x86_64-linux-gnu/dri/swrast_dri.so"),
    ("armctl render: OpenGL for PyOpenGL on EGL", _library("libOpenGL.so.0")),
    ("test_report_html: headless Chromium", _program("chromium-headless-shell")),
    ("the user guide's diagrams: Graphviz's dot (tools/commands/docs_hooks.py)", _program("dot")),
]


def listed_packages() -> list[str]:
    return [ln.strip() for path in (APT_LIST, APT_TEST_LIST) for ln in path.read_text().splitlines()
            if ln.strip() and not ln.startswith("#")]


@cache
def closure() -> frozenset[str]:
    """What `apt-get install --no-install-recommends LIST` installs on a machine with nothing
    installed: apt's own resolution against an empty dpkg status file."""
    empty = Path(os.environ.get("TMPDIR", "/tmp")) / f"armctl-empty-dpkg-status-{os.getpid()}"
    empty.write_text("")
    try:
        r = subprocess.run(["apt-get", "install", "-s", "--no-install-recommends", "-o",
                            f"Dir::State::status={empty}", *listed_packages()], capture_output=True, text=True,
                           env={**os.environ, "LC_ALL": "C"})
    finally:
        empty.unlink(missing_ok=True)
    assert r.returncode == 0, f"apt-get -s cannot resolve tools/apt-packages.txt: {r.stderr[-2000:]}"
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
                                reason="not a Debian machine: tools/apt-packages.txt does not apply")


def test_the_list_resolves_without_recommends_and_names_real_packages() -> None:
    got = closure()
    for pkg in listed_packages():
        assert pkg in got or subprocess.run(["dpkg-query", "-W", pkg], capture_output=True).returncode == 0, pkg
    assert len(got) > len(listed_packages())


@pytest.mark.parametrize(("what", "path"), REQUIRED, ids=[w for w, _ in REQUIRED])
def test_every_needed_file_comes_from_the_list(what: str, path: str) -> None:
    assert path and os.path.exists(path), f"{what}: not found on this machine ({path or 'no such file'})"
    pkg = owner(path)
    assert pkg is not None, f"{what}: {path} belongs to no Debian package (installed by hand?)"
    assert pkg in closure(), (f"{what}: {path} comes from Debian package '{pkg}', which "
                              f"`apt-get install --no-install-recommends` of tools/apt-packages.txt does not "
                              f"install: add it to tools/apt-packages.txt")


def test_the_vm_kernel_package_is_in_the_archive() -> None:
    """The VM boots Debian's kernel, downloaded (never installed) by `apt-get download` of the
    package linux-image-amd64 names: that name must resolve in this machine's apt sources."""
    from tools.vm.image import kernel_package_name

    pkg = kernel_package_name()
    r = subprocess.run(["apt-cache", "policy", pkg], capture_output=True, text=True)
    assert re.search(r"Candidate: (?!\(none\))\S+", r.stdout), f"{pkg}: no candidate in the apt sources: {r.stdout}"
