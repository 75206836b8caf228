"""Tuning pairs side by side in worker processes (tools/study/pairs.py): the same records as one
pair after another, and a signal to armctl stops every worker's runs, leaves nothing running, and
the same command then finishes the tuning."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from study_configs import with_tuning
from gen.lib.paths import REPO

# Where a pair's records differ by where they were made, not by what the tuning found.
WHERE = ("storage", "source")


def _config(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    cfg = folder / "paper.toml"
    cfg.write_text(with_tuning((REPO / "tools" / "studies" / "paper.toml").read_text(), duration_s=0.2, batch=2))
    return cfg


def _what(recs: dict[str, dict[str, Any]]) -> dict[str, Any]:
    return {s: {m: {k: v for k, v in r.items() if k not in WHERE} for m, r in ms.items()} for s, ms in recs.items()}


def test_pairs_in_workers_tune_as_one_pair_after_another(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from tools.build.arm import DEFAULT_ARM, build_arm
    from tools.study import pairs, setup_for, tuned
    from tools.study.config import load

    build_arm("release", DEFAULT_ARM)
    cfg = load(_config(tmp_path / "cfg"))
    setup, info, _ = setup_for(cfg, DEFAULT_ARM, tmp_path / "side-by-side", 2, None)
    assert pairs.pair_workers(setup, 3) == 2
    side_by_side = tuned(setup.cfg, DEFAULT_ARM, setup, info, ["ideal"], ["pm", "pd", "tde"], retune=True, trials=3)
    monkeypatch.setattr(pairs, "pair_workers", lambda setup, n: 1)
    in_turn = tuned(setup.cfg, DEFAULT_ARM, replace(setup, out=tmp_path / "in-turn"), info, ["ideal"],
                    ["pm", "pd", "tde"], retune=True, trials=3)
    assert list(side_by_side["ideal"]) == ["pm", "pd", "tde"]  # the config's order, however they finished
    assert all(r["trials_run"] == 3 for r in side_by_side["ideal"].values())
    assert _what(side_by_side) == _what(in_turn)


def _left_running(out: Path) -> list[str]:
    """armctl's workers and runs still alive (their command lines name the tuning's folder)."""
    r = subprocess.run(["pgrep", "-af", str(out)], capture_output=True, text=True)
    return [ln for ln in r.stdout.splitlines() if "pgrep" not in ln]


def _interrupt(p: subprocess.Popen[str], out: Path) -> None:
    """A Ctrl-C's SIGINT to armctl: it exits 130 in its own words, and nothing of it runs on."""
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 128 + signal.SIGINT, err
    assert "Traceback" not in err
    deadline = time.monotonic() + 10
    while _left_running(out) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _left_running(out)


def test_a_signal_stops_every_pair_and_the_same_command_finishes_the_tuning(tmp_path: Path) -> None:
    cfg = _config(tmp_path / "cfg")
    out = tmp_path / "tune"
    cmd = [sys.executable, "-m", "tools.cli", "tune", "--config", str(cfg), "--scenarios", "ideal,realistic",
           "--methods", "pm,pd,tde", "--trials", "6", "--jobs", "2", "--out", str(out)]
    p = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    busy: set[str] = set()
    while time.monotonic() < deadline and p.poll() is None and len(busy) < 2:
        try:  # two pairs under way: both workers have runs
            busy = {r.parent.name for r in out.glob("*/*/r0-t*")}
        except FileNotFoundError:  # armctl's check of --out makes the folder and removes it again
            pass
        time.sleep(0.02)
    assert len(busy) >= 2, "two pairs were never tuned at once"
    _interrupt(p, out)
    r = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    recs = json.loads((cfg.parent / "paper.tuning.json").read_text())["scenarios"]
    assert {s: sorted(ms) for s, ms in recs.items()} == {s: ["pd", "pm", "tde"] for s in ("ideal", "realistic")}
    assert all(r["trials_run"] == 6 for ms in recs.values() for r in ms.values())


def _study(out: Path) -> list[str]:
    # the bundled arm's kept tuning of pd and tde: nothing is tuned; 30 s runs take about 0.3 s in SIL
    return [sys.executable, "-m", "tools.cli", "study", "--methods", "pd,tde", "--scenarios", "ideal", "--seeds", "6",
            "--duration", "30", "--jobs", "2", "--confirm", "0", "--no-figures", "--out", str(out)]


def test_a_study_s_forked_runs_stop_on_a_signal_and_resume_to_the_same_numbers(tmp_path: Path) -> None:
    """A SIL study runs its runs in forked workers (tools/run/workers.py); a SIGINT stops them all,
    nothing is left running, no stopped run is kept, and the same command gives the numbers of
    the study run through once."""
    whole = subprocess.run(_study(tmp_path / "whole"), cwd=REPO, capture_output=True, text=True, timeout=600)
    assert whole.returncode == 0, whole.stderr[-3000:]
    out = tmp_path / "stopped"
    p = subprocess.Popen(_study(out), cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    done: list[Path] = []
    while time.monotonic() < deadline and p.poll() is None and len(done) < 2:
        try:
            done = list(out.glob("ideal/*/seed-*/spec.json"))
        except FileNotFoundError:  # armctl's check of --out makes the folder and removes it again
            pass
        time.sleep(0.01)
    assert len(done) >= 2 and p.poll() is None, "the study ended before it could be stopped"
    _interrupt(p, out)
    assert len(list(out.glob("ideal/*/seed-*/spec.json"))) < 12
    again = subprocess.run(_study(out), cwd=REPO, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr[-3000:]
    ref = json.loads((tmp_path / "whole" / "study.json").read_text())["scenarios"]["ideal"]
    got = json.loads((out / "study.json").read_text())["scenarios"]["ideal"]
    for part in ("runs", "stats", "pm_versus"):
        assert got.get(part) == ref.get(part), part
