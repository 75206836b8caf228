"""The code identity (tools/build/code_identity.py) moves with what can change a run's numbers, never
with documentation: a README edit does not mark the kept tuning as made by other code."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tools.build import code_identity as ci


@pytest.fixture()
def tree(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    for name in ("firmware/core/src/x.c", "firmware/README.md", "host_sim/README.md", "host_sim/sim.c", "gen/a.py"):
        p = tmp_path / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(f"// {name}\n")
    monkeypatch.setattr(ci, "REPO", tmp_path)
    monkeypatch.setattr(ci, "SOURCES", ("firmware", "host_sim", "gen"))
    ci.code_identity.cache_clear()
    yield tmp_path
    ci.code_identity.cache_clear()


def _identity() -> str:
    ci.code_identity.cache_clear()
    return ci.code_identity()


def test_documentation_does_not_move_it_and_sources_do(tree: Path) -> None:
    before = _identity()
    (tree / "firmware" / "README.md").write_text("an edited README\n")
    (tree / "host_sim" / "NOTES.md").write_text("new notes\n")
    assert _identity() == before
    (tree / "firmware" / "core" / "src" / "x.c").write_text("// changed\n")
    assert _identity() != before
    shutil.rmtree(tree / "gen")
    assert _identity() != before


def test_the_real_identity_covers_the_firmware_the_simulator_the_synthesis_and_the_run() -> None:
    """The identity of this repository hashes every source of the controller, the simulator and the
    synthesis, and the run's own verdict (the test above holds its rule on a made-up tree)."""
    from gen.lib.paths import REPO

    hashed = {str(p.relative_to(REPO)) for name in ci.SOURCES for p in ci._files(REPO / name)}
    for folder in ("firmware", "host_sim", "gen"):
        sources = {str(p.relative_to(REPO)) for p in (REPO / folder).rglob("*") if p.suffix in (".c", ".h", ".py")
                   and not ci.SKIP_PARTS.intersection(p.parts)}
        assert sources and not sources - hashed, (folder, sorted(sources - hashed)[:5])
    assert {"tools/run/verdict.py", "tools/run/hil.py", "firmware/params/params.toml"} <= hashed
    assert not any(p.endswith(".md") for p in hashed)
