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

With --qemu it fetches instead qemu-aarch64 (x86-64 host binary, statically linked) from the
release's backports (bookworm-backports: QEMU 10) into OUT/qemu-aarch64: bookworm's own QEMU 7.2
does not translate setsockopt(IP_MULTICAST_IF), which the CAN transport needs to pin its multicast
to the loopback interface, so the cross-compiled controller cannot open its bus under it.

Usage: python3 cmake/fetch_aarch64_deps.py --out build/deps/aarch64   (idempotent; ~10 s, ~5 MB)
       python3 cmake/fetch_aarch64_deps.py --qemu --out build/deps/qemu   (~15 s, 63 MB download)
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


def _codename() -> str:
    for line in Path("/etc/os-release").read_text().splitlines():
        if line.startswith("VERSION_CODENAME="):
            return line.split("=", 1)[1].strip().strip('"')
    raise SystemExit("fetch_aarch64_deps: no VERSION_CODENAME in /etc/os-release")


def _backports_sources() -> list[tuple[str, str]]:
    """The machine's own archive URI(s) for its release, with the release's backports suite."""
    code = _codename()
    uris: list[str] = []
    for _, text in _system_sources():
        for stanza in text.split("\n\n"):
            fields = dict(l.split(":", 1) for l in stanza.splitlines() if ":" in l and not l.startswith("#"))
            suites = fields.get("Suites", "").split()
            if code in suites:
                uris += fields.get("URIs", "").split()
        for line in text.splitlines():
            parts = line.split()
            if len(parts) >= 3 and parts[0] == "deb" and parts[2] == code:
                uris.append(parts[1])
    if not uris:
        raise SystemExit(f"fetch_aarch64_deps: no apt source for {code} found")
    key = "/usr/share/keyrings/debian-archive-keyring.gpg"
    text = (f"Types: deb\nURIs: {uris[0]}\nSuites: {code}-backports\nComponents: main\n"
            + (f"Signed-By: {key}\n" if os.path.exists(key) else ""))
    return [("backports.sources", text)]


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


def _apt(root: Path, *args: str, cwd: Path | None = None, check: bool = True, arch: str = ARCH) -> str:
    opts = [
        f"-oDir::State={root}/state",
        f"-oDir::State::status={root}/state/status",
        f"-oDir::Cache={root}/cache",
        f"-oDir::Etc::SourceList={root}/etc/none.list",
        f"-oDir::Etc::SourceParts={root}/etc/sources.list.d",
        f"-oAPT::Architecture={arch}",
        f"-oAPT::Architectures::={arch}",
        "-oAPT::Sandbox::User=root",
        "-qq",
    ]
    r = subprocess.run(["apt-get", *opts, *args], cwd=cwd, capture_output=True, text=True)
    if r.returncode != 0 and check:
        raise SystemExit(f"fetch_aarch64_deps: apt-get {' '.join(args)} failed:\n{r.stdout}{r.stderr}")
    return r.stdout + r.stderr


def safe_extract(tf: tarfile.TarFile, dest: Path) -> None:
    """Extract refusing members that leave dest (absolute paths, .., links out). Python 3.11.4+
    has the "data" filter for that; Debian 12's 3.11.2 does not, so check by hand there."""
    if hasattr(tarfile, "data_filter"):
        tf.extractall(dest, filter="data")
        return
    root = dest.resolve()
    for m in tf.getmembers():
        target = (root / m.name).resolve()
        if root not in target.parents and target != root:
            raise SystemExit(f"fetch_aarch64_deps: {m.name}: outside the extraction folder")
        if (m.issym() or m.islnk()) and not (target.parent / m.linkname).resolve().is_relative_to(root):
            raise SystemExit(f"fetch_aarch64_deps: {m.name}: links outside the extraction folder")
        if not (m.isfile() or m.isdir() or m.issym() or m.islnk()):
            raise SystemExit(f"fetch_aarch64_deps: {m.name}: not a file, folder or link")
    tf.extractall(dest)


def _fresh_apt(tmp: Path, sources: list[tuple[str, str]]) -> Path:
    """An empty apt state below a fresh `tmp`, knowing only `sources`: nothing of the host's apt is read or changed."""
    shutil.rmtree(tmp, ignore_errors=True)
    apt = tmp / "apt"
    for d in ("state/lists/partial", "cache/archives/partial", "etc/sources.list.d"):
        (apt / d).mkdir(parents=True)
    (apt / "state" / "status").touch()
    (apt / "etc" / "none.list").touch()
    for name, text in sources:
        (apt / "etc" / "sources.list.d" / name).write_text(text)
    return apt


def _publish(tmp: Path, out: Path, versions: dict[str, str]) -> dict[str, str]:
    """Stamps `tmp` and puts it at `out` in one rename, so an interrupted fetch never leaves a stamped half."""
    (tmp / STAMP).write_text(json.dumps(versions, indent=2) + "\n")
    shutil.rmtree(out, ignore_errors=True)
    tmp.rename(out)
    return versions


def fetch(out: Path) -> dict[str, str]:
    stamp = out / STAMP
    if stamp.exists():
        return json.loads(stamp.read_text())
    if shutil.which("apt-get") is None or shutil.which("dpkg") is None:
        raise SystemExit("fetch_aarch64_deps: needs apt-get and dpkg (a Debian machine)")
    tmp = out.with_name(out.name + ".partial")
    apt = _fresh_apt(tmp, _system_sources())

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
        safe_extract(tf, src)
    tops = [p for p in src.iterdir() if p.is_dir() and (p / "lcm" / "lcm.c").exists()]
    if not tops:
        raise SystemExit(f"fetch_aarch64_deps: {origs[0].name} has no lcm/lcm.c")
    tops[0].rename(tmp / "lcm-src")
    versions[SOURCE_PACKAGE + " (source)"] = origs[0].name.split("_")[1].split(".orig")[0]
    shutil.rmtree(apt)
    shutil.rmtree(debs)
    shutil.rmtree(src)
    return _publish(tmp, out, versions)


def fetch_qemu(out: Path) -> dict[str, str]:
    stamp = out / STAMP
    if stamp.exists():
        return json.loads(stamp.read_text())
    host = subprocess.run(["dpkg", "--print-architecture"], capture_output=True, text=True,
                          check=True).stdout.strip()
    tmp = out.with_name(out.name + ".partial")
    apt = _fresh_apt(tmp, _backports_sources())
    _apt(apt, "update", arch=host)
    debs = tmp / "debs"
    debs.mkdir()
    _apt(apt, "download", "qemu-user", cwd=debs, arch=host)
    deb = next(debs.glob("qemu-user_*.deb"))
    root = tmp / "root"
    subprocess.run(["dpkg-deb", "-x", str(deb), str(root)], check=True)
    exe = root / "usr" / "bin" / "qemu-aarch64"
    if not exe.exists():
        raise SystemExit(f"fetch_aarch64_deps: {deb.name} has no usr/bin/qemu-aarch64")
    shutil.copy2(exe, tmp / "qemu-aarch64")
    versions = {"qemu-user": deb.name.split("_")[1].replace("%3a", ":")}
    for d in (apt, debs, root):
        shutil.rmtree(d)
    return _publish(tmp, out, versions)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--qemu", action="store_true", help="fetch qemu-aarch64 from backports instead")
    ns = p.parse_args()
    versions = fetch_qemu(ns.out.resolve()) if ns.qemu else fetch(ns.out.resolve())
    print("aarch64 deps: " + ", ".join(f"{k} {v}" for k, v in versions.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
