"""Read a run's LCM log: decode every message, check sequence numbers, collect per-channel series."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import lcm

from gen import lcmtypes

CHANNEL_TYPES = {
    "ARM_CTL": "controller_t",
    "ARM_TIMING": "timing_t",
    "ARM_EVENT": "event_t",
    "ARM_SIM": "sim_truth_t",
    "ARM_SIM_EVENT": "event_t",
}


@dataclass
class ChannelLog:
    messages: list[Any] = field(default_factory=list)
    gaps: int = 0          # sequence numbers below the highest logged one that are missing
    duplicates: int = 0
    undecodable: int = 0


def read_log(path: Path) -> dict[str, ChannelLog]:
    """Every known channel's messages in log order. A truncated log (killed writer) is read up to
    its last whole event."""
    types = lcmtypes.load()
    out: dict[str, ChannelLog] = {ch: ChannelLog() for ch in CHANNEL_TYPES}
    log = lcm.EventLog(str(path), "r")
    try:
        while True:
            try:
                ev = log.read_next_event()
            except (ValueError, OSError):
                break  # torn last event
            if ev is None:
                break
            name = CHANNEL_TYPES.get(ev.channel)
            if name is None:
                continue
            try:
                out[ev.channel].messages.append(getattr(types, name).decode(ev.data))
            except Exception:  # noqa: BLE001 - lcm-gen's decoders raise ValueError, struct.error, ...: count, drop
                out[ev.channel].undecodable += 1
    finally:
        log.close()
    for ch in out.values():
        seqs = [m.seq for m in ch.messages]
        if seqs:
            unique = set(seqs)
            ch.duplicates = len(seqs) - len(unique)
            ch.gaps = (max(unique) + 1) - len(unique)  # sequence numbers start at 0
    return out
