"""Arm models built from the features real MJCF and URDF files use (for the hypothesis tests of
the importer, tests/python/test_arm_features.py): nested default classes and childclass,
<include>, frames, sites, cameras, lights, tendons, equality constraints, mesh-only bodies,
fromto geoms, <compiler> angle, eulerseq and autolimits, keyframes, scenes with objects; URDF
package:// meshes, mimic joints, fixed joints, <transmission> and missing inertials.

A drawn model is a plain description (dataclasses of choices) and a writer that turns it into
files, so a failing example prints what it was made of. `defect` names the one thing a model was
given that the importer must refuse (None: it must import), and `refusal` the text that names it."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from hypothesis import strategies as st

AXES = ("0 0 1", "0 1 0", "1 0 0", "0 1 1")
MJCF_DEFECTS = (None, None, None, None, "coupled", "weak", "massless")


@dataclass
class Link:
    axis: str
    orient: str          # "none", "quat", "euler", "axisangle", "frame" (the body inside a <frame>)
    mass_from: str       # "inertial", "geoms" (sphere and fromto capsule), "mesh" (inline vertices), "mesh-file"
    joint_class: str     # "", "large", "small" (nested in "large"), or "child" (the body's childclass)
    limited: bool
    site: bool
    camera: bool
    light: bool


@dataclass
class MjcfArm:
    links: list[Link]
    angle: str           # "radian" or "degree"
    eulerseq: str
    autolimits: bool
    include: bool        # defaults and assets in an included file (like dm_control's common.xml)
    actuators: str       # "motor", "general" (geared), "none" (no limit in the model)
    gripper: str         # "none", "fingers" (two slides coupled by an equality), "jaw" (one more hinge)
    scene: str           # "none", "box" (a free body), "door" (a hinged tree of its own)
    keyframe: bool
    tendons: bool
    mocap: bool          # a mocap body welded to the tip (a handle to drag the arm by)
    defect: str | None = None
    home: list[float] = field(default_factory=list)

    @property
    def arm_joints(self) -> list[str]:
        return [f"j{i}" for i in range(len(self.links))] + (["jaw"] if self.gripper == "jaw" else [])

    @property
    def refusal(self) -> str:
        return {"coupled": "couples controlled joint", "weak": "cannot hold the arm at home",
                "massless": f"body 'l{len(self.links) - 1}' moves but has no mass and inertia"}.get(self.defect or "", "")


@st.composite
def mjcf_arms(draw: st.DrawFn) -> MjcfArm:
    n = draw(st.integers(3, 6))
    links = [Link(axis=AXES[0] if i == 0 else draw(st.sampled_from(AXES)),
                  orient=draw(st.sampled_from(("none", "quat", "euler", "axisangle", "frame"))),
                  mass_from=draw(st.sampled_from(("inertial", "geoms", "mesh", "mesh-file"))),
                  joint_class=draw(st.sampled_from(("", "large", "small", "child"))),
                  limited=draw(st.booleans()), site=draw(st.booleans()), camera=draw(st.booleans()),
                  light=draw(st.booleans()))
             for i in range(n)]
    arm = MjcfArm(links, angle=draw(st.sampled_from(("radian", "degree"))),
                  eulerseq=draw(st.sampled_from(("xyz", "XYZ", "zyx", "ZXY"))), autolimits=draw(st.booleans()),
                  include=draw(st.booleans()), actuators=draw(st.sampled_from(("motor", "general", "none"))),
                  gripper=draw(st.sampled_from(("none", "fingers", "jaw"))),
                  scene=draw(st.sampled_from(("none", "box", "door"))), keyframe=draw(st.booleans()),
                  tendons=draw(st.booleans()), mocap=draw(st.booleans()), defect=draw(st.sampled_from(MJCF_DEFECTS)))
    if arm.defect == "weak":  # a tiny motor on a joint that gravity loads at home
        arm.actuators = "motor"
        arm.links[1].axis = "0 1 0"
        arm.links[1].limited = True
        arm.keyframe = True
    if arm.defect == "massless":
        arm.links[-1].mass_from = "none"
        arm.gripper = "none"
    arm.home = [round(draw(st.floats(-1.0, 1.0)), 3) for _ in arm.links]
    if arm.gripper == "jaw":
        arm.home.append(round(draw(st.floats(-0.3, 0.3)), 3))  # its range is +-0.5 rad
    if arm.defect == "weak":
        arm.home[1] = 1.2
    return arm


def _angle(arm: MjcfArm, rad: float) -> str:
    return f"{math.degrees(rad):.6g}" if arm.angle == "degree" else f"{rad:.6g}"


def _orientation(arm: MjcfArm, link: Link, i: int) -> str:
    a = 0.3 + 0.1 * i
    if link.orient == "quat":
        return f'quat="{math.cos(a / 2):.6f} 0 {math.sin(a / 2):.6f} 0"'
    if link.orient in ("euler", "frame"):
        return f'euler="{_angle(arm, a)} 0 {_angle(arm, -a / 2)}"'
    if link.orient == "axisangle":
        return f'axisangle="1 0 0 {_angle(arm, a)}"'
    return ""


def _range(arm: MjcfArm, link: Link) -> str:
    if not link.limited:
        return ""
    r = f'range="{_angle(arm, -2.0)} {_angle(arm, 2.0)}"'
    return r if arm.autolimits else f'limited="true" {r}'


def _mass(link: Link, i: int) -> str:
    if link.mass_from == "inertial":
        return '<inertial pos="0 0 0.1" mass="1.2" diaginertia="0.012 0.012 0.008"/>'
    if link.mass_from == "geoms":
        return ('<geom type="sphere" size="0.04" pos="0 0 0.1" mass="0.6"/>'
                '<geom type="capsule" fromto="0 0 0 0 0 0.2" size="0.03" mass="0.6"/>')
    if link.mass_from == "mesh":  # a mesh-only body: its mass from the mesh's volume
        return f'<geom type="mesh" mesh="block{i}" density="2000"/>'
    if link.mass_from == "mesh-file":  # a vendor's mesh that is not shipped, with the link's inertial
        return ('<inertial pos="0 0 0.1" mass="1.2" diaginertia="0.012 0.012 0.008"/>'
                f'<geom type="mesh" mesh="shell{i}" class="visual"/>')
    return ""


def _body(arm: MjcfArm, i: int, inner: str) -> str:
    link = arm.links[i]
    jclass = f' class="{link.joint_class}"' if link.joint_class in ("large", "small") else ""
    child = ' childclass="child"' if link.joint_class == "child" else ""
    extras = '<site name="cable_end" pos="0 0.02 0.1"/>' if i == 1 and arm.tendons else ""
    if link.site:
        extras += f'<site name="s{i}" pos="0 0 0.1"/>'
    if link.camera:
        extras += f'<camera name="cam{i}" pos="0.2 0 0.1" mode="targetbody" target="base"/>'
    if link.light:
        extras += f'<light name="light{i}" pos="0 0 0.5" dir="0 0 -1"/>'
    pos = "0 0 0.05" if i == 0 else "0 0 0.2"
    body = (f'<body name="l{i}" pos="{pos}" {"" if link.orient == "frame" else _orientation(arm, link, i)}{child}>'
            f'<joint name="j{i}" axis="{link.axis}" {_range(arm, link)}{jclass}/>{_mass(link, i)}{extras}{inner}</body>')
    if link.orient == "frame":
        body = f'<frame name="f{i}" {_orientation(arm, link, i)}>{body}</frame>'
    return body


def _gripper(arm: MjcfArm) -> str:
    inertial = '<inertial pos="0 0 0.02" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/>'
    if arm.gripper == "jaw":
        jaw_range = f"{_angle(arm, -0.5)} {_angle(arm, 0.5)}"
        return (f'<body name="jawlink" pos="0 0 0.2"><joint name="jaw" axis="1 0 0" range="{jaw_range}" '
                f'limited="true"/>{inertial}</body>')
    if arm.gripper == "fingers":
        return "".join(f'<body name="finger{k}" pos="0 {0.02 * (1 - 2 * k)} 0.2"><joint name="finger{k}" '
                       f'type="slide" axis="0 1 0" range="0 0.04" limited="true"/>{inertial}</body>' for k in range(2))
    return ""


def _assets(arm: MjcfArm) -> str:
    meshes = "".join(f'<mesh name="block{i}" vertex="-0.03 -0.03 0  0.03 -0.03 0  0.03 0.03 0  -0.03 0.03 0  '
                     f'-0.03 -0.03 0.2  0.03 -0.03 0.2  0.03 0.03 0.2  -0.03 0.03 0.2"/>'
                     if link.mass_from == "mesh" else f'<mesh name="shell{i}" file="meshes/shell{i}.stl"/>'
                     if link.mass_from == "mesh-file" else "" for i, link in enumerate(arm.links))
    return ('<asset><texture name="grid" type="2d" builtin="checker" rgb1="0.1 0.2 0.3" rgb2="0.2 0.3 0.4" '
            'width="32" height="32"/><material name="grid" texture="grid"/>'
            '<material name="reference_site" rgba="1 0 0 0.5"/><material name="dark" rgba="0.1 0.1 0.1 1"/>'
            f'{meshes}</asset>')


def _defaults() -> str:
    """Nested classes as vendors write them: a site material for every site (dm_control's
    common.xml), a visual class whose geoms carry a material, joint classes inside classes."""
    return ('<default><site type="sphere" size="0.01" material="reference_site" group="4"/>'
            '<geom material="dark"/><joint damping="0.05"/>'
            '<default class="visual"><geom contype="0" conaffinity="0" group="2" material="grid"/></default>'
            '<default class="large"><joint armature="0.2" frictionloss="0.1"/>'
            '<default class="small"><joint armature="0.05"/></default></default>'
            '<default class="child"><joint damping="0.2"/><site material="grid"/></default></default>')


def _actuators(arm: MjcfArm) -> str:
    out = []
    for k, j in enumerate(arm.arm_joints):
        if arm.actuators == "none":
            break
        lim = 1e-6 if arm.defect == "weak" else 80
        if arm.actuators == "motor":
            out.append(f'<motor name="m_{j}" joint="{j}" ctrlrange="{-lim} {lim}" ctrllimited="true"/>')
        else:
            out.append(f'<general name="m_{j}" joint="{j}" gear="100" ctrlrange="-1 1" forcerange="{-lim / 100} '
                       f'{lim / 100}" forcelimited="true" ctrllimited="true"/>')
    return f"<actuator>{''.join(out)}</actuator>" if out else ""


def write_mjcf(arm: MjcfArm, folder: Path) -> Path:
    """The model's files in folder: arm.xml (and common.xml when the arm includes one)."""
    inner = _gripper(arm)
    if arm.mocap:
        inner += '<site name="tip" pos="0 0 0.2"/>'
    for i in reversed(range(len(arm.links))):
        inner = _body(arm, i, inner)
    scene = ""
    if arm.scene == "box":
        scene = ('<body name="box" pos="0.5 0 0.1"><freejoint name="box_free"/>'
                 '<geom type="box" size="0.03 0.03 0.03" mass="0.2"/></body>')
    elif arm.scene == "door":
        scene = ('<body name="door" pos="-0.5 0 0.3"><joint name="door_hinge" axis="0 0 1" range="0 1.5" limited="true"/>'
                 '<geom type="box" size="0.2 0.01 0.3" mass="2"/></body>')
    if arm.mocap:
        scene += '<body name="handle" mocap="true" pos="0 0 1.4"/>'
    common = _defaults() + _assets(arm)
    head = '<include file="common.xml"/>' if arm.include else common
    eq = []
    if arm.gripper == "fingers":
        eq.append('<joint joint1="finger0" joint2="finger1"/>')
    if arm.mocap:
        eq.append('<weld body1="handle" body2="l%d"/>' % (len(arm.links) - 1))
    if arm.defect == "coupled":
        eq.append('<joint joint1="j0" joint2="j1" polycoef="0 1 0 0 0"/>')
    tendons = ""
    if arm.tendons:
        tendons = ('<tendon><fixed name="couple"><joint joint="j0" coef="1"/><joint joint="j1" coef="-1"/></fixed>'
                   '<spatial name="cable" material="grid" width="0.005"><site site="basesite"/>'
                   '<site site="cable_end"/></spatial></tendon>')
    key = ""
    if arm.keyframe:
        qpos = list(arm.home[:len(arm.links)])
        qpos += [arm.home[-1]] if arm.gripper == "jaw" else [0.01, 0.01] if arm.gripper == "fingers" else []
        if arm.scene == "box":
            qpos = [0.5, 0.0, 0.1, 1.0, 0.0, 0.0, 0.0] + qpos
        elif arm.scene == "door":
            qpos = [0.5] + qpos
        key = f'<keyframe><key name="home" qpos="{" ".join(f"{q:.6g}" for q in qpos)}"/></keyframe>'
    text = (f'<mujoco model="feature_arm"><compiler angle="{arm.angle}" eulerseq="{arm.eulerseq}" '
            f'autolimits="{str(arm.autolimits).lower()}"/>{head}'
            f'<worldbody><light name="sun" pos="0 0 3" dir="0 0 -1"/><camera name="overview" pos="1 1 1" '
            f'xyaxes="-1 1 0 0 0 1"/>{scene}<body name="base" pos="0 0 0.1"><inertial pos="0 0 0" mass="3" '
            f'diaginertia="0.02 0.02 0.02"/><site name="basesite"/>{inner}</body></worldbody>'
            f'{_actuators(arm)}{tendons}{"<equality>" + "".join(eq) + "</equality>" if eq else ""}{key}</mujoco>')
    folder.mkdir(parents=True, exist_ok=True)
    if arm.include:
        (folder / "common.xml").write_text(f"<mujoco>{common}</mujoco>")
    path = folder / "arm.xml"
    path.write_text(text)
    return path


# ---- URDF --------------------------------------------------------------------------------------
URDF_DEFECTS = (None, None, None, "no-inertial")


@dataclass
class UrdfArm:
    joints: list[str]        # "revolute" or "continuous" per arm joint; fixed joints sit between some
    fixed_between: list[bool]
    efforts: bool            # <limit effort> given
    meshes: bool             # package:// visual and collision meshes (not shipped)
    gripper: str             # "none", "mimic" (two prismatic fingers, one mimicking the other)
    transmission: bool
    defect: str | None = None

    @property
    def refusal(self) -> str:
        return "body 'link2' moves but has no mass and inertia" if self.defect == "no-inertial" else ""


@st.composite
def urdf_arms(draw: st.DrawFn) -> UrdfArm:
    n = draw(st.integers(3, 6))
    return UrdfArm(joints=[draw(st.sampled_from(("revolute", "continuous"))) for _ in range(n)],
                   fixed_between=[draw(st.booleans()) for _ in range(n)], efforts=draw(st.booleans()),
                   meshes=draw(st.booleans()), gripper=draw(st.sampled_from(("none", "mimic"))),
                   transmission=draw(st.booleans()), defect=draw(st.sampled_from(URDF_DEFECTS)))


def _urdf_link(name: str, arm: UrdfArm, inertial: bool = True) -> str:
    visual = ""
    if arm.meshes:
        visual = (f'<visual><geometry><mesh filename="package://vendor_description/meshes/{name}.dae"/></geometry>'
                  f'</visual><collision><geometry><mesh filename="package://vendor_description/meshes/{name}.stl"/>'
                  '</geometry></collision>')
    mass = ('<inertial><origin xyz="0 0 0.1" rpy="0 0 0"/><mass value="1.5"/><inertia ixx="0.01" ixy="0" ixz="0" '
            'iyy="0.01" iyz="0" izz="0.005"/></inertial>') if inertial else ""
    return f'<link name="{name}">{mass}{visual}</link>'


def write_urdf(arm: UrdfArm, folder: Path) -> Path:
    parts = ['<robot name="vendor_arm">', _urdf_link("base_link", arm)]
    parent = "base_link"
    axes = ("0 0 1", "0 1 0", "1 0 0")
    for i, kind in enumerate(arm.joints):
        if arm.fixed_between[i]:
            parts += [_urdf_link(f"flange{i}", arm, inertial=False),
                      f'<joint name="fix{i}" type="fixed"><parent link="{parent}"/><child link="flange{i}"/>'
                      '<origin xyz="0 0 0.05" rpy="0 0 0.3"/></joint>']
            parent = f"flange{i}"
        link = f"link{i}"
        parts.append(_urdf_link(link, arm, inertial=not (arm.defect == "no-inertial" and i == 2)))
        limit = ""
        if kind == "revolute" or arm.efforts:
            bounds = 'lower="-2.5" upper="2.5" ' if kind == "revolute" else ""
            effort = 'effort="90" ' if arm.efforts else ""
            limit = f'<limit {bounds}{effort}velocity="2"/>'
        parts.append(f'<joint name="joint{i}" type="{kind}"><parent link="{parent}"/><child link="{link}"/>'
                     f'<origin xyz="0 0 0.2" rpy="{0.2 * i:.2f} 0 0"/><axis xyz="{axes[i % 3]}"/>{limit}</joint>')
        parent = link
    if arm.gripper == "mimic":
        for k in range(2):
            parts.append(_urdf_link(f"finger{k}", arm))
            mimic = '<mimic joint="finger_joint0" multiplier="1" offset="0"/>' if k == 1 else ""
            parts.append(f'<joint name="finger_joint{k}" type="prismatic"><parent link="{parent}"/>'
                         f'<child link="finger{k}"/><origin xyz="0 {0.02 * (1 - 2 * k)} 0.1"/><axis xyz="0 1 0"/>'
                         f'<limit lower="0" upper="0.04" effort="20" velocity="0.2"/>{mimic}</joint>')
    if arm.transmission:
        parts += [f'<transmission name="t{i}"><type>transmission_interface/SimpleTransmission</type>'
                  f'<joint name="joint{i}"><hardwareInterface>hardware_interface/EffortJointInterface'
                  f'</hardwareInterface></joint><actuator name="motor{i}"><mechanicalReduction>100'
                  '</mechanicalReduction></actuator></transmission>' for i in range(len(arm.joints))]
    parts.append("</robot>")
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "vendor_arm.urdf"
    path.write_text("".join(parts))
    return path
