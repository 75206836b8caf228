"""Lockstep simulator: six drives on the bus, the arm advancing one period per controller SYNC."""

from __future__ import annotations

import gc
import json
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import can
import lcm
import numpy as np

from gen import lcmtypes
from host_sim.arm import Arm
from host_sim.bus_timing import BusTimeline
from host_sim.drive import Drive
from host_sim.frame_io import Frame, FrameIO, MultiFrameIO
from host_sim.protocol import NMT_STATE_BOOT, DriveProtocol

HEARTBEAT_PERIODS = 100
DEFER_S = 0.2  # longest a next-period SYNC waits for this period's commands on another bus


@dataclass
class SimConfig:
    bus: str = "udp"
    lcm_url: str = "udpm://239.255.76.67:7667?ttl=0"
    boot_timeout_s: float = 60.0
    idle_timeout_s: float = 5.0
    command_timeout_periods: int = 3
    summary_path: str = ""
    # Bus timing emulation (host_sim/bus_timing.py): off; virtual (commands take effect when
    # their frames would end on the bus; for lockstep); wallclock (that, and state frames are sent
    # no earlier than they would end; for realtime runs).
    bus_timing: str = "off"
    # Last state frame in -> commands queued, on the emulated timeline. Not measured through this
    # simulator even in wallclock mode: its own receive latency (~0.1 ms of Python per period)
    # would dominate the controller's compute time (1.5 us p50, tools/armctl timing).
    controller_latency_s: float = 0.0


@dataclass
class SimReport:
    result: str = "ok"
    reason: str = ""
    periods: int = 0
    frames_tx: int = 0
    frames_rx: int = 0
    rx_own_echo: int = 0
    rx_unknown_id: int = 0
    rx_bad_frame: int = 0
    rx_wrong_bus: int = 0  # a command for a drive that is not on the bus it arrived on: ignored
    commands_missed: int = 0
    commands_late: int = 0  # bus timing: the command's frame ended after its period (not applied)
    commands_missed_per_drive: list[int] = field(default_factory=list)  # drive i+1, while operation enabled
    bus_timing: list[dict[str, Any]] = field(default_factory=list)  # per bus, when emulated
    telemetry_sent: dict[str, int] = field(default_factory=lambda: {"ARM_SIM": 0, "ARM_SIM_EVENT": 0})
    wall_s: float = 0.0
    drive_faults: list[int] = field(default_factory=list)


class Simulator:
    def __init__(self, cfg: SimConfig, bus: can.BusABC | list[can.BusABC], arm: Arm,
                 bus_of: list[int] | None = None, timing: list[BusTimeline] | None = None) -> None:
        """bus: one bus (every drive on it) or a list; bus_of[i]: index of drive i+1's bus;
        timing: one timeline per bus when cfg.bus_timing is not off."""
        self.cfg = cfg
        self.buses = list(bus) if isinstance(bus, (list, tuple)) else [bus]
        self.bus = self.buses[0]
        self.bus_of = list(bus_of) if bus_of is not None else [0] * arm.n
        if len(self.bus_of) != arm.n or any(not 0 <= b < len(self.buses) for b in self.bus_of):
            raise ValueError(f"bus_of {self.bus_of}: one bus index per drive, each < {len(self.buses)}")
        self.arm = arm
        self.proto = DriveProtocol(arm.n)
        self.drives = [
            Drive(node_id=i + 1, torque_limit=float(arm.torque_limit[i]),
                  command_timeout_periods=cfg.command_timeout_periods)
            for i in range(arm.n)
        ]
        self.report = SimReport()
        self.ios = [FrameIO(b, self.proto.own_ids) for b in self.buses]
        self.io = MultiFrameIO(self.ios)
        self.types = lcmtypes.load()
        self.lc = lcm.LCM(cfg.lcm_url) if cfg.lcm_url else None
        self.counter: int | None = None  # SYNC counter of the period being served
        self.synced: set[int] = set()  # buses whose SYNC for this period arrived
        self.got_cmd = [False] * arm.n
        self.cmd: list[tuple[int, float]] = [(0, 0.0)] * arm.n  # this period's (controlword, torque)
        if (cfg.bus_timing != "off") != (timing is not None) or (timing is not None and len(timing) != len(self.buses)):
            raise ValueError(f"bus timing '{cfg.bus_timing}' needs one timeline per bus ({len(self.buses)})")
        self.timing = timing
        self.period_wall = 0.0  # monotonic time of the period's first SYNC (wallclock timing)
        self.states_end = 0.0  # bus timing: when the last state frame of the period ended
        self.last_w = np.zeros(arm.n)
        self.last_tau = np.zeros(arm.n)

    # ---- bus -------------------------------------------------------------------------------
    def send(self, frame_id: int, data: bytes, fd: bool = False, bus: int = 0) -> None:
        self.ios[bus].send(frame_id, data, fd)
        self.report.frames_tx += 1

    def send_heartbeat(self, d: Drive, state: int | None = None) -> None:
        fid = self.proto.heartbeat[d.node_id - 1].frame_id
        self.send(fid, bytes([d.nmt_state if state is None else state]), bus=self.bus_of[d.node_id - 1])
        self._occupy_at_period_end(d, fid)

    def send_emcy(self, d: Drive, code: int) -> None:
        m = self.proto.emcy[d.node_id - 1]
        self.send(m.frame_id, m.encode({"error_code": code, "error_register": 0x01, "detail": 0}),
                  bus=self.bus_of[d.node_id - 1])
        self._occupy_at_period_end(d, m.frame_id)
        self.event(f"drive{d.node_id}", "fault", f"EMCY 0x{code:04x}: drive {d.node_id} fault, torque off")

    def _occupy_at_period_end(self, d: Drive, frame_id: int) -> None:
        """Heartbeats and EMCY are sent after a period's step: they delay the next SYNC if the
        bus is still busy with them."""
        if self.timing is not None and self.report.periods > 0:
            self.timing[self.bus_of[d.node_id - 1]].transmit(self.arm.period, [frame_id])

    def _emulate_commands(self) -> list[float | None]:
        """Bus timing: put this period's commands on their buses; per joint, the fraction of
        the period before its new command took effect, None if it ended after the period."""
        assert self.timing is not None
        period = self.arm.period
        effect: list[float | None] = [0.0] * self.arm.n
        queued = self.states_end + self.cfg.controller_latency_s
        for b, tl in enumerate(self.timing):
            joints = [j for j in range(self.arm.n) if self.bus_of[j] == b and self.got_cmd[j]]
            if not joints:
                continue
            ends = tl.transmit(queued, [self.proto.cmd[j].frame_id for j in joints])
            last = max(ends.values())
            tl.stats.periods += 1
            tl.stats.sync_to_last_cmd_sum_s += last
            tl.stats.sync_to_last_cmd_max_s = max(tl.stats.sync_to_last_cmd_max_s, last)
            for j in joints:
                end = ends[self.proto.cmd[j].frame_id]
                if end > period:
                    effect[j] = None
                    tl.stats.commands_late += 1
                    if tl.stats.commands_late == 1:  # the first one says so; the count says the rest
                        self.event(f"bus{b}", "warning",
                                   f"bus timing: drive {j + 1}'s command ended {end * 1e3:.3f} ms after its SYNC, "
                                   f"after its {period * 1e3:g} ms period: not applied (bus overloaded?)")
                else:
                    effect[j] = end / period
        return effect

    # ---- telemetry -------------------------------------------------------------------------
    def event(self, source: str, level: str, text: str) -> None:
        if self.lc is None:
            return
        m = self.types.event_t()
        m.seq = self.report.telemetry_sent["ARM_SIM_EVENT"]
        m.step = self.arm.step_count
        m.source, m.level, m.text = source, level, text
        self.lc.publish("ARM_SIM_EVENT", m.encode())
        self.report.telemetry_sent["ARM_SIM_EVENT"] += 1

    def publish_truth(self) -> None:
        if self.lc is None:
            return
        m = self.types.sim_truth_t()
        m.seq = self.report.telemetry_sent["ARM_SIM"]
        m.step = self.arm.step_count - 1  # the period whose torque produced w_true
        m.t = m.step * self.arm.period
        m.n = self.arm.n
        m.q = self.arm.q.tolist()
        m.qd = self.arm.qd.tolist()
        m.tau_applied = self.last_tau.tolist()
        m.w_true = self.last_w.tolist()
        m.drive_faults = sum(1 << i for i, d in enumerate(self.drives) if d.error_code)
        self.lc.publish("ARM_SIM", m.encode())
        self.report.telemetry_sent["ARM_SIM"] += 1

    # ---- one period ------------------------------------------------------------------------
    def finish_period(self) -> None:
        """Apply the period's commands and advance the arm by one step."""
        effect = self._emulate_commands() if self.timing is not None else None
        tau = np.empty(self.arm.n)
        tau_cmd = np.empty(self.arm.n)
        for j, (d, got) in enumerate(zip(self.drives, self.got_cmd)):
            before = d.applied_torque
            held_for = 0.0  # fraction of the period the previous torque still acts (bus timing)
            if got and effect is not None:
                if effect[j] is None:
                    got = False  # its frame ended after the period: too late for it
                    self.report.commands_late += 1
                else:
                    held_for = effect[j]  # type: ignore[assignment]
            if got:
                d.on_command(*self.cmd[j])
            was_fault = d.error_code
            d.on_period_end(got)
            if d.emcy_pending:
                for code in d.emcy_pending:
                    self.send_emcy(d, code)
                d.emcy_pending.clear()
            if not got and not was_fault:
                self.report.commands_missed += 1
            # One physics step per period: a torque that changes inside it acts as its time average.
            tau_cmd[j] = d.applied_torque
            tau[j] = held_for * before + (1.0 - held_for) * tau_cmd[j]
        self.last_tau = tau
        self.last_w = self.arm.step(tau, tau_cmd if self.timing is not None else None)
        self.report.periods += 1
        if self.report.periods % 2000 == 0:
            gc.collect(0)
        self.publish_truth()
        if self.arm.step_count % HEARTBEAT_PERIODS == 0:
            for d in self.drives:
                self.send_heartbeat(d)
        self.counter = None

    def on_sync(self, counter: int, bus: int = 0) -> None:
        """SYNC goes on every bus; the drives on `bus` answer on it. A period starts with its
        first SYNC; the same counter on another bus joins it."""
        if self.counter is not None and (counter != self.counter or bus in self.synced):
            self.finish_period()  # commands missing: the drives count it, the arm still moves
        if self.counter is None:
            self.counter = counter
            self.got_cmd = [False] * self.arm.n
            self.synced = set()
            if self.timing is not None:
                self.period_wall = time.monotonic()
                self.states_end = 0.0
                for tl in self.timing:
                    tl.new_period(self.arm.period)
        self.synced.add(bus)
        q, qd = self.arm.q, self.arm.qd
        send_at: dict[int, float] = {}
        if self.timing is not None:  # SYNC, then the drives' states in id order once it has ended
            tl = self.timing[bus]
            sync_end = tl.transmit(0.0, [self.proto.sync.frame_id])[self.proto.sync.frame_id]
            send_at = tl.transmit(sync_end, [self.proto.state[i].frame_id for i in range(self.arm.n)
                                             if self.bus_of[i] == bus])
            self.states_end = max([self.states_end, *send_at.values()])
        for i, d in enumerate(self.drives):
            if self.bus_of[i] != bus:
                continue
            data = self.proto.state_codec[i].encode({
                "position": float(q[i]), "velocity": float(qd[i]), "torque": d.applied_torque,
                "statusword": d.power.statusword, "sync_counter": counter, "error_code": d.error_code,
            })
            fid = self.proto.state[i].frame_id
            if self.cfg.bus_timing == "wallclock":  # not before the frame would have ended on the bus
                wait = self.period_wall + send_at[fid] - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
            self.send(fid, data, fd=True, bus=bus)

    def _holds_back(self, bus: int, msg: Frame) -> bool:
        """A SYNC on `bus` for the next period while this period's commands for drives on other
        buses are still missing, and the drives on `bus` have theirs. Such commands may still be
        on their way: a socket per bus (and, on vcan, a per-CPU receive backlog) does not keep
        the order between buses, so the next SYNC on one bus can overtake the commands on
        another. Commands missing on `bus` itself are really missing (one bus keeps its order)."""
        if len(self.ios) < 2 or self.counter is None or len(msg.data) != 1:
            return False
        if msg.data[0] == self.counter and bus not in self.synced:
            return False  # this period's SYNC on another bus
        mine = [self.got_cmd[j] for j in range(self.arm.n) if self.bus_of[j] == bus]
        others = [self.got_cmd[j] for j in range(self.arm.n) if self.bus_of[j] != bus]
        return all(mine) and not all(others)

    def on_command(self, joint: int, data: bytes, bus: int = 0) -> None:
        if self.bus_of[joint] != bus:
            self.report.rx_wrong_bus += 1  # not this drive's bus: a real drive never sees it
            return
        try:
            v = self.proto.cmd_codec[joint].decode(data)
        except Exception:  # noqa: BLE001 - a malformed frame is counted, never fatal
            self.report.rx_bad_frame += 1
            return
        if self.counter is None or int(v["sync_counter"]) != self.counter:
            return  # a command for another period: a real drive ignores it too
        self.cmd[joint] = (int(v["controlword"]), float(v["target_torque"]))
        self.got_cmd[joint] = True
        if all(self.got_cmd):
            self.finish_period()

    def on_nmt(self, data: bytes, bus: int = 0) -> bool:
        """NMT goes on every bus and reaches the drives on it. Returns False when the controller
        stopped the node set (end of run)."""
        if len(data) != 2:
            self.report.rx_bad_frame += 1
            return True
        command, node = data[0], data[1]
        for d in self.drives:
            if self.bus_of[d.node_id - 1] == bus and node in (0, d.node_id) and d.on_nmt(command):
                self.send_heartbeat(d)
        return not all(d.nmt_state == 0x04 for d in self.drives)

    # ---- main loop -------------------------------------------------------------------------
    def run(self) -> SimReport:
        # A collector pause of a few hundred ms would stall the lockstep loop; the loop makes
        # little cyclic garbage, so collect the young generation on our own schedule instead.
        gc.disable()
        try:
            return self._run()
        finally:
            gc.enable()

    def _run(self) -> SimReport:
        t0 = time.monotonic()
        for d in self.drives:
            self.send_heartbeat(d, NMT_STATE_BOOT)  # CANopen boot-up message
        self.event("sim", "info", f"{self.arm.n} drives up on bus {self.cfg.bus}")
        booted = False
        cmd_joint, sync_id, nmt_id = self.proto.cmd_joint, self.proto.sync.frame_id, self.proto.nmt.frame_id
        # Frames read but not handled yet: (bus, frame, flag);
        # flag: 0 fresh, 1 other buses already drained for it, 2 that and never held back again
        pending: list[tuple[int, Frame, int]] = []
        # Next-period SYNCs held back while the current period still waits for commands on other
        # buses (see _holds_back): handled once the period is complete, every bus moved on, or
        # DEFER_S passed without the missing commands.
        deferred: list[tuple[int, Frame, int]] = []
        while True:
            timeout = self.cfg.idle_timeout_s if booted else self.cfg.boot_timeout_s
            if deferred and (self.counter is None or len(deferred) >= len(self.ios)):
                pending[:0] = [(b, f, 2) for b, f, _ in deferred]
                deferred = []
            flag = 0
            if pending:
                bus, msg, flag = pending.pop(0)
                got = (bus, msg)
            else:
                got = self.io.recv(min(timeout, DEFER_S) if deferred else timeout)
                if got is None and deferred:
                    # the missing commands never came: the period ends without them
                    pending[:0] = [(b, f, 2) for b, f, _ in deferred]
                    deferred = []
                    continue
            if got is not None and len(self.ios) > 1 and not flag and got[1].id in (sync_id, nmt_id):
                # SYNC and NMT go on every bus. Order between buses is lost in the sockets: what is
                # already queued on the other buses was sent before this frame (e.g. the previous
                # period's commands), so it is handled first.
                earlier = [(i, f, 1) for i, io in enumerate(self.ios) if i != got[0]
                           for f in iter(io.poll, None)]
                if earlier:
                    pending[:0] = [*earlier, (got[0], got[1], 1)]
                    continue
            if got is not None and flag != 2 and got[1].id == sync_id and self._holds_back(got[0], got[1]) \
                    and all(b != got[0] for b, _, _ in deferred):
                deferred.append((got[0], got[1], 1))
                continue
            if got is None:
                who = "controller silent" if booted else "no controller on the bus"
                self.report.result = "controller-lost"
                self.report.reason = f"{who} for {timeout:g} s: drives faulted, torque off"
                for d in self.drives:
                    d.fault(1, 0x8130)  # CiA 301: life guard / heartbeat error
                    for code in d.emcy_pending:
                        self.send_emcy(d, code)
                    d.emcy_pending.clear()
                break
            bus, msg = got
            self.report.frames_rx += 1
            fid = msg.id
            if msg.bad:
                self.report.rx_bad_frame += 1
            elif fid == sync_id:
                booted = True
                if len(msg.data) != 1:
                    self.report.rx_bad_frame += 1
                else:
                    self.on_sync(msg.data[0], bus)
            elif fid in cmd_joint:
                self.on_command(cmd_joint[fid], msg.data, bus)
            elif fid == nmt_id:
                booted = True
                if not self.on_nmt(msg.data, bus):
                    break
            else:
                self.report.rx_unknown_id += 1
        self.report.wall_s = time.monotonic() - t0
        self.report.rx_own_echo = self.io.echoes
        self.report.rx_bad_frame += self.io.undecodable
        self.report.drive_faults = [d.node_id for d in self.drives if d.error_code]
        self.report.commands_missed_per_drive = [d.commands_missed for d in self.drives]
        if self.timing is not None:
            self.report.bus_timing = [{"bus": i, "phy": tl.bus.describe(), "drives": tl.bus.drives,
                                       **tl.stats.as_dict()} for i, tl in enumerate(self.timing)]
        self.event("sim", "info" if self.report.result == "ok" else "fault",
                   self.report.reason or f"stopped by the controller after {self.report.periods} periods")
        return self.report


def write_summary(path: str, report: SimReport) -> None:
    tmp = f"{path}.tmp.{os.getpid()}"
    Path(tmp).write_text(json.dumps(asdict(report), indent=2))
    os.replace(tmp, path)


def report_dict(report: SimReport) -> dict[str, Any]:
    return asdict(report)
