"""A design config from synthesis knobs: what the tuner varies for pm, pm-paper and gh2.

The knobs are the paper's weights in one joint's terms (gen/SYNTH.md): the estimator weight
F(s) = f_bw / (s + f_bw) and H, and the controller penalty z_o = E1 e + E2 e_dot + D12 u_o
(searched as a bandwidth and a damping ratio, E1/D12 = wn^2, E2/D12 = 2 zeta wn, D12 = 1:
both forms depend only on the ratios) ("single": one row, a degenerate generalized-H2 problem whose optimum is the static gain
-(E1 e + E2 e_dot) / D12) or z_o = [E1 e + E2 e_dot; D12 u_o] ("split": the tracking and the
control penalty in separate rows, a non-degenerate problem with a dynamic controller). Everything
else (the loop rate, the design rules, the fixed-point ranges) is the base config's.
"""

from __future__ import annotations

import json
import math
import re
from typing import Any

from gen.lib import toml_input


class KnobError(ValueError):
    pass


def design_doc(base_text: str, knobs: dict[str, Any], with_estimator: bool = True) -> dict[str, Any]:
    doc = toml_input.loads(base_text)
    form = knobs.get("form", "single")
    if "wn" in knobs:  # the search's terms: E1/D12 = wn^2, E2/D12 = 2 zeta wn (only the ratios matter)
        wn, zeta = float(knobs["wn"]), float(knobs["zeta"])
        e1, e2, d12 = wn * wn, 2.0 * zeta * wn, 1.0
    else:
        e1, e2, d12 = float(knobs["E1"]), float(knobs["E2"]), float(knobs["D12"])
    if form == "single":
        doc["controller"] = {"E1": [[e1]], "E2": [[e2]], "D12": [[d12]]}
    elif form == "split":
        doc["controller"] = {"E1": [[e1], [0.0]], "E2": [[e2], [0.0]], "D12": [[0.0], [d12]]}
    else:
        raise KnobError(f"form: '{form}' is not single or split")
    if with_estimator:
        a = float(knobs["f_bw"])
        doc["estimator"] = {"F": {"num": [a], "den": [1.0, a]}, "H": [[float(knobs["H"])]]}
    doc["description"] = "tuned: " + ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                                               for k, v in sorted(knobs.items()))
    return doc


def design_text(base_text: str, knobs: dict[str, Any], with_estimator: bool = True) -> str:
    return dumps(design_doc(base_text, knobs, with_estimator))


def dumps(doc: dict[str, Any]) -> str:
    """TOML for a design config: top-level keys, then one [table] per section (values are numbers,
    strings, booleans, lists of them, or inline tables)."""
    lines = [f"{_key(k)} = {_value(v)}" for k, v in doc.items() if not isinstance(v, dict)]
    for section, table in doc.items():
        if isinstance(table, dict):
            lines += ["", f"[{_key(section)}]"] + [f"{_key(k)} = {_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


def _key(k: str) -> str:
    """A bare key where TOML allows one, else a quoted key (a scenario named realistic+friction)."""
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else _string(k)


def _string(text: str) -> str:
    """A TOML basic string (JSON's escapes are not all TOML's: a surrogate pair is not)."""
    return '"' + "".join(f"\\u{ord(c):04x}" if ord(c) < 0x20 or ord(c) == 0x7F
                         else "\\" + c if c in '"\\' else c for c in text) + '"'


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float) and not math.isfinite(v):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")  # TOML's words, not JSON's
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, (int, float)):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    raise KnobError(f"cannot write {v!r} as TOML")
