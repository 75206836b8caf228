"""The one place a string from a user's file becomes part of another language: one rule per
target, and every writer of that target calls it (docs/safety.md).

A model, an arm file, a drive table, an EDS/DCF or a study config may come from anyone; its names
reach generated C, DBC files, shell commands the reports print, Markdown, HTML and figures. Each
target has one function here, and no generator builds a literal, a comment or a command line any
other way (tests/python/test_escape.py greps the generators for it):

| target | function | rule |
|---|---|---|
| C string literal | `c_string` | printable ASCII as is, `"` `\\` and each `?` of `??` escaped, every other byte (UTF-8) as an octal escape; a NUL or a literal over C11's 4095 characters is refused |
| C comment | `c_comment` | printable ASCII as is but a backslash and the first character of `*/`, `/*`, `??`; the rest `\\xNN`/`\\uNNNN`: nothing ends the comment or splices a line |
| identifier (C, DBC signal, LCM channel) | `identifier`, `Identifiers` | letters (accents dropped), digits and `_`, other runs one `_`, none left: the caller's fallback, never a C keyword, never a leading digit; longer than the target allows, empty, or two names on one identifier: refused |
| DBC string (a comment) | `dbc_string` | printable ASCII but `"` `\\` `%`; the rest percent-encoded |
| HTML | `html_text` | `html.escape` with quotes |
| JSON inside `<script>` | `script_json` | `<`, `>`, `&` as `\\u003c`, ... |
| plotly labels | `plotly_text` | HTML-escaped, and `%` and `$` as character references (no template field, no LaTeX) |
| matplotlib labels | `matplotlib_text` | one line, `$` escaped (no mathtext), a leading `_` kept visible |
| Markdown text | `markdown_text` | one line; `&<~` as entities; `` \\ ` * _ [ ] | # `` backslash-escaped (not `_` inside a word); a leading block marker escaped |
| Markdown code span / block | `markdown_code`, `markdown_fence` | a backtick fence longer than any run inside |
| Markdown to HTML | `markdown_html` | python-markdown with raw HTML off: data cannot bring an element |
| a folder or file name | `path_component`, `file_stem` | no `/`, `.`, `..` or NUL, at most 128 bytes; a stem: letters and digits, the rest `-` |
| shell | `shell_word`, `shell_command` | `shlex.quote` of each argument |
| Ninja depfile | `depfile_path` | space, `#`, `$` escaped; a line break refused |
| CMake value (a path) | `cmake_value` | `;` (a list separator), a line break or NUL refused |
| TOML | `toml_text` | a serializer (strings as basic strings, every control character escaped) |
| JSON | `json_text` | `json.dumps`, NaN refused |

A name a target cannot hold is refused with EscapeError, one line naming the element (the caller's
`what`) and the reason; nothing is ever truncated into another name.
"""

from __future__ import annotations

import datetime
import html
import json
import math
import re
import shlex
import unicodedata
import urllib.parse
from collections.abc import Iterable, Sequence
from typing import Any

from gen.lib.one_line import one_line

C_STRING_MAX = 4095   # C11 5.2.4.1: characters in a string literal a compiler must take
C_IDENTIFIER_MAX = 63  # C11 5.2.4.1: significant initial characters of an internal identifier
C_KEYWORDS = frozenset("""auto break case char const continue default do double else enum extern float for goto if
inline int long register restrict return short signed sizeof static struct switch typedef union unsigned void
volatile while _Alignas _Alignof _Atomic _Bool _Complex _Generic _Imaginary _Noreturn _Static_assert _Thread_local
bool true false NULL""".split())


class EscapeError(ValueError):
    """A name its target cannot represent; str() is one line naming the element and the reason."""

    def __init__(self, message: str) -> None:
        super().__init__(one_line(message))


def _shown(text: str, limit: int = 60) -> str:
    """A name as an error shows it: one line, and a long one cut (the error is not the place for it)."""
    s = one_line(text)
    return repr(s if len(s) <= limit else s[:limit] + "...")


# ---- C ----------------------------------------------------------------------------------------
_C_NAMED = {'"': '\\"', "\\": "\\\\", "\n": "\\n", "\t": "\\t"}


def c_string(text: str, what: str) -> str:
    """`text` as a C string literal, quotes included (UTF-8 bytes; octal escapes have at most three
    digits, so no escape runs into the next character; each `?` of `??` escaped: no trigraph)."""
    if "\0" in text:
        raise EscapeError(f"{what}: {_shown(text)} holds a NUL character, which a C string cannot")
    data = text.encode("utf-8", "surrogatepass")
    out = ['"']
    for i, b in enumerate(data):
        ch = chr(b)
        if ch in _C_NAMED:
            out.append(_C_NAMED[ch])
        elif ch == "?" and b"?" in (data[i - 1:i] if i else b"", data[i + 1:i + 2]):
            out.append("\\?")
        elif 0x20 <= b < 0x7F:
            out.append(ch)
        else:
            out.append(f"\\{b:03o}")
    out.append('"')
    literal = "".join(out)
    if len(literal) - 2 > C_STRING_MAX:
        raise EscapeError(f"{what}: {_shown(text)} is {len(text)} characters, a C string literal of "
                          f"{len(literal) - 2}: more than the {C_STRING_MAX} a C11 compiler must take")
    return literal


_COMMENT_SAFE = frozenset(chr(c) for c in range(0x20, 0x7F)) - {"\\"}
_COMMENT_PAIRS = ("*/", "/*", "??")  # the end of the comment, a comment in it (-Wcomment), a trigraph


def _char_escape(ch: str) -> str:
    return f"\\x{ord(ch):02x}" if ord(ch) < 0x100 else f"\\u{ord(ch):04x}" if ord(ch) < 0x10000 else f"\\U{ord(ch):08x}"


def c_comment(text: str) -> str:
    """`text` for inside a C block comment: the first character of `*/`, `/*` or `??` escaped, so
    nothing ends the comment, opens another or makes a trigraph; a backslash, a line break and
    every character beyond printable ASCII escaped, so nothing splices a line."""
    out = []
    for i, ch in enumerate(text):
        if ch in _COMMENT_SAFE and text[i:i + 2] not in _COMMENT_PAIRS:
            out.append(ch)
        else:
            out.append(_char_escape(ch))
    return "".join(out)


# ---- identifiers ------------------------------------------------------------------------------
def identifier(text: str, what: str, max_len: int = C_IDENTIFIER_MAX, prefix: str = "n_", lower: bool = True,
               fallback: str | None = None) -> str:
    """`text` as an identifier of C, a DBC or an LCM channel: accents dropped (für: fur), each run of
    other characters one `_`, no `_` at either end, `prefix` before a leading digit, `_` after a C
    keyword. A name with no letter or digit left is `fallback` (an identifier the caller makes of
    where the name is, such as an object's index), else refused; one longer than max_len is refused
    (never cut to fit)."""
    plain = "".join(c for c in unicodedata.normalize("NFKD", text) if not unicodedata.combining(c))
    ident = re.sub(r"[^0-9A-Za-z]+", "_", plain).strip("_")
    if lower:
        ident = ident.lower()
    if not ident:
        if fallback is None:
            raise EscapeError(f"{what}: {_shown(text)} has no letter or digit to make an identifier of")
        ident = fallback
    if ident[0].isdigit():
        ident = prefix + ident
    if ident in C_KEYWORDS:
        ident += "_"
    if len(ident) > max_len:
        raise EscapeError(f"{what}: {_shown(text)} makes the identifier {ident[:24]}... of {len(ident)} characters, "
                          f"more than the {max_len} its target takes (it is refused, not cut: two names cut alike "
                          "would become one)")
    return ident


class Identifiers:
    """Names of one scope (the signals of one message, the fields of one struct) made identifiers:
    two different names on one identifier are refused, naming both, never numbered apart."""

    def __init__(self, scope: str, max_len: int = C_IDENTIFIER_MAX) -> None:
        self.scope = scope
        self.max_len = max_len
        self._by_ident: dict[str, tuple[str, str]] = {}

    def add(self, text: str, what: str, fallback: str | None = None) -> str:
        ident = identifier(text, what, self.max_len, fallback=fallback)
        other = self._by_ident.get(ident)
        if other is not None and other[0] != text:
            raise EscapeError(f"{what}: {_shown(text)} and {other[1]} ({_shown(other[0])}) both become the identifier "
                              f"{ident} in {self.scope}: rename one")
        self._by_ident.setdefault(ident, (text, what))
        return ident


_DBC_SAFE = "".join(chr(c) for c in range(0x20, 0x7F) if chr(c) not in '"\\%')


def dbc_string(text: str) -> str:
    """`text` for a DBC string (a comment): printable ASCII but `"`, `\\` and `%` as is, everything
    else percent-encoded (its UTF-8 bytes, `%22` for a quote): no quote can end the string and no
    backslash can escape its closing quote, in any DBC reader."""
    return urllib.parse.quote(text, safe=_DBC_SAFE)


# ---- HTML and figures -------------------------------------------------------------------------
def html_text(text: str) -> str:
    """`text` as HTML text or an attribute's value: no element, no entity, no end of the attribute."""
    return html.escape(text, quote=True)


def script_json(text: str) -> str:
    """JSON text made safe inside an HTML <script> element: `<`, `>` and `&` only occur inside JSON
    strings, where \\u003c and the like mean the same; no `</script>` or `<!--` can end or bend it."""
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


_PLOTLY_REFS = {"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&#34;", "'": "&#39;", "%": "&#37;", "$": "&#36;"}


def plotly_text(text: str) -> str:
    """`text` for a plotly label (a trace's name, a title, a hover text): plotly reads a few tags
    (<b>, <br>, <a href>, ...) and `%{...}` template fields in them, and LaTeX between `$`: all
    written as character references, which plotly shows as the characters."""
    out = []
    for ch in one_line(text):  # plotly knows &amp; &lt; &gt; and numeric references, not &quot;
        out.append(_PLOTLY_REFS.get(ch, ch))
    return "".join(out)


def matplotlib_text(text: str) -> str:
    """`text` for a matplotlib label: `$` would start mathtext (and an unbalanced one fails the
    figure), a leading `_` hides the label from the legend."""
    s = one_line(text).replace("$", r"\$")
    return " " + s if s.startswith("_") else s


# ---- Markdown ---------------------------------------------------------------------------------
_MD_ENTITIES = {"&": "&amp;", "<": "&lt;", "~": "&#126;"}
_MD_BACKSLASHED = set("\\`*_[]|#")
_MD_BLOCK_START = re.compile(r"^(?:[-+=>]|\d+(?=[.)]))")


def markdown_text(text: str) -> str:
    """`text` as inert Markdown, one line: it cannot open a link, an image, a code span or fence,
    emphasis, raw HTML or an entity, nor start a heading, list, quote or table row."""
    line = one_line(text)
    out = []
    for i, ch in enumerate(line):
        if ch in _MD_ENTITIES:
            out.append(_MD_ENTITIES[ch])
        elif ch == "_" and 0 < i < len(line) - 1 and line[i - 1].isalnum() and line[i + 1].isalnum():
            out.append(ch)  # inside a word an underscore opens and closes nothing (python-markdown, CommonMark)
        elif ch in _MD_BACKSLASHED:
            out.append("\\" + ch)
        else:
            out.append(ch)
    s = "".join(out)
    if s[:1] in (" ", "\t"):  # after leading blanks a quote or list still starts, and four make code
        return f"&#{ord(s[0])};" + s[1:]
    m = _MD_BLOCK_START.match(s)
    if m:  # a list item's "-", "+", a setext "=", a quote's ">", a numbered item's "1." at the start of a line
        if m.group(0)[0].isdigit():
            s = s[:m.end()] + "\\" + s[m.end():]
        else:  # "=" has no backslash escape in python-markdown: its character reference
            s = ("&#61;" + s[1:]) if s[0] == "=" else "\\" + s
    return s


def _longest_backtick_run(text: str) -> int:
    return max((len(r) for r in re.findall(r"`+", text)), default=0)


def markdown_code(text: str) -> str:
    """`text` as a Markdown code span, shown as it is (one line): its fence longer than any run
    of backticks inside, padded when the text begins or ends with one."""
    s = one_line(text)
    fence = "`" * (_longest_backtick_run(s) + 1)
    pad = " " if s.startswith(("`", " ")) or s.endswith(("`", " ")) or not s else ""
    return f"{fence}{pad}{s}{pad}{fence}"


def markdown_fence(lines: Iterable[str], info: str = "") -> str:
    """Lines as a fenced code block: each line one line, the fence longer than any run of
    backticks in them, so no line can close it."""
    body = [one_line(ln) for ln in lines]
    fence = "`" * max(3, max((_longest_backtick_run(ln) for ln in body), default=0) + 1)
    return "\n".join([fence + info, *body, fence])


def markdown_html(text: str, extensions: Sequence[str] = ("tables", "fenced_code", "toc")) -> str:
    """Markdown made HTML with raw HTML off: a `<tag>` or an autolink in the text is shown as text,
    never passed on as an element (python-markdown passes it by default)."""
    import markdown

    md = markdown.Markdown(extensions=list(extensions))
    md.preprocessors.deregister("html_block")
    for name in ("html", "autolink", "automail"):
        md.inlinePatterns.deregister(name)
    return md.convert(text)


# ---- file names ----------------------------------------------------------------------------
PATH_COMPONENT_MAX = 128  # bytes of a name that names a folder and the files made from it (NAME_MAX is 255)


def path_component(text: str, what: str, max_bytes: int = PATH_COMPONENT_MAX) -> str:
    """A name that becomes one folder or file name as it is: no `/`, not `.` or `..`, no NUL, at
    most max_bytes of UTF-8. Refused otherwise: it would name a place outside its folder, or none."""
    if not text or text in (".", "..") or "/" in text or "\0" in text:
        raise EscapeError(f"{what}: {_shown(text)} cannot name a folder (it is empty, . or .., or holds / or a NUL)")
    if len(text.encode("utf-8", "surrogatepass")) > max_bytes:
        raise EscapeError(f"{what}: {_shown(text)} is {len(text.encode('utf-8', 'surrogatepass'))} bytes, more than the "
                          f"{max_bytes} a name that names folders and files may have")
    return text


def file_stem(text: str) -> str:
    """A name made part of a file name: every character but a letter or digit a `-` (two names may
    meet on one stem: a caller that names several files so checks them, see Identifiers)."""
    return "".join(c if c.isalnum() else "-" for c in text)


# ---- shell and build files --------------------------------------------------------------------
def shell_word(text: str) -> str:
    """One argument of a command a person copies into a POSIX shell."""
    return shlex.quote(str(text))


def shell_command(argv: Iterable[Any]) -> str:
    """A command line a report or a page prints for copy and paste: every argument quoted."""
    return " ".join(shell_word(str(a)) for a in argv)


def depfile_path(path: str, what: str) -> str:
    """A path in a Ninja/Make depfile: space, `#` and `$` escaped; a line break or a NUL cannot be
    written in one."""
    if any(c in path for c in "\n\r\0"):
        raise EscapeError(f"{what}: {_shown(path)} holds a line break or a NUL, which a build's depfile cannot "
                          "hold: rename the file or its folder")
    return path.replace("\\", "\\\\").replace(" ", "\\ ").replace("#", "\\#").replace("$", "$$")


def cmake_value(text: str, what: str) -> str:
    """A value passed to CMake (`-DNAME=VALUE`, a cache entry): CMake splits a value at `;` into a
    list, and a line break or NUL cannot be in a cache entry; such a value is refused, never split."""
    bad = next((c for c in text if c in ";\n\r\0"), None)
    if bad is not None:
        raise EscapeError(f"{what}: {_shown(text)} holds {'a ;' if bad == ';' else 'a line break or a NUL'}, which "
                          "CMake cannot take in a value (it splits lists at ;): rename the file or its folder")
    return text


# ---- TOML and JSON ----------------------------------------------------------------------------
def json_text(data: Any, indent: int | None = 2) -> str:
    """JSON by the serializer: NaN and infinities refused (they are not JSON)."""
    return json.dumps(data, indent=indent, allow_nan=False)


_TOML_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def toml_string(text: str) -> str:
    """`text` as a TOML basic string, quotes included (every control character escaped)."""
    out = ['"']
    for ch in text:
        if ch in ('"', "\\"):
            out.append("\\" + ch)
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04X}")
        else:
            out.append(ch)
    out.append('"')
    return "".join(out)


def _toml_key(key: str) -> str:
    return key if _TOML_BARE_KEY.match(key) else toml_string(key)


def _toml_value(v: Any, where: str) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return toml_string(v)
    if isinstance(v, (datetime.datetime, datetime.date, datetime.time)):
        return v.isoformat()
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x, where) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_toml_key(str(k))} = {_toml_value(x, where)}" for k, x in v.items()) + "}"
    raise EscapeError(f"{where}: a {type(v).__name__} has no TOML form")


def toml_text(doc: dict[str, Any]) -> str:
    """A document as TOML: top-level values first, then each table (a list of tables as [[name]]),
    nested tables inline."""
    lines: list[str] = []
    tables: list[tuple[str, Any]] = []
    for k, v in doc.items():
        if isinstance(v, dict) or (isinstance(v, list) and v and all(isinstance(x, dict) for x in v)):
            tables.append((k, v))
        else:
            lines.append(f"{_toml_key(str(k))} = {_toml_value(v, str(k))}")
    for k, v in tables:
        rows = v if isinstance(v, list) else [v]
        for row in rows:
            lines += ["", f"[[{_toml_key(k)}]]" if isinstance(v, list) else f"[{_toml_key(k)}]"]
            lines += [f"{_toml_key(str(kk))} = {_toml_value(x, f'{k}.{kk}')}" for kk, x in row.items()]
    return "\n".join(lines).lstrip("\n") + "\n"
