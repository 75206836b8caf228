"""Worst-case CAN bus load of the drive protocol per control period: the library gen/, host_sim/
and tools/ share (the command line, `armctl busload`, is tools/busload.py).

Reads firmware/protocol/arm_drives.dbc: the messages with a GenMsgCycleTime are sent once per
control period (SYNC, DRIVE_i_STATE, DRIVE_i_CMD); heartbeats are time-based (CANopen producer
time, --heartbeat-ms) and amortised over the periods; NMT and EMCY are events and not counted.
Each message goes on the bus of the drive it is sent to or from; SYNC (to every drive) goes on
every bus that has drives. Frame format (classic / FD, bit-rate switch) is the DBC's.

Frame lengths are exact worst cases (every bit the frame can take, including worst-case dynamic
stuffing and the 3-bit intermission):

Classic CAN (ISO 11898-1), n data bytes:
    11-bit id: 8n + 47 + floor((34 + 8n - 1) / 4) bits   (34 + 8n bits SOF..CRC are stuffed)
    29-bit id: 8n + 67 + floor((54 + 8n - 1) / 4) bits   (54 + 8n bits SOF..CRC are stuffed)
    e.g. 8 bytes, 11-bit: 64 + 47 + 24 = 135 bits. The worst case inserts a stuff bit after the
    first 5 bits and then after every 4 (the stuff bit starts the next run): floor((L - 1) / 4).

CAN FD (ISO 11898-1:2015, ISO CRC), n data bytes (a DLC step), id 11-bit (29-bit):
    nominal rate: SOF, id, RRS, IDE, FDF, res, BRS = 17 (36) bits, their worst-case stuff bits
                  floor((17 - 1) / 4) = 4 (floor((36 - 1) / 4) = 8), CRC delimiter 1, ACK slot 1,
                  ACK delimiter 1, EOF 7, intermission 3
    data rate:    ESI 1, DLC 4, data 8n, the rest of the dynamic stuff bits
                  floor((A + 5 + 8n - 1) / 4) - floor((A - 1) / 4) with A = 17 (36),
                  stuff count 4 (3-bit Gray count + parity), CRC 17 (n <= 16) or 21 (n > 16),
                  fixed stuff bits: one before the stuff count and one after every 4 bits of
                  stuff count + CRC: 6 with CRC17 (21 bits), 7 with CRC21 (25 bits)
    The bit rate switches inside BRS and inside the CRC delimiter (at their sample points); both
    boundary bits, and the stuff bits of the arbitration field, are counted at the slower nominal
    rate: the figures are upper bounds, never below the real length. Without BRS (or on a bus
    without a data rate) every bit is at the nominal rate.
    e.g. 16 bytes, 11-bit: nominal 17 + 4 + 13 = 34, data 1 + 4 + 128 + 33 + 4 + 17 + 6 = 193
    -> 34 us + 38.6 us = 72.6 us at 1 / 5 Mbit/s.

A message longer than 8 bytes on a classic bus (DRIVE_i_STATE is 16 bytes) is carried as
ceil(n / 8) frames of 8 bytes, the way a classic CiA 402 drive maps it onto two TPDOs.
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gen.lib.cia402 import CODEC_MAPPING, pdo_bytes
from gen.lib.params import constant, default
from gen.lib.paths import REPO

# The drives' heartbeat period the load counts: the one arm_controller writes to each drive by
# default (firmware/params/params.toml [controller.heartbeat-ms]); the busiest bus's load a design may take.
HEARTBEAT_MS: float = float(default("controller", "heartbeat-ms"))
BUS_BUDGET: float = constant("bus-budget")

DEFAULT_DBC = REPO / "firmware" / "protocol" / "arm_drives.dbc"
DEFAULT_TOPOLOGY = REPO / "firmware" / "protocol" / "buses.toml"
MAX_BUSES = 4  # the controller's bus limit: ARM_CAN_BUS_SET_MAX (firmware/transport/include/arm/can_bus.h)
FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)
# CRC delimiter, ACK slot, ACK delimiter, EOF, intermission: never stuffed, always nominal rate
TRAILER_BITS = 1 + 1 + 1 + 7 + 3


class ConfigError(ValueError):
    pass


def _worst_stuff(stuffed_bits: int) -> int:
    return (stuffed_bits - 1) // 4 if stuffed_bits > 0 else 0


def classic_frame_bits(n_bytes: int, extended: bool = False) -> int:
    """Worst-case length in bits of a classic data frame with n_bytes (0..8), incl. intermission."""
    if not 0 <= n_bytes <= 8:
        raise ValueError(f"classic CAN carries 0..8 data bytes, not {n_bytes}")
    # SOF 1, id 11 | (11 + SRR 1 + IDE 1 + 18), RTR 1, IDE/r1 1, r0 1, DLC 4, data, CRC 15
    stuffed = (1 + 11 + 1 + 1 + 1 + 4 if not extended else 1 + 11 + 1 + 1 + 18 + 1 + 1 + 1 + 4) + 8 * n_bytes + 15
    return stuffed + _worst_stuff(stuffed) + TRAILER_BITS


def fd_frame_bits(n_bytes: int, extended: bool = False, brs: bool = True) -> tuple[int, int]:
    """Worst-case (nominal-rate bits, data-rate bits) of a CAN FD data frame; with brs False all
    bits are returned as nominal-rate bits (data-rate count 0)."""
    if n_bytes not in FD_LENGTHS:
        raise ValueError(f"CAN FD data length must be one of {FD_LENGTHS}, not {n_bytes}")
    arb = 1 + 11 + 1 + 1 + 1 + 1 + 1 if not extended else 1 + 11 + 1 + 1 + 18 + 1 + 1 + 1 + 1
    ctrl_data = 1 + 4 + 8 * n_bytes  # ESI, DLC, data
    stuff_arb = _worst_stuff(arb)
    stuff_data = _worst_stuff(arb + ctrl_data) - stuff_arb
    crc = 17 if n_bytes <= 16 else 21
    crc_field = 4 + crc  # stuff count + CRC sequence
    fixed_stuff = 1 + (crc_field - 1) // 4  # one before the stuff count, then one per 4 bits
    nominal = arb + stuff_arb + TRAILER_BITS
    data = ctrl_data + stuff_data + crc_field + fixed_stuff
    return (nominal + data, 0) if not brs else (nominal, data)


@dataclass
class Bus:
    name: str
    fd: bool
    nominal_bps: float
    data_bps: float | None  # FD with bit-rate switch; None: no BRS
    drives: list[int]

    def describe(self) -> str:
        if not self.fd:
            return f"classic {_fmt_rate(self.nominal_bps)}"
        if self.data_bps is None:
            return f"CAN FD {_fmt_rate(self.nominal_bps)}, no bit-rate switch"
        return f"CAN FD {_fmt_rate(self.nominal_bps)} arbitration / {_fmt_rate(self.data_bps)} data"


@dataclass
class FrameLoad:
    message: str
    frames: int           # frames per occurrence (2 for a 16-byte message on classic)
    per_period: float     # occurrences per control period (heartbeat: a fraction)
    nominal_bits: int     # per frame
    data_bits: int        # per frame
    time_s: float         # per frame


@dataclass
class BusLoad:
    bus: Bus
    rate_hz: float
    frames: list[FrameLoad] = field(default_factory=list)
    periodic_s: float = 0.0      # bus time of the per-period frames, per period
    background_load: float = 0.0  # time-based traffic (heartbeats) as a fraction of bus time

    @property
    def load(self) -> float:
        return self.periodic_s * self.rate_hz + self.background_load

    def max_rate_hz(self, budget: float) -> float:
        if self.periodic_s <= 0:
            return math.inf
        return max(0.0, (budget - self.background_load) / self.periodic_s)


def _fmt_rate(bps: float) -> str:
    for unit, scale in (("Mbit/s", 1e6), ("kbit/s", 1e3)):
        if bps >= scale:
            return f"{bps / scale:g} {unit}"
    return f"{bps:g} bit/s"


def parse_rate(text: str) -> float:
    m = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]+)?)\s*([kKmM]?)\s*", text)
    if not m:
        raise ConfigError(f"bit rate '{text}': expected e.g. 500k, 1M, 5M or 1000000")
    v = float(m.group(1)) * {"": 1, "k": 1e3, "K": 1e3, "m": 1e6, "M": 1e6}[m.group(2)]
    if not 10e3 <= v <= 20e6:
        raise ConfigError(f"bit rate '{text}': outside 10 kbit/s .. 20 Mbit/s")
    return v


def parse_drives(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        a, sep, b = part.partition("-")
        try:
            lo, hi = int(a), int(b) if sep else int(a)
        except ValueError as exc:
            raise ConfigError(f"drives '{text}': expected e.g. 1-6 or 1,3,5") from exc
        if lo > hi:
            raise ConfigError(f"drives '{text}': range {part} is empty")
        out.extend(range(lo, hi + 1))
    return out


def parse_bus(text: str, index: int) -> Bus:
    """[NAME=]classic:RATE:DRIVES | [NAME=]fd:NOMINAL[/DATA]:DRIVES, e.g. can0=fd:1M/5M:1-6."""
    name, _, spec = text.rpartition("=")
    parts = spec.split(":")
    if len(parts) != 3 or parts[0] not in ("classic", "fd"):
        raise ConfigError(f"--bus '{text}': expected classic:RATE:DRIVES or fd:NOMINAL[/DATA]:DRIVES "
                          "(e.g. fd:1M/5M:1-6, classic:1M:1-3)")
    kind, rates, drives = parts
    nominal, _, data = rates.partition("/")
    if kind == "classic" and data:
        raise ConfigError(f"--bus '{text}': a classic bus has one bit rate")
    return Bus(name=name or f"can{index}", fd=kind == "fd", nominal_bps=parse_rate(nominal),
               data_bps=parse_rate(data) if data else None, drives=parse_drives(drives))


def load_topology(path: Path = DEFAULT_TOPOLOGY, n_drives: int = 6) -> list[Bus]:
    """The [[bus]] tables of a topology file (firmware/protocol/buses.toml), validated: known
    fields and kinds, valid rates, unique names, every drive 1..n_drives on exactly one bus.
    Errors name the file, the bus and the field."""
    import tomllib

    from gen.lib import toml_input

    try:
        doc = toml_input.loads(Path(path).read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"{path}: {exc}") from exc
    return topology_from_doc(doc, str(path), n_drives)


def topology_from_doc(doc: dict[str, Any], path: str, n_drives: int = 6) -> list[Bus]:
    """load_topology() of a document already read (an arm file's buses); `path` names it in errors."""
    unknown = set(doc) - {"bus"}
    if unknown:
        raise ConfigError(f"{path}: unknown top-level key(s) {', '.join(sorted(unknown))} (expected [[bus]] tables)")
    tables = doc.get("bus")
    if not isinstance(tables, list) or not tables:
        raise ConfigError(f"{path}: bus: expected one or more [[bus]] tables")
    buses: list[Bus] = []
    names: set[str] = set()
    for i, t in enumerate(tables):
        where = f"{path}: bus[{i}]"
        if not isinstance(t, dict):
            raise ConfigError(f"{where}: expected a table")
        extra = set(t) - {"name", "kind", "nominal", "data", "drives"}
        if extra:
            raise ConfigError(f"{where}: unknown field(s) {', '.join(sorted(extra))}")
        name = t.get("name")
        if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_.-]{1,15}", name):
            raise ConfigError(f"{where}.name: expected 1..15 characters [A-Za-z0-9_.-], got {name!r}")
        if name in names:
            raise ConfigError(f"{where}.name: bus name '{name}' is used twice")
        names.add(name)
        where = f"{path}: bus {name}"
        kind = t.get("kind")
        if kind not in ("fd", "classic"):
            raise ConfigError(f"{where}.kind: expected \"fd\" or \"classic\", got {kind!r}")
        rates = {}
        for key in ("nominal", "data"):
            v = t.get(key)
            if v is None:
                rates[key] = None
                continue
            try:
                rates[key] = parse_rate(str(v))
            except ConfigError as exc:
                raise ConfigError(f"{where}.{key}: {exc}") from exc
        if rates["nominal"] is None:
            raise ConfigError(f"{where}.nominal: missing (bit rate, e.g. \"1M\")")
        if kind == "classic" and rates["data"] is not None:
            raise ConfigError(f"{where}.data: a classic bus has one bit rate (no data rate)")
        drives = t.get("drives")
        if (not isinstance(drives, list) or not drives
                or not all(isinstance(d, int) and not isinstance(d, bool) for d in drives)):
            raise ConfigError(f"{where}.drives: expected a non-empty list of drive numbers, got {drives!r}")
        buses.append(Bus(name, kind == "fd", rates["nominal"], rates["data"], list(drives)))
    _check_placement(buses, n_drives, {
        "none": lambda bus, d, _: f"{path}: bus {bus}.drives: drive {d} does not exist (drives 1..{n_drives})",
        "two": lambda bus, d, other: f"{path}: bus {bus}.drives: drive {d} is on two buses ({other} and {bus})",
        "missing": lambda _, __, other: f"{path}: drives: drive(s) {other} are on no bus"})
    return buses


def topology_drives(path: Path) -> int:
    """The number of drives a topology file wires (its highest drive number; 0 if unreadable:
    load_topology then says what is wrong)."""
    import tomllib

    from gen.lib import toml_input

    try:
        tables = toml_input.loads(Path(path).read_text()).get("bus", [])
        return max((d for t in tables if isinstance(t, dict) for d in t.get("drives", []) if isinstance(d, int)),
                   default=0)
    except (OSError, tomllib.TOMLDecodeError, TypeError, AttributeError):
        return 0


def default_wiring(n_drives: int, rate_hz: float = default("controller", "rate"),
                   budget: float = BUS_BUDGET,
                   template: Bus | None = None) -> list[Bus]:
    """The fewest buses of the template's kind (CAN FD 1/5 Mbit/s) that carry drives 1..n within
    the budget at the loop rate, drives split evenly in order; at most 4 buses (the controller's
    limit). ConfigError if even 4 do not fit."""
    template = template or Bus("can0", True, 1e6, 5e6, [])
    proto = default_protocol()
    for k in range(1, min(MAX_BUSES, n_drives) + 1):
        split = even_split(template, n_drives, k)
        if all(bl.load <= budget for bl in compute(split, rate_hz, 100.0, proto, n_drives)):
            return split
    raise ConfigError(f"{n_drives} drives at {rate_hz:g} Hz do not fit {min(MAX_BUSES, n_drives)} "
                      f"{template.describe()} buses within {budget * 100:g}%: give the arm file a wiring "
                      "(buses = ...) or a lower loop rate")


@functools.cache
def default_protocol() -> "Protocol":
    """The project's DBC, parsed once per process (a study asks for it in every run)."""
    return Protocol()


class Protocol:
    """The per-period and heartbeat messages of the DBC, each tagged with its drive (or all)."""

    def __init__(self, dbc: Path = DEFAULT_DBC) -> None:
        import cantools

        self.db = cantools.database.load_file(str(dbc))
        self.drive_nodes = sorted((n.name for n in self.db.nodes if re.fullmatch(r"DRIVE_\d+", n.name)),
                                  key=lambda s: int(s.split("_")[1]))
        self.n_drives = len(self.drive_nodes)

    def drive_of(self, msg) -> int | None:  # noqa: ANN001 - cantools Message
        """The one drive a message is sent by or to; None if it goes to every drive (SYNC)."""
        nodes = set(msg.senders)
        for s in msg.signals:
            nodes |= set(s.receivers)
        drives = sorted(n for n in nodes if n in self.drive_nodes)
        if len(drives) == 1:
            return int(drives[0].split("_")[1])
        return None

    def periodic(self):  # noqa: ANN201
        return [m for m in self.db.messages if m.cycle_time]

    def heartbeats(self):  # noqa: ANN201
        return [m for m in self.db.messages if m.name.endswith("_HEARTBEAT")]

    @staticmethod
    def brs(msg) -> bool:  # noqa: ANN001
        attr = msg.dbc.attributes.get("CANFD_BRS") if msg.dbc else None
        return True if attr is None else int(attr.value) == 1


def frame_time(msg, bus: Bus) -> tuple[int, int, int, float]:  # noqa: ANN001
    """(frames, nominal bits, data bits, seconds) per frame of msg on bus."""
    n = msg.length
    if msg.is_fd and bus.fd:
        brs = Protocol.brs(msg) and bus.data_bps is not None
        nom, dat = fd_frame_bits(n, msg.is_extended_frame, brs)
        return 1, nom, dat, nom / bus.nominal_bps + (dat / bus.data_bps if dat else 0.0)  # type: ignore[operator]
    frames = max(1, math.ceil(n / 8))
    per = min(n, 8)
    bits = classic_frame_bits(per, msg.is_extended_frame)
    return frames, bits, 0, bits / bus.nominal_bps


def compute(buses: list[Bus], rate_hz: float, heartbeat_ms: float, proto: Protocol,
            n_drives: int | None = None) -> list[BusLoad]:
    """The load of each bus; drives 1..n_drives (default: the highest drive the buses name) must
    each be on exactly one bus, within the DBC's drive slots."""
    n = n_drives if n_drives is not None else max((d for b in buses for d in b.drives), default=0)
    _check_drives(buses, n, proto.n_drives, "the DBC has drive slots")
    out = []
    for b in buses:
        bl = BusLoad(bus=b, rate_hz=rate_hz)
        for m in proto.periodic():
            d = proto.drive_of(m)
            if (d is None and b.drives) or d in b.drives:
                frames, nom, dat, t = frame_time(m, b)
                bl.frames.append(FrameLoad(m.name, frames, 1.0, nom, dat, t))
                bl.periodic_s += frames * t
        for m in proto.heartbeats():
            if proto.drive_of(m) in b.drives:
                frames, nom, dat, t = frame_time(m, b)
                share = 1.0 / (rate_hz * heartbeat_ms * 1e-3)
                bl.frames.append(FrameLoad(m.name, frames, share, nom, dat, t))
                bl.background_load += frames * t / (heartbeat_ms * 1e-3)
        out.append(bl)
    return out


def even_split(bus: Bus, n_drives: int, k: int) -> list[Bus]:
    """Drives 1..n in k contiguous groups, sizes differing by at most one (larger groups first)."""
    out, first = [], 1
    for i in range(k):
        size = n_drives // k + (1 if i < n_drives % k else 0)
        out.append(Bus(f"can{i}", bus.fd, bus.nominal_bps, bus.data_bps, list(range(first, first + size))))
        first += size
    return out


def drives_arg(b: Bus) -> str:
    return str(b.drives[0]) if len(b.drives) == 1 else f"{b.drives[0]}-{b.drives[-1]}"


def rate_arg(b: Bus) -> str:
    def r(v: float) -> str:
        return f"{v / 1e6:g}M" if v >= 1e6 else f"{v / 1e3:g}k"

    return r(b.nominal_bps) + (f"/{r(b.data_bps)}" if b.data_bps else "")


def phy_spec(b: Bus) -> str:
    """The bus's physical layer as host_sim --bus-phy takes it: fd:1M/5M, fd:1M, classic:500k."""
    return f"{'fd' if b.fd else 'classic'}:{rate_arg(b)}"


# The CiA 402 drives of issue #23 (docs/drives.md, The CANopen master): per drive and period
# RPDO1 (controlword + target torque), TPDO1 (position + velocity), TPDO2 (torque + statusword);
# one SYNC (no counter) per bus and period; a 1-byte heartbeat per drive every heartbeat_ms.
CANOPEN_PDO_BYTES = {name.upper(): pdo_bytes(name) for name in CODEC_MAPPING}  # RPDO1 4, TPDO1 8, TPDO2 4


def canopen_frame_s(n_bytes: int, bus: Bus) -> float:
    """One frame of n_bytes on this bus, worst case (classic, or FD with its bit-rate switch)."""
    if not bus.fd:
        return classic_frame_bits(n_bytes) / bus.nominal_bps
    nom, dat = fd_frame_bits(n_bytes, brs=bus.data_bps is not None)
    return nom / bus.nominal_bps + (dat / bus.data_bps if dat else 0.0)  # type: ignore[operator]


def _every(transmission_type: int) -> int:
    """The SYNCs per frame of a PDO's CiA 301 transmission type: n for synchronous 1-240; an
    event-driven (254/255) RPDO goes once a period, as the master sends it."""
    return transmission_type if 1 <= transmission_type <= 240 else 1


def _check_drives(buses: list[Bus], n: int, slots: int, what: str) -> None:
    """Drives 1..n each on exactly one bus, within `slots` (the DBC's, or CANopen's node ids)."""
    if not 1 <= n <= slots:
        raise ConfigError(f"{n} drives: {what} 1..{slots}")
    _check_placement(buses, n, {
        "none": lambda bus, d, _: f"bus {bus}: drive {d} does not exist (drives 1..{n}; {what} 1..{slots})",
        "two": lambda bus, d, other: f"drive {d} is on two buses ({other} and {bus})",
        "missing": lambda _, __, other: f"drives {other} are on no bus"})


def _check_placement(buses: list[Bus], n: int, messages: dict[str, Callable[[str, int, str], str]]) -> None:
    """Drives 1..n each on exactly one bus; else ConfigError with the caller's message for the first
    break: "none" (no such drive), "two" (other: the bus it is on already) or "missing" (other:
    every drive on no bus, comma-separated), each message made of (bus, drive, other)."""
    seen: dict[int, str] = {}
    for b in buses:
        for d in b.drives:
            if not 1 <= d <= n:
                raise ConfigError(messages["none"](b.name, d, ""))
            if d in seen:
                raise ConfigError(messages["two"](b.name, d, seen[d]))
            seen[d] = b.name
    missing = [d for d in range(1, n + 1) if d not in seen]
    if missing:
        raise ConfigError(messages["missing"]("", 0, ", ".join(map(str, missing))))


def canopen_compute(buses: list[Bus], rate_hz: float, heartbeat_ms: float = HEARTBEAT_MS,
                    every: dict[str, int] | None = None, n_drives: int | None = None) -> list[BusLoad]:
    """The load of each bus of CiA 402 drives: per period one SYNC, and per drive RPDO1, TPDO1 and
    TPDO2, each once every `every[pdo]` SYNCs (their CiA 301 transmission types; absent: 1); a
    heartbeat per drive every heartbeat_ms. Node ids are the drive numbers (1..127)."""
    every = every or {}
    n = n_drives if n_drives is not None else max((d for b in buses for d in b.drives), default=0)
    _check_drives(buses, n, 127, "CANopen node ids")
    out = []
    for b in buses:
        bl = BusLoad(bus=b, rate_hz=rate_hz)
        periodic = [_canopen_frame("SYNC", 0, 1.0, b)] + [
            _canopen_frame(f"{name} node {d}", n_bytes, 1.0 / _every(every.get(name.lower(), 1)), b)
            for d in b.drives for name, n_bytes in CANOPEN_PDO_BYTES.items()]
        heartbeats = [_canopen_frame(f"heartbeat node {d}", 1, 1.0 / (rate_hz * heartbeat_ms * 1e-3), b)
                      for d in b.drives]
        bl.frames = periodic + heartbeats
        bl.periodic_s = sum(f.per_period * f.time_s for f in periodic)
        bl.background_load = sum(f.time_s for f in heartbeats) / (heartbeat_ms * 1e-3)
        out.append(bl)
    return out


def _canopen_frame(name: str, n_bytes: int, per_period: float, bus: Bus) -> FrameLoad:
    nom, dat = (classic_frame_bits(n_bytes), 0) if not bus.fd else fd_frame_bits(n_bytes, brs=bus.data_bps is not None)
    return FrameLoad(name, 1, per_period, nom, dat, canopen_frame_s(n_bytes, bus))


def canopen_load(bus: Bus, n_drives: int, rate_hz: float, heartbeat_ms: float = HEARTBEAT_MS,
                 every: dict[str, int] | None = None) -> float:
    """Worst-case load (fraction of bus time) of n_drives CiA 402 drives on one bus at rate_hz;
    every: the PDOs' transmission types (gen/drives.py [pdo] transmission; absent: 1, every SYNC)."""
    one = Bus(bus.name, bus.fd, bus.nominal_bps, bus.data_bps, list(range(1, n_drives + 1)))
    return canopen_compute([one], rate_hz, heartbeat_ms, every, n_drives)[0].load


def canopen_drives_per_bus(bus: Bus, rate_hz: float, budget: float = BUS_BUDGET, heartbeat_ms: float = HEARTBEAT_MS,
                           every: dict[str, int] | None = None) -> int:
    """The most drives one bus carries within the budget (0: not even one)."""
    n = 0
    while n < 127 and canopen_load(bus, n + 1, rate_hz, heartbeat_ms, every) <= budget:
        n += 1
    return n


CLASSIC_1M = Bus("can0", False, 1e6, None, [])  # the CiA 402 drives' default wire (issue #23: classic CAN)


def canopen_wiring(n_drives: int, rate_hz: float, every: dict[str, int] | None = None,
                   budget: float = BUS_BUDGET, heartbeat_ms: float = HEARTBEAT_MS,
                   template: Bus = CLASSIC_1M, max_buses: int = MAX_BUSES) -> list[Bus] | None:
    """The fewest buses of the template's kind (classic 1 Mbit/s) that carry drives 1..n within
    the budget at rate_hz, drives split evenly in order; None if even max_buses do not."""
    for k in range(1, min(max_buses, n_drives) + 1):
        split = even_split(template, n_drives, k)
        if all(canopen_load(b, len(b.drives), rate_hz, heartbeat_ms, every) <= budget for b in split):
            return split
    return None
