"""Read back the tables and macros of the generated design headers, exactly as C compiles them.

Golden vectors are computed from these values (not from the manifest's doubles) so that a test
compares the firmware's arithmetic, not two different roundings of the coefficients.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

_DEFINE = re.compile(r"^#define\s+(ARM_\w+)\s+(?:INT32_C\()?(-?[0-9.eE+-]+)f?\)?\s*(?:/\*.*)?$", re.M)
_ARRAY = re.compile(r"static const (float|int32_t) (ARM_\w+)\[[^\]]+\](?:\[[^\]]+\])?[^=]*=\s*\{(.*?)\};", re.S)


def parse(path: Path) -> tuple[dict[str, float], dict[str, np.ndarray]]:
    text = path.read_text()
    macros: dict[str, float] = {}
    for name, value in _DEFINE.findall(text):
        macros[name] = float(value) if any(c in value for c in ".eE") else int(value)
    # Aliases such as "#define ARM_EST_Y_FRAC ARM_Y_FRAC".
    for name, other in re.findall(r"^#define\s+(ARM_\w+)\s+(ARM_\w+)\s*$", text, re.M):
        if other in macros:
            macros[name] = macros[other]
    arrays: dict[str, np.ndarray] = {}
    for ctype, name, body in _ARRAY.findall(text):
        rows = re.findall(r"\{([^{}]*)\}", body) or [body]
        values = [[float(v.strip().rstrip("f")) for v in r.split(",") if v.strip()] for r in rows]
        dtype = np.float32 if ctype == "float" else np.int64
        arrays[name] = np.array(values, dtype=dtype)
    return macros, arrays
