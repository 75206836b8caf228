"""Kernel-module dependency order read straight from the .ko files (no depmod, no modinfo needed).

A Debian kernel package unpacked with `dpkg -x` has no modules.dep (depmod runs in postinst), so
the `depends=` entries of each module's .modinfo ELF section are read here and the modules the VM
needs are put in an order busybox `insmod` can load them in (dependencies first).
"""

from __future__ import annotations

import struct
from pathlib import Path


class ModuleError(RuntimeError):
    pass


def _sections(data: bytes) -> dict[str, bytes]:
    """Section name -> contents of a little-endian ELF64 file."""
    if data[:4] != b"\x7fELF" or data[4] != 2 or data[5] != 1:
        raise ModuleError("not a little-endian ELF64 file")
    (e_shoff,) = struct.unpack_from("<Q", data, 0x28)
    e_shentsize, e_shnum, e_shstrndx = struct.unpack_from("<HHH", data, 0x3A)
    headers = []
    for i in range(e_shnum):
        _name, _type, _flags, _addr, off, size = struct.unpack_from("<IIQQQQ", data, e_shoff + i * e_shentsize)
        headers.append((_name, off, size))
    _, str_off, str_size = headers[e_shstrndx]
    strtab = data[str_off:str_off + str_size]
    out = {}
    for name_off, off, size in headers:
        name = strtab[name_off:strtab.index(b"\0", name_off)].decode()
        out[name] = data[off:off + size]
    return out


def modinfo(path: Path) -> dict[str, str]:
    """The key=value pairs of a module's .modinfo section (last value wins for repeated keys)."""
    try:
        raw = _sections(path.read_bytes()).get(".modinfo", b"")
    except (OSError, struct.error, ValueError) as exc:
        raise ModuleError(f"{path}: cannot read .modinfo ({exc})") from exc
    info: dict[str, str] = {}
    for entry in raw.split(b"\0"):
        if b"=" in entry:
            k, _, v = entry.partition(b"=")
            info[k.decode(errors="replace")] = v.decode(errors="replace")
    return info


def module_index(modules_dir: Path) -> dict[str, Path]:
    """Module name (dashes as underscores, like the kernel) -> .ko path under modules_dir."""
    return {p.name[:-3].replace("-", "_"): p for p in modules_dir.rglob("*.ko")}


def builtin_modules(modules_dir: Path) -> set[str]:
    f = modules_dir / "modules.builtin"
    if not f.exists():
        return set()
    return {Path(line.strip()).name.removesuffix(".ko").replace("-", "_")
            for line in f.read_text().splitlines() if line.strip()}


def load_order(modules_dir: Path, wanted: list[str]) -> list[Path]:
    """The .ko files to insmod, dependencies first, for the wanted modules (built-ins skipped)."""
    index = module_index(modules_dir)
    builtin = builtin_modules(modules_dir)
    order: list[Path] = []
    state: dict[str, str] = {}

    def visit(name: str, chain: tuple[str, ...]) -> None:
        name = name.replace("-", "_")
        if state.get(name) == "done" or name in builtin:
            return
        if state.get(name) == "visiting":
            raise ModuleError(f"module dependency cycle: {' -> '.join(chain + (name,))}")
        path = index.get(name)
        if path is None:
            raise ModuleError(f"module {name} (needed by {' -> '.join(chain) or 'the VM'}) is neither "
                              f"in {modules_dir} nor built in")
        state[name] = "visiting"
        for dep in filter(None, modinfo(path).get("depends", "").split(",")):
            visit(dep, chain + (name,))
        state[name] = "done"
        order.append(path)

    for w in wanted:
        visit(w, ())
    return order
