"""The parameter registry (firmware/params/params.toml) for Python: every option of arm_controller,
arm_sim and armctl hil with its type, default, range, unit and help, declared once. gen/params.py
writes the C side from the same file; argparse defaults, the drive model's ranges and the option tables
of docs/reference/parameters.md come from here."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path
from typing import Any

from gen.lib.paths import REPO
from gen.lib.toml_input import loads as toml_loads

REGISTRY = REPO / "firmware" / "params" / "params.toml"
PROGRAMS = ("controller", "simulator", "hil", "identify")
TYPES = ("float", "int", "text", "flag", "choice", "special")
C_TYPES = ("double", "float", "floats", "uint32", "int", "long")
_FIELDS = {"type", "c", "field", "default", "min", "max", "min_open", "scale", "unit", "arg", "help", "group", "hidden",
           "choices"}


class RegistryError(ValueError):
    pass


@dataclass(frozen=True)
class Param:
    program: str
    name: str  # the option without its leading "--"
    type: str
    default: Any
    help: str
    min: float | None = None
    max: float | None = None
    min_open: bool = False
    scale: float = 1.0
    unit: str = ""
    arg: str = ""
    c: str = "double"
    field: str = ""
    group: str = ""
    hidden: bool = False
    choices: tuple[str, ...] = ()

    @property
    def option(self) -> str:
        return f"--{self.name}"

    def range_text(self) -> str:
        """'[lo, hi]' or '(lo, hi]' as the C parser's messages write it; '' when unbounded."""
        if self.min is None and self.max is None:
            return ""
        lo = "-inf" if self.min is None else f"{self.min:g}"
        hi = "inf" if self.max is None else f"{self.max:g}"
        return f"{'(' if self.min_open else '['}{lo}, {hi}]"

    def default_text(self) -> str:
        d = self.default
        if isinstance(d, bool):
            return "off" if not d else "on"
        if isinstance(d, float):
            return f"{d:g}"
        return str(d)

    def check(self, value: float, where: str | None = None, with_default: bool = False) -> float:
        """value if it is a finite number in range, else a ValueError naming where and the range;
        with_default: the range extended down to a numeric default below it (0: the feature off)."""
        p = self
        if with_default and isinstance(self.default, (int, float)) and self.min is not None and self.default < self.min:
            p = replace(self, min=float(self.default), min_open=False)
        name = where or self.option
        ok = not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)
        if ok and p.min is not None:
            ok = value > p.min if p.min_open else value >= p.min
        if ok and p.max is not None:
            ok = value <= p.max
        if not ok:
            raise ValueError(f"{name}: must be a number in {p.range_text()}, got {value!r}")
        if self.type == "int" and value != int(value):
            raise ValueError(f"{name}: must be a whole number, got {value!r}")
        return value


def _param(program: str, name: str, t: Any, where: str) -> Param:
    if not isinstance(t, dict):
        raise RegistryError(f"{where}: expected a table")
    unknown = set(t) - _FIELDS
    if unknown:
        raise RegistryError(f"{where}: unknown field(s) {sorted(unknown)}")
    if t.get("type") not in TYPES:
        raise RegistryError(f"{where}.type: one of {', '.join(TYPES)}, got {t.get('type')!r}")
    if "default" not in t or not isinstance(t.get("help"), str):
        raise RegistryError(f"{where}: default and help are required")
    if t.get("c", "double") not in C_TYPES:
        raise RegistryError(f"{where}.c: one of {', '.join(C_TYPES)}, got {t['c']!r}")
    choices = t.get("choices", [])
    if (t["type"] == "choice") != bool(choices) or not all(isinstance(c, str) for c in choices):
        raise RegistryError(f"{where}.choices: a list of words for type choice (and only for it)")
    if choices and t["default"] not in choices:
        raise RegistryError(f"{where}.default: one of the choices {choices}, got {t['default']!r}")
    for k in ("min", "max", "scale"):
        if k in t and (isinstance(t[k], bool) or not isinstance(t[k], (int, float))):
            raise RegistryError(f"{where}.{k}: a number, got {t[k]!r}")
    return Param(program=program, name=name, type=t["type"], default=t["default"], help=t["help"],
                 min=None if "min" not in t else float(t["min"]), max=None if "max" not in t else float(t["max"]),
                 min_open=bool(t.get("min_open", False)), scale=float(t.get("scale", 1.0)), unit=t.get("unit", ""),
                 arg=t.get("arg", "|".join(choices)), c=t.get("c", "double"), choices=tuple(choices), field=t.get("field", ""), group=t.get("group", ""),
                 hidden=bool(t.get("hidden", False)))


@lru_cache(maxsize=4)
def _load(path: Path) -> tuple[dict[str, dict[str, Param]], dict[str, Any]]:
    doc = toml_loads(path.read_text())
    constants = {name: t["value"] for name, t in doc.get("constant", {}).items()}
    out: dict[str, dict[str, Param]] = {}
    for program in PROGRAMS:
        table = doc.get(program, {})
        out[program] = {name: _param(program, name, _with_constants(t, constants, f"{path.name}: {program}.{name}"),
                                     f"{path.name}: {program}.{name}") for name, t in table.items()}
    return out, constants


def _with_constants(t: Any, constants: dict[str, Any], where: str) -> Any:
    """A parameter's help and default text with {const:NAME} replaced by that constant's value: a
    number a help text quotes is the constant's, never typed again."""
    if not isinstance(t, dict):
        return t

    def fill(text: Any) -> Any:
        if not isinstance(text, str):
            return text

        def value(m: re.Match[str]) -> str:
            if m.group(1) not in constants:
                raise RegistryError(f"{where}: {{const:{m.group(1)}}}: no [constant.{m.group(1)}]")
            return f"{constants[m.group(1)]:g}" if isinstance(constants[m.group(1)], float) else str(constants[m.group(1)])

        return re.sub(r"\{const:([a-z0-9-]+)\}", value, text)

    return {**t, "help": fill(t.get("help")), "default": fill(t.get("default"))}


def params(program: str, path: Path = REGISTRY) -> dict[str, Param]:
    """The program's parameters by option name (without "--"), in the registry's order."""
    return _load(path)[0][program]


def param(program: str, name: str) -> Param:
    return params(program)[name]


def default(program: str, name: str) -> Any:
    return param(program, name).default


def constants(path: Path = REGISTRY) -> dict[str, Any]:
    return _load(path)[1]


def constant(name: str) -> Any:
    return constants()[name]


def markdown_table(program: str, path: Path = REGISTRY) -> str:
    """The option table of a program (docs/reference/parameters.md): option, default, range, unit, what."""
    rows = ["| option | default | range | unit | what |", "|---|---|---|---|---|"]
    for p in params(program, path).values():
        if p.hidden:
            continue
        arg = f" {p.arg}".replace("|", "\\|") if p.arg else ""
        what = p.help.replace("|", "\\|").replace("{max_buses}", "4").replace("{methods}", "the method table's")
        default_text = p.default_text().replace("{model}", "the built arm")
        rows.append(f"| `{p.option}{arg}` | {default_text or '-'} | {p.range_text() or '-'} | {p.unit or '-'} | "
                    f"{what} |")
    return "\n".join(rows) + "\n"


# The generated option tables sit between these lines (gen/params.py --readme rewrites them).
def readme_markers(program: str) -> tuple[str, str]:
    return f"<!-- params:{program} (generated from firmware/params/params.toml: python -m gen.params --readme) -->", \
        f"<!-- /params:{program} -->"


def check_table(data: Any, known: set[str], where: str) -> None:
    """A config table of a dataclass's fields (the drive model, the uncertainty): a dict with no
    unknown field, else a ValueError naming where."""
    if not isinstance(data, dict):
        raise ValueError(f"{where}: expected a table of fields, got {type(data).__name__}")
    unknown = set(data) - known
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {sorted(unknown)} (known: {', '.join(sorted(known))})")
