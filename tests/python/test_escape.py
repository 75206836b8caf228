"""The escaping rules (gen/lib/escape.py, issue 51), each held to its target by the target's own
reader: C strings and comments by the compiler (with the build's warnings, as errors), Markdown by
python-markdown, HTML by html.parser, TOML by tomllib, shell words by sh, DBC strings by cantools.
And the rule that no generator builds a literal any other way, checked on the generators' source."""

from __future__ import annotations

import ast
import html
import html.parser
import json
import shutil
import subprocess
import tomllib
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from gen.lib import escape
from gen.lib.escape import EscapeError
from gen.lib.one_line import one_line
from gen.lib.paths import REPO

CC = shutil.which("cc") or shutil.which("gcc")
# the build's own C dialect and warnings (CMakeLists.txt: C11 without extensions: trigraphs are on)
C_FLAGS = ["-std=c11", "-Wall", "-Wextra", "-Wconversion", "-Wshadow", "-Wvla", "-Werror", "-Wtrigraphs", "-Wcomment"]

# What breaks a target that takes a name unescaped: quotes, backslashes, line breaks, comment and
# trigraph sequences, markup, template fields, shell expansions, format specifiers, unicode.
HOSTILE = ['a"}; int injected; static const char *x[] = {"b', "back\\slash\\", 'quote"', "line\nbreak\r\n", "*/ int x; /*",
           "/* nested", "??/\n", "??=define X", "<script>document.title=1</script>", "<img src=x onerror=alert(1)>",
           "[link](javascript:alert(1))", "![img](http://evil/x.png)", "```", "~~~", "`code`", "%s%n%x", "%{y}",
           "$(touch /tmp/pwned)", "`touch /tmp/pwned`", "; rm -rf /", "'single'", "$x $$", "é ü ∑ 😀",
           "\u202eRTL", "tab\there", "\x1b[31mred", "\u2028sep", "-flag", "# heading", "> quote", "1. item",
           "| a | b |", "&amp; &lt;", "__bold__", "*em*", "$math$", "_hidden", "   ", ""]
hostile_text = st.one_of(st.sampled_from(HOSTILE), st.text(max_size=60),
                         st.text(alphabet=st.sampled_from(list("\"'\\`*/?<>&$%{}[]()!#|~_-+=.\n\t;: aZ09é")),
                                 max_size=40))


def _cc(tmp: Path, source: str, run: bool = False) -> subprocess.CompletedProcess[str]:
    if CC is None:
        pytest.skip("no C compiler")
    src = tmp / "t.c"
    src.write_text(source)
    exe = tmp / "t"
    r = subprocess.run([CC, *C_FLAGS, str(src), "-o", str(exe)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-3000:]
    return subprocess.run([str(exe)], capture_output=True, text=True) if run else r


def _symbols(path: Path) -> set[str]:
    r = subprocess.run(["nm", "--defined-only", str(path)], capture_output=True, text=True, check=True)
    return {ln.split()[-1] for ln in r.stdout.splitlines() if ln.strip()}


# ---- C ------------------------------------------------------------------------------------------
def test_c_strings_compile_to_the_names_bytes_and_comments_hide_everything(tmp_path: Path) -> None:
    """Every hostile name as a string literal compiles under the build's warnings and holds the
    name's UTF-8 bytes; as a comment it hides everything: the program defines only its own
    symbols, whatever the comments held."""
    names = [n for n in HOSTILE if "\0" not in n]
    lits = ",\n".join(f"    {escape.c_string(n, 'test')} /* {escape.c_comment(n)} */" for n in names)
    source = ("#include <stdio.h>\n#include <string.h>\n"
              f"static const char *const NAMES[] = {{\n{lits}\n}};\n"
              "int main(void) {\n    for (size_t i = 0; i < sizeof NAMES / sizeof NAMES[0]; i++) {\n"
              "        for (const char *c = NAMES[i]; *c; c++) printf(\"%02x\", (unsigned char)*c);\n"
              "        printf(\"\\n\");\n    }\n    return 0;\n}\n")
    r = _cc(tmp_path, source, run=True)
    got = r.stdout.splitlines()
    assert got == [n.encode("utf-8").hex() for n in names]
    assert not {"injected", "x"} & _symbols(tmp_path / "t")


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=hostile_text)
def test_any_text_is_a_c_string_and_a_comment_or_is_refused(tmp_path: Path, text: str) -> None:
    try:
        lit = escape.c_string(text, "the name")
    except EscapeError as exc:
        assert "\0" in text and "NUL" in str(exc) and "\n" not in str(exc)
        return
    comment = escape.c_comment(text)
    assert all(0x20 <= ord(c) < 0x7F for c in lit + comment)  # printable ASCII: no line, no trigraph
    assert "*/" not in comment and "/*" not in comment and "??" not in comment and "??" not in lit
    body = lit[1:-1].replace('\\"', "").replace("\\\\", "")
    assert '"' not in body  # every quote inside is escaped


def test_c_limits_are_refused_in_one_line_never_cut() -> None:
    with pytest.raises(EscapeError, match="joint 3's name.*NUL"):
        escape.c_string("a\0b", "joint 3's name")
    with pytest.raises(EscapeError) as exc:
        escape.c_string("x" * 5000, "joint 1's name")
    assert "4095" in str(exc.value) and "\n" not in str(exc.value) and len(str(exc.value)) < 300
    assert escape.c_string("x" * 4095, "ok").count("x") == 4095


# ---- identifiers --------------------------------------------------------------------------------
@settings(max_examples=200, deadline=None)
@given(text=hostile_text)
def test_identifiers_are_identifiers_or_refused(text: str) -> None:
    import re

    try:
        ident = escape.identifier(text, "the name", 32)
    except EscapeError as exc:
        assert "\n" not in str(exc)
        return
    assert re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]{0,31}", ident) and ident not in escape.C_KEYWORDS


def test_two_names_on_one_identifier_are_refused_naming_both() -> None:
    ids = escape.Identifiers("RPDO1_node1")
    assert ids.add("Target torque", "0x6071:00") == "target_torque"
    assert ids.add("Target torque", "0x6071:00") == "target_torque"  # the same name again is the same signal
    with pytest.raises(EscapeError, match="0x6072:00.*0x6071:00.*target_torque in RPDO1_node1"):
        ids.add("target-torque", "0x6072:00")
    with pytest.raises(EscapeError, match="refused, not cut"):
        escape.identifier("a" * 70, "x", 63)
    assert escape.identifier("int", "x") == "int_" and escape.identifier("3rd", "x") == "n_3rd"
    assert escape.identifier("Sollwert für Moment", "x") == "sollwert_fur_moment"
    assert escape.identifier("目標トルク", "x", fallback="object_6071_00") == "object_6071_00"
    with pytest.raises(EscapeError, match="no letter or digit"):
        escape.identifier("目標トルク", "0x6071:00 ParameterName")


# ---- Markdown and HTML ----------------------------------------------------------------------------
class _Tags(html.parser.HTMLParser):
    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: list[str] = []
        self.attrs: list[tuple[str, str | None]] = []
        self.text = ""

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append(tag)
        self.attrs += attrs

    def handle_data(self, data: str) -> None:
        self.text += data


def _parsed(page: str) -> _Tags:
    p = _Tags()
    p.feed(page)
    p.close()
    return p


@settings(max_examples=200, deadline=None)
@given(text=hostile_text)
def test_markdown_text_and_code_are_inert_and_show_the_name(text: str) -> None:
    """In any context a report puts a name (a paragraph, a table cell, a code span, a fenced
    block), python-markdown with raw HTML off makes no element of it and shows it as it is."""
    shown = one_line(text)
    para = _parsed(escape.markdown_html("Joint " + escape.markdown_text(text) + " ends."))
    assert para.tags == ["p"] and not para.attrs and para.text == f"Joint {shown} ends.", (para.tags, para.text)
    alone = _parsed(escape.markdown_html(escape.markdown_text(text)))
    assert set(alone.tags) <= {"p"} and alone.text.strip() == shown.strip()
    span = _parsed(escape.markdown_html("see " + escape.markdown_code(text)))
    assert span.tags == ["p", "code"], span.tags
    cell = _parsed(escape.markdown_html(f"| a | b |\n|---|---|\n| {escape.markdown_text(text)} | x |"))
    assert cell.tags == ["table", "thead", "tr", "th", "th", "tbody", "tr", "td", "td"], cell.tags
    fence = _parsed(escape.markdown_html(escape.markdown_fence([text, "after"]) + "\n\nend"))
    lines = fence.text.split("\n")  # (python-markdown blanks a line of spaces alone)
    assert fence.tags == ["pre", "code", "p"] and [ln.strip() for ln in lines[:2]] == [shown.strip(), "after"], fence.tags


def test_the_renderer_passes_no_raw_html() -> None:
    page = escape.markdown_html("<script>alert(1)</script>\n\nhi <b>x</b> <img src=x onerror=y> <http://a.b>")
    assert _parsed(page).tags == ["p", "p"]


@settings(max_examples=200, deadline=None)
@given(text=hostile_text)
def test_html_plotly_and_matplotlib_text(text: str) -> None:
    assert _parsed(f'<p title="{escape.html_text(text)}">{escape.html_text(text)}</p>').tags == ["p"]
    assert html.unescape(escape.html_text(text)) == text
    label = escape.plotly_text(text)
    assert "<" not in label and "%" not in label and "$" not in label and html.unescape(label) == one_line(text)
    mpl = escape.matplotlib_text(text)
    assert "\n" not in mpl and not mpl.startswith("_") and "$" not in mpl.replace("\\$", "")


def test_json_in_a_script_element_cannot_end_it() -> None:
    text = json.dumps({"name": "</script><script>alert(1)</script><!--"})
    safe = escape.script_json(text)
    assert "<" not in safe and json.loads(safe) == json.loads(text)


# ---- shell, files, TOML, DBC ------------------------------------------------------------------------
@settings(max_examples=50, deadline=None)
@given(argv=st.lists(hostile_text.filter(lambda s: "\0" not in s), min_size=1, max_size=4))
def test_a_printed_command_is_the_same_words_in_sh(argv: list[str]) -> None:
    line = escape.shell_command(["printf", "%s\\0", *argv])
    r = subprocess.run(["sh", "-c", line], capture_output=True, check=True)
    assert r.stdout.split(b"\0")[:-1] == [a.encode() for a in argv]


def test_paths_and_depfiles() -> None:
    for bad in ("", ".", "..", "a/b", "a\0b", "é" * 100):
        with pytest.raises(EscapeError):
            escape.path_component(bad, "scenario")
    assert escape.path_component("x`<img src=x>` $(y)", "scenario")
    assert escape.depfile_path("/a b/#c$d", "f") == "/a\\ b/\\#c$$d"
    with pytest.raises(EscapeError, match="line break"):
        escape.depfile_path("/a\nb", "f")
    with pytest.raises(EscapeError, match="CMake"):
        escape.cmake_value("/a;b.xml", "--model")


toml_values = st.recursive(st.one_of(st.text(max_size=20), st.integers(-2**63, 2**63 - 1), st.booleans(),
                                     st.floats(allow_nan=False)),
                           lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner,
                                                                                       max_size=3), max_leaves=8)


@settings(max_examples=100, deadline=None)
@given(doc=st.dictionaries(st.text(max_size=12), toml_values, max_size=5))
def test_toml_is_written_by_a_serializer_that_round_trips(doc: dict) -> None:
    assert tomllib.loads(escape.toml_text(doc)) == doc


def test_a_dbc_comment_round_trips_through_cantools() -> None:
    import cantools
    from cantools.database.can import Database, Message, Signal

    for text in HOSTILE:
        c = escape.dbc_string(text)
        db = Database([Message(0x100, "M", 1, [Signal("s", 0, 8, comment=c)], comment=c)])
        back = cantools.database.load_string(db.as_dbc_string(), database_format="dbc")
        assert back.messages[0].comment == c and back.messages[0].signals[0].comment == c
        import urllib.parse

        assert urllib.parse.unquote(c) == text


# ---- the one place ----------------------------------------------------------------------------------
# Modules that write C, a DBC, Markdown, HTML, a figure's labels, a shell script or a depfile.
EMITTERS = ["gen/robot_model.py", "gen/rnea_kernel.py", "gen/params.py", "gen/eds.py", "gen/drive_ids.py",
            "gen/synth/emit.py", "gen/canopen_dbc.py", "gen/arm/cli.py", "tools/study/report.py",
            "tools/study/html_report.py", "tools/study/html_figures.py", "tools/study/figures.py",
            "tools/study/headline.py", "tools/commands/docs.py", "tools/bench/arms_page.py", "tools/vm/run.py",
            "tools/run/run_analysis.py", "tools/study/__init__.py"]
ESCAPES = {n for n in dir(escape) if not n.startswith("_") and callable(getattr(escape, n))}
# names the escape module is imported as in the emitters (`markdown_text as md`, ...)
ALIASES = {"md", "code", "pt", "mt", "q", "_cell", "_cstr"}
# Only escape.py may call these: every other caller would be a second rule for the same target.
ONLY_IN_ESCAPE = {("shlex", "quote"), ("shlex", "join"), ("html", "escape"), ("markdown", "markdown"),
                  ("markdown", "Markdown")}


def _escaped(node: ast.expr) -> bool:
    """The value is a call of an escape function (or a number: a format spec says so)."""
    f = node.func if isinstance(node, ast.Call) else None
    name = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else None
    return name in ESCAPES or name in ALIASES


def _offences(path: Path) -> list[str]:
    out = []
    tree = ast.parse(path.read_text(), str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.JoinedStr):
            vals = node.values
            for i, v in enumerate(vals):
                if not isinstance(v, ast.FormattedValue) or v.format_spec is not None:
                    continue
                before = vals[i - 1].value if i and isinstance(vals[i - 1], ast.Constant) else ""
                after = vals[i + 1].value if i + 1 < len(vals) and isinstance(vals[i + 1], ast.Constant) else ""
                quoted = any(before.endswith(q) and after.startswith(q) for q in ('"', "`"))
                if (quoted or before.rstrip().endswith("/*")) and not _escaped(v.value):
                    out.append(f"{path.relative_to(REPO)}:{node.lineno}: {ast.unparse(v.value)} formatted into "
                               "a literal or comment")
        elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
            for side in (node.left, node.right):
                if isinstance(side, ast.Constant) and isinstance(side.value, str) and side.value in ('"', "'", "`"):
                    out.append(f"{path.relative_to(REPO)}:{node.lineno}: a quote concatenated to a value")
    return out


def test_no_generator_builds_a_literal_but_through_the_escaping_module() -> None:
    """In every module that writes C, a DBC, Markdown, HTML, labels, a script or a depfile, a value
    formatted between quotes or backticks, or into a C comment, is an escape function's result;
    no quote is concatenated to a value; and only gen/lib/escape.py quotes for a shell, escapes
    HTML or runs python-markdown."""
    bad = [o for p in EMITTERS for o in _offences(REPO / p)]
    assert bad == [], "\n".join(bad)
    for path in sorted([*(REPO / "gen").rglob("*.py"), *(REPO / "tools").rglob("*.py"),
                        *(REPO / "host_sim").rglob("*.py")]):
        if path.name == "escape.py" or "__pycache__" in path.parts:
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
                assert (node.value.id, node.attr) not in ONLY_IN_ESCAPE, \
                    f"{path.relative_to(REPO)}:{node.lineno}: {node.value.id}.{node.attr} outside gen/lib/escape.py"


def test_the_checker_sees_what_it_forbids(tmp_path: Path) -> None:
    """The test above would pass on a checker that sees nothing: each pattern is found."""
    probe = REPO / "gen" / "_escape_probe.py"
    probe.write_text('n = "x"\n'
                     'a = f\'static const char *N = "{n}";\'\n'
                     'b = f"/* {n} */"\n'
                     'c = \'"\' + n + \'"\'\n'
                     'd = f"`{n}`"\n'
                     'ok = f"/* {c_comment(n)} */ {x:.3f}"\n')
    try:
        found = _offences(probe)
    finally:
        probe.unlink()
    assert len(found) == 5 and all("_escape_probe.py" in f for f in found), found
