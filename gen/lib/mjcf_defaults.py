"""A model's default classes, and how the elements a program adds to it are kept out of their reach.

MuJoCo applies a default class when an element is made: an element read from a file holds its
values with the classes applied, and an element added to a spec takes them from the class of its
body (a childclass) or from `main`. Written to XML, an element carries only what differs from its
class, and reading the file back applies the classes again. So a class that makes every `general`
actuator a position servo makes one too of every actuator a program adds, unless the class no
longer says so when the element is made and when the file is written: `reset_to_builtin` gives the
classes MuJoCo's own values for the kinds of element a program adds, and the elements of those
kinds that the model keeps are then written with their values in full."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any, Iterable

import mujoco

# the members of a default class (mujoco.MjsDefault), one per kind of element
KINDS = ("actuator", "camera", "equality", "flex", "geom", "joint", "light", "material", "mesh", "pair", "site",
         "tendon", "texture")
# what a class member holds besides the values it gives its elements
_NOT_VALUES = {"classname", "compiler", "id", "name", "info", "signature", "parent", "frame", "plugin", "default",
               "alt", "attach_body", "path"}
_ELEMENT_LISTS = ("bodies", "frames", "geoms", "sites", "joints", "tendons", "actuators", "cameras", "lights", "meshes",
                  "materials", "textures", "equalities", "pairs", "flexes")


def class_names_in(root: ET.Element) -> set[str]:
    """The names of the <default class=...> elements under root (nested or not)."""
    return {el.get("class", "") for el in root.iter("default") if el.get("class")}


def class_names_in_file(path: Path) -> set[str]:
    """The default classes a model file and its includes define."""
    names: set[str] = set()
    _in_file(path, path, names, set())
    return names


def _in_file(path: Path, top: Path, names: set[str], seen: set[Path]) -> None:
    seen.add(path)
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError):
        return  # MuJoCo read it, ElementTree cannot: its classes are found by use (default_classes)
    names |= class_names_in(root)
    for el in root.iter("include"):
        inc = (top.parent / el.get("file", "")).resolve()
        if el.get("file") and inc.is_file() and inc not in seen:
            _in_file(inc, top, names, seen)


def default_classes(spec: mujoco.MjSpec, names: Iterable[str]) -> list[mujoco.MjsDefault]:
    """`main` and every class named (a file's), and every class an element uses (class or
    childclass), defined or only inherited."""
    found = set(names)
    for elist in _ELEMENT_LISTS:
        for e in getattr(spec, elist, []):
            for attr in ("classname", "childclass"):
                d = getattr(e, attr, None)
                if isinstance(d, mujoco.MjsDefault) and d.name:
                    found.add(d.name)
                elif isinstance(d, str) and d:
                    found.add(d)
    out = [spec.default]
    for name in sorted(found - {"main"}):
        d = spec.find_default(name)
        if d is not None:
            out.append(d)
    return out


def _values(member: Any) -> list[tuple[str, Any]]:
    out = []
    for attr in dir(member):
        if attr.startswith("_") or attr in _NOT_VALUES:
            continue
        value = getattr(member, attr)
        if not callable(value):
            out.append((attr, value))
    return out


def reset_to_builtin(classes: list[mujoco.MjsDefault], kinds: Iterable[str]) -> None:
    """Every class in `classes` gives the elements of `kinds` MuJoCo's own defaults (those of a
    model without a <default>): an element of those kinds added now takes nothing from the model's
    classes, and the ones the model has are written with their own values in full."""
    builtin = mujoco.MjSpec().default
    for kind in kinds:
        assert kind in KINDS, kind
        values = _values(getattr(builtin, kind))
        for d in classes:
            member = getattr(d, kind)
            for attr, value in values:
                setattr(member, attr, value)

