"""Builds (once) and caches what the qemu VM boots: Debian's kernel and a busybox initramfs.

Cache: REPO/.cache/vm (gitignored):
    kernel/<version>/          the linux-image package, unpacked with dpkg -x (boot/, lib/modules/)
    initrd-<version>-<hash>.gz busybox + the modules below + /init; <hash> covers everything in it
    image.json                 what the last set-up produced (read by status and run)
    runs/                      one folder per `vcan run` (script, stdout, stderr, rc), removed after
Only the Debian archive is contacted (apt-get download), and only when no kernel is cached.
"""

from __future__ import annotations

import fcntl
import gzip
import hashlib
import io
import json
import os
import shutil
import subprocess
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path

from gen.lib.atomic_output import write_bytes_atomic
from gen.lib.paths import REPO
from tools.vm.kmod import ModuleError, load_order

CACHE = REPO / ".cache" / "vm"
BUSYBOX = Path("/bin/busybox")
QEMU = "qemu-system-x86_64"
META_PACKAGE = "linux-image-amd64"
APT_HINT = "apt-get install qemu-system-x86 busybox-static (tools/armctl installs them when run as root)"

# vcan0 itself is created by the run script inside the chroot, with the host's iproute2 (busybox ip
# cannot set txqueuelen).
# Loaded in the initramfs, dependencies first (resolved from the .ko files): virtio PCI + 9p for
# the host root, then SocketCAN (can, can-raw) and the virtual CAN driver (vcan needs can-dev).
MODULES = ["virtio_pci", "9pnet_virtio", "9p", "can", "can_raw", "can_dev", "vcan"]

INIT = r"""#!/bin/busybox sh
# armctl VM init: mount the host root over 9p, load CAN, run the script named on the command line.
/bin/busybox --install -s /bin
export PATH=/bin
mount -t proc proc /proc
mount -t sysfs sys /sys
mount -t devtmpfs dev /dev
say() { echo "armvm: $*" > /dev/console; }
while read -r m; do
    insmod "/lib/modules/$m" || say "insmod $m failed"
done < /modules.list
ip link set lo up
run=""
for arg in $(cat /proc/cmdline); do
    case "$arg" in armvm.run=*) run="${arg#armvm.run=}" ;; esac
done
if mount -t 9p -o trans=virtio,version=9p2000.L,msize=512000@CACHE_OPT@ host /mnt; then
    mount -t proc proc /mnt/proc
    mount -t sysfs sys /mnt/sys
    mount -t devtmpfs dev /mnt/dev
    mkdir -p /mnt/dev/shm /mnt/dev/pts
    mount -t tmpfs -o mode=1777 shm /mnt/dev/shm
    mount -t devpts devpts /mnt/dev/pts
    # What udev and systemd add on a normal system: bash's process substitution needs /dev/fd,
    # many scripts write to /dev/stdout or /dev/stderr.
    ln -sfn /proc/self/fd /mnt/dev/fd
    ln -sfn /proc/self/fd/0 /mnt/dev/stdin
    ln -sfn /proc/self/fd/1 /mnt/dev/stdout
    ln -sfn /proc/self/fd/2 /mnt/dev/stderr
    if [ -n "$run" ] && [ -f "/mnt$run/run.sh" ]; then
        chroot /mnt /bin/sh "$run/run.sh"
    else
        say "no run script at '$run/run.sh'"
    fi
    sync
else
    say "mounting the host root over 9p failed"
fi
poweroff -f
"""
NINEP_CACHE_OPT = ",cache=loose"  # default cache=none: what the host writes is seen at once, and vice versa


class VmError(RuntimeError):
    """The VM cannot be set up or run here; the message says why and what to do."""


@dataclass
class Image:
    kernel_version: str
    vmlinuz: str
    initrd: str
    modules: list[str]
    built_s: float = 0.0

    @property
    def ready(self) -> bool:
        return Path(self.vmlinuz).is_file() and Path(self.initrd).is_file()


@contextmanager
def cache_lock() -> Iterator[None]:
    """One set-up at a time (a second `vcan run` waits instead of unpacking the kernel twice)."""
    CACHE.mkdir(parents=True, exist_ok=True)
    with open(CACHE / ".lock", "w") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def missing_tools() -> list[str]:
    out = []
    if shutil.which(QEMU) is None:
        out.append(f"{QEMU} (Debian package qemu-system-x86)")
    if not _is_static_elf(BUSYBOX):
        out.append(f"a static {BUSYBOX} (Debian package busybox-static)")
    return out


def _is_static_elf(path: Path) -> bool:
    """True for an ELF executable without a PT_INTERP program header (no dynamic loader)."""
    try:
        data = path.read_bytes()
    except OSError:
        return False
    if data[:4] != b"\x7fELF" or data[4] != 2:
        return False
    import struct

    (phoff,) = struct.unpack_from("<Q", data, 0x20)
    phentsize, phnum = struct.unpack_from("<HH", data, 0x36)
    return all(struct.unpack_from("<I", data, phoff + i * phentsize)[0] != 3 for i in range(phnum))


def cached_kernels() -> list[Path]:
    d = CACHE / "kernel"
    if not d.is_dir():
        return []
    return sorted(p for p in d.iterdir() if (p / "boot").is_dir() and _vmlinuz(p) is not None)


def _vmlinuz(kdir: Path) -> Path | None:
    found = sorted((kdir / "boot").glob("vmlinuz-*"))
    return found[-1] if found else None


def kernel_package_name() -> str:
    """The versioned image package the meta package depends on, e.g. linux-image-6.1.0-56-amd64."""
    r = subprocess.run(["apt-cache", "depends", META_PACKAGE], capture_output=True, text=True)
    for line in r.stdout.splitlines():
        line = line.strip()
        if line.startswith("Depends:") and "linux-image-" in line:
            return line.split(":", 1)[1].strip().strip("<>")
    raise VmError(f"apt-cache depends {META_PACKAGE} names no kernel image package "
                  f"(run apt-get update first?): {r.stderr.strip() or r.stdout.strip()}")


def fetch_kernel(log=print) -> Path:  # noqa: ANN001 - a print-like callable
    """apt-get download + dpkg -x of the kernel the meta package names; returns the unpacked dir."""
    pkg = kernel_package_name()
    version = pkg.removeprefix("linux-image-")
    dest = CACHE / "kernel" / version
    if _vmlinuz(dest) is not None:
        return dest
    with tempfile.TemporaryDirectory(dir=CACHE) as tmp:
        os.chmod(tmp, 0o755)
        log(f"armctl vcan: downloading {pkg} from the Debian archive (apt-get download, ~70 MB)")
        r = subprocess.run(["apt-get", "download", pkg], cwd=tmp, capture_output=True, text=True)
        debs = list(Path(tmp).glob("*.deb"))
        if r.returncode != 0 or not debs:
            raise VmError(f"apt-get download {pkg} failed: {r.stderr.strip()[-500:]}")
        staging = Path(tmp) / "x"
        log(f"armctl vcan: unpacking {debs[0].name}")
        r = subprocess.run(["dpkg", "-x", str(debs[0]), str(staging)], capture_output=True, text=True)
        if r.returncode != 0:
            raise VmError(f"dpkg -x {debs[0].name} failed: {r.stderr.strip()[-500:]}")
        _trim(staging)
        dest.parent.mkdir(parents=True, exist_ok=True)
        os.replace(staging, dest)
    return dest


# Module folders kept after unpacking (the package is ~400 MB unpacked; these are ~3 MB).
KEEP_MODULE_DIRS = ("kernel/drivers/virtio", "kernel/net/9p", "kernel/fs/9p", "kernel/fs/netfs",
                    "kernel/fs/fscache", "kernel/net/can", "kernel/drivers/net/can")


def _trim(kdir: Path) -> None:
    """Drop everything the VM never loads: keep boot/vmlinuz-*, modules.builtin and KEEP_MODULE_DIRS."""
    for p in list(kdir.iterdir()) + list((kdir / "lib").iterdir()):
        if p.name not in ("boot", "lib", "modules"):
            _remove(p)
    for p in (kdir / "boot").iterdir():
        if not p.name.startswith("vmlinuz-"):
            _remove(p)
    for mod_root in (kdir / "lib" / "modules").iterdir():
        keep = [mod_root / k for k in KEEP_MODULE_DIRS]

        def wanted(p: Path) -> bool:
            if p.parent == mod_root and p.name.startswith("modules.builtin"):
                return True
            return any(k == p or k in p.parents for k in keep)

        for p in list(mod_root.rglob("*")):
            if (p.is_symlink() or p.is_file()) and not wanted(p):
                p.unlink()
        dirs = sorted((q for q in mod_root.rglob("*") if q.is_dir()), key=lambda q: len(q.parts), reverse=True)
        for p in dirs:
            if not any(p.iterdir()):
                p.rmdir()


def _remove(p: Path) -> None:
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p)
    else:
        p.unlink()


def _cpio_newc(entries: list[tuple[str, int, bytes, tuple[int, int]]]) -> bytes:
    """A cpio 'newc' archive; entries are (name, mode, data, (rdev_major, rdev_minor))."""
    buf = io.BytesIO()

    def pad4() -> None:
        buf.write(b"\0" * (-buf.tell() % 4))

    for ino, (name, mode, data, (rmaj, rmin)) in enumerate([*entries, ("TRAILER!!!", 0, b"", (0, 0))], 1):
        fields = [ino, mode, 0, 0, 1, 0, len(data), 0, 0, rmaj, rmin, len(name) + 1, 0]
        buf.write(b"070701" + b"".join(b"%08X" % f for f in fields))
        buf.write(name.encode() + b"\0")
        pad4()
        buf.write(data)
        pad4()
    return buf.getvalue()


def build_initrd(kdir: Path) -> tuple[Path, list[str]]:
    version = kdir.name
    mod_root = kdir / "lib" / "modules" / version
    if not mod_root.is_dir():
        cands = list((kdir / "lib" / "modules").iterdir())
        if len(cands) != 1:
            raise VmError(f"{kdir}: cannot find the module tree under lib/modules")
        mod_root = cands[0]
    try:
        kos = load_order(mod_root, MODULES)
    except ModuleError as exc:
        raise VmError(str(exc)) from exc
    busybox = BUSYBOX.read_bytes()
    init = INIT.replace("@CACHE_OPT@", NINEP_CACHE_OPT).encode()
    names = [k.name for k in kos]
    h = hashlib.sha256(init + busybox + "\n".join(names).encode())
    for k in kos:
        h.update(k.read_bytes())
    out = CACHE / f"initrd-{version}-{h.hexdigest()[:12]}.gz"
    if out.exists():
        return out, names
    d, f, c = 0o040755, 0o100755, 0o020600
    entries: list[tuple[str, int, bytes, tuple[int, int]]] = [
        ("bin", d, b"", (0, 0)), ("dev", d, b"", (0, 0)), ("dev/console", c, b"", (5, 1)),
        ("proc", d, b"", (0, 0)), ("sys", d, b"", (0, 0)), ("mnt", d, b"", (0, 0)), ("tmp", d, b"", (0, 0)),
        ("lib", d, b"", (0, 0)), ("lib/modules", d, b"", (0, 0)),
        ("bin/busybox", f, busybox, (0, 0)), ("init", f, init, (0, 0)),
        ("modules.list", 0o100644, "".join(n + "\n" for n in names).encode(), (0, 0)),
    ]
    entries += [(f"lib/modules/{k.name}", 0o100644, k.read_bytes(), (0, 0)) for k in kos]
    write_bytes_atomic(out, gzip.compress(_cpio_newc(entries), compresslevel=6))
    for old in CACHE.glob(f"initrd-{version}-*.gz"):
        if old != out:
            old.unlink(missing_ok=True)
    return out, names


def load_image() -> Image | None:
    try:
        img = Image(**json.loads((CACHE / "image.json").read_text()))
    except (OSError, ValueError, TypeError):
        return None
    return img if img.ready else None


def ensure_image(refresh: bool = False, log=print) -> Image:  # noqa: ANN001
    """The cached VM image, built on first use (download + unpack + initramfs). The initramfs is
    rebuilt whenever its content (init script, busybox, modules) changes."""
    from tools.build.packages import ensure

    ensure("vm")
    missing = missing_tools()
    if missing:
        raise VmError(f"missing {', '.join(missing)}: {APT_HINT}")
    with cache_lock():
        t0 = time.monotonic()
        kernels = cached_kernels()
        kdir = fetch_kernel(log) if (refresh or not kernels) else kernels[-1]
        vmlinuz = _vmlinuz(kdir)
        if vmlinuz is None:
            raise VmError(f"{kdir}: no boot/vmlinuz-* in the kernel package")
        initrd, names = build_initrd(kdir)
        old = load_image()
        if old is not None and old.vmlinuz == str(vmlinuz) and old.initrd == str(initrd):
            return old  # nothing changed (the usual, warm case: ~50 ms of hashing)
        img = Image(kernel_version=kdir.name, vmlinuz=str(vmlinuz), initrd=str(initrd), modules=names,
                    built_s=round(time.monotonic() - t0, 1))
        (CACHE / "image.json").write_text(json.dumps(asdict(img), indent=2))
        return img
