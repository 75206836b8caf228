"""The real-time loop: `armctl timing` writes complete, well-formed results (short run), overruns
are counted when a step is forced to be slow (the controller's --debug-slow-step-us test hook),
the rt options are validated. Nothing here asserts an absolute time."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tools.run.hil import HilOptions, run_hil
from gen.lib.paths import REPO, env_with_repo
from tools.bench.timing import parse_cyclictest

# armctl test runs these alone (no other test beside them): realtime runs: their timing is what is measured
pytestmark = pytest.mark.serial

PCTS = ("p50", "p99", "p99.9", "max")


def _well_formed(stats: dict) -> None:
    assert stats["n"] > 0
    vals = [stats[k] for k in PCTS]
    assert all(isinstance(v, (int, float)) and math.isfinite(v) and v >= 0 for v in vals), stats
    assert vals == sorted(vals), stats  # p50 <= p99 <= p99.9 <= max


@pytest.fixture(scope="module")
def timing_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict, subprocess.CompletedProcess[str]]:
    if shutil.which("cyclictest") is None:
        pytest.skip("cyclictest not found: apt-get install rt-tests (tools/armctl does as root)")
    out = tmp_path_factory.mktemp("timing")
    # 200 Hz: a rate the Python simulator sustains on a loaded 2-core machine; two runs of 1 s of
    # loop (--repeat: each run's files in OUT/RUN/, the runs together in OUT/repeat.json)
    r = subprocess.run([sys.executable, "-m", "tools.cli", "timing", "--duration", "1", "--rate", "200",
                        "--repeat", "2", "--out", str(out)], cwd=REPO, env=env_with_repo(), capture_output=True,
                       text=True, timeout=600)
    return out / "1", json.loads((out / "1" / "timing.json").read_text()), r


def test_timing_command_writes_complete_well_formed_results(timing_run) -> None:
    out, d, r = timing_run
    assert r.returncode == 0, r.stdout + r.stderr
    assert "controller wake-up latency" in r.stdout and "cyclictest wake-up latency" in r.stdout
    c = d["controller"]
    assert c["periods_measured"] > 0
    for key in ("wake_latency_us", "compute_us", "cycle_us"):
        _well_formed(c[key])
    assert isinstance(c["overruns"], int) and 0 <= c["overruns"] <= c["periods_measured"]
    assert "error" not in d["cyclictest"], d["cyclictest"]
    _well_formed(d["cyclictest"]["stats"])
    assert sum(d["cyclictest"]["histogram_us"].values()) > 0
    assert set(d["relative_to_cyclictest"]) == set(PCTS)
    assert d["config"]["rate_hz"] == 200 and d["config"]["period_us"] == 5000
    for key in ("joint_states_in_time", "joint_states_late", "commands_missed_by_simulator"):
        assert isinstance(d["bus"][key], int), d["bus"]
    assert d["controller_rt_setup"]  # what the loop got (SCHED_FIFO or the reason it did not)
    assert set(d["definitions"]) >= {"wake_latency", "compute", "cycle", "overrun"}
    png = (out / "timing.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10000
    assert (out / "hil" / "run.json").exists() and (out / "hil" / "telemetry.lcmlog").exists()


def test_repeated_runs_are_summarised_run_by_run(timing_run) -> None:
    out, d, r = timing_run
    rep = json.loads((out.parent / "repeat.json").read_text())
    assert rep["config"] == {"runs": 2, "duration_s": 1.0, "rate_hz": 200.0}
    assert [row["run"] for row in rep["runs"]] == [1, 2]
    assert rep["runs"][0]["verdict"] == d["verdict"]  # the row is that run's own timing.json
    assert rep["runs"][0]["controller_wake_us"]["max"] == d["controller"]["wake_latency_us"]["max"]
    assert rep["runs_ok"] == sum(row["verdict"] == "ok" for row in rep["runs"]) == 2, rep
    assert "run 2 of 2: ok" in r.stdout and (out.parent / "2" / "timing.json").is_file()


def test_a_stop_naming_another_node_is_counted_apart() -> None:
    """With nothing injected, a stop naming another node on a drive's id is the controller misreading
    late answers: the summary counts it apart from the machine's lateness, and its verdict is not ok."""
    from tools.bench.timing_repeat import ANOTHER_NODE, run_row, summarise

    def run(verdict: str, reason: str, side: str) -> dict:
        return {"verdict": verdict, "verdict_reason": reason, "lateness": {"stop_side": side},
                "controller": {"wake_latency_us": {"p99.9": 40.0, "max": 900.0}},
                "cyclictest": {"stats": {"p99.9": 50.0, "max": 1200.0}}}

    rows = [run_row(1, run("ok", "", "none")),
            run_row(2, run("incomplete", "period 9: stale joint state (watchdog); late: the plant's answer", "plant")),
            run_row(3, run("incomplete", f"period 174: drive 1's state came twice for one SYNC: {ANOTHER_NODE}", "none"))]
    s = summarise(rows, 10.0, 1000.0)
    assert s["verdict"] == "stopped" and s["runs_ok"] == 1 and s["another_node"] == 1, s
    assert s["stopped_by_side"] == {"plant": 1, "another node (misread)": 1}, s
    assert rows[1]["cyclictest_wake_us"]["max"] == 1200.0
    assert summarise(rows[:1], 10.0, 1000.0)["verdict"] == "ok"


def test_overruns_are_counted_when_every_step_is_forced_slow(tmp_path: Path, controller_bin: Path) -> None:
    # 200 Hz (5 ms) with a 6 ms busy wait inside every control step: every period overruns.
    run = run_hil(HilOptions(out=tmp_path, duration_s=0.2, mode="realtime",
                             preset=controller_bin.parent.parent.name,
                             controller_args=("--rate", "200", "--rt-priority", "0",
                                              "--debug-slow-step-us", "6000")))
    summary = json.loads((tmp_path / "controller_summary.json").read_text())
    assert summary["steps_done"] > 0, run["results"]["problems"]
    # every step overran, and so may the controlled stop's periods after them
    assert summary["steps_done"] <= summary["overruns"] <= summary["steps_done"] + summary["stop"]["periods"], summary
    assert run["transport"]["overruns"] == summary["overruns"]
    # the simulator is the other half of a realtime loop: real-time priority when permitted, on
    # the loop's CPU (the last one by default)
    expected = "SCHED_FIFO 70" if os.geteuid() == 0 else "SCHED_OTHER"
    cpu = (os.cpu_count() or 1) - 1
    assert run["environment"]["simulator_scheduling"] == f"{expected} on CPU {cpu}"


LATE_PERIOD = 60  # the bus period whose SYNC the drives answer late (the simulator's test hook)
WIDE_WATCHDOG_PERIODS = 20  # 0.1 s at 200 Hz: a stall beside the late answer does not end the run


@pytest.mark.parametrize("protocol", ["canopen", "arm"])
@pytest.mark.parametrize(("release", "late_periods"), [("command", 1), ("next-sync", 1), ("next-sync", 3),
                                                    ("burst", 3)])
def test_a_late_answer_is_counted_late_not_taken_for_another_node(tmp_path: Path, controller_bin: Path, protocol: str,
                                                                  release: str, late_periods: int) -> None:
    """A stalled simulator (a descheduled vCPU did it in CI) answers after the controller stopped
    waiting: before its next SYNC or after it, and for one period or several in a row. A CANopen TPDO
    carries no SYNC counter; the late one once passed for the next period's state, and that period's
    own then for a second node on the drive's id, which stopped the run (after late periods in a row,
    even once the first was told apart), or when a plant that stalled for several periods sent them
    all in one burst (the third of a burst once did). Late answers are counted late and the run goes
    on (the arm protocol tells them by their counter).
    The simulator holds the answers back until the controller's first command of the period (it has
    stopped waiting) or its next SYNC: a delay in time would not do, since a stall of the controller
    on a loaded machine can outlast it, and an answer read before the controller stops waiting is
    its period's own. The watchdog is widened: the late periods are stale by design, and a realtime
    run on a shared machine may see a stall of its own beside them (CI once saw the simulator answer
    three more periods late), which would stop the run for a reason this test is not about."""
    periods = f"{LATE_PERIOD}-{LATE_PERIOD + late_periods - 1}"
    # CANopen: TPDO2 at every other SYNC, so a late answer may lack the TPDO2 the period it is read
    # in waits for, and the pump reads on into that period's own answers
    tpdo2 = ("--tpdo2-type", "2") if protocol == "canopen" else ()
    run_hil(HilOptions(out=tmp_path, duration_s=0.6, mode="realtime", preset=controller_bin.parent.parent.name,
                       protocol=protocol, controller_args=("--rate", "200", "--rt-priority", "0",
                                                           "--watchdog-periods", str(WIDE_WATCHDOG_PERIODS), *tpdo2),
                       sim_args=("--debug-late-answer", f"{periods}:{release}")))
    summary = json.loads((tmp_path / "controller_summary.json").read_text())
    frames = summary["frames"]
    assert "came twice" not in summary["reason"], summary["reason"]
    assert frames["rx_duplicate_state"] == 0, frames
    assert summary["bus_periods"] > LATE_PERIOD + 5, summary["reason"]  # it went on past the late periods
    # every drive's late answer counted as late (a CANopen drive's first of two in a row passes for
    # the next period's: without a counter nothing tells it apart; the second then is told)
    n_drives = json.loads((tmp_path / "sim_summary.json").read_text())["n_drives"]
    assert frames["rx_wrong_counter"] >= n_drives, frames


def test_rt_options_are_validated(controller_bin: Path) -> None:
    for args, word in ((["--rt-priority", "150"], "--rt-priority"), (["--cpu", "-1"], "--cpu"),
                       (["--cpu", "1000"], "--cpu"), (["--debug-slow-step-us", "x"], "--debug-slow-step-us")):
        r = subprocess.run([str(controller_bin), "--lcm-url", "", "--boot-timeout", "0.1", *args],
                           capture_output=True, text=True, timeout=60)
        assert r.returncode == 2, (args, r.stderr)
        assert word in r.stderr, (args, r.stderr)
    r = subprocess.run([str(controller_bin), "--help"], capture_output=True, text=True, timeout=60)
    assert "--rt-priority" in r.stdout and "--cpu" in r.stdout
    assert "debug-slow-step" not in r.stdout  # a test hook, not a product option


def test_cyclictest_histogram_is_parsed() -> None:
    text = "\n".join(["# /dev/cpu_dma_latency set to 0us", "000000 000000", "000005 000050", "000010 000049",
                      "000300 000001", "# Total: 000000100", "# Min Latencies: 00005", "# Avg Latencies: 00010",
                      "# Max Latencies: 00300", "# Histogram Overflows: 00000"])
    p = parse_cyclictest(text)
    assert p["histogram_us"] == {5: 50, 10: 49, 300: 1}
    s = p["stats"]
    assert (s["n"], s["p50"], s["p99"], s["p99.9"], s["max"], s["min"]) == (100, 5.0, 10.0, 300.0, 300.0, 5.0)


def test_a_slower_loop_gets_its_whole_period_simulated() -> None:
    """At 200 Hz on a 1 kHz arm each period is 5 MuJoCo steps (it once was 1: the simulated arm ran
    5x slow and the controller's step check caught the positions the velocities did not explain)."""
    from tools.run.hil import HilError, sim_substeps

    assert sim_substeps({"loop_rate_hz": 1000.0, "substeps": 1}, 200.0) == 5
    assert sim_substeps({"loop_rate_hz": 1000.0, "substeps": 2}, 500.0) == 4
    assert sim_substeps({"loop_rate_hz": 1000.0, "substeps": 1}, 1000.0) == 1
    for bad in (300.0, 2000.0):
        with pytest.raises(HilError, match="--rate"):
            sim_substeps({"loop_rate_hz": 1000.0, "substeps": 1}, bad)
