"""The HIL run's telemetry logger keeps every message through a stall (lcm-logger does not)."""

from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path

import lcm
import pytest

from tools.run.slots import LCM_GROUP, Slot

# armctl test runs these alone (no other test beside them): a logger stalled and woken on the wall clock
pytestmark = pytest.mark.serial

N_MESSAGES = 3000


def test_a_stalled_logger_loses_nothing_and_flushes_on_sigint(build_dir: Path, tmp_path: Path, slot: Slot) -> None:
    exe = build_dir / "tools" / "lcm_logger" / "arm_lcm_logger"
    if not exe.exists():
        pytest.skip(f"{exe} not built")
    url = f"udpm://{LCM_GROUP}:{slot.lcm_port}?ttl=0&recv_buf_size=8388608"
    log_path = tmp_path / "t.lcmlog"
    proc = subprocess.Popen([str(exe), "--lcm-url", url, str(log_path)], stderr=subprocess.PIPE, text=True)
    try:
        pub = lcm.LCM(url)
        end = time.monotonic() + 10
        while not (log_path.exists() and log_path.stat().st_size > 0):  # ready: a probe reached the file
            assert proc.poll() is None and time.monotonic() < end, "the logger did not start"
            pub.publish("PROBE", b"?")
            time.sleep(0.1)
        proc.send_signal(signal.SIGSTOP)  # a stall far longer than LCM's default 30-message queue lasts
        for i in range(N_MESSAGES):
            pub.publish("BURST", i.to_bytes(4, "little"))
        time.sleep(0.2)
        proc.send_signal(signal.SIGCONT)
        time.sleep(0.3)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    got = [int.from_bytes(e.data, "little") for e in lcm.EventLog(str(log_path), "r") if e.channel == "BURST"]
    assert got == list(range(N_MESSAGES))
    assert "write errors" in err and " 0 write errors" in err
