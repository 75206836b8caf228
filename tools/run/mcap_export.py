"""A run in one MCAP file (`armctl export RUN_DIR --mcap`), for the field's viewers: Foxglove and
Lichtblick, PlotJuggler's MCAP loader, the `mcap` CLI.

- Every LCM channel of the run's telemetry.lcmlog is a topic of its own name, every message in it
  once, as JSON with a JSON schema made from its lcm-gen type (each field, its type, arrays as
  arrays: `ARM_CTL.e[2]` is joint 3's tracking error in rad).
- Every frame of the run's capture (bus.log or bus.log.gz) is a message of topic
  `can/BUS/MESSAGE`, decoded with the run's DBC (run.json environment.dbc: the drive table's
  canopen.dbc, or the arm protocol's) into its named signals, in the DBC's units (SI: rad, rad/s,
  N m), under `signals`; the raw frame under `frame` (`bus`, `id`, `data` in hex, `is_fd`). A
  frame no DBC message describes goes to `can/BUS/unknown`, raw.
- One timeline, the run's: in lockstep and in software in the loop the simulated time the capture
  keeps (a controller message at its bus period, a simulator message at its step, both times the
  loop period); in realtime the wall clock (the logger's receive time, the capture's own). A
  message's publish_time is the LCM logger's receive time; its sequence is its `seq`.

Non-finite floats (a faulted run's) are JSON null: JSON has no NaN.

A damaged log or capture is exported as far as it can be read and named: where it breaks (the
log's byte offset and event number, the capture's line), what was skipped and what was left unread
(Exported.log_damage, .capture_damage; `armctl export` says so and exits 1). The log is read
through the events tools/run/telemetry_log.py finds, bytes that are no event skipped, so the
export and the run's analysis read the same events.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gen import lcmtypes
from tools.run.run_files import RUN_RECORD, TELEMETRY_LOG
from tools.run.telemetry_log import LogDamage, log_damage

MCAP_FILE = "telemetry.mcap"
CAN_PREFIX = "can"
UNKNOWN_FRAME = "unknown"
LCM_JSON_TYPES = {"int8_t": "integer", "int16_t": "integer", "int32_t": "integer", "int64_t": "integer",
                  "byte": "integer", "boolean": "boolean", "float": "number", "double": "number", "string": "string"}
# Which clock each of our channels keeps in lockstep: the controller's bus period, the controller's
# step (mapped to its bus period through ARM_CTL), the simulator's step. Another channel's message
# is put at the time of the message logged before it.
STEP_CLOCK = {"ARM_CTL": "bus_period", "ARM_TIMING": "controller", "ARM_EVENT": "controller",
              "ARM_SIM": "simulator", "ARM_SIM_EVENT": "simulator"}


class ExportError(Exception):
    """A run that cannot be exported: one line naming the file and what is wrong."""


@dataclass
class Exported:
    path: Path
    lcm: dict[str, int] = field(default_factory=dict)        # LCM channel -> messages written
    can: dict[str, int] = field(default_factory=dict)        # topic -> frames written
    undecodable: dict[str, int] = field(default_factory=dict)  # LCM channel -> messages no type decodes
    capture: Path | None = None
    dbc: Path | None = None
    timeline: str = ""
    log_damage: LogDamage | None = None      # where the log breaks (None: it is whole)
    capture_damage: str | None = None        # where the capture breaks and what was left unread
    capture_damage_of: Any = field(default_factory=lambda: CaptureDamage())  # read as the capture is


@dataclass
class CaptureDamage:
    """Where a capture breaks: lines no frame (line number, byte offset), an end inside the file."""
    lines_read: int = 0
    bad_lines: list[tuple[int, int, str]] = field(default_factory=list)  # (line, byte offset, why)
    stop: str | None = None                  # why reading ended before the file did
    unread: int = 0                          # bytes of the file (compressed, for a .gz) not read

    def describe(self, path: Path, size: int) -> str | None:
        parts = []
        if self.bad_lines:
            line, at, why = self.bad_lines[0]
            parts.append(f"{len(self.bad_lines)} line(s) that are no frame skipped, the first line {line} at byte "
                         f"{at} ({why})")
        if self.stop:
            parts.append(f"it breaks after line {self.lines_read}: {self.stop}; " + (
                f"{self.unread} of its {size} bytes left unread" if self.unread else "what followed is lost"))
        return f"{path}: " + "; ".join(parts) + f"; {self.lines_read} lines read" if parts else None


def _schema_of(cls: Any, types: Any) -> dict[str, Any]:
    """The JSON schema of an lcm-gen class: every field, arrays as arrays, nested types as objects."""
    props: dict[str, Any] = {}
    for name, typename, dims in zip(cls.__slots__, cls.__typenames__, cls.__dimensions__):
        if typename in LCM_JSON_TYPES:
            item: dict[str, Any] = {"type": LCM_JSON_TYPES[typename]}
            if item["type"] == "number":
                item = {"type": ["number", "null"]}
        else:
            item = _schema_of(getattr(types, typename.rpartition(".")[2]), types)
        for _ in dims or ():
            item = {"type": "array", "items": item}
        props[name] = item
    return {"type": "object", "title": cls.__name__, "properties": props}


def _value(v: Any) -> Any:
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, (list, tuple)):
        return [_value(x) for x in v]
    if hasattr(v, "__slots__") and hasattr(v, "__typenames__"):
        return {k: _value(getattr(v, k)) for k in v.__slots__}
    if isinstance(v, bytes):
        return list(v)
    return v


def lcm_events(path: Path, damage: LogDamage | None = None) -> Iterator[tuple[str, int, bytes]]:
    """(channel, logger timestamp in us, data) of every event of an LCM log, in log order, read by
    liblcm's own reader (the lcm package); where `damage` (tools/run/telemetry_log.py's reading of
    the same file) found bytes that are no event, on after them, as that reader goes on."""
    import lcm

    # liblcm gives up on an event not followed by a sync word: on at the next event found after it
    resume = sorted((k["offset"], k["offset"] + k["bytes"]) for k in (damage.skipped if damage else []))
    try:
        log = lcm.EventLog(str(path), "r")
    except (OSError, ValueError) as exc:
        raise ExportError(f"{path}: not an LCM log ({exc})") from None
    try:
        at = 0
        while True:
            ev = log.read_next_event()
            if ev is None:
                after = next((i for i, (skip_at, _) in enumerate(resume) if skip_at >= at), None)
                if after is None:
                    break
                at = resume.pop(after)[1]
                log.seek(at)
                continue
            at = log.tell()
            yield ev.channel, int(ev.timestamp), bytes(ev.data)
    finally:
        log.close()


def _decode_lcm(path: Path, damage: LogDamage | None = None) -> tuple[list[tuple[str, int, Any]], dict[str, int],
                                                                    dict[str, Any]]:
    """Every message of the log decoded by its fingerprint: (channel, logger us, message) in log
    order; per channel the messages no type decodes; per channel its type's class."""
    types = lcmtypes.load()
    by_fp = {}
    for name in dir(types):
        cls = getattr(types, name)
        if hasattr(cls, "_get_packed_fingerprint"):
            by_fp[cls._get_packed_fingerprint()] = cls
    out, undecodable, classes = [], {}, {}
    for channel, stamp, data in lcm_events(path, damage):
        cls = by_fp.get(data[:8])
        try:
            if cls is None:
                raise ValueError("unknown fingerprint")
            msg = cls.decode(data)
        except Exception:  # noqa: BLE001 - lcm-gen's decode raises ValueError, struct.error, ...: counted
            undecodable[channel] = undecodable.get(channel, 0) + 1
            continue
        if classes.setdefault(channel, cls) is not cls:  # one channel, one schema: another type is not it
            undecodable[channel] = undecodable.get(channel, 0) + 1
            continue
        out.append((channel, stamp, msg))
    return out, undecodable, classes


def _lockstep_times(msgs: list[tuple[str, int, Any]], period: float) -> list[float]:
    """Each message's time on the simulator's clock (s): see STEP_CLOCK."""
    ctl = np.array([(m.step, m.bus_period) for ch, _, m in msgs if ch == "ARM_CTL"], dtype=np.int64).reshape(-1, 2)
    ctl = ctl[np.argsort(ctl[:, 0], kind="stable")]

    def bus_period_of(step: int) -> int:
        if not len(ctl):
            return step
        i = min(int(np.searchsorted(ctl[:, 0], step)), len(ctl) - 1)
        return int(step + ctl[i, 1] - ctl[i, 0])

    times, last = [], 0.0
    for ch, _, m in msgs:
        clock = STEP_CLOCK.get(ch)
        if clock == "bus_period":
            last = m.bus_period * period
        elif clock == "controller":
            last = bus_period_of(m.step) * period
        elif clock == "simulator":
            last = m.step * period
        times.append(last)
    return times


def _run_file(run_dir: Path, recorded: str | None) -> Path | None:
    """A file run.json names: where it was written, else (a run folder moved) beside run.json."""
    if not recorded:
        return None
    p = Path(recorded)
    if p.exists():
        return p
    here = run_dir / p.name
    return here if here.exists() else None


class _Lines:
    """A capture's lines, counted: python-can's candump reader reads through it, and a reader that
    gave up on a bad line is followed by a new one on the next line."""

    def __init__(self, capture: Path) -> None:
        import gzip

        self.raw = open(capture, "rb")
        self.stream = gzip.GzipFile(fileobj=self.raw) if capture.suffix == ".gz" else self.raw
        self.line = 0
        self.offset = 0  # of the line being read, in the (uncompressed) text
        self.next_offset = 0

    def __iter__(self) -> Iterator[str]:
        for raw in self.stream:
            self.line += 1
            self.offset, self.next_offset = self.next_offset, self.next_offset + len(raw)
            yield raw.decode("utf-8", "replace")

    def close(self) -> None:
        self.stream.close()
        self.raw.close()


def _frames(capture: Path, damage: CaptureDamage) -> Iterator[Any]:
    """Every frame of a candump log (or its .gz), in its order: a line that is no frame skipped and
    named, an end inside the file (a torn gzip stream, bytes that are no text) named."""
    import zlib

    from can.io.canutils import CanutilsLogReader

    try:
        lines = _Lines(capture)
    except OSError as exc:
        raise ExportError(f"{capture}: {exc.strerror or exc}") from None
    try:
        while True:
            reader = CanutilsLogReader(lines)
            try:
                for fr in reader:
                    damage.lines_read = lines.line
                    yield fr
                return
            except (ValueError, IndexError) as exc:  # python-can's parser on a line that is no frame
                damage.bad_lines.append((lines.line, lines.offset, f"{type(exc).__name__}: {exc}"))
                damage.lines_read = lines.line
            except (EOFError, OSError, zlib.error) as exc:  # a gzip stream cut short or corrupt
                damage.stop = f"{type(exc).__name__}: {exc}"
                damage.unread = max(0, capture.stat().st_size - lines.raw.tell())
                return
    finally:
        lines.close()


FRAME_SCHEMA = {"type": "object", "properties": {
    "bus": {"type": "string"}, "id": {"type": "integer"}, "data": {"type": "string", "description": "its bytes, hex"},
    "is_fd": {"type": "boolean"}}}


def _can_schema(msg: Any) -> dict[str, Any]:
    """A DBC message's topic: the raw frame, and its signals (apart: a signal may be named `data`)."""
    return {"type": "object", "title": msg.name, "properties": {
        "frame": FRAME_SCHEMA,
        "signals": {"type": "object", "properties": {
            s.name: {"type": ["number", "null"], "description": f"{s.comment or s.name} ({s.unit or 'no unit'})"}
            for s in msg.signals}}}}


RAW_SCHEMA = {"type": "object", "title": "CAN frame", "properties": {
    "frame": FRAME_SCHEMA, "error": {"type": "string", "description": "why its DBC message did not decode it"}}}


def _read_run(run_dir: Path) -> tuple[dict[str, Any], dict[str, Any], str, float]:
    """run.json's results and environment, the run's mode and loop rate."""
    try:
        run = json.loads((run_dir / RUN_RECORD).read_text())
        res, env = run["results"], run["environment"]
        return res, env, str(res["mode"]), float(res["rate_hz"])
    except FileNotFoundError:
        raise ExportError(f"{run_dir / 'run.json'}: no such file: not a run folder (armctl hil --out writes one)") from None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ExportError(f"{run_dir / 'run.json'}: not a run's results ({type(exc).__name__}: {exc})") from None


def _capture_and_dbc(run_dir: Path, env: dict[str, Any], result: Exported) -> tuple[Path | None, Path | None, Any]:
    """The run's capture, the DBC that decodes it and that DBC loaded (all None: no capture kept)."""
    capture = _run_file(run_dir, env.get("capture"))
    if capture is None:
        return None, None, None
    dbc_path = _run_file(run_dir, env.get("dbc"))
    if dbc_path is None:
        raise ExportError(f"{run_dir / 'run.json'}: environment.dbc {env.get('dbc')!r}: no such file, and none "
                          "beside run.json: the capture cannot be decoded")
    import cantools

    try:
        db = cantools.database.load_file(str(dbc_path), strict=False)
    except Exception as exc:  # noqa: BLE001 - cantools raises its own parse errors
        raise ExportError(f"{dbc_path}: not a DBC cantools reads ({type(exc).__name__}: {exc})") from None
    result.capture, result.dbc = capture, dbc_path
    return capture, dbc_path, db


def _lcm_channels(w: Any, classes: dict[str, Any]) -> dict[str, int]:
    """Each LCM channel registered with its type's JSON schema: its MCAP channel id."""
    channel_ids = {}
    for ch, cls in classes.items():
        sid = w.register_schema(name=f"armlcm.{cls.__name__}", encoding="jsonschema",
                                data=json.dumps(_schema_of(cls, lcmtypes.load())).encode())
        channel_ids[ch] = w.register_channel(topic=ch, message_encoding="json", schema_id=sid,
                                             metadata={"source": "LCM", "lcm_type": cls.__name__})
    return channel_ids


def _write_merged(w: Any, msgs: list[Any], times_ns: list[int], channel_ids: dict[str, int],
                  pending: Iterator[tuple[int, int, bytes]], result: Exported) -> None:
    """The LCM messages and the capture's frames, in one order of time."""
    order = sorted(range(len(msgs)), key=lambda i: times_ns[i])  # stable: log order within a time
    nxt = next(pending, None)
    for i in order:
        while nxt is not None and nxt[0] < times_ns[i]:
            w.add_message(nxt[1], log_time=nxt[0], data=nxt[2], publish_time=nxt[0])
            nxt = next(pending, None)
        ch, stamp, m = msgs[i]
        w.add_message(channel_ids[ch], log_time=times_ns[i], publish_time=stamp * 1000,
                      sequence=int(getattr(m, "seq", 0)) & 0xFFFFFFFF,
                      data=json.dumps({k: _value(getattr(m, k)) for k in m.__slots__},
                                      allow_nan=False).encode())
        result.lcm[ch] = result.lcm.get(ch, 0) + 1
    while nxt is not None:
        w.add_message(nxt[1], log_time=nxt[0], data=nxt[2], publish_time=nxt[0])
        nxt = next(pending, None)


def export_mcap(run_dir: Path, out: Path | None = None,
                progress: Callable[[str], None] | None = None) -> Exported:
    """RUN_DIR's telemetry and capture into one MCAP file (default RUN_DIR/telemetry.mcap)."""
    from mcap.writer import CompressionType, Writer

    say = progress or (lambda _: None)
    res, env, mode, rate = _read_run(run_dir)
    log_path = run_dir / TELEMETRY_LOG
    if not log_path.exists():
        raise ExportError(f"{log_path}: no such file: the run kept no telemetry")
    out = out or run_dir / MCAP_FILE
    realtime = mode == "realtime"
    result = Exported(path=out, timeline="the wall clock (realtime)" if realtime else
                      f"simulated time, s (the loop period {1e3 / rate:g} ms a step)")

    say(f"reading {log_path}")
    damage = log_damage(log_path)
    result.log_damage = damage if damage.damaged else None
    msgs, result.undecodable, classes = _decode_lcm(log_path, damage)
    times_ns = ([stamp * 1000 for _, stamp, _ in msgs] if realtime else
                [round(t * 1e9) for t in _lockstep_times(msgs, 1.0 / rate)])
    capture, dbc_path, db = _capture_and_dbc(run_dir, env, result)

    tmp = out.with_name(f".{out.name}.tmp")
    try:
        with open(tmp, "wb") as f:
            w = Writer(f, compression=CompressionType.ZSTD)
            w.start(profile="", library="armctl export")
            w.add_metadata("run", {"run_dir": str(run_dir), "method": str(res.get("method")),
                                   "result": str(res.get("result")), "mode": mode, "rate_hz": f"{rate:g}",
                                   "arm": str(res.get("arm", {}).get("name")), "timeline": result.timeline,
                                   "joint_names": ",".join(res.get("joint_names") or []),
                                   "telemetry_log": damage.describe()})
            channel_ids = _lcm_channels(w, classes)
            pending = _can_messages(capture, db, w, realtime, result) if capture is not None else iter(())
            say(f"writing {out}" + (f" with {capture.name} decoded by {dbc_path.name}" if capture and dbc_path else ""))
            _write_merged(w, msgs, times_ns, channel_ids, pending, result)
            if capture is not None:
                result.capture_damage = result.capture_damage_of.describe(capture, capture.stat().st_size)
                if result.capture_damage:
                    w.add_metadata("capture", {"damage": result.capture_damage})
            w.finish()
            f.flush()
            os.fsync(f.fileno())
        tmp.replace(out)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return result


def _can_messages(capture: Path, db: Any, w: Any, realtime: bool, result: Exported) -> Iterator[tuple[int, int, bytes]]:
    """(log time ns, channel id, JSON) of every frame of the capture, in its order, each frame's
    topic registered on first use."""
    by_id = {(m.frame_id, m.is_extended_frame): m for m in db.messages}
    channels: dict[str, int] = {}
    schemas: dict[str, int] = {}
    for fr in _frames(capture, result.capture_damage_of):
        bus = str(fr.channel)
        msg = by_id.get((fr.arbitration_id, fr.is_extended_id))
        body: dict[str, Any] = {"frame": {"bus": bus, "id": int(fr.arbitration_id), "data": bytes(fr.data).hex(),
                                          "is_fd": bool(fr.is_fd)}}
        name = msg.name if msg is not None else UNKNOWN_FRAME
        if msg is not None:
            try:
                body["signals"] = {k: _value(float(v)) for k, v in
                                   msg.decode(bytes(fr.data), decode_choices=False, allow_truncated=True).items()}
            except Exception as exc:  # noqa: BLE001 - a frame its DBC message cannot decode: kept raw, named
                name, body["error"] = UNKNOWN_FRAME, f"{msg.name}: {exc}"
        topic = f"{CAN_PREFIX}/{bus}/{name}"
        if topic not in channels:
            if name not in schemas:
                schema = RAW_SCHEMA if msg is None or name == UNKNOWN_FRAME else _can_schema(msg)
                schemas[name] = w.register_schema(name=f"can.{name}", encoding="jsonschema",
                                                  data=json.dumps(schema).encode())
            channels[topic] = w.register_channel(topic=topic, message_encoding="json", schema_id=schemas[name],
                                                 metadata={"source": "CAN capture", "bus": bus})
        result.can[topic] = result.can.get(topic, 0) + 1
        yield round(fr.timestamp * 1e9), channels[topic], json.dumps(body, allow_nan=False).encode()

