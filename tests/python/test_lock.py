"""Dependencies by hash (issue 51): requirements.lock pins every package with the sha256 of each of
its artifacts, tools/armctl's bootstrap installs it with --require-hashes (an artifact whose hash is
not the lock's is refused: tried here on a real wheel), and the lock is what the one documented
command, `tools/armctl lock`, makes from requirements.txt."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

from gen.lib.paths import REPO

LOCK = REPO / "requirements.lock"


def _entries(text: str) -> dict[str, tuple[str, list[str]]]:
    """name -> (version, hashes) of a pip-compile'd lock (its continuation lines joined)."""
    joined = re.sub(r"\\\n\s*", " ", text)
    out = {}
    for line in joined.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        m = re.fullmatch(r"([A-Za-z0-9_.-]+)==(\S+)((?:\s+--hash=sha256:[0-9a-f]{64})*)", line)
        assert m, f"requirements.lock: not `NAME==VERSION --hash=sha256:...`: {line[:100]}"
        out[m.group(1).lower().replace("_", "-")] = (m.group(2), re.findall(r"sha256:([0-9a-f]{64})", m.group(3)))
    return out


def test_every_locked_package_names_its_artifacts_by_hash() -> None:
    entries = _entries(LOCK.read_text())
    assert len(entries) > 100
    assert all(hashes for _, hashes in entries.values()), [n for n, (_, h) in entries.items() if not h]
    for line in (REPO / "requirements.txt").read_text().splitlines():  # every direct requirement, at its pin
        m = re.match(r"([A-Za-z0-9_.-]+)==(\S+)", line)
        if m:
            assert entries[m.group(1).lower().replace("_", "-")][0] == m.group(2), line
    assert "--find-links" not in LOCK.read_text() and "--index-url" not in LOCK.read_text()


def _bootstrap(repo: Path) -> subprocess.CompletedProcess[str]:
    """tools/armctl's own ensure_venv (extracted from the script) for a repository at `repo`."""
    script = (REPO / "tools" / "armctl").read_text()
    funcs = ""
    for name in ("say", "find_python", "ensure_venv"):
        start = script.index(f"{name}() {{")
        funcs += script[start:script.index("\n}\n", start) + 3] if name != "say" else \
            script[start:script.index("\n", start) + 1]
    body = f'set -euo pipefail\nREPO={repo}\nVENV="$REPO/.venv"\nSTAMP="$VENV/.requirements.sha256"\n{funcs}\nensure_venv\n'
    return subprocess.run(["bash", "-c", body], capture_output=True, text=True, timeout=600)


def test_the_bootstrap_refuses_an_artifact_whose_hash_is_not_the_locks(tmp_path: Path) -> None:
    """A lock of one small package of ours (argparse-addons, cantools' dependency): its real
    hashes install; a replaced artifact's (a hash that is not the lock's) is refused, and so is the
    package without a hash; nothing installed then."""
    name, (version, hashes) = "argparse-addons", _entries(LOCK.read_text())["argparse-addons"]
    good, bad, bare = tmp_path / "good", tmp_path / "bad", tmp_path / "bare"
    for repo, digests in ((good, hashes), (bad, ["0" * 64]), (bare, [])):
        repo.mkdir()
        (repo / "requirements.lock").write_text(
            f"{name}=={version} " + " ".join(f"--hash=sha256:{h}" for h in digests) + "\n")
    r = _bootstrap(good)
    if r.returncode != 0 and ("Could not find" in r.stderr or "connection" in r.stderr.lower()):
        pytest.skip(f"no package index reachable: {r.stderr.strip().splitlines()[-1]}")
    assert r.returncode == 0, r.stderr[-3000:]
    assert list((good / ".venv").glob("lib/python3*/site-packages/argparse_addons*"))
    r = _bootstrap(bad)
    assert r.returncode != 0 and "DO NOT MATCH THE HASHES" in r.stderr, r.stderr[-3000:]
    assert not list((bad / ".venv").glob("lib/python3*/site-packages/argparse_addons*"))
    assert not (bad / ".venv" / ".requirements.sha256").exists()
    r = _bootstrap(bare)  # a lock entry without its hash is refused too, not installed unchecked
    assert r.returncode != 0 and "Hashes are required" in r.stderr, r.stderr[-3000:]
    assert not list((bare / ".venv").glob("lib/python3*/site-packages/argparse_addons*"))


@pytest.mark.long  # a minute: pip-compile asks the package index for every pin
def test_the_lock_is_what_armctl_lock_makes_from_the_requirements() -> None:
    r = subprocess.run([str(REPO / "tools" / "armctl"), "lock", "--check"], cwd=REPO, capture_output=True, text=True,
                       timeout=900)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-3000:]
    assert "every artifact hashed" in r.stdout
