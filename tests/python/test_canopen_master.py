"""The firmware's CANopen master (firmware/canopen, arm_canopen_boot) against python-canopen's
LocalNode with the drives' EDS, on the UDP bus (python-can udp_multicast on loopback, TTL 0).

The test drive is a LocalNode that keeps its file's rules (tests/python/cia402_localnode.py): the
statusword follows the controlword (written by SDO, the way the master confirms each state), 0x6060
takes the modes 0x6502 lists, and a PDO mapping follows CiA 301 and the file. After the boot the
test reads back, from LocalNode's own dictionary, every object the master wrote and checks it
against the boot sequence (docs/drives-bring-up.md). Also gen/drives.py: the drive configuration's
rule and its one-line errors. Other vendors' files: test_canopen_vendor.py."""

from __future__ import annotations

import json
import math
import re
import struct
import subprocess
from pathlib import Path
from typing import Any

import pytest

canopen = pytest.importorskip("canopen")
from canopen.sdo import SdoAbortedError  # noqa: E402
from canopen_network import loopback_network  # noqa: E402
from cia402_localnode import FileDrive, controller_on_localnodes  # noqa: E402

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


def Cia402Drive(node_id: int, eds: Path = EDS, **kw: Any) -> FileDrive:  # noqa: N802 - reads as the drive it makes
    """A drive of the project's own EDS, or of eds (tests/python/cia402_localnode.py)."""
    return FileDrive(node_id, eds, **kw)


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
    # the bundled table: the motor that gives the joint's torque limit through the 101:1 gear (28 N m:
    # 278 mN m, rounded up), checked against the drive's own; its quick stop deceleration; the limit
    # for the boot to check
    assert "3,rated=278,encoder=524288,gear=101/1,quick_stop=337109828,limit=28" in args
    drives = [Cia402Drive(1), Cia402Drive(2), Cia402Drive(3, commissioned={(0x6076, 0): 278})]
    out = tmp_path / "boot.json"
    p, _ = _run(boot_bin, udp_port, [*args, "--json", str(out)], drives, monkeypatch)
    assert p.returncode == 0, p.stderr
    assert "3 nodes operation enabled" in p.stdout
    result = json.loads(out.read_text())
    assert result["result"] == "operation_enabled" and result["fault"]["code"] == "none"
    assert [(n["node"], n["state"], n["statusword"] & 0x6F) for n in result["nodes"]] == \
        [(i, "operation_enabled", 0x27) for i in (1, 2, 3)]
    assert result["nodes"][0]["identity"][1] == drives[0].stored(0x1018, 2)  # product code, from the EDS
    assert [(n["units"]["rated_torque"], n["units"]["torque_units_per_nm"]) for n in result["nodes"]] == \
        [(1486, 1000), (1486, 1000), (278, 1000)]  # read, not written
    assert [n["units"]["joint_rated_torque_nm"] for n in result["nodes"]] == \
        pytest.approx([150.086, 150.086, 28.078], rel=1e-9)  # at the joint: x 101
    assert all(n["units"]["gear"] == [101, 1] and n["absent"] == "" for n in result["nodes"])
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
        assert not written & {(0x6076, 0), (0x608F, 1), (0x608F, 2), (0x6091, 1), (0x6091, 2)}  # units: read only
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
    assert line == ("arm_canopen_boot: no_cst: node 2: 0x6060:00: no cyclic synchronous torque (mode 10), which this "
                    "controller needs (SDO abort 0x06090030); the drive offers cst (0x6502 = 0x00000200)"), p.stderr
    fault = json.loads(out.read_text())["fault"]
    assert (fault["code"], fault["node"], fault["index"], fault["abort_code"]) == ("no_cst", 2, 0x6060, 0x06090030)


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
                                "127", "--node", "1,rated=1486,encoder=524288,gear=101/1,quick_stop=337109828,limit=150",
                                "--node", "2,rated=1486,encoder=524288,gear=101/1,quick_stop=337109828,limit=150",
                                "--node", "3,rated=278,encoder=524288,gear=101/1,quick_stop=337109828,limit=28"]
    p = subprocess.run([*run, "--boot-args", "can7"], capture_output=True, text=True, cwd=REPO)
    assert p.returncode == 2 and "no drive is on bus 'can7'" in p.stderr
    table = json.loads(subprocess.run(run, capture_output=True, text=True, cwd=REPO).stdout)
    assert [d["rated_torque_mnm"] for d in table["drives"]] == [1486, 1486, 278]


def test_unwritable_json_is_refused_before_the_bus(boot_bin: Path, tmp_path: Path) -> None:
    p = subprocess.run([str(boot_bin), "--bus", "udp", "--node", "1", "--json", str(tmp_path / "no" / "x.json")],
                       capture_output=True, text=True, timeout=30)
    assert p.returncode == 2 and "--json" in p.stderr and "cannot write into" in p.stderr, p.stderr


def test_wrong_device_type_is_named(boot_bin: Path, udp_port: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """The profile word (CiA 402: 0x0192) is checked; the upper word is the device's own."""
    p, _ = _run(boot_bin, udp_port, ["--node", "1"], [Cia402Drive(1, device_type=0x00020191)], monkeypatch)
    assert p.returncode == 1
    assert "node 1: 0x1000:00: device type 0x00020191: profile 0x0191, not CiA 402 (0x0192)" in p.stderr, p.stderr
    p, _ = _run(boot_bin, udp_port + 1, ["--node", "1"], [Cia402Drive(1, device_type=0xFFFF0192)], monkeypatch)
    assert p.returncode == 0, p.stderr  # ros2_canopen's fake slave says 0xFFFF0192


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
    # a 175 mN m motor behind 160:1: 28 N m at the joint at 1000 per-mille
    drive = Cia402Drive(4, commissioned={(0x6076, 0): 175, (0x608F, 1): 4096, (0x6091, 1): 160})
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
                            "--node", "4,rated=175,encoder=4096,gear=160/1", "--hold-periods", "50",
                            "--hold-torque", "-3.5", "--json", str(out)], capture_output=True, text=True, timeout=120)
    finally:
        drive.node.nmt.stop_heartbeat()
        net.disconnect()
    assert p.returncode == 0, p.stderr
    assert not {i for i, _, _ in drive.writes} & {0x6076, 0x608F, 0x6091}  # the drive's units, read
    assert len(rpdo1) == 50
    assert all(struct.unpack("<Hh", r) == (0x000F, -125) for r in rpdo1)  # -3.5 N m / (0.175 x 160) = -125 per-mille
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
    """arm_controller --protocol canopen, lockstep, on six LocalNodes: the CANopen boot (each drive's
    own units, read: the EDS's 1486 mN m motor behind 101:1), then each SYNC answered with TPDO1 (a fixed pose) and
    TPDO2 (the torque of the RPDO1 the drive applied at that SYNC, CiA 301's synchronous RPDO)."""
    ctl = build_dir / "firmware" / "arm_controller"
    if not ctl.exists():
        pytest.skip(f"{ctl} not built")
    drives = {i: Cia402Drive(i) for i in range(1, 7)}
    pending = {i: 0 for i in drives}   # the latest RPDO1 torque, applied at the next SYNC
    applied = {i: 0 for i in drives}
    rpdo_cw: list[int] = []  # each change of an RPDO1's controlword
    sync_lengths: set[int] = set()
    net = loopback_network(monkeypatch, GROUP, udp_port)
    summary = tmp_path / "controller.json"
    try:
        for i, d in drives.items():
            net.add_node(d.node)

            def on_rpdo(can_id: int, data: bytes, ts: float, i: int = i) -> None:
                cw, tq = struct.unpack("<Hh", data)
                if not rpdo_cw or rpdo_cw[-1] != cw:
                    rpdo_cw.append(cw)
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
    # no drive table: each drive's own units, read (the EDS's 1486 mN m motor), never written
    assert all(drives[i].stored(0x6076) == 1486 and (0x6076, 0) not in {(x, s) for x, s, _ in drives[i].writes}
               for i in drives)
    assert all(drives[i].sw & 0x6F == 0x27 and drives[i].stored(0x6060) == 10 for i in drives)
    # enable operation all along, then the end of the run's controlled stop: quick stop (these drives
    # never leave operation enabled, so until --stop-timeout), disable voltage, then the NMT stop
    assert rpdo_cw == [0x000F, 0x0002, 0x0000]
    assert sync_lengths == {0}  # CiA 301 SYNC without a counter


def _controller_on_localnodes(build_dir: Path, port: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                              drives: dict[int, FileDrive], emcy_at: tuple[int, int, int] | None = None,
                              duration: str = "0.5") -> tuple[subprocess.CompletedProcess[str], dict]:
    ctl = build_dir / "firmware" / "arm_controller"
    if not ctl.exists():
        pytest.skip(f"{ctl} not built")
    return controller_on_localnodes(ctl, GROUP, port, tmp_path, monkeypatch, drives, emcy_at=emcy_at, duration=duration)


@pytest.mark.parametrize("bad,fault,index", [
    ({"device_type": 0x00010191}, "wrong_value", 0x1000),   # a CiA 401 I/O module, not a servo drive
    ({"reject_mode": True}, "no_cst", 0x6060),               # CST refused: abort 0x06090030
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
    if fault == "no_cst":
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


# ---- the drive configuration (gen/drives.py) ----------------------------------------------------

def test_drive_config_rule_and_what_the_table_gives(tmp_path: Path) -> None:
    """A field is the joint's, else [defaults]; units the table leaves out are the drive's (the
    file's, here), and only what it gives goes to the boot, to be compared with the drive's."""
    f = tmp_path / "drives.toml"
    f.write_text(f'eds = "{EDS}"\n[defaults]\ngear = [160, 1]\n[joint.j2]\nnode = 7\nrated_torque_nm = 1.5\n'
                 'encoder_increments = 4096\n[joint.j3]\nrated_torque_nm = "joint_torque_limit / gear"\n'
                 'gear_efficiency = 0.8\n')
    cfg = gen_drives.load(_arm(), f)
    d1, d2, d3 = cfg.drives
    assert (d1.node, d1.rated_torque_mnm, d1.encoder_increments, d1.gear, d1.given) == (1, 1486, 524288, (160, 1),
                                                                                        ["0x6091"])
    assert d1.joint_rated_torque_nm == pytest.approx(1.486 * 160)  # the file's motor, through the table's gear
    assert (d2.node, d2.encoder_increments, d2.given) == (7, 4096, ["0x6076", "0x608F", "0x6091"])
    # 28 N m at the joint through 160:1 at 80 %: a 218.75 mN m motor, rounded up to the drive's unit
    assert (d3.rated_torque_mnm, d3.gear_efficiency, d3.given) == (219, 0.8, ["0x6076", "0x6091"])
    assert d3.joint_rated_torque_nm == pytest.approx(0.219 * 160 * 0.8)
    assert cfg.boot_args("can0")[-4:] == ["--node", "7,rated=1500,encoder=4096,gear=160/1,limit=150",
                                          "--node", "3,rated=219,gear=160/1,efficiency=0.8,limit=28"]
    assert d3.node_spec() == "3,rated=219,gear=160/1,efficiency=0.8"  # arm_controller's: its limit is the arm's
    assert all(d.brake is None and d.brake_spec() is None for d in cfg.drives)  # no brake fields: no brake


def test_drive_config_brakes_and_quick_stop(tmp_path: Path) -> None:
    """The stopping fields: a brake (holding torque at the joint, or the joint's torque limit; its
    delays) to the simulator's --brake, 0x6085 to both programs' --node."""
    f = tmp_path / "drives.toml"
    f.write_text(f'eds = "{EDS}"\n[defaults]\nbrake_holding_nm = "joint_torque_limit"\nbrake_close_ms = 50\n'
                 'brake_release_ms = 80\nquick_stop_deceleration = 84277457\n[joint.j2]\nbrake_holding_nm = 300\n')
    d1, d2, d3 = gen_drives.load(_arm(), f).drives
    assert d1.brake == (150.0, 50.0, 80.0) and d2.brake == (300.0, 50.0, 80.0) and d3.brake == (28.0, 50.0, 80.0)
    assert d1.brake_spec() == "1:150:50:80" and d3.brake_spec() == "3:28:50:80"
    assert d2.node_spec().endswith(",quick_stop=84277457")
    # the bundled table's: a brake on every joint, the deceleration of 40 rad/s^2 at the joint
    bundled = gen_drives.load(_arm())
    assert all(d.brake is not None and d.brake[1:] == (50.0, 80.0) for d in bundled.drives)
    assert all(d.quick_stop_deceleration == 337109828 for d in bundled.drives)


@pytest.mark.parametrize("body, message", [
    ('[joint.j9]\nnode = 2\n', "joint.j9: not a joint of the arm"),
    ('[joint.j1]\nnode = 0\n', "joint.j1.node: expected an integer 1..127, got 0"),
    ('[defaults]\ngear = [101]\n', "defaults.gear: expected [motor revolutions, shaft revolutions]"),
    ('[defaults]\nspeed = 1\n', "defaults: unknown field(s) speed"),
    ('[joint.j2]\nnode = 1\n', "node: node id 1 is used twice on bus can0"),
    ('[pdo]\nrpdo1 = ["0x6040:0:16"]\n', "pdo.rpdo1: the codec (firmware/canopen co_pdo.c) packs"),
    ('[joint.j3]\nrated_torque_nm = -1\n', "joint.j3.rated_torque_nm: expected the motor's rated torque in N m"),
    ('[defaults]\nrated_torque_nm = "joint_torque_limit"\n', "defaults.rated_torque_nm: \"joint_torque_limit\": 0x6076 "
     "is the motor's rated torque (CiA 402), the joint gets it times the gear"),
    ('[defaults]\ngear_efficiency = 1.2\n', "defaults.gear_efficiency: expected the gear's efficiency, above 0 and at "
     "most 1"),
    ('accept_no_master_watchdog = "yes"\n', "accept_no_master_watchdog: expected true or false"),
    # 0x6072 1000 per-mille x 1486 mN m x 101 is 150.086 N m: a 150 N m joint behind a 90 % gear is not given
    ('[defaults]\ngear_efficiency = 0.9\n', "joint j1 (node 1): its torque limit 150 N m is more than its drive gives "
     "at the joint, 135.077 N m = 0x6072 1000 per-mille x 0x6076 1486 mN m (the motor's) x gear 101/1 x "
     "efficiency 0.9"),
    ('consumer_ms = 0\n', "0x1016:01 (consumer heartbeat, the drive's watchdog on the master): a consumer time of 0 "
     "ms turns it off"),
    ('[pdo]\ntransmission = { tpdo1 = 2 }\n', "pdo.transmission.tpdo1: expected 1 (the joint state, every SYNC)"),
    ('[pdo]\ntransmission = { tpdo2 = 254 }\n', "pdo.transmission.tpdo2: expected 1..240 (every n-th SYNC)"),
    ('[pdo]\ntransmission = { rpdo1 = 250 }\n', "pdo.transmission.rpdo1: expected 1..240, 254 or 255"),
    ('[pdo]\ntransmission = { tpdo3 = 1 }\n', "pdo.transmission: expected a table of rpdo1, tpdo1, tpdo2"),
    ('[defaults]\nbrake_holding_nm = 100\nbrake_close_ms = 50\n',
     "defaults.brake_release_ms: missing: a brake needs brake_holding_nm, brake_close_ms, brake_release_ms"),
    ('[joint.j1]\nbrake_holding_nm = 0\nbrake_close_ms = 50\nbrake_release_ms = 80\n',
     "joint.j1.brake_holding_nm: expected a holding torque in N m at the joint"),
    ('[defaults]\nbrake_holding_nm = 100\nbrake_close_ms = -5\nbrake_release_ms = 80\n',
     "defaults.brake_close_ms: expected a delay in ms, 0..10000, got -5"),
    ('[defaults]\nquick_stop_deceleration = 0\n', "defaults.quick_stop_deceleration: expected an integer 1..4294967295"),
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
    own.write_text(f'eds = "{EDS}"\n[defaults]\nrated_torque_nm = 1.5\n')
    arm_file = tmp_path / "arm.toml"
    arm_file.write_text('model = "m.xml"\ndrives = "my_drives.toml"\n')
    assert gen_drives.drives_file_of({"arm_file": str(arm_file)}) == own.resolve()
    assert gen_drives.load({**_arm(), "arm_file": str(arm_file)}).drives[2].rated_torque_mnm == 1500
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


def test_a_unit_the_drive_reports_as_zero_is_named(boot_bin: Path, udp_port: int,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """No unit can be made of a gear of 101/0: refused before anything is written, the value named."""
    drive = Cia402Drive(3, commissioned={(0x6091, 2): 0})
    p, _ = _run(boot_bin, udp_port, ["--node", "3"], [drive], monkeypatch)
    assert p.returncode == 1 and drive.writes == []
    assert p.stderr.strip().splitlines() == ["arm_canopen_boot: bad_units: node 3: 0x6091 gear ratio (motor per shaft "
                                             "revolutions): the drive has 101/0, from which no unit can be made"], p.stderr


@pytest.mark.parametrize("edit, message", [
    (("[1017]\nParameterName=Producer heartbeat time\nObjectType=0x7\nDataType=0x0006\nAccessType=rw\nDefaultValue=0\n",
      "[1017]\nParameterName=Producer heartbeat time\nObjectType=0x7\nDataType=0x0006\nAccessType=rw\nDefaultValue=0\n"
      "HighLimit=50\n"), "0x1017:00 (producer heartbeat): the master writes 100, above its HighLimit 50"),
    (("[1006]\nParameterName=Communication cycle period\nObjectType=0x7\nDataType=0x0007\nAccessType=rw",
      "[1006]\nParameterName=Communication cycle period\nObjectType=0x7\nDataType=0x0007\nAccessType=ro"),
     "0x1006:00 (communication cycle period): access ro; the master writes 0x3E8"),
    (("[1017]\nParameterName=Producer heartbeat time\nObjectType=0x7\nDataType=0x0006",
      "[1017]\nParameterName=Producer heartbeat time\nObjectType=0x7\nDataType=0x0007"),
     "0x1017:00 (producer heartbeat): the file says UNSIGNED32, the master writes 2 bytes (CiA 301's type)"),
    (("[6077]\nParameterName=Torque actual value\nObjectType=0x7\nDataType=0x0003\nAccessType=ro\nDefaultValue=0\n"
      "PDOMapping=1", "[6077]\nParameterName=Torque actual value\nObjectType=0x7\nDataType=0x0003\nAccessType=ro\n"
      "DefaultValue=0\nPDOMapping=0"), "0x6077:00 in TPDO2: PDOMapping=0 in the file; the master maps it"),
])
def test_a_value_the_drive_cannot_take_is_named_before_the_boot(tmp_path: Path, edit: tuple[str, str],
                                                                message: str) -> None:
    """Every value the boot writes is checked against the drive's file first: access, type, limits,
    mapping rules (gen/drive_check.py); the drive table is refused in one line, no frame sent."""
    text = EDS.read_text()
    assert edit[0] in text
    (tmp_path / "drive.eds").write_text(text.replace(edit[0], edit[1]))
    table = tmp_path / "drives.toml"
    table.write_text('eds = "drive.eds"\n')
    with pytest.raises(gen_drives.DrivesError) as exc:
        gen_drives.load(_arm(1), table)
    assert str(exc.value) == f"{table}: joint j1 (node 1): drive.eds: {message}"
