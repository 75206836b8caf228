"""A signal to armctl mid-run (a CI timeout, kill, Ctrl-C): the children stop in order, the
controller's safe-stop frames are on the bus, nothing is left running, and run.json says the run
was interrupted."""

from __future__ import annotations

import json
import signal
import subprocess
import time
from pathlib import Path

import pytest

from hil_procs import BusRecorder
from gen.lib.paths import REPO

# armctl test runs these alone (no other test beside them): signals sent into a run at moments of the wall clock
pytestmark = pytest.mark.serial

ARMCTL = str(REPO / "tools" / "armctl")
CMD_IDS = set(range(0x201, 0x207))


def _children_of(out: Path) -> list[str]:
    """Processes still running for this run (their command lines name its folder or its port)."""
    r = subprocess.run(["pgrep", "-af", str(out)], capture_output=True, text=True)
    return [ln for ln in r.stdout.splitlines() if "pgrep" not in ln]


@pytest.mark.parametrize("sig,protocol", [(signal.SIGTERM, "canopen"), (signal.SIGINT, "canopen"),
                                          (signal.SIGHUP, "canopen"), (signal.SIGTERM, "arm")])
def test_a_signal_to_armctl_stops_the_run_safely_and_leaves_nothing(tmp_path: Path, sig: signal.Signals,
                                                                     protocol: str) -> None:
    port = 45300 + 10 * int(sig) + (5 if protocol == "arm" else 0)
    rec = BusRecorder(f"udp:239.74.163.2:{port}")  # the first bus (CiA 402 on classic CAN: drives 1-2)
    out = tmp_path / "run"
    p = subprocess.Popen([ARMCTL, "hil", "--duration", "60", "--can-port", str(port), "--protocol", protocol,
                          "--out", str(out)], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not any(f.arbitration_id in CMD_IDS for f in rec.frames[-50:]):
        time.sleep(0.1)  # until the controller is commanding torques
    time.sleep(1.0)
    p.send_signal(sig)
    _, err = p.communicate(timeout=60)
    frames = rec.close()
    assert p.returncode == 128 + int(sig), err
    run = json.loads((out / "run.json").read_text())
    assert run["results"]["result"] == "interrupted", run["results"]["verdict_reasons"]
    assert not _children_of(out)
    # the controlled stop on the bus (RPDO1, COB-ID 0x200 + node, as the arm protocol's 0x200 + drive):
    # quick stop (controlword 0x0002) under the hold, the shoulder's (drive 2) torque its weight, never
    # zero torque alone; then disable voltage (0x0000) once the drives braked, then NMT stop
    cmds = [f for f in frames if f.arbitration_id in CMD_IDS]
    cw = [int.from_bytes(f.data[0:2], "little") for f in cmds]
    assert 0x02 in cw, cw[-20:]
    first_stop = cw.index(0x02)
    assert all(c in (0x02, 0x00) for c in cw[first_stop:]), cw[first_stop:]
    shoulder = [f for f in cmds[first_stop:] if f.arbitration_id == 0x202 and f.data[0] == 0x02]
    assert shoulder and all(any(f.data[2:4]) for f in shoulder), [bytes(f.data).hex() for f in shoulder[:3]]
    last = {f.arbitration_id: f for f in cmds}
    assert len(last) >= 2 and all(int.from_bytes(f.data[0:2], "little") == 0x00 for f in last.values()), \
        [bytes(f.data).hex() for f in last.values()]
    assert any(f.arbitration_id == 0x000 and f.data[0] == 0x02 for f in frames)
    assert "interrupted" in run["results"]["verdict_reasons"][0]
    # the arm braked and stayed where it was (canopen: the table's brakes; the arm protocol's drives have none)
    stop = run["results"]["stop"]
    assert stop["cause"] == "stop signal" and stop["braked"] is True, stop
    if protocol == "canopen":
        assert stop["moved_after_stop_max_deg"] <= 1.0, stop
    # the stop's commands came in periods of their own: the drives took them, none saw a second
    # master (the arm protocol's drives fault on a second command for one SYNC: a race between two buses
    # once made them, in the VM)
    sim = json.loads((out / "sim_summary.json").read_text())
    assert sim["rx_duplicate_command"] == 0 and not run["results"]["drive_faults"], (sim, run["results"]["drive_faults"])


def _handles(pid: int, sig: signal.Signals) -> bool:
    """The process has a handler of its own for sig (its SigCgt mask in /proc)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    caught = int(next(ln.split()[1] for ln in status.splitlines() if ln.startswith("SigCgt:")), 16)
    return bool(caught >> (int(sig) - 1) & 1)


def test_ctrl_c_before_any_child_is_a_one_line_exit(tmp_path: Path) -> None:
    """Ctrl-C (SIGINT) while only Python works (here a synthesis, in its imports): armctl exits
    130 with one line saying it was interrupted, no traceback, and writes no half a design."""
    out = tmp_path / "d"
    p = subprocess.Popen([ARMCTL, "synth", "--config", str(REPO / "gen" / "configs" / "paper.toml"), "--out",
                          str(out)], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # armctl's own handlers are in place (tools/run/procs.py install: SIGTERM is caught only by
    # them) once the command runs, and its synthesis has not begun: its imports take seconds
    deadline = time.monotonic() + 60
    while not _handles(p.pid, signal.SIGTERM) and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.005)
    assert p.poll() is None, "armctl synth ended before it could be interrupted"
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 128 + signal.SIGINT, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "interrupted" in lines[0] and "Traceback" not in err, err
    assert not (out / "manifest.json").exists() and not (out / "pm_design.txt").exists()
