"""arm_sim's reorder ring (host_sim/native/sim_loop.c): a SYNC read on one bus first puts back what
is already queued on the other buses (sent before it), up to 256 frames, and itself. The ring holds
all of them; a frame it could not hold would be counted (rx_pending_dropped), never lost silently."""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path

import pytest

from sim_master import SimMaster

# armctl test runs these alone (no other test beside them): frames timed by the wall clock around the simulator
pytestmark = pytest.mark.serial

UNKNOWN_ID = 0x555  # no message of the DBC: arm_sim counts it (rx_unknown_id) and goes on


def test_a_sync_behind_a_full_other_bus_loses_no_frame(sim_exe: Path) -> None:
    flood = 300  # more than the 256 the SYNC path puts back: the rest wait in the socket
    m = SimMaster(sim_exe, [[1, 2, 3], [4, 5, 6]])
    try:
        m.wait_until_up()
        os.kill(m.proc.pid, signal.SIGSTOP)  # everything below is queued before it reads again
        try:
            for i in range(flood):
                m.send(1, UNKNOWN_ID, bytes([i & 0xFF]))
            time.sleep(0.05)
            m.send(0, m.proto.sync.frame_id, bytes([0]))  # bus 0 is served first: the SYNC, then bus 1's
            time.sleep(0.2)
        finally:
            os.kill(m.proc.pid, signal.SIGCONT)
        time.sleep(0.5)
    finally:
        code, err = m.stop()
    assert code == 0, err
    s = json.loads(m.summary.read_text())
    assert s["rx_kernel_drops"] == 0, s  # every frame reached the simulator's socket
    assert s["rx_pending_dropped"] == 0, s
    assert s["rx_unknown_id"] == flood, s
