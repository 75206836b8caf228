"""The project's one TOML reader: tomllib, with a bound on nesting.

tomllib recurses once per nested array or inline table, so a few thousand `[` end in a
RecursionError (and a structure that survives parsing would recurse in every walk after it).
No config of this project nests more than a few levels; anything deeper than MAX_NESTING is
refused as a TOMLDecodeError, which every loader already reports in one line naming its file."""

from __future__ import annotations

import tomllib
from typing import Any

MAX_NESTING = 32


class TomlNestingError(tomllib.TOMLDecodeError):
    pass


def _too_deep() -> TomlNestingError:
    return TomlNestingError(f"nested deeper than {MAX_NESTING} levels of arrays or tables (this project's "
                            "configs need a few)")


def _depth(doc: dict[str, Any]) -> int:
    """Levels of arrays and tables below the document itself: `x = [[1]]` is 2."""
    deepest = 0
    todo: list[tuple[Any, int]] = [(doc, 0)]
    while todo:  # iterative: the walk must not recurse either
        v, d = todo.pop()
        deepest = max(deepest, d)
        if d > MAX_NESTING:
            break
        items = v.values() if isinstance(v, dict) else v
        todo.extend((x, d + 1) for x in items if isinstance(x, (dict, list)))
    return deepest


def loads(text: str) -> dict[str, Any]:
    try:
        doc = tomllib.loads(text)
    except RecursionError:
        raise _too_deep() from None
    if _depth(doc) > MAX_NESTING:
        raise _too_deep()
    return doc
