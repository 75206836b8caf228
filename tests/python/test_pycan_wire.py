"""Cross-checks of the C python-can wire codec and loopback bus against python-can itself.

The C side is reached through two test binaries built by tests/c/transport:
  pycan_wire_tool   codec CLI (encode/decode/batch)
  can_udp_selftest  live bus checks (send/recv/--print-sockopts)
found under $ARM_BUILD_DIR (default build/debug of this checkout)/tests/c/transport.

Every multicast socket opened here stays on this host: TTL 0, outgoing
interface 127.0.0.1, membership only on 127.0.0.1 (see _loopback_bus).
"""

import os
import random
import socket
import struct
import subprocess
import time
from pathlib import Path

import pytest

can = pytest.importorskip("can")
msgpack = pytest.importorskip("msgpack")
from can.interfaces.udp_multicast.utils import pack_message, unpack_message  # noqa: E402

# armctl test runs these alone (no other test beside them): python-can peers with wall-clock deadlines
pytestmark = pytest.mark.serial

BUILD_DIR = Path(os.environ.get("ARM_BUILD_DIR", Path(__file__).resolve().parents[2] / "build" / "debug"))
TOOL_DIR = BUILD_DIR / "tests" / "c" / "transport"
TOOL = TOOL_DIR / "pycan_wire_tool"
SELFTEST = TOOL_DIR / "can_udp_selftest"

GROUP = "239.74.163.2"
# Distinct from python-can's 43113 so a running HIL session is neither disturbed nor heard.
PORT_C_TO_PY = 43199
PORT_PY_TO_C = 43198
PORT_SOCKOPTS = 43194
# Group nobody else uses, so /proc/net/igmp shows only our own memberships.
IGMP_CHECK_GROUP = "239.74.163.199"
IGMP_CHECK_PORT = 43193

FLAG_FD, FLAG_BRS, FLAG_EXT, FLAG_ESI, FLAG_RTR, FLAG_ERR = 0x01, 0x02, 0x04, 0x08, 0x10, 0x20
FD_LENS = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64]


def _need(path):
    if not (path.is_file() and os.access(path, os.X_OK)):
        pytest.skip(f"{path.name} not built at {path} (build the C tests or set ARM_BUILD_DIR)")
    return path


@pytest.fixture(scope="module")
def tool():
    return _need(TOOL)


@pytest.fixture(scope="module")
def selftest():
    return _need(SELFTEST)


def run_batch(tool_path, commands):
    """One tool process answers every command, one line each, in order."""
    proc = subprocess.run(
        [str(tool_path), "batch"],
        input="\n".join(commands) + "\n",
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    lines = proc.stdout.splitlines()
    assert len(lines) == len(commands), proc.stderr
    return lines


# ---- frames <-> python-can Messages -----------------------------------------


def flags_of(msg):
    return (
        (FLAG_FD if msg.is_fd else 0)
        | (FLAG_BRS if msg.bitrate_switch else 0)
        | (FLAG_EXT if msg.is_extended_id else 0)
        | (FLAG_ESI if msg.error_state_indicator else 0)
        | (FLAG_RTR if msg.is_remote_frame else 0)
        | (FLAG_ERR if msg.is_error_frame else 0)
    )


def random_message(rng, fd):
    ext = rng.random() < 0.5
    arb_id = rng.randrange(0x20000000 if ext else 0x800)
    rtr = (not fd) and rng.random() < 0.15
    err = (not rtr) and rng.random() < 0.1
    length = rng.choice(FD_LENS) if fd else rng.randrange(9)
    data = b"" if rtr else bytes(rng.randrange(256) for _ in range(length))
    ts = rng.choice([0.0, rng.uniform(0, 2e9), rng.random(), float(rng.randrange(10**6)), 1e-300])
    return can.Message(
        timestamp=ts,
        arbitration_id=arb_id,
        is_extended_id=ext,
        is_remote_frame=rtr,
        is_error_frame=err,
        dlc=length,
        data=data,
        is_fd=fd,
        bitrate_switch=fd and rng.random() < 0.5,
        error_state_indicator=fd and rng.random() < 0.3,
        check=True,
    )


def encode_cmd(msg):
    return (
        f"encode {msg.arbitration_id:#x} {msg.dlc} {bytes(msg.data).hex() or '-'} "
        f"{flags_of(msg):#x} {msg.timestamp!r}"
    )


def parse_decoded(line):
    """'0xID LEN 0xFLAGS HEX TS' -> tuple, or ('error', name)."""
    parts = line.split()
    if parts[0] == "error":
        return ("error", parts[1])
    arb_id, length, flags, data_hex, ts = parts
    data = b"" if data_hex == "-" else bytes.fromhex(data_hex)
    return (int(arb_id, 0), int(length), int(flags, 0), data, float(ts))


def assert_same_message(got, want, check_timestamp=True):
    for field in (
        "arbitration_id",
        "is_extended_id",
        "is_remote_frame",
        "is_error_frame",
        "dlc",
        "is_fd",
        "bitrate_switch",
        "error_state_indicator",
    ):
        assert getattr(got, field) == getattr(want, field), field
    assert bytes(got.data) == bytes(want.data)
    if check_timestamp:
        assert got.timestamp == want.timestamp


@pytest.fixture(scope="module")
def random_messages():
    rng = random.Random(0xC0FFEE)  # fixed seed: a failure names a reproducible frame
    return [random_message(rng, fd=False) for _ in range(400)] + [
        random_message(rng, fd=True) for _ in range(400)
    ]


# ---- codec cross-checks ------------------------------------------------------


def test_c_encode_matches_pack_message_bytes(tool, random_messages):
    lines = run_batch(tool, [encode_cmd(m) for m in random_messages])
    for msg, line in zip(random_messages, lines):
        assert line == pack_message(msg).hex(), msg


def test_c_encode_unpacks_in_python_can(tool, random_messages):
    lines = run_batch(tool, [encode_cmd(m) for m in random_messages])
    for msg, line in zip(random_messages, lines):
        got = unpack_message(bytes.fromhex(line), check=True)
        assert_same_message(got, msg)
        assert got.channel is None


def test_pack_message_decodes_in_c(tool, random_messages):
    lines = run_batch(tool, [f"decode {pack_message(m).hex()}" for m in random_messages])
    for msg, line in zip(random_messages, lines):
        arb_id, length, flags, data, ts = parse_decoded(line)
        assert (arb_id, length, flags, data, ts) == (
            msg.arbitration_id,
            msg.dlc,
            flags_of(msg),
            bytes(msg.data),
            msg.timestamp,
        ), msg


def test_c_accepts_other_packers_layouts(tool, random_messages):
    """Key order, channel strings and extra simple-typed keys must not matter."""
    rng = random.Random(7)
    cmds, wants = [], []
    for msg in random_messages[::8]:
        d = msgpack.unpackb(pack_message(msg), raw=False)
        d["channel"] = rng.choice([None, "vcan0", "239.74.163.2"])
        d["is_rx"] = True
        items = list(d.items())
        rng.shuffle(items)
        cmds.append(f"decode {msgpack.packb(dict(items), use_bin_type=True).hex()}")
        wants.append(msg)
    for msg, line in zip(wants, run_batch(tool, cmds)):
        assert parse_decoded(line)[:4] == (
            msg.arbitration_id,
            msg.dlc,
            flags_of(msg),
            bytes(msg.data),
        )


def _invalid_variants():
    base = dict(
        timestamp=1.0,
        arbitration_id=0x123,
        is_extended_id=False,
        is_remote_frame=False,
        is_error_frame=False,
        channel=None,
        dlc=2,
        data=b"\x11\x22",
        is_fd=False,
        bitrate_switch=False,
        error_state_indicator=False,
    )
    cases = {
        "dlc_mismatch": dict(dlc=3),
        "std_id_too_big": dict(arbitration_id=0x800),
        "ext_id_too_big": dict(arbitration_id=0x20000000, is_extended_id=True),
        "negative_id": dict(arbitration_id=-1),
        "classic_len_9": dict(dlc=9, data=bytes(9)),
        "fd_len_65": dict(dlc=65, data=bytes(65), is_fd=True),
        "brs_without_fd": dict(bitrate_switch=True),
        "esi_without_fd": dict(error_state_indicator=True),
        "rtr_and_fd": dict(is_remote_frame=True, is_fd=True, data=b"", dlc=0),
        "rtr_and_err": dict(is_remote_frame=True, is_error_frame=True, data=b"", dlc=0),
        "negative_timestamp": dict(timestamp=-1.0),
        "nan_timestamp": dict(timestamp=float("nan")),
    }
    for name, change in cases.items():
        d = dict(base)
        d.update(change)
        yield name, d


@pytest.mark.parametrize("name,fields", list(_invalid_variants()))
def test_c_rejects_what_python_can_rejects(tool, name, fields):
    with pytest.raises(ValueError):
        can.Message(check=True, **fields)
    line = run_batch(tool, [f"decode {msgpack.packb(fields, use_bin_type=True).hex()}"])[0]
    assert line.startswith("error "), (name, line)


@pytest.mark.parametrize(
    "name,change,expected",
    [
        # Deliberately stricter than python-can (documented in firmware/transport/README.md).
        ("fd_len_13_not_a_dlc", dict(is_fd=True, dlc=13, data=bytes(13)), "bad_length"),
        ("rtr_with_data", dict(is_remote_frame=True), "bad_length"),
        ("missing_dlc", dict(dlc=None), "missing_key"),
        ("duplicate_key_impossible_in_dict", None, "duplicate_key"),
    ],
)
def test_c_stricter_than_python_can(tool, name, change, expected):
    base = dict(
        timestamp=1.0, arbitration_id=0x123, is_extended_id=False, is_remote_frame=False,
        is_error_frame=False, channel=None, dlc=2, data=b"\x11\x22", is_fd=False,
        bitrate_switch=False, error_state_indicator=False,
    )
    if change is None:
        raw = msgpack.packb(base, use_bin_type=True)
        # append a second "dlc" entry: bump the fixmap count and add a3 'dlc' 02
        raw = bytes([raw[0] + 1]) + raw[1:] + b"\xa3dlc\x02"
    else:
        base.update(change)
        base = {k: v for k, v in base.items() if v is not None}
        raw = msgpack.packb(base, use_bin_type=True)
    line = run_batch(tool, [f"decode {raw.hex()}"])[0]
    assert line == f"error {expected}"


def test_tool_single_shot_exit_codes(tool):
    ok = subprocess.run([str(tool), "decode", "93010203"], capture_output=True, text=True)
    assert ok.returncode == 2 and ok.stdout.strip() == "error not_map"
    enc = subprocess.run([str(tool), "encode", "0x800", "0", "-", "0"], capture_output=True, text=True)
    assert enc.returncode == 2 and enc.stdout.strip() == "error encode"


# ---- live bus --------------------------------------------------------------


def _loopback_bus(monkeypatch, group, port):
    """python-can udp_multicast Bus that never leaves this host.

    python-can joins the group with INADDR_ANY, i.e. on the default-route NIC,
    which makes the kernel send IGMP reports off-host. While the Bus is built
    we make that "any" mean 127.0.0.1 (python-can packs it native-endian with
    struct "@I"), so the only membership is on lo; then the outgoing
    interface is pinned to 127.0.0.1. hop_limit=0 gives TTL 0.
    """
    lo_native = struct.unpack("@I", socket.inet_aton("127.0.0.1"))[0]
    with monkeypatch.context() as m:
        m.setattr(socket, "INADDR_ANY", lo_native)
        bus = can.Bus(interface="udp_multicast", channel=group, port=port, hop_limit=0)
    sock = bus._multicast._socket
    sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
    assert sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL) == 0
    return bus


def pattern_message(arb_id, k, fd, ext):
    length = FD_LENS[k % 16] if fd else k % 9
    return can.Message(
        arbitration_id=arb_id,
        is_extended_id=ext,
        is_fd=fd,
        bitrate_switch=fd,
        dlc=length,
        data=bytes((7 * k + i) & 0xFF for i in range(length)),
    )


@pytest.mark.parametrize("fd,ext,arb_id", [(False, False, 0x321), (True, True, 0x1ABCDE)])
def test_live_c_to_python_can(selftest, monkeypatch, fd, ext, arb_id):
    n = 100
    bus = _loopback_bus(monkeypatch, GROUP, PORT_C_TO_PY)
    try:
        cmd = [str(selftest), "send", "--id", hex(arb_id), "--count", str(n),
               "--port", str(PORT_C_TO_PY), "--group", GROUP, "--interval-us", "200"]
        cmd += ["--fd"] if fd else []
        cmd += ["--ext"] if ext else []
        sender = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        got = []
        deadline = time.monotonic() + 10.0
        while len(got) < n and time.monotonic() < deadline:
            msg = bus.recv(timeout=0.5)
            if msg is not None and msg.arbitration_id == arb_id:
                got.append(msg)
        out, err = sender.communicate(timeout=10)
        assert sender.returncode == 0, (out, err)
    finally:
        bus.shutdown()
    assert len(got) == n
    for k, msg in enumerate(got):
        assert_same_message(msg, pattern_message(arb_id, k, fd, ext), check_timestamp=False)


@pytest.mark.parametrize("fd,ext,arb_id", [(False, False, 0x456), (True, True, 0x1FFFFFFF)])
def test_live_python_can_to_c(selftest, monkeypatch, fd, ext, arb_id):
    n = 100
    bus = _loopback_bus(monkeypatch, GROUP, PORT_PY_TO_C)
    receiver = subprocess.Popen(
        [str(selftest), "recv", "--id", hex(arb_id), "--count", str(n), "--timeout-ms", "10000",
         "--port", str(PORT_PY_TO_C), "--group", GROUP],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        assert receiver.stdout.readline().strip() == "ready"
        sent = []
        for k in range(n):
            msg = pattern_message(arb_id, k, fd, ext)
            bus.send(msg)
            sent.append(msg)
            time.sleep(0.0002)
        out, err = receiver.communicate(timeout=15)
    finally:
        bus.shutdown()
        if receiver.poll() is None:
            receiver.kill()
    assert receiver.returncode == 0, (out, err)
    lines = [ln for ln in out.splitlines() if ln.startswith("0x")]
    assert len(lines) == n
    for msg, line in zip(sent, lines):
        arb, length, flags, data_hex = line.split()
        assert int(arb, 0) == msg.arbitration_id
        assert int(length) == msg.dlc
        assert int(flags, 0) == flags_of(msg)
        assert (b"" if data_hex == "-" else bytes.fromhex(data_hex)) == bytes(msg.data)


def test_c_socket_options_are_loopback_only(selftest):
    proc = subprocess.run(
        [str(selftest), "--print-sockopts", "--port", str(PORT_SOCKOPTS), "--group", GROUP],
        capture_output=True, text=True, timeout=10,
    )
    assert proc.returncode == 0, proc.stderr
    opts = dict(kv.split("=", 1) for kv in proc.stdout.split())
    assert int(opts["ttl"]) == 0
    assert opts["if"] == "127.0.0.1"
    assert int(opts["loop"]) == 1
    assert int(opts["multicast_all"]) in (0, -1)  # -1: option unavailable on this kernel
    assert opts["bound"] == f"{GROUP}:{PORT_SOCKOPTS}"
    # frames leave through a socket of their own: the same TTL 0 and loopback interface
    assert int(opts["tx_ttl"]) == 0 and opts["tx_if"] == "127.0.0.1" and int(opts["tx_loop"]) == 1
    assert opts["tx_bound"].startswith("127.0.0.1:") and opts["tx_bound"] != "127.0.0.1:0"


def _igmp_devices(group):
    """Devices on which this host is a member of `group`, from /proc/net/igmp."""
    want = "%08X" % struct.unpack("@I", socket.inet_aton(group))[0]
    devices, current = set(), None
    with open("/proc/net/igmp") as fh:
        for line in fh.readlines()[1:]:
            if not line.startswith("\t"):
                current = line.split()[1]
            elif line.split()[0] == want:
                devices.add(current)
    return devices


@pytest.mark.skipif(not Path("/proc/net/igmp").exists(), reason="needs Linux /proc/net/igmp")
def test_memberships_only_on_loopback(selftest, monkeypatch):
    assert _igmp_devices(IGMP_CHECK_GROUP) == set(), "test group already joined by someone else"
    receiver = subprocess.Popen(
        [str(selftest), "recv", "--count", "1", "--timeout-ms", "3000",
         "--port", str(IGMP_CHECK_PORT), "--group", IGMP_CHECK_GROUP],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        assert receiver.stdout.readline().strip() == "ready"
        assert _igmp_devices(IGMP_CHECK_GROUP) == {"lo"}, "C bus joined off loopback"
        bus = _loopback_bus(monkeypatch, IGMP_CHECK_GROUP, IGMP_CHECK_PORT)
        try:
            assert _igmp_devices(IGMP_CHECK_GROUP) == {"lo"}, "python-can bus joined off loopback"
            bus.send(can.Message(arbitration_id=0x123, is_extended_id=False, data=b"\x01"))
        finally:
            bus.shutdown()
        receiver.communicate(timeout=5)
    finally:
        if receiver.poll() is None:
            receiver.kill()
    assert receiver.returncode == 0
