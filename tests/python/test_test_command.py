"""`armctl test`'s two pytest passes (tools/commands/test.py): the tests that may share the cores
side by side, then the `serial` ones alone; each serial mark says why; no test picks its ports at
random (side by side, two tests would meet on one)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

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


# The test files that skip themselves whole when a package they import is missing (a module-level
# importorskip), and the package each needs.
SELF_SKIPPING = {"test_canopen_drive.py": "canopen", "test_canopen_master.py": "canopen",
                 "test_canopen_vendor.py": "canopen", "test_pycan_wire.py": "can", "test_slcan.py": "can"}


def test_strict_fails_a_file_that_skips_itself_at_collection(tmp_path: Path) -> None:
    """python-canopen (and python-can, which it brings) uninstalled, simulated by a shadow on
    PYTHONPATH: the files skip themselves quietly, unless ARM_TEST_STRICT=1 (armctl test as root),
    where the run fails naming each of them."""
    for name in ("canopen", "can", "msgpack"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "__init__.py").write_text(
            f"raise ModuleNotFoundError(\"No module named {name} (uninstalled: a test shadow)\", name={name!r})\n")
    files = [str(TESTS / f) for f in SELF_SKIPPING]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(REPO)])}
    env.pop("ARM_TEST_STRICT", None)
    quiet = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                            "--collect-only", *files], cwd=REPO, env=env, capture_output=True, text=True, timeout=120)
    # 5: nothing collected, and no error: the five skipped themselves unseen
    assert quiet.returncode == 5 and "error" not in quiet.stdout.lower(), quiet.stdout + quiet.stderr
    strict = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--collect-only",
                             *files], cwd=REPO, env={**env, "ARM_TEST_STRICT": "1"}, capture_output=True, text=True,
                            timeout=120)
    assert strict.returncode not in (0, 5), strict.stdout
    for f, package in SELF_SKIPPING.items():
        assert (f"tests/python/{f}: skipped whole under ARM_TEST_STRICT=1" in strict.stdout
                and f"could not import '{package}'" in strict.stdout), (f, strict.stdout[-3000:])
