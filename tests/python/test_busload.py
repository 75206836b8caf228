"""gen/lib/busload.py (and its command line, tools/busload.py) against frame lengths and bus loads
computed by hand (the arithmetic is in the comments, field by field, so a reviewer can check it without the code)."""

from __future__ import annotations

import json
import math
import re

import pytest
from pathlib import Path

from gen.lib import busload
from gen.lib.paths import REPO
from tools.cli import main as armctl
from gen.lib.busload import Bus, Protocol, classic_frame_bits, compute, fd_frame_bits

# ---- classic CAN --------------------------------------------------------------------------------
# 11-bit data frame: SOF 1 + id 11 + RTR 1 + IDE 1 + r0 1 + DLC 4 + data 8n + CRC 15 = 34 + 8n bits
# are stuffed; worst case floor((34 + 8n - 1) / 4) stuff bits; then CRC delimiter 1 + ACK 2 +
# EOF 7 + intermission 3 = 13 bits that are never stuffed.
#   n = 8: 98 + floor(97 / 4) = 98 + 24 -> 122 + 13 = 135   (anchors: "111-135 bits")
#   n = 1: 42 + floor(41 / 4) = 42 + 10 -> 52 + 13 = 65     (SYNC, heartbeat)
#   n = 0: 34 + floor(33 / 4) = 34 + 8 -> 42 + 13 = 55
# 29-bit: SOF 1 + id 11 + SRR 1 + IDE 1 + id 18 + RTR 1 + r1 1 + r0 1 + DLC 4 + data + CRC 15
# = 54 + 8n stuffed bits.
#   n = 8: 118 + floor(117 / 4) = 118 + 29 -> 147 + 13 = 160
#   n = 0: 54 + floor(53 / 4) = 54 + 13 -> 67 + 13 = 80


@pytest.mark.parametrize(("n", "extended", "bits"), [
    (8, False, 135), (1, False, 65), (0, False, 55), (8, True, 160), (0, True, 80),
])
def test_classic_frame_lengths(n: int, extended: bool, bits: int) -> None:
    assert classic_frame_bits(n, extended) == bits


def test_classic_matches_the_textbook_formula_for_every_length() -> None:
    # the closed form usually quoted (e.g. Davis et al. 2007): 8n + 47 + floor((34 + 8n - 1) / 4)
    for n in range(9):
        assert classic_frame_bits(n) == 8 * n + 47 + (34 + 8 * n - 1) // 4
        assert classic_frame_bits(n, extended=True) == 8 * n + 67 + (54 + 8 * n - 1) // 4


# ---- CAN FD -------------------------------------------------------------------------------------
# Nominal rate, 11-bit id: SOF 1 + id 11 + RRS 1 + IDE 1 + FDF 1 + res 1 + BRS 1 = 17 bits, worst
# stuff floor(16 / 4) = 4, trailer (CRC delimiter 1, ACK 2, EOF 7, intermission 3) 13 -> 34 bits.
# Data rate: ESI 1 + DLC 4 + data 8n; dynamic stuff over SOF..data minus the 4 already counted;
# stuff count 4; CRC 17 (n <= 16) or 21; fixed stuff bits 6 (CRC17) or 7 (CRC21).
#   n = 16: data bits 1 + 4 + 128 = 133; stuff floor((17 + 133 - 1) / 4) = 37, minus 4 -> 33;
#           133 + 33 + 4 + 17 + 6 = 193.   At 1 / 5 Mbit/s: 34 us + 193 / 5 us = 72.6 us.
#   n = 64: 1 + 4 + 512 = 517; floor((17 + 517 - 1) / 4) = 133, minus 4 -> 129;
#           517 + 129 + 4 + 21 + 7 = 678.
#   n = 20: 1 + 4 + 160 = 165; floor(181 / 4) = 45 - 4 = 41; 165 + 41 + 4 + 21 + 7 = 238 (CRC21)
#   n = 0:  5; floor(21 / 4) = 5 - 4 = 1; 5 + 1 + 4 + 17 + 6 = 33
# 29-bit id: arbitration SOF 1 + id 11 + SRR 1 + IDE 1 + id 18 + RRS 1 + FDF 1 + res 1 + BRS 1 = 36,
# stuff floor(35 / 4) = 8 -> nominal 36 + 8 + 13 = 57;
#   n = 16: 133 + (floor((36 + 133 - 1) / 4) = 42, minus 8 -> 34) + 4 + 17 + 6 = 194.


@pytest.mark.parametrize(("n", "extended", "nominal", "data"), [
    (16, False, 34, 193), (64, False, 34, 678), (20, False, 34, 238), (0, False, 34, 33),
    (16, True, 57, 194),
])
def test_fd_frame_lengths(n: int, extended: bool, nominal: int, data: int) -> None:
    assert fd_frame_bits(n, extended) == (nominal, data)


def test_fd_without_bit_rate_switch_is_all_nominal() -> None:
    # 16 bytes without BRS: 34 + 193 = 227 bits, all at the nominal rate
    assert fd_frame_bits(16, brs=False) == (227, 0)


def test_fixed_stuff_bits_follow_the_crc_length() -> None:
    # Going from 16 to 20 bytes adds 32 data bits, the dynamic stuff bits for them
    # (41 - 33 = 8), 4 more CRC bits (17 -> 21) and one more fixed stuff bit (6 -> 7).
    assert fd_frame_bits(20)[1] - fd_frame_bits(16)[1] == 32 + 8 + 4 + 1


def test_bad_lengths_are_refused() -> None:
    with pytest.raises(ValueError):
        classic_frame_bits(9)
    with pytest.raises(ValueError):
        fd_frame_bits(13)


# ---- per control period, from the DBC ------------------------------------------------------------
# One period on a bus: SYNC (classic, 1 byte) + per drive STATE (FD 16 bytes, BRS) + CMD (classic
# 8 bytes); heartbeats (classic 1 byte) every 100 ms, i.e. 1/100 of a period at 1 kHz.

@pytest.fixture(scope="module")
def proto() -> Protocol:
    return Protocol()


def _one_bus(spec: str) -> list[Bus]:
    return [busload.parse_bus(spec, 0)]


def test_default_config_fd_1m_5m_six_drives(proto: Protocol) -> None:
    # 65 us (SYNC) + 6 x (72.6 us STATE + 135 us CMD) = 65 + 1245.6 = 1310.6 us per period
    # heartbeats: 6 x 65 us per 100 ms = 0.39 %  -> 131.06 % + 0.39 % = 131.45 % at 1 kHz
    # highest rate within 70 %: (0.70 - 0.0039) / 1310.6 us = 531.1 Hz -> 531 Hz
    (bl,) = compute(_one_bus("fd:1M/5M:1-6"), 1000.0, 100.0, proto)
    assert bl.periodic_s == pytest.approx(1310.6e-6, abs=1e-12)
    assert bl.background_load == pytest.approx(6 * 65e-6 / 0.1)
    assert bl.load == pytest.approx(1.3106 + 0.0039)
    assert math.floor(bl.max_rate_hz(0.70)) == 531
    state = next(f for f in bl.frames if f.message == "DRIVE_1_STATE")
    assert (state.frames, state.nominal_bits, state.data_bits) == (1, 34, 193)
    assert state.time_s == pytest.approx(72.6e-6)


def test_classic_single_bus_limit(proto: Protocol) -> None:
    # Classic 1 Mbit/s: the 16-byte STATE needs two 8-byte frames (2 x 135 us), CMD 135 us,
    # SYNC 65 us: 65 + 6 x 405 = 2495 us per period -> 249.5 % + 0.39 % at 1 kHz.
    # Highest rate within 70 %: (0.70 - 0.0039) / 2495 us = 278.99 Hz -> 278 Hz.
    (bl,) = compute(_one_bus("classic:1M:1-6"), 1000.0, 100.0, proto)
    assert bl.periodic_s == pytest.approx(2495e-6, abs=1e-12)
    assert bl.load == pytest.approx(2.495 + 0.0039)
    assert math.floor(bl.max_rate_hz(0.70)) == 278
    state = next(f for f in bl.frames if f.message == "DRIVE_3_STATE")
    assert (state.frames, state.nominal_bits) == (2, 135)


def test_two_fd_buses_fit_at_1khz(proto: Protocol) -> None:
    # each bus: SYNC 65 + 3 x 207.6 = 687.8 us -> 68.78 % + 3 x 65 us / 100 ms (0.195 %) = 68.98 %
    loads = compute([busload.parse_bus("fd:1M/5M:1-3", 0), busload.parse_bus("fd:1M/5M:4-6", 1)],
                    1000.0, 100.0, proto)
    for bl in loads:
        assert bl.periodic_s == pytest.approx(687.8e-6, abs=1e-12)
        assert bl.load == pytest.approx(0.6878 + 0.00195)


def test_fd_bus_without_data_rate(proto: Protocol) -> None:
    # no BRS: STATE 227 us; 65 + 6 x (227 + 135) = 2237 us per period
    (bl,) = compute(_one_bus("fd:1M:1-6"), 1000.0, 100.0, proto)
    assert bl.periodic_s == pytest.approx(2237e-6, abs=1e-12)


# ---- the command ----------------------------------------------------------------------------------

def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    """armctl busload, of the arm protocol's DBC frames unless argv names a protocol."""
    rc = armctl(["busload", *(argv if "--protocol" in argv else ("--protocol", "arm", *argv))])
    out, err = capsys.readouterr()
    return rc, out, err


def test_default_topology_fits(capsys: pytest.CaptureFixture[str]) -> None:
    # firmware/protocol/buses.toml: two CAN FD 1/5 Mbit/s buses, drives 1-3 and 4-6: 69.0 % each
    rc, out, _ = _run(capsys)
    assert rc == 0 and "fits" in out
    assert "can0: CAN FD 1 Mbit/s arbitration / 5 Mbit/s data, drives 1,2,3" in out
    assert "can1: CAN FD 1 Mbit/s arbitration / 5 Mbit/s data, drives 4,5,6" in out
    assert out.count("load 69.0%") == 2


def test_one_fd_bus_is_refused_naming_bus_load_and_rate(capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, err = _run(capsys, "--bus", "fd:1M/5M:1-6")
    assert rc == 2
    assert "bus can0" in err and "131.4%" in err and "70% budget" in err
    assert "highest loop rate that fits is 531 Hz" in err
    assert "2 such buses fit" in err and "--bus fd:1M/5M:1-3 --bus fd:1M/5M:4-6" in err
    assert "DRIVE_6_STATE" in out


def test_classic_single_bus_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    rc, _, err = _run(capsys, "--bus", "classic:1M:1-6")
    assert rc == 2 and "249.9%" in err and "278 Hz" in err


def test_a_fitting_config_exits_0(capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, _ = _run(capsys, "--bus", "left=fd:1M/5M:1-3", "--bus", "right=fd:1M/5M:4-6")
    assert rc == 0 and "left:" in out and "right:" in out and "fits" in out
    rc, out, _ = _run(capsys, "--bus", "classic:1M:1-6", "--rate", "250")
    assert rc == 0
    # a 7-DOF arm: three CAN FD buses (drive slots 7 and 8 are in the DBC)
    rc, out, _ = _run(capsys, "--bus", "fd:1M/5M:1-3", "--bus", "fd:1M/5M:4-5", "--bus", "fd:1M/5M:6-7")
    assert rc == 0 and "fits" in out
    rc, _, err = _run(capsys, "--bus", "fd:1M/5M:1-7")
    assert rc != 0 and "3 such buses fit" in err


def test_json_output(capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, _ = _run(capsys, "--json", "--rate", "500", "--bus", "fd:1M/5M:1-6")
    doc = json.loads(out)
    assert rc == 0 and doc["fits"] and doc["max_rate_hz"] == 531
    assert doc["buses"][0]["periodic_us"] == pytest.approx(1310.6)


@pytest.mark.parametrize(("argv", "needle"), [
    (["--bus", "fd:1M/5M:1-3", "--drives", "6"], "drives 4, 5, 6 are on no bus"),
    (["--bus", "fd:1M/5M:1-3", "--bus", "fd:1M/5M:5-6"], "drives 4 are on no bus"),
    (["--bus", "fd:1M/5M:1-4", "--bus", "fd:1M/5M:4-6"], "drive 4 is on two buses"),
    (["--bus", "fd:1M/5M:1-7", "--drives", "6"], "drive 7 does not exist"),
    (["--bus", "fd:1M/5M:1-9"], "9 drives: the DBC has drive slots 1..8"),
    (["--drives", "9"], "--drives 9: the DBC has drive slots 1..8"),
    (["--bus", "classic:1M/5M:1-6"], "one bit rate"),
    (["--bus", "fd:fast:1-6"], "bit rate 'fast'"),
    (["--bus", "can:1M:1-6"], "expected classic:RATE:DRIVES"),
    (["--budget", "0"], "--budget"),
])
def test_config_errors_exit_2(capsys: pytest.CaptureFixture[str], argv: list[str], needle: str) -> None:
    rc, _, err = _run(capsys, *argv)
    assert rc == 2 and needle in err


def _topology(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "buses.toml"
    p.write_text(text)
    return p


BUS = '[[bus]]\nname = "{name}"\nkind = "{kind}"\nnominal = "1M"\n{data}drives = {drives}\n'


def _bus(name: str = "can0", kind: str = "fd", data: str = 'data = "5M"\n', drives: str = "[1, 2, 3]") -> str:
    return BUS.format(name=name, kind=kind, data=data, drives=drives)


@pytest.mark.parametrize(("text", "needle"), [
    (_bus() + _bus("can1", drives="[3, 4, 5, 6]"), "bus can1.drives: drive 3 is on two buses (can0 and can1)"),
    (_bus(), "drives: drive(s) 4, 5, 6 are on no bus"),
    (_bus(drives="[1, 2, 3, 4, 5, 6, 7]"), "bus can0.drives: drive 7 does not exist"),
    (_bus(kind="lin", drives="[1, 2, 3, 4, 5, 6]"), "bus can0.kind: expected"),
    (_bus(kind="classic", drives="[1, 2, 3, 4, 5, 6]"), "bus can0.data: a classic bus has one bit rate"),
    (_bus(data='data = "fast"\n', drives="[1, 2, 3, 4, 5, 6]"), "bus can0.data: bit rate 'fast'"),
    (_bus(drives='"1-6"'), "bus can0.drives: expected a non-empty list"),
    (_bus() + _bus(drives="[4, 5, 6]"), "bus[1].name: bus name 'can0' is used twice"),
    (_bus(drives="[1, 2, 3, 4, 5, 6]") + "speed = 3\n", "bus[0]: unknown field(s) speed"),
    ("bus = 1\n", "bus: expected one or more [[bus]] tables"),
])
def test_topology_errors_name_the_field(tmp_path: Path, text: str, needle: str) -> None:
    with pytest.raises(busload.ConfigError) as exc:
        busload.load_topology(_topology(tmp_path, text), 6)
    assert needle in str(exc.value)


def test_topology_file_drives_the_default(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    p = _topology(tmp_path, _bus(drives="[1, 2, 3, 4, 5, 6]"))
    rc, _, err = _run(capsys, "--topology", str(p))
    assert rc == 2 and "131.4%" in err
    bad = _topology(tmp_path, _bus())
    rc, _, err = _run(capsys, "--topology", str(bad), "--drives", "6")
    assert rc == 2 and "are on no bus" in err


def test_canopen_default_is_the_fewest_classic_buses_that_fit(capsys: pytest.CaptureFixture[str]) -> None:
    """The CiA 402 drives' default wire: six drives at 1 kHz with the drive table's TPDO2 every 2nd
    SYNC take three classic 1 Mbit/s buses of two, 61.1 % each, and the check names them."""
    rc, out, _ = _run(capsys, "--protocol", "canopen")
    assert rc == 0 and out.count("load 61.1%") == 3, out
    assert "--bus classic:1M:1-2 --bus classic:1M:3-4 --bus classic:1M:5-6" in out
    assert "TPDO2 node 6                     1/2" in out


def test_canopen_over_the_budget_says_what_fits(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    rc, _, err = _run(capsys, "--protocol", "canopen", "--bus", "classic:1M:1-3", "--drives", "3")
    assert rc == 2 and "bus can0 (classic 1 Mbit/s) is at 88.9%" in err and "highest loop rate that fits is 786 Hz" in err
    assert "2 buses up to 1145 Hz" in err, err
    rc, _, err = _run(capsys, "--protocol", "canopen", "--drives", "9")
    assert rc == 2 and "9 CiA 402 drives at 1000 Hz do not fit 4 classic 1 Mbit/s buses" in err, err
    rc, out, _ = _run(capsys, "--protocol", "canopen", "--drives", "9", "--rate", "500")
    assert rc == 0 and out.count("classic 1 Mbit/s, drives") == 3, out  # fewer buses at a lower rate
    every_sync = tmp_path / "drives.toml"
    every_sync.write_text((REPO / "firmware" / "protocol" / "drives.toml").read_text().replace("tpdo2 = 2", "tpdo2 = 1"))
    rc, _, err = _run(capsys, "--protocol", "canopen", "--drive-config", str(every_sync))
    assert rc == 2 and "6 CiA 402 drives at 1000 Hz do not fit 4 classic" in err, err
    rc, _, err = _run(capsys, "--protocol", "arm", "--drive-config", str(every_sync))
    assert rc == 2 and "--drive-config: the CiA 402 drive table, for --protocol canopen" in err


def test_max_buses_is_the_controllers_limit() -> None:
    from gen.lib.busload import MAX_BUSES

    headers = "".join(h.read_text() for h in (REPO / "firmware" / "transport" / "include" / "arm").glob("*.h"))
    assert re.findall(r"#define ARM_CAN_BUS_SET_MAX (\d+)u\b", headers) == [str(MAX_BUSES)]
