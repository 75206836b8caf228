"""Every libFuzzer harness runs briefly on its corpus under ASan/UBSan, after replaying every input
that ever crashed it (tools/bench/fuzz.py; `tools/armctl fuzz --seconds N` for as long as asked)."""

from __future__ import annotations

import re
import shutil
import subprocess

import pytest

from tools.bench.fuzz import HARNESSES
from gen.lib.paths import REPO


def test_every_harness_runs_clean() -> None:
    if shutil.which("clang") is None:
        pytest.skip("clang not found: apt-get install clang libclang-rt-14-dev (tools/armctl does as root)")
    # a second each (libFuzzer's least): tens of thousands of inputs a harness, after its regression
    # seeds and its whole corpus; `armctl fuzz --seconds N` fuzzes for as long as asked
    r = subprocess.run([str(REPO / "tools" / "armctl"), "fuzz", "--seconds", str(len(HARNESSES))], cwd=REPO,
                       capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stdout + r.stderr
    for name in HARNESSES:
        line = next((ln for ln in r.stdout.splitlines() if ln.startswith(f"fuzz_{name} ")), "")
        m = re.search(r": (\d+) runs, .*no finding$", line)
        assert m and int(m.group(1)) > 0, f"fuzz_{name}: {line or 'no line'}"  # it fuzzed, and found nothing
    assert "1 regression seed(s)" in r.stdout  # the datagram that once killed the Python simulator
