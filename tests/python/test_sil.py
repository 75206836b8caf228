"""Software in the loop (arm_sil) against lockstep HIL (arm_controller and arm_sim on the UDP bus):
every firmware method in every scenario of the study, the same seed, the same results bit for bit,
and the same torques in the telemetry, period by period."""

from __future__ import annotations

from pathlib import Path

import pytest

from host_sim.drive_model import DriveModel
from tools.run.hil import HilOptions, run_hil
from tools.build.arm import DEFAULT_ARM, arm_build_dir, arm_info
from tools.study.config import for_arm, load
from tools.study import DEFAULT_CONFIG
from tools.run.telemetry_log import read_log

FIRMWARE_METHODS = ("pm", "pm-paper", "gh2", "pd", "tde", "usde-smc")
CFG = load(DEFAULT_CONFIG)


def _run(out: Path, preset: str, method: str, scenario: str, bus: str, protocol: str = "arm") -> dict:
    sc = for_arm(CFG, arm_info(arm_build_dir(preset, DEFAULT_ARM))).scenarios[scenario]  # friction for this arm
    return run_hil(HilOptions(out=out, duration_s=0.4, method=method, preset=preset, bus=bus,
                              controller_args=("--ref-hold", "0.1"), uncertainty={**sc.uncertainty, "seed": 7},
                              drives=sc.drives, bus_timing=sc.bus_timing, protocol=protocol))


@pytest.mark.parametrize("scenario", list(CFG.scenarios))
def test_sil_equals_lockstep_hil_for_every_method(tmp_path: Path, controller_bin: Path, scenario: str) -> None:
    preset = controller_bin.parent.parent.name
    for method in FIRMWARE_METHODS:
        sil = _run(tmp_path / method / "sil", preset, method, scenario, "sil")
        hil = _run(tmp_path / method / "udp", preset, method, scenario, "udp")
        assert sil["environment"]["bus_choice"].startswith("sil") and hil["environment"]["bus_choice"].startswith("udp")
        # (a method the safety layer stops in a scenario still has to stop the same way in both)
        assert sil["results"]["steps"] > 100 and sil["results"].get("periods_running", 0) > 0, sil["results"]
        differ = {k: (sil["results"].get(k), hil["results"].get(k))
                  for k in set(sil["results"]) | set(hil["results"]) if sil["results"].get(k) != hil["results"].get(k)}
        assert not differ, f"{method} in {scenario}: {differ}"
        logs = [read_log(tmp_path / method / b / "telemetry.lcmlog") for b in ("sil", "udp")]
        for channel, field in (("ARM_CTL", "tau"), ("ARM_CTL", "w_hat"), ("ARM_SIM", "tau_applied"),
                               ("ARM_SIM", "w_true")):
            series = [[list(getattr(m, field)) for m in log[channel].messages] for log in logs]
            assert series[0] and series[0] == series[1], f"{method} in {scenario}: {channel}.{field} differs"
        assert sil["transport"]["telemetry_lost_total"] == 0


@pytest.mark.parametrize("scenario", list(CFG.scenarios))
def test_sil_equals_lockstep_hil_over_canopen(tmp_path: Path, controller_bin: Path, scenario: str) -> None:
    """The same over CiA 402 drives, the study's protocol (their frames timed on the bus where the
    scenario emulates its timing; the flexible arm and the payload where it has them): a few
    methods, results and torques bit for bit."""
    preset = controller_bin.parent.parent.name
    for method in ("pm", "tde", "usde-smc"):
        sil = _run(tmp_path / method / "sil", preset, method, scenario, "sil", "canopen")
        hil = _run(tmp_path / method / "udp", preset, method, scenario, "udp", "canopen")
        assert sil["results"]["protocol"] == hil["results"]["protocol"] == "canopen"
        assert sil["results"]["steps"] > 100, sil["results"]
        differ = {k: (sil["results"].get(k), hil["results"].get(k))
                  for k in set(sil["results"]) | set(hil["results"]) if sil["results"].get(k) != hil["results"].get(k)}
        assert not differ, f"{method} in {scenario}: {differ}"
        logs = [read_log(tmp_path / method / b / "telemetry.lcmlog") for b in ("sil", "udp")]
        for channel, field in (("ARM_CTL", "tau"), ("ARM_SIM", "tau_applied")):
            series = [[list(getattr(m, field)) for m in log[channel].messages] for log in logs]
            assert series[0] and series[0] == series[1], f"{method} in {scenario}: {channel}.{field} differs"


def test_sil_refuses_realtime_and_a_foreign_controller(tmp_path: Path, controller_bin: Path) -> None:
    from tools.run.hil import HilError

    preset = controller_bin.parent.parent.name
    with pytest.raises(HilError, match="lockstep only"):
        run_hil(HilOptions(out=tmp_path / "rt", duration_s=0.1, preset=preset, bus="sil", mode="realtime"))
    with pytest.raises(HilError, match="lockstep only"):
        run_hil(HilOptions(out=tmp_path / "x", duration_s=0.1, preset=preset, bus="sil", controller=controller_bin))


def test_sil_run_counts_its_frames_like_the_wire(tmp_path: Path, controller_bin: Path) -> None:
    """Each side's frame counters in SIL equal lockstep HIL's (the in-process bus drops nothing
    and adds nothing), and the telemetry log holds every message each side sent."""
    preset = controller_bin.parent.parent.name
    # the arm protocol: its drives' heartbeats go by SYNC periods (the CiA 402 drives' by the wall
    # clock, so their count differs between runs; their results do not: test_canopen_hil.py)
    runs = {b: run_hil(HilOptions(out=tmp_path / b, duration_s=0.3, preset=preset, bus=b, drives=DriveModel(),
                                  protocol="arm")) for b in ("sil", "udp")}
    # (the controller repeats NMT start until the drives answer: how often is the wire's timing)
    sil_sim, udp_sim = runs["sil"]["transport"]["simulator_frames"], runs["udp"]["transport"]["simulator_frames"]
    assert {k: v for k, v in sil_sim.items() if k != "frames_rx"} == {k: v for k, v in udp_sim.items() if k != "frames_rx"}
    # and in SIL the drives' boot-up heartbeats and identity reach a controller already listening
    # (over a bus it starts after them): every state and every rejected frame is counted the same
    sil_ctl, udp_ctl = runs["sil"]["transport"]["controller_frames"], runs["udp"]["transport"]["controller_frames"]
    boot = ("tx", "rx", "rx_heartbeat", "rx_sim_identity")
    assert {k: v for k, v in sil_ctl.items() if k not in boot} == {k: v for k, v in udp_ctl.items() if k not in boot}
    assert sil_ctl["rx_state"] >= 6 * runs["sil"]["results"]["steps"]  # every period, every drive
    tele = runs["sil"]["transport"]["telemetry"]
    assert tele and all(v["lost"] == 0 and v["sequence_gaps"] == 0 for v in tele.values()), tele


def test_capture_holds_every_frame_and_the_field_s_tools_read_it(tmp_path: Path, controller_bin: Path) -> None:
    """--capture: every frame the drives received or sent, in candump's log format, on the in-process
    bus and on UDP alike; python-can's LogReader and cantools decode read every line."""
    import subprocess
    import sys

    import can

    from tools.run.hil import CAPTURE_FILE
    from gen.lib.paths import REPO

    preset = controller_bin.parent.parent.name
    for bus in ("sil", "udp"):
        # the arm protocol's frames and DBC (a CANopen run's capture and its derived DBC: test_canopen_hil.py)
        run = run_hil(HilOptions(out=tmp_path / bus, duration_s=0.2, preset=preset, bus=bus, capture=True,
                                 protocol="arm"))
        path = tmp_path / bus / CAPTURE_FILE
        assert run["environment"]["capture"] == str(path)
        frames = list(can.LogReader(str(path)))
        sim = run["transport"]["simulator_frames"]
        assert len(frames) == sim["frames_tx"] + sim["frames_rx"] + sim["rx_foreign_drive"] > 0
        assert [f.timestamp for f in frames] == sorted(f.timestamp for f in frames)
        assert sum(f.is_fd for f in frames) == run["transport"]["controller_frames"]["rx_state"]  # states are FD
        decoded = subprocess.run([sys.executable, "-m", "cantools", "decode", str(REPO / "firmware" / "protocol" /
                                  "arm_drives.dbc")], input=path.read_text(), capture_output=True, text=True)
        assert decoded.returncode == 0 and "Unknown frame id" not in decoded.stdout, decoded.stdout[-2000:]
        assert decoded.stdout.count(" ::\n") == len(frames)
