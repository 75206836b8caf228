"""Bus timing emulation: when each frame of a period would end on a real CAN bus.

vcan and the UDP transport deliver a frame the moment it is sent, so without this the arm sees
every command at the start of its period, however loaded the bus. Here each bus keeps a timeline
(seconds from the start of the current control period): a frame occupies the bus for its
worst-case length (tools/busload.py: exact bit counts, worst-case stuffing, FD bit-rate switch),
frames that are ready together go in id order (arbitration: lowest id first), and a bus still busy
at the end of a period carries the backlog into the next one, so the next SYNC waits for it.

Frames are queued in batches in the order the protocol produces them (SYNC; the drives' states
once SYNC has ended; the commands once every state is in; heartbeats and EMCY at the end of the
period). A later batch never pre-empts an earlier one: with this protocol's ids
(SYNC 0x080 < EMCY 0x081.. < STATE 0x181.. < CMD 0x201.. < heartbeat 0x701..) that is what
arbitration would do as well, except that a heartbeat left over from the previous period goes
before the next SYNC instead of after it (it only ever delays that SYNC by its own length).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from tools.busload import Bus, ConfigError, Protocol, frame_time, parse_rate

MODES = ("off", "virtual", "wallclock")


def parse_phy(text: str) -> tuple[bool, float, float | None]:
    """"fd:1M/5M", "fd:1M" (no bit-rate switch) or "classic:1M" -> (fd, nominal, data)."""
    kind, _, rates = text.partition(":")
    if kind not in ("fd", "classic") or not rates:
        raise ConfigError(f"'{text}': expected fd:NOMINAL[/DATA] or classic:RATE (e.g. fd:1M/5M, classic:1M)")
    nominal, _, data = rates.partition("/")
    if kind == "classic" and data:
        raise ConfigError(f"'{text}': a classic bus has one bit rate")
    return kind == "fd", parse_rate(nominal), parse_rate(data) if data else None


@dataclass
class BusStats:
    periods: int = 0
    sync_to_last_cmd_max_s: float = 0.0
    sync_to_last_cmd_sum_s: float = 0.0
    backlog_max_s: float = 0.0  # bus still busy this long after a period's end
    commands_late: int = 0      # ended after their period: too late for it, not applied

    def as_dict(self) -> dict[str, float | int]:
        mean = self.sync_to_last_cmd_sum_s / self.periods if self.periods else 0.0
        return {"periods": self.periods, "sync_to_last_cmd_max_us": round(self.sync_to_last_cmd_max_s * 1e6, 3),
                "sync_to_last_cmd_mean_us": round(mean * 1e6, 3),
                "backlog_max_us": round(self.backlog_max_s * 1e6, 3), "commands_late": self.commands_late}


@dataclass
class BusTimeline:
    """One bus: the time (from the current period's start) at which it is next idle."""

    bus: Bus
    frame_s: dict[int, float]  # frame id -> worst-case seconds on this bus (all its frames)
    free: float = 0.0
    stats: BusStats = field(default_factory=BusStats)

    def new_period(self, period_s: float) -> None:
        backlog = self.free - period_s
        self.stats.backlog_max_s = max(self.stats.backlog_max_s, backlog)
        self.free = max(0.0, backlog)

    def transmit(self, ready: float, ids: list[int]) -> dict[int, float]:
        """Frames all ready at `ready`: each one's end time, lowest id first."""
        t = max(self.free, ready)
        ends = {}
        for fid in sorted(ids):
            t += self.frame_s[fid]
            ends[fid] = t
        self.free = t
        return ends


def timelines(phys: list[tuple[bool, float, float | None]], drives_of_bus: list[list[int]],
              proto: Protocol | None = None) -> list[BusTimeline]:
    """One timeline per bus; phys[i] is bus i's physical layer, drives_of_bus[i] its drives (1-based)."""
    proto = proto or Protocol()
    out = []
    for i, ((fd, nominal, data), drives) in enumerate(zip(phys, drives_of_bus)):
        bus = Bus(f"bus{i}", fd, nominal, data, drives)
        frame_s = {}
        for msg in proto.db.messages:
            frames, _, _, seconds = frame_time(msg, bus)
            frame_s[msg.frame_id] = frames * seconds
        out.append(BusTimeline(bus, frame_s))
    return out
