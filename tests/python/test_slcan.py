"""python-can's slcan interface (4.6.1) and ours on one SLCAN line: python-can's parser reads every
frame our transport writes (classic, extended, remote, CAN FD with and without bit-rate switch),
ours reads every frame python-can writes, and each side's command (O, which opens an adapter's channel) is
taken as a command, not a frame.

The line: a TCP relay in this test between two listening sockets, one for our transport
(tests/c/transport/slcan_tool: arm_can_slcan, slcan:127.0.0.1:PORT) and one for python-can
(channel socket://127.0.0.1:PORT, pyserial's TCP client), copying bytes both ways as a serial
cable does. Every socket is on 127.0.0.1."""

from __future__ import annotations

import os
import re
import socket
import subprocess
import threading
from pathlib import Path

import pytest

can = pytest.importorskip("can")

BUILD_DIR = Path(os.environ.get("ARM_BUILD_DIR", Path(__file__).resolve().parents[2] / "build" / "debug"))
TOOL = BUILD_DIR / "tests" / "c" / "transport" / "slcan_tool"
FLAG_FD, FLAG_BRS, FLAG_EXT, FLAG_RTR = 0x01, 0x02, 0x04, 0x10


def _listener() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.bind(("127.0.0.1", 0))
    s.listen(1)
    return s


def _relay(a: socket.socket, b: socket.socket, seen: bytearray) -> None:
    """Copies a -> b until a closes (then closes b's sending side)."""
    try:
        while data := a.recv(4096):
            seen.extend(data)
            b.sendall(data)
        b.shutdown(socket.SHUT_WR)
    except OSError:
        pass  # the other end went first: the test is over


def _parse(line: str) -> tuple[int, int, int, bytes]:
    ident, length, flags, data = line.split()
    return int(ident, 16), int(length), int(flags, 16), b"" if data == "-" else bytes.fromhex(data)


def _as_tuple(m: can.Message) -> tuple[int, int, int, bytes]:
    flags = ((FLAG_FD if m.is_fd else 0) | (FLAG_BRS if m.bitrate_switch else 0) |
             (FLAG_EXT if m.is_extended_id else 0) | (FLAG_RTR if m.is_remote_frame else 0))
    return m.arbitration_id, m.dlc, flags, b"" if m.is_remote_frame else bytes(m.data)


def test_python_can_slcan_and_ours_read_each_others_frames() -> None:
    if not TOOL.exists():
        pytest.skip(f"{TOOL} not built (build the C tests or set ARM_BUILD_DIR)")
    ours_l, theirs_l = _listener(), _listener()
    ours_port, theirs_port = ours_l.getsockname()[1], theirs_l.getsockname()[1]
    to_send = [
        can.Message(arbitration_id=0x701, data=[0x05], is_extended_id=False),
        can.Message(arbitration_id=0x281, data=[0x00, 0x00, 0x37, 0x00], is_extended_id=False),
        can.Message(arbitration_id=0x12345678, data=bytes(range(8)), is_extended_id=True),
        can.Message(arbitration_id=0x7E0, is_remote_frame=True, dlc=2, is_extended_id=False),
        can.Message(arbitration_id=0x1F0, data=bytes(range(20)), is_fd=True, is_extended_id=False),
        can.Message(arbitration_id=0x1F1, data=bytes(range(64)), is_fd=True, bitrate_switch=True, is_extended_id=False),
    ]
    tool = subprocess.Popen([str(TOOL), f"127.0.0.1:{ours_port}", str(len(to_send))], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        ours_l.settimeout(20)
        ours, _ = ours_l.accept()
        bus_box: list[can.BusABC] = []
        opener = threading.Thread(target=lambda: bus_box.append(
            can.Bus(interface="slcan", channel=f"socket://127.0.0.1:{theirs_port}", sleep_after_open=0)))
        opener.start()
        theirs_l.settimeout(20)
        theirs, _ = theirs_l.accept()
        opener.join(20)
        bus = bus_box[0]
        to_ours, to_theirs = bytearray(), bytearray()
        relays = [threading.Thread(target=_relay, args=(ours, theirs, to_theirs), daemon=True),
                  threading.Thread(target=_relay, args=(theirs, ours, to_ours), daemon=True)]
        for r in relays:
            r.start()
        # ours -> python-can: every frame the tool sent, in order, as python-can's parser reads it
        received = []
        while len(received) < 10:
            m = bus.recv(timeout=10)
            assert m is not None, f"python-can read {len(received)} frames; the line carried {bytes(to_theirs)!r}"
            received.append(_as_tuple(m))
        for m in to_send:
            bus.send(m)
        out, err = tool.communicate(timeout=30)
        bus.shutdown()
    finally:
        if tool.poll() is None:
            tool.kill()
        ours_l.close()
        theirs_l.close()
    assert tool.returncode == 0, err
    sent = [_parse(line[5:]) for line in out.splitlines() if line.startswith("sent ")]
    assert len(sent) == 10 and received == sent, (received, sent)
    # python-can -> ours: every frame it sent, as our decoder reads it
    recv = [_parse(line[5:]) for line in out.splitlines() if line.startswith("recv ")]
    assert recv == [_as_tuple(m) for m in to_send], (recv, out)
    counts = dict(re.findall(r"(\w+)=(\d+)", out.splitlines()[-1]))
    # python-can's O at open (C and S8 only when a bitrate is given) is a command; nothing was refused
    assert counts["commands"] == "1" and counts["garbage"] == counts["too_long"] == counts["bad_dlc"] == "0", out
    assert to_ours.startswith(b"O\r") and to_theirs.startswith(b"O\r"), (to_ours[:20], to_theirs[:20])
