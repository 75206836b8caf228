"""Bus timing emulation (host_sim/native/sim_bus_timing.c): frame lengths, arbitration, backlog,
and what the arm feels of them, checked on the real arm_sim driven frame by frame (sim_master.py)
and in whole HIL runs of the arm protocol (the CiA 402 drives' timing: test_canopen_hil.py). The
timeline's own arithmetic has a C unit test (tests/c/sim)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from host_sim.launch import frame_times, parse_phy
from gen.lib.busload import Bus, ConfigError, Protocol, compute
from tools.run.hil import HilOptions, run_hil
from tools.run.telemetry_log import read_log

from sim_master import SimMaster

FD = (True, 1e6, 5e6)


@pytest.fixture(scope="module")
def proto() -> Protocol:
    return Protocol()


def test_parse_phy_names_what_is_wrong() -> None:
    assert parse_phy("fd:1M/5M") == (True, 1e6, 5e6)
    assert parse_phy("fd:500k") == (True, 5e5, None)
    assert parse_phy("classic:1M") == (False, 1e6, None)
    for bad, named in (("can:1M", "expected fd:"), ("classic:1M/5M", "one bit rate"), ("fd:7Q", "bit rate")):
        with pytest.raises(ConfigError, match=named):
            parse_phy(bad)


def test_frame_times_are_busloads(proto: Protocol) -> None:
    """The frame lengths arm_sim is given are exactly busload's, for every message of the DBC."""
    bus = Bus("b", *FD, [1, 2, 3])
    given = dict(item.split(":") for item in frame_times(bus, proto).split(","))
    load = compute([bus, Bus("c", *FD, [4, 5, 6])], 1000.0, 100.0, proto)[0]
    per_period = sum(float(given[str(fid)]) for fid in (0x080, 0x181, 0x182, 0x183, 0x201, 0x202, 0x203))
    assert per_period * 1e-6 == pytest.approx(load.periodic_s, rel=1e-9)
    assert float(given[str(0x080)]) == pytest.approx(65.0)  # 1 byte classic at 1 Mbit/s: 65 bits worst case
    assert float(given[str(0x181)]) == pytest.approx(72.6)  # 16-byte FD state at 1/5 Mbit/s
    assert len(given) == len(proto.db.messages)


def _phys(spec: list[str], drives: list[list[int]]) -> list[Bus]:
    return [Bus(f"b{i}", *parse_phy(s), d) for i, (s, d) in enumerate(zip(spec, drives))]


def test_a_new_torque_acts_from_the_end_of_its_frame(sim_exe: Path) -> None:
    """Two buses (default wiring): drive 1's command ends 417.8 us into the period (SYNC 65,
    three states 3 x 72.6, its own 135), so a step from 0 to 1 N m acts for 58.22 % of it."""
    drives = [[1, 2, 3], [4, 5, 6]]
    m = SimMaster(sim_exe, drives, timing="virtual", phys=_phys(["fd:1M/5M"] * 2, drives))
    try:
        m.boot_and_enable()
        step = m.counter  # the next period's index (no heartbeat round yet)
        m.period([0x0F] * 6, [1.0] * 6)
        m.period([0x0F] * 6, [1.0] * 6)  # the same torque again: no change inside the period
        m.period([0x0F] * 6, [1.0] * 6)  # (a period's truth is published once the next one began)
        first_cmd_end = 65 + 3 * 72.6 + 135
        expected = [1.0 - (first_cmd_end + 135 * (j % 3)) * 1e-3 for j in range(6)]
        assert list(m.truth_of(step).tau_applied) == pytest.approx(expected, abs=1e-9)
        assert list(m.truth_of(step + 1).tau_applied) == pytest.approx([1.0] * 6)
    finally:
        code, err = m.stop()
    assert code == 0, err
    s = json.loads(m.summary.read_text())
    assert s["commands_late"] == 0 and s["commands_missed"] == 0
    assert [b["sync_to_last_cmd_max_us"] for b in s["bus_timing"]] == pytest.approx([687.8, 687.8])


def test_a_late_command_is_not_applied_and_the_drive_faults_on_its_timeout(sim_exe: Path, proto: Protocol) -> None:
    """Bus 1 at 1 / 2 Mbit/s: its states end at 456.5 us, and the controller's commands for both
    buses follow the last state of the period, so every command ends by 861.5 us. After a
    heartbeat round (three heartbeats of 65 us per bus) the next SYNC waits 195 us, and the last
    command on each bus (drives 3 and 6) ends at 1056.5 us, after its period. It is not applied,
    counted late, and with a one-period command timeout those drives fault (EMCY) - what a real
    drive does when its RPDO does not come in time."""
    drives = [[1, 2, 3], [4, 5, 6]]
    phys = _phys(["fd:1M/5M", "fd:1M/2M"], drives)
    m = SimMaster(sim_exe, drives, timing="virtual", phys=phys, extra=["--command-timeout-periods", "1"])
    try:
        m.boot_and_enable()
        while m.counter <= 102:  # the heartbeat round ends period 99: period 100's SYNC waits for it
            m.period([0x0F] * 6, [0.5] * 6)
        time_course = [m.truth_of(k) for k in (99, 100, 101)]
    finally:
        code, err = m.stop()
    assert code == 0, err
    s = json.loads(m.summary.read_text())
    assert s["drive_faults"] == [3, 6], s
    # and once more in period 101: period 100 left the buses busy past its end, and the faults' EMCY
    # frames (135 us) delay 101's SYNC again
    assert [b["commands_late"] for b in s["bus_timing"]] == [2, 2] and s["commands_late"] == 4, s
    assert [b["sync_to_last_cmd_max_us"] for b in s["bus_timing"]] == pytest.approx([1056.5, 1056.5], abs=0.01)
    assert time_course[0].drive_faults == 0 and time_course[0].tau_applied[5] == pytest.approx(0.5)
    faulted = (1 << 2) | (1 << 5)
    # the faulted drive no longer follows the command: its fault reaction (0x605E = 2, CiA 402's
    # default) ramps the torque down on the quick stop ramp, then takes it off
    assert time_course[1].drive_faults == faulted and 0.0 <= time_course[1].tau_applied[5] < 0.5
    assert time_course[2].tau_applied[2] != pytest.approx(0.5) and time_course[2].tau_applied[4] == pytest.approx(0.5)
    assert sum("command ended 1.056 ms after its SYNC" in e for e in m.events) == 2, m.events  # one per bus
    assert {e for e in m.events if e.startswith("EMCY")} == {"EMCY 0x8250: drive 3 fault, torque off",
                                                             "EMCY 0x8250: drive 6 fault, torque off"}


def test_hil_with_bus_timing_on_the_default_wiring(tmp_path: Path, controller_bin: Path) -> None:
    """Lockstep HIL over the two default buses with their timing emulated: every command ends
    inside its period, at the time busload computes (687.8 us; 882.8 us in the periods after a
    heartbeat round, whose three frames delay that SYNC by 3 x 65 us)."""
    run = run_hil(HilOptions(protocol="arm", out=tmp_path, duration_s=0.5, method="pm", bus="udp", bus_timing=True,
                             preset=controller_bin.parent.parent.name))
    r, t = run["results"], run["transport"]
    assert r["result"] == "ok", r["problems"]
    assert r["bus_timing"] == "virtual" and r["commands_late"] == 0 and r["commands_missed"] == 0
    assert max(r["tracking_max_abs_deg"]) < 2.0
    assert [b["drives"] for b in t["bus_timing"]] == [[1, 2, 3], [4, 5, 6]]
    for b in t["bus_timing"]:
        assert b["periods"] == r["simulated_periods"]
        assert b["sync_to_last_cmd_max_us"] == pytest.approx(687.8 + 3 * 65, abs=1e-3)
        assert 687.8 - 1e-3 <= b["sync_to_last_cmd_mean_us"] < 687.8 + 3 * 65 * 0.02
    assert run["environment"]["bus_load_pct"] == {"can0": pytest.approx(69.0, abs=0.1),
                                                  "can1": pytest.approx(69.0, abs=0.1)}


def test_hil_with_bus_timing_on_one_overloaded_bus_fails_and_says_why(tmp_path: Path, controller_bin: Path) -> None:
    """All six drives on one CAN FD bus (131 % per period): the enable commands end ever later,
    the drives never reach operation enabled and the controller gives up naming them."""
    topo = tmp_path / "one_bus.toml"
    topo.write_text('[[bus]]\nname = "can0"\nkind = "fd"\nnominal = "1M"\ndata = "5M"\ndrives = [1, 2, 3, 4, 5, 6]\n')
    run = run_hil(HilOptions(protocol="arm", out=tmp_path / "run", duration_s=0.5, bus="udp", bus_timing=True, topology=topo,
                             preset=controller_bin.parent.parent.name))
    r, t = run["results"], run["transport"]
    assert r["result"] == "failed" and r["commands_late"] > 0 and t["bus_timing"][0]["commands_late"] > 0
    assert any(re.search(r"drive\(s\) [1-6](,[1-6])* not operation enabled", p) for p in r["problems"]), r["problems"]
    assert run["environment"]["bus_load_pct"] == {"can0": pytest.approx(131.4, abs=0.1)}
    events = [m.text for m in read_log(tmp_path / "run" / "telemetry.lcmlog")["ARM_SIM_EVENT"].messages]
    assert sum("bus timing: drive" in t and "not applied" in t for t in events) == 1, events  # said once
