"""The fault-injection matrix (tools/bench/faults.py, `tools/armctl faults`): every fault that must stop
the arm stopped it in a safe state under a named verdict, the others left it running with what
they did counted; no fault left a process behind."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from tools.bench.faults import FAULTS
from gen.lib.paths import REPO


@pytest.fixture(scope="module")
def faults_out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("faults")


@pytest.fixture(scope="module")
def matrix(faults_out: Path) -> dict[str, dict]:
    out = faults_out
    r = subprocess.run([str(REPO / "tools" / "armctl"), "faults", "--out", str(out)], cwd=REPO, capture_output=True,
                       text=True, timeout=1200)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "fault" in r.stdout and "detected in" in r.stdout
    return {x["fault"]: x for x in json.loads((out / "faults.json").read_text())["rows"]}


def test_every_fault_has_its_row(matrix: dict[str, dict]) -> None:
    assert list(matrix) == [f.name for f in FAULTS]


@pytest.mark.parametrize("name", [f.name for f in FAULTS])
def test_no_joint_moves_more_than_the_bound_after_the_stop(matrix: dict[str, dict], name: str) -> None:
    """At the arm's most gravity-loaded pose, whatever stopped it (the controller's safe stop, the drives'
    own reaction to a dead controller, a lost supply): the simulator's truth of the window after the stop;
    a row where there is none says why, in words."""
    from tools.bench.faults import MOVED_BOUND_DEG, UNMEASURED

    row = matrix[name]
    if name in UNMEASURED:
        assert row["moved_after_stop_deg"] is None and row["moved_unmeasured"] == UNMEASURED[name], row
        return
    assert row["moved_unmeasured"] is None, row
    assert 0.0 <= row["moved_after_stop_deg"] <= MOVED_BOUND_DEG, row
    assert len(row["moved_after_stop_per_joint_deg"]) == 6 and row["stop"]["from_bus_period"] is not None


def test_the_rows_run_at_the_most_gravity_loaded_pose(faults_out: Path) -> None:
    doc = json.loads((faults_out / "faults.json").read_text())
    from tools.bench.loaded_pose import most_loaded_pose

    pose = most_loaded_pose(REPO / "build" / "release" / "generated" / "arm" / "arm.xml")
    assert doc["pose"]["q_rad"] == pose.q and max(doc["pose"]["load"]) > 0.3  # the shoulder carries the arm
    for row in doc["rows"]:
        sim = json.loads((faults_out / row["fault"] / "run.json").read_text())["results"]
        assert sim["controller_args"][sim["controller_args"].index("--ref-amp") + 1] == "0,0,0,0,0,0"


@pytest.mark.parametrize("name", [f.name for f in FAULTS if f.expect_stop])
def test_faults_that_must_stop_the_arm_stop_it_and_are_never_ok(matrix: dict[str, dict], name: str) -> None:
    row = matrix[name]
    assert row["safe_state"] and row["verdict"] not in ("ok", None), row
    assert row["reasons"], row


def test_what_the_arm_can_run_through_is_counted(matrix: dict[str, dict]) -> None:
    garbage = matrix["garbage"]
    assert garbage["verdict"] == "ok" and garbage["counters"]["controller"]["rx_undecodable"] > 0
    assert garbage["counters"]["simulator"]["rx_undecodable"] > 0
    # the flood's 10,000 frames of an unknown id: each counted (or, on a full receive queue, counted
    # as the kernel's drop and the run named incomplete for it); the arm ran on, never stopped
    flood = matrix["flood"]
    ctl = flood["counters"]["controller"]
    assert not flood["safe_state"], flood
    assert ctl["rx_unknown_id"] + ctl["rx_kernel_drops"] == 10000, ctl
    if ctl["rx_kernel_drops"]:
        assert flood["verdict"] == "incomplete" and any(f"dropped {ctl['rx_kernel_drops']} frames" in r
                                                        for r in flood["reasons"]), flood
    else:
        assert flood["verdict"] == "ok" and not flood["reasons"], flood


def test_forged_telemetry_is_named_and_never_ok(matrix: dict[str, dict]) -> None:
    row = matrix["forged-telemetry"]
    assert row["verdict"] == "incomplete" and any("foreign telemetry: ARM_SIM" in r for r in row["reasons"]), row


def test_a_killed_logger_makes_the_run_incomplete_naming_the_logger_and_the_loss(matrix: dict[str, dict]) -> None:
    row = matrix["kill-logger"]
    assert row["verdict"] == "incomplete" and not row["safe_state"], row
    assert any(r.startswith("incomplete: the telemetry logger failed (exit -9)") for r in row["reasons"]), row
    lost = row["telemetry_lost"]
    assert lost is None or lost > 0, row  # what it never logged is lost (or cannot be counted)
    assert any(f"telemetry lost: {lost if lost is not None else 'unknown'} messages" in r for r in row["reasons"]), row


def _distinct_logged(log: Path) -> dict[str, int]:
    """Each channel's distinct sequence numbers in the log, read here."""
    from tools.run.telemetry_log import read_log

    out = {}
    for ch, c in read_log(log).items():
        msgs = c.messages
        seqs = msgs["seq"] if hasattr(msgs, "dtype") else [m.seq for m in msgs]
        out[ch] = len({int(s) for s in seqs})
    return out


def test_a_stalled_logger_is_incomplete_exactly_when_it_lost_telemetry(matrix: dict[str, dict],
                                                                       faults_out: Path) -> None:
    """0.5 s stopped: what its receive queue could not hold is counted lost, by the messages'
    sequence numbers, and the run is incomplete for exactly that; nothing lost, the run is ok."""
    row = matrix["stalled-logger"]
    lost = row["telemetry_lost"]
    assert isinstance(lost, int) and lost >= 0 and not row["safe_state"], row  # counted, and the arm ran on
    # the count is the log's: each channel's messages found in it (read here) are those sent less those lost
    run = json.loads((faults_out / "stalled-logger" / "run.json").read_text())
    tele = run["transport"]["telemetry"]
    logged = _distinct_logged(faults_out / "stalled-logger" / "telemetry.lcmlog")
    assert {ch: logged.get(ch, 0) for ch in tele} == {ch: t["sent"] - t["lost"] for ch, t in tele.items()}, tele
    assert sum(t["lost"] for t in tele.values()) == lost, (tele, lost)
    if lost:
        assert row["verdict"] == "incomplete" and row["reasons"] == [f"incomplete: telemetry lost: {lost} messages"], row
    else:
        assert row["verdict"] == "ok" and row["reasons"] == [], row


def test_no_process_is_left_behind(matrix: dict[str, dict], faults_out: Path) -> None:
    # this matrix's runs alone: their command lines name its folder (other tests' runs may be going)
    r = subprocess.run(["pgrep", "-af", "arm_controller|arm_sim|arm_lcm_logger"], capture_output=True, text=True)
    leftovers = [ln for ln in r.stdout.splitlines() if str(faults_out) in ln]
    assert not leftovers, leftovers


def test_hostile_names_are_data_the_run_is_normal_and_nothing_of_the_file_ran(matrix: dict[str, dict]) -> None:
    from tools.bench.faults import HOSTILE_MARKER

    row = matrix["hostile-names"]
    assert row["verdict"] == "ok" and row["telemetry_lost"] == 0, row
    assert row["input_ran_code"] is False and not HOSTILE_MARKER.exists()
