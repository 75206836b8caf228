"""A scripted bus master for tests of arm_sim: python-can on the real UDP buses, LCM for the
simulator's truth. It plays the controller's part of the protocol one step at a time (NMT, SYNC,
the CiA 402 enable sequence, commands) so a test can put exactly the frames it wants on the bus."""

from __future__ import annotations

import contextlib
import subprocess
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import can
import lcm

from gen import lcmtypes
from host_sim.canbus import open_bus
from host_sim.launch import sim_argv
from host_sim.protocol import NMT_START, NMT_STOP, DriveProtocol
from tools.run.slots import CAN_GROUP, LCM_GROUP, acquire_slot

OP_ENABLED_MASK, OP_ENABLED = 0x006F, 0x0027


@dataclass
class Truth:
    """ARM_SIM messages as they arrive (one per simulated period)."""

    messages: list = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)


class SimMaster:
    def __init__(self, sim_exe: Path, drives_per_bus: list[list[int]], *, extra: list[str] | None = None,
                 timing: str = "off", phys: list | None = None, n: int = 6) -> None:
        # a run slot's ports, held until stop(): no other test or run hears this bus or telemetry
        self._slot = contextlib.ExitStack()
        slot = self._slot.enter_context(acquire_slot(quiet_ports=True))
        port, lcm_port = slot.can_port, slot.lcm_port
        self.specs = [f"udp:{CAN_GROUP}:{port + i}" for i in range(len(drives_per_bus))]
        self.drives_per_bus = drives_per_bus
        self.bus_of = {d: i for i, ds in enumerate(drives_per_bus) for d in ds}
        self.proto = DriveProtocol(n)
        self.n = n
        self.url = f"udpm://{LCM_GROUP}:{lcm_port}?ttl=0"
        self.truth = Truth()
        self.events: list[str] = []
        self._lc = lcm.LCM(self.url)
        types = lcmtypes.load()
        subs = [self._lc.subscribe("ARM_SIM", lambda _c, data: self._on_truth(types.sim_truth_t.decode(data))),
                self._lc.subscribe("ARM_SIM_EVENT", lambda _c, data: self.events.append(types.event_t.decode(data).text))]
        for s in subs:
            s.set_queue_capacity(0)  # no limit: LCM's default of 30 drops while this test thread works
        self._stop = threading.Event()
        self._lcm_thread = threading.Thread(target=self._lcm_loop, daemon=True)
        self._lcm_thread.start()
        self.buses = [open_bus(s) for s in self.specs]
        buses = [f"{s}@{','.join(map(str, ds))}" for s, ds in zip(self.specs, drives_per_bus)]
        self.summary = Path(f"/tmp/sim_master_{port}.json")
        argv = sim_argv(sim_exe, buses, lcm_url=self.url, summary=self.summary, timing=timing, phys=phys,
                        extra=["--boot-timeout", "20", "--idle-timeout", "5", *(extra or [])])
        self.proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.counter = 0
        self.statusword = [0] * n

    def _on_truth(self, m) -> None:  # noqa: ANN001 - an lcm-gen message
        with self.truth.lock:
            self.truth.messages.append(m)

    def _lcm_loop(self) -> None:
        while not self._stop.is_set():
            self._lc.handle_timeout(50)

    # ---- frames -----------------------------------------------------------------------------
    def send(self, bus: int, frame_id: int, data: bytes, fd: bool = False) -> None:
        self.buses[bus].send(can.Message(arbitration_id=frame_id, data=data, is_extended_id=False, is_fd=fd,
                                         bitrate_switch=fd))

    def nmt(self, command: int) -> None:
        for b in range(len(self.buses)):
            self.send(b, self.proto.nmt.frame_id, bytes([command, 0]))

    def recv_states(self, timeout: float = 5.0) -> dict[int, dict]:
        """This period's DRIVE_i_STATE of every drive (others' frames are skipped)."""
        got: dict[int, dict] = {}
        end = time.monotonic() + timeout
        while len(got) < self.n and time.monotonic() < end:
            for b, bus in enumerate(self.buses):
                msg = bus.recv(0.01)
                if msg is None or msg.arbitration_id not in self.proto.state_joint:
                    continue
                j = self.proto.state_joint[msg.arbitration_id]
                v = self.proto.state_codec[j].decode(bytes(msg.data))
                if int(v["sync_counter"]) == self.counter:
                    got[j] = v
        assert len(got) == self.n, f"states of drives {sorted(set(range(self.n)) - set(got))} missing"
        return got

    def period(self, controlwords: list[int], torques: list[float]) -> dict[int, dict]:
        """SYNC on every bus, the drives' states, then each drive's command on its bus."""
        for b in range(len(self.buses)):
            self.send(b, self.proto.sync.frame_id, bytes([self.counter]))
        states = self.recv_states()
        for j in range(self.n):
            data = self.proto.cmd_codec[j].encode({"controlword": controlwords[j], "target_torque": torques[j],
                                                   "sync_counter": self.counter})
            self.send(self.bus_of[j + 1], self.proto.cmd[j].frame_id, data)
        self.statusword = [int(states[j]["statusword"]) for j in range(self.n)]
        self.counter = (self.counter + 1) % 256
        return states

    def wait_until_up(self, timeout: float = 20.0) -> None:
        """Until the simulator says its drives are up: it opens its sockets before that, so a frame
        sent earlier may reach no socket (a fixed sleep lost that race under a loaded machine)."""
        end = time.monotonic() + timeout
        while not any(" drives up on bus " in e for e in self.events):
            assert self.proc.poll() is None, f"arm_sim exited with {self.proc.returncode} before its drives were up"
            assert time.monotonic() < end, f"arm_sim's drives not up after {timeout} s"
            time.sleep(0.01)

    def boot_and_enable(self) -> None:
        """NMT start, then the CiA 402 sequence with zero torque until every drive is enabled."""
        self.wait_until_up()
        self.nmt(NMT_START)
        for _ in range(10):
            cws = [0x06 if (sw & 0x4F) == 0x40 else 0x07 if (sw & OP_ENABLED_MASK) == 0x21 else 0x0F
                   for sw in self.statusword]
            self.period(cws, [0.0] * self.n)
            if all((sw & OP_ENABLED_MASK) == OP_ENABLED for sw in self.statusword):
                return
        raise AssertionError(f"drives not enabled: statuswords {[hex(s) for s in self.statusword]}")

    def truth_of(self, step: int, timeout: float = 2.0):  # noqa: ANN201 - an lcm-gen message
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with self.truth.lock:
                for m in self.truth.messages:
                    if m.step == step:
                        return m
            time.sleep(0.01)
        raise AssertionError(f"no ARM_SIM message for step {step}")

    def stop(self) -> tuple[int, str]:
        """NMT stop (the end of a run); the simulator's exit code and stderr."""
        self.nmt(NMT_STOP)
        try:
            _, err = self.proc.communicate(timeout=20)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
            self._stop.set()
            for b in self.buses:
                b.shutdown()
            self._slot.close()
        return self.proc.returncode, err
