"""A user's error is one line (docs/runs.md: bad values fail fast, in one line), even when it names a key or value of theirs
that holds a line break or another control character: those are shown escaped, as in Python."""

from __future__ import annotations


def one_line(text: str) -> str:
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)
