"""The plant's truth file (armctl plant --truth FILE): the arm as it really is, where the model the
controller was built from is silent or wrong. The controller never reads it: it meets the arm only
through the bus, as it would a real one; `armctl commission` has to find what the file hides. The
drives' holding brakes are the drive table's (brake_holding_nm, gen/drives.py), as on a real arm.

    flexible = true          # the arm with flexible joints (the build's plant.xml) [false]
    payload_kg = 1.5         # at the flange, unmodelled [0]

    [joint.shoulder_lift]    # any joint of the arm, by name
    viscous = 0.5            # N m s/rad of friction the model lacks [0]
    coulomb = 2.0            # N m [0]
    rotor_inertia = 0.2      # kg m^2 added to the joint's armature [0]
    stiffness_scale = 0.8    # its gear's stiffness times this (flexible = true) [1]
    encoder_offset_deg = 10  # its encoder zeroed this far off [0]
    reversed = "motor"       # its motor (or "encoder") turns the other way
    gear = [101, 1]          # the real gear, when the drive's 0x6091 (the drive table's) is not it
    start_deg = 30           # its angle when the plant starts [the arm's home]

Bad input is one line naming the file and the field (TruthError)."""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gen.lib import toml_input
from gen.lib.one_line import one_line
from gen.lib.params import param
from host_sim.uncertainty import UncertaintyConfig

TOP_FIELDS = {"flexible", "payload_kg", "joint"}
JOINT_FIELDS = {"viscous", "coulomb", "rotor_inertia", "stiffness_scale", "encoder_offset_deg", "reversed", "gear",
                "start_deg"}
REVERSED = ("motor", "encoder")


class TruthError(ValueError):
    pass


@dataclass
class Truth:
    """What arm_sim is told: the uncertainty (friction, payload, flexible joints) and the plant's own options."""
    uncertainty: UncertaintyConfig
    args: list[str]
    notes: list[str]  # one line per joint whose truth differs from the model, for the plant's printout


def _number(v: Any, where: str, lo: float, hi: float) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi:
        raise TruthError(f"{where}: expected a number in [{lo:g}, {hi:g}], got {one_line(repr(v))}")
    return float(v)


def _csv(vals: list[float]) -> str:
    return ",".join(repr(float(x)) for x in vals)


def _parse(path: Path) -> dict[str, Any]:
    try:
        return toml_input.loads(path.read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise TruthError(f"{path}: {one_line(str(exc))}") from None


def _read(path: Path | None, where: str) -> dict[str, Any]:
    doc = _parse(path) if path is not None else {}
    unknown = set(doc) - TOP_FIELDS
    if unknown:
        raise TruthError(f"{where}: unknown field(s) {one_line(', '.join(sorted(unknown)))} (known: "
                         f"{', '.join(sorted(TOP_FIELDS))}; per joint [joint.NAME])")
    return doc


def _joint_tables(doc: dict[str, Any], joints: list[str], where: str) -> dict[str, Any]:
    """[joint.NAME] tables, each naming a joint of the arm and known fields only."""
    tab = doc.get("joint", {})
    if not isinstance(tab, dict):
        raise TruthError(f"{where}: joint: expected tables [joint.NAME]")
    for name, t in tab.items():
        if name not in joints:
            raise TruthError(f"{where}: joint.{one_line(name)}: not a joint of the arm ({', '.join(joints)})")
        if not isinstance(t, dict):
            raise TruthError(f"{where}: joint.{one_line(name)}: expected a table")
        extra = set(t) - JOINT_FIELDS
        if extra:
            raise TruthError(f"{where}: joint.{name}: unknown field(s) {one_line(', '.join(sorted(extra)))} "
                             f"(known: {', '.join(sorted(JOINT_FIELDS))})")
    return tab


def _start_pose(tab: dict[str, Any], info: dict[str, Any], where: str) -> list[float]:
    """Each joint's start_deg inside its range, or its home."""
    start = []
    for spec in info["joints"]:
        j = spec["name"]
        lo, hi = spec["range"]
        v = tab.get(j, {}).get("start_deg")
        start.append(spec["home"] if v is None else math.radians(
            _number(v, f"{where}: joint.{j}.start_deg", math.degrees(lo), math.degrees(hi))))
    return start


def _reversed(tab: dict[str, Any], joints: list[str], where: str) -> dict[str, list[int]]:
    """The joints (1-based) whose motor or encoder is wired the other way round."""
    reversed_: dict[str, list[int]] = {"motor": [], "encoder": []}
    for i, j in enumerate(joints):
        r = tab.get(j, {}).get("reversed")
        if r is None:
            continue
        if r not in REVERSED:
            raise TruthError(f"{where}: joint.{j}.reversed: \"motor\" or \"encoder\", got {one_line(repr(r))}")
        reversed_[r].append(i + 1)
    return reversed_


def _gear_factors(tab: dict[str, Any], joints: list[str], table: Any, where: str) -> list[float]:
    """Per joint, its true gear ratio over the drive table's (1: as the table says)."""
    factors = []
    for i, j in enumerate(joints):
        g = tab.get(j, {}).get("gear")
        if g is None:
            factors.append(1.0)
            continue
        if (not isinstance(g, list) or len(g) != 2 or any(isinstance(x, bool) or not isinstance(x, int) or x < 1
                                                         for x in g)):
            raise TruthError(f"{where}: joint.{j}.gear: expected [motor revolutions, shaft revolutions], "
                             f"got {one_line(repr(g))}")
        dm, ds = table.drives[i].gear
        factors.append((g[0] / g[1]) / (dm / ds))
    return factors


def _sim_args(start: list[float], rotor: list[float], stiff: list[float], offset: list[float],
              factors: list[float], reversed_: dict[str, list[int]]) -> list[str]:
    """arm_sim's arguments for what differs from the model."""
    args = ["--start-pose", _csv(start)]
    if any(rotor):
        args += ["--rotor-inertia", _csv(rotor)]
    if any(s != 1.0 for s in stiff):
        args += ["--joint-stiffness-scale", _csv(stiff)]
    if any(offset):
        args += ["--encoder-offset", _csv([math.radians(x) for x in offset])]
    if any(f != 1.0 for f in factors):
        args += ["--gear-factor", _csv(factors)]
    for kind, js in reversed_.items():
        if js:
            args += [f"--reversed-{kind}", ",".join(map(str, js))]
    return args


def _notes(tab: dict[str, Any], joints: list[str], payload: float, flexible: bool) -> list[str]:
    notes = []
    for j in joints:
        t = tab.get(j, {})
        bits = [f"{k} = {one_line(repr(t[k]))}" for k in sorted(t) if k != "start_deg"]
        if bits:
            notes.append(f"{j}: {', '.join(bits)}")
    if payload:
        notes.append(f"a payload of {payload:g} kg at the flange")
    if flexible:
        notes.append("flexible joints (the build's plant.xml)")
    return notes


def load(path: Path | None, info: dict[str, Any], table: Any) -> Truth:
    """The truth for the arm (arm.json as a dict) and its drive table (gen/drives.py DriveConfig):
    None is the arm as modelled."""
    where = str(path) if path is not None else "truth"
    doc = _read(path, where)
    joints = [j["name"] for j in info["joints"]]
    tab = _joint_tables(doc, joints, where)
    flexible = doc.get("flexible", False)
    if not isinstance(flexible, bool):
        raise TruthError(f"{where}: flexible: true or false, got {one_line(repr(flexible))}")
    payload = _number(doc.get("payload_kg", 0.0), f"{where}: payload_kg", 0.0, param("simulator", "payload-kg").max)

    def per_joint(key: str, default: float, lo: float, hi: float) -> list[float]:
        return [_number(tab.get(j, {}).get(key, default), f"{where}: joint.{j}.{key}", lo, hi) for j in joints]

    viscous = per_joint("viscous", 0.0, 0.0, param("simulator", "viscous").max)
    coulomb = per_joint("coulomb", 0.0, 0.0, param("simulator", "coulomb").max)
    rotor = per_joint("rotor_inertia", 0.0, 0.0, param("simulator", "rotor-inertia").max)
    stiff = per_joint("stiffness_scale", 1.0, param("simulator", "joint-stiffness-scale").min,
                      param("simulator", "joint-stiffness-scale").max)
    offset = per_joint("encoder_offset_deg", 0.0, -360.0, 360.0)
    start = _start_pose(tab, info, where)
    reversed_ = _reversed(tab, joints, where)
    factors = _gear_factors(tab, joints, table, where)
    if any(s != 1.0 for s in stiff) and not flexible:
        raise TruthError(f"{where}: stiffness_scale: scales the gears of a flexible arm (flexible = true)")
    unc = UncertaintyConfig(viscous=viscous if any(viscous) else [], coulomb=coulomb if any(coulomb) else [],
                            flexible=flexible, payload_kg=[payload] if payload > 0 else [])
    assert len(start) == len(joints)
    return Truth(unc, _sim_args(start, rotor, stiff, offset, factors, reversed_),
                 _notes(tab, joints, payload, flexible))
