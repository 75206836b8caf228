"""The user guide (docs/, mkdocs.yml) builds strictly, and its figures are generated: MkDocs's strict
build fails on a broken link or anchor and on a page missing from the navigation; every figure of
speed or time in README.md and docs/ is rendered by `tools/armctl docs` from a results file a
command wrote (tools/commands/docs.py), and rendering them again from the committed files changes
nothing."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from gen.lib.paths import DOCS, REPO
from tools.commands import docs as docs_cmd


def mkdocs_build(root: Path, site: Path) -> subprocess.CompletedProcess[str]:
    # not -q: a quiet build does not count its warnings, so --strict would let them pass
    return subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(root / "mkdocs.yml"),
                           "-d", str(site)], cwd=root, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})


def test_the_guide_builds_strictly(tmp_path: Path) -> None:
    r = mkdocs_build(REPO, tmp_path / "site")
    assert r.returncode == 0, r.stdout + r.stderr
    assert (tmp_path / "site" / "reference" / "commands" / "index.html").is_file()


@pytest.fixture
def guide_copy(tmp_path: Path) -> Path:
    """mkdocs.yml and docs/ copied, to break."""
    shutil.copy(REPO / "mkdocs.yml", tmp_path / "mkdocs.yml")
    shutil.copytree(DOCS, tmp_path / "docs", ignore=shutil.ignore_patterns("results"))
    return tmp_path


@pytest.mark.parametrize("breakage", ["link", "anchor", "not in the nav"])
def test_the_strict_build_fails_on_a_broken_link_anchor_or_page(guide_copy: Path, breakage: str) -> None:
    quick = guide_copy / "docs" / "quickstart.md"
    if breakage == "link":
        quick.write_text(quick.read_text() + "\n[gone](no-such-page.md)\n")
    elif breakage == "anchor":
        quick.write_text(quick.read_text() + "\n[gone](study.md#no-such-heading)\n")
    else:
        (guide_copy / "docs" / "stray.md").write_text("# A page nobody links\n")
    r = mkdocs_build(guide_copy, guide_copy / "site")
    assert r.returncode != 0, f"{breakage}: the strict build passed\n{r.stdout}{r.stderr}"
    assert {"link": "no-such-page.md", "anchor": "no-such-heading", "not in the nav": "stray.md"}[breakage] in r.stderr


def test_armctl_docs_check_finds_every_figure_rendered_from_its_results_file() -> None:
    """docs --check renders every region of every page (counted here from the pages themselves)
    and finds each as its results file renders it."""
    r = subprocess.run([str(REPO / "tools" / "armctl"), "docs", "--check"], cwd=REPO, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    found = {str(p.relative_to(REPO)): len(docs_cmd.REGION.findall(p.read_text())) for p in docs_cmd.pages()}
    found = {p: n for p, n in found.items() if n}
    assert sum(found.values()) >= len(docs_cmd.RENDERERS)
    assert (f"armctl docs: {sum(found.values())} region(s) on {len(found)} page(s) rendered from their results "
            f"files, each as it stands: {', '.join(sorted(found))}") in r.stdout, r.stdout


def test_every_region_renders_and_a_typed_figure_is_caught() -> None:
    regions = {m.group("name") for p in docs_cmd.pages() for m in docs_cmd.REGION.finditer(p.read_text())}
    assert regions == set(docs_cmd.RENDERERS), f"regions without a renderer, or renderers no page uses: {regions}"
    page = DOCS / "reference" / "benchmarks.md"
    text = page.read_text()
    m = docs_cmd.REGION.search(text)
    figure = re.search(r"\d+\.\d+", m.group("body"))
    assert figure, m.group("body")
    typed = text[:m.start("body") + figure.start()] + "9" + text[m.start("body") + figure.start():]
    assert docs_cmd.rendered(typed, page.name) == text  # the typed digit is rendered away


# Phrases that state how fast or how long something went. Such a figure belongs in a numbers region
# (rendered from its results file); outside one it was typed by hand.
TIMING_PHRASES = re.compile(r"\b(?:takes?|took|taking|costs?)\s+(?:about\s+|only\s+)?[\d.,]+\s*(?:s|ms|µs|us|min|"
                            r"seconds?|minutes?)\b|\d(?:\.\d+)?x real time|"
                            r"\b\d+ min \d+ s\b|runs/min|\d[\d,]* instructions\b|\bmeasured here\b", re.I)


def test_no_timing_figure_is_typed_outside_a_rendered_region() -> None:
    found = []
    for page in docs_cmd.pages():
        text = docs_cmd.REGION.sub("", page.read_text())
        for m in TIMING_PHRASES.finditer(text):
            line = text.count("\n", 0, m.start()) + 1
            found.append(f"{page.relative_to(REPO)}:{line}: {text[max(0, m.start() - 40):m.end() + 20]!r}")
    assert found == []
    assert TIMING_PHRASES.search("a study took 34 s here") and TIMING_PHRASES.search("156.6x real time")


@pytest.mark.parametrize(("seconds", "text"), [(839.7, "14 min 0 s"), (706.5, "11 min 46 s"), (59.6, "1 min 0 s"),
                                               (42.2, "42 s")])
def test_a_duration_reads_in_whole_minutes_and_seconds(seconds: float, text: str) -> None:
    assert docs_cmd._minutes(seconds) == text
