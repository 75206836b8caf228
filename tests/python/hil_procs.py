"""Helpers for tests that run the controller and simulator as real processes on a real bus."""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from pathlib import Path

import can

from host_sim.canbus import open_bus
from gen.lib.paths import REPO, env_with_repo


class BusRecorder:
    """Records every frame on the bus from a background thread."""

    def __init__(self, spec: str) -> None:
        self.bus = open_bus(spec)
        self.frames: list[can.Message] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(0.05)
            if msg is not None:
                self.frames.append(msg)

    def close(self) -> list[can.Message]:
        self._stop.set()
        self._thread.join(2)
        self.bus.shutdown()
        return self.frames


def start_sim(bus: str, *extra: str, summary: Path | None = None) -> subprocess.Popen[str]:
    args = [sys.executable, "-m", "host_sim", "--bus", bus, "--lcm-url", "", *extra]
    if summary is not None:
        args += ["--summary", str(summary)]
    return subprocess.Popen(args, cwd=REPO, env=env_with_repo(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def start_controller(exe: Path, bus: str, *extra: str) -> subprocess.Popen[str]:
    return subprocess.Popen([str(exe), "--bus", bus, "--lcm-url", "", *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def wait_exit(p: subprocess.Popen[str], timeout: float) -> tuple[int, float, str]:
    """Exit code, seconds it took, stderr."""
    t0 = time.monotonic()
    try:
        _, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        p.kill()
        _, err = p.communicate()
        raise AssertionError(f"{p.args[0]} still running after {timeout} s; stderr: {err}") from None
    return p.returncode, time.monotonic() - t0, err


def armctl(*args: str, timeout: float = 600.0) -> subprocess.CompletedProcess[str]:
    """tools/armctl as a user runs it; past `timeout` it is stopped (its children in order) and the
    test fails with what it printed."""
    from tools.run.procs import communicate_or_kill

    p = subprocess.Popen([str(REPO / "tools" / "armctl"), *args], cwd=REPO, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        out, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        p.terminate()
        out, err = communicate_or_kill(p, 60)
        raise AssertionError(f"armctl {' '.join(args)}: no end after {timeout:g} s\n{out}\n{err[-3000:]}") from None
    return subprocess.CompletedProcess(p.args, p.returncode, out, err)
