"""Arm models for tests: the vendored public arms (tests/arms, README there) and a variant of one
with what drive vendors' models carry (rotor armature, damping, friction, geared actuators)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
ARMS = REPO / "tests" / "arms"
UR5E = ARMS / "robosuite" / "ur5e.xml"

ARMATURE = [2.0, 4.0, 2.0, 0.5, 0.5, 0.5]


def armature_variant(tmp_path: Path) -> Path:
    """robosuite's UR5e as a drive vendor would ship it: rotor armature, joint damping and
    friction, and general actuators with a gear, a ctrlrange and a forcerange."""
    tree = ET.parse(UR5E)
    root = tree.getroot()
    for joint, a in zip(root.iter("joint"), ARMATURE):
        joint.set("armature", str(a))
        joint.set("damping", "1.0")
        joint.set("frictionloss", "2.0")
    act = root.find("actuator")
    assert act is not None
    for i, motor in enumerate(list(act)):
        peak = float(motor.get("ctrlrange", "0 0").split()[1]) * 1.1 / 100
        act.remove(motor)
        ET.SubElement(act, "general", {"name": f"drive{i}", "joint": motor.get("joint", ""), "gear": "100",
                                       "ctrllimited": "true", "ctrlrange": "-1.2 1.2", "forcelimited": "true",
                                       "forcerange": f"{-peak:.6g} {peak:.6g}"})
    out = tmp_path / "ur5e_armature.xml"
    tree.write(out)
    return out
