"""docs/drives-bring-up.md says what the code does: its table of the master's needs is
gen/drive_check.py's NEEDS, its example `armctl drive check` outputs are what the command prints,
and its list of vendors' files is tests/drives/ with each file's recorded source."""

from __future__ import annotations

import re
import subprocess
import tomllib

from gen.drive_check import NEEDS
from gen.lib.paths import REPO

DOC = REPO / "docs" / "drives-bring-up.md"
DRIVES = REPO / "tests" / "drives"


def _table_after(text: str, heading: str) -> list[list[str]]:
    section = text[text.index(heading):]
    rows = []
    for line in section.splitlines()[1:]:
        if line.startswith("## "):
            break
        if line.startswith("| ") and not line.startswith("|---"):
            rows.append([c.strip() for c in line.strip("|").split(" | ")])
    return rows[1:]  # the header row off


def test_the_needs_table_is_the_master_s() -> None:
    rows = _table_after(DOC.read_text(), "## What the master needs from a drive")
    assert rows == [[n.objects, n.need, n.what] for n in NEEDS]


def test_the_example_outputs_are_what_drive_check_prints() -> None:
    blocks = re.findall(r"```\n\$ (tools/armctl drive check [^\n]+)\n(.*?)```", DOC.read_text(), re.S)
    assert len(blocks) == 3
    for command, shown in blocks:
        p = subprocess.run(command.split(), cwd=REPO, capture_output=True, text=True, timeout=120)
        assert p.returncode in (0, 2) and p.stdout == shown, (command, p.stdout)


def test_the_vendor_files_listed_are_those_in_tests_drives_with_their_sources() -> None:
    rows = _table_after(DOC.read_text(), "## Vendors' files in this repository")
    files = sorted(p.name for p in DRIVES.iterdir() if p.suffix in (".eds", ".dcf"))
    assert sorted(r[0].strip("`") for r in rows) == files
    for name, _drive, cst, source, licence in rows:
        name = name.strip("`")
        src = tomllib.loads((DRIVES / f"{name}.source.toml").read_text())
        assert source == f"{src['repository']}, `{src['path']}`, {src['commit']}", name
        assert src["licence"].startswith(licence) and (DRIVES / src["licence_file"]).is_file(), name
        assert cst == ("yes" if src["cst"] else "no"), name
