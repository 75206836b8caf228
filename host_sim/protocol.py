"""The drive protocol as Python sees it: everything is read from firmware/protocol/arm_drives.dbc.

cantools reads the DBC; for the per-period frames we derive a struct layout from the DBC's own
signal definitions (byte-aligned little-endian integers) because cantools' generic encoder costs
~23 us per frame, a large share of a 1 kHz lockstep period in Python. tests/python/test_protocol.py
checks both paths agree.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import cantools
from cantools.database.can import Message

REPO = Path(__file__).resolve().parent.parent
DBC_PATH = REPO / "firmware" / "protocol" / "arm_drives.dbc"

NMT_START = 0x01
NMT_STOP = 0x02
NMT_STATE_BOOT = 0x00
NMT_STATE_STOPPED = 0x04
NMT_STATE_OPERATIONAL = 0x05
NMT_STATE_PRE_OPERATIONAL = 0x7F

_INT_CODES = {(8, True): "b", (8, False): "B", (16, True): "h", (16, False): "H", (32, True): "i", (32, False): "I"}


@dataclass(frozen=True)
class FastCodec:
    """Struct-based encode/decode of one message, built from its DBC signals."""

    message: Message
    fmt: struct.Struct
    names: tuple[str, ...]
    scales: tuple[float, ...]
    offsets: tuple[float, ...]
    raw_limits: tuple[tuple[int, int], ...]

    @classmethod
    def from_message(cls, msg: Message) -> "FastCodec":
        fmt = "<"
        pos = 0
        names, scales, offsets, limits = [], [], [], []
        for sig in sorted(msg.signals, key=lambda s: s.start):
            if sig.byte_order != "little_endian" or sig.start % 8 or (sig.length, sig.is_signed) not in _INT_CODES:
                raise ValueError(f"{msg.name}.{sig.name}: not a byte-aligned little-endian 8/16/32-bit integer")
            if sig.start < pos:
                raise ValueError(f"{msg.name}.{sig.name}: overlaps the previous signal")
            fmt += "x" * ((sig.start - pos) // 8) + _INT_CODES[(sig.length, sig.is_signed)]
            pos = sig.start + sig.length
            names.append(sig.name)
            scales.append(float(sig.scale))
            offsets.append(float(sig.offset))
            bits = sig.length
            limits.append((-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if sig.is_signed else (0, (1 << bits) - 1))
        fmt += "x" * ((msg.length * 8 - pos) // 8)
        return cls(msg, struct.Struct(fmt), tuple(names), tuple(scales), tuple(offsets), tuple(limits))

    def encode(self, values: dict[str, float]) -> bytes:
        """Values beyond a signal's range saturate, as a drive's register would (never a crash)."""
        raw = [round((values[n] - o) / s) for n, s, o in zip(self.names, self.scales, self.offsets)]
        try:
            return self.fmt.pack(*raw)
        except struct.error:  # rare: clamp only when a value is out of range
            return self.fmt.pack(*(min(hi, max(lo, r)) for r, (lo, hi) in zip(raw, self.raw_limits)))

    def decode(self, data: bytes) -> dict[str, float] | None:
        """The signals, or None for a payload of another length (the caller counts and drops it)."""
        if not isinstance(data, (bytes, bytearray, memoryview)) or len(data) != self.fmt.size:
            return None
        raw = self.fmt.unpack(data)
        return {n: r * s + o for n, r, s, o in zip(self.names, raw, self.scales, self.offsets)}


class DriveProtocol:
    """Frame ids and codecs for a bus of n_drives drives (node i + 1 drives joint i)."""

    def __init__(self, n_drives: int, dbc: Path = DBC_PATH) -> None:
        self.db = cantools.database.load_file(str(dbc))
        self.n = n_drives
        get = self.db.get_message_by_name
        try:
            self.sync = get("SYNC")
            self.nmt = get("NMT")
            self.state = [get(f"DRIVE_{i + 1}_STATE") for i in range(n_drives)]
            self.cmd = [get(f"DRIVE_{i + 1}_CMD") for i in range(n_drives)]
            self.heartbeat = [get(f"DRIVE_{i + 1}_HEARTBEAT") for i in range(n_drives)]
            self.emcy = [get(f"DRIVE_{i + 1}_EMCY") for i in range(n_drives)]
        except KeyError as exc:
            raise ValueError(f"{dbc}: the DBC defines fewer than {n_drives} drives ({exc})") from exc
        self.state_codec = [FastCodec.from_message(m) for m in self.state]
        self.cmd_codec = [FastCodec.from_message(m) for m in self.cmd]
        self.cmd_joint = {m.frame_id: i for i, m in enumerate(self.cmd)}
        self.state_joint = {m.frame_id: i for i, m in enumerate(self.state)}
        self.own_ids = (
            set(self.state_joint) | {m.frame_id for m in self.heartbeat} | {m.frame_id for m in self.emcy}
        )

    def message_by_id(self, frame_id: int) -> Message | None:
        try:
            return self.db.get_message_by_frame_id(frame_id)
        except KeyError:
            return None
