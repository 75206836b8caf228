"""Open the python-can bus the simulator and tools use; multicast never leaves this host."""

from __future__ import annotations

import errno
import socket
import struct
from collections.abc import Iterator
from contextlib import contextmanager

import can

from gen.lib.multicast import CAN_GROUP, CAN_PORT

DEFAULT_UDP_GROUP, DEFAULT_UDP_PORT = CAN_GROUP, CAN_PORT


class BusSpecError(ValueError):
    pass


MAX_BUSES = 4


def parse_drive_list(text: str, n_drives: int) -> list[int]:
    """"1-3", "4,5,6", "1-2,6" -> sorted drive numbers in 1..n_drives; ValueError otherwise."""
    out: set[int] = set()
    for part in text.split(","):
        a, sep, b = part.partition("-")
        if not a.isdigit() or (sep and not b.isdigit()):
            raise ValueError(text)
        lo, hi = int(a), int(b) if sep else int(a)
        if lo < 1 or hi < lo or hi > n_drives:
            raise ValueError(text)
        out.update(range(lo, hi + 1))
    return sorted(out)


def _spec_key(spec: str) -> tuple[str, ...]:
    if spec.startswith("socketcan:"):
        iface = spec.split(":", 1)[1]
        if not iface or len(iface) > 15 or any(c in iface for c in "/: \t"):
            raise BusSpecError(f"bus '{spec}': expected socketcan:IFACE, e.g. socketcan:vcan0")
        return ("socketcan", iface)
    group, port = parse_udp_spec(spec)
    return ("udp", group, str(port))


def parse_bus_assignments(args: list[str], n_drives: int, option: str = "--bus") -> list[tuple[str, list[int]]]:
    """The repeatable SPEC[@DRIVES] option (same rules as the controller's --bus): at most
    MAX_BUSES buses, no bus twice, every drive 1..n_drives on exactly one bus; without @DRIVES a
    bus carries every drive. BusSpecError names the option."""
    if not args:
        raise BusSpecError(f"{option}: no bus given")
    if len(args) > MAX_BUSES:
        raise BusSpecError(f"{option}: at most {MAX_BUSES} buses, got {len(args)}")
    out: list[tuple[str, list[int]]] = []
    keys: dict[tuple[str, ...], str] = {}
    owner: dict[int, str] = {}
    for arg in args:
        spec, at, drives_text = arg.rpartition("@") if "@" in arg else (arg, "", "")
        try:
            key = _spec_key(spec) if spec.startswith(("socketcan:", "udp")) else None
        except BusSpecError as exc:
            raise BusSpecError(f"{option}: {exc}") from exc
        if key is None:
            raise BusSpecError(f"{option}: unknown bus '{spec}' (expected udp, udp:GROUP:PORT or socketcan:IFACE)")
        if key in keys:
            raise BusSpecError(f"{option}: bus '{spec}' is given twice ('{keys[key]}' and '{spec}')")
        keys[key] = spec
        try:
            drives = parse_drive_list(drives_text, n_drives) if at else list(range(1, n_drives + 1))
        except ValueError:
            raise BusSpecError(f"{option}: '{arg}': drives '{drives_text}' are not a list of drives 1..{n_drives} "
                               "(e.g. @1-3 or @4,5,6)") from None
        for d in drives:
            if d in owner:
                raise BusSpecError(f"{option}: drive {d} is on two buses ('{owner[d]}' and '{spec}'); "
                                   "each drive on exactly one")
            owner[d] = spec
        out.append((spec, drives))
    missing = [d for d in range(1, n_drives + 1) if d not in owner]
    if missing:
        raise BusSpecError(f"{option}: drive(s) {','.join(map(str, missing))} on no bus (give each drive a bus: "
                           f"SPEC@DRIVES, e.g. {out[0][0]}@1-3)")
    return out


def parse_udp_spec(spec: str) -> tuple[str, int]:
    if spec == "udp":
        return DEFAULT_UDP_GROUP, DEFAULT_UDP_PORT
    if not spec.startswith("udp:"):
        raise BusSpecError(f"bus '{spec}': expected udp or udp:GROUP:PORT")
    group, _, port = spec[4:].rpartition(":")
    try:
        port_n = int(port)
        socket.inet_aton(group)
    except (ValueError, OSError) as exc:
        raise BusSpecError(f"bus '{spec}': expected udp:GROUP:PORT, e.g. udp:{CAN_GROUP}:{CAN_PORT}") from exc
    if not (1 <= port_n <= 65535) or not 224 <= int(group.split(".")[0]) <= 239:
        raise BusSpecError(f"bus '{spec}': group must be IPv4 multicast and port 1..65535")
    return group, port_n


@contextmanager
def _inaddr_any_is_loopback() -> Iterator[None]:
    """python-can joins its group with INADDR_ANY, which the kernel places on the default-route
    interface (eth0), and the kernel then sends IGMP reports off the host. While the bus is
    built, "any" means 127.0.0.1 (python-can packs it native-endian with struct "@I"), so the
    only membership is on lo."""
    saved = socket.INADDR_ANY
    socket.INADDR_ANY = struct.unpack("@I", socket.inet_aton("127.0.0.1"))[0]
    try:
        yield
    finally:
        socket.INADDR_ANY = saved


def restrict_to_loopback(sock: socket.socket) -> None:
    """TTL 0 keeps datagrams on this host; sending via lo keeps them off eth0 too."""
    sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, struct.pack("@I", 0))
    sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
    sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)


def open_bus(spec: str) -> can.BusABC:
    """udp | udp:GROUP:PORT (python-can udp_multicast, loopback only) | socketcan:IFACE."""
    if spec.startswith("socketcan:"):
        iface = spec.split(":", 1)[1]
        if not iface or len(iface) > 15 or any(c in iface for c in "/: \t"):
            raise BusSpecError(f"bus '{spec}': expected socketcan:IFACE, e.g. socketcan:vcan0")
        try:
            return can.Bus(interface="socketcan", channel=iface, fd=True)
        except OSError as exc:  # same wording as the C transport (firmware/transport/src/can_socketcan.c)
            if exc.errno == errno.EAFNOSUPPORT:
                raise BusSpecError(f"{spec}: this kernel has no SocketCAN (AF_CAN): use --bus udp or "
                                   "tools/armctl vcan run") from exc
            if exc.errno == errno.ENODEV:
                raise BusSpecError(f"{spec}: no such interface (create it: tools/armctl vcan up)") from exc
            raise BusSpecError(f"{spec}: {exc.strerror or exc}") from exc
    group, port = parse_udp_spec(spec)
    with _inaddr_any_is_loopback():
        bus = can.Bus(interface="udp_multicast", channel=group, port=port, hop_limit=0, fd=True)
    restrict_to_loopback(udp_socket(bus))  # python-can exposes no option for this
    return bus


def udp_socket(bus: can.BusABC) -> socket.socket:
    return bus._multicast._socket  # type: ignore[attr-defined, no-any-return]
