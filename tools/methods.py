"""The firmware's methods, read from the one table that defines them (firmware/core/src/methods.c,
`X(ARM_METHOD_ID, "name", uses_design, init, output, update)` in ARM_METHOD_TABLE): the CLI, the benchmarks and the study's method map
take the names from here, so adding a method to the core's table is all a new method needs for them
to list it (docs/firmware.md, Adding a method)."""

from __future__ import annotations

import functools
import re

from gen.lib.paths import REPO

TABLE = REPO / "firmware" / "core" / "src" / "methods.c"
_ENTRY = re.compile(r'^\s*X\(ARM_METHOD_\w+,\s*"([^"]+)",\s*([01]),', re.M)


@functools.cache
def firmware_methods() -> dict[str, bool]:
    """name -> uses the synthesised design, in the table's order."""
    found = {m.group(1): m.group(2) == "1" for m in _ENTRY.finditer(TABLE.read_text())}
    if not found:
        raise RuntimeError(f"{TABLE}: no method entries found (expected X(ARM_METHOD_ID, \"name\", 0|1, ...) lines)")
    return found


def method_names() -> tuple[str, ...]:
    return tuple(firmware_methods())
