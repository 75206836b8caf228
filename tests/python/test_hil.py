"""End-to-end HIL: the C controller and the MuJoCo simulator as two processes on a CAN bus."""

from __future__ import annotations

import json
import signal
import re
import time
from pathlib import Path

import numpy as np
import pytest

from hil_procs import BusRecorder, start_controller, start_sim, wait_exit
from host_sim.canbus import open_bus, udp_socket
from tools.run.hil import HilOptions, run_hil
from tools.run.telemetry_log import read_log

# armctl test runs these alone (no other test beside them): a killed peer is noticed within a wall-clock bound
pytestmark = pytest.mark.serial

CMD_IDS = set(range(0x201, 0x207))


@pytest.fixture(scope="module")
def short_run(tmp_path_factory: pytest.TempPathFactory, controller_bin: Path) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("hil")
    run = run_hil(HilOptions(out=out, duration_s=1.0, preset=controller_bin.parent.parent.name))
    return out, run


def test_short_lockstep_run_tracks_within_a_degree(short_run: tuple[Path, dict]) -> None:
    _, run = short_run
    r = run["results"]
    assert r["result"] == "ok", run
    assert r["steps"] == round((r["duration_s"] + r["ref_hold_s"]) * 1000)  # hold, then the trajectory
    assert r["final_state"] == "running"
    assert len(r["tracking_max_abs_deg"]) == 6
    assert max(r["tracking_max_abs_deg"]) < 1.0


def test_every_period_is_accounted_for(short_run: tuple[Path, dict]) -> None:
    out, run = short_run
    ctl = json.loads((out / "controller_summary.json").read_text())
    sim = json.loads((out / "sim_summary.json").read_text())
    # One state per drive per SYNC, including the few enabling periods before tracking starts.
    assert ctl["frames"]["rx_state"] == 6 * sim["periods"]
    assert sim["periods"] >= ctl["steps_done"]
    assert sim["commands_missed"] == 0 and sim["commands_missed_per_drive"] == [0] * 6
    assert ctl["frames"]["rx_unknown_id"] == 0 and ctl["frames"]["rx_wrong_counter"] == 0
    assert ctl["frames"]["rx_wrong_bus"] == 0 and sim["rx_wrong_bus"] == 0


def test_default_run_uses_three_classic_buses(short_run: tuple[Path, dict]) -> None:
    # CiA 402 on classic CAN: can0 carries drives 1-2, can1 3-4, can2 5-6 (one UDP port each)
    out, run = short_run
    assert run["environment"]["protocol"] == "canopen"
    topo = run["environment"]["topology"]
    assert [b["drives"] for b in topo["buses"]] == [[1, 2], [3, 4], [5, 6]]
    assert [b["name"] for b in topo["buses"]] == ["can0", "can1", "can2"]
    specs = [b["spec"] for b in topo["buses"]]
    ports = [int(s.rpartition(":")[2]) for s in specs]
    assert specs[0].startswith("udp:239.74.163.2:") and ports == [ports[0], ports[0] + 1, ports[0] + 2]
    assert run["environment"]["bus"] == f"{specs[0]}@1,2 {specs[1]}@3,4 {specs[2]}@5,6"
    ctl = json.loads((out / "controller_summary.json").read_text())
    sim = json.loads((out / "sim_summary.json").read_text())
    # SYNC goes on every bus, each RPDO on its drive's bus: per period the controller sends
    # 3 SYNC + 6 RPDO1 (and the boot's SDO requests before).
    assert ctl["frames"]["tx"] >= 9 * sim["periods"]


def test_the_arm_protocol_runs_on_the_two_fd_buses(tmp_path: Path, controller_bin: Path) -> None:
    # firmware/protocol/buses.toml: can0 carries drives 1-3, can1 drives 4-6
    run = run_hil(HilOptions(out=tmp_path, duration_s=0.3, preset=controller_bin.parent.parent.name, protocol="arm"))
    assert run["results"]["result"] == "ok", run["results"]["verdict_reasons"]
    topo = run["environment"]["topology"]
    assert [b["drives"] for b in topo["buses"]] == [[1, 2, 3], [4, 5, 6]]
    assert [b["kind"] for b in topo["buses"]] == ["CAN FD 1 Mbit/s arbitration / 5 Mbit/s data"] * 2
    ctl = json.loads((tmp_path / "controller_summary.json").read_text())
    sim = json.loads((tmp_path / "sim_summary.json").read_text())
    # per period 2 SYNC + 6 CMD (plus the two NMT frames per bus)
    assert ctl["frames"]["tx"] >= 8 * sim["periods"]


def test_telemetry_log_is_complete_and_recomputes_the_table(short_run: tuple[Path, dict]) -> None:
    out, run = short_run
    for channel, acct in run["transport"]["telemetry"].items():
        assert acct["sequence_gaps"] == 0, channel
        assert acct["lost"] == 0, channel
    log = read_log(out / "telemetry.lcmlog")
    hold = run["results"]["ref_hold_s"]
    ctl = [m for m in log["ARM_CTL"].messages if m.state == 1 and m.t >= hold - 1e-9]  # the trajectory
    e = np.array([m.e for m in ctl])
    q_err = np.array([np.subtract(m.q_d, m.q) for m in ctl])
    assert np.allclose(e, q_err, atol=1e-6)  # e is q_d - q, as published
    assert np.allclose(np.degrees(np.abs(e).max(axis=0)), run["results"]["tracking_max_abs_deg"])
    # one truth per simulated period, then the arm simulated on after the stop (flagged so)
    after = (np.asarray(log["ARM_SIM"].messages.flags) & (1 << 16)) != 0
    assert int((~after).sum()) == run["results"]["simulated_periods"]
    assert int(after.sum()) == round(run["results"]["stop"]["window_s"] * run["results"]["rate_hz"])
    assert not after[:int((~after).sum())].any()  # the run's own periods first


def _kill_one_side(controller_bin: Path, bus_spec: str, kill: str, *sim_args: str,
                   summary: Path | None = None) -> tuple[int, float, str, list]:
    """Simulator and controller on a recorded bus; once both run, `kill` ("simulator" or
    "controller") is killed: the other's exit code, seconds to exit and stderr, and every frame."""
    rec = BusRecorder(bus_spec)
    sim = start_sim(bus_spec, *sim_args, summary=summary)
    ctl = start_controller(controller_bin, bus_spec, "--duration", "600")
    victim, survivor = (sim, ctl) if kill == "simulator" else (ctl, sim)
    try:
        time.sleep(3.0)  # booted and running
        assert ctl.poll() is None and sim.poll() is None
        victim.kill()
        code, seconds, err = wait_exit(survivor, timeout=10)
    finally:
        for p in (sim, ctl):
            if p.poll() is None:
                p.kill()
        frames = rec.close()
    return code, seconds, err, frames


def test_controller_safe_stops_when_the_simulator_dies(controller_bin: Path, bus_spec: str) -> None:
    code, seconds, err, frames = _kill_one_side(controller_bin, bus_spec, "simulator")
    assert code == 4, err
    # Killed mid-period, the simulator may have sent some drives' states already: the message names
    # exactly the ones missing.
    assert re.search(r"no joint state from drive\(s\) [1-6](,[1-6])* within", err) and "zero torque" in err
    assert seconds < 4.0  # lockstep timeout 1 s by default, plus process start-up margin
    last_cmds = [f for f in frames if f.arbitration_id in CMD_IDS][-6:]
    assert sorted(f.arbitration_id for f in last_cmds) == sorted(CMD_IDS)
    for f in last_cmds:
        controlword = int.from_bytes(f.data[0:2], "little")
        torque_raw = int.from_bytes(f.data[2:6], "little", signed=True)
        assert torque_raw == 0 and controlword == 0x0006  # zero torque, power stage off


def test_simulator_faults_the_drives_when_the_controller_dies(controller_bin: Path, bus_spec: str,
                                                              tmp_path: Path) -> None:
    code, seconds, err, frames = _kill_one_side(controller_bin, bus_spec, "controller", "--idle-timeout", "0.5",
                                                summary=tmp_path / "sim.json")
    assert code == 3, err
    assert "controller silent" in err
    emcy = {f.arbitration_id for f in frames if 0x81 <= f.arbitration_id <= 0x86}
    assert emcy == set(range(0x81, 0x87))
    summary = json.loads((tmp_path / "sim.json").read_text())
    assert summary["drive_faults"] == [1, 2, 3, 4, 5, 6]


def test_controller_boot_names_the_missing_drives(controller_bin: Path, bus_spec: str) -> None:
    ctl = start_controller(controller_bin, bus_spec, "--boot-timeout", "0.3")
    code, _, err = wait_exit(ctl, timeout=10)
    assert code == 3
    assert "drive(s) 1,2,3,4,5,6 not operational" in err


def test_controller_refuses_a_simulator_running_another_arm(controller_bin: Path, bus_spec: str,
                                                            tmp_path: Path) -> None:
    """The model hash exchanged at boot (SIM_IDENTITY): the same arm with one byte changed in
    its file is another arm as far as the run's evidence goes."""
    prepared = controller_bin.parent.parent / "generated" / "arm" / "arm.xml"
    other = tmp_path / "arm.xml"
    other.write_text(prepared.read_text() + "<!-- edited -->\n")
    sim = start_sim(bus_spec, "--model", str(other), "--boot-timeout", "10")
    ctl = start_controller(controller_bin, bus_spec, "--boot-timeout", "5")
    code, _, err = wait_exit(ctl, timeout=30)
    wait_exit(sim, timeout=30)
    assert code == 3, err
    assert "the simulator runs another arm" in err and "6 joints" in err


@pytest.mark.parametrize(("args", "named"), [
    (["--duration", "-1"], "--duration"),
    (["--duration", "abc"], "--duration"),
    (["--method", "magic"], "--method"),
    (["--mode", "fast"], "--mode"),
    (["--bus", "can9"], "--bus"),
    (["--bus", "udp:239.74.163.2:44001@1-4", "--bus", "udp:239.74.163.2:44002@4-6"],
     "--bus: drive 4 is on two buses"),
    (["--bus", "udp:239.74.163.2:44001@1-3"], "--bus: drive(s) 4,5,6 on no bus"),
    (["--bus", "udp:239.74.163.2:44001@1-3", "--bus", "udp:239.74.163.2:44001@4-6"], "--bus: bus"),
    (["--bus", "udp@1-7"], "--bus: 'udp@1-7': drives '1-7'"),
    (["--lcm-url", "udpm://239.255.76.67:7667?ttl=1"], "ttl must be exactly 0"),
    (["--kp"], "--kp: missing value"),
    (["--frobnicate", "1"], "--frobnicate"),
    (["stray"], "stray"),
])
def test_controller_refuses_bad_arguments(controller_bin: Path, args: list[str], named: str) -> None:
    import subprocess

    r = subprocess.run([str(controller_bin), *args], capture_output=True, text=True, timeout=10)
    assert r.returncode == 2
    assert named in r.stderr


def _igmp_groups() -> dict[str, set[str]]:
    groups: dict[str, set[str]] = {}
    dev = ""
    for line in open("/proc/net/igmp").read().splitlines()[1:]:
        if not line.startswith("\t"):
            dev = line.split()[1]
            groups.setdefault(dev, set())
        else:
            groups[dev].add(line.split()[0])
    return groups


def _hex_group(addr: str) -> str:
    return "".join(f"{int(b):02X}" for b in reversed(addr.split(".")))


def test_multicast_stays_on_loopback(controller_bin: Path, bus_spec: str) -> None:
    bus = open_bus(bus_spec)
    try:
        s = udp_socket(bus)
        import socket

        assert s.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL) == 0
        assert socket.inet_ntoa(s.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, 4)) == "127.0.0.1"
        can_group = _hex_group(bus_spec.split(":")[1])
        for dev, groups in _igmp_groups().items():
            if dev != "lo":
                assert can_group not in groups, f"CAN group joined on {dev}"
        assert can_group in _igmp_groups()["lo"]
    finally:
        bus.shutdown()


def test_telemetry_group_is_routed_to_loopback() -> None:
    import subprocess

    r = subprocess.run(["ip", "route", "get", "239.255.76.67"], capture_output=True, text=True)
    assert " dev lo " in f" {r.stdout} "


@pytest.mark.parametrize(("args", "named"), [
    (["--bus", "udp:239.74.163.2:44001@1-4", "--bus", "udp:239.74.163.2:44002@4-6"],
     "--bus: drive 4 is on two buses"),
    (["--bus", "udp:239.74.163.2:44001@1-3"], "--bus: drive(s) 4,5,6 on no bus"),
])
def test_simulator_refuses_bad_bus_mappings(args: list[str], named: str) -> None:
    import subprocess
    import sys

    from gen.lib.paths import REPO, env_with_repo

    r = subprocess.run([sys.executable, "-m", "host_sim", *args, "--lcm-url", ""], capture_output=True, text=True,
                       timeout=60, cwd=REPO, env=env_with_repo())
    assert r.returncode == 2
    assert named in r.stderr


def test_a_drive_frame_on_the_wrong_bus_is_counted_and_ignored(controller_bin: Path, bus_spec: str,
                                                               tmp_path: Path) -> None:
    """Drive 1 is on bus 0; its STATE and HEARTBEAT ids injected on bus 1 must not reach it."""
    group, port = bus_spec.rsplit(":", 1)
    bus0, bus1 = bus_spec, f"{group}:{int(port) + 1}"  # the test's slot's second port
    summary = tmp_path / "ctl.json"
    sim = start_sim(f"{bus0}@1-3", "--bus", f"{bus1}@4-6", summary=tmp_path / "sim.json")
    ctl = start_controller(controller_bin, f"{bus0}@1-3", "--bus", f"{bus1}@4-6", "--duration", "3600",
                           "--summary", str(summary))
    intruder = open_bus(bus1)
    import can

    injected = 0
    try:
        time.sleep(2.5)  # booted and tracking (an hour of lockstep periods takes minutes more)
        assert ctl.poll() is None and sim.poll() is None
        for _ in range(5):  # a burst: all of it lands while the run is going
            state = bytes(range(16))  # DRIVE_1_STATE: CAN FD, 16 bytes; a counter that may even match
            intruder.send(can.Message(arbitration_id=0x181, data=state, is_extended_id=False, is_fd=True,
                                      bitrate_switch=True))
            intruder.send(can.Message(arbitration_id=0x701, data=bytes([0x7F]), is_extended_id=False))
            injected += 2
        time.sleep(0.1)
        assert ctl.poll() is None, "the run ended before the injected frames could arrive"
        ctl.send_signal(signal.SIGTERM)  # the end of the run: a safe stop, then the summary
        code, _, err = wait_exit(ctl, timeout=60)
        sim_code, _, sim_err = wait_exit(sim, timeout=30)
    finally:
        intruder.shutdown()
        for p in (sim, ctl):
            if p.poll() is None:
                p.kill()
    assert code == 5, err  # interrupted
    assert sim_code == 0, sim_err
    s = json.loads(summary.read_text())
    sim_s = json.loads((tmp_path / "sim.json").read_text())
    assert s["result"] == 5 and s["final_state"] == "safe-stop" and "stopped by signal" in s["reason"]
    assert s["frames"]["rx_wrong_bus"] == injected
    # ignored: no extra state or heartbeat accepted, nothing else counted as bad (the stop comes
    # at a period boundary, in a period of its own: its SYNC and zero-torque shutdown commands; the
    # controller reads no more states then)
    assert s["bus_periods"] == sim_s["periods"]
    assert s["frames"]["rx_state"] == 6 * (sim_s["periods"] - 1)
    assert s["frames"]["rx_wrong_counter"] == 0 and s["frames"]["rx_bad_length"] == 0
    assert sim_s["commands_missed"] == 0
