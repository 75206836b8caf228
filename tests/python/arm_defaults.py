"""MJCF arms whose elements get their values from default classes (for the hypothesis test of the
importer, tests/python/test_arm_defaults.py): `main` and up to three named classes, nested, each
with a random mix of attributes over every kind of element the importer reads or writes (joints,
geoms, sites, tendons, every actuator shortcut, cameras, lights, materials, meshes, equalities),
used by `class` on the elements and `childclass` on the bodies. Whatever the classes say, MuJoCo
compiles the arm; the importer must keep what they give the arm's own elements and nothing of them
may reach the elements it adds.

A drawn arm is a plain description (dataclasses of choices) and a writer that turns it into a file,
so a failing example prints what it was made of."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from hypothesis import strategies as st

# (kind, the tag in a <default>, attribute, value): every value one MuJoCo compiles on any element of
# the kind here. Angles are in radians (written in degrees when the arm's compiler says so).
ATTRIBUTES = (
    ("joint", "joint", "armature", "0.3"), ("joint", "joint", "armature", "0.02"),
    ("joint", "joint", "damping", "0.5"), ("joint", "joint", "frictionloss", "0.2"),
    ("joint", "joint", "stiffness", "2"), ("joint", "joint", "springref", "@0.3"), ("joint", "joint", "ref", "@0.2"),
    ("joint", "joint", "range", "@-1.5 1.5"), ("joint", "joint", "limited", "false"), ("joint", "joint", "margin", "0.01"),
    ("joint", "joint", "actuatorfrcrange", "-60 60"), ("joint", "joint", "group", "2"),
    ("geom", "geom", "density", "2500"), ("geom", "geom", "mass", "0.7"), ("geom", "geom", "type", "box"),
    ("geom", "geom", "type", "capsule"), ("geom", "geom", "group", "3"), ("geom", "geom", "contype", "0"),
    ("geom", "geom", "material", "dark"), ("geom", "geom", "rgba", "0.2 0.2 0.2 1"), ("geom", "geom", "friction", "0.5"),
    ("site", "site", "type", "box"), ("site", "site", "size", "0.02 0.02 0.02"), ("site", "site", "material", "reference_site"),
    ("site", "site", "group", "4"), ("site", "site", "rgba", "1 0 0 0.5"),
    ("tendon", "tendon", "stiffness", "50"), ("tendon", "tendon", "damping", "2"), ("tendon", "tendon", "frictionloss", "1"),
    ("tendon", "tendon", "range", "-0.5 0.5"), ("tendon", "tendon", "armature", "0.1"),
    ("tendon", "tendon", "margin", "0.02"), ("tendon", "tendon", "width", "0.01"), ("tendon", "tendon", "material", "grid"),
    ("tendon", "tendon", "actuatorfrcrange", "-5 5"),
    # actuators: a stiff position servo (issue 50), a filter, gains and gears, limits, actuator armature
    ("actuator", "general", "biastype", "affine"), ("actuator", "general", "gainprm", "2000"),
    ("actuator", "general", "biasprm", "0 -2000 -100"), ("actuator", "general", "dyntype", "filter"),
    ("actuator", "general", "dynprm", "0.05"), ("actuator", "general", "gear", "50"),
    ("actuator", "general", "ctrlrange", "-3 3"), ("actuator", "general", "ctrllimited", "true"),
    ("actuator", "general", "forcerange", "-70 70"), ("actuator", "general", "forcelimited", "true"),
    ("actuator", "general", "armature", "0.2"), ("actuator", "general", "damping", "1"),
    ("actuator", "motor", "gear", "2"), ("actuator", "motor", "ctrlrange", "-40 40"),
    ("actuator", "position", "kp", "300"), ("actuator", "position", "kv", "10"),
    ("actuator", "velocity", "kv", "20"),
    ("camera", "camera", "fovy", "60"), ("light", "light", "diffuse", "0.5 0.5 0.5"),
    ("material", "material", "rgba", "0 1 0 1"), ("mesh", "mesh", "scale", "0.8 0.8 1.2"),
    ("equality", "equality", "solref", "0.01 1"),
)
ACTUATORS = ("none", "general", "motor", "position", "velocity")
MASS_FROM = ("inertial", "geoms", "mesh")


@dataclass
class Klass:
    name: str                 # "main" or c0, c1, ...
    parent: int | None        # index of the class it is nested in (None: main itself)
    attrs: list[int]          # indices into ATTRIBUTES (one value per (tag, attribute): the last wins)


@dataclass
class Link:
    axis: str
    mass_from: str
    joint_class: int | None   # index into classes, None: the body's (or main)
    childclass: int | None    # the body's childclass
    geom_class: int | None
    site_class: int | None    # a site on the link (-1: none)
    camera: bool
    light: bool


@dataclass
class DefaultsArm:
    classes: list[Klass]
    links: list[Link]
    angle: str
    actuators: str
    actuator_class: int | None
    tendon: bool
    tendon_class: int | None
    fingers: bool             # two finger hinges beyond the last link (a branch: locked), coupled by an equality
    eq_class: int | None
    keyframe: bool
    home: list[float] = field(default_factory=list)

    @property
    def joints(self) -> list[str]:
        return [f"j{i}" for i in range(len(self.links))]


def _class(draw: st.DrawFn, n: int) -> int | None:
    return draw(st.one_of(st.none(), st.integers(0, n - 1)))


@st.composite
def defaults_arms(draw: st.DrawFn) -> DefaultsArm:
    nclass = draw(st.integers(1, 4))  # main and up to three named classes
    pick = st.lists(st.integers(0, len(ATTRIBUTES) - 1), max_size=12)
    classes = [Klass("main", None, draw(pick))]
    for k in range(1, nclass):
        classes.append(Klass(f"c{k - 1}", draw(st.integers(0, k - 1)), draw(pick)))
    n = draw(st.integers(3, 5))
    links = [Link(axis="0 0 1" if i == 0 else draw(st.sampled_from(("0 1 0", "1 0 0", "0 1 1"))),
                  mass_from=draw(st.sampled_from(MASS_FROM)), joint_class=_class(draw, nclass),
                  childclass=_class(draw, nclass), geom_class=_class(draw, nclass),
                  site_class=draw(st.one_of(st.just(-1), st.none(), st.integers(0, nclass - 1))),
                  camera=draw(st.booleans()), light=draw(st.booleans()))
             for i in range(n)]
    arm = DefaultsArm(classes, links, angle=draw(st.sampled_from(("radian", "degree"))),
                      actuators=draw(st.sampled_from(ACTUATORS)), actuator_class=_class(draw, nclass),
                      tendon=draw(st.booleans()), tendon_class=_class(draw, nclass), fingers=draw(st.booleans()),
                      eq_class=_class(draw, nclass), keyframe=draw(st.booleans()))
    arm.home = [round(draw(st.floats(-0.4, 0.4)), 3) for _ in links]
    return arm


def _value(arm: DefaultsArm, value: str) -> str:
    """A value as the file writes it: '@' marks angles, in degrees when the compiler says so."""
    if not value.startswith("@"):
        return value
    rad = [float(x) for x in value[1:].split()]
    return " ".join(f"{math.degrees(x):.8g}" if arm.angle == "degree" else f"{x:.8g}" for x in rad)


def _default(arm: DefaultsArm, k: int) -> str:
    """One <default> element with its nested classes."""
    klass = arm.classes[k]
    by_tag: dict[str, dict[str, str]] = {}
    for a in klass.attrs:
        _, tag, attr, value = ATTRIBUTES[a]
        by_tag.setdefault(tag, {})[attr] = _value(arm, value)
    inner = "".join(f"<{tag} " + " ".join(f'{attr}="{v}"' for attr, v in attrs.items()) + "/>"
                    for tag, attrs in by_tag.items())
    inner += "".join(_default(arm, c) for c in range(len(arm.classes)) if arm.classes[c].parent == k)
    head = "<default>" if k == 0 else f'<default class="{klass.name}">'
    return f"{head}{inner}</default>"


def _cls(arm: DefaultsArm, k: int | None, attr: str = "class") -> str:
    return f' {attr}="{arm.classes[k].name}"' if k is not None else ""


def _mass(arm: DefaultsArm, link: Link, i: int) -> str:
    if link.mass_from == "inertial":
        return '<inertial pos="0 0 0.1" mass="1.2" diaginertia="0.012 0.012 0.008"/>'
    if link.mass_from == "geoms":  # sizes any geom type takes: a sphere, a capsule or a box
        return (f'<geom pos="0 0 0.1" size="0.04 0.08 0.03"{_cls(arm, link.geom_class)}/>'
                f'<geom type="sphere" pos="0 0 0.18" size="0.03"{_cls(arm, link.geom_class)}/>')
    return f'<geom type="mesh" mesh="block{i}"{_cls(arm, link.geom_class)}/>'  # a mesh's class scales it


def _body(arm: DefaultsArm, i: int, inner: str) -> str:
    link = arm.links[i]
    extras = ""
    if link.site_class != -1:
        extras += f'<site name="s{i}" pos="0 0 0.1"{_cls(arm, link.site_class)}/>'
    if i == len(arm.links) - 1:
        extras += '<site name="tool" pos="0 0 0.2"/>'
    if link.camera:
        extras += f'<camera name="cam{i}" pos="0.2 0 0.1"/>'
    if link.light:
        extras += f'<light name="light{i}" pos="0 0 0.5" dir="0 0 -1"/>'
    pos = "0 0 0.05" if i == 0 else "0 0 0.2"
    return (f'<body name="l{i}" pos="{pos}"{_cls(arm, link.childclass, "childclass")}>'
            f'<joint name="j{i}" axis="{link.axis}"{_cls(arm, link.joint_class)}/>{_mass(arm, link, i)}{extras}'
            f'{inner}</body>')


def _fingers(arm: DefaultsArm) -> str:
    if not arm.fingers:
        return ""
    inertial = '<inertial pos="0 0 0.02" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/>'
    return "".join(f'<body name="finger{k}" pos="0 {0.02 * (1 - 2 * k)} 0.2"><joint name="finger{k}" axis="1 0 0"/>'
                   f'{inertial}</body>' for k in range(2))


def _actuators(arm: DefaultsArm) -> str:
    if arm.actuators == "none":
        return ""
    limits = {"general": 'ctrlrange="-1 1" ctrllimited="true" forcerange="-80 80" gear="80"',
              "motor": 'ctrlrange="-80 80" ctrllimited="true" forcerange="-80 80"',
              "position": 'ctrlrange="-3 3" ctrllimited="true" forcerange="-80 80" forcelimited="true"',
              "velocity": 'ctrlrange="-3 3" ctrllimited="true" forcerange="-80 80" forcelimited="true"'}[arm.actuators]
    acts = "".join(f'<{arm.actuators} name="a{i}" joint="{j}" {limits}{_cls(arm, arm.actuator_class)}/>'
                   for i, j in enumerate(arm.joints))
    if arm.fingers:  # a gripper's actuator, of whatever the classes make it
        acts += f'<general name="grip" joint="finger0" ctrlrange="-1 1" forcerange="-1 1"{_cls(arm, arm.actuator_class)}/>'
    return f"<actuator>{acts}</actuator>"


def write_arm(arm: DefaultsArm, folder: Path) -> Path:
    inner = _fingers(arm)
    for i in reversed(range(len(arm.links))):
        inner = _body(arm, i, inner)
    meshes = "".join(f'<mesh name="block{i}" vertex="-0.03 -0.03 0  0.03 -0.03 0  0.03 0.03 0  -0.03 0.03 0  '
                     f'-0.03 -0.03 0.2  0.03 -0.03 0.2  0.03 0.03 0.2  -0.03 0.03 0.2"/>'
                     for i, link in enumerate(arm.links) if link.mass_from == "mesh")
    assets = ('<asset><texture name="grid" type="2d" builtin="checker" rgb1="0.1 0.2 0.3" rgb2="0.2 0.3 0.4" '
              'width="32" height="32"/><material name="grid" texture="grid"/>'
              '<material name="reference_site" rgba="1 0 0 0.5"/><material name="dark" rgba="0.1 0.1 0.1 1"/>'
              f'{meshes}</asset>')
    tendon = ""
    if arm.tendon:
        tendon = (f'<tendon><fixed name="couple"{_cls(arm, arm.tendon_class)}><joint joint="j0" coef="1"/>'
                  f'<joint joint="j1" coef="-1"/></fixed></tendon>')
    eq = ""
    if arm.fingers:
        eq = f'<equality><joint joint1="finger0" joint2="finger1"{_cls(arm, arm.eq_class)}/></equality>'
    key = ""
    if arm.keyframe:
        qpos = arm.home + ([0.0, 0.0] if arm.fingers else [])
        key = f'<keyframe><key name="home" qpos="{" ".join(f"{q:.6g}" for q in qpos)}"/></keyframe>'
    text = (f'<mujoco model="defaults_arm"><compiler angle="{arm.angle}" autolimits="true"/>{_default(arm, 0)}{assets}'
            '<worldbody><light name="sun" pos="0 0 3" dir="0 0 -1"/><body name="base" pos="0 0 0.1">'
            f'<inertial pos="0 0 0" mass="3" diaginertia="0.02 0.02 0.02"/>{inner}</body></worldbody>'
            f'{_actuators(arm)}{tendon}{eq}{key}</mujoco>')
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "arm.xml"
    path.write_text(text)
    return path
