"""The identity of the code that decides a HIL run's result: a hash over the firmware, the
simulator, the synthesis and the run's own tooling (their sources, not their documentation). A kept run (tools/run/runner.py) is reused only
when this is unchanged, so changing the controller or the simulator never leaves stale results in
a resumed study or tuning. A kept tuning stamped with another identity is verified by what it
does on this one (tools/study/verify.py), not taken for stale."""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

from gen.lib.paths import REPO

# What a run's result depends on; reporting, statistics and the CLI are not in it.
SOURCES = ("firmware", "host_sim", "gen", "tools/lcm_logger", "tools/run/hil.py", "tools/run/processes.py",
           "tools/run/run_analysis.py", "tools/run/verdict.py", "tools/run/telemetry_log.py", "tools/build/arm.py",
           "CMakeLists.txt", "CMakePresets.json")
SKIP_PARTS = {"__pycache__", ".pytest_cache"}
# Documentation in those folders changes no result: a README edit must not mark a kept tuning stale.
DOCS = (".md", ".txt", ".pyc")


def _files(root: Path) -> list[Path]:
    if root.is_file():
        return [root]
    return sorted(p for p in root.rglob("*") if p.is_file() and not SKIP_PARTS.intersection(p.parts)
                  and p.suffix not in DOCS and p.name != "LICENSE")


def identity_of(names: tuple[str, ...]) -> str:
    h = hashlib.sha256()
    for name in names:
        for p in _files(REPO / name):
            h.update(str(p.relative_to(REPO)).encode() + b"\0")
            h.update(hashlib.sha256(p.read_bytes()).digest())
    return h.hexdigest()[:16]


@functools.cache
def code_identity() -> str:
    return identity_of(SOURCES)


@functools.cache
def synthesis_identity() -> str:
    """The synthesis's own code (gen/): a design made from a design text by other code is made
    again (tools/run/runner.py sil_design), or a verification could run a design of the old code."""
    return identity_of(("gen",))
