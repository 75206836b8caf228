"""Fetch what the aarch64 controller needs to link LCM statically, from Debian's own archive.

The lcm wheel ships an x86-64 liblcm only, PyPI has no lcm sdist, and Debian builds no static
liblcm. So this fetches, with apt-get on a private state directory (the machine's apt
configuration, its architectures and its package lists stay untouched):

- the source of Debian's lcm package (bookworm: 1.3.1; only its C library is compiled, by
  cmake/lcm_cross.cmake, into a static library for the target),
- libglib2.0-dev:arm64 and libpcre2-dev:arm64 (headers and static libraries liblcm needs),
  unpacked with dpkg -x into OUT/sysroot, never installed.

The LCM wire format is the same in 1.3.1 and the wheel's 1.5.3 (the host side: lcm-logger,
Python), and lcm-gen 1.5.3's C compiles against 1.3.1's lcm_coretypes.h.

Usage: python3 cmake/fetch_aarch64_deps.py --out build/deps/aarch64   (idempotent; ~10 s, ~5 MB)
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import shutil
import subprocess
import sys
import tarfile
from pathlib import Path

ARCH = "arm64"
BINARY_PACKAGES = ["libglib2.0-dev", "libpcre2-dev"]
SOURCE_PACKAGE = "lcm"
STAMP = "fetched.json"


def _system_sources() -> list[tuple[str, str]]:
    """(file name, text) of the machine's apt sources, deb-src enabled alongside deb."""
    out: list[tuple[str, str]] = []
    for path in sorted(glob.glob("/etc/apt/sources.list.d/*.sources")):
        lines = []
        for line in Path(path).read_text().splitlines():
            if line.strip().startswith("Types:") and "deb-src" not in line:
                line = "Types: deb deb-src"
            lines.append(line)
        out.append((Path(path).name, "\n".join(lines) + "\n"))
    for path in ["/etc/apt/sources.list", *sorted(glob.glob("/etc/apt/sources.list.d/*.list"))]:
        if not os.path.exists(path):
            continue
        lines = []
        for line in Path(path).read_text().splitlines():
            lines.append(line)
            if line.strip().startswith("deb "):
                lines.append("deb-src " + line.strip()[4:])
        out.append((Path(path).name if path.endswith(".list") else "sources.list", "\n".join(lines) + "\n"))
    if not out:
        raise SystemExit("fetch_aarch64_deps: no apt sources found under /etc/apt")
    return out


def _apt(root: Path, *args: str, cwd: Path | None = None, check: bool = True) -> str:
    opts = [
        f"-oDir::State={root}/state",
        f"-oDir::State::status={root}/state/status",
        f"-oDir::Cache={root}/cache",
        f"-oDir::Etc::SourceList={root}/etc/none.list",
        f"-oDir::Etc::SourceParts={root}/etc/sources.list.d",
        f"-oAPT::Architecture={ARCH}",
        f"-oAPT::Architectures::={ARCH}",
        "-oAPT::Sandbox::User=root",
        "-qq",
    ]
    r = subprocess.run(["apt-get", *opts, *args], cwd=cwd, capture_output=True, text=True)
    if r.returncode != 0 and check:
        raise SystemExit(f"fetch_aarch64_deps: apt-get {' '.join(args)} failed:\n{r.stdout}{r.stderr}")
    return r.stdout + r.stderr


def fetch(out: Path) -> dict[str, str]:
    stamp = out / STAMP
    if stamp.exists():
        return json.loads(stamp.read_text())
    if shutil.which("apt-get") is None or shutil.which("dpkg") is None:
        raise SystemExit("fetch_aarch64_deps: needs apt-get and dpkg (a Debian machine)")
    tmp = out.with_name(out.name + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)
    apt = tmp / "apt"
    for d in ("state/lists/partial", "cache/archives/partial", "etc/sources.list.d"):
        (apt / d).mkdir(parents=True)
    (apt / "state" / "status").touch()
    (apt / "etc" / "none.list").touch()
    for name, text in _system_sources():
        (apt / "etc" / "sources.list.d" / name).write_text(text)

    _apt(apt, "update")
    debs = tmp / "debs"
    debs.mkdir()
    _apt(apt, "download", *BINARY_PACKAGES, cwd=debs)
    src = tmp / "src"
    src.mkdir()
    # Only the upstream tarball is used; the Debian packaging files may be missing from a
    # mirror (seen: 404 for the .debian.tar.xz), which apt reports as a failure. Judged below.
    apt_said = _apt(apt, "source", "--download-only", SOURCE_PACKAGE, cwd=src, check=False)

    sysroot = tmp / "sysroot"
    sysroot.mkdir()
    versions: dict[str, str] = {}
    for deb in sorted(debs.glob("*.deb")):
        subprocess.run(["dpkg-deb", "-x", str(deb), str(sysroot)], check=True)
        versions[deb.name.split("_")[0]] = deb.name.split("_")[1]
    origs = sorted(src.glob(f"{SOURCE_PACKAGE}_*.orig.tar.*"))
    if not origs:
        raise SystemExit(f"fetch_aarch64_deps: no {SOURCE_PACKAGE} source tarball was downloaded:\n{apt_said}")
    with tarfile.open(origs[0]) as tf:
        tf.extractall(src, filter="data")
    tops = [p for p in src.iterdir() if p.is_dir() and (p / "lcm" / "lcm.c").exists()]
    if not tops:
        raise SystemExit(f"fetch_aarch64_deps: {origs[0].name} has no lcm/lcm.c")
    tops[0].rename(tmp / "lcm-src")
    versions[SOURCE_PACKAGE + " (source)"] = origs[0].name.split("_")[1].split(".orig")[0]
    shutil.rmtree(apt)
    shutil.rmtree(debs)
    shutil.rmtree(src)
    (tmp / STAMP).write_text(json.dumps(versions, indent=2) + "\n")
    shutil.rmtree(out, ignore_errors=True)
    tmp.rename(out)
    return versions


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, required=True)
    ns = p.parse_args()
    versions = fetch(ns.out.resolve())
    print("aarch64 deps: " + ", ".join(f"{k} {v}" for k, v in versions.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
