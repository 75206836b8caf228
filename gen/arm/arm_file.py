"""The arm file (TOML): the model, the controlled joints, home, limits, wiring, design; and the
arm's name in reports and build folders."""

from __future__ import annotations

import functools
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gen.arm.errors import ArmError, number
from gen.lib import toml_input
from gen.lib.paths import BUNDLED_DRIVETRAIN, REPO

if TYPE_CHECKING:
    import mujoco

DEFAULT_MODEL = REPO / "host_sim" / "models" / "ur5e_arm.xml"
DEFAULT_DESIGN = REPO / "gen" / "configs" / "paper.toml"
ARM_FILE_FIELDS = {"name", "model", "joints", "locked", "home", "keyframe", "torque_limits", "buses",
                   "topology", "design", "contacts", "timestep", "drives", "drivetrain", "rated_payload_kg", "flange"}
GENERIC_STEMS = ("robot", "model", "arm")  # a file named so says less than its folder


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


def _names(v: Any, where: str) -> list[str]:
    if not isinstance(v, list) or not v or not all(isinstance(x, str) and x for x in v):
        raise ArmError(f"{where}: expected a list of joint names, got {v!r}")
    if len(set(v)) != len(v):
        raise ArmError(f"{where}: a joint is named twice")
    return list(v)


def _table_of_numbers(v: Any, where: str) -> dict[str, float]:
    if not isinstance(v, dict):
        raise ArmError(f"{where}: expected a table of joint = number, got {v!r}")
    return {k: number(x, f"{where}.{k}") for k, x in v.items()}


def _bare_model(model: Path | None) -> ArmFile:
    """The defaults for a model given without an arm file."""
    # gen.drivetrain (MuJoCo) only where it is needed: `python -m gen.arm` finds a prepared folder without it
    if (model or DEFAULT_MODEL).resolve() == DEFAULT_MODEL.resolve():
        from gen import drivetrain

        # the bundled arm: its drive train and rated payload are cited in a file of their own
        table, payload = drivetrain.load_bundled()
        return ArmFile(None, None, DEFAULT_MODEL, drivetrain=table, rated_payload_kg=payload)
    return ArmFile(None, None, model)


def _read_arm_toml(path: Path) -> dict[str, Any]:
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
    return doc


def _file_path(path: Path, v: Any, where: str) -> Path:
    """A file the arm file names, relative to the arm file's folder."""
    if not isinstance(v, str) or not v:
        raise ArmError(f"arm file {path}: {where}: expected a file path, got {v!r}")
    p = Path(v)
    return p if p.is_absolute() else (path.parent / p).resolve()


def _joint_fields(af: ArmFile, doc: dict[str, Any], path: Path) -> None:
    """joints, locked, home, keyframe and torque_limits."""
    if "joints" in doc:
        af.joints = _names(doc["joints"], f"arm file {path}: joints")
    if "locked" in doc:
        af.locked = _table_of_numbers(doc["locked"], f"arm file {path}: locked")
    if "home" in doc:
        h = doc["home"]
        if isinstance(h, list):
            af.home = [number(x, f"arm file {path}: home[{i}]") for i, x in enumerate(h)]
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


def _wiring_fields(af: ArmFile, doc: dict[str, Any], path: Path) -> None:
    """buses or topology, design and drives."""
    if "buses" in doc and "topology" in doc:
        raise ArmError(f"arm file {path}: give buses or topology, not both")
    if "buses" in doc:
        if not isinstance(doc["buses"], list) or not all(isinstance(b, dict) for b in doc["buses"]):
            raise ArmError(f"arm file {path}: buses: expected [[buses]] tables (name, kind, nominal, data, drives)")
        af.buses = doc["buses"]
    if "topology" in doc:
        af.topology = _file_path(path, doc["topology"], "topology")
    if "design" in doc:
        af.design = _file_path(path, doc["design"], "design")
    if "drives" in doc:  # the CiA 402 drive configuration: read by gen/drives.py, checked here early
        drives = _file_path(path, doc["drives"], "drives")
        if not drives.is_file():
            raise ArmError(f"arm file {path}: drives: {drives} is not a file (the drive configuration, "
                           "like firmware/protocol/drives.toml)")


def _simulation_fields(af: ArmFile, doc: dict[str, Any], path: Path) -> None:
    """contacts, timestep, drivetrain, rated_payload_kg and flange."""
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
        from gen import drivetrain

        try:
            af.drivetrain = drivetrain.check_table(doc["drivetrain"], f"arm file {path}: drivetrain")
        except drivetrain.DrivetrainError as exc:
            raise ArmError(str(exc)) from exc
    if "rated_payload_kg" in doc:
        af.rated_payload_kg = number(doc["rated_payload_kg"], f"arm file {path}: rated_payload_kg")
        if af.rated_payload_kg < 0:
            raise ArmError(f"arm file {path}: rated_payload_kg: must be >= 0 kg, got {af.rated_payload_kg:g}")
    if "flange" in doc:
        if not isinstance(doc["flange"], str) or not doc["flange"]:
            raise ArmError(f"arm file {path}: flange: expected the name of a site on the last link")
        af.flange = doc["flange"]


def load_arm_file(path: Path | None, model: Path | None = None) -> ArmFile:
    """The arm file (TOML) validated field by field, or the defaults for a bare model."""
    if path is None:
        return _bare_model(model)
    doc = _read_arm_toml(path)
    if "model" not in doc and model is None:
        raise ArmError(f"arm file {path}: model: missing (the MJCF or URDF file of the arm)")
    m = model or _file_path(path, doc["model"], "model")
    af = ArmFile(path, slug(doc["name"]) if isinstance(doc.get("name"), str) else None, m)
    if "name" in doc and not isinstance(doc["name"], str):
        raise ArmError(f"arm file {path}: name: expected a string")
    _joint_fields(af, doc, path)
    _wiring_fields(af, doc, path)
    _simulation_fields(af, doc, path)
    return af


def drivetrain_inputs(af: ArmFile) -> list[Path]:
    """The files the drive train is read from besides the arm file: the bundled arm's own."""
    return [BUNDLED_DRIVETRAIN] if af.path is None and af.drivetrain is not None else []


def slug(text: str) -> str:
    s = re.sub(r"[^A-Za-z0-9_-]+", "-", text).strip("-").lower()
    return s[:40] or "arm"


def arm_name(af: ArmFile, spec: mujoco.MjSpec) -> str:
    """The arm's name in reports and build folders: the arm file's name, else the model's, else
    its file's stem (its folder's for robot.xml, model.xml, arm.xml)."""
    if af.name:
        return af.name
    if spec.modelname and spec.modelname != "MuJoCo Model":
        return slug(spec.modelname)
    path = af.model.resolve()
    return slug(path.parent.name if path.stem.lower() in GENERIC_STEMS and path.parent.name else path.stem)


@functools.lru_cache(maxsize=64)
def arm_name_of(arm_file: Path | None, model: Path | None) -> str:
    """arm_name() without preparing the arm (the model is parsed, not compiled): for the name of
    its build folder. An arm that cannot be read is named after its file (the import says why)."""
    from gen.arm.load import load

    try:
        af = load_arm_file(arm_file, model)
        return arm_name(af, load(af.model.resolve()))
    except ArmError:
        what = arm_file or model or DEFAULT_MODEL
        return slug(what.stem)
