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


# What a Kinova-Jaco-like MJCF carries besides its dynamics: textures (one built in, one from a
# file that is not vendored), materials using them, and sites, geoms and a skin using the materials.
MATERIAL_ASSETS = """
    <texture name="grid" type="2d" builtin="checker" rgb1="0.1 0.2 0.3" rgb2="0.2 0.3 0.4" width="64" height="64"/>
    <texture name="logo" type="2d" file="textures/kinova_logo.png"/>
    <material name="reference_site" rgba="0.9 0.1 0.1 1"/>
    <material name="grid" texture="grid" texrepeat="2 2"/>
    <material name="logo" texture="logo"/>
"""
MATERIAL_SITES = {  # body -> what is added to it
    "fixed_base_link": '<site name="basesite" material="grid" size="0.01"/>',
    "wrist_3_link": '<site name="wristsite" material="reference_site" pos="0 0.08 0" size="0.01"/>'
                    '<geom name="badge" type="box" size="0.01 0.01 0.001" material="logo" contype="0" '
                    'conaffinity="0" group="1" mass="0"/>',
}
MATERIAL_SKIN = ('<deformable><skin name="cover" material="grid" vertex="0 0 0 0.02 0 0 0 0.02 0" face="0 1 2">'
                 '<bone body="wrist_3_link" bindpos="0 0 0" bindquat="1 0 0 0" vertid="0 1 2" '
                 'vertweight="1 1 1"/></skin></deformable>')


def materials_variant(out: Path) -> Path:
    """robosuite's UR5e with what MJCF files of other arms add (MATERIAL_ASSETS, MATERIAL_SITES,
    MATERIAL_SKIN): MuJoCo compiles it, and so must the importer."""
    tree = ET.parse(UR5E)
    root = tree.getroot()
    asset = root.find("asset")
    assert asset is not None
    for el in ET.fromstring(f"<a>{MATERIAL_ASSETS}</a>"):
        asset.append(el)
    for body in root.iter("body"):
        if body.get("name") in MATERIAL_SITES:
            for el in ET.fromstring(f"<a>{MATERIAL_SITES[body.get('name', '')]}</a>"):
                body.append(el)
    root.append(ET.fromstring(MATERIAL_SKIN))
    out.parent.mkdir(parents=True, exist_ok=True)
    tree.write(out)
    return out


def heavy_wrist_variant(tmp_path: Path) -> Path:
    """robosuite's UR5e with the wrists of the arms in issue 21: a Sawyer's 10 N m s/rad damping
    on 9 N m wrist motors, and a Jaco's last joint (armature 2 kg m^2, 1 N m friction, a 7 N m
    motor). The default reference of the importer asks more than these wrists have."""
    tree = ET.parse(UR5E)
    root = tree.getroot()
    wrists = {"wrist_1_joint": (0.0, 10.0, 0.0, 9.0), "wrist_2_joint": (0.0, 10.0, 0.0, 9.0),
              "wrist_3_joint": (2.0, 0.0, 1.0, 7.0)}  # armature, damping, frictionloss, torque limit
    for joint in root.iter("joint"):
        if joint.get("name") in wrists:
            arm_, damp, fric, _ = wrists[joint.get("name", "")]
            joint.set("armature", str(arm_))
            joint.set("damping", str(damp))
            joint.set("frictionloss", str(fric))
    act = root.find("actuator")
    assert act is not None
    for motor in act:
        if motor.get("joint") in wrists:
            lim = wrists[motor.get("joint", "")][3]
            motor.set("ctrlrange", f"{-lim:g} {lim:g}")
            motor.set("ctrllimited", "true")
    out = tmp_path / "ur5e_heavy_wrist.xml"
    tree.write(out)
    return out
