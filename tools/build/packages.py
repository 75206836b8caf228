"""The Debian packages a command needs beyond every command's (tools/apt-packages.txt, which
tools/armctl installs before any command), installed when a command first needs them, and saying
so: the demo never pays for a cross compiler, QEMU or a browser it does not run.

Each need is a list beside the base one, tools/apt-packages-NEED.txt (one package a line); `armctl
test` installs them all. As root on Debian, a missing package is installed (apt-get, no
recommends); otherwise the error names the apt-get line to run.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import threading

from gen.lib.paths import REPO

LISTS = REPO / "tools"
# need -> what needs it (said when installing)
NEEDS = {
    "cortex-m": "the Cortex-M build and its QEMU runs (build --target cortex-m*, hil --target, bench pil)",
    "aarch64": "the aarch64 build (build --target aarch64)",
    "vm": "the qemu VM with SocketCAN (hil --bus vm, vcan)",
    "timing": "armctl timing (cyclictest)",
    "bench": "armctl bench step (valgrind's callgrind)",
    "fuzz": "armctl fuzz (clang and libFuzzer)",
    "docs": "the user guide's build (mkdocs build, mkdocs serve: its diagrams, Graphviz's dot)",
    "test": "armctl test",
}
_LOCK = threading.Lock()
_READY: set[str] = set()  # the needs found installed in this process


class PackagesMissing(RuntimeError):
    """A command needs Debian packages this user cannot install; the message gives the line."""


def list_path(need: str) -> str:
    return str(LISTS / f"apt-packages-{need}.txt")


def listed(need: str | None) -> list[str]:
    """A list's packages: the base one (None), or a need's."""
    path = LISTS / ("apt-packages.txt" if need is None else f"apt-packages-{need}.txt")
    return [ln.strip() for ln in path.read_text().splitlines() if ln.strip() and not ln.lstrip().startswith("#")]


def missing(packages: list[str]) -> list[str]:
    """The packages dpkg does not have installed (all of them when dpkg-query fails)."""
    r = subprocess.run(["dpkg-query", "-W", "-f", "${Package} ${Status}\n", *packages], capture_output=True, text=True)
    have = {ln.split()[0] for ln in r.stdout.splitlines() if ln.endswith(" install ok installed")}
    return [p for p in packages if p not in have]


def ensure(need: str) -> None:
    """The need's packages installed (as root), else PackagesMissing with the apt-get line; not a
    Debian machine (no dpkg-query): nothing to do, the user installs by hand."""
    if need not in NEEDS:
        raise ValueError(f"unknown need {need!r}")
    if shutil.which("dpkg-query") is None:
        return
    with _LOCK:
        if need in _READY:
            return
        todo = missing(listed(need))
        if not todo:
            _READY.add(need)
            return
        if os.geteuid() != 0:
            raise PackagesMissing(f"{NEEDS[need]} needs Debian packages that are not installed; run: "
                                  f"sudo apt-get install -y --no-install-recommends {' '.join(todo)}")
        print(f"armctl: installing Debian packages for {NEEDS[need]} (first use): {' '.join(todo)}",
              file=sys.stderr, flush=True)
        env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
        for argv in (["apt-get", "update", "-qq"], ["apt-get", "install", "-y", "-qq", "--no-install-recommends",
                                                    *todo]):
            r = subprocess.run(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            if r.returncode != 0:
                last = (r.stderr.strip().splitlines() or ["no output"])[-1]
                raise PackagesMissing(f"{' '.join(argv[:2])} failed for {NEEDS[need]}: {last}")
        _READY.add(need)
