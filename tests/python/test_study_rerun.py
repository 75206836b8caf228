"""A study's run is reproducible alone (issue 21, item 6): the command the study records for a run
(`hil --scenario --seed --knobs`, or `--tuned METHOD`) gives its run.json results exactly."""

from __future__ import annotations

import json
import shlex
import subprocess
from pathlib import Path

from gen.lib.paths import REPO

ARMCTL = str(REPO / "tools" / "armctl")


def _armctl(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([ARMCTL, *args], cwd=REPO, capture_output=True, text=True, timeout=1200)


def test_a_study_run_by_hand_gives_its_results(tmp_path: Path) -> None:
    out = tmp_path / "study"
    r = _armctl("study", "--scenarios", "realistic", "--methods", "pd,pm-paper-weights", "--seeds", "1",
                "--duration", "0.5", "--confirm", "0", "--no-figures", "--out", str(out))
    assert r.returncode in (0, 1), r.stderr
    study = json.loads((out / "study.json").read_text())
    seed = study["seeds"][0]
    report = (out / "report.md").read_text()
    for method in ("pd", "pm-paper-weights"):
        cmd = study["commands"]["realistic"][method]
        assert cmd in report
        argv = shlex.split(cmd.replace("SEED", str(seed)))
        argv[argv.index("--out") + 1] = str(tmp_path / method)
        by_hand = _armctl(*argv[1:])
        assert by_hand.returncode in (0, 1), by_hand.stderr
        want = json.loads((out / "realistic" / method / f"seed-{seed}" / "run.json").read_text())["results"]
        got = json.loads((tmp_path / method / "run.json").read_text())["results"]
        assert got == want, sorted(k for k in set(got) | set(want) if got.get(k) != want.get(k))
    # the kept tuning's knobs by name: the same run as the recorded --knobs
    r = _armctl("hil", "--bus", "sil", "--scenario", "realistic", "--tuned", "pd", "--seed", str(seed),
                "--duration", "0.5", "--out", str(tmp_path / "tuned"))
    assert r.returncode in (0, 1), r.stderr
    got = json.loads((tmp_path / "tuned" / "run.json").read_text())["results"]
    assert got == json.loads((tmp_path / "pd" / "run.json").read_text())["results"]


def test_study_options_need_a_scenario(tmp_path: Path) -> None:
    r = _armctl("hil", "--seed", "3", "--out", str(tmp_path / "x"))
    assert r.returncode == 2 and "give --scenario" in r.stderr
    r = _armctl("hil", "--scenario", "nowhere", "--out", str(tmp_path / "x"))
    assert r.returncode == 2 and "--scenario nowhere: not in" in r.stderr
    r = _armctl("hil", "--scenario", "ideal", "--tuned", "pm-paper-weights", "--out", str(tmp_path / "x"))
    assert r.returncode == 2 and "is not tuned" in r.stderr
    for method in ("pm", "pd"):  # a tuned method's knobs are the tuning's: none given is a usage error, not a crash
        r = _armctl("hil", "--scenario", "ideal", "--method", method, "--out", str(tmp_path / "x"))
        assert r.returncode == 2 and f"{method} is tuned; give --tuned {method}" in r.stderr, r.stderr
        assert "Traceback" not in r.stderr and not (tmp_path / "x").exists()
