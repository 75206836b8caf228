"""`--record`: a command's results kept for the docs. The file goes to docs/results/NAME.json with
what made it (the command, the code, the machine, the time), and `tools/armctl docs` renders the
docs' figures from it (tools/commands/docs.py): no figure of speed or time in the docs is typed."""

from __future__ import annotations

import os
import platform
from pathlib import Path
from typing import Any

from gen.lib.atomic_output import write_json_atomic
from gen.lib.paths import DOCS_RESULTS


class RecordError(ValueError):
    """A record that would not be the documented figure (a --quick or partial run)."""


def _first(path: str, key: str) -> str | None:
    """The value of the first `key: value` (or `KEY=value`) line of a /proc or /etc file."""
    try:
        for line in Path(path).read_text().splitlines():
            name, sep, value = line.partition(":" if ":" in line else "=")
            if sep and name.strip() == key:
                return value.strip().strip('"')
    except OSError:
        pass
    return None


def machine() -> dict[str, Any]:
    """What the figures depend on: the processor, how many cores this process may use, the memory,
    the system, whether it is a virtual machine, and how busy the machine was when it started."""
    mem_kb = _first("/proc/meminfo", "MemTotal")
    flags = _first("/proc/cpuinfo", "flags") or ""
    return {"cpu": _first("/proc/cpuinfo", "model name") or platform.processor() or platform.machine(),
            "cores": len(os.sched_getaffinity(0)),
            "memory_gib": round(int(mem_kb.split()[0]) / 2**20, 1) if mem_kb else None,
            "os": _first("/etc/os-release", "PRETTY_NAME") or platform.system(),
            "kernel": platform.release(),
            "virtual": "hypervisor" in flags.split(),
            "load_average_1min": round(os.getloadavg()[0], 2)}


def record(name: str, result: dict[str, Any], command: str) -> Path:
    """Write docs/results/NAME.json: the result, and under `recorded` the command that made it
    (as a user types it), the code (run.json's provenance: commit, dirty, date) and the machine."""
    from tools.run.hil import provenance

    prov = provenance()
    out = DOCS_RESULTS / f"{name}.json"
    write_json_atomic(out, {"recorded": {"command": command, "date_utc": prov["date_utc"], "commit": prov["commit"],
                                         "dirty": prov["dirty"], "machine": machine()}, **result})
    print(f"recorded: {out.relative_to(DOCS_RESULTS.parents[1])} (tools/armctl docs renders it into the docs)")
    return out
