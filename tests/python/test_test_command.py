"""`armctl test`'s two pytest passes (tools/commands/test.py): the tests that may share the cores
side by side, then the `serial` ones alone; each serial mark says why; no test picks its ports at
random (side by side, two tests would meet on one)."""

from __future__ import annotations

import re
import subprocess

from gen.lib.paths import REPO
from tools.commands.test import pytest_passes

TESTS = REPO / "tests" / "python"


def test_the_passes_split_the_suite_by_the_serial_mark() -> None:
    (first, shared), (second, alone) = pytest_passes(2)
    assert (first, second) == ("side by side", "alone")
    assert shared[:2] == ["-m", "not serial"]
    assert shared[2:] == ["-n", "2", "--dist", "loadfile", "--no-loadscope-reorder"]
    assert alone == ["-m", "serial"]
    assert pytest_passes(1)[0][1] == ["-m", "not serial"]  # one core: no workers, the same split


def test_every_serial_mark_says_why() -> None:
    for path in sorted(TESTS.glob("test_*.py")):
        lines = path.read_text().splitlines()
        for i, line in enumerate(lines):
            if "pytest.mark.serial" in line and "def " not in line:
                said = "#" in line or lines[i - 1].lstrip().startswith("#")
                assert said, f"{path.name}:{i + 1}: a serial mark without its reason (a comment at the mark)"


def test_no_test_picks_its_ports_at_random() -> None:
    picks = re.compile(r"randint\(\s*(4[3-6]\d{3}|7[6-9]\d\d|2[23]\d{3})")
    for path in sorted(TESTS.glob("*.py")):
        for i, line in enumerate(path.read_text().splitlines(), 1):
            assert not picks.search(line), f"{path.name}:{i}: a random port; use conftest's slot or bus_spec"


def test_a_worker_count_below_one_is_refused_before_anything_builds() -> None:
    r = subprocess.run([str(REPO / "tools" / "armctl"), "test", "--workers", "0"], cwd=REPO, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode != 0 and r.stderr.strip().splitlines() == [
        "armctl test: --workers: 0 is not a worker count (1 or more)"], r.stderr
