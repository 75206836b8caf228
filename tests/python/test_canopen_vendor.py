"""Drives described by files no one here wrote (tests/drives/: maxon EPOS4, python-canopen's servo
example, Technosoft iPOS, Pilz PRBT, ros2_canopen's fake slave; their sources beside them):
- `armctl drive check` says whether this controller can run each, one line per problem;
- our master (arm_canopen_boot, arm_controller) boots python-canopen LocalNodes that keep each
  file's rules, reads each drive's units and decodes with them as CiA 402 defines them (one motor
  revolution reads as 2 pi / gear rad; a per-mille of the motor's rated torque 0x6076 is gear times
  that at the joint), refuses a drive without CST in one line naming its modes, and a joint whose
  torque limit its drive cannot give;
- a vendor's file is taken as it is: its harmless mistakes (an object the master never uses, a
  limit that contradicts CiA 301's definition of the object) are warnings naming the file's line,
  and a drive whose watchdog on the master cannot be set is refused unless its table accepts that;
- a drive table that disagrees with a drive's units never runs: one line, the node, the object
  and both values;
- our emulated drive built from each file (arm_sim --od) is booted by python-canopen's BaseNode402,
  and reports its position and torque in the file's units.
Expectations come from python-canopen's own reading of each file, not from ours."""

from __future__ import annotations

import json
import math
import struct
import subprocess
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

canopen = pytest.importorskip("canopen")
from canopen.profiles.p402 import BaseNode402  # noqa: E402
from canopen.sdo.exceptions import SdoAbortedError  # noqa: E402
from canopen_network import loopback_network, stop_nodes_and_wait  # noqa: E402
from cia402_localnode import FileDrive, controller_on_localnodes  # noqa: E402

from gen import drives as gen_drives  # noqa: E402
from gen import eds as gen_eds  # noqa: E402
from gen.lib.paths import REPO  # noqa: E402

# armctl test runs these alone (no other test beside them): python-canopen answers within SDO timeouts
pytestmark = pytest.mark.serial

DRIVES = REPO / "tests" / "drives"
GROUP = "239.74.163.2"
TWO_PI = 2 * math.pi
CST = {"python_canopen_e35.eds": "python_canopen_e35.toml", "maxon_epos4_50_15.dcf": "maxon_epos4_50_15.toml"}
# no CST: the modes each file's 0x6502 lists, and units for the boot to get that far
NO_CST = {"technosoft_ipos.eds": "pp, pv, hm, ip, manufacturer-specific", "pilz_prbt.dcf": "pp, vl, ip",
          "ros2_canopen_cia402_slave.eds": "pp, pv, hm, csp"}
# The motor's rated torque in N m, as the vendor states it: CiA 402's mN m for the e35 (310); maxon's
# EPOS4 gives µN m (512871: the EC 90 flat's nominal 0.513 N m), which its drive table has to say.
RATED_NM = {"python_canopen_e35.eds": 0.310, "maxon_epos4_50_15.dcf": 0.512871}


@dataclass(frozen=True)
class Units:
    rated: int          # 0x6076, in the drive's unit
    units_per_nm: int   # that unit: 1000 mN m (CiA 402), 1000000 µN m (the drive table's torque_unit)
    increments: int     # per encoder_revs motor revolutions
    revs: int
    gear: tuple[int, int]
    max_permille: int

    def rad_per_increment(self) -> float:
        return TWO_PI * self.revs * self.gear[1] / (self.increments * self.gear[0])

    def joint_nm_per_permille(self) -> float:
        """CiA 402: per-mille of the motor's rated torque, times the gear at the joint."""
        return self.rated / self.units_per_nm / 1000 * self.gear[0] / self.gear[1]


def _value(od: canopen.ObjectDictionary, index: int, sub: int | None = None) -> int | None:
    """python-canopen's reading of the file: the configured value, else the default (None: no object)."""
    if index not in od:
        return None
    var = od[index] if sub is None else od[index][sub]
    return var.value if var.value is not None else var.default


def _units(name: str) -> Units:
    """What the file says each unit is, the drive table standing in where the file lacks one."""
    od = canopen.import_od(str(DRIVES / name), 1)
    table = gen_drives.table_plan(DRIVES / CST[name])[0]
    unit = gen_drives.toml_input.loads((DRIVES / CST[name]).read_text()).get("defaults", {}).get("torque_unit", "mNm")
    inc, revs = _value(od, 0x608F, 1), _value(od, 0x608F, 2)
    motor, shaft = _value(od, 0x6091, 1), _value(od, 0x6091, 2)
    max_torque = _value(od, 0x6072)
    return Units(rated=_value(od, 0x6076) if 0x6076 in od else table.rated,
                 units_per_nm=gen_drives.TORQUE_UNITS[unit],
                 increments=inc if inc is not None else table.encoder, revs=revs or 1,
                 gear=(motor, shaft or 1) if motor is not None else table.gear,
                 max_permille=min(max_torque, 32767) if max_torque is not None else 32767)


def _arm(n: int, torque_limit: float = 0.3) -> dict:
    """n joints whose torque limit every CST drive here gives (the e35's motor: 0.31 N m, 1:1)."""
    return {"joints": [{"name": f"j{i + 1}", "torque_limit": torque_limit} for i in range(n)],
            "buses": [{"name": "can0", "drives": list(range(1, n + 1))}], "loop_rate_hz": 1000.0}


@pytest.fixture()
def udp_port(slot) -> int:  # noqa: ANN001 - conftest's run slot: ports no other test uses meanwhile
    return slot.can_port


# ---- armctl drive check -------------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(CST) + sorted(NO_CST))
def test_drive_check_says_whether_this_controller_can_run_it(name: str) -> None:
    run = [str(REPO / "tools" / "armctl"), "drive", "check", str(DRIVES / name)]
    table = ["--drive-config", str(DRIVES / CST[name])] if name in CST else []
    p = subprocess.run([*run, *table], capture_output=True, text=True, timeout=120)
    lines = p.stdout.splitlines()
    if name in CST:
        assert p.returncode == 0, p.stdout + p.stderr
        assert lines[0].endswith("this controller can run it") and not any("problem:" in ln for ln in lines)
    else:
        assert p.returncode == 2, p.stdout + p.stderr
        assert lines[0].endswith("this controller cannot run it")
        assert any(ln.strip().startswith("problem: 0x6502 (supported drive modes)") and f"({NO_CST[name]})" in ln and
                   "no cyclic synchronous torque (mode 10, bit 9), which this controller needs" in ln for ln in lines)


def test_drive_check_without_the_table_names_what_it_must_give() -> None:
    """The EPOS4's DCF has no 0x608F or 0x6091: without a drive table giving them, two problems."""
    p = subprocess.run([str(REPO / "tools" / "armctl"), "drive", "check", str(DRIVES / "maxon_epos4_50_15.dcf")],
                       capture_output=True, text=True, timeout=120)
    problems = [ln.strip() for ln in p.stdout.splitlines() if ln.strip().startswith("problem:")]
    assert p.returncode == 2 and problems == [
        "problem: 0x608F (encoder increments): not in the file, and the drive table gives no encoder_increments",
        "problem: 0x6091 (gear ratio): not in the file, and the drive table gives no gear"], p.stdout


# ---- our master on LocalNodes of each file ------------------------------------------------------
def _boot(boot_bin: Path, port: int, monkeypatch: pytest.MonkeyPatch, drives: list[FileDrive], args: list[str],
          out: Path, hold: tuple[int, int] | None = None) -> subprocess.CompletedProcess[str]:
    """arm_canopen_boot on the drives; hold = (position increments, torque per-mille) each drive's
    TPDO1/TPDO2 report at every SYNC once operational (50 periods held)."""
    net = loopback_network(monkeypatch, GROUP, port)
    try:
        for d in drives:
            net.add_node(d.node)
        if hold is not None:
            def on_sync(can_id: int, data: bytes, ts: float) -> None:
                for d in drives:
                    if d.node.nmt.state == "OPERATIONAL":
                        net.send_message(0x180 + d.id, struct.pack("<ii", hold[0], 0))
                        net.send_message(0x280 + d.id, struct.pack("<hH", hold[1], d.sw))

            net.subscribe(0x080, on_sync)
        held = ["--hold-periods", "50", "--hold-torque", "0"] if hold is not None else []
        return subprocess.run([str(boot_bin), "--bus", f"udp:{GROUP}:{port}", "--sdo-timeout-ms", "300", *args, *held,
                               "--json", str(out)], capture_output=True, text=True, timeout=120)
    finally:
        for d in drives:
            d.node.nmt.stop_heartbeat()
        net.disconnect()


@pytest.mark.parametrize("name", sorted(CST))
def test_master_boots_the_vendor_drive_and_decodes_its_units(name: str, boot_bin: Path, udp_port: int,
                                                             tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    units = _units(name)
    cfg = gen_drives.load(_arm(2), DRIVES / CST[name])
    drives = [FileDrive(1, DRIVES / name), FileDrive(2, DRIVES / name)]
    revolution = units.increments // units.revs  # one motor revolution, in the drive's increments
    out = tmp_path / "boot.json"
    p = _boot(boot_bin, udp_port, monkeypatch, drives, cfg.boot_args("can0"), out, hold=(revolution, 500))
    assert p.returncode == 0, p.stderr
    result = json.loads(out.read_text())
    d = gen_eds.load(DRIVES / name)
    absent = {f"0x{i:04X}" for i in (0x1006, 0x1016, 0x1017, 0x605A, 0x605E, 0x6502, 0x6076, 0x608F, 0x6091, 0x6072)
              if not d.has(i)}  # 0x605A/0x605E: the quick stop and fault reaction options the boot writes
    for node, drive in zip(result["nodes"], drives):
        got = node["units"]
        assert (got["rated_torque"], got["torque_units_per_nm"], got["encoder_increments"], got["encoder_revs"],
                tuple(got["gear"]), got["max_torque_permille"]) == (units.rated, units.units_per_nm, units.increments,
                                                                    units.revs, units.gear, units.max_permille)
        assert set(node["absent"].split()) == absent
        hold = node["hold"]
        assert hold["tpdo1"] >= 10 and hold["tpdo2"] >= 10
        assert hold["q_rad"] == pytest.approx(TWO_PI * units.gear[1] / units.gear[0], rel=1e-6)  # 2 pi / gear
        # 500 per-mille of the motor's rated torque, times the gear at the joint
        assert hold["tau_nm"] == pytest.approx(0.5 * RATED_NM[name] * units.gear[0] / units.gear[1], rel=1e-6)
        assert got["joint_rated_torque_nm"] == pytest.approx(1000 * units.joint_nm_per_permille(), rel=1e-6)
        written = {(i, s) for i, s, _ in drive.writes}
        assert not written & {(0x6076, 0), (0x608F, 1), (0x608F, 2), (0x6091, 1), (0x6091, 2)}  # read only
        assert not any(i in (0x1006, 0x1016, 0x1017) and not d.has(i) for i, _ in written)  # skipped where absent
        for comm, mapping, entries in ((0x1400, 0x1600, [0x60400010, 0x60710010]),
                                       (0x1800, 0x1A00, [0x60640020, 0x606C0020]),
                                       (0x1801, 0x1A01, [0x60770010, 0x60410010])):
            assert [drive.stored(mapping, k) for k in range(len(entries) + 1)] == [len(entries), *entries]
            assert not drive.stored(comm, 1) & 0x80000000
        assert drive.stored(0x6060) == 10 and drive.sw & 0x6F == 0x27


@pytest.mark.parametrize("name", sorted(NO_CST))
def test_master_refuses_a_drive_without_cst_in_one_line(name: str, boot_bin: Path, udp_port: int, tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    # the PRBT's DCF gives 0x1000 no value: the module reports CiA 402's profile, as a drive must
    stated = _value(canopen.import_od(str(DRIVES / name), 1), 0x1000)
    drive = FileDrive(1, DRIVES / name, device_type=None if stated else 0x00020192)
    modes = drive.stored(0x6502)
    p = _boot(boot_bin, udp_port, monkeypatch, [drive], ["--node", "1,rated=1000,encoder=4096,gear=1/1"],
              tmp_path / "boot.json")
    assert p.returncode == 1
    assert p.stderr.strip().splitlines() == [
        f"arm_canopen_boot: no_cst: node 1: 0x6502:00: no cyclic synchronous torque (mode 10), which this controller "
        f"needs; the drive offers {NO_CST[name]} (0x6502 = 0x{modes:08X})"], p.stderr
    assert drive.writes == []  # refused before anything is written
    # and a drive table naming the file is refused before a boot starts, in one line
    table = tmp_path / "drives.toml"
    table.write_text(f'eds = "{DRIVES / name}"\n[defaults]\nrated_torque_nm = 1.0\nencoder_increments = 4096\n'
                     "gear = [1, 1]\n")
    with pytest.raises(gen_drives.DrivesError, match=rf"0x6502 .*\({NO_CST[name]}\): no cyclic synchronous torque"):
        gen_drives.load(_arm(1), table)


def test_a_drive_table_that_disagrees_with_the_drive_never_runs(boot_bin: Path, udp_port: int, tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """The e35's encoder has 2000 increments a turn; a table that says 2^19 stops the boot, before
    anything is written, with one line naming the node, the object and both values. A DCF's
    configured value that the table contradicts is refused before the boot starts."""
    table = tmp_path / "drives.toml"
    table.write_text(f'eds = "{DRIVES / "python_canopen_e35.eds"}"\naccept_no_master_watchdog = true\n[defaults]\n'
                     'encoder_increments = 524288\n')
    args = gen_drives.load(_arm(1), table).boot_args("can0")
    drive = FileDrive(1, DRIVES / "python_canopen_e35.eds")
    p = _boot(boot_bin, udp_port, monkeypatch, [drive], args, tmp_path / "boot.json")
    assert p.returncode == 1
    assert p.stderr.strip().splitlines() == [
        "arm_canopen_boot: units_mismatch: node 1: 0x608F encoder increments per motor revolutions: the drive has "
        "2000/1, the drive table says 524288/1 (encoder_increments)"], p.stderr
    assert drive.writes == []
    fault = json.loads((tmp_path / "boot.json").read_text())["fault"]
    assert (fault["code"], fault["node"], fault["index"], fault["value"]) == ("units_mismatch", 1, 0x608F, 2000)
    table.write_text(f'eds = "{DRIVES / "maxon_epos4_50_15.dcf"}"\n[defaults]\nencoder_increments = 3200\n'
                     "gear = [26, 1]\nrated_torque_nm = 0.6\n")
    with pytest.raises(gen_drives.DrivesError, match=r"0x6076 \(motor rated torque\): the DCF configures 512871, the "
                                                     r"drive table says 600: the boot would stop"):
        gen_drives.load(_arm(1), table)


def test_the_epos4_decodes_100_permille_as_1_33_nm_at_the_joint(boot_bin: Path, udp_port: int, tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """maxon's EPOS4 of the DCF (0x6076 = 512871 µN m, the EC 90 flat's; a GP 52 C 26:1 gearhead)
    with its drive table (encoder, gear, µN m), on a python-canopen drive built from the DCF: 100
    per-mille reported is 0.0513 N m at the motor and 1.33 N m at the joint, and 1.33 N m asked
    for at the joint goes out as 100 per-mille."""
    name = "maxon_epos4_50_15.dcf"
    cfg = gen_drives.load(_arm(1), DRIVES / CST[name])
    assert cfg.drives[0].joint_rated_torque_nm == pytest.approx(0.512871 * 26)
    drive = FileDrive(1, DRIVES / name)
    rpdo1: list[bytes] = []
    net = loopback_network(monkeypatch, GROUP, udp_port)
    out = tmp_path / "boot.json"
    try:
        net.add_node(drive.node)
        net.subscribe(0x201, lambda can_id, data, ts: rpdo1.append(bytes(data)))

        def on_sync(can_id: int, data: bytes, ts: float) -> None:
            if drive.node.nmt.state == "OPERATIONAL":
                net.send_message(0x181, struct.pack("<ii", 0, 0))
                net.send_message(0x281, struct.pack("<hH", 100, drive.sw))

        net.subscribe(0x080, on_sync)
        p = subprocess.run([str(boot_bin), "--bus", f"udp:{GROUP}:{udp_port}", "--sdo-timeout-ms", "300",
                            *cfg.boot_args("can0"), "--hold-periods", "30", "--hold-torque", "1.3334646",
                            "--json", str(out)], capture_output=True, text=True, timeout=120)
    finally:
        drive.node.nmt.stop_heartbeat()
        net.disconnect()
    assert p.returncode == 0, p.stderr
    node = json.loads(out.read_text())["nodes"][0]
    assert (node["units"]["rated_torque"], node["units"]["torque_units_per_nm"], node["units"]["gear"]) == \
        (512871, 1000000, [26, 1])
    assert node["hold"]["tau_nm"] == pytest.approx(1.3334646, rel=1e-6)  # 100 per-mille at the joint: 1.33 N m
    assert round(node["hold"]["tau_nm"], 2) == 1.33
    assert node["hold"]["target_permille"] == 100 and rpdo1 and all(struct.unpack("<Hh", r)[1] == 100 for r in rpdo1)
    assert "1000 per-mille is 13.3346 N m at the joint" in p.stdout, p.stdout


def test_a_joint_torque_limit_the_drive_cannot_give_is_refused(build_dir: Path, udp_port: int, tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """python-canopen's e35 servo: 1000 per-mille (0x6072) of its 310 mN m motor, 1:1, is 0.31 N m at
    the joint, far below the bundled arm's 150 N m: refused in one line naming the joint, the node and
    the numbers, by the drive table (before a boot) and by the controller's boot (before anything is
    written)."""
    ctl = build_dir / "firmware" / "arm_controller"
    if not ctl.exists():
        pytest.skip(f"{ctl} not built")
    name = "python_canopen_e35.eds"
    arm = json.loads((build_dir / "generated" / "arm" / "arm.json").read_text())
    first = arm["joints"][0]["name"]
    with pytest.raises(gen_drives.DrivesError) as exc:
        gen_drives.load(arm, DRIVES / CST[name])
    assert str(exc.value).endswith(
        f"joint {first} (node 1): its torque limit {arm['joints'][0]['torque_limit']:g} N m is more than its drive "
        "gives at the joint, 0.31 N m = 0x6072 1000 per-mille x 0x6076 310 mN m (the motor's) x gear 1/1 x "
        "efficiency 1"), exc.value
    drives = {i: FileDrive(i, DRIVES / name) for i in range(1, 7)}
    nodes = [a for i in range(1, 7) for a in ("--node", f"{i},{gen_drives.drive_check.ACCEPT_NO_WATCHDOG}=true")]
    p, s = controller_on_localnodes(ctl, GROUP, udp_port, tmp_path, monkeypatch, drives, duration="0.2", args=nodes)
    assert p.returncode == 3, p.stderr
    assert s["reason"] == (
        "boot: canopen: torque_limit: joint 1: node 1: the joint's torque limit 150 N m is more than the drive gives "
        "at the joint, 0.31 N m = 0x6072 1000 per-mille x 0x6076 310 mN m x gear 1/1 x efficiency 1"), s["reason"]
    assert not any(i in (0x1400, 0x1600, 0x6060, 0x6040) for i, _, _ in drives[1].writes)  # refused untouched
    assert all(d.sw & 0x6F != 0x27 for d in drives.values())


# the e35's 0.31 N m cannot give the bundled arm's torque limits: refused (the test above)
@pytest.mark.parametrize("name", ["maxon_epos4_50_15.dcf"])
def test_controller_runs_on_the_vendor_drives(name: str, build_dir: Path, udp_port: int, tmp_path: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """arm_controller --protocol canopen on six LocalNodes of the file, with the drive table's
    --node: each joint's units are its drive's, and a quarter motor revolution decodes as
    pi / 2 / gear (a whole one may be outside a joint's range, which the controller stops on)."""
    ctl = build_dir / "firmware" / "arm_controller"
    if not ctl.exists():
        pytest.skip(f"{ctl} not built")
    arm = json.loads((build_dir / "generated" / "arm" / "arm.json").read_text())
    units = _units(name)
    cfg = gen_drives.load(arm, DRIVES / CST[name])
    nodes = [a for d in sorted(cfg.drives, key=lambda d: d.drive) for a in ("--node", d.node_spec())]
    drives = {i: FileDrive(i, DRIVES / name) for i in range(1, 7)}
    quarter = units.increments // units.revs // 4
    assert quarter * 4 * units.revs == units.increments
    # the torque check is left out: these LocalNodes do not move
    p, s = controller_on_localnodes(ctl, GROUP, udp_port, tmp_path, monkeypatch, drives, duration="0.2",
                                    args=[*nodes, "--checks", "range,velocity,step,following"],
                                    positions={i: quarter for i in drives})
    assert s["canopen"]["fault"]["code"] == "none", s["reason"]
    assert p.returncode == 0 and s["final_state"] == "running", s["reason"]
    for u in s["canopen"]["units"]:
        assert (u["rated_torque"], u["torque_units_per_nm"], u["encoder_increments"], tuple(u["gear"])) == \
            (units.rated, units.units_per_nm, units.increments, units.gear)
    assert s["canopen"]["q_first_rad"] == pytest.approx([TWO_PI / 4 * units.gear[1] / units.gear[0]] * 6, rel=1e-6)
    assert all(d.sw & 0x6F == 0x27 and d.stored(0x6060) == 10 for d in drives.values())


# ---- our emulated drive, built from each file, booted by python-canopen ----------------------------
def _until(what: str, cond: Callable[[], bool], timeout: float = 10.0) -> None:
    end = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < end, f"timed out waiting for {what}"
        time.sleep(0.02)


def _emulate(name: str, sim: Path, port: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, node_args: list[str],
             master: Callable[[BaseNode402, canopen.Network], None]) -> tuple[int, str]:
    """arm_sim's six drives built from the file (--od), python-canopen's BaseNode402 on drive 2 as the
    master (master(node, network)); the simulator's exit code and stderr once every node is stopped."""
    table = tmp_path / "od.txt"
    assert gen_eds.main(["--eds", str(DRIVES / name), "--table", str(table)]) == 0
    net = loopback_network(monkeypatch, GROUP, port)
    node = BaseNode402(2, str(DRIVES / name))
    node.TIMEOUT_SWITCH_STATE_FINAL, node.TIMEOUT_SWITCH_STATE_SINGLE, node.TIMEOUT_CHECK_TPDO = 5.0, 2.0, 1.0
    net.add_node(node)
    bootups: list[float] = []
    net.subscribe(0x702, lambda _id, data, ts: bootups.append(ts) if data[:1] == b"\x00" else None)
    proc = subprocess.Popen([str(sim), "--protocol", "canopen", "--bus", f"udp:{GROUP}:{port}", "--lcm-url", "",
                             "--boot-timeout", "20", "--idle-timeout", "5", "--od", str(table), *node_args],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        _until("the emulated drives' boot-up", lambda: bool(bootups) or proc.poll() is not None, timeout=20.0)
        assert proc.poll() is None, proc.communicate()[1]
        master(node, net)
    finally:
        net.sync.stop()
        err = stop_nodes_and_wait(net, proc)
    return proc.returncode, err


def _sim_bin(build_dir: Path) -> Path:
    sim = build_dir / "host_sim" / "native" / "arm_sim"
    if not sim.exists():
        pytest.skip(f"{sim} not built")
    return sim


def _map(node: BaseNode402, pdos: dict[str, list[int]]) -> None:
    """These PDOs (rpdo1, tpdo1, ...) on CiA 301's predefined COB-IDs, on every SYNC; every other PDO
    of the file disabled (a DCF's are configured for its own node id, python-canopen keeps them)."""
    node.tpdo.read()
    node.rpdo.read()
    for kind, maps, base in (("rpdo", node.rpdo.map, 0x200), ("tpdo", node.tpdo.map, 0x180)):
        for k, pdo in maps.items():
            indices = pdos.get(f"{kind}{k}")
            pdo.clear()
            pdo.enabled = indices is not None
            if indices is not None:
                for index in indices:
                    pdo.add_variable(index)
                pdo.cob_id = base + 0x100 * (k - 1) + node.id
                pdo.trans_type = 1
            pdo.save()


@pytest.mark.parametrize("name", sorted(CST))
def test_python_canopen_boots_our_emulated_drive_of_the_file(name: str, build_dir: Path, udp_port: int, tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """BaseNode402 maps the PDOs, sets CST, enables the drive; its TPDO1 reports the arm's home pose
    in the file's units (within an increment) and its TPDO2 the torque commanded in per-mille."""
    sim = _sim_bin(build_dir)
    arm = json.loads((build_dir / "generated" / "arm" / "arm.json").read_text())
    units = _units(name)
    # the table's --node specs (units); the arm's torque limits within what the drive gives (the e35's
    # cannot give the bundled arm's: the controller would refuse it, the emulated drive need not)
    most = units.max_permille * units.joint_nm_per_permille()
    cfg = gen_drives.load({**arm, "joints": [{**j, "torque_limit": min(j["torque_limit"], most)}
                                              for j in arm["joints"]]}, DRIVES / CST[name])
    d = gen_eds.load(DRIVES / name)
    home = arm["joints"][1]["home"]
    seen: dict[str, object] = {}

    def master(node: BaseNode402, net: canopen.Network) -> None:
        node.nmt.state = "PRE-OPERATIONAL"
        assert node.sdo[0x1000].raw & 0xFFFF == 0x0192
        for index, sub, want in ((0x6076, None, units.rated), (0x608F, 1, units.increments),
                                 (0x6091, 1, units.gear[0])):
            if d.has(index):  # the file's object, as the file says
                assert (node.sdo[index] if sub is None else node.sdo[index][sub]).raw == want
            else:  # an object the file lacks, the emulated drive lacks too
                with pytest.raises(SdoAbortedError) as exc:
                    node.sdo.upload(index, sub or 0)
                assert exc.value.code == 0x06020000
        _map(node, {"rpdo1": [0x6040, 0x6071], "tpdo1": [0x6064, 0x606C], "tpdo2": [0x6077, 0x6041]})
        node.sdo[0x6060].raw = 10
        assert node.sdo[0x6061].raw == 10
        node.setup_402_state_machine(read_pdos=False)
        first: list[int] = []  # the first TPDO1: the pose at the first SYNC, before the arm sags
        net.subscribe(0x182, lambda _id, data, ts: first.append(struct.unpack_from("<i", data)[0]) if not first else None)
        node.nmt.state = "OPERATIONAL"
        net.sync.start(0.01)
        node.rpdo[1][0x6071].raw = 100  # per-mille of the rated torque
        node.rpdo[1].start(0.01)
        node.state = "OPERATION ENABLED"
        _until("the first TPDO1", lambda: bool(first))
        seen["position"] = first[0]
        _until("the torque commanded", lambda: node.tpdo[2][0x6077].raw == 100)
        seen["statusword"] = node.statusword
        node.rpdo[1].stop()

    node_args = [a for dr in sorted(cfg.drives, key=lambda x: x.drive) for a in ("--node", dr.node_spec())]
    rc, err = _emulate(name, sim, udp_port, tmp_path, monkeypatch, node_args, master)
    assert rc == 0, err
    assert seen["statusword"] & 0x6F == 0x27
    increments_per_rad = 1 / units.rad_per_increment()
    assert abs(seen["position"] - home * increments_per_rad) <= 1.0 + abs(home) * 1e-6 * increments_per_rad


@pytest.mark.parametrize("name", sorted(NO_CST))
def test_python_canopen_boots_our_emulated_drive_without_cst(name: str, build_dir: Path, udp_port: int,
                                                            tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The emulated drive of a file without CST refuses mode 10 as that drive would, takes a mode it
    offers, and comes to operation enabled under BaseNode402 (it moves only in CST: no torque here)."""
    sim = _sim_bin(build_dir)
    seen: dict[str, int] = {}
    mode_of = {"pp": 1, "vl": 2, "pv": 3, "hm": 6, "ip": 7, "csp": 8}

    def master(node: BaseNode402, net: canopen.Network) -> None:
        node.nmt.state = "PRE-OPERATIONAL"
        with pytest.raises(SdoAbortedError) as exc:
            node.sdo[0x6060].raw = 10
        seen["abort"] = exc.value.code
        mode = mode_of[NO_CST[name].split(", ")[0]]
        node.sdo[0x6060].raw = mode
        seen["display"] = node.sdo[0x6061].raw
        _map(node, {"tpdo1": [0x6041]})  # the controlword by SDO, the statusword by TPDO
        node.setup_402_state_machine(read_pdos=False)
        node.nmt.state = "OPERATIONAL"
        net.sync.start(0.01)
        node.state = "OPERATION ENABLED"
        seen["statusword"] = node.statusword

    rc, err = _emulate(name, sim, udp_port, tmp_path, monkeypatch,
                       ["--rated-torque-mnm", "1000", "--encoder-increments", "4096", "--od-gear-ratio", "1:1"], master)
    assert rc == 0, err
    assert seen["abort"] == 0x06090030 and seen["display"] == mode_of[NO_CST[name].split(", ")[0]]
    assert seen["statusword"] & 0x6F == 0x27


# ---- vendors' files as they are ---------------------------------------------------------------------
# Mistakes seen in vendors' files, made here in copies (tmp): the originals in tests/drives stay as
# their vendors wrote them.
MAXON = "maxon_epos4_50_15.dcf"
# an UNSIGNED16 manufacturer object (0x2005, RS232 frame timeout) whose HighLimit its type cannot hold
MAXON_2005 = (b"[2005]\r\nParameterName=RS232 frame timeout\r\nObjectType=0x7\r\nDataType=0x6\r\nAccessType=rw\r\n"
              b"DefaultValue=500\r\nLowLimit=50\r\nHighLimit=65535\r\n")
# 0x1016:01 with HighLimit 65535: no room for the node id CiA 301 puts in bits 16-23
MAXON_1016 = (b"[1016sub1]\r\nParameterName=Consumer 1 heartbeat time\r\nObjectType=0x7\r\nDataType=0x7\r\n"
              b"AccessType=rw\r\nDefaultValue=0\r\n")
VENDOR_MISTAKES = [(MAXON_2005, MAXON_2005.replace(b"HighLimit=65535", b"HighLimit=65536")),
                   (MAXON_1016, MAXON_1016 + b"HighLimit=65535\r\n")]


def _copy_with(tmp_path: Path, name: str, edits: list[tuple[bytes, bytes]]) -> Path:
    """A copy of a vendor's file, in tmp, with these edits (each made exactly once)."""
    raw = (DRIVES / name).read_bytes()
    for old, new in edits:
        assert raw.count(old) == 1, old
        raw = raw.replace(old, new)
    out = tmp_path / name
    out.write_bytes(raw)
    return out


def _line_of(path: Path, section: str, key: str) -> int:
    """The 1-based line of key in [section]."""
    lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    start = lines.index(f"[{section}]")
    return next(k for k in range(start, len(lines)) if lines[k].startswith(f"{key}=")) + 1


def _table_for(tmp_path: Path, eds: Path, extra: str = "") -> Path:
    """The EPOS4's drive table (tests/drives) naming another file."""
    table = tmp_path / "drives.toml"
    text = (DRIVES / CST[MAXON]).read_text().replace(f'eds = "{MAXON}"', f'eds = "{eds}"\n{extra}')
    table.write_text(text)
    return table


def test_a_vendor_file_s_harmless_mistakes_are_warnings_naming_the_line(boot_bin: Path, udp_port: int,
                                                                         tmp_path: Path,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """HighLimit=65536 on an UNSIGNED16 the master never uses, and a 0x1016:01 HighLimit of 65535
    that contradicts CiA 301's consumer heartbeat: each a warning naming the file's line (the limit
    ignored), not a refusal. The drive itself, as CiA 301 defines 0x1016 (python-canopen's drive of
    the vendor's own file), boots with its watchdog on the master set and its units right."""
    original = (DRIVES / MAXON).read_bytes()
    copy = _copy_with(tmp_path, MAXON, VENDOR_MISTAKES)
    warnings = [
        f"{copy}:{_line_of(copy, '1016sub1', 'HighLimit')}: [1016sub1] HighLimit=65535: below 0x7FFFFF, which CiA "
        "301's definition of 0x1016 needs (the consumer heartbeat's node id is in bits 16-23 and its time in ms in "
        "bits 0-15): the limit is ignored",
        f"{copy}:{_line_of(copy, '2005', 'HighLimit')}: [2005] HighLimit=65536: out of range for UNSIGNED16 "
        "(0..65535): the limit is ignored"]
    table = _table_for(tmp_path, copy)
    p = subprocess.run([str(REPO / "tools" / "armctl"), "drive", "check", str(copy), "--drive-config", str(table)],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stdout + p.stderr
    assert p.stdout.splitlines()[0].endswith("this controller can run it")
    assert [ln.strip() for ln in p.stdout.splitlines() if "warning:" in ln] == [f"warning: {w}" for w in warnings]
    table_out = tmp_path / "od.txt"
    g = subprocess.run([str(REPO / ".venv" / "bin" / "python"), "-m", "gen.eds", "--eds", str(copy), "--table",
                        str(table_out)], capture_output=True, text=True, cwd=REPO)
    assert g.returncode == 0 and g.stderr.splitlines() == [f"gen.eds: warning: {w}" for w in warnings], g.stderr
    cfg = gen_drives.load(_arm(1), table)
    assert [n for n in cfg.drives[0].notes if n.startswith("warning:")] == [f"warning: {w}" for w in warnings]
    drive = FileDrive(1, DRIVES / MAXON)
    p = _boot(boot_bin, udp_port, monkeypatch, [drive], cfg.boot_args("can0"), tmp_path / "boot.json",
              hold=(3200, 100))
    assert p.returncode == 0, p.stderr
    assert drive.stored(0x1016, 1) == 127 << 16 | 300  # the watchdog on the master, set
    hold = json.loads((tmp_path / "boot.json").read_text())["nodes"][0]["hold"]
    assert hold["tau_nm"] == pytest.approx(0.1 * 0.512871 * 26, rel=1e-6)
    assert (DRIVES / MAXON).read_bytes() == original


def test_a_drive_whose_master_watchdog_cannot_be_set_is_refused_unless_accepted(
        boot_bin: Path, udp_port: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A drive that keeps its file's 0x1016:01 HighLimit of 65535 refuses the master's consumer
    heartbeat; python-canopen's e35 has no 0x1016 at all. Either would go on with its last torque if
    the master died: refused in one line saying so, before it is enabled; booted when the drive table
    accepts it (accept_no_master_watchdog = true)."""
    copy = _copy_with(tmp_path, MAXON, VENDOR_MISTAKES)
    cfg = gen_drives.load(_arm(1), _table_for(tmp_path, copy))
    drive = FileDrive(1, copy)  # keeps the file's limit, as its firmware might
    p = _boot(boot_bin, udp_port, monkeypatch, [drive], cfg.boot_args("can0"), tmp_path / "boot.json")
    assert p.returncode == 1
    assert p.stderr.strip().splitlines() == [
        "arm_canopen_boot: no_master_watchdog: node 1: 0x1016:01 (consumer heartbeat, the drive's watchdog on the "
        "master): the drive refused the master's 0x007F012C (SDO abort 0x06090030); a dead master would leave this "
        "drive applying its last torque; refused (a drive table that accepts this says accept_no_master_watchdog = "
        "true)"], p.stderr
    assert drive.sw & 0x6F != 0x27 and (0x6060, 0) not in {(i, s) for i, s, _ in drive.writes}
    accepted = gen_drives.load(_arm(1), _table_for(tmp_path, copy, "accept_no_master_watchdog = true"))
    drive = FileDrive(1, copy)
    p = _boot(boot_bin, udp_port + 1, monkeypatch, [drive], accepted.boot_args("can0"), tmp_path / "boot.json")
    assert p.returncode == 0, p.stderr
    assert "0x1016" in json.loads((tmp_path / "boot.json").read_text())["nodes"][0]["absent"]
    # no 0x1016 at all: the drive table refuses it before a boot, unless it accepts it; so does the boot
    e35 = tmp_path / "e35.toml"
    e35.write_text(f'eds = "{DRIVES / "python_canopen_e35.eds"}"\n')
    with pytest.raises(gen_drives.DrivesError, match=r"0x1016:01 \(consumer heartbeat, the drive's watchdog on the "
                                                     r"master\): not in the file; a dead master would leave this drive "
                                                     r"applying its last torque; a drive table that accepts this says "
                                                     r"accept_no_master_watchdog = true"):
        gen_drives.load(_arm(1), e35)
    drive = FileDrive(1, DRIVES / "python_canopen_e35.eds")
    p = _boot(boot_bin, udp_port + 2, monkeypatch, [drive], ["--node", "1"], tmp_path / "boot.json")
    assert p.returncode == 1 and p.stderr.strip().splitlines() == [
        "arm_canopen_boot: no_master_watchdog: node 1: 0x1016:01 (consumer heartbeat, the drive's watchdog on the "
        "master): the drive has no such object (SDO abort 0x06020000); a dead master would leave this drive applying "
        "its last torque; refused (a drive table that accepts this says accept_no_master_watchdog = true)"], p.stderr


def test_a_mistake_in_an_object_the_master_uses_is_still_refused(tmp_path: Path) -> None:
    """0x6072 (max torque) of an unknown data type: the master reads it, so the file is refused, in
    one line naming the section and the key; the same mistake in an object no one uses is a warning."""
    name = "python_canopen_e35.eds"
    max_torque = b"[6072]\nParameterName=Max torque\nObjectType=0x7\nDataType=0x0006\n"
    bad = _copy_with(tmp_path, name, [(max_torque, max_torque.replace(b"0x0006", b"0x0066"))])
    p = subprocess.run([str(REPO / "tools" / "armctl"), "drive", "check", str(bad)], capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1, p.stdout + p.stderr
    assert "[6072] DataType=0x0066: not a CiA 301 basic data type" in p.stderr, p.stderr
    (tmp_path / "unused").mkdir()
    uart = b"[2000sub1]\nParameterName=Node ID\nObjectType=0x7\nDataType=0x0005\n"
    unused = _copy_with(tmp_path / "unused", name, [(uart, uart.replace(b"0x0005", b"0x0066"))])
    d = gen_eds.load(unused)
    assert not d.has(0x2000) and d.warnings == [
        f"{unused}:{_line_of(unused, '2000sub1', 'DataType')}: [2000sub1] DataType=0x0066: not a CiA 301 basic data "
        "type (0x0001-0x001B; 0x000E and 0x0017 are reserved): 0x2000 (Uart configuration) is left out: the master "
        "never uses it"]
