"""The C tests' harness (tests/c/check.h): a binary passes only when it ran a check and none failed;
one that ran no check (its checks skipped, or never reached) fails, saying so, as one with a failed
check does. Each case is a tiny program compiled here against the harness itself."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from gen.lib.paths import REPO

CASES = {
    "no check": ("", 1, "0 passed, 0 failed", "no check ran"),
    "a passing check": ("CHECK(1 + 1 == 2);", 0, "1 passed, 0 failed", ""),
    "a failed check": ("CHECK(1 + 1 == 2); CHECK_MSG(2 + 2 == 5, \"four is %d\", 2 + 2);", 1, "1 passed, 1 failed",
                       "CHECK failed: 2 + 2 == 5: four is 4"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_the_c_harness_passes_only_a_binary_whose_checks_ran_and_held(tmp_path: Path, case: str) -> None:
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        pytest.skip("no C compiler (tools/apt-packages.txt installs gcc)")
    body, rc, out, err = CASES[case]
    src = tmp_path / "t.c"
    src.write_text(f'#include "check.h"\nint main(void)\n{{\n    {body}\n    TEST_MAIN_END();\n}}\n')
    exe = tmp_path / "t"
    built = subprocess.run([cc, "-std=c11", "-Wall", "-Wextra", "-Werror", f"-I{REPO / 'tests' / 'c'}", str(src),
                            "-o", str(exe)], capture_output=True, text=True)
    assert built.returncode == 0, built.stderr
    r = subprocess.run([str(exe)], capture_output=True, text=True, timeout=30)
    assert (r.returncode, r.stdout.strip()) == (rc, out), (r.returncode, r.stdout, r.stderr)
    assert err in r.stderr, r.stderr
