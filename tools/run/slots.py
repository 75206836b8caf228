"""Run slots: each HIL run on this host holds one, and with it bus and telemetry ports no other
run uses at the same time. Guaranteed, not random: a slot is an exclusive lock (flock) on a file
in /run/lock (or the temp dir), held for the run by armctl and by every process it starts for the
run (they inherit the lock's descriptor: tools/run/procs.py), so it is free again only when the
last of them has ended: a run whose armctl was killed keeps its slot until its controller, which
stops the arm first, has exited too.

Slot i owns UDP ports CAN_BASE + 8 i .. + 3 (one per bus, up to four) and LCM_BASE + i, in ranges
that tests which pick their own ports (44000-44999) never touch.
"""

from __future__ import annotations

import fcntl
import os
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from gen.lib.multicast import CAN_GROUP, LCM_GROUP  # the groups a slot's ports are on
from tools.run import procs

MAX_SLOTS = 64
CAN_BASE = 46000  # .. 46511
LCM_BASE = 7800   # .. 7863


def _lock_dir() -> Path:
    for d in (Path("/run/lock"), Path(tempfile.gettempdir())):
        if d.is_dir() and os.access(d, os.W_OK):
            return d / "armctl-slots"
    raise OSError("no writable lock directory (/run/lock or the temp dir)")


@dataclass(frozen=True)
class Slot:
    index: int

    @property
    def can_port(self) -> int:
        return CAN_BASE + 8 * self.index

    @property
    def lcm_port(self) -> int:
        return LCM_BASE + self.index


LISTEN_S = 0.02  # a live lockstep run sends thousands of frames a second: 20 ms hears one


def ports_carry_traffic(slot: Slot, listen_s: float = LISTEN_S) -> bool:
    """Whether anything is sent on the slot's bus or telemetry ports: a run whose armctl was killed
    (before its children could follow) may still hold them, although its lock is gone."""
    import select
    import socket

    socks = []
    try:
        for group, port in [(CAN_GROUP, slot.can_port + b) for b in range(4)] + [(LCM_GROUP, slot.lcm_port)]:
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind((group, port))
            s.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP,
                         socket.inet_aton(group) + socket.inet_aton("127.0.0.1"))
            socks.append(s)
        ready, _, _ = select.select(socks, [], [], listen_s)
        return bool(ready)
    except OSError:
        return False  # no multicast here (no route to lo): the HIL run itself will say so
    finally:
        for s in socks:
            s.close()


@contextmanager
def acquire_slot(timeout_s: float = 600.0, prefer: Callable[[int], bool] | None = None,
                 quiet_ports: bool = False) -> Iterator[Slot]:
    """The lowest free slot (one that `prefer` likes first: e.g. the slot that already has this run's
    design built), held until the block ends; waits while all are taken. quiet_ports: a run on the
    slot's ports also needs them silent (ports_carry_traffic); a slot they are not is passed over."""
    d = _lock_dir()
    d.mkdir(parents=True, exist_ok=True)
    deadline = time.monotonic() + timeout_s
    while True:
        order = sorted(range(MAX_SLOTS), key=lambda i: not prefer(i)) if prefer else range(MAX_SLOTS)
        for i in order:
            fd = os.open(d / f"slot-{i}.lock", os.O_RDWR | os.O_CREAT, 0o666)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                continue
            if quiet_ports and ports_carry_traffic(Slot(i)):
                fcntl.flock(fd, fcntl.LOCK_UN)
                os.close(fd)
                continue
            procs.hold_for_children(fd)
            try:
                yield Slot(i)
            finally:
                procs.release_for_children(fd)
                # closed, not unlocked: an unlock would free the slot for children that hold it still
                os.close(fd)
            return
        if time.monotonic() > deadline:
            raise TimeoutError(f"all {MAX_SLOTS} run slots in {d} stayed taken for {timeout_s:g} s")
        time.sleep(0.05)


def default_jobs(bus: str = "udp") -> int:
    """Software in the loop: every core (a run is one thread that never waits on a socket). Over a
    bus, half the cores: the controller and the simulator of a lockstep run each poll the bus before
    they sleep, so one run keeps two cores busy (armctl bench study: --jobs 2 gave 0.95x the runs
    per minute of --jobs 1 on two cores)."""
    cores = os.cpu_count() or 1
    return cores if bus == "sil" else max(1, cores // 2)
