"""python-canopen's Network on python-can's udp_multicast, confined to this host as
test_pycan_wire.py's _loopback_bus does: membership on 127.0.0.1 (INADDR_ANY means 127.0.0.1 while
the bus is built), TTL 0, outgoing IF lo. The real stack the CANopen tests check ours against."""

from __future__ import annotations

import socket
import struct
import subprocess

import canopen
import pytest

# How long its notifier thread waits for a frame before it sees a disconnect: at python-canopen's
# 1 s, every test's disconnect took up to a second (the two CANopen test files: 39.5 s -> 14.5 s).
NOTIFIER_CYCLE_S = 0.05


def loopback_network(monkeypatch: pytest.MonkeyPatch, group: str, port: int) -> canopen.Network:
    net = canopen.Network()
    net.NOTIFIER_CYCLE = NOTIFIER_CYCLE_S
    lo_native = struct.unpack("@I", socket.inet_aton("127.0.0.1"))[0]
    with monkeypatch.context() as m:
        m.setattr(socket, "INADDR_ANY", lo_native)
        net.connect(interface="udp_multicast", channel=group, port=port, hop_limit=0)
    sock = net.bus._multicast._socket
    sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
    assert sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL) == 0
    return net


def stop_nodes_and_wait(net: canopen.Network, proc: subprocess.Popen) -> str:
    """NMT stop to every node of the network (broadcast: the end of an emulated drives' run), then
    the simulator's exit (killed if it does not end), the network closed. Its standard error."""
    net.nmt.state = "STOPPED"
    err = ""
    try:
        _, err = proc.communicate(timeout=15)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        net.disconnect()
    return err or ""
