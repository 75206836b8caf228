"""Frame send/receive for the simulator's hot path, on a python-can bus.

On the udp_multicast bus every frame a process sends comes back to it (loopback membership), so
half of what the simulator receives is its own echo. python-can builds and validates a Message
for each (~50 us); here an echo is recognised by its bytes (the very datagram this process sent,
timestamp included) before any decoding, other datagrams are decoded with the same msgpack wire
format python-can uses, ignored ids are dropped before any Message exists, and frames are sent by
packing the same dict pack_message writes. The socket, its options and the format stay python-can's. On
SocketCAN the bus's own recv/send are used unchanged (the kernel does not echo to the sender).
"""

from __future__ import annotations

import select
import socket
import time
from typing import NamedTuple

import can
import msgpack


class Frame(NamedTuple):
    id: int
    data: bytes
    is_fd: bool
    bad: bool  # error/remote/extended frame: not part of the protocol


class FrameIO:
    def __init__(self, bus: can.BusABC, ignore_ids: set[int]) -> None:
        self.bus = bus
        self.ignore = ignore_ids
        self.udp = getattr(bus, "_multicast", None)
        self.sock = self.udp._socket if self.udp is not None else None
        self.echoes = 0
        self.undecodable = 0
        # Datagrams sent and not yet seen back (insertion-ordered; bounded in case one is lost).
        self._unechoed: dict[bytes, None] = {}

    def send(self, frame_id: int, data: bytes, fd: bool) -> None:
        if self.udp is None:
            self.bus.send(can.Message(arbitration_id=frame_id, data=data, is_extended_id=False, is_fd=fd,
                                      bitrate_switch=fd))
            return
        datagram = msgpack.packb({
            "timestamp": time.time(), "arbitration_id": frame_id, "is_extended_id": False,
            "is_remote_frame": False, "is_error_frame": False, "channel": None, "dlc": len(data),
            "data": data, "is_fd": fd, "bitrate_switch": fd, "error_state_indicator": False,
        }, use_bin_type=True)
        self._unechoed[datagram] = None
        if len(self._unechoed) > 256:
            del self._unechoed[next(iter(self._unechoed))]
        self.udp.send(datagram)

    def _recv_datagram(self, end: float) -> bytes | None:
        """A queued datagram at once; otherwise wait for one until end (python-can's recv would
        select and parse a receive timestamp for every datagram, half the simulator's time)."""
        while True:
            try:
                return self.sock.recv(4096, socket.MSG_DONTWAIT)
            except BlockingIOError:
                pass
            left = end - time.monotonic()
            if left < 0 or not select.select([self.sock], [], [], left)[0]:
                return None

    def fileno(self) -> int:
        return self.sock.fileno() if self.sock is not None else self.bus.fileno()

    def poll(self) -> Frame | None:
        """A frame that is already queued (not one of ignore_ids), else None at once."""
        return self.recv(0.0)

    def _from_message(self, msg: can.Message) -> Frame | None:
        """A python-can Message (SocketCAN path) as a Frame; None for an ignored id."""
        if msg.arbitration_id in self.ignore:
            self.echoes += 1
            return None
        return Frame(msg.arbitration_id, bytes(msg.data), msg.is_fd,
                     msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id)

    def _decode(self, datagram: bytes) -> Frame | None:
        if datagram in self._unechoed:
            del self._unechoed[datagram]
            self.echoes += 1
            return None
        try:
            d = msgpack.unpackb(datagram, raw=False)
            fid = d["arbitration_id"]
            data = bytes(d["data"])
            if d["dlc"] != len(data):
                raise ValueError("dlc does not match the data")
        except Exception:  # noqa: BLE001 - a garbage datagram is counted, never fatal
            self.undecodable += 1
            return None
        if fid in self.ignore:
            self.echoes += 1
            return None
        return Frame(fid, data, bool(d.get("is_fd")),
                     bool(d.get("is_error_frame") or d.get("is_remote_frame") or d.get("is_extended_id")))

    def recv(self, timeout: float) -> Frame | None:
        """The next frame that is not one of ignore_ids, or None after timeout seconds (what is
        already queued is always read, also with timeout 0)."""
        end = time.monotonic() + timeout
        while True:
            if self.udp is None:
                msg = self.bus.recv(max(0.0, end - time.monotonic()))
                if msg is None:
                    return None
                f = self._from_message(msg)
            else:
                datagram = self._recv_datagram(end)
                if datagram is None:
                    return None
                f = self._decode(datagram)
            if f is not None:
                return f


class MultiFrameIO:
    """Several buses (one FrameIO each, so own echoes are dropped per bus); recv returns
    (bus index, frame) from whichever bus has one, waiting in one select() over all of them."""

    def __init__(self, ios: list[FrameIO]) -> None:
        self.ios = ios
        self.next = 0

    @property
    def echoes(self) -> int:
        return sum(io.echoes for io in self.ios)

    @property
    def undecodable(self) -> int:
        return sum(io.undecodable for io in self.ios)

    def recv(self, timeout: float) -> tuple[int, Frame] | None:
        if len(self.ios) == 1:
            f = self.ios[0].recv(timeout)
            return None if f is None else (0, f)
        end = time.monotonic() + timeout
        n = len(self.ios)
        while True:
            for k in range(n):  # drain what is queued, round-robin so no bus starves another
                i = (self.next + k) % n
                f = self.ios[i].poll()
                if f is not None:
                    self.next = (i + 1) % n
                    return i, f
            left = end - time.monotonic()
            if left < 0 or not select.select(self.ios, [], [], left)[0]:
                return None
