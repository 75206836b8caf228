"""Stage 1, load: the user's MJCF or URDF read by MuJoCo's own parser, after the checks of what it
would take without a word (bytes that are not UTF-8, NaN and infinite numbers, endless nesting,
ranges given upside down)."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco

from gen.arm.errors import ArmError
from gen.lib.one_line import joined_lines

MAX_NESTING = 256  # XML elements, and bodies below the world: deeper is no arm, and walks would recurse
MODEL_SUFFIXES = (".xml", ".urdf", ".mjcf")

# Attributes that hold names or files, never numbers (a joint may be called "inf").
_TEXT_ATTRS = {"name", "class", "childclass", "file", "filename", "prefix", "model", "joint", "joint1", "joint2",
               "body", "body1", "body2", "site", "site1", "site2", "tendon", "tendon1", "tendon2", "actuator",
               "target", "mesh", "material", "texture", "hfield", "geom", "geom1", "geom2", "objname", "refname",
               "link", "plugin", "instance", "key", "meshdir", "texturedir", "assetdir"}


def load(path: Path) -> mujoco.MjSpec:
    if not path.is_file():
        raise ArmError(f"model {path}: no such file")
    if path.suffix.lower() not in MODEL_SUFFIXES:
        raise ArmError(f"model {path}: expected an MJCF (.xml) or URDF (.urdf) file")
    _check_raw(path, path, set())
    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except Exception as exc:  # noqa: BLE001 - MuJoCo's parser raises ValueError with its message
        raise ArmError(f"model {path}: MuJoCo cannot read it: {joined_lines(str(exc))}") from exc
    _check_ranges(spec, path)
    return spec


def _check_raw(path: Path, top: Path, seen: set[Path]) -> None:
    """What MuJoCo would take without a word, checked in the file itself (and its includes):
    bytes that are not UTF-8 (MuJoCo hands them on as names, and reading one back fails), NaN
    and infinite numbers (MuJoCo puts a default in their place), elements nested without end."""
    seen.add(path)
    data = path.read_bytes()
    try:
        data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        start = max(data.rfind(b"<", 0, exc.start), data.rfind(b"\n", 0, exc.start) + 1)
        snippet = data[start:exc.start + 1].decode("utf-8", "backslashreplace")[:80]
        raise ArmError(f"model {path}: line {line}: byte 0x{data[exc.start]:02x} in {snippet} is not UTF-8: "
                       "MuJoCo reads names as UTF-8; save the file as UTF-8") from None
    where: list[str] = []  # the element path: the nearest named element names what is wrong
    try:
        for event, el in ET.iterparse(str(path), events=("start", "end")):
            if event == "end":
                where.pop()
                el.clear()
                continue
            label = f"{el.tag} '{el.get('name')}'" if el.get("name") else f"<{el.tag}>"
            named = next((w for w in reversed(where) if not w.startswith("<")), "")
            what = label if not label.startswith("<") or not named else f"{named} {label}"
            where.append(label)
            if len(where) > MAX_NESTING:
                raise ArmError(f"model {path}: {what} is nested {len(where)} elements deep, more than "
                               f"{MAX_NESTING}: no arm needs that many levels")
            for attr, value in el.attrib.items():
                if attr in _TEXT_ATTRS:
                    continue
                try:
                    nums = [float(t) for t in value.split()]
                except ValueError:
                    continue
                if not all(math.isfinite(x) for x in nums):
                    raise ArmError(f"model {path}: {what}: {attr}=\"{value}\" is not finite: MuJoCo would put a "
                                   "default in its place; give a number")
            if el.tag == "include" and el.get("file"):
                inc = (top.parent / el.get("file", "")).resolve()
                if inc.is_file() and inc not in seen:
                    _check_raw(inc, top, seen)
    except ET.ParseError:
        return  # not XML: MuJoCo's own parser names the error


def _check_ranges(spec: mujoco.MjSpec, path: Path) -> None:
    """A range given upside down or unbounded is a typo, not a choice: with autolimits MuJoCo
    makes such a joint unlimited without a word."""
    for i, j in enumerate(spec.joints):
        lo, hi = (float(x) for x in j.range)
        if lo == 0.0 and hi == 0.0:
            continue  # no range given
        name = j.name or f"joint {i}"
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ArmError(f"model {path}: joint '{name}': range [{lo:g}, {hi:g}] is not a finite interval with "
                           "range[0] < range[1] (swapped?): give the lower limit first")


def check_depth(m: mujoco.MjModel, path: Path) -> None:
    depth = [0] * m.nbody
    for b in range(1, m.nbody):  # a parent's id is below its children's: one pass, no recursion
        depth[b] = depth[int(m.body_parentid[b])] + 1
        if depth[b] > MAX_NESTING:
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"
            raise ArmError(f"model {path}: body '{name}' hangs {depth[b]} bodies below the world, more than "
                           f"{MAX_NESTING}: no arm needs that many levels")
