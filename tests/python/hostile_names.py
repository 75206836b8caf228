"""Inputs an attacker would write (issue 51): the bundled arm's MJCF with names changed, and the
names that break a target that takes them unescaped. Shared by test_escape.py (the attacks, one
each) and test_hostile_names.py (every name-bearing place at once, property-based)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
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


# ---- every name-bearing place of a model, an arm file, a drive table and its EDS -----------------
JOINTS = ["shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3"]
BODIES = ["link1", "link2", "link3", "link4", "link5", "link6"]
# EDS objects whose names become the DBC's signals (the PDO mapping) or nothing but text
EDS_NAMED = {0x6071: "Target torque", 0x6064: "Position actual value", 0x1008: "Manufacturer device name"}


@dataclass
class Names:
    """The names an attacker controls, one per place."""
    model: str
    arm: str
    joints: list[str]
    bodies: list[str]
    site: str
    product: str
    parameters: dict[int, str]
    eds_file: str
    scenario: str
    description: str


def hostile_arm(folder: Path, n: Names) -> Path:
    """An arm file naming the bundled arm's MJCF with every name replaced, and a drive table naming
    an EDS (the project's own drive's, its strings replaced): `folder`/arm.toml. Files are rewritten
    only when their text changes (the arm's build folder stays valid)."""
    from gen.lib.escape import toml_text

    folder.mkdir(parents=True, exist_ok=True)
    renamed_model(folder / "model.xml", dict(zip(JOINTS, n.joints)), dict(zip(BODIES, n.bodies)),
                  {"flange": n.site}, model=n.model)
    eds = (REPO / "firmware" / "protocol" / "cia402_servo.eds").read_text()
    assert "ProductName=Arm emulated CiA 402 servo drive\n" in eds  # what is replaced is there to replace
    eds = eds.replace("ProductName=Arm emulated CiA 402 servo drive", f"ProductName={n.product}")
    for index, old in EDS_NAMED.items():
        assert f"[{index:X}]\nParameterName={old}\n" in eds
        eds = eds.replace(f"[{index:X}]\nParameterName={old}\n", f"[{index:X}]\nParameterName={n.parameters[index]}\n")
    _write(folder / n.eds_file, eds)
    import tomllib

    table = tomllib.loads((REPO / "firmware" / "protocol" / "drives.toml").read_text())  # the project's drives
    table["eds"] = n.eds_file
    table["joint"] = {j: {"node": i + 1} for i, j in enumerate(n.joints)}
    _write(folder / "drives.toml", toml_text(table))
    _write(folder / "arm.toml", toml_text({
        "name": n.arm, "model": "model.xml", "joints": n.joints, "flange": n.site, "drives": "drives.toml",
        "home": {j: q for j, q in zip(n.joints, [0.0, -1.3, 1.6, -1.87, -1.5708, 0.0])},
        "torque_limits": {j: t for j, t in zip(n.joints, [150.0, 150.0, 150.0, 28.0, 28.0, 28.0])}}))
    return folder / "arm.toml"


def _write(path: Path, text: str) -> None:
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


def study_config(path: Path, n: Names) -> Path:
    """The default study config with its scenario `ideal` named and described by the attacker."""
    import json

    text = (REPO / "tools" / "studies" / "paper.toml").read_text()
    text = text.replace('"ideal", ', f"{json.dumps(n.scenario)}, ", 1).replace(
        "[scenario.ideal]", f"[scenario.{json.dumps(n.scenario)}]", 1)
    old = next(ln for ln in text.splitlines() if ln.startswith("description = \"the paper's simulation"))
    _write(path, text.replace(old, f"description = {json.dumps(n.description)}", 1))
    return path


TOKEN = "zq7"  # in every name below: no symbol of a built program may hold it
WORST = Names(
    model=f'{TOKEN}model"<b>*/ $(touch x)',
    arm=f'{TOKEN}arm "; rm -rf',
    joints=[f'{TOKEN}j1"}}; int {TOKEN}inj = 1; static const char *{TOKEN}t[] = {{"',
            f"{TOKEN}j2*/ int {TOKEN}c; /*",
            f"{TOKEN}j3<img src=x onerror=\"document.title='{TOKEN}'\">",
            f"{TOKEN}j4\\\n%s%n??/",
            f"{TOKEN}j5$(touch {TOKEN}) `id` [a](javascript:x) ~~~",
            f'{TOKEN}j6 ü∑😀 | # _e_ <script>document.title="{TOKEN}"</script>'],
    bodies=[f'{TOKEN}b1"', f"{TOKEN}b2*/", f"{TOKEN}b3<b>", f"{TOKEN}b4\\", f"{TOKEN}b5$(x)", f"{TOKEN}b6 é"],
    site=f'{TOKEN}site"<i>x</i>',
    product=f'{TOKEN}prod"*/<script>alert(1)</script>',
    parameters={0x6071: f'{TOKEN}tt"*/ Target <b>torque</b>', 0x6064: f"{TOKEN}pos $(x) %s",
                0x1008: f'{TOKEN}dev"'},
    eds_file=f'{TOKEN} drive "x" $y.eds',
    scenario=f'{TOKEN}sc`<img src=x onerror="document.title=1">`',
    description=f'<script>document.title="{TOKEN}"</script> **{TOKEN}**')
