"""The arm's CiA 402 drive configuration (firmware/protocol/drives.toml, or the arm file's
`drives = "FILE"`), resolved per joint, and the arm_canopen_boot options it makes.

    python -m gen.drives --arm-json build/debug/generated/arm/arm.json            # the table, JSON
    python -m gen.drives --arm-json ... --boot-args can0                          # one bus's options

Rule (docs/drives.md, The CANopen master): a joint's field is its [joint.NAME] value, else
[defaults], else node = the drive's number, rated_torque_nm = the joint's torque limit (arm.json),
encoder and gear = the EDS defaults. An override is written at boot only where it differs from the
EDS. Bad input: one line naming the file and the field, exit 2.
"""

from __future__ import annotations

import argparse
import configparser
import json
import math
import shlex
import sys
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from gen.lib.cia402 import CODEC_MAPPING
from gen.lib import toml_input

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DRIVES = ROOT / "firmware" / "protocol" / "drives.toml"
TOP_FIELDS = {"eds", "heartbeat_ms", "consumer_ms", "master_id", "defaults", "joint", "pdo"}
JOINT_FIELDS = {"node", "encoder_increments", "gear", "rated_torque_nm"}
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
    rated_torque_mnm: int   # 0x6076
    encoder_increments: int  # 0x608F.1
    gear: tuple[int, int]   # 0x6091.1, .2
    overrides: list[str]    # objects written at boot because they differ from the EDS

    def node_spec(self) -> str:
        """The programs' --node value: ID, then only what the drive overrides of the EDS."""
        spec = [str(self.node)]
        if "0x6076" in self.overrides:
            spec.append(f"rated={self.rated_torque_mnm}")
        if "0x608F" in self.overrides:
            spec.append(f"encoder={self.encoder_increments}")
        if "0x6091" in self.overrides:
            spec.append(f"gear={self.gear[0]}/{self.gear[1]}")
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
            args += ["--node", d.node_spec()]
        return args


def eds_defaults(path: Path) -> dict[str, int]:
    """The EDS's rated torque, encoder increments and gear (DefaultValue of 6076, 608Fsub1, 6091sub1/2)."""
    cp = configparser.ConfigParser(interpolation=None, strict=False)
    try:
        if not cp.read(path):
            raise DrivesError(f"{path}: cannot read the EDS")
        out = {}
        for key, (sec, fld) in {"rated": ("6076", "DefaultValue"), "encoder": ("608Fsub1", "DefaultValue"),
                                "gear_motor": ("6091sub1", "DefaultValue"),
                                "gear_shaft": ("6091sub2", "DefaultValue")}.items():
            out[key] = int(cp[sec][fld], 0)
        return out
    except (configparser.Error, KeyError, ValueError) as exc:
        raise DrivesError(f"{path}: not an EDS with 0x6076, 0x608F and 0x6091 defaults ({exc})") from exc


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
    eds_def = eds_defaults(eds)
    heartbeat = _uint(doc.get("heartbeat_ms", 100), f"{path}: heartbeat_ms", 0, 65535)
    consumer = _uint(doc.get("consumer_ms", 300), f"{path}: consumer_ms", 0, 65535)
    master = _uint(doc.get("master_id", 127), f"{path}: master_id", 1, 127)
    transmission = _pdo(doc, path)
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

        def get(key: str, fallback: Any) -> tuple[Any, str]:
            if key in t:
                return t[key], f"{path}: joint.{name}.{key}"
            if key in defaults:
                return defaults[key], f"{path}: defaults.{key}"
            return fallback, f"{path}: {src}.{key}"

        node_v, w = get("node", num)
        node = _uint(node_v, w, 1, 127)
        enc_v, w = get("encoder_increments", eds_def["encoder"])
        enc = _uint(enc_v, w)
        gear_v, w = get("gear", [eds_def["gear_motor"], eds_def["gear_shaft"]])
        if not isinstance(gear_v, list) or len(gear_v) != 2:
            raise DrivesError(f"{w}: expected [motor revolutions, shaft revolutions], got {gear_v!r}")
        gear = (_uint(gear_v[0], w), _uint(gear_v[1], w))
        rated_v, w = get("rated_torque_nm", j["torque_limit"])
        if isinstance(rated_v, bool) or not isinstance(rated_v, (int, float)) or not math.isfinite(rated_v) \
                or not 0.001 <= rated_v <= U32_MAX / 1000:
            raise DrivesError(f"{w}: expected a torque in N m, 0.001..{U32_MAX / 1000:g}, got {rated_v!r}")
        rated = round(rated_v * 1000)
        overrides = ([o for o, differs in (("0x6076", rated != eds_def["rated"]),
                                           ("0x608F", enc != eds_def["encoder"]),
                                           ("0x6091", gear != (eds_def["gear_motor"], eds_def["gear_shaft"])))
                      if differs])
        if num not in bus_of:
            raise DrivesError(f"arm.json: drive {num} (joint {name}) is on no bus")
        out.append(Drive(name, num, bus_of[num], node, rated, enc, gear, overrides))
    for b in {d.bus for d in out}:
        nodes = [d.node for d in out if d.bus == b]
        dup = sorted({n for n in nodes if nodes.count(n) > 1})
        if dup:
            raise DrivesError(f"{path}: node: node id {dup[0]} is used twice on bus {b}")
        if master in nodes:
            raise DrivesError(f"{path}: master_id: {master} is a drive's node id on bus {b}")
    rate = float(arm.get("loop_rate_hz", 1000.0))
    return DriveConfig(str(path), str(eds), heartbeat, consumer, master, round(1e6 / rate), out, transmission)


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
            print(shlex.join(cfg.boot_args(a.boot_args)))
        else:
            print(json.dumps(asdict(cfg), indent=2))
    except DrivesError as exc:
        print(f"gen.drives: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
