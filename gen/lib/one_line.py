"""A user's error is one line (docs/runs.md: bad values fail fast, in one line), even when it names a key or value of theirs
that holds a line break or another control character: those are shown escaped, as in Python."""

from __future__ import annotations


def one_line(text: str) -> str:
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)


def joined_lines(text: str) -> str:
    """A message of several lines (MuJoCo's parser and compiler write them) as one: its lines,
    stripped, joined by '; ', anything else unprintable escaped."""
    return one_line("; ".join(ln.strip() for ln in text.splitlines() if ln.strip()))
