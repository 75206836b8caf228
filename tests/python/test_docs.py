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
from typing import Any

import pytest

from gen.lib.paths import DOCS, REPO
from tools.commands import docs as docs_cmd


def mkdocs_build(root: Path, site: Path) -> subprocess.CompletedProcess[str]:
    # not -q: a quiet build does not count its warnings, so --strict would let them pass.
    # PYTHONPATH: a copied guide's hooks import tools.build from the repository.
    return subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(root / "mkdocs.yml"),
                           "-d", str(site)], cwd=root, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "NO_MKDOCS_2_WARNING": "1", "PYTHONPATH": str(REPO)})


def test_the_guide_builds_strictly_and_the_site_fetches_nothing(tmp_path: Path) -> None:
    """The strict build passes; its diagram is drawn into the site; no page loads a script, style,
    font or image from elsewhere (links a reader follows are not loads)."""
    site = tmp_path / "site"
    r = mkdocs_build(REPO, site)
    assert r.returncode == 0, r.stdout + r.stderr
    assert (site / "reference" / "commands" / "index.html").is_file()
    assert (site / "diagrams" / "data-flow.svg").read_text().lstrip().startswith(("<?xml", "<svg", "<!--"))
    fetched = {m for page in site.rglob("*.html") for m in re.findall(
        r"""<(?:script|link|img|iframe|source)\b[^>]*\b(?:src|href)=["']?((?:https?:)?//[^"' >]+)""", page.read_text())}
    assert fetched == set()


@pytest.fixture
def guide_copy(tmp_path: Path) -> Path:
    """mkdocs.yml and docs/ copied, to break."""
    shutil.copy(REPO / "mkdocs.yml", tmp_path / "mkdocs.yml")
    (tmp_path / "tools" / "commands").mkdir(parents=True)
    shutil.copy(REPO / "tools" / "commands" / "docs_hooks.py", tmp_path / "tools" / "commands")  # mkdocs.yml's hooks
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



def test_armctl_docs_check_fails_on_a_page_that_differs_and_changes_nothing(tmp_path: Path,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """The check itself (the command's run, as armctl calls it): a page with a figure typed into a
    region is named, the command fails, and the page is left as it was."""
    import argparse

    page = tmp_path / "benchmarks.md"
    text = (DOCS / "reference" / "benchmarks.md").read_text()
    m = docs_cmd.REGION.search(text)
    figure = re.search(r"\d+\.\d+", m.group("body"))
    typed = text[:m.start("body") + figure.start()] + "9" + text[m.start("body") + figure.start():]
    page.write_text(typed)
    monkeypatch.setattr(docs_cmd, "REPO", tmp_path)
    monkeypatch.setattr(docs_cmd, "pages", lambda: [page])
    with pytest.raises(docs_cmd.DocsError, match=r"^1 page\(s\) differ from their results files"):
        docs_cmd.run(argparse.Namespace(check=True))
    assert page.read_text() == typed

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


# ---- the guide as a newcomer reads it: every word explained, nothing of a machine or a lab notebook

from tools.bench import arms_page  # noqa: E402
from tools.commands.docs_hooks import glossary_terms, render_diagram  # noqa: E402

GLOSSARY = DOCS / "glossary.md"
# Parts a command writes: the numbers regions (tools/armctl docs), the parameter tables (gen.params),
# README's headline table (study --record) and the arm matrix (tools.bench.arms_page).
RENDERED = re.compile(r"<!-- (numbers|params):([a-z0-9-]+)\b.*?-->.*?<!-- /\1:\2 -->|<!-- headline:.*?<!-- /headline -->|"
                      + re.escape(arms_page.BEGIN) + ".*?" + re.escape(arms_page.END), re.S)
FENCE = re.compile(r"^(`{3,}).*?^\1", re.S | re.M)
CODE_SPAN = re.compile(r"(`+)(?!`).*?(?<!`)\1(?!`)", re.S)
COMMENT = re.compile(r"<!--.*?-->", re.S)
LINK_TARGET = re.compile(r"\]\([^)]*\)")
WORD = re.compile(r"(?<![\w/.-])[A-Z][A-Z0-9]*(?:-[A-Z0-9]+)*s?(?![\w/]|\.\w)")  # not a file name (README.md)


def prose(text: str) -> str:
    """What a page says in its own words: no rendered region, code block, code span, comment or
    link target."""
    for pattern in (RENDERED, FENCE, COMMENT, CODE_SPAN, LINK_TARGET):
        text = pattern.sub(" ", text)
    return text


def acronym(word: str) -> str | None:
    """An all-capital word as the glossary lists it (TPDOs, TPDO1: TPDO; STM32F407: STM; SHA-256:
    SHA); None for a single letter with digits (H2, M4, K2)."""
    letters = re.match(r"[A-Z]+", word.removesuffix("s") if word[:-1].isupper() else word)
    return letters.group(0) if letters and len(letters.group(0)) >= 2 else None


def glossary_acronyms(text: str) -> set[str]:
    return {a for t in glossary_terms(text) for w in WORD.findall(t) if (a := acronym(w))}


def missing_acronyms(pages: dict[str, str], glossary: str) -> dict[str, list[str]]:
    """acronym -> the pages that use it in their own words and the glossary lacks."""
    known = glossary_acronyms(glossary)
    out: dict[str, list[str]] = {}
    for name, text in pages.items():
        for w in WORD.findall(prose(text)):
            a = acronym(w)
            if a and a not in known:
                out.setdefault(a, []).append(name)
    return out


def guide_pages() -> dict[str, str]:
    return {str(p.relative_to(REPO)): p.read_text() for p in docs_cmd.pages()}


def test_every_acronym_of_the_guide_is_in_the_glossary() -> None:
    missing = missing_acronyms(guide_pages(), GLOSSARY.read_text())
    assert missing == {}, {a: sorted(set(p)) for a, p in missing.items()}


def test_an_acronym_the_glossary_lacks_is_named() -> None:
    """The check itself: a glossary without SDO's row, and a page with a new acronym."""
    glossary = GLOSSARY.read_text()
    without = "\n".join(line for line in glossary.splitlines() if not line.startswith("| **SDO**"))
    pages = guide_pages()
    assert "SDO" in missing_acronyms(pages, without)
    assert missing_acronyms({"x.md": "The XYZQ bus, the `ABCD` code, the TPDO2s."}, glossary) == {"XYZQ": ["x.md"]}


# The product's own terms: a page that uses one must find it in the glossary. Those the code defines
# are read from it (methods, scenarios, controller states); the coined phrases are listed here.
COINED = ("lockstep", "realtime", "software in the loop", "hardware in the loop", "processor in the loop", "run slot",
          "kept tuning", "code identity", "safe stop", "safety layer", "following error", "tracking bound",
          "drive table", "arm file", "design config", "default design", "prepared model", "model hash",
          "first resonance", "closed-loop bandwidth", "confirmation", "rendered region", "results file", "run folder",
          "headline record", "bundled arm", "drive slot", "bus timing", "bus load", "wiring", "per-mille",
          "nominal model", "total uncertainty", "golden vectors", "scenario", "seed", "verdict", "arm protocol",
          "consumer heartbeat", "transmission type", "capture", "telemetry", "study", "tuning")


def product_terms() -> set[str]:
    import tomllib

    from gen.lib.params import constant
    from tools.study.config import METHODS

    study = tomllib.loads((REPO / "tools" / "studies" / "paper.toml").read_text())
    return {*COINED, *METHODS, *study["scenarios"], *constant("controller-states")}


def test_every_product_term_the_guide_uses_is_in_the_glossary() -> None:
    glossary = GLOSSARY.read_text()
    defined = {t.lower() for t in glossary_terms(glossary)}
    text = " ".join(guide_pages().values()).lower()
    used = {t for t in product_terms() if re.search(rf"(?<![\w-]){re.escape(t.lower())}(?![\w-])", text)}
    assert used >= set(COINED) - {"headline record"}, set(COINED) - used
    lacking = {t for t in used if t.lower() not in defined and not re.search(
        rf"`{re.escape(t)}`", glossary)}
    assert lacking == set(), sorted(lacking)


def markdown_files() -> list[Path]:
    """Every Markdown file of the repository but the changelog, which is its history."""
    out = subprocess.run(["git", "-C", str(REPO), "ls-files", "*.md"], capture_output=True, text=True, check=True)
    return [REPO / f for f in out.stdout.split() if f != "CHANGELOG.md"]


# A path of one machine (the repository's own checkout, a home or work folder, a temporary file)
# and the phrases of a lab notebook: the documents describe the product, not where or when it was made.
MACHINE_PATH = re.compile(r"(?<![\w.])/(?:work|home|root|Users|mnt|srv)/\w|(?<![\w.])/tmp/[\w.-]+\.\w+|C:\\\\")
NOTEBOOK = re.compile(r"\bthis round\b|\bCI once\b|\bonce saw\b|cost time to find|could not be read here|"
                      r"\bon this machine\b|this machine's kernel|machine that builds these docs|\bwith local changes\b|"
                      r"\bthe lead\b|\bhelper\b", re.I)


def test_no_machine_path_or_lab_notebook_prose_in_any_document() -> None:
    found = []
    for f in markdown_files():
        text = RENDERED.sub(" ", f.read_text()) if f.parent.is_relative_to(DOCS) or f.name == "README.md" else f.read_text()
        for pattern in (MACHINE_PATH, NOTEBOOK):
            for m in pattern.finditer(text):
                line = text.count("\n", 0, m.start()) + 1
                found.append(f"{f.relative_to(REPO)}:{line}: {text[max(0, m.start() - 30):m.end() + 30]!r}")
    assert str(REPO) not in "".join(f.read_text() for f in markdown_files())
    assert found == []
    assert MACHINE_PATH.search("see /work/shared/notes/machine.md") and NOTEBOOK.search("not taken in this round")


# A measured figure: a number with a fraction (or thousands) and the unit of a result (an error, a
# share, a time, a ratio, a size, a rate). Outside a rendered region it was typed by hand, unless it
# is a value the product defines in a file (the parameter registry, the study config, the drive
# model and the drive table), which the page then quotes.
MEASURED = re.compile(r"(?<![\w.])(\d{1,3}(?:,\d{3})+|\d+\.\d+)\s?(deg\b|%|µs|us\b|ms\b|s\b|min\b|x\b|KiB\b|MiB\b|kB\b|"
                      r"bytes\b|instructions\b|W\b|Hz\b|kHz\b|rad/s\^2)")
DEFINING = ("firmware/params/params.toml", "tools/studies/paper.toml", "host_sim/drive_model.py",
            "firmware/protocol/drives.toml")


def _numbers(x: Any) -> list[float]:
    if isinstance(x, bool):
        return []
    if isinstance(x, (int, float)):
        return [float(x)]
    if isinstance(x, dict):
        return [v for y in x.values() for v in _numbers(y)]
    if isinstance(x, list):
        return [v for y in x for v in _numbers(y)]
    return []


def defined_values() -> set[float]:
    """Every number the defining files give (their values, not their comments), also as a percentage,
    a thousandth, a thousandfold and in degrees."""
    import ast
    import math
    import tomllib

    values: list[float] = []
    for f in DEFINING:
        text = (REPO / f).read_text()
        if f.endswith(".toml"):
            values += _numbers(tomllib.loads(text))
        else:
            values += [float(n.value) for n in ast.walk(ast.parse(text)) if isinstance(n, ast.Constant)
                       and isinstance(n.value, (int, float)) and not isinstance(n.value, bool)]
    return {y for x in values for y in (abs(x), abs(x) * 100, abs(x) / 1000, abs(x) * 1000, math.degrees(abs(x)))}


def typed_figures(text: str, defined: set[float]) -> list[str]:
    found = []
    for m in MEASURED.finditer(prose(text)):
        figure = m.group(1).replace(",", "")
        digits = len(figure.split(".")[1]) if "." in figure else 0
        if any(abs(float(figure) - v) <= 0.5 * 10 ** -digits for v in defined):
            continue
        found.append(m.group(0))
    return found


def test_no_measured_figure_is_typed_outside_a_rendered_region() -> None:
    defined = defined_values()
    found = {name: f for name, text in guide_pages().items() if (f := typed_figures(text, defined))}
    assert found == {}
    assert typed_figures("pm tracks within 0.44 deg, 61.1 % of a bus, 2.4x mj_step, 1,208 instructions", defined) == [
        "0.44 deg", "61.1 %", "2.4x", "1,208 instructions"]
    assert typed_figures("the 0.5 s hold (the registry's), `0.44 deg` in code", defined) == []


TROUBLE_KEY = re.compile(r"^\| `([^`]+)` \|", re.M)
SOURCES = ("firmware", "gen", "host_sim", "tools")


def test_every_troubleshooting_line_is_one_the_product_prints() -> None:
    """Each key of docs/troubleshooting.md is the start of a message in the sources: its longest
    literal piece (between the `...` of the names and values) is in a C or Python file."""
    keys = TROUBLE_KEY.findall((DOCS / "troubleshooting.md").read_text())
    assert len(keys) >= 20, keys
    sources = "\n".join(p.read_text(errors="replace") for d in SOURCES for p in (REPO / d).rglob("*")
                        if p.suffix in (".c", ".h", ".py") and "__pycache__" not in p.parts)
    sources = re.sub(r'"\s*\n\s*[rf]?"', "", sources)  # a literal continued on the next line, joined
    absent = []
    for k in keys:  # its distinctive parts: those with a space, an underscore or a hyphen, between the values
        parts = [p.strip(" '()") for p in re.split(r"\.\.\.|: ", k)]
        distinctive = [p for p in parts if len(p) >= 6 and re.search(r"[ _-]", p)]
        if not distinctive or any(p not in sources for p in distinctive):
            absent.append(k)
    assert absent == []


def test_the_data_flow_diagram_is_drawn_from_its_source(tmp_path: Path) -> None:
    """docs/diagrams/data-flow.dot, rendered by Graphviz when the guide is built: an SVG naming
    every stage of the data's way, which the overview shows; a broken source is named."""
    svg = render_diagram(DOCS / "diagrams" / "data-flow.dot")
    for stage in ("synthesis", "C headers", "firmware", "CAN bus", "CiA 402 drives", "the arm", "telemetry"):
        assert stage in svg, stage
    assert "diagrams/data-flow.svg" in (DOCS / "index.md").read_text()
    bad = tmp_path / "bad.dot"
    bad.write_text("digraph { a -> }")
    from tools.commands.docs_hooks import DiagramError

    with pytest.raises(DiagramError, match="bad.dot: dot failed"):
        render_diagram(bad)


def test_the_guide_build_installs_graphviz_as_its_own_need(monkeypatch: pytest.MonkeyPatch) -> None:
    """The diagrams ask for the docs need (tools/apt-packages-docs.txt), not the base list every
    command installs; where it cannot be installed, the build's error gives the apt-get line."""
    from tools.build import packages
    from tools.commands.docs_hooks import DiagramError

    assert "graphviz" in packages.listed("docs") and "graphviz" not in packages.listed(None)
    asked: list[str] = []

    def refuse(need: str) -> None:
        asked.append(need)
        raise packages.PackagesMissing("run: sudo apt-get install -y --no-install-recommends graphviz")

    monkeypatch.setattr(packages, "ensure", refuse)
    with pytest.raises(DiagramError, match=r"data-flow.dot: Graphviz's dot is missing: run: sudo apt-get .* graphviz"):
        render_diagram(DOCS / "diagrams" / "data-flow.dot")
    assert asked == ["docs"]
