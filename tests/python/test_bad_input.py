"""Bad values fail fast and in one line (issue 15): before any process starts or any solve runs,
naming the option, with exit 2 and no traceback."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import pytest

from gen.lib.paths import REPO

ARMCTL = str(REPO / "tools" / "armctl")


@pytest.fixture()
def a_file(tmp_path: Path) -> Path:
    f = tmp_path / "a_file"
    f.write_text("x")
    return f


@pytest.mark.parametrize("args,named", [
    (["hil", "--duration", "1", "--out", "{file}"], "--out"),
    (["study", "--seeds", "1", "--out", "{file}"], "--out"),
    (["tune", "--out", "{file}"], "--out"),
    (["synth", "--out", "{file}"], "--out"),
    (["synth", "--config", "{dir}", "--out", "{dir}/o"], "is a directory"),
    (["synth", "--config", "{binary}", "--out", "{dir}/o"], "not valid TOML"),
    (["hil", "--duration", "0.0001"], "--duration"),
    (["hil", "--duration", "inf"], "--duration"),
    (["hil", "--ref-hold", "-1"], "--ref-hold"),
    (["hil", "--can-port", "80"], "--can-port"),
    (["study", "--seeds", "0"], "--seeds"),
    (["study", "--jobs", "0"], "--jobs"),
    (["study", "--scenarios", "windy"], "--scenarios"),
    (["hil", "--model", "{file}"], "--model"),
])
def test_bad_values_are_one_line_errors(tmp_path: Path, a_file: Path, args: list[str], named: str) -> None:
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"\x00\xff\xfe")
    argv = [a.format(file=a_file, dir=tmp_path, binary=binary) for a in args]
    t0 = time.monotonic()
    r = subprocess.run([ARMCTL, *argv], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert named in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert time.monotonic() - t0 < 60  # nothing waited for a timeout
