"""Study configs for tests: the default one with some [tuning] settings changed in place (the
top-level settings of the same names, such as duration_s, are the study's and stay)."""

from __future__ import annotations

import re


def with_tuning(text: str, **settings: object) -> str:
    """text with `key = value` replaced in its [tuning] table only (the table's own lines, before
    its sub-tables)."""
    head, tuning = text.split("\n[tuning]", 1)
    end = re.search(r"(?m)^\[", tuning)
    cut = end.start() if end else len(tuning)
    section = tuning[:cut]
    for key, value in settings.items():
        section, n = re.subn(rf"(?m)^{key} = [^#\n]*?(\s*(#.*)?)$", rf"{key} = {value}\1", section, count=1)
        assert n == 1, f"[tuning] has no {key}"
    return head + "\n[tuning]" + section + tuning[cut:]
