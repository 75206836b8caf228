"""What the importer refuses, and the number checks every stage shares."""

from __future__ import annotations

import math
from typing import Any

from gen.lib.one_line import one_line

FLOAT32_MAX = 3.4028234663852886e38  # the largest float32: the firmware computes in float32, every number it takes fits


class ArmError(ValueError):
    """The model or the arm file cannot be used; the message names what and says what to change."""

    def __init__(self, message: str) -> None:
        super().__init__(one_line(message))


def number(v: Any, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ArmError(f"{where}: expected a number, got {v!r}")
    float32(float(v), where)
    return float(v)


def float32(v: float, where: str) -> None:
    if not (math.isfinite(v) and abs(v) <= FLOAT32_MAX):
        raise ArmError(f"{where}: {v:g} is not a finite float32 (|x| <= {FLOAT32_MAX:.3g}), which the firmware "
                       "computes in")
