"""Run slots: each HIL run on this host holds one, and with it bus and telemetry ports no other
run uses at the same time. Guaranteed, not random: a slot is an exclusive lock (flock) on a file
in /run/lock (or the temp dir), held for the run and released when it ends or its process dies.

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


@contextmanager
def acquire_slot(timeout_s: float = 600.0, prefer: Callable[[int], bool] | None = None) -> Iterator[Slot]:
    """The lowest free slot (one that `prefer` likes first: e.g. the slot that already has this run's
    design built), held until the block ends; waits while all are taken."""
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
            try:
                yield Slot(i)
            finally:
                fcntl.flock(fd, fcntl.LOCK_UN)
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
