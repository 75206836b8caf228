"""report.html: the study's report as one self-contained page, for a browser, offline. Its text
and tables are report.md's (python-markdown), so both always say the same; where report.md shows a
figure the page shows its interactive version (plotly: zoom into a run, hover a value, a method
toggled in the legend; tools/study/html_figures.py), or the PNG itself, inlined. plotly.js, the
figures' data, the images and the style are all inside the page: no CDN, no file beside it.

It reads at a glance: the first screen is report.md's first section (the answer per scenario, the
table of means, the answer drawn); every later section (how the study was run, each scenario's
per-joint detail) is folded in a <details> the reader opens, and its figures are drawn when it is
opened."""

from __future__ import annotations

import base64
import re
from pathlib import Path
from typing import Any

from gen.lib.atomic_output import write_text_atomic
from gen.lib.escape import html_text, markdown_html, script_json

HTML_FILE = "report.html"
STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; margin: 0; color: #222;
       background: #fafafa; }
main { max-width: 1200px; margin: 0 auto; padding: 1em 2em 4em; background: #fff; }
h1 { font-size: 1.6em; } h2 { border-bottom: 1px solid #ddd; padding-bottom: .2em; margin-top: 2em; }
h3 { margin-top: 1.6em; }
table { border-collapse: collapse; margin: .6em 0; font-size: .85em; display: block; overflow-x: auto; }
th, td { border: 1px solid #ccc; padding: .25em .55em; text-align: right; white-space: nowrap; }
th { background: #f0f0f0; } td:first-child, th:first-child { text-align: left; }
code { background: #f3f3f3; padding: 0 .2em; border-radius: 3px; font-size: .92em; }
pre { background: #f6f6f6; padding: .8em; overflow-x: auto; font-size: .8em; }
pre code { background: none; padding: 0; }
.figure { width: 100%; margin: 1em 0; border: 1px solid #eee; }
img.figure { height: auto; }
.glance { display: flex; flex-wrap: wrap; gap: 1em; align-items: flex-start; }
.glance > pre { flex: 0 1 auto; margin: 0; font-size: .72em; }
.glance > .figure, .glance > p { flex: 1 1 420px; min-width: 380px; margin: 0; }
details.section { margin-top: 1.2em; border-top: 1px solid #ddd; }
details.section > summary { cursor: pointer; padding: .3em 0; }
details.section > summary > h2 { display: inline; border: none; margin: 0; font-size: 1.3em; }
"""
# Each figure is drawn once it can be seen: at load, those outside a folded section; the others
# when their section is opened (plotly sizes a figure by its container, which a closed <details>
# gives none). A drawn figure says so (data-drawn="yes"); the page, once the first screen's are.
RENDER = """
function draw(root) {
  const drawing = [];
  for (const el of root.querySelectorAll("div.figure[data-figure]:not([data-drawn])")) {
    if (el.closest("details:not([open])")) continue;
    el.dataset.drawn = "pending";
    const fig = JSON.parse(document.getElementById(el.dataset.figure).textContent);
    drawing.push(Plotly.newPlot(el, fig.data, fig.layout, {responsive: true, displaylogo: false})
      .then(() => { el.dataset.drawn = "yes"; }));
  }
  return Promise.all(drawing);
}
for (const d of document.querySelectorAll("details.section")) {
  d.addEventListener("toggle", () => { if (d.open) draw(d); });
}
draw(document).then(() => { document.body.dataset.figures = "drawn"; });
"""
SECTION = re.compile(r"(?=<h2[ >])")
HEADING = re.compile(r"^(<h2[^>]*>.*?</h2>)", re.S)
IMAGE = re.compile(r'<p><img alt="([^"]*)" src="([^"]+\.png)" ?/?></p>')


def page(title: str, body: str, plotly: bool) -> str:
    from plotly.offline import get_plotlyjs

    scripts = f"<script>{get_plotlyjs()}</script>" if plotly else ""
    return (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">\n<title>{html_text(title)}</title>\n'
            f"<style>{STYLE}</style>\n{scripts}\n</head>\n<body>\n<main>\n{body}\n</main>\n"
            + (f"<script>{RENDER}</script>\n" if plotly else "") + "</body>\n</html>\n")


def folded(body: str) -> str:
    """The body with every h2 section after the first folded: <details> whose summary is its
    heading. What comes before the first h2 (the title) and the first section stay open."""
    head, *sections = SECTION.split(body)
    if not sections:
        return body
    first = sections[0]
    at = first.find("<pre>")
    if at >= 0:  # the table of means and the figure after it side by side, where the page is wide enough
        first = f'{first[:at]}<div class="glance">\n{first[at:]}</div>\n'
    out = [head, first]
    for sec in sections[1:]:
        m = HEADING.match(sec)
        if m is None:
            out.append(sec)
            continue
        out.append(f'<details class="section">\n<summary>{m.group(1)}</summary>\n{sec[m.end():]}</details>\n')
    return "".join(out)


def write_html(out: Path, study: dict[str, Any], markdown_text: str, interactive: dict[str, str]) -> Path:
    """OUT/report.html from report.md's text: each figure interactive where `interactive` has it
    (file name -> plotly JSON), else its PNG inlined."""
    body = markdown_html(markdown_text)  # raw HTML off: report.md's data is escaped, and the renderer adds none
    used: list[str] = []

    def figure(m: re.Match[str]) -> str:
        alt, src = m.group(1), m.group(2)
        if src in interactive:
            key = f"figure-{len(used)}"
            used.append(key)
            return (f'<div class="figure" data-figure="{html_text(key)}" title="{html_text(alt)}"></div>\n'
                    f'<script type="application/json" id="{html_text(key)}">{script_json(interactive[src])}</script>')
        try:
            data = base64.b64encode((out / src).read_bytes()).decode()
        except OSError:
            return m.group(0)  # report.md names it and it is gone: the page says so as the Markdown does
        return f'<p><img class="figure" alt="{html_text(alt)}" src="data:image/png;base64,{data}"></p>'

    body = folded(IMAGE.sub(figure, body))
    path = out / HTML_FILE
    write_text_atomic(path, page(f"Study: {study['description']}", body, bool(used)))
    return path

