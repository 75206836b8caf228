"""Bus timing emulation: frame lengths, arbitration, backlog, and what the arm feels of them."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import can
import pytest

from host_sim.arm import Arm
from host_sim.bus_timing import BusTimeline, parse_phy, timelines
from host_sim.cia402 import PowerState
from host_sim.protocol import NMT_START
from host_sim.simulator import SimConfig, Simulator
from tools.busload import Bus, ConfigError, Protocol, compute
from tools.hil import HilOptions, run_hil
from tools.telemetry_log import read_log

FD = (True, 1e6, 5e6)
SYNC, STATE1, CMD1 = 0x080, 0x181, 0x201


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


def test_lowest_id_first_and_backlog_carries_over() -> None:
    tl = BusTimeline(Bus("b", True, 1e6, 5e6, [1]), {1: 1e-4, 2: 2e-4, 3: 3e-4})
    ends = tl.transmit(0.0, [3, 1, 2])
    assert ends == pytest.approx({1: 1e-4, 2: 3e-4, 3: 6e-4})
    assert tl.transmit(1e-4, [1]) == pytest.approx({1: 7e-4})  # waits for the bus
    tl.transmit(9e-4, [3])  # ends at 1.2 ms: 0.2 ms into the next period
    tl.new_period(1e-3)
    assert tl.free == pytest.approx(2e-4) and tl.stats.backlog_max_s == pytest.approx(2e-4)
    assert tl.transmit(0.0, [1]) == pytest.approx({1: 3e-4})


@pytest.mark.parametrize("drives", [[1, 2, 3], [1, 2, 3, 4, 5, 6]])
def test_one_period_costs_what_busload_says(proto: Protocol, drives: list[int]) -> None:
    """SYNC, the states and the commands of one period end exactly at busload's per-period time."""
    (tl,) = timelines([FD], [drives], proto)
    sync_end = tl.transmit(0.0, [SYNC])[SYNC]
    states = tl.transmit(sync_end, [STATE1 + d - 1 for d in drives])
    cmds = tl.transmit(max(states.values()), [CMD1 + d - 1 for d in drives])
    rest = [d for d in range(1, 7) if d not in drives]
    load = compute([Bus("b", *FD, drives), *([Bus("c", *FD, rest)] if rest else [])], 1000.0, 100.0, proto)[0]
    assert max(cmds.values()) == pytest.approx(load.periodic_s, rel=1e-12)
    assert sync_end == pytest.approx(65e-6)  # 1 byte classic at 1 Mbit/s: 65 bits worst case
    assert [round(states[STATE1 + d - 1] * 1e7) for d in drives[:2]] == [round((65 + 72.6) * 10),
                                                                       round((65 + 2 * 72.6) * 10)]


@pytest.fixture()
def virtual_buses() -> Iterator[list[can.BusABC]]:
    """In-process python-can buses: the simulator's logic without any transport."""
    buses = [can.Bus(interface="virtual", channel=f"timing-test-{i}", receive_own_messages=False) for i in range(2)]
    yield buses
    for b in buses:
        b.shutdown()


def running_sim(buses: list[can.BusABC], bus_of: list[int], phys: list[tuple[bool, float, float | None]]) -> Simulator:
    arm = Arm()
    drives = [[j + 1 for j in range(arm.n) if bus_of[j] == b] for b in range(len(buses))]
    sim = Simulator(SimConfig(lcm_url="", bus_timing="virtual"), buses, arm, bus_of, timelines(phys, drives))
    for d in sim.drives:
        d.on_nmt(NMT_START)
        d.power = PowerState.OPERATION_ENABLED
    return sim


def serve_period(sim: Simulator, counter: int, torque: float) -> None:
    for b in range(len(sim.buses)):
        sim.on_sync(counter, b)
    for j in range(sim.arm.n):
        data = sim.proto.cmd_codec[j].encode({"controlword": 0x0F, "target_torque": torque, "sync_counter": counter})
        sim.on_command(j, data, sim.bus_of[j])


def test_a_new_torque_acts_from_the_end_of_its_frame(virtual_buses: list[can.BusABC]) -> None:
    """Two buses (default wiring): drive 1's command ends 417.8 us into the period (SYNC 65,
    three states 3 x 72.6, its own 135), so a step from 0 to 1 N m acts for 58.22 % of it."""
    sim = running_sim(virtual_buses, [0, 0, 0, 1, 1, 1], [FD, FD])
    serve_period(sim, 0, 1.0)
    first_cmd_end = 65 + 3 * 72.6 + 135
    expected = [1.0 - (first_cmd_end + 135 * (j % 3)) * 1e-3 for j in range(6)]
    assert sim.last_tau == pytest.approx(expected, abs=1e-9)
    serve_period(sim, 1, 1.0)  # the same torque again: no change inside the period
    assert sim.last_tau == pytest.approx([1.0] * 6)
    assert sim.report.commands_late == 0 and sim.report.commands_missed == 0


def test_one_overloaded_bus_makes_commands_late_and_faults_the_drives(virtual_buses: list[can.BusABC]) -> None:
    """All six drives on one CAN FD 1/5 Mbit/s bus: 1310.6 us per period (busload: 131 %). The
    last commands end after their period, the backlog grows, and the drives whose commands keep
    arriving late fault on their command timeout (3 periods), as a real overloaded bus would."""
    sim = running_sim(virtual_buses[:1], [0] * 6, [FD])
    for k in range(3):
        serve_period(sim, k, 1.0)
    late_first = sim.timing[0].stats.commands_late  # type: ignore[index]
    assert late_first >= 3 * 3  # drives 4-6 late in every period, more as the backlog grows
    assert sim.report.commands_late == late_first
    assert [d.node_id for d in sim.drives if d.power is PowerState.FAULT] == [4, 5, 6]
    assert sim.timing[0].stats.backlog_max_s > 0.3e-3  # type: ignore[index]


def test_hil_with_bus_timing_on_the_default_wiring(tmp_path: Path, controller_bin: Path) -> None:
    """Lockstep HIL over the two default buses with their timing emulated: every command ends
    inside its period, at the time busload computes (687.8 us; 882.8 us in the periods after a
    heartbeat round, whose three frames delay that SYNC by 3 x 65 us)."""
    run = run_hil(HilOptions(out=tmp_path, duration_s=0.5, method="pm", bus="udp", bus_timing=True,
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
    run = run_hil(HilOptions(out=tmp_path / "run", duration_s=0.5, bus="udp", bus_timing=True, topology=topo,
                             preset=controller_bin.parent.parent.name))
    r, t = run["results"], run["transport"]
    assert r["result"] == "failed" and r["commands_late"] > 0 and t["bus_timing"][0]["commands_late"] > 0
    assert any(re.search(r"drive\(s\) [1-6](,[1-6])* not operation enabled", p) for p in r["problems"]), r["problems"]
    assert run["environment"]["bus_load_pct"] == {"can0": pytest.approx(131.4, abs=0.1)}
    events = [m.text for m in read_log(tmp_path / "run" / "telemetry.lcmlog")["ARM_SIM_EVENT"].messages]
    assert sum("bus timing: drive" in t and "not applied" in t for t in events) == 1, events  # said once
