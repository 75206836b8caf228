"""The firmware's CANopen master (firmware/canopen, arm_canopen_boot) against python-canopen's
LocalNode with the drives' EDS, on the UDP bus (python-can udp_multicast on loopback, TTL 0).

The test drive is a LocalNode with a thin CiA 402 device in its SDO callbacks: the statusword
follows the controlword (written by SDO, the way the master confirms each state), 0x6060 takes
the modes 0x6502 lists, and a PDO mapping may be written only while its PDO's COB-ID is invalid
(else abort 0x08000022, CiA 301). After the boot the test reads back, from LocalNode's own
dictionary, every object the master wrote and checks it against the contract (docs/drives.md).
Also gen/drives.py: the drive configuration's rule and its one-line errors."""

from __future__ import annotations

import json
import math
import re
import struct
import subprocess
import threading
import time
from pathlib import Path

import pytest

canopen = pytest.importorskip("canopen")
from canopen.sdo import SdoAbortedError  # noqa: E402
from canopen_network import loopback_network  # noqa: E402

from gen import drives as gen_drives  # noqa: E402

# armctl test runs these alone (no other test beside them): python-canopen drives answer within SDO timeouts
pytestmark = pytest.mark.serial

REPO = Path(__file__).resolve().parents[2]
EDS = REPO / "firmware" / "protocol" / "cia402_servo.eds"
GROUP = "239.74.163.2"
MASTER_ID = 127
PDOS = {  # communication, mapping, COB-ID base, the contract's mapping
    "rpdo1": (0x1400, 0x1600, 0x200, [0x60400010, 0x60710010]),
    "tpdo1": (0x1800, 0x1A00, 0x180, [0x60640020, 0x606C0020]),
    "tpdo2": (0x1801, 0x1A01, 0x280, [0x60770010, 0x60410010]),
}


@pytest.fixture(scope="module")
def boot_bin(build_dir: Path) -> Path:
    exe = build_dir / "firmware" / "arm_canopen_boot"
    if not exe.exists():
        pytest.skip(f"{exe} not built (cmake --build build/debug --target arm_canopen_boot)")
    return exe


class Cia402Drive:
    """A LocalNode that behaves like the contract's drive, as far as the boot needs."""

    def __init__(self, node_id: int, reject_mode: bool = False, device_type: int | None = None,
                 in_fault: bool = False, stuck_at: int | None = None, eds: Path = EDS,
                 late: tuple[int, int, float] | None = None) -> None:
        self.node = canopen.LocalNode(node_id, str(eds))
        self.late = late  # (index, sub, seconds): the first read of it is answered that late
        self.id = node_id
        self.reject_mode = reject_mode
        self.device_type = device_type
        self.sw = 0x0008 if in_fault else 0x0040  # fault, or switch on disabled
        self.cw = 0
        self.stuck_at = stuck_at  # a statusword state the drive never leaves
        self.mode = 0
        self.writes: list[tuple[int, int, int]] = []  # (index, sub, value) in the order they came
        self.lock = threading.Lock()
        self.node.add_write_callback(self.on_write)
        self.node.add_read_callback(self.on_read)

    def stored(self, index: int, sub: int = 0) -> int:
        od = self.node.object_dictionary[index]
        var = od if isinstance(od, canopen.objectdictionary.ODVariable) else od[sub]
        return var.decode_raw(self.node.get_data(index, sub))

    def on_read(self, index: int, subindex: int, od) -> int | None:  # noqa: ANN001 - canopen's ODVariable
        if self.late is not None and (index, subindex) == self.late[:2]:
            time.sleep(self.late[2])  # the network's one receive thread: later requests wait too
            self.late = None
        if index == 0x6041:
            return self.sw
        if index == 0x6061:
            return self.mode
        if index == 0x1000 and self.device_type is not None:
            return self.device_type
        return None

    def on_write(self, index: int, subindex: int, od, data: bytes) -> None:  # noqa: ANN001
        value = od.decode_raw(data)
        for comm, mapping, _, _ in PDOS.values():
            if index == mapping and not self.stored(comm, 1) & 0x80000000:
                raise SdoAbortedError(0x08000022)  # mapping written while the PDO is valid
        if index == 0x6060:
            supported = {10: 1 << 9, 8: 1 << 7}
            if self.reject_mode or not self.stored(0x6502) & supported.get(value, 0):
                raise SdoAbortedError(0x06090030)
            self.mode = value
        if index == 0x6040:
            rising_reset = value & 0x80 and not self.cw & 0x80
            self.cw = value
            if self.sw & 0x08:  # fault: only bit 7's rising edge leaves it (to switch on disabled)
                if rising_reset:
                    self.sw = 0x0040
            else:
                state = {0x00: 0x40, 0x06: 0x21, 0x07: 0x23, 0x0F: 0x27}.get(value & 0x8F)
                operational = self.node.nmt.state == "OPERATIONAL"
                if state is not None and (state != 0x27 or operational) and self.sw != self.stuck_at:
                    self.sw = state
        with self.lock:
            self.writes.append((index, subindex, value))


@pytest.fixture()
def udp_port(slot) -> int:  # noqa: ANN001 - conftest's run slot: ports no other test uses meanwhile
    return slot.can_port


def _run(boot_bin: Path, port: int, args: list[str], drives: list[Cia402Drive], monkeypatch: pytest.MonkeyPatch,
         watch: list[int] | None = None) -> tuple[subprocess.CompletedProcess[str], list[bytes]]:
    net = loopback_network(monkeypatch, GROUP, port)
    seen: list[bytes] = []
    try:
        for d in drives:
            net.add_node(d.node)
        for cob in watch or []:
            net.subscribe(cob, lambda can_id, data, ts: seen.append(bytes(data)))
        p = subprocess.run([str(boot_bin), "--bus", f"udp:{GROUP}:{port}", "--sdo-timeout-ms", "300", *args],
                           capture_output=True, text=True, timeout=120)
    finally:
        for d in drives:
            d.node.nmt.stop_heartbeat()
        net.disconnect()
    return p, seen


def _arm(n: int = 3, limits: tuple[float, ...] = (150.0, 150.0, 28.0)) -> dict:
    return {"joints": [{"name": f"j{i + 1}", "torque_limit": limits[i]} for i in range(n)],
            "buses": [{"name": "can0", "drives": list(range(1, n + 1))}], "loop_rate_hz": 1000.0}


def test_boot_brings_every_node_to_operation_enabled(boot_bin: Path, udp_port: int, tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    cfg = gen_drives.load(_arm())
    args = cfg.boot_args("can0")
    assert "3,rated=28000" in args  # the rule: the 28 N m joint's torque limit overrides the EDS's 150
    drives = [Cia402Drive(i) for i in (1, 2, 3)]
    out = tmp_path / "boot.json"
    p, _ = _run(boot_bin, udp_port, [*args, "--json", str(out)], drives, monkeypatch)
    assert p.returncode == 0, p.stderr
    assert "3 nodes operation enabled" in p.stdout
    result = json.loads(out.read_text())
    assert result["result"] == "operation_enabled" and result["fault"]["code"] == "none"
    assert [(n["node"], n["state"], n["statusword"] & 0x6F) for n in result["nodes"]] == \
        [(i, "operation_enabled", 0x27) for i in (1, 2, 3)]
    assert result["nodes"][0]["identity"][1] == drives[0].stored(0x1018, 2)  # product code, from the EDS
    assert [(w["node"], w["index"], w["sub"], w["value"]) for w in result["sdo_writes"] if w["node"] == 1] == \
        [(1, i, s, v) for i, s, v in drives[0].writes]
    printed = [ln.split() for ln in p.stdout.splitlines() if ln.startswith("write node")]
    for d in drives:
        nid = d.id
        # what the master says it wrote is what the drive received, in that order
        mine = [(int(w[3].split(":")[0], 16), int(w[3].split(":")[1], 16), int(w[5], 16)) for w in printed if w[2] == str(nid)]
        assert [(i, s, v) for i, s, v in mine] == [(i, s, v & 0xFFFFFFFF) for i, s, v in d.writes], nid
        for comm, mapping, base, entries in PDOS.values():
            assert d.stored(comm, 1) == base + nid
            assert d.stored(comm, 2) == 1  # on every SYNC
            assert d.stored(mapping, 0) == len(entries)
            assert [d.stored(mapping, k + 1) for k in range(len(entries))] == entries
            seq = [(s, v) for i, s, v in d.writes if i in (comm, mapping)]
            assert seq[0] == (1, 0x80000000 | (base + nid)) and seq[1] == (0, 0) and seq[-1] == (1, base + nid)
        assert d.stored(0x1006) == 1000
        assert d.stored(0x1017) == 100
        assert d.stored(0x1016, 1) == (MASTER_ID << 16) | 300
        assert d.stored(0x6060) == 10
        assert d.stored(0x6040) == 0x0F and d.sw & 0x6F == 0x27
        written = {(i, s) for i, s, _ in d.writes}
        if nid == 3:
            assert d.stored(0x6076) == 28000
        else:  # no override: the EDS default stays, not written
            assert (0x6076, 0) not in written and d.stored(0x6076) == 150000
        assert (0x608F, 1) not in written and (0x6091, 1) not in written
        assert [v for i, _, v in d.writes if i == 0x6040] == [0x06, 0x07, 0x0F]  # fresh: no 0x00 first


def test_a_late_sdo_answer_and_its_retry_s_twin_do_not_fail_the_boot(boot_bin: Path, udp_port: int, tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """Node 2 answers 0x1018:03 after the master's 300 ms timed out: the master asked again, takes
    the late answer, and the retry's twin answer, which comes during the next transfer, is not that
    transfer's (it once failed the boot: "master aborted the response with 0x05040001")."""
    out = tmp_path / "boot.json"
    drives = [Cia402Drive(1), Cia402Drive(2, late=(0x1018, 3, 0.45))]
    p, _ = _run(boot_bin, udp_port, ["--node", "1", "--node", "2", "--json", str(out)], drives, monkeypatch)
    assert p.returncode == 0, p.stderr
    assert [n["identity"] for n in json.loads(out.read_text())["nodes"]][1][2] == drives[1].stored(0x1018, 3)


def _eds_with_identity_sub1_only(tmp_path: Path) -> Path:
    text = EDS.read_text()
    for sub in (2, 3, 4):
        start = text.index(f"[1018sub{sub}]")
        text = text[:start] + text[text.index("\n\n", start) + 2:]
    text = text.replace("[1018]\nParameterName=Identity object\nObjectType=0x9\nSubNumber=5",
                        "[1018]\nParameterName=Identity object\nObjectType=0x9\nSubNumber=2")
    start = text.index("[1018sub0]")
    end = text.index("\n\n", start)
    text = text[:start] + text[start:end].replace("DefaultValue=4", "DefaultValue=1") + text[end:]
    path = tmp_path / "identity_sub1.eds"
    path.write_text(text)
    return path


def test_a_drive_with_the_mandatory_identity_alone_boots(boot_bin: Path, udp_port: int, tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """CiA 301 makes 0x1018 sub 1 (vendor) mandatory and 2-4 optional: a drive without them boots,
    the missing ones recorded as 0."""
    out = tmp_path / "boot.json"
    drive = Cia402Drive(1, eds=_eds_with_identity_sub1_only(tmp_path))
    assert sorted(drive.node.object_dictionary[0x1018].subindices) == [0, 1]  # the drive really lacks them
    p, _ = _run(boot_bin, udp_port, ["--node", "1", "--json", str(out)], [drive], monkeypatch)
    assert p.returncode == 0, p.stderr
    assert json.loads(out.read_text())["nodes"][0]["identity"] == [0, 0, 0, 0]


def test_unsupported_mode_names_node_object_and_abort(boot_bin: Path, udp_port: int, tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "boot.json"
    p, _ = _run(boot_bin, udp_port, ["--node", "1", "--node", "2", "--json", str(out)],
                [Cia402Drive(1), Cia402Drive(2, reject_mode=True)], monkeypatch)
    assert p.returncode == 1
    line = p.stderr.strip().splitlines()[-1]
    assert line == ("arm_canopen_boot: sdo_abort: node 2: 0x6060:00: SDO abort 0x06090030 "
                    "(value range of parameter exceeded)"), p.stderr
    fault = json.loads(out.read_text())["fault"]
    assert (fault["code"], fault["node"], fault["index"], fault["abort_code"]) == ("sdo_abort", 2, 0x6060, 0x06090030)


def test_drive_in_fault_is_reported_or_reset_when_asked(boot_bin: Path, udp_port: int,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    p, _ = _run(boot_bin, udp_port, ["--node", "1"], [Cia402Drive(1, in_fault=True)], monkeypatch)
    assert p.returncode == 1
    assert "drive_fault: node 1: 0x6041:00: statusword 0x0008 shows fault (bit 3) while waiting for 0x40" in p.stderr
    drive = Cia402Drive(1, in_fault=True)
    p, _ = _run(boot_bin, udp_port + 1, ["--node", "1", "--fault-reset"], [drive], monkeypatch)
    assert p.returncode == 0, p.stderr
    # the reset (0x00, 0x80) before the configuration, then switch on disabled confirmed (0x00)
    assert [v for i, _, v in drive.writes if i == 0x6040] == [0x00, 0x80, 0x00, 0x06, 0x07, 0x0F]
    first_config = next(k for k, (i, _, _) in enumerate(drive.writes) if i == 0x1400)
    assert [i for i, _, _ in drive.writes[:first_config]] == [0x6040] * 3
    assert drive.sw & 0x6F == 0x27


def test_a_drive_left_enabled_is_disabled_before_it_is_configured(boot_bin: Path, udp_port: int,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """A master that restarts finds its drives enabled: no new mode or scaling while torque flows
    (the emulated drive aborts 0x08000022), so controlword 0x00 goes first; a fresh drive gets none."""
    drive = Cia402Drive(1)
    drive.sw = 0x0027
    p, _ = _run(boot_bin, udp_port, ["--node", "1"], [drive], monkeypatch)
    assert p.returncode == 0, p.stderr
    assert drive.writes[0] == (0x6040, 0, 0x00) and drive.writes[1][0] == 0x1400


def test_a_statusword_that_does_not_follow_is_a_state_timeout(boot_bin: Path, udp_port: int,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    p, _ = _run(boot_bin, udp_port, ["--node", "1", "--state-timeout-ms", "200", "--period-us", "2000"],
                [Cia402Drive(1, stuck_at=0x21)], monkeypatch)
    assert p.returncode == 1
    assert p.stderr.strip().splitlines()[-1] == ("arm_canopen_boot: state_timeout: node 1: 0x6041:00: statusword "
                                                 "0x0021 did not reach 0x23 (under mask 0x6F)"), p.stderr


def test_help_lists_every_option(boot_bin: Path) -> None:
    p = subprocess.run([str(boot_bin), "--help"], capture_output=True, text=True, timeout=30)
    assert p.returncode == 0
    for opt in ("--bus", "--node", "--cycle-us", "--heartbeat-ms", "--master-id", "--consumer-ms", "--sdo-timeout-ms",
                "--sdo-tries", "--state-timeout-ms", "--period-us", "--timeout-ms", "--json", "--hold-periods",
                "--hold-torque", "--fault-reset"):
        assert opt in p.stdout, opt


def test_gen_drives_boot_args_on_the_command_line(tmp_path: Path) -> None:
    arm_json = tmp_path / "arm.json"
    arm_json.write_text(json.dumps(_arm()))
    run = [str(REPO / ".venv" / "bin" / "python"), "-m", "gen.drives", "--arm-json", str(arm_json)]
    p = subprocess.run([*run, "--boot-args", "can0"], capture_output=True, text=True, cwd=REPO)
    assert p.returncode == 0, p.stderr
    assert p.stdout.split() == ["--cycle-us", "1000", "--heartbeat-ms", "100", "--consumer-ms", "300", "--master-id",
                                "127", "--node", "1", "--node", "2", "--node", "3,rated=28000"]
    p = subprocess.run([*run, "--boot-args", "can7"], capture_output=True, text=True, cwd=REPO)
    assert p.returncode == 2 and "no drive is on bus 'can7'" in p.stderr
    table = json.loads(subprocess.run(run, capture_output=True, text=True, cwd=REPO).stdout)
    assert [d["rated_torque_mnm"] for d in table["drives"]] == [150000, 150000, 28000]


def test_unwritable_json_is_refused_before_the_bus(boot_bin: Path, tmp_path: Path) -> None:
    p = subprocess.run([str(boot_bin), "--bus", "udp", "--node", "1", "--json", str(tmp_path / "no" / "x.json")],
                       capture_output=True, text=True, timeout=30)
    assert p.returncode == 2 and "--json" in p.stderr and "cannot write into" in p.stderr, p.stderr


def test_wrong_device_type_is_named(boot_bin: Path, udp_port: int, monkeypatch: pytest.MonkeyPatch) -> None:
    p, _ = _run(boot_bin, udp_port, ["--node", "1"], [Cia402Drive(1, device_type=0x00020191)], monkeypatch)
    assert p.returncode == 1
    assert "node 1: 0x1000:00: read 0x00020191, expected 0x00020192" in p.stderr, p.stderr


def test_silent_node_is_no_answer_after_the_tries(boot_bin: Path, udp_port: int,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    p, seen = _run(boot_bin, udp_port, ["--node", "1", "--node", "9", "--sdo-tries", "3"], [Cia402Drive(1)],
                   monkeypatch, watch=[0x600 + 9])
    assert p.returncode == 1
    assert "node 9: 0x1000:00: no answer after 3 tries" in p.stderr, p.stderr
    initiates = [d for d in seen if d[0] == 0x40 and d[1:4] == bytes([0x00, 0x10, 0x00])]
    assert len(initiates) == 3  # one upload request per try
    assert seen[-1][0] == 0x80 and int.from_bytes(seen[-1][4:8], "little") == 0x05040000


def test_bad_node_option_is_one_line(boot_bin: Path) -> None:
    p = subprocess.run([str(boot_bin), "--bus", "udp", "--node", "2,gear=101"], capture_output=True, text=True)
    assert p.returncode == 2
    assert p.stderr.strip() == "arm_canopen_boot: --node '2,gear=101': field gear: expected MOTOR/SHAFT revolutions, both >= 1"


def test_hold_packs_rpdo1_and_decodes_tpdos_in_si_units(boot_bin: Path, udp_port: int, tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """After the boot: RPDO1 (enable operation, the torque in per-mille of the node's rated torque)
    then SYNC every period; the test drive answers each SYNC with TPDO1 and TPDO2 (LocalNode does not
    produce or consume PDOs by itself: its SYNC and RPDO1 subscriptions do it here)."""
    drive = Cia402Drive(4)
    pos, vel, tq = -12_345_678, 52_953_088, -250  # increments, increments/s (one joint rev/s), per-mille
    rpdo1: list[bytes] = []
    net = loopback_network(monkeypatch, GROUP, udp_port)
    out = tmp_path / "boot.json"
    try:
        net.add_node(drive.node)
        net.subscribe(0x200 + 4, lambda can_id, data, ts: rpdo1.append(bytes(data)))

        def on_sync(can_id: int, data: bytes, ts: float) -> None:
            if drive.node.nmt.state == "OPERATIONAL":
                net.send_message(0x180 + 4, struct.pack("<ii", pos, vel))
                net.send_message(0x280 + 4, struct.pack("<hH", tq, drive.sw))

        net.subscribe(0x080, on_sync)
        p = subprocess.run([str(boot_bin), "--bus", f"udp:{GROUP}:{udp_port}", "--sdo-timeout-ms", "300",
                            "--node", "4,rated=28000,encoder=4096,gear=160/1", "--hold-periods", "50",
                            "--hold-torque", "-3.5", "--json", str(out)], capture_output=True, text=True, timeout=120)
    finally:
        drive.node.nmt.stop_heartbeat()
        net.disconnect()
    assert p.returncode == 0, p.stderr
    assert drive.stored(0x608F, 1) == 4096 and drive.stored(0x6091, 1) == 160 and drive.stored(0x6076) == 28000
    assert len(rpdo1) == 50
    assert all(struct.unpack("<Hh", r) == (0x000F, -125) for r in rpdo1)  # -3.5 N m / 28 N m = -125 per-mille
    hold = json.loads(out.read_text())["nodes"][0]["hold"]
    assert hold["target_permille"] == -125 and hold["tpdo1"] >= 45 and hold["tpdo2"] >= 45
    inc_per_rad = 4096 * 160 / (2 * math.pi)
    assert hold["q_rad"] == pytest.approx(pos / inc_per_rad, rel=1e-6)
    assert hold["qd_rad_s"] == pytest.approx(vel / inc_per_rad, rel=1e-6)
    assert hold["tau_nm"] == pytest.approx(tq * 28.0 / 1000, rel=1e-6)
    assert hold["statusword"] & 0x6F == 0x27


def test_boots_the_simulators_cia402_drives(boot_bin: Path, build_dir: Path, udp_port: int, tmp_path: Path) -> None:
    """The master against the emulated drives (arm_sim --protocol canopen, task D's side of the
    contract) when this build's simulator has them: every drive enabled, then held at 2 N m."""
    sim = build_dir / "host_sim" / "native" / "arm_sim"
    if not sim.exists():
        pytest.skip(f"{sim} not built")
    if "--protocol" not in subprocess.run([str(sim), "--help"], capture_output=True, text=True).stdout:
        pytest.skip(f"{sim} has no --protocol canopen (the emulated CiA 402 drives are not in this build)")
    bus = f"udp:{GROUP}:{udp_port}"
    proc = subprocess.Popen([str(sim), "--protocol", "canopen", "--bus", bus, "--lcm-url", "", "--boot-timeout", "30",
                             "--idle-timeout", "5"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    out = tmp_path / "boot.json"
    try:
        nodes = [a for i in range(1, 7) for a in ("--node", str(i))]
        for _ in range(2):  # the second boot finds the drives enabled (or faulted: --fault-reset)
            p = subprocess.run([str(boot_bin), "--bus", bus, "--sdo-timeout-ms", "300", "--timeout-ms", "60000",
                                *nodes, "--fault-reset", "--hold-periods", "100", "--hold-torque", "2",
                                "--json", str(out)], capture_output=True, text=True, timeout=120)
            assert p.returncode == 0, p.stderr
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    assert p.returncode == 0, p.stderr
    result = json.loads(out.read_text())
    assert [n["state"] for n in result["nodes"]] == ["operation_enabled"] * 6
    # no overrides: the contract's 28 writes per node, and the restart's controlword 0x00 (+ a reset)
    assert 6 * 29 <= len(result["sdo_writes"]) <= 6 * 31
    for n in result["nodes"]:
        assert n["hold"]["target_permille"] == 13 and n["hold"]["tpdo1"] > 0 and n["hold"]["tpdo2"] > 0
        assert n["hold"]["statusword"] & 0x6F == 0x27


def test_controller_runs_on_the_simulators_cia402_drives(build_dir: Path, udp_port: int, tmp_path: Path) -> None:
    """arm_controller --protocol canopen, lockstep, against arm_sim --protocol canopen when the build
    has it: the CANopen boot, then RPDO1/SYNC/TPDOs every period, the run ends running (no check
    tripped: following error, torque mismatch, missing states)."""
    sim, ctl = build_dir / "host_sim" / "native" / "arm_sim", build_dir / "firmware" / "arm_controller"
    if not sim.exists() or not ctl.exists():
        pytest.skip(f"{sim} or {ctl} not built")
    if "--protocol" not in subprocess.run([str(sim), "--help"], capture_output=True, text=True).stdout:
        pytest.skip(f"{sim} has no --protocol canopen (the emulated CiA 402 drives are not in this build)")
    bus = f"udp:{GROUP}:{udp_port}"
    proc = subprocess.Popen([str(sim), "--protocol", "canopen", "--bus", bus, "--lcm-url", "", "--boot-timeout", "30",
                             "--idle-timeout", "5"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    summary = tmp_path / "controller.json"
    try:
        p = subprocess.run([str(ctl), "--protocol", "canopen", "--bus", bus, "--mode", "lockstep", "--duration", "2",
                            "--lcm-url", "", "--summary", str(summary)], capture_output=True, text=True, timeout=300)
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    assert p.returncode == 0, p.stderr
    s = json.loads(summary.read_text())
    assert s["final_state"] == "running" and s["final_fault"] == "none", s["reason"]
    assert s["frames"]["rx_state"] == 6 * s["bus_periods"]  # TPDO1 + TPDO2 of every drive, every period
    assert s["frames"]["rx_bad_length"] == 0 and s["frames"]["rx_unknown_id"] == 0


def test_controller_runs_on_localnode_drives(build_dir: Path, udp_port: int, tmp_path: Path,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """arm_controller --protocol canopen, lockstep, on six LocalNodes: the CANopen boot (the wrists'
    rated torque, their 28 N m limit, written), then each SYNC answered with TPDO1 (a fixed pose) and
    TPDO2 (the torque of the RPDO1 the drive applied at that SYNC, CiA 301's synchronous RPDO)."""
    ctl = build_dir / "firmware" / "arm_controller"
    if not ctl.exists():
        pytest.skip(f"{ctl} not built")
    drives = {i: Cia402Drive(i) for i in range(1, 7)}
    pending = {i: 0 for i in drives}   # the latest RPDO1 torque, applied at the next SYNC
    applied = {i: 0 for i in drives}
    rpdo_cw: set[int] = set()
    sync_lengths: set[int] = set()
    net = loopback_network(monkeypatch, GROUP, udp_port)
    summary = tmp_path / "controller.json"
    try:
        for i, d in drives.items():
            net.add_node(d.node)

            def on_rpdo(can_id: int, data: bytes, ts: float, i: int = i) -> None:
                cw, tq = struct.unpack("<Hh", data)
                rpdo_cw.add(cw)
                pending[i] = tq

            net.subscribe(0x200 + i, on_rpdo)

        def on_sync(can_id: int, data: bytes, ts: float) -> None:
            sync_lengths.add(len(data))
            for i, d in drives.items():
                if d.node.nmt.state != "OPERATIONAL":
                    continue
                applied[i] = pending[i]
                net.send_message(0x180 + i, struct.pack("<ii", 1000 * i, 0))
                net.send_message(0x280 + i, struct.pack("<hH", applied[i], d.sw))

        net.subscribe(0x080, on_sync)
        p = subprocess.run([str(ctl), "--protocol", "canopen", "--bus", f"udp:{GROUP}:{udp_port}", "--mode", "lockstep",
                            "--duration", "0.2", "--ref-hold", "0.1", "--lcm-url", "", "--summary", str(summary)],
                           capture_output=True, text=True, timeout=300)
    finally:
        for d in drives.values():
            d.node.nmt.stop_heartbeat()
        net.disconnect()
    assert p.returncode == 0, p.stderr
    s = json.loads(summary.read_text())
    assert s["final_state"] == "running" and s["frames"]["rx_state"] == 6 * s["bus_periods"], s["reason"]
    assert [drives[i].stored(0x6076) for i in range(1, 7)] == [150000] * 3 + [28000] * 3
    assert all(drives[i].sw & 0x6F == 0x27 and drives[i].stored(0x6060) == 10 for i in drives)
    assert rpdo_cw == {0x000F}  # enable operation all along (the NMT stop ends the run)
    assert sync_lengths == {0}  # CiA 301 SYNC without a counter


def _controller_on_localnodes(build_dir: Path, port: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                              drives: dict[int, Cia402Drive], emcy_at: tuple[int, int, int] | None = None,
                              duration: str = "0.5") -> tuple[subprocess.CompletedProcess[str], dict]:
    """arm_controller --protocol canopen on six LocalNodes that answer each SYNC with TPDO1 and
    TPDO2; emcy_at = (node, SYNC number, code): that node sends that EMCY then, and faults (statusword
    fault) unless the code is 0x0000, CiA 301's "error reset or no error"."""
    ctl = build_dir / "firmware" / "arm_controller"
    if not ctl.exists():
        pytest.skip(f"{ctl} not built")
    net = loopback_network(monkeypatch, GROUP, port)
    summary = tmp_path / "controller.json"
    syncs = [0]
    pending = {i: 0 for i in drives}  # the latest RPDO1 torque, applied at the next SYNC (type 1)
    try:
        for i, d in drives.items():
            net.add_node(d.node)

            def on_rpdo(can_id: int, data: bytes, ts: float, i: int = i) -> None:
                pending[i] = struct.unpack("<Hh", data)[1]

            net.subscribe(0x200 + i, on_rpdo)

        def on_sync(can_id: int, data: bytes, ts: float) -> None:
            syncs[0] += 1
            for i, d in drives.items():
                if d.node.nmt.state != "OPERATIONAL":
                    continue
                if emcy_at is not None and emcy_at[0] == i and syncs[0] == emcy_at[1]:
                    d.sw = 0x0008 if emcy_at[2] else d.sw  # fault, torque off
                    net.send_message(0x080 + i, struct.pack("<HB5x", emcy_at[2], 0x11))
                net.send_message(0x180 + i, struct.pack("<ii", 1000 * i, 0))
                net.send_message(0x280 + i, struct.pack("<hH", 0 if d.sw & 0x08 else pending[i], d.sw))

        net.subscribe(0x080, on_sync)
        p = subprocess.run([str(ctl), "--protocol", "canopen", "--bus", f"udp:{GROUP}:{port}", "--mode", "lockstep",
                            "--duration", duration, "--ref-hold", "0.1", "--lcm-url", "", "--boot-timeout", "5",
                            "--summary", str(summary)], capture_output=True, text=True, timeout=300)
    finally:
        for d in drives.values():
            d.node.nmt.stop_heartbeat()
        net.disconnect()
    return p, json.loads(summary.read_text())


@pytest.mark.parametrize("bad,fault,index", [
    ({"device_type": 0x00010191}, "wrong_value", 0x1000),   # a CiA 401 I/O module, not a servo drive
    ({"reject_mode": True}, "sdo_abort", 0x6060),            # CST refused: abort 0x06090030
])
def test_controller_names_a_drive_it_cannot_configure(build_dir: Path, udp_port: int, tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch, bad: dict, fault: str,
                                                      index: int) -> None:
    """Through the whole controller: node 3 is refused at boot, by name; no drive is left enabled
    (the others are stopped), exit 3 (boot failed)."""
    drives = {i: Cia402Drive(i, **(bad if i == 3 else {})) for i in range(1, 7)}
    p, s = _controller_on_localnodes(build_dir, udp_port, tmp_path, monkeypatch, drives)
    assert p.returncode == 3, p.stderr
    f = s["canopen"]["fault"]
    assert (f["code"], f["node"], f["index"]) == (fault, 3, index), f
    assert s["reason"].startswith(f"boot: canopen: {fault}: node 3: 0x{index:04x}:00"), s["reason"]
    if fault == "sdo_abort":
        assert f["abort_code"] == 0x06090030
    assert s["final_state"] == "init" and s["steps_done"] == 0
    assert all(d.node.nmt.state == "STOPPED" for d in drives.values())  # NMT stop to every drive


def test_controller_safe_stops_on_a_lost_heartbeat_emcy(build_dir: Path, udp_port: int, tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """Mid-run, drive 5's consumer misses the master's heartbeat (CiA 301: EMCY 0x8130, fault,
    torque off): the controller names it, stops safely, exit 4."""
    drives = {i: Cia402Drive(i) for i in range(1, 7)}
    p, s = _controller_on_localnodes(build_dir, udp_port, tmp_path, monkeypatch, drives, emcy_at=(5, 150, 0x8130))
    assert p.returncode == 4, p.stderr
    assert "drive 5 reports a fault (EMCY 0x8130)" in s["reason"], s["reason"]
    assert s["final_state"] in ("safe_stop", "fault") and 0 < s["steps_done"] < s["steps_requested"]


def test_an_error_reset_emcy_is_no_fault(build_dir: Path, udp_port: int, tmp_path: Path,
                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """EMCY 0x0000 ("error reset or no error", what python-canopen's EmcyProducer.reset sends)
    mid-run: counted, and the run goes on to its end."""
    drives = {i: Cia402Drive(i) for i in range(1, 7)}
    p, s = _controller_on_localnodes(build_dir, udp_port, tmp_path, monkeypatch, drives, emcy_at=(2, 150, 0x0000))
    assert p.returncode == 0, p.stderr + s.get("reason", "")
    assert s["frames"]["rx_emcy"] == 1 and s["steps_done"] == s["steps_requested"]


def test_controller_protocol_option_is_checked(build_dir: Path) -> None:
    ctl = build_dir / "firmware" / "arm_controller"
    if not ctl.exists():
        pytest.skip(f"{ctl} not built")
    p = subprocess.run([str(ctl), "--protocol", "cia402"], capture_output=True, text=True, timeout=30)
    assert p.returncode == 2 and "--protocol: 'cia402' is not arm or canopen" in p.stderr, p.stderr


def test_c_eds_defaults_are_the_eds() -> None:
    header = (REPO / "firmware" / "canopen" / "include" / "arm" / "co_pdo.h").read_text()
    c = {k: int(v) for k, v in re.findall(r"#define ARM_CO_EDS_(\w+) (\d+)u", header)}
    eds = gen_drives.eds_defaults(EDS)
    assert c == {"RATED_TORQUE_MNM": eds["rated"], "ENCODER_INCREMENTS": eds["encoder"],
                 "GEAR_MOTOR_REVS": eds["gear_motor"], "GEAR_SHAFT_REVS": eds["gear_shaft"]}


# ---- the drive configuration (gen/drives.py) ----------------------------------------------------

def test_drive_config_rule_and_overrides(tmp_path: Path) -> None:
    f = tmp_path / "drives.toml"
    f.write_text(f'eds = "{EDS}"\n[defaults]\ngear = [160, 1]\n[joint.j2]\nnode = 7\nrated_torque_nm = 150\n'
                 "encoder_increments = 4096\n")
    cfg = gen_drives.load(_arm(), f)
    d1, d2, d3 = cfg.drives
    assert (d1.node, d1.rated_torque_mnm, d1.gear, d1.overrides) == (1, 150000, (160, 1), ["0x6091"])
    assert (d2.node, d2.encoder_increments, d2.overrides) == (7, 4096, ["0x608F", "0x6091"])
    assert (d3.rated_torque_mnm, d3.overrides) == (28000, ["0x6076", "0x6091"])
    assert cfg.boot_args("can0")[-4:] == ["--node", "7,encoder=4096,gear=160/1", "--node", "3,rated=28000,gear=160/1"]


@pytest.mark.parametrize("body, message", [
    ('[joint.j9]\nnode = 2\n', "joint.j9: not a joint of the arm"),
    ('[joint.j1]\nnode = 0\n', "joint.j1.node: expected an integer 1..127, got 0"),
    ('[defaults]\ngear = [101]\n', "defaults.gear: expected [motor revolutions, shaft revolutions]"),
    ('[defaults]\nspeed = 1\n', "defaults: unknown field(s) speed"),
    ('[joint.j2]\nnode = 1\n', "node: node id 1 is used twice on bus can0"),
    ('[pdo]\nrpdo1 = ["0x6040:0:16"]\n', "pdo.rpdo1: the codec (firmware/canopen co_pdo.c) packs"),
    ('[joint.j3]\nrated_torque_nm = -1\n', "joint.j3.rated_torque_nm: expected a torque in N m"),
    ('[pdo]\ntransmission = { tpdo1 = 2 }\n', "pdo.transmission.tpdo1: expected 1 (the joint state, every SYNC)"),
    ('[pdo]\ntransmission = { tpdo2 = 254 }\n', "pdo.transmission.tpdo2: expected 1..240 (every n-th SYNC)"),
    ('[pdo]\ntransmission = { rpdo1 = 250 }\n', "pdo.transmission.rpdo1: expected 1..240, 254 or 255"),
    ('[pdo]\ntransmission = { tpdo3 = 1 }\n', "pdo.transmission: expected a table of rpdo1, tpdo1, tpdo2"),
])
def test_drive_config_bad_input_is_one_line(tmp_path: Path, body: str, message: str) -> None:
    f = tmp_path / "drives.toml"
    f.write_text(f'eds = "{EDS}"\n' + body)
    arm_json = tmp_path / "arm.json"
    arm_json.write_text(json.dumps(_arm()))
    p = subprocess.run([str(REPO / ".venv" / "bin" / "python"), "-m", "gen.drives", "--arm-json", str(arm_json),
                        "--drives", str(f)], capture_output=True, text=True, cwd=REPO)
    assert p.returncode == 2
    assert len(p.stderr.strip().splitlines()) == 1 and message in p.stderr, p.stderr
    assert p.stdout == ""


def test_arm_file_names_its_drive_config(tmp_path: Path) -> None:
    from gen.arm import ArmError, load_arm_file

    own = tmp_path / "my_drives.toml"
    own.write_text(f'eds = "{EDS}"\n[defaults]\nrated_torque_nm = 150\n')
    arm_file = tmp_path / "arm.toml"
    arm_file.write_text('model = "m.xml"\ndrives = "my_drives.toml"\n')
    assert gen_drives.drives_file_of({"arm_file": str(arm_file)}) == own.resolve()
    assert gen_drives.load({**_arm(), "arm_file": str(arm_file)}).drives[2].rated_torque_mnm == 150000
    assert gen_drives.drives_file_of({"arm_file": None}) == gen_drives.DEFAULT_DRIVES
    arm_file.write_text('model = "m.xml"\ndrives = "missing.toml"\n')
    with pytest.raises(ArmError, match="drives: .*missing.toml is not a file"):
        load_arm_file(arm_file)


def test_the_docs_bus_load_table_is_what_busload_computes() -> None:
    from gen.lib.busload import Bus, canopen_drives_per_bus, canopen_load

    readme = (REPO / "docs" / "drives.md").read_text()
    classic, fd = Bus("c", False, 1e6, None, []), Bus("f", True, 1e6, 5e6, [])
    for bus, label in ((classic, "classic 1 Mbit/s"), (fd, "CAN FD 1/5 Mbit/s")):
        row = next(ln for ln in readme.splitlines() if ln.startswith(f"| {label} | 1 / 2 / 3 / 6 |"))
        for rate in (1000, 500):
            cells = " / ".join(f"{100 * canopen_load(bus, n, rate):.1f}" for n in (1, 2, 3, 6)) + " %"
            assert cells in row, (label, rate, cells)
    assert canopen_drives_per_bus(classic, 1000) == 1 and canopen_drives_per_bus(classic, 500) == 4
    # TPDO2 every 2nd SYNC (firmware/protocol/drives_classic.toml): two drives per classic bus at 1 kHz
    every = {"tpdo2": 2}
    row = next(ln for ln in readme.splitlines() if ln.startswith("| classic 1 Mbit/s, TPDO2 every 2nd SYNC |"))
    cells = " / ".join(f"{100 * canopen_load(classic, n, 1000, every=every):.1f}" for n in (1, 2, 3, 6)) + " %"
    assert cells in row, cells
    assert canopen_drives_per_bus(classic, 1000, every=every) == 2
    assert canopen_drives_per_bus(fd, 1000) == 4 and canopen_drives_per_bus(fd, 500) == 8
