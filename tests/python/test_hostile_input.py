"""Hostile and unlucky input (issue 24, items 8-13): a full or read-only disk under --out, hostile
arm models and TOML nested without end. Each gives one line naming the path or element, a
non-zero exit (2 for bad input), no traceback, and nothing half-written: no temporary file, no
build folder."""

from __future__ import annotations

import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

from gen.atomic_output import OutputError, write_files_atomically, write_json_atomic
from tools.paths import REPO

ARMCTL = str(REPO / "tools" / "armctl")


def armctl(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run([ARMCTL, *args], cwd=REPO, capture_output=True, text=True, timeout=timeout)


def one_line_error(r: subprocess.CompletedProcess[str], code: int, *named: str) -> str:
    assert r.returncode == code, (r.returncode, r.stdout, r.stderr)
    assert "Traceback" not in r.stderr, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip() and not ln.startswith("armctl: ")]
    assert len(lines) == 1, r.stderr
    for n in named:
        assert n in lines[0], lines[0]
    return lines[0]


def leftovers(d: Path) -> list[str]:
    return sorted(str(p.relative_to(d)) for p in d.rglob("*") if ".tmp" in p.name or p.name.startswith(".tmp-"))


# ---- a full disk, a read-only disk ----------------------------------------------------------
def _mount_tmpfs(where: Path, size: str) -> None:
    where.mkdir(parents=True, exist_ok=True)
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here (needs root): {r.stderr.strip()}")


@pytest.fixture()
def full_disk(tmp_path: Path) -> Iterator[Path]:
    """A 2 MB tmpfs with no byte left: the next write of any size fails with ENOSPC."""
    d = tmp_path / "full"
    _mount_tmpfs(d, "2m")
    try:
        with open(d / "filler", "wb") as fh:
            try:
                while True:
                    fh.write(b"\0" * 65536)
                    fh.flush()
            except OSError:
                pass
        yield d
    finally:
        subprocess.run(["umount", "-l", str(d)], check=False)


@pytest.fixture()
def read_only_disk(tmp_path: Path) -> Iterator[Path]:
    """A tmpfs remounted read-only: every write fails with EROFS (as root, too)."""
    d = tmp_path / "ro"
    _mount_tmpfs(d, "2m")
    try:
        (d / "old.json").write_text("{}\n")
        r = subprocess.run(["mount", "-o", "remount,ro", str(d)], capture_output=True, text=True)
        if r.returncode != 0:
            pytest.skip(f"cannot remount the tmpfs read-only: {r.stderr.strip()}")
        yield d
    finally:
        subprocess.run(["umount", "-l", str(d)], check=False)


def test_the_writer_on_a_full_disk_names_the_path_and_leaves_no_temporary_file(full_disk: Path) -> None:
    with pytest.raises(OutputError) as e:
        write_json_atomic(full_disk / "run.json", {"x": "y" * 100_000})
    assert str(e.value) == f"cannot write {full_disk / 'run.json'}: No space left on device"
    with pytest.raises(OutputError) as e:
        write_files_atomically(full_disk / "gen", {"a.h": "int x;\n" * 10_000, "manifest.json": "{}\n"})
    assert str(e.value) == f"cannot write {full_disk / 'gen' / 'a.h'}: No space left on device"
    assert sorted(p.name for p in full_disk.iterdir()) == ["filler"]  # no temp file, no half-made folder


def test_the_writer_on_a_read_only_disk_keeps_the_old_file(read_only_disk: Path) -> None:
    with pytest.raises(OutputError) as e:
        write_json_atomic(read_only_disk / "old.json", {"new": True})
    assert str(e.value) == f"cannot write {read_only_disk / 'old.json'}: Read-only file system"
    assert (read_only_disk / "old.json").read_text() == "{}\n"
    with pytest.raises(OutputError, match="Read-only file system"):
        write_files_atomically(read_only_disk / "gen", {"a.h": "x"})
    assert sorted(p.name for p in read_only_disk.iterdir()) == ["old.json"]


def test_hil_on_a_full_disk_is_one_line_and_leaves_no_temporary_file(full_disk: Path) -> None:
    r = armctl("hil", "--duration", "0.3", "--out", str(full_disk))
    one_line_error(r, 1, f"cannot write {full_disk / 'run.json'}", "No space left on device")
    assert leftovers(full_disk) == []
    assert not (full_disk / "run.json").exists()


def test_synth_on_a_full_disk_is_one_line_and_leaves_no_temporary_file(full_disk: Path) -> None:
    out = full_disk / "design"
    r = armctl("synth", "--out", str(out))
    one_line_error(r, 1, f"cannot write {out}", "No space left on device")
    assert sorted(p.name for p in full_disk.iterdir()) == ["filler"]


def test_a_read_only_out_is_refused_before_any_work(read_only_disk: Path) -> None:
    for cmd in (["synth"], ["hil", "--duration", "0.3"]):
        r = armctl(*cmd, "--out", str(read_only_disk / "o"))
        one_line_error(r, 2, "--out", "Read-only file system")
    assert sorted(p.name for p in read_only_disk.iterdir()) == ["old.json"]


# ---- TOML nested without end ----------------------------------------------------------------
def test_toml_nesting_is_bounded_at_the_stated_limit() -> None:
    from gen.toml_input import MAX_NESTING, TomlNestingError, loads

    assert loads("x = " + "[" * MAX_NESTING + "]" * MAX_NESTING)["x"] is not None
    for text in ("x = " + "[" * (MAX_NESTING + 1) + "]" * (MAX_NESTING + 1),  # parses, but too deep
                 "x = " + "[" * 3000 + "]" * 3000,  # RecursionError inside tomllib
                 "a" + ".a" * (MAX_NESTING + 1) + " = 1",  # dotted keys: tables without recursion
                 "x = " + "{a = " * 3000 + "1" + "}" * 3000):
        with pytest.raises(TomlNestingError, match=f"nested deeper than {MAX_NESTING} levels"):
            loads(text)


DEEP = "x = " + "[" * 3000 + "]" * 3000 + "\n"


@pytest.mark.parametrize("args", [
    ["hil", "--arm", "{f}"], ["hil", "--design", "{f}"], ["hil", "--topology", "{f}"],
    ["study", "--config", "{f}"], ["synth", "--config", "{f}", "--out", "{d}/o"],
    ["busload", "--topology", "{f}"],
])
def test_a_3000_deep_toml_is_one_line_naming_the_file(tmp_path: Path, args: list[str]) -> None:
    f = tmp_path / "deep.toml"
    f.write_text(('model = "arm.xml"\n' if "--arm" in args else "") + DEEP)
    r = armctl(*[a.format(f=f, d=tmp_path) for a in args])
    one_line_error(r, 2, str(f), "nested deeper than 32 levels")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["deep.toml"]
