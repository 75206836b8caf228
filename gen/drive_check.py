"""What the CANopen master needs from a CiA 402 drive, and whether a drive's EDS or DCF gives it:
every object the boot reads or writes (firmware/canopen co_boot.c), checked against the file's
objects, access types, data types, limits and PDO mapping rules before any frame goes out.

`armctl drive check FILE` prints check()'s problems (one line each: why this controller cannot run
the drive), warnings (the file's own harmless mistakes, by line: gen/eds.py) and notes (what the
master skips or takes from the drive table, and the torque at the joint); gen/drives.py refuses a
drive table whose drive has a problem, before a boot starts. docs/drives-bring-up.md has the table
of NEEDS."""

from __future__ import annotations

from dataclasses import dataclass, field

from gen.eds import Dictionary, Entry
from gen.lib.cia402 import CODEC_MAPPING, PDO_COB
from gen.lib.params import default

PROFILE = 0x0192              # CiA 402, the low word of 0x1000
CST_MODE = 10                 # cyclic synchronous torque, the mode this controller commands torque in
PDO_INVALID = 0x80000000
# 0x6502's bits (CiA 402): bit k is mode k + 1; 16..31 are the manufacturer's
MODE_NAMES = {0: "pp", 1: "vl", 2: "pv", 3: "tq", 5: "hm", 6: "ip", 7: "csp", 8: "csv", 9: "cst", 10: "cstca"}
COMM = {"rpdo1": 0x1400, "tpdo1": 0x1800, "tpdo2": 0x1801}
MAPPING = {"rpdo1": 0x1600, "tpdo1": 0x1A00, "tpdo2": 0x1A01}

REQUIRED, OPTIONAL, TABLE = "required", "written only if present", "read if present, else the drive table's"
READ_IF_PRESENT = "read if present"
WATCHDOG = "required, unless the drive table accepts its absence"
ACCEPT_NO_WATCHDOG = "accept_no_master_watchdog"  # the drive table's field that accepts a drive without 0x1016
MAX_PERMILLE = 32767  # a target torque's range (INTEGER16): the most a drive without 0x6072 is asked for


@dataclass(frozen=True)
class Need:
    objects: str
    need: str
    what: str


# The master's needs, in boot order: the table docs/drives-bring-up.md shows (a test holds them equal).
NEEDS = [
    Need("0x1000", REQUIRED, "device type: its low word must be 0x0192 (CiA 402); the high word is the device's"),
    Need("0x1018.1", REQUIRED, "vendor id (checked when the drive table names one)"),
    Need("0x1018.2-4", READ_IF_PRESENT, "product code, revision, serial: recorded"),
    Need("0x6502", READ_IF_PRESENT, "supported drive modes: bit 9 (cyclic synchronous torque) must be set"),
    Need("0x6076", TABLE, "the motor's rated torque (mN m, or the drive table's torque_unit): 0x6071/0x6077 are "
         "per-mille of it, and the joint gets it times the gear (and its efficiency); never written"),
    Need("0x608F.1-2", TABLE, "encoder increments per motor revolutions; never written"),
    Need("0x6091.1-2", TABLE, "gear ratio, motor per shaft revolutions; never written"),
    Need("0x6072", READ_IF_PRESENT, "max torque, per-mille: the target torque is saturated to it, and the joint's "
         "torque limit must be within it x 0x6076 x gear"),
    Need("0x6040, 0x6041", REQUIRED, "controlword (written) and statusword (read): the power state machine"),
    Need("0x1400/0x1600", REQUIRED, "RPDO1: COB-ID, type, mapping 0x6040 + 0x6071 (target torque) written"),
    Need("0x1800/0x1A00", REQUIRED, "TPDO1: mapping 0x6064 + 0x606C (position, velocity actual) written"),
    Need("0x1801/0x1A01", REQUIRED, "TPDO2: mapping 0x6077 + 0x6041 (torque actual, statusword) written"),
    Need("0x1006", OPTIONAL, "communication cycle period, us"),
    Need("0x1017", OPTIONAL, "producer heartbeat, ms"),
    Need("0x1016.1", WATCHDOG, "consumer heartbeat: the drive faults if the master's heartbeat stops; without it a "
         "dead master leaves the drive applying its last torque"),
    Need("0x605A", "written 2 where present and writable",
         "quick stop option: the quick stop ramp, then switch on disabled (the brake closed)"),
    Need("0x605E", "written 2 where present and writable", "fault reaction option: the quick stop ramp"),
    Need("0x6085", "written where present, if the drive table gives it", "quick stop deceleration, in the drive's own unit"),
    Need("0x6060, 0x6061", REQUIRED, "mode of operation 10 (CST) written, then read back"),
]


@dataclass(frozen=True)
class Plan:
    """What the boot writes to one drive (gen/drives.py DriveConfig's values)."""
    node: int = 1
    cycle_us: int = 1000
    heartbeat_ms: int = default("controller", "heartbeat-ms")  # arm_controller's defaults
    consumer_ms: int = default("controller", "consumer-ms")
    master_id: int = default("controller", "master-id")
    transmission: dict[str, int] = field(default_factory=lambda: {"rpdo1": 1, "tpdo1": 1, "tpdo2": 1})
    # the drive table's units (None: not given): the boot compares the drive's objects with them
    rated: int | None = None  # 0x6076, the motor's, in the drive's torque unit (mN m unless the table names another)
    encoder: int | None = None
    gear: tuple[int, int] | None = None
    units_per_nm: int = 1000           # 0x6076's unit per N m (the table's torque_unit)
    gear_efficiency: float = 1.0       # the table's: the joint gets 0x6076 x gear x it
    accept_no_master_watchdog: bool = False  # the table accepts a drive without a settable 0x1016.1


@dataclass
class Report:
    problems: list[str] = field(default_factory=list)  # why this controller cannot run the drive
    notes: list[str] = field(default_factory=list)     # what the boot skips, or takes from the drive table
    warnings: list[str] = field(default_factory=list)  # the file's harmless mistakes, "FILE:LINE: ..." (gen/eds.py)
    joint_rated_nm: float | None = None                # 1000 per-mille at the joint: 0x6076 x gear x efficiency
    max_permille: int = MAX_PERMILLE                   # 0x6072 (the file's), else the per-mille's range

    @property
    def max_joint_torque_nm(self) -> float | None:
        """The most the drive gives at the joint, N m (0x6072 x 0x6076 x gear x efficiency)."""
        return None if self.joint_rated_nm is None else self.max_permille * self.joint_rated_nm / 1000

    @property
    def ok(self) -> bool:
        return not self.problems


def modes_text(modes: int) -> str:
    names = [name for bit, name in MODE_NAMES.items() if modes >> bit & 1]
    if modes >> 16:
        names.append("manufacturer-specific")
    return ", ".join(names) or "none"


def _obj(index: int, sub: int) -> str:
    return f"0x{index:04X}:{sub:02X}"


def _writes(p: Plan) -> list[tuple[int, int, int, int, bool, str]]:
    """(index, sub, bytes, value, optional, what) of every SDO download, in the master's order."""
    out: list[tuple[int, int, int, int, bool, str]] = [(0x6040, 0, 2, 0x00, False, "controlword")]
    for name, mapping in CODEC_MAPPING.items():
        comm, m, cob = COMM[name], MAPPING[name], PDO_COB[name] + p.node
        label = name.upper()
        out.append((comm, 1, 4, cob | PDO_INVALID, False, f"{label} COB-ID"))
        out.append((m, 0, 1, 0, False, f"{label} mapping count"))
        for k, (index, sub, bits) in enumerate(mapping):
            out.append((m, k + 1, 4, index << 16 | sub << 8 | bits, False, f"{label} mapping entry {k + 1}"))
        out.append((m, 0, 1, len(mapping), False, f"{label} mapping count"))
        out.append((comm, 2, 1, p.transmission[name], False, f"{label} transmission type"))
        out.append((comm, 1, 4, cob, False, f"{label} COB-ID"))
    out += [(0x1006, 0, 4, p.cycle_us, True, "communication cycle period"),
            (0x1017, 0, 2, p.heartbeat_ms, True, "producer heartbeat"),
            (0x1016, 1, 4, p.master_id << 16 | p.consumer_ms, True, "consumer heartbeat"),
            (0x6060, 0, 1, CST_MODE, False, "mode of operation")]
    out += [(0x6040, 0, 2, cw, False, "controlword") for cw in (0x06, 0x07, 0x0F)]
    return out


def _in_limits(e: Entry, value: int) -> str | None:
    if e.type.kind == "int" and value >= 1 << (e.bits() - 1):
        value -= 1 << e.bits()
    if e.low is not None and value < e.low:
        return f"below its LowLimit {e.low}"
    if e.high is not None and value > e.high:
        return f"above its HighLimit {e.high}"
    return None


def _write_problem(d: Dictionary, index: int, sub: int, size: int, value: int) -> str | None:
    """Why the master's write of value cannot be done on the file's object (None: it can; "": the
    file has no such object)."""
    e = d.get(index, sub)
    if e is None:
        return ""
    if not e.writable:
        return f"access {e.access_raw}; the master writes 0x{value:X}"
    if e.type.size != size:
        return f"the file says {e.type.name}, the master writes {size} bytes (CiA 301's type)"
    why = _in_limits(e, value)
    return None if why is None else f"the master writes {value}, {why}"


def _check_write(d: Dictionary, r: Report, index: int, sub: int, size: int, value: int, optional: bool,
                 what: str) -> bool:
    where = f"{_obj(index, sub)} ({what})"
    why = _write_problem(d, index, sub, size, value)
    if why == "":
        if optional:
            if not d.has(index) or sub != 0:
                note = f"{where}: not in the file (optional in CiA 301): not written"
                if note not in r.notes:
                    r.notes.append(note)
            return False
        r.problems.append(f"{where}: not in the file; the master writes it")
        return False
    if why is not None:
        r.problems.append(f"{where}: {why}")
        return False
    return True


def _check_watchdog(d: Dictionary, r: Report, p: Plan) -> None:
    """0x1016.1, the drive's watchdog on the master: a drive on which the master cannot set it is
    refused, unless the drive table accepts what a dead master then leaves it doing."""
    value = p.master_id << 16 | p.consumer_ms
    why = "a consumer time of 0 ms turns it off" if p.consumer_ms == 0 else _write_problem(d, 0x1016, 1, 4, value)
    if why is None:
        return
    why = why or "not in the file"
    line = (f"0x1016:01 (consumer heartbeat, the drive's watchdog on the master): {why}; a dead master would leave "
            "this drive applying its last torque")
    if p.accept_no_master_watchdog:
        r.notes.append(f"{line} (the drive table accepts it: {ACCEPT_NO_WATCHDOG} = true)")
    else:
        r.problems.append(f"{line}; a drive table that accepts this says {ACCEPT_NO_WATCHDOG} = true")


def _joint_torque(d: Dictionary, r: Report, p: Plan) -> None:
    """What 1000 per-mille is at the joint (0x6076 x gear x efficiency) and the most the drive gives
    there (x 0x6072), from the table's units (the drive's must equal them) or the file's."""
    def num(index: int, sub: int = 0) -> int | None:
        e = d.get(index, sub)
        return int(e.value(p.node)) if e is not None and isinstance(e.default, int) else None

    rated = p.rated if p.rated is not None else num(0x6076)
    motor, shaft = num(0x6091, 1), num(0x6091, 2) or 1
    gear = p.gear if p.gear is not None else (motor, shaft) if motor else None
    max_permille = num(0x6072)
    r.max_permille = MAX_PERMILLE if max_permille is None else min(max_permille, MAX_PERMILLE)
    if not rated or gear is None or not gear[1]:
        return
    r.joint_rated_nm = rated / p.units_per_nm * gear[0] / gear[1] * p.gear_efficiency
    unit = "uN m" if p.units_per_nm == 1_000_000 else "mN m"
    r.notes.append(f"torque at the joint: 1000 per-mille is 0x6076 {rated} {unit} (the motor's) x gear {gear[0]}/"
                   f"{gear[1]} x efficiency {p.gear_efficiency:g} = {r.joint_rated_nm:.6g} N m; the drive gives at "
                   f"most {r.max_joint_torque_nm:.6g} N m ({r.max_permille} per-mille"
                   f"{'' if max_permille is not None else ', no 0x6072'})")


def _check_mapping(d: Dictionary, r: Report, name: str) -> None:
    mapping, m = CODEC_MAPPING[name], MAPPING[name]
    receive = name.startswith("r")
    capacity = max((e.sub for e in d.subs(m)), default=0)
    if d.has(m) and capacity < len(mapping):
        r.problems.append(f"0x{m:04X} ({name.upper()} mapping): {capacity} entries; the master maps {len(mapping)}")
    bits = 0
    for index, sub, n in mapping:
        bits += n
        e = d.get(index, sub)
        where = f"{_obj(index, sub)} in {name.upper()}"
        if e is None:
            r.problems.append(f"{where}: not in the file; the master maps it"
                              + (" (target torque: this controller commands torque)" if index == 0x6071 else ""))
            continue
        direction_ok = (e.writable and e.access_raw != "rwr") if receive else (e.readable and e.access_raw != "rww")
        if not e.pdo:
            r.problems.append(f"{where}: PDOMapping=0 in the file; the master maps it")
        elif not direction_ok:
            r.problems.append(f"{where}: access {e.access_raw} cannot be mapped to a{' receive' if receive else ' transmit'}"
                              " PDO")
        elif e.bits() != n:
            r.problems.append(f"{where}: the file says {e.type.name}, the master maps {n} bits")
    if bits > 64:
        r.problems.append(f"{name.upper()}: {bits} bits, more than a CAN frame's 64")


def _text(value: object) -> str:
    return "/".join(map(str, value)) if isinstance(value, tuple) else str(value)


def _unit(d: Dictionary, r: Report, index: int, label: str, field_name: str, given: object, subs: int) -> None:
    entries = [d.get(index, s) for s in (range(1, subs + 1) if subs else (0,))]
    if entries[0] is None:
        if given is None:
            r.problems.append(f"0x{index:04X} ({label}): not in the file, and the drive table gives no {field_name}")
        else:
            r.notes.append(f"0x{index:04X} ({label}): not in the file: the drive table's {field_name} {_text(given)} "
                           "is used")
        return
    values = [e.value(0) if e is not None else 1 for e in entries]
    file_value = values[0] if subs == 0 else tuple(values)
    configured = any(e is not None and e.configured for e in entries)
    if given is not None:
        want = given if subs == 0 else ((given, 1) if isinstance(given, int) else given)
        same = want == file_value if subs == 0 else want[0] * file_value[1] == want[1] * file_value[0]  # type: ignore[index]
        if not same and configured:
            r.problems.append(f"0x{index:04X} ({label}): the DCF configures {_text(file_value)}, the drive table says "
                              f"{_text(given)}: the boot would stop")


def check(d: Dictionary, plan: Plan | None = None) -> Report:
    """Can this controller run the drive the file describes, with this boot plan? (Report)"""
    p = plan or Plan()
    r = Report()
    dev = d.get(0x1000)
    if dev is None:
        r.problems.append("0x1000 (device type): not in the file (CiA 301 makes it mandatory)")
    elif isinstance(dev.default, int) and dev.default != 0 and dev.default & 0xFFFF != PROFILE:
        r.problems.append(f"0x1000 (device type): 0x{dev.default:08X}: profile 0x{dev.default & 0xFFFF:04X}, not CiA "
                          f"402 (0x{PROFILE:04X})")
    if d.get(0x1018, 1) is None:
        r.problems.append("0x1018:01 (vendor id): not in the file (CiA 301 makes it mandatory)")
    modes = d.get(0x6502)
    if modes is not None and isinstance(modes.default, int) and not modes.default >> (CST_MODE - 1) & 1:
        r.problems.append(f"0x6502 (supported drive modes) = 0x{modes.default:08X} ({modes_text(modes.default)}): no "
                          f"cyclic synchronous torque (mode {CST_MODE}, bit 9), which this controller needs")
    elif modes is None:
        r.notes.append("0x6502 (supported drive modes): not in the file: the mode write shows whether CST is there")
    _unit(d, r, 0x6076, "motor rated torque", "rated_torque_nm", p.rated, 0)
    _unit(d, r, 0x608F, "encoder increments", "encoder_increments", p.encoder, 2)
    _unit(d, r, 0x6091, "gear ratio", "gear", p.gear, 2)
    if d.get(0x6072) is None:
        r.notes.append("0x6072 (max torque): not in the file: the target torque is not saturated below 32767 per-mille")
    _joint_torque(d, r, p)
    for index, sub, what in ((0x6041, 0, "statusword"), (0x6061, 0, "mode of operation display")):
        e = d.get(index, sub)
        if e is None or not e.readable:
            r.problems.append(f"{_obj(index, sub)} ({what}): {'not in the file' if e is None else 'not readable'}; "
                              "the master reads it")
    for index, sub, size, value, optional, what in _writes(p):
        if index == 0x1016:
            _check_watchdog(d, r, p)
        else:
            _check_write(d, r, index, sub, size, value, optional, what)
    for name in CODEC_MAPPING:
        _check_mapping(d, r, name)
    r.problems = list(dict.fromkeys(r.problems))  # one line per problem: the controlword is written four times
    r.warnings = list(d.warnings)
    return r
