"""The arm's CiA 402 drive configuration (firmware/protocol/drives.toml, or the arm file's
`drives = "FILE"`), resolved per joint, and the arm_canopen_boot options it makes.

    python -m gen.drives --arm-json build/debug/generated/arm/arm.json            # the table, JSON
    python -m gen.drives --arm-json ... --boot-args can0                          # one bus's options

Rule (docs/drives-bring-up.md): a joint's field is its [joint.NAME] value, else [defaults], else
node = the drive's number. Units (the motor's rated torque, encoder, gear) are the drive's: the
master reads 0x6076, 0x608F and 0x6091 at boot and never writes them; what the table gives is
compared with them (a mismatch stops the boot), and fills what the drive lacks. CiA 402: 0x6076 is
the MOTOR's; the joint's torque is per-mille / 1000 x 0x6076 x gear x gear_efficiency (1 unless
the table gives one). rated_torque_nm = "joint_torque_limit / gear" is the motor that gives the
joint's torque limit (arm.json) through the gear, rounded up to the drive's torque unit (the
emulated drives, commissioned for this arm). Each joint's torque limit must be within what its
drive gives at the joint (0x6072 x 0x6076 x gear x efficiency). A drive without a settable 0x1016.1
(its watchdog on the master) is refused unless accept_no_master_watchdog = true. The drive's EDS or
DCF is checked against the boot before it starts (gen/drive_check.py). Bad input: one line naming
the file and the field, exit 2.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tomllib
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from gen import drive_check
from gen import eds as eds_mod
from gen.lib.cia402 import CODEC_MAPPING
from gen.lib import toml_input
from gen.lib.escape import shell_command

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DRIVES = ROOT / "firmware" / "protocol" / "drives.toml"
TOP_FIELDS = {"eds", "heartbeat_ms", "consumer_ms", "master_id", "defaults", "joint", "pdo",
              drive_check.ACCEPT_NO_WATCHDOG}
JOINT_FIELDS = {"node", "encoder_increments", "gear", "rated_torque_nm", "torque_unit", "gear_efficiency",
                "brake_holding_nm", "brake_close_ms", "brake_release_ms", "quick_stop_deceleration"}
BRAKE_FIELDS = ("brake_holding_nm", "brake_close_ms", "brake_release_ms")  # all or none
BRAKE_JOINT_TORQUE_LIMIT = "joint_torque_limit"  # brake_holding_nm: the joint's torque limit (arm.json)
# 0x6076's unit, per N m: CiA 402 says mN m; maxon's EPOS4 gives µN m (its firmware specification)
TORQUE_UNITS = {"mNm": 1000, "uNm": 1000000}
# rated_torque_nm: the motor that gives the joint's torque limit (arm.json) through the gear
JOINT_TORQUE_LIMIT = "joint_torque_limit / gear"
U32_MAX = 0xFFFFFFFF
# The contract's: every PDO on every SYNC. TPDO2 may come every n-th SYNC (the controller keeps its
# torque and statusword in between); TPDO1, the joint state, must come every SYNC; RPDO1 may be
# synchronous (1-240, at the next SYNC) or event-driven (254/255, at once).
DEFAULT_TRANSMISSION = {"rpdo1": 1, "tpdo1": 1, "tpdo2": 1}


class DrivesError(ValueError):
    pass


@dataclass
class Drive:
    joint: str
    drive: int              # the drive's number, 1..n (buses.toml)
    bus: str
    node: int
    rated_torque_mnm: float  # 0x6076, the MOTOR's, in mN m: the table's, else the file's
    encoder_increments: int  # 0x608F.1 increments per 0x608F.2 motor revolutions: the table's, else the file's
    gear: tuple[int, int]   # 0x6091.1, .2: the table's, else the file's
    given: list[str]        # the objects the table gives: the boot compares the drive's with them
    notes: list[str] = field(default_factory=list)  # what the table fills, what the boot skips; the file's warnings
    encoder_revs: int = 1   # 0x608F.2 (the table gives increments per one revolution)
    torque_unit: str = "mNm"  # 0x6076's unit (TORQUE_UNITS)
    gear_efficiency: float = 1.0  # the table's: the joint gets 0x6076 x gear x it
    joint_torque_limit_nm: float = 0.0  # arm.json's: the drive must give it at the joint
    max_torque_permille: int = drive_check.MAX_PERMILLE  # 0x6072 as the file says (the boot reads the drive's)
    accept_no_master_watchdog: bool = False  # the table accepts a drive without a settable 0x1016.1
    # The drive's holding brake (its own settings, no CiA 402 object): holding torque at the joint,
    # closing and release delays; None: no brake. And 0x6085 in the drive's own unit (None: its own).
    brake: tuple[float, float, float] | None = None
    quick_stop_deceleration: int | None = None

    def brake_spec(self) -> str | None:
        """arm_sim's --brake value for this drive's joint, or None."""
        if self.brake is None:
            return None
        hold, close, release = self.brake
        return f"{self.drive}:{hold:g}:{close:g}:{release:g}"

    @property
    def joint_rated_torque_nm(self) -> float:
        """1000 per-mille at the joint: the motor's rated torque x gear x efficiency (CiA 402)."""
        return self.rated_torque_mnm / 1000 * self.gear[0] / self.gear[1] * self.gear_efficiency

    def node_spec(self, limit: bool = False, sim: bool = False) -> str:
        """The programs' --node value: ID, then what the table gives (arm_controller and
        arm_canopen_boot check the drive against it; arm_sim commissions its drive with it), the
        gear's efficiency, whether a drive without a master watchdog is accepted, (limit:
        arm_canopen_boot's, which has no arm) the joint's torque limit the drive must give, and (sim:
        arm_sim's) the max torque 0x6072 of a motor sized below the limit, which the master reads
        from the drive as it reads a real one's."""
        spec = [str(self.node)]
        if "0x6076" in self.given:  # in the drive's own unit
            spec.append(f"rated={round(self.rated_torque_mnm * TORQUE_UNITS[self.torque_unit] / 1000)}")
        if "0x608F" in self.given:
            spec.append(f"encoder={self.encoder_increments}")
        if "0x6091" in self.given:
            spec.append(f"gear={self.gear[0]}/{self.gear[1]}")
        if self.torque_unit != "mNm":
            spec.append(f"torque_unit={self.torque_unit}")
        if self.gear_efficiency != 1.0:
            spec.append(f"efficiency={self.gear_efficiency:g}")
        if self.accept_no_master_watchdog:
            spec.append(f"{drive_check.ACCEPT_NO_WATCHDOG}=true")
        if self.quick_stop_deceleration is not None:
            spec.append(f"quick_stop={self.quick_stop_deceleration}")
        if sim and "0x6072" in self.given:
            spec.append(f"max={self.max_torque_permille}")
        if limit and self.joint_torque_limit_nm > 0:
            spec.append(f"limit={self.joint_torque_limit_nm:g}")
        return ",".join(spec)


@dataclass
class DriveConfig:
    path: str
    eds: str
    heartbeat_ms: int
    consumer_ms: int
    master_id: int
    cycle_us: int
    drives: list[Drive]
    # [pdo] transmission: CiA 301 transmission type per PDO (1: every SYNC)
    transmission: dict[str, int] = field(default_factory=lambda: dict(DEFAULT_TRANSMISSION))

    def boot_args(self, bus: str) -> list[str]:
        on_bus = [d for d in self.drives if d.bus == bus]
        if not on_bus:
            raise DrivesError(f"--boot-args {bus}: no drive is on bus '{bus}' "
                              f"(buses: {', '.join(sorted({d.bus for d in self.drives}))})")
        args = ["--cycle-us", str(self.cycle_us), "--heartbeat-ms", str(self.heartbeat_ms),
                "--consumer-ms", str(self.consumer_ms), "--master-id", str(self.master_id)]
        for d in on_bus:
            args += ["--node", d.node_spec(limit=True)]
        return args


def file_units(d: eds_mod.Dictionary) -> dict[str, Any]:
    """The file's rated torque (in the drive's unit), encoder increments per motor revolutions and
    gear, where it has them (a DCF's ParameterValue over the DefaultValue); None where it has not."""
    def num(index: int, sub: int) -> int | None:
        e = d.get(index, sub)
        return int(e.value(0)) if e is not None and isinstance(e.default, int) else None

    enc, revs = num(0x608F, 1), num(0x608F, 2)
    motor, shaft = num(0x6091, 1), num(0x6091, 2)
    return {"rated": num(0x6076, 0), "encoder": enc or None, "encoder_revs": revs or 1,
            "gear": None if not motor else (motor, shaft or 1)}


def _uint(v: Any, where: str, lo: int = 1, hi: int = U32_MAX) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise DrivesError(f"{where}: expected an integer {lo}..{hi}, got {v!r}")
    return v


def _mapping(v: Any, where: str) -> list[tuple[int, int, int]]:
    if not isinstance(v, list) or not all(isinstance(e, str) for e in v):
        raise DrivesError(f"{where}: expected a list of \"INDEX:SUB:BITS\" strings, got {v!r}")
    out = []
    for e in v:
        try:
            idx, sub, bits = (int(x, 0) for x in e.split(":"))
        except ValueError as exc:
            raise DrivesError(f"{where}: '{e}' is not INDEX:SUB:BITS (e.g. 0x6040:0:16)") from exc
        out.append((idx, sub, bits))
    return out


def _fmt(m: list[tuple[int, int, int]]) -> str:
    return ", ".join(f"0x{i:04X}:{s}:{b}" for i, s, b in m)


@dataclass(frozen=True)
class TableUnits:
    """The units a table gives for one drive (None where it gives none)."""
    rated_nm: float | None          # 0x6076, the motor's rated torque, N m
    encoder: int | None             # increments per motor revolution
    gear: tuple[int, int] | None    # motor, shaft revolutions
    unit: str                       # 0x6076's unit (TORQUE_UNITS)
    efficiency: float               # the gear's: the joint gets 0x6076 x gear x it
    max_permille: int | None = None  # 0x6072: a motor the importer sized below the joint's limit gives it so


def _units(get: Callable[[str], tuple[Any, str]], torque_limit: float | None,
           file_gear: tuple[int, int] | None, sized_nm: float | None = None) -> TableUnits:
    """The units a table gives. get(key) -> (value or None, where it is); torque_limit: the joint's
    (None: no arm); file_gear: the drive file's 0x6091 (for "joint_torque_limit / gear"); sized_nm:
    the motor's rated torque at the joint where the importer sized it below the limit (arm.json's
    motor_rated_torque_at_joint_nm: a drive rated at the limit would step too coarsely for the link),
    which "joint_torque_limit / gear" then takes, with the 0x6072 that gives the limit."""
    unit, w = get("torque_unit")
    if unit is None:
        unit = "mNm"
    if unit not in TORQUE_UNITS:
        raise DrivesError(f"{w}: expected one of {', '.join(TORQUE_UNITS)} (0x6076's unit), got {unit!r}")
    enc_v, w = get("encoder_increments")
    enc = None if enc_v is None else _uint(enc_v, w)
    gear_v, w = get("gear")
    gear = None
    if gear_v is not None:
        if not isinstance(gear_v, list) or len(gear_v) != 2:
            raise DrivesError(f"{w}: expected [motor revolutions, shaft revolutions], got {gear_v!r}")
        gear = (_uint(gear_v[0], w), _uint(gear_v[1], w))
    eff_v, w = get("gear_efficiency")
    efficiency = 1.0 if eff_v is None else eff_v
    if isinstance(efficiency, bool) or not isinstance(efficiency, (int, float)) or not 0 < efficiency <= 1:
        raise DrivesError(f"{w}: expected the gear's efficiency, above 0 and at most 1 (a strain-wave gear's is "
                          f"about 0.7-0.85), got {eff_v!r}")
    rated_v, w = get("rated_torque_nm")
    if rated_v == "joint_torque_limit":  # the joint's torque as 0x6076: what CiA 402 does not define
        raise DrivesError(f"{w}: \"joint_torque_limit\": 0x6076 is the motor's rated torque (CiA 402), the joint "
                          f"gets it times the gear; \"{JOINT_TORQUE_LIMIT}\" is the motor that gives the joint's limit")
    max_permille = None
    if rated_v == JOINT_TORQUE_LIMIT:
        through = gear or file_gear
        if torque_limit is None:
            rated_v = None
        elif through is None:
            raise DrivesError(f"{w}: \"{JOINT_TORQUE_LIMIT}\": neither the table nor the drive's file gives the gear")
        else:  # rounded up to the drive's unit: the drive gives at least the joint's limit at 1000 per-mille
            per_unit = TORQUE_UNITS[unit]
            at_joint = torque_limit if sized_nm is None else sized_nm
            rated_v = math.ceil(round(at_joint / (through[0] / through[1]) / efficiency * per_unit, 6)) / per_unit
            if sized_nm is not None:  # the least per-mille of that motor that gives the joint's limit
                joint_rated = rated_v * through[0] / through[1] * efficiency
                max_permille = min(math.ceil(round(torque_limit / joint_rated * 1000, 6)), drive_check.MAX_PERMILLE)
    if rated_v is None:
        return TableUnits(None, enc, gear, unit, float(efficiency))
    top = U32_MAX / TORQUE_UNITS[unit]
    if isinstance(rated_v, bool) or not isinstance(rated_v, (int, float)) or not math.isfinite(rated_v) \
            or not 1 / TORQUE_UNITS[unit] <= rated_v <= top:
        raise DrivesError(f"{w}: expected the motor's rated torque in N m, {1 / TORQUE_UNITS[unit]:g}..{top:g} (or "
                          f"\"{JOINT_TORQUE_LIMIT}\"), got {rated_v!r}")
    return TableUnits(float(rated_v), enc, gear, unit, float(efficiency), max_permille)


def _stopping(get: Callable[[str], tuple[Any, str]], torque_limit: float | None) -> tuple[
        tuple[float, float, float] | None, int | None]:
    """The brake a table gives (holding torque in N m at the joint, or "joint_torque_limit"; closing
    and release delays in ms: all three or none) and 0x6085 in the drive's own unit."""
    given = {k: get(k) for k in BRAKE_FIELDS}
    have = [k for k in BRAKE_FIELDS if given[k][0] is not None]
    brake = None
    if have:
        missing = [k for k in BRAKE_FIELDS if given[k][0] is None]
        if missing:
            raise DrivesError(f"{given[missing[0]][1]}: missing: a brake needs {', '.join(BRAKE_FIELDS)} "
                              f"(given: {', '.join(have)})")
        hold, w = given["brake_holding_nm"]
        if hold == BRAKE_JOINT_TORQUE_LIMIT:
            hold = torque_limit
        if isinstance(hold, bool) or not isinstance(hold, (int, float)) or not math.isfinite(hold) \
                or not 0 < hold <= 1e6:
            raise DrivesError(f"{w}: expected a holding torque in N m at the joint, (0, 1e6] (or "
                              f"\"{BRAKE_JOINT_TORQUE_LIMIT}\"), got {hold!r}")
        delays = []
        for k in ("brake_close_ms", "brake_release_ms"):
            v, w = given[k]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not 0 <= v <= 10000:
                raise DrivesError(f"{w}: expected a delay in ms, 0..10000, got {v!r}")
            delays.append(float(v))
        brake = (float(hold), delays[0], delays[1])
    qs_v, w = get("quick_stop_deceleration")
    qs = None if qs_v is None else _uint(qs_v, w)
    return brake, qs


def _in_unit(rated_nm: float | None, unit: str) -> int | None:
    """A rated torque in N m as the drive's 0x6076 holds it."""
    return None if rated_nm is None else round(rated_nm * TORQUE_UNITS[unit])


def table_plan(path: Path) -> tuple[drive_check.Plan, Path]:
    """A drive table's boot plan for any of its drives, from its top-level fields and [defaults]
    alone (no arm: armctl drive check), and the drive file it names."""
    doc = _read(path)
    defaults = doc.get("defaults", {})
    if not isinstance(defaults, dict) or set(defaults) - JOINT_FIELDS:
        raise DrivesError(f"{path}: defaults: expected a table of {', '.join(sorted(JOINT_FIELDS))}")

    def get(key: str) -> tuple[Any, str]:
        return defaults.get(key), f"{path}: defaults.{key}"

    u = _units(get, None, None)
    node = _uint(defaults.get("node", 1), f"{path}: defaults.node", 1, 127)
    eds_rel = doc.get("eds")
    eds = Path(str(eds_rel)) if eds_rel and Path(str(eds_rel)).is_absolute() else path.parent / str(eds_rel or "")
    plan = drive_check.Plan(node=node, heartbeat_ms=_uint(doc.get("heartbeat_ms", 100), f"{path}: heartbeat_ms", 0, 65535),
                            consumer_ms=_uint(doc.get("consumer_ms", 300), f"{path}: consumer_ms", 0, 65535),
                            master_id=_uint(doc.get("master_id", 127), f"{path}: master_id", 1, 127),
                            transmission=_pdo(doc, path), rated=_in_unit(u.rated_nm, u.unit), encoder=u.encoder,
                            gear=u.gear, units_per_nm=TORQUE_UNITS[u.unit], gear_efficiency=u.efficiency,
                            accept_no_master_watchdog=_accept_no_watchdog(doc, path))
    return plan, eds.resolve()


def _accept_no_watchdog(doc: dict[str, Any], path: Path) -> bool:
    v = doc.get(drive_check.ACCEPT_NO_WATCHDOG, False)
    if not isinstance(v, bool):
        raise DrivesError(f"{path}: {drive_check.ACCEPT_NO_WATCHDOG}: expected true or false (true: a drive without a "
                          f"settable 0x1016.1 boots, and a dead master leaves it applying its last torque), got {v!r}")
    return v


def drives_file_of(arm: dict[str, Any]) -> Path:
    """The arm file's `drives` field, else the default file."""
    arm_file = arm.get("arm_file")
    if arm_file:
        try:
            doc = toml_input.loads(Path(arm_file).read_text())
        except (OSError, tomllib.TOMLDecodeError) as exc:
            raise DrivesError(f"arm file {arm_file}: {exc}") from exc
        v = doc.get("drives")
        if v is not None:
            if not isinstance(v, str) or not v:
                raise DrivesError(f"arm file {arm_file}: drives: expected a file path, got {v!r}")
            p = Path(v)
            return p if p.is_absolute() else (Path(arm_file).parent / p).resolve()
    return DEFAULT_DRIVES


def _read(path: Path) -> dict[str, Any]:
    try:
        return toml_input.loads(path.read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise DrivesError(f"{path}: {exc}") from exc


def _pdo(doc: dict[str, Any], path: Path) -> dict[str, int]:
    """The table's [pdo]: its mapping checked against the codec's, and its transmission types."""
    pdo = doc.get("pdo", {})
    if not isinstance(pdo, dict) or set(pdo) - set(CODEC_MAPPING) - {"transmission"}:
        raise DrivesError(f"{path}: pdo: expected a table of rpdo1, tpdo1, tpdo2, transmission")
    trans_v = pdo.get("transmission", {})
    if not isinstance(trans_v, dict) or set(trans_v) - set(DEFAULT_TRANSMISSION):
        raise DrivesError(f"{path}: pdo.transmission: expected a table of rpdo1, tpdo1, tpdo2 (CiA 301 types)")
    transmission = {**DEFAULT_TRANSMISSION, **trans_v}
    allowed = {"rpdo1": (set(range(1, 241)) | {254, 255}, "1..240, 254 or 255"), "tpdo1": ({1}, "1 (the joint "
               "state, every SYNC)"), "tpdo2": (set(range(1, 241)), "1..240 (every n-th SYNC)")}
    for name, v in transmission.items():
        if isinstance(v, bool) or not isinstance(v, int) or v not in allowed[name][0]:
            raise DrivesError(f"{path}: pdo.transmission.{name}: expected {allowed[name][1]}, got {v!r}")
    for name, want in CODEC_MAPPING.items():
        if name in pdo:
            got = _mapping(pdo[name], f"{path}: pdo.{name}")
            if got != want:
                raise DrivesError(f"{path}: pdo.{name}: the codec (firmware/canopen co_pdo.c) packs {_fmt(want)}, "
                                  f"not {_fmt(got)}")
    return transmission


def load_transmission(path: Path | None = None) -> dict[str, int]:
    """A drive table's PDO transmission types alone (armctl busload: what the load counts)."""
    path = path or DEFAULT_DRIVES
    return _pdo(_read(path), path)


def load(arm: dict[str, Any], path: Path | None = None) -> DriveConfig:
    """The drive configuration of the arm (arm.json as a dict), resolved and validated."""
    path = path or drives_file_of(arm)
    doc = _read(path)
    unknown = set(doc) - TOP_FIELDS
    if unknown:
        raise DrivesError(f"{path}: unknown field(s) {', '.join(sorted(unknown))} (known: {', '.join(sorted(TOP_FIELDS))})")
    eds_rel = doc.get("eds")
    if not isinstance(eds_rel, str) or not eds_rel:
        raise DrivesError(f"{path}: eds: expected the drives' EDS file, got {eds_rel!r}")
    eds = Path(eds_rel) if Path(eds_rel).is_absolute() else (path.parent / eds_rel).resolve()
    try:
        dictionary = eds_mod.load(eds)
    except eds_mod.EdsError as exc:
        raise DrivesError(f"{path}: eds: {exc}") from None
    units = file_units(dictionary)
    heartbeat = _uint(doc.get("heartbeat_ms", 100), f"{path}: heartbeat_ms", 0, 65535)
    consumer = _uint(doc.get("consumer_ms", 300), f"{path}: consumer_ms", 0, 65535)
    master = _uint(doc.get("master_id", 127), f"{path}: master_id", 1, 127)
    accept = _accept_no_watchdog(doc, path)
    transmission = _pdo(doc, path)
    cycle_us = round(1e6 / float(arm.get("loop_rate_hz", 1000.0)))
    defaults = doc.get("defaults", {})
    joints_tab = doc.get("joint", {})
    if not isinstance(defaults, dict) or not isinstance(joints_tab, dict):
        raise DrivesError(f"{path}: defaults and joint must be tables")
    joints = [j["name"] for j in arm["joints"]]
    for name, t in joints_tab.items():
        if name not in joints:
            raise DrivesError(f"{path}: joint.{name}: not a joint of the arm ({', '.join(joints)})")
        if not isinstance(t, dict):
            raise DrivesError(f"{path}: joint.{name}: expected a table")
    for where, t in [("defaults", defaults)] + [(f"joint.{n}", t) for n, t in joints_tab.items()]:
        extra = set(t) - JOINT_FIELDS
        if extra:
            raise DrivesError(f"{path}: {where}: unknown field(s) {', '.join(sorted(extra))} "
                              f"(known: {', '.join(sorted(JOINT_FIELDS))})")
    bus_of = {d: b["name"] for b in arm.get("buses", []) for d in b["drives"]}
    out: list[Drive] = []
    for i, j in enumerate(arm["joints"]):
        name, num = j["name"], i + 1
        t = joints_tab.get(name, {})
        src = f"joint.{name}" if name in joints_tab else "defaults"

        def get(key: str) -> tuple[Any, str]:
            if key in t:
                return t[key], f"{path}: joint.{name}.{key}"
            if key in defaults:
                return defaults[key], f"{path}: defaults.{key}"
            return None, f"{path}: {src}.{key}"

        node_v, w = get("node")
        node = _uint(num if node_v is None else node_v, w, 1, 127)
        u = _units(get, j["torque_limit"], units["gear"], j.get("motor_rated_torque_at_joint_nm"))
        given = [o for o, v in (("0x6076", u.rated_nm), ("0x608F", u.encoder), ("0x6091", u.gear),
                                ("0x6072", u.max_permille)) if v is not None]
        plan = drive_check.Plan(node=node, cycle_us=cycle_us, heartbeat_ms=heartbeat, consumer_ms=consumer,
                                master_id=master, transmission=transmission, rated=_in_unit(u.rated_nm, u.unit),
                                encoder=u.encoder, gear=u.gear, units_per_nm=TORQUE_UNITS[u.unit],
                                gear_efficiency=u.efficiency, accept_no_master_watchdog=accept)
        report = drive_check.check(dictionary, plan)
        if not report.ok:
            raise DrivesError(f"{path}: joint {name} (node {node}): {eds.name}: {report.problems[0]}")
        if num not in bus_of:
            raise DrivesError(f"arm.json: drive {num} (joint {name}) is on no bus")
        rated_mnm = u.rated_nm * 1000 if u.rated_nm is not None else units["rated"] * 1000 / TORQUE_UNITS[u.unit]
        brake, quick_stop = _stopping(get, j["torque_limit"])
        d = Drive(name, num, bus_of[num], node, rated_mnm, u.encoder if u.encoder is not None else units["encoder"],
                  u.gear if u.gear is not None else units["gear"], given,
                  [f"warning: {x}" for x in report.warnings] + report.notes,
                  1 if u.encoder is not None else units["encoder_revs"], u.unit, u.efficiency, float(j["torque_limit"]),
                  u.max_permille or report.max_permille, accept, brake, quick_stop)
        _check_torque_limit(path, d)
        out.append(d)
    for b in {d.bus for d in out}:
        nodes = [d.node for d in out if d.bus == b]
        dup = sorted({n for n in nodes if nodes.count(n) > 1})
        if dup:
            raise DrivesError(f"{path}: node: node id {dup[0]} is used twice on bus {b}")
        if master in nodes:
            raise DrivesError(f"{path}: master_id: {master} is a drive's node id on bus {b}")
    return DriveConfig(str(path), str(eds), heartbeat, consumer, master, cycle_us, out, transmission)


def _check_torque_limit(path: Path, d: Drive) -> None:
    """The joint's torque limit must be within what its drive gives at the joint: 0x6072 x 0x6076 x
    gear x efficiency (the boot checks the drive's own 0x6072 again)."""
    most = d.max_torque_permille * d.joint_rated_torque_nm / 1000
    if most < d.joint_torque_limit_nm * (1 - 1e-6):
        unit = "uN m" if d.torque_unit == "uNm" else "mN m"
        raise DrivesError(f"{path}: joint {d.joint} (node {d.node}): its torque limit {d.joint_torque_limit_nm:g} N m "
                          f"is more than its drive gives at the joint, {most:.6g} N m = 0x6072 "
                          f"{d.max_torque_permille} per-mille x 0x6076 "
                          f"{round(d.rated_torque_mnm * TORQUE_UNITS[d.torque_unit] / 1000)} {unit} (the motor's) x "
                          f"gear {d.gear[0]}/{d.gear[1]} x efficiency {d.gear_efficiency:g}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m gen.drives", description=__doc__.split("\n\n")[0])
    p.add_argument("--arm-json", type=Path, required=True, help="the prepared arm (build/<preset>/generated/arm/arm.json)")
    p.add_argument("--drives", type=Path, default=None, help="the drive configuration [the arm file's, else "
                   "firmware/protocol/drives.toml]")
    p.add_argument("--boot-args", metavar="BUS", default=None,
                   help="print arm_canopen_boot's options for the drives of this bus (shell words)")
    a = p.parse_args(argv)
    try:
        try:
            arm = json.loads(a.arm_json.read_text())
        except (OSError, ValueError) as exc:
            raise DrivesError(f"--arm-json {a.arm_json}: {exc}") from exc
        cfg = load(arm, a.drives)
        if a.boot_args is not None:
            print(shell_command(cfg.boot_args(a.boot_args)))
        else:
            print(json.dumps(asdict(cfg), indent=2))
    except DrivesError as exc:
        print(f"gen.drives: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
