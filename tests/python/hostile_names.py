"""Inputs an attacker would write (issue 51): the bundled arm's MJCF with names changed, and the
names that break a target that takes them unescaped. Shared by test_escape.py (the attacks, one
each) and test_hostile_names.py (every name-bearing place at once, property-based)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from gen.lib.paths import BUILD, REPO

BUNDLED = REPO / "host_sim" / "models" / "ur5e_arm.xml"
STABLE = BUILD / "test-arms"  # a fixed path: an arm's build folder is keyed on it, a second session rebuilds nothing


def c_injection(marker: Path) -> str:
    """A joint name that, pasted into a C string array unescaped, closes it and defines a
    constructor that runs at every start of every program built with it: it touches `marker`."""
    return ('a"}; extern int system(const char *); __attribute__((constructor)) static void injected_ctor(void) '
            f'{{ system("touch {marker}"); }} static const char *const injected_tail[] __attribute__((used)) = {{"b')


SCRIPT_TITLE = "424242"
SCRIPT_NAME = f"elbow<script>document.title={SCRIPT_TITLE}</script>"


def renamed_model(out: Path, joints: dict[str, str], bodies: dict[str, str] | None = None,
                  sites: dict[str, str] | None = None, model: str | None = None) -> Path:
    """The bundled arm's MJCF with joints (and their motors), bodies and sites renamed (old -> new),
    written to `out` (rewritten only when its text changes: its build folder stays valid)."""
    tree = ET.parse(BUNDLED)
    root = tree.getroot()
    if model is not None:
        root.set("model", model)
    for el in root.iter():
        name = el.get("name")
        if el.tag == "joint" and name in joints:
            el.set("name", joints[name])
        elif el.tag == "body" and bodies and name in bodies:
            el.set("name", bodies[name])
        elif el.tag == "site" and sites and name in sites:
            el.set("name", sites[name])
        elif el.tag == "motor":
            if name in joints:
                el.set("name", joints[name])
            if el.get("joint") in joints:
                el.set("joint", joints[el.get("joint", "")])
    text = ET.tostring(root, encoding="unicode")
    out.parent.mkdir(parents=True, exist_ok=True)
    if not out.exists() or out.read_text() != text:
        out.write_text(text)
    return out
