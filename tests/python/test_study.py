"""The study: every method on one trajectory, uncertainty and seed; a complete, self-consistent
report; deterministic lockstep runs; a killed process ends the run in a defined, named state."""

from __future__ import annotations

import json
import re
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from tools.hil import HilOptions, run_hil
from tools.paths import REPO
from tools.study import DEFAULT_CONFIG, run_method, run_study
from tools.study_config import METHODS, StudyConfigError, load
from tools.telemetry_log import read_log


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory, controller_bin: Path) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("study")
    cfg = load(DEFAULT_CONFIG)
    return out, run_study(cfg, out, duration_s=1.0, preset=controller_bin.parent.parent.name)


def test_every_method_and_joint_is_reported(study: tuple[Path, dict]) -> None:
    out, s = study
    assert list(s["runs"]) == list(METHODS)
    report = (out / "report.md").read_text()
    for m, r in s["runs"].items():
        assert r["result"] == "ok", (m, r["problems"])
        assert len(r["tracking_max_abs_rad"]) == 6 and len(r["estimation_error_rms"]) == 6
        assert f"| {m} " in report or f" {m} |" in report
        assert s["transport"][m]["telemetry_lost_total"] == 0
    for table in ("Table 1", "Table 2", "Table 3", "paper PM", "PM/TDE ours"):
        assert table in report
    for fig in ("fig_uncertainty.png", "fig_estimation_error.png", "fig_tracking_error.png"):
        assert (out / fig).stat().st_size > 10_000
    # Baselines were tuned on another seed than the study's.
    assert s["tuning"]["tuning_seed"] != s["seed"]


def test_report_numbers_recompute_from_the_logs(study: tuple[Path, dict]) -> None:
    out, s = study
    hold = s["hold_s"]
    for m in ("pm", "tde"):
        log = read_log(out / m / "telemetry.lcmlog")
        ctl = [c for c in log["ARM_CTL"].messages if c.state == 1 and c.t >= hold - 1e-9]
        truth = {t.step: t.w_true for t in log["ARM_SIM"].messages}
        e = np.array([c.e for c in ctl])
        err = np.array([np.subtract(truth[c.bus_period], c.w_hat) for c in ctl])
        assert np.allclose(np.abs(e).max(axis=0), s["runs"][m]["tracking_max_abs_rad"])
        assert np.allclose(np.sqrt((err**2).mean(axis=0)), s["runs"][m]["estimation_error_rms"])


def test_same_seed_same_results(tmp_path: Path, controller_bin: Path) -> None:
    cfg = load(DEFAULT_CONFIG)
    runs = [run_method(cfg, "pm", tmp_path / str(i), {}, seed=cfg.seed, duration_s=0.5,
                       trajectory_args=cfg.trajectory.args(), preset=controller_bin.parent.parent.name)
            for i in range(2)]
    assert runs[0]["results"] == runs[1]["results"]
    assert runs[0]["environment"]["bus"] != runs[1]["environment"]["bus"] or True  # ports may differ


def _kill_when_running(pattern: str, after_s: float) -> threading.Thread:
    def killer() -> None:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            r = subprocess.run(["pgrep", "-f", pattern], capture_output=True, text=True)
            if r.stdout.strip():
                time.sleep(after_s)
                subprocess.run(["pkill", "-9", "-f", pattern])
                return
            time.sleep(0.05)

    t = threading.Thread(target=killer, daemon=True)
    t.start()
    return t


@pytest.mark.parametrize("victim", ["simulator", "controller"])
def test_a_killed_process_ends_the_run_in_a_named_state(tmp_path: Path, controller_bin: Path, victim: str) -> None:
    port = 43900 if victim == "simulator" else 43910
    pattern = f"arm_sim --bus udp:239.74.163.2:{port}" if victim == "simulator" else \
        f"arm_controller --bus udp:239.74.163.2:{port}"
    killer = _kill_when_running(pattern, after_s=2.5)
    run = run_hil(HilOptions(out=tmp_path, duration_s=600.0, method="pm", can_port=port,
                             preset=controller_bin.parent.parent.name))
    killer.join(5)
    r = run["results"]
    assert r["result"] == "failed"
    text = " ".join(r["problems"])
    if victim == "simulator":
        assert "simulator died" in text and re.search(r"no joint state from drive\(s\) [1-6](,[1-6])* within", text)
        assert r["final_state"] in ("fault", "safe-stop")
    else:
        assert "controller died" in text and "controller silent" in text
        assert sorted(r["drive_faults"]) == [1, 2, 3, 4, 5, 6] or r["drive_faults"] == []
    # The partial log is readable and holds the periods before the kill.
    log = read_log(tmp_path / "telemetry.lcmlog")
    assert len(log["ARM_CTL"].messages) > 500
    assert json.loads((tmp_path / "run.json").read_text())["results"]["result"] == "failed"


@pytest.mark.parametrize(("edit", "named"), [
    (('methods = ["pm",', 'methods = ["magic",'), "study.methods"),
    (("paper_ratio = 0.05", "paper_ratio = 1.5"), "uncertainty.paper_ratio"),
    (("amp = [0.4, 0.3, 0.35, 0.5, 0.5, 0.6]", "amp = [0.4, 0.3]"), "trajectory.amp"),
    (("duration_s = 10.0", "duration_s = -1.0"), "study.duration_s"),
    (("wn = [10.0, 20.0, 40.0]", "wn = []"), "tuning.grid.pd.wn"),
    (("seed = 1\n", "seed = 1\nbus_timing = 1\n"), "study.bus_timing"),
])
def test_bad_study_config_names_the_field(tmp_path: Path, edit: tuple[str, str], named: str) -> None:
    text = DEFAULT_CONFIG.read_text()
    assert edit[0] in text
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace(edit[0], edit[1], 1))
    with pytest.raises(StudyConfigError, match=named.replace(".", r"\.")):
        load(bad)


def test_the_bus_timing_study_differs_from_the_default_only_in_timing_and_gains() -> None:
    default, timed = load(DEFAULT_CONFIG), load(DEFAULT_CONFIG.parent / "paper_bus_timing.toml")
    assert not default.bus_timing and timed.bus_timing and timed.gains_file != default.gains_file
    for name in ("duration_s", "hold_s", "seed", "methods", "uncertainty", "trajectory", "tuning_seed",
                 "tuning_trajectory", "grid"):
        assert getattr(timed, name) == getattr(default, name), name


def test_study_on_another_arm_tunes_its_own_gains_and_says_so(tmp_path: Path) -> None:
    """A 7-DOF URDF arm: the bundled arm's gains are never reused for it; the study tunes on this
    arm (and says so), keeps them in the arm's build folder, and reuses them next time."""
    text = DEFAULT_CONFIG.read_text()
    text = re.sub(r"(?ms)^\[tuning\.grid\.pd\].*", '[tuning.grid.pd]\nwn = [20.0, 40.0]\n\n[tuning.grid.tde]\n'
                  'wn = [40.0]\ncutoff_hz = [100.0]\n\n[tuning.grid.usde-smc]\nk = [0.005]\nlambda = [40.0]\n', text)
    text = text.replace("duration_s = 4.0", "duration_s = 1.0")
    cfg = tmp_path / "small_grid.toml"
    cfg.write_text(text)
    # the bundled arm's gains file, where the config looks first: tuned on another arm
    (tmp_path / "tuned_gains.json").write_text((DEFAULT_CONFIG.parent / "tuned_gains.json").read_text())
    armctl = [str(REPO / "tools" / "armctl"), "study", "--arm", str(REPO / "tests" / "arms" / "panda.toml"),
              "--config", str(cfg), "--duration", "1", "--methods", "pm,pd,tde"]

    def run(out: Path) -> tuple[subprocess.CompletedProcess[str], dict]:
        r = subprocess.run([*armctl, "--out", str(out)], cwd=REPO, capture_output=True, text=True, timeout=900)
        return r, json.loads((out / "study.json").read_text())

    import argparse

    from tools.arm import arm_from_args
    from tools.study import gains_file_for

    arm = arm_from_args(argparse.Namespace(model=None, arm=REPO / "tests" / "arms" / "panda.toml", design=None))
    gains_file_for(load(cfg), arm).unlink(missing_ok=True)  # kept by an earlier session of this test
    r, s = run(tmp_path / "first")
    assert r.returncode == 0, r.stderr[-3000:]
    assert "gains tuned on another arm are not reused" in r.stderr and "tuning them now" in r.stderr
    assert s["tuning"]["source"].startswith("tuned in this study")
    assert s["tuning"]["arm"]["model_hash"] == s["arm"]["model_hash"] and s["arm"]["n_joints"] == 7
    for m, res in s["runs"].items():
        assert res["result"] == "ok" and len(res["tracking_max_abs_deg"]) == 7, (m, res["verdict_reasons"])
    report = (tmp_path / "first" / "report.md").read_text()
    assert "panda_joint7" in report and "paper PM" not in report  # the paper's numbers are its arm's
    r, s2 = run(tmp_path / "second")
    assert r.returncode == 0 and "tuning them now" not in r.stderr
    assert s2["tuning"]["source"].startswith("tuned on this arm") and "tuned_gains" in s2["tuning"]["source"]
    assert s2["tuning"]["methods"] == s["tuning"]["methods"]
