"""The emulated drives as CANopen CiA 402 slaves (`arm_sim --protocol canopen`), with an
independent stack as the master: python-canopen (RemoteNode / BaseNode402 with our EDS) on the
UDP bus through python-can's udp_multicast interface, loopback only (TTL 0, 127.0.0.1).

The master does what the contract's boot sequence says (docs/drives.md): SDO reads of
0x1000 and 0x1018, the PDO mappings, 0x1006, 0x1017, 0x1016, the mode, NMT start, then the CiA
402 enable sequence over RPDO1/TPDO2 on SYNC, and a target torque that moves the joint."""

from __future__ import annotations

import json
import struct
import subprocess
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from tools.run.slots import CAN_GROUP, Slot

canopen = pytest.importorskip("canopen")
from canopen.profiles.p402 import BaseNode402  # noqa: E402
from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError  # noqa: E402
from canopen_network import loopback_network, stop_nodes_and_wait  # noqa: E402

# armctl test runs these alone (no other test beside them): python-canopen's state and SDO timeouts are wall-clock
pytestmark = pytest.mark.serial

REPO = Path(__file__).resolve().parents[2]
EDS = REPO / "firmware" / "protocol" / "cia402_servo.eds"
MASTER_ID = 0x7F
CYCLE_S = 0.01       # SYNC period: the master's clock
HEARTBEAT_MS = 100   # the drives' producer heartbeat
CONSUMER_MS = 1000   # the drives watch the master's heartbeat this closely (20 of its periods: a busy host stalls)
TWO_PI = 6.283185307179586


@pytest.fixture(scope="module")
def sim_bin() -> Path:
    from host_sim.launch import sim_binary

    exe = sim_binary("debug")
    if not exe.exists():
        pytest.skip(f"{exe} not built (cmake --build build/debug --target arm_sim)")
    return exe


@dataclass
class Rig:
    net: canopen.Network
    node: BaseNode402
    proc: subprocess.Popen
    heartbeat: object | None = None
    ended: tuple[int, str] | None = None  # the simulator's exit code and stderr, once stopped

    def sdo_abort(self, index: int, sub: int, value: bytes) -> int:
        with pytest.raises(SdoAbortedError) as exc:
            self.node.sdo.download(index, sub, value)
        return exc.value.code


def _bootups(net: canopen.Network, node_id: int) -> list[float]:
    """Boot-up heartbeats of a node as they come (subscribed before the cause: none is missed)."""
    seen: list[float] = []
    net.subscribe(0x700 + node_id, lambda _id, data, ts: seen.append(ts) if data[:1] == b"\x00" else None)
    return seen


def _start(sim_bin: Path, monkeypatch: pytest.MonkeyPatch, port: int, extra: list[str],
           summary: Path | None = None) -> Rig:
    group = CAN_GROUP
    if summary is not None:
        extra = [*extra, "--summary", str(summary)]
    net = loopback_network(monkeypatch, group, port)
    node = BaseNode402(1, str(EDS))
    # python-canopen's state-change timeouts are sized for a quiet host; this one is shared
    node.TIMEOUT_SWITCH_STATE_FINAL, node.TIMEOUT_SWITCH_STATE_SINGLE, node.TIMEOUT_CHECK_TPDO = 5.0, 2.0, 1.0
    net.add_node(node)
    bootups = _bootups(net, 1)
    proc = subprocess.Popen([str(sim_bin), "--protocol", "canopen", "--bus", f"udp:{group}:{port}",
                             "--lcm-url", "", "--boot-timeout", "20", "--idle-timeout", "5", *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _until("the drives' boot-up", lambda: len(bootups) >= 1, timeout=15.0)
    except AssertionError:
        proc.kill()
        net.disconnect()
        raise
    return Rig(net, node, proc)


def _configure(rig: Rig) -> None:
    """The contract's boot sequence, through python-canopen's SDO client and PDO maps."""
    node = rig.node
    node.nmt.state = "PRE-OPERATIONAL"
    assert node.sdo[0x1000].raw == 0x00020192
    ident = [node.sdo[0x1018][k].raw for k in range(1, 5)]
    assert ident[1] == 0x402 and ident[3] == 1  # product code; serial = node id
    node.tpdo.read()
    node.rpdo.read()
    for pdo, entries in ((node.rpdo[1], [(0x6040, 0), (0x6071, 0)]), (node.tpdo[1], [(0x6064, 0), (0x606C, 0)]),
                         (node.tpdo[2], [(0x6077, 0), (0x6041, 0)])):
        pdo.clear()
        for index, sub in entries:
            pdo.add_variable(index, sub)
        pdo.trans_type = 1
        pdo.enabled = True
        pdo.save()
    node.sdo[0x1006].raw = int(CYCLE_S * 1e6)
    node.sdo[0x1017].raw = HEARTBEAT_MS
    node.sdo[0x1016][1].raw = MASTER_ID << 16 | CONSUMER_MS
    node.sdo[0x6060].raw = 10
    assert node.sdo[0x6061].raw == 10
    node.setup_402_state_machine(read_pdos=False)
    rig.heartbeat = rig.net.send_periodic(0x700 + MASTER_ID, [0x05], 0.05)


def _run(rig: Rig) -> None:
    """NMT start, SYNC every cycle, RPDO1 every cycle, then the CiA 402 enable sequence."""
    rig.node.nmt.state = "OPERATIONAL"
    rig.net.sync.start(CYCLE_S)
    rig.node.rpdo[1]["Target torque"].raw = 0
    rig.node.rpdo[1].start(CYCLE_S)
    rig.node.state = "OPERATION ENABLED"


def _stop(rig: Rig) -> tuple[int, str]:
    if rig.ended is not None:
        return rig.ended
    err = ""
    try:
        rig.net.sync.stop()
        rig.node.rpdo[1].stop()
        if rig.heartbeat is not None:
            rig.heartbeat.stop()
        rig.net.nmt.state = "STOPPED"  # every node (broadcast): the end of the run
        out, err = rig.proc.communicate(timeout=10)
    finally:
        if rig.proc.poll() is None:
            rig.proc.kill()
            rig.proc.communicate()
        rig.net.disconnect()
    rig.ended = (rig.proc.returncode, err)
    return rig.ended


@pytest.fixture()
def rig(sim_bin: Path, monkeypatch: pytest.MonkeyPatch, request: pytest.FixtureRequest,
        tmp_path: Path, slot: Slot) -> Iterator[Rig]:
    extra = getattr(request, "param", [])
    r = _start(sim_bin, monkeypatch, slot.can_port, extra, tmp_path / "summary.json")
    try:
        yield r
    finally:
        rc, err = _stop(r)
    assert rc == 0, err  # NMT stop of every node ends the run normally


def _emcy(rig: Rig, code: int, timeout: float = 3.0) -> bool:
    """The node sent an EMCY with this code (already logged, or within the timeout)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if any(e.code == code for e in rig.node.emcy.log):
            return True
        rig.node.emcy.wait(None, timeout=0.1)
    return any(e.code == code for e in rig.node.emcy.log)


def _until(what: str, cond: Callable[[], bool], timeout: float = 5.0) -> None:
    """Waits for a state the drive reaches after some SYNCs (however slowly this host runs them)."""
    end = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < end, f"timed out waiting for {what}"
        time.sleep(0.02)


def _tpdo_value(rig: Rig, pdo: int, name: str) -> int:
    rig.node.tpdo[pdo].wait_for_reception(1.0)
    return rig.node.tpdo[pdo][name].raw


def test_sdo_identity_and_segmented_name(rig: Rig) -> None:
    node = rig.node
    assert node.sdo[0x1000].raw == 0x00020192
    assert node.sdo[0x1018][2].raw == 0x402
    name = node.sdo[0x1008].raw  # 32 bytes: a segmented upload
    assert name == "Arm emulated CiA 402 servo drive" and len(name) > 4
    assert node.sdo[0x6502].raw & (1 << 9)  # CST


def test_target_torque_moves_the_joint(rig: Rig, tmp_path: Path) -> None:
    _configure(rig)
    _run(rig)
    assert rig.node.statusword & 0x6F == 0x27
    rated_nm = rig.node.sdo[0x6076].raw * 1e-3  # the motor's (CiA 402)
    gear = rig.node.sdo[0x6091][1].raw / rig.node.sdo[0x6091][2].raw
    inc_per_rad = rig.node.sdo[0x608F][1].raw * gear / TWO_PI
    p0 = _tpdo_value(rig, 1, "Position actual value")
    assert _tpdo_value(rig, 2, "Torque actual value") == 0
    permille = 200  # 30 N m on the base joint (a 1486 mN m motor behind 101:1): the arm turns about it
    assert abs(permille * 1e-3 * rated_nm * gear - 30.0172) < 1e-9
    rig.node.rpdo[1]["Target torque"].raw = permille
    _until("torque actual = target", lambda: _tpdo_value(rig, 2, "Torque actual value") == permille)
    # more than a milliradian, the commanded way
    _until("the joint to turn", lambda: _tpdo_value(rig, 1, "Position actual value") - p0 > 0.001 * inc_per_rad)
    assert _tpdo_value(rig, 1, "Velocity actual value") > 0
    rig.node.rpdo[1]["Target torque"].raw = -permille
    _until("torque actual = -target", lambda: _tpdo_value(rig, 2, "Torque actual value") == -permille)
    _until("the joint to turn back", lambda: _tpdo_value(rig, 1, "Velocity actual value") < 0)
    rc, err = _stop(rig)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert rc == 0 and summary["result"] == "ok", err
    assert summary["protocol"] == "canopen" and summary["drive_faults"] == []
    # every SYNC (all after 0x1006 = 10000 us was written) moved the arm by ten 1 ms periods
    assert summary["periods"] % 10 == 0 and summary["periods"] >= 100, summary["periods"]


def test_unsupported_mode_is_refused(rig: Rig) -> None:
    assert rig.sdo_abort(0x6060, 0, bytes([3])) == 0x06090030
    assert rig.node.sdo[0x6061].raw == 0


def test_read_only_unknown_and_wrong_length(rig: Rig) -> None:
    assert rig.sdo_abort(0x1000, 0, struct.pack("<I", 0x00020192)) == 0x06010002
    assert rig.sdo_abort(0x2345, 0, bytes(4)) == 0x06020000
    assert rig.sdo_abort(0x1018, 9, bytes(4)) == 0x06090011
    assert rig.sdo_abort(0x6040, 0, bytes(4)) == 0x06070010  # controlword is 16 bits


def test_mapping_refused_while_pdo_valid(rig: Rig) -> None:
    rig.node.nmt.state = "PRE-OPERATIONAL"
    assert rig.node.sdo[0x1800][1].raw & 0x80000000 == 0  # TPDO1 valid (EDS default)
    assert rig.sdo_abort(0x1A00, 0, bytes([0])) == 0x08000022
    assert rig.sdo_abort(0x1A00, 1, struct.pack("<I", 0x60410010)) == 0x08000022


def test_master_heartbeat_lost_faults_the_drive(rig: Rig) -> None:
    _configure(rig)
    _run(rig)
    rig.node.rpdo[1]["Target torque"].raw = 100
    _until("torque actual = target", lambda: _tpdo_value(rig, 2, "Torque actual value") == 100)
    rig.heartbeat.stop()
    assert _emcy(rig, 0x8130)
    _until("fault", lambda: rig.node.check_statusword() & 0x4F == 0x08)
    assert _tpdo_value(rig, 2, "Torque actual value") == 0
    assert rig.node.sdo[0x603F].raw == 0x8130


@pytest.mark.parametrize("rig", [["--inject-overcurrent", "1:0.05"]], indirect=True)
def test_injected_overcurrent_faults_the_drive(rig: Rig) -> None:
    _configure(rig)
    _run(rig)
    assert _emcy(rig, 0x2310)
    assert rig.node.emcy.active[-1].register & 0x02  # error register: current
    _until("fault", lambda: rig.node.check_statusword() & 0x4F == 0x08)
    rig.node.rpdo[1]["Target torque"].raw = 100
    for _ in range(5):  # SYNCs with a target torque: none applied in fault
        assert _tpdo_value(rig, 2, "Torque actual value") == 0
    rig.node.state = "OPERATION ENABLED"  # fault reset (controlword bit 7), then enable again
    assert _emcy(rig, 0x0000, timeout=1.0) and rig.node.emcy.active == []
    assert rig.node.statusword & 0x6F == 0x27


@pytest.mark.parametrize("rig", [["--rated-torque-mnm", "28000", "--encoder-increments", "4096",
                                  "--od-gear-ratio", "50:1"]], indirect=True)
def test_arm_overrides_preset_the_scaling(rig: Rig) -> None:
    node = rig.node
    assert node.sdo[0x6076].raw == 28000
    assert node.sdo[0x608F][1].raw == 4096 and node.sdo[0x608F][2].raw == 1
    assert node.sdo[0x6091][1].raw == 50 and node.sdo[0x6091][2].raw == 1


@pytest.mark.parametrize("rig", [["--rated-torque-mnm", "100000", "--node",
                                  "1,rated=28000,encoder=4096,gear=160/1,max=6418", "--node", "2,rated=5000"]],
                         indirect=True)
def test_a_nodes_own_preset_from_the_drive_table(rig: Rig) -> None:
    """--node (the arm's drive table, as armctl hil passes it): node 1's own scaling over every
    node's --rated-torque-mnm, and the max torque of a motor the importer sized below the joint's
    limit (0x6072 above 1000); node 2's preset is not node 1's."""
    node = rig.node
    assert node.sdo[0x6076].raw == 28000 and node.sdo[0x6072].raw == 6418
    assert node.sdo[0x608F][1].raw == 4096
    assert node.sdo[0x6091][1].raw == 160 and node.sdo[0x6091][2].raw == 1
    # node 2 (the same bus: drives 1 and 2) reads its own rated torque, and none of node 1's scaling
    two = rig.net.add_node(2, str(EDS))
    assert two.sdo[0x1018][4].raw == 2  # its serial number is its node id: it is node 2 that answers
    assert two.sdo[0x6076].raw == 5000
    assert two.sdo[0x608F][1].raw != 4096 and two.sdo[0x6091][1].raw != 160 and two.sdo[0x6072].raw == 1000


def test_quick_stop_and_the_shortcut_to_operation_enabled_as_python_canopen_asks(rig: Rig) -> None:
    """BaseNode402's QUICK STOP ACTIVE (0x605A's default, 6: the drive ramps to standstill and holds
    there, its own torque within its limit) and back; a raw controlword 0x0F from READY TO SWITCH ON
    is CiA 402's transitions 3 and 4; 0x605A 2 ends a quick stop in SWITCH ON DISABLED once the ramp
    is done (no brake here to wait for)."""
    _configure(rig)
    _run(rig)
    node = rig.node
    assert node.sdo[0x605A].raw == 6
    node.state = "QUICK STOP ACTIVE"
    assert node.sdo[0x6041].raw & 0x6F == 0x07 and abs(_tpdo_value(rig, 2, "Torque actual value")) <= 1000
    node.state = "OPERATION ENABLED"
    node.state = "READY TO SWITCH ON"
    # the controlword through the running RPDO1 (an SDO write would be undone by its next frame)
    node.controlword = 0x0F
    _until("operation enabled from ready to switch on", lambda: node.sdo[0x6041].raw & 0x6F == 0x27)
    node.sdo[0x605A].raw = 2  # 1-4: a quick stop ends in SWITCH ON DISABLED, after its ramp
    node.controlword = 0x02
    _until("switch on disabled after the ramp", lambda: node.sdo[0x6041].raw & 0x4F == 0x40)


def test_nmt_resets_restore_defaults(rig: Rig) -> None:
    node = rig.node
    bootups = _bootups(rig.net, node.id)
    node.sdo[0x1017].raw = 20
    node.sdo[0x6072].raw = 500
    node.nmt.state = "RESET COMMUNICATION"
    _until("the boot-up after reset communication", lambda: len(bootups) == 1)
    assert node.sdo[0x1017].raw == 0  # communication area: back to the EDS
    assert node.sdo[0x1018][4].raw == node.id  # but the serial number stays the drive's own
    assert node.sdo[0x6072].raw == 500  # the profile area survives a communication reset
    node.nmt.state = "RESET"
    _until("the boot-up after reset node", lambda: len(bootups) == 2)
    assert node.sdo[0x6072].raw == 1000


@pytest.mark.parametrize(("args", "needle"), [
    (["--protocol", "ethercat"], "--protocol: 'ethercat' is not arm or canopen"),
    (["--node", "1,rated=5"], "only with --protocol canopen"),
    (["--protocol", "canopen", "--node", "17"], "--node '17': the node id must be a drive, 1..16"),
    (["--protocol", "canopen", "--node", "1,speed=3"], "--node '1,speed=3': expected ID[,rated=N]"),
    (["--protocol", "canopen", "--node", "1,efficiency=1.5"], "--node '1,efficiency=1.5': expected ID[,rated=N]"),
    (["--od-gear-ratio", "50:1"], "only with --protocol canopen"),
    (["--protocol", "canopen", "--od-gear-ratio", "50:0"], "--od-gear-ratio: '50:0' is not MOTOR:SHAFT"),
    (["--protocol", "canopen", "--inject-overcurrent", "0:1"], "--inject-overcurrent: '0:1' is not NODE:TIME"),
    (["--protocol", "canopen", "--rated-torque-mnm", "1.5"], "--rated-torque-mnm: '1.5' is not a whole number"),
])
def test_bad_canopen_options(sim_bin: Path, args: list[str], needle: str) -> None:
    p = subprocess.run([str(sim_bin), "--lcm-url", "", *args], capture_output=True, text=True, timeout=30)
    assert p.returncode == 2 and needle in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr


def test_nodes_on_a_second_bus(sim_bin: Path, monkeypatch: pytest.MonkeyPatch, slot: Slot) -> None:
    """Today's wiring (buses.toml): drives 1-3 on one bus, 4-6 on another; node id = drive number."""
    group, port = CAN_GROUP, slot.can_port
    net = loopback_network(monkeypatch, group, port + 1)
    node = BaseNode402(4, str(EDS))
    net.add_node(node)
    bootups = _bootups(net, 4)
    proc = subprocess.Popen([str(sim_bin), "--protocol", "canopen", "--bus", f"udp:{group}:{port}@1-3",
                             "--bus", f"udp:{group}:{port + 1}@4-6", "--lcm-url", "", "--idle-timeout", "1"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _until("node 4's boot-up", lambda: len(bootups) == 1, timeout=15.0)
        assert node.sdo[0x1018][4].raw == 4  # serial = node id
        assert node.sdo[0x1400][1].raw == 0x204
        with pytest.raises(SdoCommunicationError):  # nodes 1-3 are not on this bus: nobody answers
            net.add_node(BaseNode402(1, str(EDS))).sdo[0x1000].raw
    finally:
        err = stop_nodes_and_wait(net, proc)  # this bus's nodes; the others then stop on their idle timeout
    assert proc.returncode == 3 and "master silent" in err  # bus 0 never heard a master
