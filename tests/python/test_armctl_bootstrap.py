"""tools/armctl's bootstrap: which Debian packages it would install."""

from __future__ import annotations

import shlex
import shutil
import subprocess
from pathlib import Path

import pytest

from gen.lib.paths import REPO


def apt_missing(apt_list: Path) -> list[str]:
    """Runs armctl's own apt_missing function (extracted from the script) on a package list."""
    script = (REPO / "tools" / "armctl").read_text()
    start = script.index("apt_missing() {")
    body = script[start:script.index("\n}\n", start) + 3]
    r = subprocess.run(["bash", "-c", f"set -euo pipefail\n{body}\napt_missing {shlex.quote(str(apt_list))}"],
                       capture_output=True, text=True, timeout=60, check=True)
    return r.stdout.split()


@pytest.mark.skipif(shutil.which("dpkg-query") is None, reason="not a Debian system")
def test_apt_missing_names_exactly_the_packages_not_installed(tmp_path: Path) -> None:
    listed = tmp_path / "apt.txt"
    listed.write_text("# a comment\ncmake\n\nno-such-package-armctl-test\ngcc\n")
    assert apt_missing(listed) == ["no-such-package-armctl-test"]
    assert apt_missing(REPO / "tools" / "apt-packages.txt") == []  # armctl installed them for this run
