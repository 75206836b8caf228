"""MkDocs hooks of the user guide (mkdocs.yml `hooks:`).

- Every Graphviz source under docs/diagrams/ (`NAME.dot`) is rendered to `diagrams/NAME.svg` when
  the guide is built, by Graphviz's `dot` (the Debian package graphviz, tools/apt-packages-docs.txt,
  installed when the guide is first built: the demo never pays for it): the diagram's one
  definition is its text, and the site holds the SVG, fetching nothing.
- Every acronym of the glossary (docs/glossary.md) explains itself on every page: the page gets the
  glossary's abbreviations (python-markdown's `abbr`, shown as a tooltip by the theme).

The glossary's terms are also what tests/python/test_docs.py holds every page's acronyms and
terms to (glossary_terms)."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

# mkdocs loads this file by its path, from a console script whose sys.path lacks the repository, and
# gives the hook no sys.path of its own when it runs: what it needs of ours is imported here, at load
_REPO = str(Path(__file__).resolve().parents[2])
if _REPO not in sys.path:
    sys.path.append(_REPO)
from tools.build import packages  # noqa: E402

DIAGRAMS = "diagrams"
GLOSSARY = "glossary.md"
# A glossary row: `| **TERM**, **ALIAS** | meaning |`
ROW = re.compile(r"^\| (?P<terms>(?:\*\*[^*]+\*\*(?:, )?)+) \| (?P<meaning>.+) \|$", re.M)
ACRONYM = re.compile(r"[A-Z][A-Z0-9-]*[A-Z0-9]")


class DiagramError(Exception):
    """A diagram that does not render, or no Graphviz to render it."""


def glossary_terms(text: str) -> dict[str, str]:
    """Every term of the glossary's tables (each alias its own entry) -> its meaning as plain text."""
    out: dict[str, str] = {}
    for m in ROW.finditer(text):
        meaning = re.sub(r"\[([^]]+)\]\([^)]*\)", r"\1", m.group("meaning"))  # a link: its text
        meaning = meaning.replace("`", "").replace("\\|", "|")
        for term in re.findall(r"\*\*([^*]+)\*\*", m.group("terms")):
            out[term] = meaning
    return out


def render_diagram(source: Path) -> str:
    """The SVG Graphviz's dot draws from `source`; DiagramError naming the file when it cannot."""
    try:
        packages.ensure("docs")
    except packages.PackagesMissing as e:
        raise DiagramError(f"{source.name}: Graphviz's dot is missing: {e}") from None
    dot = shutil.which("dot")
    if dot is None:
        raise DiagramError(f"{source.name}: Graphviz's dot is missing: install graphviz (tools/apt-packages-docs.txt)")
    r = subprocess.run([dot, "-Tsvg", str(source)], capture_output=True, text=True, timeout=60)
    if r.returncode != 0 or "<svg" not in r.stdout:
        raise DiagramError(f"{source.name}: dot failed: {' '.join(r.stderr.split())[:300]}")
    return r.stdout


def on_files(files: Any, config: Any) -> Any:
    from mkdocs.structure.files import File

    docs = Path(config["docs_dir"])
    for source in sorted((docs / DIAGRAMS).glob("*.dot")):
        svg = render_diagram(source)
        files.append(File.generated(config, f"{DIAGRAMS}/{source.stem}.svg", content=svg))
    return files


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    glossary = Path(config["docs_dir"]) / GLOSSARY
    terms = glossary_terms(glossary.read_text())
    abbreviations = [f"*[{t}]: {' '.join(meaning.split())}" for t, meaning in terms.items()
                     if ACRONYM.fullmatch(t)]
    return markdown + "\n\n" + "\n".join(abbreviations) + "\n"
