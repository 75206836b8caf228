"""Read a run's LCM event log in bounded chunks, decoding the fixed-layout channels in bulk.

An LCM event log is a sequence of events: sync word 0xEDA1DA01, event number (int64), timestamp
(int64), channel length (int32), data length (int32), channel name, data; all big-endian. The data
of a message is its type's 8-byte fingerprint followed by its fields, big-endian. ARM_CTL
(controller_t), ARM_SIM (sim_truth_t) and ARM_TIMING (timing_t) have a fixed layout for a given
joint count n, so a chunk's messages of one channel are one numpy structured array, decoded in
one step; events (ARM_EVENT, ARM_SIM_EVENT: strings) go through lcm-gen's classes.

iter_chunks() reads the file a few MB at a time and yields each chunk's messages per channel, so
memory does not grow with the log. A message whose size is not its type's for its n (or for the
channel's n, fixed by its first good message), or whose fingerprint is not its type's, is counted
as undecodable. A torn last event (a killed writer) is read up to the last whole event, and bytes
between events that are not an event are skipped up to the next sync word, as liblcm does; an
event header no event has (a channel or data length out of range) ends the reading, as in liblcm.
What was not read is named in a LogDamage: where (byte offset, the event number before it), why,
and how much (bytes left unread; event numbers missing between the events read, since a writer
numbers its events 0, 1, 2, ...).

read_log() loads a whole run through the same reader (for the figures of a kept run and for
tests): its memory grows with the run; the analysis (tools/run/run_analysis.py) streams instead.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gen import lcmtypes

CHANNEL_TYPES = {
    "ARM_CTL": "controller_t",
    "ARM_TIMING": "timing_t",
    "ARM_EVENT": "event_t",
    "ARM_SIM": "sim_truth_t",
    "ARM_SIM_EVENT": "event_t",
}
EVENT_CHANNELS = ("ARM_EVENT", "ARM_SIM_EVENT")
CHUNK_BYTES = 2 << 20

SYNC = b"\xed\xa1\xda\x01"
HEADER = 28          # sync, event number, timestamp, channel length, data length
MAX_CHANNEL = 1000   # liblcm's own bound on a channel name's length: beyond it the log ends


@dataclass(frozen=True)
class Layout:
    """A fixed-layout LCM type (firmware/lcmtypes/*.lcm): the fields before the n-sized arrays,
    the arrays, the fields after them. `n` is None for a type without arrays."""
    head: tuple[tuple[str, str], ...]
    arrays: tuple[str, ...] = ()
    array_type: str = "f8"
    tail: tuple[tuple[str, str], ...] = ()

    def offset_of_n(self) -> int:
        return 8 + sum(np.dtype(f).itemsize for name, f in self.head if name != "n")

    def size(self, n: int) -> int:
        return (8 + sum(np.dtype(f).itemsize for _, f in self.head + self.tail)
                + len(self.arrays) * n * np.dtype(self.array_type).itemsize)

    def dtype(self, n: int, byteorder: str) -> np.dtype:
        names, formats, offsets, at = [], [], [], 8
        for name, f in self.head:
            names.append(name), formats.append(byteorder + f), offsets.append(at)
            at += np.dtype(f).itemsize
        for name in self.arrays:
            names.append(name), formats.append((byteorder + self.array_type, (n,))), offsets.append(at)
            at += n * np.dtype(self.array_type).itemsize
        for name, f in self.tail:
            names.append(name), formats.append(byteorder + f), offsets.append(at)
            at += np.dtype(f).itemsize
        return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": at})

    @property
    def has_n(self) -> bool:
        return any(name == "n" for name, _ in self.head)


LAYOUTS = {
    "controller_t": Layout(
        head=(("seq", "i8"), ("step", "i8"), ("bus_period", "i8"), ("t", "f8"), ("method", "i1"),
              ("state", "i1"), ("fault", "i1"), ("saturated_mask", "i4"), ("n", "i2")),
        arrays=("q", "qd", "q_d", "e", "e_dot", "w_hat", "u_o", "tau"), array_type="f4"),
    "sim_truth_t": Layout(
        head=(("seq", "i8"), ("step", "i8"), ("t", "f8"), ("n", "i2")),
        arrays=("q", "qd", "tau_applied", "w_true"), array_type="f8",
        tail=(("drive_faults", "i4"), ("flags", "i4"))),
    "timing_t": Layout(
        head=(("seq", "i8"), ("step", "i8"), ("period_ns", "i4"), ("wake_latency_ns", "i4"),
              ("compute_ns", "i4"), ("cycle_ns", "i4"), ("overruns", "i8"), ("telemetry_dropped", "i8"))),
}
FIXED_CHANNELS = {ch: t for ch, t in CHANNEL_TYPES.items() if t in LAYOUTS}


@dataclass
class LogDamage:
    """Where a log breaks and what was left unread (iter_chunks fills it as it reads)."""
    size: int = 0                     # the file's bytes
    events: int = 0                   # whole events read
    last_event: int | None = None     # the event number of the last event read
    skipped: list[dict[str, Any]] = field(default_factory=list)  # bytes that are no event: offset, bytes, after_event
    missing_events: int = 0           # event numbers skipped between events read
    first_missing: dict[str, int] | None = None  # the first: its offset and the event number expected there
    stop: dict[str, Any] | None = None  # reading ended before the file did: offset, after_event, why
    unread: int = 0                   # bytes from `stop` to the end of the file

    @property
    def damaged(self) -> bool:
        return bool(self.skipped or self.missing_events or self.stop)

    def describe(self) -> str:
        """One line: where the log breaks and how much of it was not read."""
        parts = []
        if self.stop is not None:
            after = "at its start" if self.stop["after_event"] is None else f"after event {self.stop['after_event']}"
            parts.append(f"it breaks at byte {self.stop['offset']} ({after}): {self.stop['why']}; {self.unread} of its "
                         f"{self.size} bytes ({100 * self.unread / max(self.size, 1):.1f} %) left unread")
        if self.skipped:
            k = self.skipped[0]
            after = "at its start" if k["after_event"] is None else f"after event {k['after_event']}"
            parts.append(f"{sum(x['bytes'] for x in self.skipped)} bytes that are no event skipped in "
                         f"{len(self.skipped)} place(s), the first {k['bytes']} at byte {k['offset']} ({after})")
        if self.missing_events:
            f = self.first_missing or {}
            parts.append(f"{self.missing_events} event(s) missing between those read, the first event "
                         f"{f.get('event')} at byte {f.get('offset')}")
        return "; ".join(parts) + f"; {self.events} events read" if parts else f"whole: {self.events} events read"

    def as_dict(self) -> dict[str, Any]:
        return {"damaged": self.damaged, "size_bytes": self.size, "events_read": self.events,
                "last_event": self.last_event, "skipped": self.skipped, "missing_events": self.missing_events,
                "first_missing": self.first_missing, "stop": self.stop, "unread_bytes": self.unread,
                "description": self.describe()}

    def _read(self, base: int, starts: np.ndarray, ends: np.ndarray, numbers: np.ndarray, prev_end: int) -> int:
        """Events read from a buffer at file offset `base`: what lies between them, their numbers."""
        starts, ends = starts + base, ends + base
        gaps_from = np.concatenate([[prev_end], ends[:-1]])
        for at in np.flatnonzero(starts > gaps_from):
            before = self.last_event if at == 0 else int(numbers[at - 1])
            self.skipped.append({"offset": int(gaps_from[at]), "bytes": int(starts[at] - gaps_from[at]),
                                 "after_event": before})
        prev = np.concatenate([[self.last_event if self.last_event is not None else -1], numbers[:-1]])
        jump = numbers - prev - 1
        lost = np.flatnonzero(jump > 0)
        if len(lost):
            self.missing_events += int(jump[lost].sum())
            if self.first_missing is None:
                self.first_missing = {"offset": int(starts[lost[0]]), "event": int(prev[lost[0]] + 1)}
        self.events += len(numbers)
        self.last_event = int(numbers[-1])
        return int(ends[-1])

    def _stopped(self, offset: int, why: str) -> None:
        if self.stop is None:
            self.stop = {"offset": offset, "after_event": self.last_event, "why": why}
            self.unread = self.size - offset


@dataclass
class Chunk:
    """One chunk's messages: per fixed-layout channel a native structured array in log order, per
    event channel the decoded messages, and per channel the messages it could not decode."""
    arrays: dict[str, np.ndarray]
    events: dict[str, list[Any]]
    undecodable: dict[str, int]


class _Decoder:
    def __init__(self) -> None:
        self.types = lcmtypes.load()
        self.fingerprint = {ch: np.frombuffer(getattr(self.types, t)._get_packed_fingerprint(), np.uint8)
                            for ch, t in FIXED_CHANNELS.items()}
        self.n: dict[str, int | None] = {ch: None for ch in FIXED_CHANNELS}  # fixed by a channel's first good message
        self._dtypes: dict[tuple[str, int], tuple[np.dtype, np.dtype]] = {}
        self.names = {ch: np.frombuffer(ch.encode(), np.uint8) for ch in CHANNEL_TYPES}
        self.width = max(len(ch) for ch in CHANNEL_TYPES)

    def dtypes(self, ch: str, n: int) -> tuple[np.dtype, np.dtype]:
        key = (ch, n)
        if key not in self._dtypes:
            lay = LAYOUTS[FIXED_CHANNELS[ch]]
            self._dtypes[key] = (lay.dtype(n, ">"), lay.dtype(n, "="))
        return self._dtypes[key]

    def empty(self, ch: str) -> np.ndarray:
        return np.empty(0, self.dtypes(ch, self.n[ch] or 0)[1])

    def decode(self, b: np.ndarray, pos: np.ndarray, chlen: np.ndarray, datalen: np.ndarray) -> Chunk:
        """The events at pos (whole, on the event chain) of buffer b."""
        arrays: dict[str, np.ndarray] = {}
        events: dict[str, list[Any]] = {ch: [] for ch in EVENT_CHANNELS}
        undecodable = {ch: 0 for ch in CHANNEL_TYPES}
        if len(pos) == 0:
            return Chunk({ch: self.empty(ch) for ch in FIXED_CHANNELS}, events, undecodable)
        nb = b if int(pos[-1]) + HEADER + self.width <= len(b) else np.concatenate([b, np.zeros(self.width, np.uint8)])
        names = _rows(nb, pos + HEADER, self.width)  # (an event that ends within `width` of the buffer's end: padded)
        data_at = pos + HEADER + chlen
        for ch, name in self.names.items():
            sel = np.flatnonzero((chlen == len(name)) & (names[:, :len(name)] == name).all(axis=1))
            if ch in FIXED_CHANNELS:
                arrays[ch] = self._fixed(ch, b, data_at[sel], datalen[sel], undecodable)
            else:
                decode = getattr(self.types, CHANNEL_TYPES[ch]).decode
                for at, size in zip(data_at[sel].tolist(), datalen[sel].tolist()):
                    try:
                        events[ch].append(decode(b[at:at + size].tobytes()))
                    except Exception:  # noqa: BLE001 - lcm-gen's decoders raise ValueError, struct.error, ...: count, drop
                        undecodable[ch] += 1
        return Chunk(arrays, events, undecodable)

    def _fixed(self, ch: str, b: np.ndarray, at: np.ndarray, size: np.ndarray, undecodable: dict[str, int]) -> np.ndarray:
        lay = LAYOUTS[FIXED_CHANNELS[ch]]
        if len(at) == 0:
            return self.empty(ch)
        fp = _rows(b, np.minimum(at, len(b) - 8), 8)
        ok = (size >= 8) & (fp == self.fingerprint[ch]).all(axis=1)
        if lay.has_n:
            o = lay.offset_of_n()
            ok &= size >= o + 2
            hi = b[np.minimum(at + o, len(b) - 1)].astype(np.int64)
            lo = b[np.minimum(at + o + 1, len(b) - 1)].astype(np.int64)
            n_of = ((hi << 8) | lo).astype(np.uint16).astype(np.int16).astype(np.int64)
            per = len(lay.arrays) * np.dtype(lay.array_type).itemsize
            ok &= (n_of >= 0) & (size == lay.size(0) + per * n_of)
            if self.n[ch] is None and ok.any():
                self.n[ch] = int(n_of[np.argmax(ok)])
            ok &= n_of == (self.n[ch] if self.n[ch] is not None else -1)
        else:
            ok &= size == lay.size(0)
            self.n[ch] = 0
        n = self.n[ch] or 0
        be, native = self.dtypes(ch, n)
        good = at[ok]
        undecodable[ch] += int(len(at) - len(good))
        rows = _rows(b, good, be.itemsize)
        return rows.view(be).reshape(len(rows)).astype(native)


def _rows(b: np.ndarray, at: np.ndarray, width: int) -> np.ndarray:
    """The `width` bytes at each offset of `at` in b, one row each (a copy of just those bytes)."""
    if len(at) == 0 or len(b) < width:
        return np.empty((0, width), np.uint8)
    return np.lib.stride_tricks.sliding_window_view(b, width)[at]


def _chain(pos: np.ndarray, ends: np.ndarray, valid: np.ndarray, start: int) -> np.ndarray:
    """Indices of the candidates that are events: from `start`, each event's successor is the first
    sync word at or after its end (liblcm skips anything else). Stops before an invalid header."""
    nxt = np.searchsorted(pos, ends)
    k = len(pos)
    m = int(np.argmin(valid)) if not valid.all() else k  # the first not to read (the buffer's last, usually)
    if start == 0 and (nxt[:m] == np.arange(1, m + 1)).all():
        return np.arange(m)  # the usual case: every sync word begins an event and they are back to back
    out = []
    i = start
    while i < k and valid[i]:
        out.append(i)
        i = int(nxt[i])
    return np.array(out, dtype=np.int64)


def iter_chunks(path: Path, chunk_bytes: int = CHUNK_BYTES, damage: LogDamage | None = None) -> Iterator[Chunk]:
    """Every known channel's messages, chunk by chunk, in log order within each channel; `damage`
    (when given) says afterwards where the log breaks and what was not read."""
    dec = _Decoder()
    damage = damage if damage is not None else LogDamage()
    with open(path, "rb") as f:
        file_size = os.fstat(f.fileno()).st_size
        damage.size = file_size
        carry = b""
        eof = False
        want = chunk_bytes
        base = 0       # the file offset of the buffer's first byte
        prev_end = 0   # the file offset where the last event read ends
        while not eof:
            data = f.read(max(want, chunk_bytes))
            eof = len(data) < max(want, chunk_bytes) or f.tell() >= file_size
            buf = carry + data if carry else data
            if not buf:
                break
            b = np.frombuffer(buf, np.uint8)
            L = len(b)
            c = np.flatnonzero(b[:-3] == 0xED) if L >= 4 else np.empty(0, np.int64)
            c = c[(b[c + 1] == 0xA1) & (b[c + 2] == 0xDA) & (b[c + 3] == 0x01)]
            whole = c + HEADER <= L  # the header is in the buffer
            hdr_at = c[whole]
            h = _rows(b, hdr_at + 20, 8).view(">i4").astype(np.int64)
            chlen, datalen = h[:, 0], h[:, 1]
            ends = hdr_at + HEADER + chlen + datalen
            valid = (chlen > 0) & (chlen < MAX_CHANNEL) & (datalen >= 0)
            in_buf = valid & (ends <= L)
            events = _chain(hdr_at, ends, in_buf, 0)
            # where the next buffer starts: at the first event that is not whole here (or whose
            # header is not), else after the last whole event, keeping a sync word split by the read
            last_end = int(ends[events[-1]]) if len(events) else 0
            if len(events):
                numbers = _rows(b, hdr_at[events] + 4, 8).view(">i8").astype(np.int64).reshape(-1)
                prev_end = damage._read(base, hdr_at[events], ends[events], numbers, prev_end)
            stop = None
            if len(events):
                after = int(np.searchsorted(hdr_at, last_end))
                if after < len(hdr_at) and valid[after]:
                    stop = int(hdr_at[after])
                elif after < len(hdr_at):  # an invalid header on the chain: liblcm stops reading
                    eof, stop = True, L
                    damage._stopped(base + int(hdr_at[after]), _bad_header(chlen[after], datalen[after]))
            elif len(hdr_at) and valid[0]:
                stop = int(hdr_at[0])
            elif len(hdr_at):
                eof, stop = True, L
                damage._stopped(base + int(hdr_at[0]), _bad_header(chlen[0], datalen[0]))
            if stop is None:
                partial = c[~whole]
                stop = int(partial[0]) if len(partial) and partial[0] >= last_end else max(last_end, L - 3)
            if len(events):
                yield dec.decode(b, hdr_at[events], chlen[events], datalen[events])
            carry = buf[stop:]
            base += stop
            want = chunk_bytes
            if len(carry) >= HEADER and carry[:4] == SYNC:
                cl, dl = int.from_bytes(carry[20:24], "big", signed=True), int.from_bytes(carry[24:28], "big", signed=True)
                need = HEADER + cl + dl - len(carry)
                if need > file_size - f.tell():
                    # a torn last event (or a length no file this size can hold)
                    damage._stopped(base, f"an event of {HEADER + cl + dl} bytes, only {file_size - base} left in "
                                          "the file (cut short: a writer killed, a file truncated)")
                    break
                want = need
            if eof:
                if carry and stop < L:  # what is left is a torn last event, or bytes that are none
                    damage._stopped(base, "the file ends inside an event" if carry[:4] == SYNC[:len(carry[:4])]
                                    else "bytes after the last event that are no event")
                break


def _bad_header(chlen: int, datalen: int) -> str:
    return (f"an event header no event has (channel length {int(chlen)}, data length {int(datalen)}: flipped or "
            "overwritten bytes)")


def log_damage(path: Path) -> LogDamage:
    """Read a whole log only to say whether, and where, it breaks."""
    damage = LogDamage()
    for _ in iter_chunks(path, damage=damage):
        pass
    return damage


@dataclass
class ChannelLog:
    messages: Any = field(default_factory=list)  # a numpy record array (fixed-layout channels) or a list
    gaps: int = 0          # sequence numbers below the highest logged one that are missing
    duplicates: int = 0
    undecodable: int = 0


def read_log(path: Path, channels: tuple[str, ...] | None = None,
             damage: LogDamage | None = None) -> dict[str, ChannelLog]:
    """A whole run's messages per channel (fixed-layout ones as numpy record arrays: m.seq, m.w_true
    ...), through iter_chunks. Memory grows with the run: for one run's series, not the analysis."""
    wanted = set(channels or CHANNEL_TYPES)
    parts: dict[str, list[Any]] = {ch: [] for ch in CHANNEL_TYPES}
    out = {ch: ChannelLog() for ch in CHANNEL_TYPES}
    for chunk in iter_chunks(path, damage=damage):
        for ch, arr in chunk.arrays.items():
            if ch in wanted:
                parts[ch].append(arr)
        for ch, evs in chunk.events.items():
            if ch in wanted:
                parts[ch].extend(evs)
        for ch, n in chunk.undecodable.items():
            out[ch].undecodable += n
    for ch, log in out.items():
        if ch in FIXED_CHANNELS:
            arrs = [a for a in parts[ch] if len(a)]
            arr = np.concatenate(arrs) if arrs else np.empty(0, LAYOUTS[FIXED_CHANNELS[ch]].dtype(0, "="))
            log.messages = arr.view(np.recarray)
            seqs = arr["seq"]
        else:
            log.messages = parts[ch]
            seqs = np.array([m.seq for m in parts[ch]], dtype=np.int64)
        if len(seqs):
            unique = np.unique(seqs)
            log.duplicates = int(len(seqs) - len(unique))
            log.gaps = int(unique[-1] + 1 - len(unique))  # sequence numbers start at 0
    return out


def truth_rows(ctl: np.ndarray, sim: np.ndarray) -> np.ndarray:
    """For each controller message, the row of the simulator's message of the period it names
    (ctl.bus_period = sim.step; the last one logged for that step), or -1 where none was logged."""
    if len(sim) == 0:
        return np.full(len(ctl), -1, np.int64)
    steps, last = np.unique(sim["step"][::-1], return_index=True)
    rows = len(sim) - 1 - last  # the last logged message of each step, in the original order
    at = np.minimum(np.searchsorted(steps, ctl["bus_period"]), len(steps) - 1)
    return np.where(steps[at] == ctl["bus_period"], rows[at], -1).astype(np.int64)
