"""The arm: a user's model (MJCF or URDF, optionally with an arm file) made into the one model
that the generator, the firmware, the simulator and the study all use.

`python -m gen.arm --model M [--arm-file F] --design CONFIG --out DIR [--depfile F]` writes into DIR:

- arm.xml: the prepared MJCF. The controlled joints are hinges of one serial chain, every other
  joint is locked (removed, its body fixed at the locked value), fixed bodies are fused into their
  link, every body's mass and inertia is explicit (geometry and meshes are dropped unless the arm
  file keeps contacts), the model's own actuators, sensors, tendons, equalities and keyframes are
  replaced by one motor per controlled joint (gear 1, ctrlrange = the torque limit) and a keyframe
  "home", and the timestep is the loop period (or an integer fraction of it).
- arm.json: what the rest of the project reads: the joints (limits, ranges, armature, damping,
  friction, home), the locked joints, the timestep and substeps, the bus wiring, the default
  reference, the policies and every warning, and the model hash (FNV-1a 64 of arm.xml).
- design.toml: the design config with the model's joint count.

Errors name the element and say what to change (exit 2); nothing is written then.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import re
import sys
import tomllib
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from gen import drivetrain
from gen.lib import toml_input
from gen.lib.bounds import DEFAULT_MAX_ERROR_DEG
from gen.lib.params import constant
from gen.lib.atomic_output import OutputError, write_files_atomically

REPO = Path(__file__).resolve().parent.parent
DEFAULT_MODEL = REPO / "host_sim" / "models" / "ur5e_arm.xml"
DEFAULT_DESIGN = REPO / "gen" / "configs" / "paper.toml"
DEFAULT_TOPOLOGY = REPO / "firmware" / "protocol" / "buses.toml"

MIN_JOINT_INERTIA = 1e-7   # kg m^2: a joint that moves less than this cannot be controlled
LIGHT_LINK_KG = 1e-6       # a link lighter than this (its children may still be heavy): a warning
RANGE_MARGIN = 0.05        # rad: the reference and the home pose stay this far inside joint ranges
# A reference every arm can follow: along it, each joint's inverse-dynamics torque (rigid bodies,
# armature, damping, the model's frictionloss and any friction a scenario adds) stays within this
# fraction of its torque limit, the rest left to the controller; its speed and acceleration within
# these (the speed: half the safety layer's 2 pi rad/s stop). Amplitudes are scaled down per joint
# until it fits (fit_reference).
REF_TORQUE_FRACTION = 0.5
REF_MAX_VELOCITY = math.pi       # rad/s
REF_MAX_ACCELERATION = 20.0      # rad/s^2
BUS_BUDGET: float = constant("bus-budget")  # the highest bus load the wiring may reach (the registry's)
# The design of an arm that names none (no --design, none in its arm file), other than the bundled
# arm: the paper's estimator with a critically damped static controller u_o = -(wn^2 e + 2 wn e_dot)
# (gen/configs/wn40.toml's form), wn the largest at which a tracking error at the bound asks no
# joint at home for more than the torque the reference leaves it ((1 - REF_TORQUE_FRACTION) of its
# limit), within [AUTO_WN_MIN, AUTO_WN_MAX] rad/s (the top: tracked by the 1 kHz loop in every arm
# tested). The paper's own weights make a 4.5 rad/s loop, which leaves light wrists 20-27 deg behind.
AUTO_WN_MIN, AUTO_WN_MAX = 5.0, 40.0
MAX_JOINTS = 16            # the firmware's bound (arm/robot_model.h); the DBC's drive slots bound it too
MAX_NESTING = 256          # XML elements, and bodies below the world: deeper is no arm, and walks would recurse
FLOAT32_MAX = float(np.finfo(np.float32).max)  # the firmware computes in float32: every number it takes fits

ARM_FILE_FIELDS = {"name", "model", "joints", "locked", "home", "keyframe", "torque_limits", "buses",
                   "topology", "design", "contacts", "timestep", "drives", "drivetrain", "rated_payload_kg", "flange"}


class ArmError(ValueError):
    """The model or the arm file cannot be used; the message names what and says what to change."""


@dataclass
class ArmFile:
    path: Path | None
    name: str | None  # None: the model's own name (or its file's)
    model: Path
    joints: list[str] | None = None
    locked: dict[str, float] = field(default_factory=dict)
    home: dict[str, float] | list[float] | None = None
    keyframe: str | None = None
    torque_limits: dict[str, float] = field(default_factory=dict)
    buses: list[dict[str, Any]] | None = None
    topology: Path | None = None
    design: Path | None = None
    contacts: bool = False
    timestep: str = "loop"
    drivetrain: dict[str, Any] | None = None  # gen/drivetrain.py: per joint size, stiffness, damping, rotor inertia
    rated_payload_kg: float = 0.0
    flange: str | None = None                 # the site the payload hangs on


def fnv1a64(data: bytes) -> int:
    """FNV-1a 64: the model hash the controller and the simulator compare at boot (arm_sim
    computes the same over the file it loads)."""
    h = 0xCBF29CE484222325
    for b in data:
        h = ((h ^ b) * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return h


def _number(v: Any, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ArmError(f"{where}: expected a number, got {v!r}")
    _float32(float(v), where)
    return float(v)


def _float32(v: float, where: str) -> None:
    if not (math.isfinite(v) and abs(v) <= FLOAT32_MAX):
        raise ArmError(f"{where}: {v:g} is not a finite float32 (|x| <= {FLOAT32_MAX:.3g}), which the firmware "
                       "computes in")


def _names(v: Any, where: str) -> list[str]:
    if not isinstance(v, list) or not v or not all(isinstance(x, str) and x for x in v):
        raise ArmError(f"{where}: expected a list of joint names, got {v!r}")
    if len(set(v)) != len(v):
        raise ArmError(f"{where}: a joint is named twice")
    return list(v)


def _table_of_numbers(v: Any, where: str) -> dict[str, float]:
    if not isinstance(v, dict):
        raise ArmError(f"{where}: expected a table of joint = number, got {v!r}")
    return {k: _number(x, f"{where}.{k}") for k, x in v.items()}


def load_arm_file(path: Path | None, model: Path | None = None) -> ArmFile:
    """The arm file (TOML) validated field by field, or the defaults for a bare model."""
    if path is None:
        if (model or DEFAULT_MODEL).resolve() == DEFAULT_MODEL.resolve():
            # the bundled arm: its drive train and rated payload are cited in a file of their own
            table, payload = drivetrain.load_bundled()
            return ArmFile(None, None, DEFAULT_MODEL, drivetrain=table, rated_payload_kg=payload)
        return ArmFile(None, None, model)
    try:
        doc = toml_input.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise ArmError(f"arm file {path}: cannot read it: {exc}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ArmError(f"arm file {path}: not TOML: {exc}") from exc
    unknown = set(doc) - ARM_FILE_FIELDS
    if unknown:
        raise ArmError(f"arm file {path}: unknown field(s) {', '.join(sorted(unknown))} "
                       f"(known: {', '.join(sorted(ARM_FILE_FIELDS))})")
    base = path.parent

    def rel(v: Any, where: str) -> Path:
        if not isinstance(v, str) or not v:
            raise ArmError(f"arm file {path}: {where}: expected a file path, got {v!r}")
        p = Path(v)
        return p if p.is_absolute() else (base / p).resolve()

    if "model" not in doc and model is None:
        raise ArmError(f"arm file {path}: model: missing (the MJCF or URDF file of the arm)")
    m = model or rel(doc["model"], "model")
    af = ArmFile(path, _slug(doc["name"]) if isinstance(doc.get("name"), str) else None, m)
    if "name" in doc and not isinstance(doc["name"], str):
        raise ArmError(f"arm file {path}: name: expected a string")
    if "joints" in doc:
        af.joints = _names(doc["joints"], f"arm file {path}: joints")
    if "locked" in doc:
        af.locked = _table_of_numbers(doc["locked"], f"arm file {path}: locked")
    if "home" in doc:
        h = doc["home"]
        if isinstance(h, list):
            af.home = [_number(x, f"arm file {path}: home[{i}]") for i, x in enumerate(h)]
        else:
            af.home = _table_of_numbers(h, f"arm file {path}: home")
    if "keyframe" in doc:
        if not isinstance(doc["keyframe"], str) or not doc["keyframe"]:
            raise ArmError(f"arm file {path}: keyframe: expected a keyframe name")
        af.keyframe = doc["keyframe"]
    if "torque_limits" in doc:
        af.torque_limits = _table_of_numbers(doc["torque_limits"], f"arm file {path}: torque_limits")
        bad = {k: v for k, v in af.torque_limits.items() if not v > 0}
        if bad:
            raise ArmError(f"arm file {path}: torque_limits: must be > 0 N m, got {bad}")
    if "buses" in doc and "topology" in doc:
        raise ArmError(f"arm file {path}: give buses or topology, not both")
    if "buses" in doc:
        if not isinstance(doc["buses"], list) or not all(isinstance(b, dict) for b in doc["buses"]):
            raise ArmError(f"arm file {path}: buses: expected [[buses]] tables (name, kind, nominal, data, drives)")
        af.buses = doc["buses"]
    if "topology" in doc:
        af.topology = rel(doc["topology"], "topology")
    if "design" in doc:
        af.design = rel(doc["design"], "design")
    if "drives" in doc:  # the CiA 402 drive configuration: read by gen/drives.py, checked here early
        drives = rel(doc["drives"], "drives")
        if not drives.is_file():
            raise ArmError(f"arm file {path}: drives: {drives} is not a file (the drive configuration, "
                           "like firmware/protocol/drives.toml)")
    if "contacts" in doc:
        if not isinstance(doc["contacts"], bool):
            raise ArmError(f"arm file {path}: contacts: expected true or false")
        af.contacts = doc["contacts"]
    if "timestep" in doc:
        if doc["timestep"] not in ("loop", "model"):
            raise ArmError(f"arm file {path}: timestep: expected \"loop\" (the loop period) or \"model\" "
                           f"(the model's own, an integer fraction of the period), got {doc['timestep']!r}")
        af.timestep = doc["timestep"]
    if "drivetrain" in doc:
        try:
            af.drivetrain = drivetrain.check_table(doc["drivetrain"], f"arm file {path}: drivetrain")
        except drivetrain.DrivetrainError as exc:
            raise ArmError(str(exc)) from exc
    if "rated_payload_kg" in doc:
        af.rated_payload_kg = _number(doc["rated_payload_kg"], f"arm file {path}: rated_payload_kg")
        if af.rated_payload_kg < 0:
            raise ArmError(f"arm file {path}: rated_payload_kg: must be >= 0 kg, got {af.rated_payload_kg:g}")
    if "flange" in doc:
        if not isinstance(doc["flange"], str) or not doc["flange"]:
            raise ArmError(f"arm file {path}: flange: expected the name of a site on the last link")
        af.flange = doc["flange"]
    return af


def _slug(text: str) -> str:
    s = re.sub(r"[^A-Za-z0-9_-]+", "-", text).strip("-").lower()
    return s[:40] or "arm"


GENERIC_STEMS = ("robot", "model", "arm")  # a file named so says less than its folder


def arm_name(af: ArmFile, spec: mujoco.MjSpec) -> str:
    """The arm's name in reports and build folders: the arm file's name, else the model's, else
    its file's stem (its folder's for robot.xml, model.xml, arm.xml)."""
    if af.name:
        return af.name
    if spec.modelname and spec.modelname != "MuJoCo Model":
        return _slug(spec.modelname)
    path = af.model.resolve()
    return _slug(path.parent.name if path.stem.lower() in GENERIC_STEMS and path.parent.name else path.stem)


@functools.lru_cache(maxsize=64)
def arm_name_of(arm_file: Path | None, model: Path | None) -> str:
    """arm_name() without preparing the arm (the model is parsed, not compiled): for the name of
    its build folder. An arm that cannot be read is named after its file (the import says why)."""
    try:
        af = load_arm_file(arm_file, model)
        return arm_name(af, _load_spec(af.model.resolve()))
    except ArmError:
        what = arm_file or model or DEFAULT_MODEL
        return _slug(what.stem)


# ---- the model --------------------------------------------------------------------------------
def _load_spec(path: Path) -> mujoco.MjSpec:
    if not path.is_file():
        raise ArmError(f"model {path}: no such file")
    if path.suffix.lower() not in (".xml", ".urdf", ".mjcf"):
        raise ArmError(f"model {path}: expected an MJCF (.xml) or URDF (.urdf) file")
    _check_raw(path, path, set())
    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except Exception as exc:  # noqa: BLE001 - MuJoCo's parser raises ValueError with its message
        raise ArmError(f"model {path}: MuJoCo cannot read it: {_one_line(exc)}") from exc
    _check_ranges(spec, path)
    return spec


def _one_line(exc: BaseException) -> str:
    return "; ".join(ln.strip() for ln in str(exc).splitlines() if ln.strip())


# Attributes that hold names or files, never numbers (a joint may be called "inf").
_TEXT_ATTRS = {"name", "class", "childclass", "file", "filename", "prefix", "model", "joint", "joint1", "joint2",
               "body", "body1", "body2", "site", "site1", "site2", "tendon", "tendon1", "tendon2", "actuator",
               "target", "mesh", "material", "texture", "hfield", "geom", "geom1", "geom2", "objname", "refname",
               "link", "plugin", "instance", "key", "meshdir", "texturedir", "assetdir"}


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


def _missing_asset_files(spec: mujoco.MjSpec, path: Path) -> list[str]:
    out = []
    for assets, sub in ((spec.meshes, spec.meshdir), (spec.textures, spec.texturedir), (spec.hfields, "")):
        for a in assets:
            if a.file and not (path.parent / (sub or "") / a.file).is_file():
                out.append(a.file)
    return out


def _check_depth(m: mujoco.MjModel, path: Path) -> None:
    depth = [0] * m.nbody
    for b in range(1, m.nbody):  # a parent's id is below its children's: one pass, no recursion
        depth[b] = depth[int(m.body_parentid[b])] + 1
        if depth[b] > MAX_NESTING:
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"
            raise ArmError(f"model {path}: body '{name}' hangs {depth[b]} bodies below the world, more than "
                           f"{MAX_NESTING}: no arm needs that many levels")


def _check_float32(m: mujoco.MjModel, path: Path, names: list[str], limits: list[tuple[float, str]],
                   home: list[float]) -> None:
    """Every number the firmware's model takes (gen/robot_model.py) fits in float32."""
    for b in range(1, m.nbody):
        body = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"
        for field_, vals in (("pos", m.body_pos[b]), ("quat", m.body_quat[b]), ("mass", [m.body_mass[b]]),
                             ("inertia", m.body_inertia[b]), ("ipos", m.body_ipos[b]), ("iquat", m.body_iquat[b])):
            for v in vals:
                _float32(float(v), f"model {path}: body '{body}': {field_}")
    for i, name in enumerate(names):
        where = f"model {path}: joint '{name}'"
        for field_, vals in (("pos", m.jnt_pos[i]), ("axis", m.jnt_axis[i]), ("armature", [m.dof_armature[i]]),
                             ("damping", [m.dof_damping[i]]), ("frictionloss", [m.dof_frictionloss[i]]),
                             ("range", m.jnt_range[i] if m.jnt_limited[i] else []), ("home", [home[i]])):
            for v in vals:
                _float32(float(v), f"{where}: {field_}")
        _float32(limits[i][0], f"{where}: torque limit (from {limits[i][1]})")


def _compile(spec: mujoco.MjSpec, path: Path, what: str) -> mujoco.MjModel:
    try:
        return spec.compile()
    except Exception as exc:  # noqa: BLE001
        msg = str(exc)
        hint = ""
        if "mass and inertia" in msg:
            hint = (": a moving body needs mass and inertia (give it an <inertial> or, in URDF, an "
                    "<inertial> element)")
        raise ArmError(f"model {path}: {what}: {_one_line(exc)}{hint}") from exc


def _strip_meshes(spec: mujoco.MjSpec) -> int:
    """Drops every mesh geom and mesh asset, and textures and skins (their files may be missing too),
    with every reference to them; the number of geoms dropped."""
    return _remove_assets(spec, {"mesh", "hfield", "texture", "skin"})


ASSET_KINDS = ("mesh", "hfield", "texture", "material", "skin")


def _remove_assets(spec: mujoco.MjSpec, kinds: set[str]) -> int:
    """Deletes every asset of the given kinds together with everything that refers to one, since
    MuJoCo refuses a model whose reference names a missing element (a site's `material=` once
    failed a Kinova Jaco with "material 'reference_site' not found"): the geoms drawn from a mesh
    or height field are deleted, a mesh site becomes a sphere, a texture leaves its materials, a
    material leaves the geoms, sites, skins, flexes and tendons that use it. The number of geoms
    deleted."""
    assert kinds <= set(ASSET_KINDS), kinds
    n = 0
    for g in list(spec.geoms):
        if ("mesh" in kinds and (g.type == mujoco.mjtGeom.mjGEOM_MESH or g.meshname)) or \
                ("hfield" in kinds and (g.type == mujoco.mjtGeom.mjGEOM_HFIELD or g.hfieldname)):
            spec.delete(g)
            n += 1
    if "mesh" in kinds:
        for s in spec.sites:
            if s.meshname or s.type == mujoco.mjtGeom.mjGEOM_MESH:
                s.meshname = ""
                s.type = mujoco.mjtGeom.mjGEOM_SPHERE
    if "texture" in kinds:
        for mat in spec.materials:
            mat.textures = [""] * len(mat.textures)
    if "material" in kinds:
        for e in [*spec.geoms, *spec.sites, *spec.skins, *spec.flexes, *spec.tendons]:
            e.material = ""
    lists = {"mesh": spec.meshes, "hfield": spec.hfields, "texture": spec.textures, "material": spec.materials,
             "skin": spec.skins}
    for kind in kinds:
        for a in list(lists[kind]):
            spec.delete(a)
    return n


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    out = np.zeros(4)
    mujoco.mju_mulQuat(out, a, b)
    return out


def _axis_quat(axis: np.ndarray, angle: float) -> np.ndarray:
    out = np.zeros(4)
    mujoco.mju_axisAngle2Quat(out, axis, angle)
    return out


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    out = np.zeros(3)
    mujoco.mju_rotVecQuat(out, v, q)
    return out


def _chain_default(m: mujoco.MjModel) -> list[int]:
    """Hinge joints of the main serial chain: from the base, follow the hinges while the rest of
    the tree below holds hinges in one branch only; a branch point (a hand with fingers) ends it."""
    hinge_bodies = {int(m.jnt_bodyid[j]): j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE}
    children: dict[int, list[int]] = {}
    for b in range(1, m.nbody):
        children.setdefault(int(m.body_parentid[b]), []).append(b)

    has_hinge = [b in hinge_bodies for b in range(m.nbody)]  # in its subtree
    for b in range(m.nbody - 1, 0, -1):  # children come after their parent: no recursion
        if has_hinge[b]:
            has_hinge[int(m.body_parentid[b])] = True

    chain: list[int] = []
    b = 0
    while True:
        nxt = [c for c in children.get(b, []) if has_hinge[c]]
        if len(nxt) != 1:
            return chain
        b = nxt[0]
        if b in hinge_bodies:
            chain.append(hinge_bodies[b])


def _dbc_drive_slots() -> int:
    from gen.drive_ids import drive_slots
    from gen.lib.busload import DEFAULT_DBC

    return len(drive_slots(DEFAULT_DBC)["STATE"])


def _joint_kind(t: int) -> str:
    return {int(mujoco.mjtJoint.mjJNT_HINGE): "hinge", int(mujoco.mjtJoint.mjJNT_BALL): "ball",
            int(mujoco.mjtJoint.mjJNT_SLIDE): "slide (prismatic)"}.get(t, "free")


def _joints_inside_chain(m: mujoco.MjModel, bodies: list[int], controlled: list[int]) -> list[int]:
    """Uncontrolled joints on the bodies from the base to the last controlled joint's body: locking
    one of those changes the arm itself (unlike a gripper's fingers beyond it), so only the arm
    file may do it."""
    on_path: set[int] = set()
    b = bodies[-1]
    while b != 0:
        on_path.add(b)
        b = int(m.body_parentid[b])
    return [j for j in range(m.njnt) if j not in controlled and int(m.jnt_bodyid[j]) in on_path]


def _joint_name(m: mujoco.MjModel, j: int) -> str:
    return mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint{j}"


def _torque_limit(m: mujoco.MjModel, j: int, override: float | None) -> tuple[float | None, str]:
    """The tightest of the joint's actuatorfrcrange and each actuator on it (motor or general:
    |gear| x |gain| x ctrlrange, |gear| x forcerange); the arm file's value replaces them all."""
    if override is not None:
        return override, "arm file"
    cands: list[tuple[float, str]] = []
    if m.jnt_actfrclimited[j]:
        cands.append((float(np.max(np.abs(m.jnt_actfrcrange[j]))), "joint actuatorfrcrange"))
    for a in range(m.nu):
        if m.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT or m.actuator_trnid[a, 0] != j:
            continue
        gear = abs(float(m.actuator_gear[a, 0]))
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a) or f"actuator{a}"
        plain = (m.actuator_gaintype[a] == mujoco.mjtGain.mjGAIN_FIXED
                 and m.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_NONE)
        if plain and m.actuator_ctrllimited[a]:
            cands.append((gear * abs(float(m.actuator_gainprm[a, 0])) * float(np.max(np.abs(m.actuator_ctrlrange[a]))),
                          f"actuator {name} ctrlrange x gear"))
        if m.actuator_forcelimited[a]:
            cands.append((gear * float(np.max(np.abs(m.actuator_forcerange[a]))), f"actuator {name} forcerange x gear"))
    cands = [c for c in cands if c[0] > 0]
    if not cands:
        return None, ""
    return min(cands)


@dataclass
class Prepared:
    xml: str
    info: dict[str, Any]
    design_text: str
    plant_xml: str  # the simulator's true arm, with its flexible joints (gen/drivetrain.py)


def prepare(af: ArmFile, design: Path | None) -> Prepared:  # noqa: C901 - one pass over the model, step by step
    """design: the design config asked for (--design); None for the arm's default: the paper's weights
    for the bundled arm, for any other arm one whose bandwidth fits it (auto_bandwidth)."""
    path = af.model.resolve()
    warnings: list[str] = []
    template = af.design or design or DEFAULT_DESIGN
    design_doc, design_text, rate = _design(template)
    period = 1.0 / rate

    spec = _load_spec(path)
    is_urdf = path.suffix.lower() == ".urdf"
    armname = arm_name(af, spec)
    try:
        spec.compile()
    except Exception as exc:  # noqa: BLE001
        msg = _one_line(exc)
        if "file" not in msg.lower() and "mesh" not in msg.lower():
            raise ArmError(f"model {path}: MuJoCo cannot compile it: {msg}") from exc
        missing = _missing_asset_files(spec, path)
        if not missing:  # the files are there: MuJoCo refuses one of them, and says which and why
            raise ArmError(f"model {path}: an asset MuJoCo cannot take (over its limits, or malformed): {msg}") from exc
        if af.contacts:
            raise ArmError(f"model {path}: {msg}; contacts = true needs the collision meshes") from exc
        n = _strip_meshes(spec)
        warnings.append(f"mesh files not found ({msg[:120]}): {n} mesh geoms dropped; the dynamics "
                        "come from the bodies' inertials")
    for i, b in enumerate(spec.bodies):
        if i > 0 and not b.name:
            b.name = f"body{i}"
    m0 = _compile(spec, path, "compiling it")
    _check_depth(m0, path)

    # ---- which joints ----
    free = [_joint_name(m0, j) for j in range(m0.njnt) if m0.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    if free:
        raise ArmError(f"model {path}: joint '{free[0]}' is a free joint (a floating base): this controller needs "
                       "a fixed base; remove the freejoint from the model")
    if af.joints is not None:
        controlled = []
        for name in af.joints:
            j = mujoco.mj_name2id(m0, mujoco.mjtObj.mjOBJ_JOINT, name)
            if j < 0:
                raise ArmError(f"arm file {af.path}: joints: no joint '{name}' in {path.name} "
                               f"(it has: {', '.join(_joint_name(m0, k) for k in range(m0.njnt))})")
            controlled.append(j)
    else:
        controlled = _chain_default(m0)
        if not controlled:
            raise ArmError(f"model {path}: no chain of hinge joints from the base (joints: "
                           f"{', '.join(_joint_name(m0, k) for k in range(m0.njnt)) or 'none'})")
    for j in controlled:
        t = m0.jnt_type[j]
        if t != mujoco.mjtJoint.mjJNT_HINGE:
            kind = _joint_kind(int(t))
            raise ArmError(f"model {path}: joint '{_joint_name(m0, j)}' is a {kind} joint: the firmware drives hinge "
                           "(revolute) joints only; lock it (arm file: leave it out of joints)")
    bodies = [int(m0.jnt_bodyid[j]) for j in controlled]
    for k in range(1, len(bodies)):  # a serial chain: each joint's body below the previous one
        b, anc = bodies[k], bodies[k - 1]
        p = int(m0.body_parentid[b])
        while p not in (anc, 0) and p not in bodies:
            p = int(m0.body_parentid[p])
        if p != anc:
            raise ArmError(f"model {path}: joint '{_joint_name(m0, controlled[k])}' is not below joint "
                           f"'{_joint_name(m0, controlled[k - 1])}': the controlled joints must form one serial "
                           "chain, base to tip, in order (a branch or a joint order the arm file got wrong)")
    inside = _joints_inside_chain(m0, bodies, controlled)
    for j in inside:
        name = _joint_name(m0, j)
        if name not in af.locked:
            raise ArmError(f"model {path}: joint '{name}' ({_joint_kind(int(m0.jnt_type[j]))}) sits inside the arm, "
                           f"between the base and joint '{_joint_name(m0, controlled[-1])}', and is not controlled: "
                           "the firmware drives hinge joints only; to run the arm with it held, name it in the arm "
                           f"file's locked table (locked = {{ {name} = value }})")
    for b in bodies:
        if sum(1 for j in range(m0.njnt) if m0.jnt_bodyid[j] == b and j in controlled) > 1:
            raise ArmError(f"model {path}: body '{mujoco.mj_id2name(m0, mujoco.mjtObj.mjOBJ_BODY, b)}' has more than "
                           "one controlled joint: one hinge per link")
    n = len(controlled)
    slots = _dbc_drive_slots()
    if n > min(MAX_JOINTS, slots):
        raise ArmError(f"model {path}: {n} controlled joints; the firmware takes at most {MAX_JOINTS} and the "
                       f"protocol (firmware/protocol/arm_drives.dbc) defines {slots} drive slots: lock joints "
                       "(arm file: joints), or add DRIVE_n slots to the DBC")
    names = [_joint_name(m0, j) for j in controlled]
    for k in af.locked:
        if k in names:
            raise ArmError(f"arm file {af.path}: locked: '{k}' is also a controlled joint")
        if mujoco.mj_name2id(m0, mujoco.mjtObj.mjOBJ_JOINT, k) < 0:
            raise ArmError(f"arm file {af.path}: locked: no joint '{k}' in {path.name}")
    for k in af.torque_limits:
        if k not in names:
            raise ArmError(f"arm file {af.path}: torque_limits: '{k}' is not a controlled joint ({', '.join(names)})")

    # closed chains: equality constraints between bodies of the arm, or coupling controlled joints
    for e in range(m0.neq):
        et = int(m0.eq_type[e])
        objs = (int(m0.eq_obj1id[e]), int(m0.eq_obj2id[e]))
        if et == int(mujoco.mjtEq.mjEQ_JOINT) and any(o in controlled for o in objs):
            raise ArmError(f"model {path}: equality constraint {e} couples controlled joint(s): a closed or coupled "
                           "chain the firmware's serial-chain model cannot represent")
        if et in (int(mujoco.mjtEq.mjEQ_CONNECT), int(mujoco.mjtEq.mjEQ_WELD)) and any(o in bodies or o == 0 for o in objs):
            raise ArmError(f"model {path}: equality constraint {e} closes a loop through the arm (connect/weld): "
                           "closed chains are not supported")

    # ---- keyframe, home, locked values ----
    key = -1
    if af.keyframe is not None:
        key = mujoco.mj_name2id(m0, mujoco.mjtObj.mjOBJ_KEY, af.keyframe)
        if key < 0:
            raise ArmError(f"arm file {af.path}: keyframe: no keyframe '{af.keyframe}' in {path.name}")
    else:
        key = mujoco.mj_name2id(m0, mujoco.mjtObj.mjOBJ_KEY, "home")
    qpos_key = m0.key_qpos[key] if key >= 0 else m0.qpos0
    ranges = []
    for j in controlled:
        lim = bool(m0.jnt_limited[j])
        ranges.append([float(m0.jnt_range[j, 0]), float(m0.jnt_range[j, 1])] if lim else None)
    if af.home is not None:
        if isinstance(af.home, list):
            if len(af.home) != n:
                raise ArmError(f"arm file {af.path}: home: {len(af.home)} values for {n} joints ({', '.join(names)})")
            home = list(af.home)
        else:
            missing = [k for k in names if k not in af.home]
            extra = [k for k in af.home if k not in names]
            if missing or extra:
                raise ArmError(f"arm file {af.path}: home: " + (f"missing {missing}" if missing else f"unknown {extra}"))
            home = [af.home[k] for k in names]
        home_src = "arm file"
    elif key >= 0:
        home = [float(qpos_key[m0.jnt_qposadr[j]]) for j in controlled]
        home_src = f"keyframe '{mujoco.mj_id2name(m0, mujoco.mjtObj.mjOBJ_KEY, key)}'"
    else:
        home = [0.5 * (r[0] + r[1]) if r else float(m0.qpos0[m0.jnt_qposadr[j]]) for j, r in zip(controlled, ranges)]
        home_src = "mid-range (no keyframe 'home' in the model, none in the arm file)"
        warnings.append(f"home pose: {home_src}")
    for name, h, r in zip(names, home, ranges):
        if r and not (r[0] + RANGE_MARGIN <= h <= r[1] - RANGE_MARGIN):
            raise ArmError(f"home pose ({home_src}): joint '{name}' at {h:g} rad is not inside its range "
                           f"[{r[0]:g}, {r[1]:g}] by {RANGE_MARGIN} rad")

    # ---- lock every other joint (its body fixed at the locked value) ----
    locked: list[dict[str, Any]] = []
    for j in range(m0.njnt):
        if j in controlled:
            continue
        name = _joint_name(m0, j)
        adr = int(m0.jnt_qposadr[j])
        t = m0.jnt_type[j]
        if t == mujoco.mjtJoint.mjJNT_BALL:
            raise ArmError(f"model {path}: joint '{name}' is a ball joint off the chain: lock it in the model "
                           "(the arm file locks hinge and slide joints)")
        v = af.locked.get(name, float(qpos_key[adr]))
        spec_joint = spec.joint(name) if mujoco.mj_id2name(m0, mujoco.mjtObj.mjOBJ_JOINT, j) else None
        if spec_joint is None:
            raise ArmError(f"model {path}: joint {j} off the chain has no name: name it, or control it")
        b = int(m0.jnt_bodyid[j])
        body = spec.body(mujoco.mj_id2name(m0, mujoco.mjtObj.mjOBJ_BODY, b))
        q0 = m0.body_quat[b].copy()
        p0 = m0.body_pos[b].copy()
        axis = m0.jnt_axis[j].copy()
        delta = v - float(m0.qpos0[adr])  # the body's frame in the model is the one at qpos0 (= ref)
        if t == mujoco.mjtJoint.mjJNT_HINGE:
            c = m0.jnt_pos[j].copy()
            r = _axis_quat(axis, delta)
            body.pos = p0 + _rotate(q0, c - _rotate(r, c))
            body.quat = _quat_mul(q0, r)
        else:
            body.pos = p0 + _rotate(q0, axis * delta)
            body.quat = q0
        body.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
        spec.delete(spec_joint)
        locked.append({"name": name, "value": v})
    if locked:
        warnings.append("locked (not controlled): " + ", ".join(f"{x['name']} at {x['value']:g}" for x in locked))

    # ---- explicit inertials, then nothing but dynamics ----
    for b in range(1, m0.nbody):
        body = spec.body(mujoco.mj_id2name(m0, mujoco.mjtObj.mjOBJ_BODY, b))
        body.explicitinertial = True
        body.mass = float(m0.body_mass[b])
        body.ipos = m0.body_ipos[b].copy()
        body.iquat = m0.body_iquat[b].copy()
        body.inertia = m0.body_inertia[b].copy()
        body.fullinertia = [math.nan, 0, 0, 0, 0, 0]  # unset: inertia + iquat are the ones
    limits = []
    for name, j in zip(names, controlled):
        lim, src = _torque_limit(m0, j, af.torque_limits.get(name))
        if lim is None:
            raise ArmError(f"model {path}: joint '{name}' has no torque limit (no actuatorfrcrange, no actuator "
                           "with a ctrlrange or forcerange, in URDF no <limit effort>): give one in the arm file "
                           f"(torque_limits = {{ {name} = ... }})")
        limits.append((lim, src))
    for elist in (spec.actuators, spec.sensors, spec.tendons, spec.equalities, spec.keys, spec.excludes, spec.pairs):
        for e in list(elist):
            spec.delete(e)
    if not af.contacts:
        for g in list(spec.geoms):
            spec.delete(g)
        _remove_assets(spec, set(ASSET_KINDS))  # nothing left draws them
        spec.option.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    else:
        spec.meshdir = str((path.parent / (spec.meshdir or "")).resolve())
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    for name, (lim, _) in zip(names, limits):
        spec.add_actuator(name=name, target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT,
                          ctrllimited=mujoco.mjtLimited.mjLIMITED_TRUE, ctrlrange=[-lim, lim], gear=[1, 0, 0, 0, 0, 0])

    # ---- the timestep: the loop period, or an integer fraction of it ----
    model_dt = float(m0.opt.timestep)
    if af.timestep == "model":
        k = period / model_dt
        if abs(k - round(k)) > 1e-9 * k or round(k) < 1:
            raise ArmError(f"model {path}: timestep {model_dt:g} s does not divide the loop period {period:g} s "
                           "(arm file timestep = \"model\"): make it period / k for an integer k, or use "
                           "timestep = \"loop\"")
        substeps, dt = int(round(k)), model_dt
    else:
        substeps, dt = 1, period
        if abs(model_dt - period) > 1e-12:
            warnings.append(f"timestep: the model's {model_dt:g} s replaced by the loop period {period:g} s "
                            "(arm file timestep = \"model\" keeps it when it divides the period)")
    spec.option.timestep = dt
    try:
        drivetrain.set_rotor_inertia(spec, af.drivetrain, names, _drivetrain_where(af))
    except drivetrain.DrivetrainError as exc:
        raise ArmError(str(exc)) from exc
    spec.compiler.fusestatic = True
    spec.modelname = armname
    m1 = _compile(spec, path, "preparing it")
    _check_float32(m1, path, names, limits, home)
    try:
        flange_body, flange_pos, flange_from = drivetrain.flange_site(m1, int(m1.jnt_bodyid[n - 1]), af.flange)
    except drivetrain.DrivetrainError as exc:
        raise ArmError(f"arm file {af.path}: {exc}") from exc
    spec.body(mujoco.mj_id2name(m1, mujoco.mjtObj.mjOBJ_BODY, flange_body)).add_site(
        name=drivetrain.PAYLOAD_SITE, pos=flange_pos)
    spec.add_key(name="home", qpos=home, ctrl=[0.0] * n)
    xml = spec.to_xml()
    try:
        m = mujoco.MjModel.from_xml_string(xml)
    except Exception as exc:  # noqa: BLE001
        raise ArmError(f"model {path}: the prepared model does not load back: {exc}") from exc
    if m.nq != n or m.nv != n or m.nu != n or m1.nbody != m.nbody:
        raise ArmError(f"model {path}: the prepared model has nq={m.nq}, nv={m.nv}, nu={m.nu} for {n} joints")
    written_error = _inverse_dynamics_difference(m1, m)
    if written_error > 1e-4:
        raise ArmError(f"model {path}: written to arm.xml (MuJoCo writes 6 significant digits) its inverse dynamics "
                       f"change by {written_error:.2g} relative: more than 1e-4")

    # ---- what the controller can use ----
    d = mujoco.MjData(m)
    d.qpos[:] = home
    mujoco.mj_forward(m, d)
    mass = np.zeros((n, n))
    mujoco.mj_fullM(m, d, mass)
    for i, name in enumerate(names):
        b = int(m.jnt_bodyid[i])
        if mass[i, i] < MIN_JOINT_INERTIA:
            raise ArmError(f"model {path}: joint '{name}' moves almost no inertia (M[{i},{i}] = {mass[i, i]:.3g} kg m^2 "
                           f"at the home pose, below {MIN_JOINT_INERTIA:g}): any torque gives an unbounded "
                           "acceleration; give the links beyond it their real mass and inertia")
        if m.body_mass[b] < LIGHT_LINK_KG:
            warnings.append(f"link of joint '{name}' weighs {m.body_mass[b]:.3g} kg ({_inertia_carrier(m, i)})")

    joints = []
    for i, jname in enumerate(names):
        joints.append({
            "name": jname, "torque_limit": limits[i][0], "torque_limit_from": limits[i][1],
            "range": ranges[i], "home": home[i],
            "armature": float(m.dof_armature[i]), "damping": float(m.dof_damping[i]),
            "frictionloss": float(m.dof_frictionloss[i]),
        })
    reference = default_reference(home, ranges)
    fitted, ref_notes = fit_reference(m, home, reference["amp"], reference["freq_hz"],
                                      [lim for lim, _ in limits], names)
    if ref_notes:
        warnings.append("default reference: " + "; ".join(ref_notes))
    reference = {"amp": fitted, "freq_hz": reference["freq_hz"],
                 "rule": reference_rule(), "peak_torque_fraction": [
                     round(x, 4) for x in reference_peak_fraction(m, home, fitted, reference["freq_hz"],
                                                                  [lim for lim, _ in limits])]}
    xml_bytes = xml.encode()
    info = {
        "name": armname,
        "model": str(path),
        "arm_file": str(af.path) if af.path else None,
        "model_format": "urdf" if is_urdf else "mjcf",
        "n_joints": n,
        "joints": joints,
        "locked": locked,
        "home_from": home_src,
        "loop_rate_hz": rate,
        "timestep_s": dt,
        "substeps": substeps,
        "contacts": af.contacts,
        "nominal_model": ("rigid bodies, armature and joint damping are in the firmware's nominal model; joint "
                          "friction (frictionloss), joint limits" + ("" if not af.contacts else " and contacts")
                          + " are left out on purpose: the estimator takes them as part of w"),
        "reference": reference,
        "buses": _wiring(af, n, rate),
        "model_hash": f"{fnv1a64(xml_bytes):016x}",
        "written_inverse_dynamics_error": written_error,
        "warnings": warnings,
    }
    del design_doc
    bundled = path == DEFAULT_MODEL.resolve() and not af.design and (design is None or design.resolve() ==
                                                                       DEFAULT_DESIGN.resolve())
    if af.design or design or bundled:
        why = ("the bundled arm's default, the paper's weights (its kept study tuning is keyed by them)" if bundled
               else f"the arm file's ({af.path})" if af.design else "asked for (--design)")
        info["design"] = {"config": str(template), "why": why}
    else:
        wn, limiting = auto_bandwidth(np.diag(mass), [lim for lim, _ in limits])
        design_text = with_static_controller(design_text, wn)
        info["design"] = {"config": f"{template} with a critically damped {wn:.3g} rad/s controller", "wn_rad_s": wn,
                          "why": (f"no design given: the largest bandwidth (in [{AUTO_WN_MIN:g}, {AUTO_WN_MAX:g}] rad/s) "
                                  f"at which a {DEFAULT_MAX_ERROR_DEG:g} deg tracking error asks no joint at home for "
                                  f"more than the {1 - REF_TORQUE_FRACTION:.0%} of its torque limit the reference "
                                  f"leaves it (the tightest: {names[limiting]}); --design gen/configs/paper.toml "
                                  "for the paper's weights")}
    info["design_config"] = info["design"]["config"]
    try:
        info["drivetrain"] = drivetrain.resolve(af.drivetrain, _drivetrain_where(af), m, names, home,
                                                [lim for lim, _ in limits], dt)
    except drivetrain.DrivetrainError as exc:
        raise ArmError(str(exc)) from exc
    info["first_resonance_hz"] = drivetrain.first_resonance_hz(info["drivetrain"])
    info["payload"] = {"rated_kg": af.rated_payload_kg, "at": flange_from}
    return Prepared(xml, info, design_for(design_text, n, template), drivetrain.plant_xml(xml, info["drivetrain"]))


def _drivetrain_where(af: ArmFile) -> str:
    return f"arm file {af.path}: drivetrain" if af.path else f"{drivetrain.BUNDLED_DRIVETRAIN}: drivetrain"


def auto_bandwidth(inertia_at_home: Any, torque_limits: list[float]) -> tuple[float, int]:
    """The default design's wn (AUTO_WN_MIN..AUTO_WN_MAX), and the joint that bounds it: the feedback
    M_jj wn^2 e of an error e at the tracking bound within the torque the reference leaves."""
    e = math.radians(DEFAULT_MAX_ERROR_DEG)
    room = [(1.0 - REF_TORQUE_FRACTION) * lim / (max(float(mjj), MIN_JOINT_INERTIA) * e)
            for mjj, lim in zip(inertia_at_home, torque_limits)]
    j = int(np.argmin(room))
    return float(min(AUTO_WN_MAX, max(AUTO_WN_MIN, math.sqrt(room[j])))), j


def with_static_controller(design_text: str, wn: float) -> str:
    """The design config with its [controller] replaced by u_o = -(wn^2 e + 2 wn e_dot): z_o = E1 e +
    E2 e_dot + D12 u_o with E1 = wn^2, E2 = 2 wn, D12 = 1 (one row: the static zeroing gain)."""
    table = f"[controller]\nE1 = [[{wn * wn!r}]]\nE2 = [[{2.0 * wn!r}]]\nD12 = [[1.0]]\n"
    out, count = re.subn(r"(?ms)^\[controller\].*?(?=^\[|\Z)", table + "\n", design_text, count=1)
    if count != 1:
        raise ArmError("design config: no [controller] table to set the default bandwidth in")
    return re.sub(r'(?m)^(\s*description\s*=\s*")', lambda mm: f"{mm.group(1)}default for the arm: {wn:.3g} rad/s "
                  "controller; ", out, count=1)


def _inertia_carrier(m: mujoco.MjModel, i: int) -> str:
    """What gives joint i of a link without mass the inertia it moves (it passed MIN_JOINT_INERTIA):
    the links beyond it, its rotor armature, or both."""
    b = int(m.jnt_bodyid[i])
    beyond = float(m.body_subtreemass[b] - m.body_mass[b])
    armature = float(m.dof_armature[i])
    parts = []
    if beyond >= LIGHT_LINK_KG:
        parts.append(f"{beyond:.3g} kg of links beyond it")
    if armature > 0:
        parts.append(f"its rotor armature of {armature:.3g} kg m^2")
    if not parts:
        return "its own rotational inertia is all it moves: no link beyond it, no armature"
    return " and ".join(parts) + (" carry" if len(parts) > 1 else " carries") + " the inertia" + \
        ("" if beyond >= LIGHT_LINK_KG else "; no link beyond it")


def inverse_forces(models: tuple[mujoco.MjModel, ...], q: np.ndarray, qd: np.ndarray,
                   qdd: np.ndarray) -> list[np.ndarray]:
    """mj_inverse of each model at the one state (q, qd, qdd): the generalised forces each needs."""
    out = []
    for m in models:
        d = mujoco.MjData(m)
        d.qpos[:], d.qvel[:], d.qacc[:] = q, qd, qdd
        mujoco.mj_inverse(m, d)
        out.append(d.qfrc_inverse.copy())
    return out


def _inverse_dynamics_difference(a: mujoco.MjModel, b: mujoco.MjModel, samples: int = 20) -> float:
    """The largest relative difference of two models' rigid-body inverse dynamics (constraints
    and springs off) over random states: what writing the model to XML cost."""
    rng = np.random.default_rng(0)
    worst = 0.0
    for m in (a, b):
        m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT) | int(mujoco.mjtDisableBit.mjDSBL_SPRING)
    try:
        for _ in range(samples):
            q, qd, qdd = rng.uniform(-3, 3, a.nv), rng.uniform(-2, 2, a.nv), rng.uniform(-5, 5, a.nv)
            out = inverse_forces((a, b), q, qd, qdd)
            scale = np.max(np.abs(out[0])) + 1e-9
            worst = max(worst, float(np.max(np.abs(out[0] - out[1])) / scale))
    finally:
        for m in (a, b):
            m.opt.disableflags &= ~(int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT) | int(mujoco.mjtDisableBit.mjDSBL_SPRING))
    return worst


def default_reference(home: list[float], ranges: list[list[float] | None]) -> dict[str, list[float]]:
    """q_d = home + a (1 - cos 2 pi f t): the firmware's default amplitudes and distinct frequencies,
    each joint moving towards the side of its range with more room and staying RANGE_MARGIN inside."""
    rule = constant("default-reference")
    amp, freq = [], []
    for i, (h, r) in enumerate(zip(home, ranges)):
        a = round(rule["amp-base"] + rule["amp-step"] * i, 6)
        amp.append(clip_amplitude(a, h, r))
        freq.append(round(rule["freq-base-hz"] + rule["freq-step-hz"] * i, 6))
    return {"amp": amp, "freq_hz": freq}


def reference_rule(fraction: float = REF_TORQUE_FRACTION) -> str:
    return (f"inverse dynamics (rigid bodies, armature, damping, frictionloss, a scenario's friction) within "
            f"{100 * fraction:g} % of each joint's torque limit, speed within {REF_MAX_VELOCITY:.3g} rad/s, "
            f"acceleration within {REF_MAX_ACCELERATION:g} rad/s^2")


def reference_torque(m: mujoco.MjModel, home: list[float], amp: list[float], freq: list[float],
                     viscous: list[float] | None = None, coulomb: list[float] | None = None,
                     samples: int = 500) -> np.ndarray:
    """Each joint's largest |torque| along q = home + a (1 - cos 2 pi f t): MuJoCo's mj_inverse on the
    prepared model (armature and damping included; constraints off), plus the model's frictionloss and
    the viscous (per rad/s) and Coulomb friction a scenario adds, at the velocity's sign. Sampled over
    the slowest joint's period (every joint's peaks fall in it)."""
    n = m.nv
    a, f = np.asarray(amp, float), np.asarray(freq, float)
    w = 2 * np.pi * f
    slowest = float(np.min(f[f > 0])) if np.any(f > 0) else 1.0
    vis = np.asarray(viscous if viscous is not None else np.zeros(n), float)
    cou = np.asarray(coulomb if coulomb is not None else np.zeros(n), float) + m.dof_frictionloss
    d = mujoco.MjData(m)
    flags = m.opt.disableflags
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    worst = np.zeros(n)
    try:
        for t in np.linspace(0.0, 1.0 / slowest, samples):
            d.qpos[:] = np.asarray(home) + a * (1 - np.cos(w * t))
            d.qvel[:] = a * w * np.sin(w * t)
            d.qacc[:] = a * w * w * np.cos(w * t)
            mujoco.mj_inverse(m, d)
            tau = d.qfrc_inverse + vis * d.qvel + cou * np.sign(d.qvel)
            worst = np.maximum(worst, np.abs(tau))
    finally:
        m.opt.disableflags = flags
    return worst


def reference_peak_fraction(m: mujoco.MjModel, home: list[float], amp: list[float], freq: list[float],
                            limits: list[float], viscous: list[float] | None = None,
                            coulomb: list[float] | None = None) -> list[float]:
    return [float(x) for x in reference_torque(m, home, amp, freq, viscous, coulomb) / np.asarray(limits)]


def fit_reference(m: mujoco.MjModel, home: list[float], amp: list[float], freq: list[float], limits: list[float],
                  names: list[str], viscous: list[float] | None = None, coulomb: list[float] | None = None,
                  fraction: float = REF_TORQUE_FRACTION) -> tuple[list[float], list[str]]:
    """The amplitudes, each scaled down as little as needed (per joint, in steps of 10 %) so that the
    reference fits REF_TORQUE_FRACTION of every torque limit, REF_MAX_VELOCITY and
    REF_MAX_ACCELERATION; one note per joint changed, naming the torque the asked-for amplitude needs.
    A joint whose torque stays over with its own motion small is loaded by the joints beyond it: those
    are scaled then. What no amplitude can fix (gravity at home) is noted, amplitudes left as fitted."""
    out = [float(x) for x in amp]
    lim = np.asarray(limits, float)
    for i, f in enumerate(freq):  # speed and acceleration: closed form
        w = 2 * math.pi * f
        if w > 0:
            cap = min(REF_MAX_VELOCITY / w, REF_MAX_ACCELERATION / (w * w))
            if abs(out[i]) > cap:
                out[i] = math.copysign(math.floor(cap * 1e4) / 1e4, out[i])
    asked = reference_torque(m, home, amp, freq, viscous, coulomb)
    notes: list[str] = []
    stuck = False
    for _ in range(200):
        peak = reference_torque(m, home, out, freq, viscous, coulomb)
        over = [i for i in range(len(out)) if peak[i] > fraction * lim[i] * (1 + 1e-9)]
        if not over:
            break
        moved = False
        for i in over:
            if abs(out[i]) > 0.02 * abs(amp[i]) and abs(out[i]) > 1e-3:
                out[i] = math.copysign(math.floor(abs(out[i]) * 0.9 * 1e4) / 1e4, out[i])
                moved = True
            else:  # its own motion is small: the joints beyond it load it
                for k in range(i + 1, len(out)):
                    if abs(out[k]) > 1e-3:
                        out[k] = math.copysign(math.floor(abs(out[k]) * 0.9 * 1e4) / 1e4, out[k])
                        moved = True
        if not moved:
            stuck = True
            break
    peak = reference_torque(m, home, out, freq, viscous, coulomb)
    for i, name in enumerate(names):
        if out[i] != amp[i]:
            notes.append(f"{name}: amplitude {amp[i]:g} rad scaled to {out[i]:g} rad: at {amp[i]:g} rad it would "
                         f"need {asked[i]:.3g} N m of its {lim[i]:g} N m torque limit ({100 * asked[i] / lim[i]:.0f} %, "
                         f"{abs(amp[i]) * 2 * math.pi * freq[i]:.3g} rad/s, "
                         f"{abs(amp[i]) * (2 * math.pi * freq[i]) ** 2:.3g} rad/s^2); the reference keeps within "
                         f"{100 * fraction:g} %")
    if stuck:
        bad = [i for i in range(len(out)) if peak[i] > fraction * lim[i] * (1 + 1e-9)]
        notes += [f"{names[i]}: needs {peak[i]:.3g} N m of its {lim[i]:g} N m torque limit even with every amplitude "
                  f"small (gravity or the model's friction at home): over {100 * fraction:g} %" for i in bad]
    return out, notes


def clip_amplitude(a: float, home: float, r: list[float] | None) -> float:
    """The amplitude nearest the one asked for whose motion home .. home + 2a stays RANGE_MARGIN
    inside the range: its sign picks the direction, flipped when only the other side has room."""
    if r is None:
        return a
    up = r[1] - RANGE_MARGIN - home
    down = home - (r[0] + RANGE_MARGIN)
    room, other = (up, down) if a >= 0 else (down, up)
    if 2 * abs(a) > room and other > room:
        a, room = -a, other
    return math.copysign(min(abs(a), max(0.0, room / 2)), a)


def _design(path: Path) -> tuple[dict[str, Any], str, float]:
    try:
        text = path.read_text()
        doc = toml_input.loads(text)
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ArmError(f"design config {path}: {exc}") from exc
    rate = doc.get("arm", {}).get("loop_rate_hz") if isinstance(doc.get("arm"), dict) else None
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not 10 <= rate <= 20000:
        raise ArmError(f"design config {path}: arm.loop_rate_hz: expected a number in [10, 20000], got {rate!r}")
    return doc, text, float(rate)


def design_for(text: str, n: int, path: Path) -> str:
    """The design config with arm.n_joints = n (its weights are one joint's, applied to every joint)."""
    out, count = re.subn(r"(?m)^(\s*n_joints\s*=\s*)\d+", lambda mm: f"{mm.group(1)}{n}", text, count=1)
    if count != 1:
        raise ArmError(f"design config {path}: arm.n_joints: missing")
    # a description that counts joints ("..., 6 joints, ...") counts the arm's
    out = re.sub(r'(?m)^(\s*description\s*=\s*".*?)\b\d+ joints\b', lambda mm: f"{mm.group(1)}{n} joints", out, count=1)
    return f"# {path} with n_joints from the arm model (gen/arm.py)\n" + out


def _wiring(af: ArmFile, n: int, rate: float) -> list[dict[str, Any]]:
    """The buses: the arm file's, else firmware/protocol/buses.toml for six drives, else the fewest
    CAN FD 1/5 Mbit/s buses that fit the drives within the 70 % budget at the loop rate."""
    from gen.lib import busload

    try:
        if af.buses is not None:
            tmp = "".join(_bus_toml(b) for b in af.buses)
            buses = _load_topology_text(tmp, f"arm file {af.path}: buses", n)
        elif af.topology is not None:
            buses = busload.load_topology(af.topology, n)
        elif n == 6:
            buses = busload.load_topology(DEFAULT_TOPOLOGY, n)
        else:
            buses = busload.default_wiring(n, rate)
        loads = busload.compute(buses, rate, constant("heartbeat-ms"), busload.default_protocol(), n)
        over = [bl for bl in loads if bl.load > BUS_BUDGET]
        if over:
            raise busload.ConfigError(
                "; ".join(f"bus {bl.bus.name} ({bl.bus.describe()}, drives {bl.bus.drives}) is loaded "
                          f"{100 * bl.load:.0f} % at {rate:g} Hz, above the {100 * BUS_BUDGET:g} % budget "
                          f"(it fits up to {bl.max_rate_hz(BUS_BUDGET):.0f} Hz)" for bl in over)
                + ": spread the drives over more buses or use CAN FD (armctl busload --drives N shows the options)")
    except busload.ConfigError as exc:
        raise ArmError(f"bus wiring: {exc}") from exc
    return [{"name": b.name, "kind": "fd" if b.fd else "classic", "nominal": b.nominal_bps, "data": b.data_bps,
             "drives": b.drives} for b in buses]


def _bus_toml(b: dict[str, Any]) -> str:
    lines = ["[[bus]]"]
    for k, v in b.items():
        lines.append(f"{k} = {json.dumps(v)}")
    return "\n".join(lines) + "\n"


def _load_topology_text(text: str, where: str, n: int) -> list[Any]:
    import tempfile

    from gen.lib import busload

    with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=True) as fh:
        fh.write(text)
        fh.flush()
        try:
            return busload.load_topology(Path(fh.name), n)
        except busload.ConfigError as exc:
            raise busload.ConfigError(str(exc).replace(fh.name, where)) from exc


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m gen.arm", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", type=Path, default=None, help="MJCF or URDF [the arm file's, else the bundled UR5e]")
    ap.add_argument("--arm-file", type=Path, default=None, help="arm file (TOML)")
    ap.add_argument("--design", type=Path, default=None,
                    help="design config when the arm file names none [the arm's default: gen/configs/paper.toml "
                         "for the bundled arm, else one whose bandwidth fits the arm (auto_bandwidth)]")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--depfile", type=Path, default=None, help="write the files read, for the build (Ninja depfile)")
    ns = ap.parse_args(argv)
    try:
        if ns.arm_file is not None and ns.model is not None:
            raise ArmError("--model and --arm-file: give one (the arm file names its model)")
        af = load_arm_file(ns.arm_file.resolve() if ns.arm_file else None, ns.model)
        prep = prepare(af, ns.design)
    except ArmError as exc:
        print(f"gen.arm: {exc}", file=sys.stderr)
        return 2
    files = {"arm.xml": prep.xml, "arm.json": json.dumps(prep.info, indent=1) + "\n", "design.toml": prep.design_text,
             "plant.xml": prep.plant_xml}
    try:
        write_files_atomically(ns.out, files)
    except OutputError as exc:
        print(f"gen.arm: {exc}", file=sys.stderr)
        return 1
    if ns.depfile is not None:
        deps = [str(af.model.resolve()), str((af.design or ns.design or DEFAULT_DESIGN).resolve())]
        if af.path:
            deps.append(str(af.path.resolve()))
        if af.topology:
            deps.append(str(af.topology.resolve()))
        if af.drivetrain is not None and af.path is None:  # the bundled arm's
            deps.append(str(drivetrain.BUNDLED_DRIVETRAIN))
        from gen.lib.busload import DEFAULT_DBC

        deps += [str(DEFAULT_DBC), str(DEFAULT_TOPOLOGY)]  # the drive slots; the six-drive wiring
        target = ns.out / "arm.xml"
        ns.depfile.write_text(f"{target}: " + " ".join(d.replace(" ", "\\ ") for d in deps) + "\n")
    for w in prep.info["warnings"]:
        print(f"gen.arm: {prep.info['name']}: {w}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
