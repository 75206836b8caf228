"""The arm's drive train and the payload it is rated for: what makes the simulated arm a real one.

Each joint is a two-mass system (Spong's reduced model of a flexible joint): the rotor, its
inertia reflected through the gear (J_m N^2) with the joint's friction (a motor-current
calibration measures it on the motor side), drives the link through a torsional spring and damper,
the strain-wave gear. The motor encoder reads the rotor, the joint encoder the link. The
controller's nominal model stays rigid (arm.xml, rotor inertia as armature): the flexibility is
part of the uncertainty w it has to reject.

Per joint, the arm file's [drivetrain] table gives the gear size, stiffness, damping and rotor
inertia; what it leaves out comes from a preset:
- size: the smallest Harmonic Drive cup-type size whose limit for repeated peak torque (ratio
  100) holds the joint's torque limit (the largest size for a joint beyond it);
- stiffness: that size's catalogue spring constant K2, the slope between T1 and T2, where a
  joint carrying its own links works; the robust tuning's 80 % and 120 % span K1 to K3;
- damping: DAMPING_RATIO of the joint's two-mass mode at home (no catalogue gives one);
- rotor inertia: the model's armature. A joint without one has no rotor to make a two-mass
  system of, and is simulated rigid, saying so (give rotor_inertia to make it flexible).
A joint whose mode the simulation step cannot resolve (omega dt above MAX_OMEGA_DT at the highest
stiffness scale the simulator takes) is simulated rigid too, and arm.json says why: such a mode
lies far above the loop's bandwidth and its Nyquist frequency.

`plant_xml` makes the simulator's true arm from the prepared rigid arm.xml: per flexible joint a
rotor body hung from the world (its hinge carries the rotor inertia and the joint's friction), a
fixed tendon rotor - link with the gear's stiffness and damping, and the joint's motor moved onto
the rotor. `resonances` gives each joint's first resonance at home, motor locked and free.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from gen.lib import mjcf_defaults
from gen.lib.params import param
from gen.lib.paths import BUNDLED_DRIVETRAIN


@dataclass(frozen=True)
class GearSize:
    size: int
    peak_nm: float                        # limit for repeated peak torque, ratio 100
    k: tuple[float, float, float]         # K1, K2, K3 (N m/rad), ratio above 50


# Harmonic Drive AG, "CHA Series engineering data", doc. 1018854 12/2015, section 3.3.5, tables
# 50.3/50.4 (the cup-type CSF/HFUC gear of those actuators; K in 1e3 N m/rad, ratio > 50).
# Repeated peak torque at ratio 100: HFUC-2A sizes 14-25 (28, 54, 82, 157 N m); sizes 32 and 40
# from their rated torque at 2000 rpm (178, 345 N m, Harmonic Drive SHG/SHF-2UH-LW rating table)
# times 1.8, the ratio of peak to rated of size 25 (157 / 87): derived, not printed.
HARMONIC_SIZES = (
    GearSize(14, 28.0, (4.7e3, 6.1e3, 7.1e3)),
    GearSize(17, 54.0, (1.0e4, 1.4e4, 1.6e4)),
    GearSize(20, 82.0, (1.6e4, 2.5e4, 2.9e4)),
    GearSize(25, 157.0, (3.1e4, 5.0e4, 5.7e4)),
    GearSize(32, 320.0, (6.7e4, 1.1e5, 1.2e5)),
    GearSize(40, 621.0, (1.3e5, 2.0e5, 2.3e5)),
)
SIZES = {g.size: g for g in HARMONIC_SIZES}
# No catalogue gives a strain-wave gear's damping; 0.05-0.2 is the range flexible-joint models
# assume. 0.1: the middle of it, an assumption the report states.
DAMPING_RATIO = 0.1
# The step resolves a mode to within 5 % of its frequency at omega dt = 1 (semi-implicit Euler:
# 2 asin(omega dt / 2) / dt); stable up to 2.
MAX_OMEGA_DT = 1.0
PAYLOAD_SITE = "payload"   # the flange site the simulator hangs the payload on (arm.xml)
FLANGE_HINTS = ("flange", "tool", "tcp", "attachment", "ee", "end_effector", "eef", "gripper", "hand")
ROTOR_PREFIX, GEAR_PREFIX = "rotor_", "gear_"
PLANT_KINDS = ("joint", "tendon", "actuator", "site")  # the kinds of element plant_xml adds or moves
# the rotor's body: its inertia is the hinge's armature; MuJoCo wants a moving body to have some mass
ROTOR_BODY_MASS, ROTOR_BODY_INERTIA = 1e-3, 1e-9
DRIVETRAIN_FIELDS = {"size", "stiffness", "damping", "damping_ratio", "rotor_inertia"}


class DrivetrainError(ValueError):
    """The arm file's drive train cannot be used; the message names the field and the joint."""


def stiffness_scale_max() -> float:
    """The highest gear stiffness scale the simulator takes (the registry's): the plant must
    resolve every flexible joint's mode up to it."""
    return float(param("simulator", "gear-stiffness-scale").max)


def size_for(torque_limit: float) -> GearSize:
    """The smallest size whose repeated peak torque holds the joint's torque limit."""
    for g in HARMONIC_SIZES:
        if g.peak_nm >= torque_limit:
            return g
    return HARMONIC_SIZES[-1]


def _per_joint(v: Any, names: list[str], where: str, positive: bool = True) -> list[float | None]:
    """A per-joint value: a list in joint order, or a table by joint name (missing: None)."""
    if isinstance(v, list):
        if len(v) != len(names):
            raise DrivetrainError(f"{where}: {len(v)} values for {len(names)} joints ({', '.join(names)})")
        items = list(zip(names, v))
    elif isinstance(v, dict):
        unknown = [k for k in v if k not in names]
        if unknown:
            raise DrivetrainError(f"{where}: '{unknown[0]}' is not a controlled joint ({', '.join(names)})")
        items = [(k, v.get(k)) for k in names]
    else:
        raise DrivetrainError(f"{where}: one value per joint (a list, or a table by joint name), got {v!r}")
    out: list[float | None] = []
    for name, x in items:
        if x is None:
            out.append(None)
            continue
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) or (
                x <= 0 if positive else x < 0):
            raise DrivetrainError(f"{where}.{name}: must be a number {'> 0' if positive else '>= 0'}, got {x!r}")
        out.append(float(x))
    return out


def check_table(table: Any, where: str) -> dict[str, Any]:
    """The arm file's [drivetrain] table, its fields known (values are checked per joint later)."""
    if not isinstance(table, dict):
        raise DrivetrainError(f"{where}: expected a table of {', '.join(sorted(DRIVETRAIN_FIELDS))}")
    unknown = set(table) - DRIVETRAIN_FIELDS
    if unknown:
        raise DrivetrainError(f"{where}: unknown field(s) {sorted(unknown)} (known: {', '.join(sorted(DRIVETRAIN_FIELDS))})")
    return dict(table)


def _link_inertia(m: mujoco.MjModel, home: list[float]) -> np.ndarray:
    """Each joint's link-side inertia at home, the other joints held: M_jj without the armature."""
    d = mujoco.MjData(m)
    d.qpos[:len(home)] = home
    mujoco.mj_forward(m, d)
    mass = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, mass)
    return np.diag(mass) - m.dof_armature


def resolve(table: dict[str, Any] | None, where: str, m: mujoco.MjModel, names: list[str], home: list[float],
            torque_limits: list[float], dt: float) -> list[dict[str, Any]]:
    """Each joint's drive train: size, stiffness, damping, rotor inertia, whether the simulator
    makes it flexible (and why not), and its first resonance at home. m: the prepared rigid arm."""
    t = table or {}
    n = len(names)
    sizes = [None] * n if "size" not in t else _per_joint(t["size"], names, f"{where}.size")
    for name, s in zip(names, sizes):
        if s is not None and int(s) not in SIZES:
            raise DrivetrainError(f"{where}.size.{name}: {s:g} is not a size of the preset "
                                  f"({', '.join(str(g.size) for g in HARMONIC_SIZES)})")
    given = {k: ([None] * n if k not in t else _per_joint(t[k], names, f"{where}.{k}", positive=k != "damping"))
             for k in ("stiffness", "damping", "rotor_inertia")}
    ratio = t.get("damping_ratio", DAMPING_RATIO)
    if isinstance(ratio, bool) or not isinstance(ratio, (int, float)) or not 0 < ratio <= 2:
        raise DrivetrainError(f"{where}.damping_ratio: a number in (0, 2], got {ratio!r}")
    link = _link_inertia(m, home)
    kmax = stiffness_scale_max()
    out = []
    for j, name in enumerate(names):
        gear = SIZES[int(sizes[j])] if sizes[j] is not None else size_for(torque_limits[j])
        k = given["stiffness"][j] or gear.k[1]
        rotor = float(m.dof_armature[j])  # the arm file's rotor_inertia is the armature already (set_rotor_inertia)
        jl = float(link[j])
        # the two-mass mode: the link and the rotor on the gear's spring (the reduced inertia)
        reduced = jl * rotor / (jl + rotor) if rotor > 0 else jl
        damping = given["damping"][j] if given["damping"][j] is not None else 2.0 * ratio * math.sqrt(k * reduced)
        locked = math.sqrt(k / jl)
        free = math.sqrt(k * (1.0 / jl + 1.0 / rotor)) if rotor > 0 else None
        why_rigid = None
        if rotor <= 0:
            why_rigid = "no rotor inertia (the model has no armature; give drivetrain.rotor_inertia)"
        elif math.sqrt(kmax) * free * dt > MAX_OMEGA_DT:
            why_rigid = (f"its mode ({math.sqrt(kmax) * free / (2 * math.pi):.0f} Hz at {kmax:g} x stiffness) is beyond "
                         f"what the {dt * 1e3:g} ms step resolves ({MAX_OMEGA_DT / dt / (2 * math.pi):.0f} Hz)")
        out.append({
            "name": name, "size": gear.size, "size_from": "arm file" if sizes[j] is not None else
            f"preset: the smallest whose repeated peak torque ({gear.peak_nm:g} N m) holds {torque_limits[j]:g} N m",
            "stiffness": k, "stiffness_from": "arm file" if given["stiffness"][j] else f"preset: size {gear.size}'s K2",
            "damping": damping, "damping_from": "arm file" if given["damping"][j] is not None else
            f"damping ratio {ratio:g} of the two-mass mode at home",
            "rotor_inertia": rotor, "rotor_inertia_from": "arm file" if given["rotor_inertia"][j] else "the model's armature",
            "link_inertia_at_home": jl,
            "resonance_locked_hz": locked / (2 * math.pi),
            "resonance_free_hz": free / (2 * math.pi) if free is not None else None,
            "flexible": why_rigid is None, "rigid_because": why_rigid,
        })
    return out


def set_rotor_inertia(spec: mujoco.MjSpec, table: dict[str, Any] | None, names: list[str], where: str) -> None:
    """The arm file's rotor inertias as the joints' armature: the nominal model knows the motor's
    datasheet, as the firmware's model of a user's arm would."""
    if table and "rotor_inertia" in table:
        for name, v in zip(names, _per_joint(table["rotor_inertia"], names, f"{where}.rotor_inertia")):
            if v is not None:
                spec.joint(name).armature = v


def first_resonance_hz(drivetrain: list[dict[str, Any]]) -> float:
    """The arm's lowest joint resonance at home (motor locked), over every joint."""
    return min(j["resonance_locked_hz"] for j in drivetrain)


def _unique(taken: set[str], name: str) -> str:
    out, k = name, 1
    while out in taken:
        k += 1
        out = f"{name}_{k}"
    taken.add(out)
    return out


def plant_xml(arm_xml: str, drivetrain: list[dict[str, Any]]) -> str:
    """The simulator's true arm: arm.xml with every flexible joint made a two-mass system (the
    module's docstring). The link joints keep their order and come first (qpos 0..n-1)."""
    spec = mujoco.MjSpec.from_string(arm_xml)
    # the rotors, their joints, the gears' tendons and the moved motors take nothing from the
    # model's classes (a joint class's range or a tendon class's friction): MuJoCo's own defaults
    classes = mjcf_defaults.default_classes(spec, mjcf_defaults.class_names_in(ET.fromstring(arm_xml)))
    mjcf_defaults.reset_to_builtin(classes, PLANT_KINDS)
    taken = {kind: {e.name for e in elems} for kind, elems in
             (("body", spec.bodies), ("joint", spec.joints), ("tendon", spec.tendons))}
    acts = {a.target: a for a in spec.actuators}
    rotors = []
    for j in drivetrain:
        if not j["flexible"]:
            continue
        link = spec.joint(j["name"])
        body = spec.worldbody.add_body(name=_unique(taken["body"], ROTOR_PREFIX + j["name"]))
        body.explicitinertial = True
        body.mass, body.inertia, body.ipos, body.iquat = ROTOR_BODY_MASS, [ROTOR_BODY_INERTIA] * 3, [0, 0, 0], [1, 0, 0, 0]
        body.fullinertia = [math.nan, 0, 0, 0, 0, 0]  # unset: inertia and iquat are the ones
        # the rotor carries the link joint's drive-side properties; nothing else (no range, no spring)
        rotor = body.add_joint(name=_unique(taken["joint"], ROTOR_PREFIX + j["name"]), type=mujoco.mjtJoint.mjJNT_HINGE,
                               axis=[0, 0, 1], armature=j["rotor_inertia"], damping=link.damping,
                               frictionloss=link.frictionloss, actfrclimited=link.actfrclimited,
                               actfrcrange=link.actfrcrange)
        link.armature = link.frictionloss = 0.0
        link.damping = [0.0, 0.0, 0.0]
        link.actfrclimited = mujoco.mjtLimited.mjLIMITED_FALSE
        tendon = spec.add_tendon(name=_unique(taken["tendon"], GEAR_PREFIX + j["name"]), stiffness=[j["stiffness"], 0.0, 0.0],
                                 damping=[j["damping"], 0.0, 0.0], springlength=[0.0, 0.0])
        tendon.wrap_joint(rotor.name, 1.0)
        tendon.wrap_joint(link.name, -1.0)
        acts[j["name"]].target = rotor.name
        rotors.append(j["name"])
    rigid = mujoco.MjModel.from_xml_string(arm_xml)  # its keyframes in full (the file may leave qpos0 out)
    names = [j["name"] for j in drivetrain]
    for k, key in enumerate(spec.keys):  # the rotors start where their links are; the simulator adds the wind-up
        qpos = [float(x) for x in rigid.key_qpos[k]]
        key.qpos = qpos + [qpos[names.index(r)] for r in rotors]
    return spec.to_xml()


def flange_site(m: mujoco.MjModel, last_body: int, named: str | None) -> tuple[int, np.ndarray, str]:
    """Where the payload hangs: (body, position in its frame, why). The arm file's `flange` site;
    else a site on the last link whose name says flange/tool/...; else the last link's origin."""
    if named is not None:
        s = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, named)
        if s < 0:
            raise DrivetrainError(f"flange: no site '{named}' in the model")
        return int(m.site_bodyid[s]), m.site_pos[s].copy(), f"site '{named}' (arm file)"
    for s in range(m.nsite):
        name = (mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, s) or "").lower()
        if int(m.site_bodyid[s]) == last_body and any(h in name for h in FLANGE_HINTS):
            return last_body, m.site_pos[s].copy(), f"site '{name}' on the last link"
    return last_body, np.zeros(3), "the last link's origin (no flange site: give one in the arm file, flange = NAME)"


def load_bundled() -> tuple[dict[str, Any], float]:
    """The bundled arm's drive train table and rated payload (host_sim/models/ur5e_arm_drivetrain.toml)."""
    import tomllib

    doc = tomllib.loads(Path(BUNDLED_DRIVETRAIN).read_text())
    return check_table(doc["drivetrain"], str(BUNDLED_DRIVETRAIN)), float(doc["rated_payload_kg"])
