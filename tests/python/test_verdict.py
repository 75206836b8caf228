"""Verdicts are promises: "ok" only for a run that met its stated bounds with every process well
and every metric covering the whole run; anything else is named and exits non-zero."""

from __future__ import annotations

import json
import math
import subprocess
from pathlib import Path

import pytest

from tools.run.hil import HilOptions, run_hil
from gen.lib.paths import REPO
from tools.run.verdict import Bounds, judge

GOOD_RESULTS = {"joint_names": ["a", "b"], "tracking_max_abs_deg": [0.5, 1.0], "saturated_fraction": [0.0, 0.01],
                "commands_missed": 0, "commands_late": 0, "trajectory_periods": 1000, "periods_running": 1000,
                "estimation_periods": 1000}
GOOD_TRANSPORT = {"telemetry_lost_total": 0}
GOOD_CONTROLLER = {"result": 0, "steps_requested": 1500, "steps_done": 1500}
GOOD_SIM = {"result": "ok"}
GOOD_EXITS = {"controller": 0, "simulator": 0, "logger": 0}


def verdict(results: dict | None = None, transport: dict | None = None, controller: dict | None = None,
            sim: dict | None = None, exits: dict | None = None, bounds: Bounds = Bounds()) -> tuple[str, list[str]]:
    return judge({**GOOD_RESULTS, **(results or {})}, {**GOOD_TRANSPORT, **(transport or {})},
                 {**GOOD_CONTROLLER, **(controller or {})}, {**GOOD_SIM, **(sim or {})},
                 {**GOOD_EXITS, **(exits or {})}, bounds)


def test_a_good_run_is_ok() -> None:
    assert verdict() == ("ok", [])


@pytest.mark.parametrize("change,expected,named", [
    ({"sim": {"result": "diverged", "reason": "MuJoCo reset the arm"}}, "diverged", "MuJoCo reset"),
    ({"results": {"tracking_max_abs_deg": [0.5, math.nan]}}, "diverged", "on b"),
    ({"results": {"tracking_max_abs_deg": [0.5, 1225.0]}}, "diverged", "beyond 180 deg on b"),
    ({"controller": {"result": 5, "reason": "SIGTERM"}}, "interrupted", "SIGTERM"),
    ({"controller": {"result": 3, "reason": "runtime fault"}}, "failed", "runtime fault"),
    ({"sim": {"result": "lost", "reason": "controller went silent"}}, "failed", "went silent"),
    ({"controller": {"steps_done": 556}}, "incomplete", "556 of 1500 periods"),
    ({"controller": {"steps_done": None}}, "incomplete", "unknown number"),
    ({"transport": {"telemetry_lost_total": 3}}, "incomplete", "telemetry lost: 3"),
    ({"transport": {"telemetry_lost_total": None}}, "incomplete", "telemetry lost: unknown"),
    ({"exits": {"logger": 1}}, "incomplete", "logger failed"),
    ({"results": {"periods_running": 999}}, "incomplete", "cover 999 of the trajectory's 1000"),
    ({"results": {"estimation_periods": 10}}, "incomplete", "estimation error covers 10"),
    ({"results": {"tracking_max_abs_deg": [0.5, 3.0]}}, "tracking-bound-exceeded", "b: max |e| 3 deg > 2 deg"),
    ({"results": {"saturated_fraction": [0.2, 0.0]}}, "torque-limited", "a: at its torque or torque-rate limit 20.0 %"),
    ({"results": {"commands_missed": 2}}, "commands-missed", "missed 2"),
    ({"results": {"commands_missed": None}}, "commands-missed", "missed None"),
    ({"results": {"commands_late": 1}}, "commands-missed", "1 late"),
])
def test_every_failure_is_named(change: dict, expected: str, named: str) -> None:
    result, reasons = verdict(**change)
    assert result == expected
    assert any(named in r for r in reasons), reasons


def test_diverged_wins_over_everything_it_causes() -> None:
    """A diverged arm faults the drives, stops the controller and shortens the run: the verdict
    is the cause, and every consequence is still listed."""
    result, reasons = verdict(sim={"result": "diverged", "reason": "reset"}, controller={"result": 3, "steps_done": 7},
                              results={"periods_running": 0})
    assert result == "diverged"
    assert {r.split(":")[0] for r in reasons} == {"diverged", "failed", "incomplete"}


def test_bounds_are_the_ones_asked_for() -> None:
    # bounds other than the defaults (2 deg, no command missed): each way
    three = {"tracking_max_abs_deg": [0.5, 3.0]}
    assert verdict(results=three, bounds=Bounds(max_error_deg=4.0)) == ("ok", [])
    assert verdict(results={"tracking_max_abs_deg": [0.5, 1.0]}, bounds=Bounds(max_error_deg=0.8)) == \
        ("tracking-bound-exceeded", ["tracking-bound-exceeded: b: max |e| 1 deg > 0.8 deg"])
    assert verdict(results={"commands_missed": 2}, bounds=Bounds(max_commands_missed=5))[0] == "ok"
    assert verdict(exits={"logger": None})[0] == "ok"  # no logger asked for: nothing to fail


def test_a_diverging_simulation_is_reported_diverged_never_ok(tmp_path: Path, controller_bin: Path) -> None:
    """A true mass matrix that the paper-style uncertainty makes nearly singular (r = 0.999): the
    simulation blows up; MuJoCo would reset the arm and carry on."""
    run = run_hil(HilOptions(out=tmp_path, duration_s=1.0, preset=controller_bin.parent.parent.name,
                             uncertainty={"paper_ratio": 0.999, "paper_knot_s": 0.01}))
    r = run["results"]
    assert r["result"] == "diverged", r["verdict_reasons"]
    assert "MuJoCo" in r["verdict_reasons"][0] and "huge acceleration" in r["verdict_reasons"][0]
    assert run["environment"]["exit_codes"]["simulator"] == 5
    sim = json.loads((tmp_path / "sim_summary.json").read_text())
    assert sim["result"] == "diverged"


def test_hil_exits_non_zero_and_states_the_bounds_it_missed(tmp_path: Path) -> None:
    r = subprocess.run([str(REPO / "tools" / "armctl"), "hil", "--duration", "1", "--out", str(tmp_path),
                        "--max-error-deg", "0.001"], cwd=REPO, capture_output=True, text=True, timeout=600)
    run = json.loads((tmp_path / "run.json").read_text())
    res = run["results"]
    assert r.returncode == 1
    assert res["result"] == "tracking-bound-exceeded" and "tracking-bound-exceeded" in r.stdout
    assert res["bounds"]["max_error_deg"] == 0.001 and res["bounds"]["max_commands_missed"] == 0
    assert all(x.startswith("tracking-bound-exceeded") for x in res["verdict_reasons"])


def test_the_default_tracking_bound_is_a_few_degrees() -> None:
    """A run 20 deg off on one joint is not ok by default (the bound is 2 deg, not 30)."""
    kind, reasons = verdict(results={"tracking_max_abs_deg": [0.5, 20.1]})
    assert Bounds().max_error_deg == 2.0
    assert kind == "tracking-bound-exceeded" and "20.1 deg > 2 deg" in reasons[0]
    assert verdict(results={"tracking_max_abs_deg": [0.5, 1.9]})[0] == "ok"


def test_a_following_error_stop_names_the_stop_and_the_bound() -> None:
    """The safety layer's 0.5 rad stop and the tracking bound, reported together: the run failed, and
    it left the 2 deg bound on the way there."""
    from tools.run.verdict import FOLLOWING_ERROR_STOP_DEG, left_tracking_bound

    why = "following error above its limit"
    kind, reasons = verdict(results={"tracking_max_abs_deg": [0.5, 28.6]},
                            controller={"result": 4, "reason": why, "final_fault": why})
    assert kind == "failed"
    assert any(f"stop at {FOLLOWING_ERROR_STOP_DEG:.3g} deg, beyond the tracking bound of 2 deg" in r for r in reasons)
    assert any(r.startswith("tracking-bound-exceeded") for r in reasons)
    assert Bounds().as_dict()["following_error_stop_deg"] == pytest.approx(28.6479, abs=1e-3)
    assert left_tracking_bound({"result": "failed", "final_fault": why})
    assert not left_tracking_bound({"result": "failed", "final_fault": "joint velocity above its limit",
                                    "tracking_max_abs_deg": [0.1], "bounds": {"max_error_deg": 2.0}})


def test_example_1_counts_runs_the_following_error_stop_ended() -> None:
    """issue 21, item 6: two gh2 runs stopped for their following error lost track: Example 1 holds."""
    from tools.study.report import _claims

    why = "following error above its limit"
    runs = [{"result": "failed", "final_fault": why, "tracking_max_abs_deg": [28.6]} for _ in range(2)]
    sc = {"pm_versus": {}, "stats": {"gh2": {"results": ["failed", "failed"]}}, "runs": {"gh2": runs}}
    line = [c for c in _claims(sc) if "Example 1" in c][0]
    assert "holds here: 2 of 2 gh2 runs" in line and "following-error stop" in line
    ok = [{"result": "ok", "final_fault": "none", "tracking_max_abs_deg": [0.1], "bounds": {"max_error_deg": 2.0}}]
    sc = {"pm_versus": {}, "stats": {"gh2": {"results": ["ok"]}}, "runs": {"gh2": ok}}
    assert "does not hold here: 0 of 1" in [c for c in _claims(sc) if "Example 1" in c][0]


def test_hil_takes_the_tracking_bound() -> None:
    r = subprocess.run([str(REPO / "tools" / "armctl"), "hil", "--max-error-deg", "0", "--out", "/tmp/x-none"],
                       cwd=REPO, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "--max-error-deg: must be a number above 0" in r.stderr
