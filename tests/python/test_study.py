"""The study: every method tuned alike in every scenario, over seeds; a complete, self-consistent
report; the same numbers whatever --jobs; resumed where it stopped; a killed process ends the run
in a defined, named state; config errors name the field."""

from __future__ import annotations

import json
import math
import platform
import re
import shutil
import signal
import socket
import subprocess
import threading
import time
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import pytest

from study_configs import with_tuning
from tools.run.hil import HilOptions, run_hil
from gen.lib.paths import REPO
from tools.study import DEFAULT_CONFIG, run_study
from tools.study.config import METHODS, StudyConfigError, load
from tools.run.slots import Slot
from tools.run.telemetry_log import read_log

pytestmark = pytest.mark.long  # minutes: studies over the bus, stopped and resumed

SMALL = {"methods": '["pm", "pm-paper-weights", "tde"]', "scenarios": '["ideal", "realistic"]'}


def small_config(dirpath: Path, seeds: int = 2, methods: str = SMALL["methods"],
                 scenarios: str = SMALL["scenarios"]) -> Path:
    """The default study made small: three methods, two scenarios, two trials each, short runs."""
    text = DEFAULT_CONFIG.read_text()
    text = re.sub(r"(?m)^methods = .*$", f"methods = {methods}", text)
    text = re.sub(r"(?m)^scenarios = .*$", f"scenarios = {scenarios}", text)
    text = re.sub(r"(?m)^seeds = \d+ .*$", f"seeds = {seeds}", text)
    for key, value in (("cap", 2), ("batch", 2), ("widen", 0)):  # (a line may end in a comment)
        text, n = re.subn(rf"(?m)^{key} = \d+(\s*#.*)?$", f"{key} = {value}", text)
        assert n == 1, f"the default config's [tuning] {key} line"
    text = with_tuning(text, duration_s=0.5)  # the tuning runs' length, not the study's
    dirpath.mkdir(parents=True, exist_ok=True)
    cfg = dirpath / "small.toml"
    cfg.write_text(text)
    return cfg


def kept_config(dirpath: Path, seeds: int = 2, methods: str = SMALL["methods"],
                scenarios: str = SMALL["scenarios"]) -> Path:
    """The default study with fewer methods, scenarios and seeds, and the kept tuning beside it (its
    [tuning] as it is: the same tuning keys): the study runs the kept, verified picks and tunes
    nothing (tests/python/test_tuning_verify.py holds the kept tuning to the code)."""
    text = DEFAULT_CONFIG.read_text()
    text = re.sub(r"(?m)^methods = .*$", f"methods = {methods}", text)
    text = re.sub(r"(?m)^scenarios = .*$", f"scenarios = {scenarios}", text)
    text = re.sub(r"(?m)^seeds = \d+ .*$", f"seeds = {seeds}", text)
    dirpath.mkdir(parents=True, exist_ok=True)
    cfg = dirpath / DEFAULT_CONFIG.name
    cfg.write_text(text)
    kept = load(DEFAULT_CONFIG).tuning_file
    shutil.copyfile(kept, dirpath / kept.name)
    return cfg


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict, Path]:
    base = tmp_path_factory.mktemp("study")
    cfg_path = kept_config(base / "cfg")
    out = base / "jobs2"
    return out, run_study(load(cfg_path), out, duration_s=0.5, jobs=2), cfg_path


def test_every_method_scenario_and_seed_is_reported(study: tuple[Path, dict, Path]) -> None:
    out, s, _ = study
    assert list(s["scenarios"]) == ["ideal", "realistic"] and s["seeds"] == [1, 2]
    report = (out / "report.md").read_text()
    for name, sc in s["scenarios"].items():
        assert f"## Scenario `{name}`" in report
        for m in ("pm", "pm-paper-weights", "tde"):
            assert len(sc["runs"][m]) == 2 and all(r["result"] is not None for r in sc["runs"][m])
            # a run the safety layer stopped before its trajectory has no metrics: counted, not averaged
            measured = sum(1 for r in sc["runs"][m] if r.get("tracking_max_abs_rad"))
            for metric in ("linf", "rms", "est"):
                joints = sc["stats"][m][metric]["per_joint"]
                assert len(joints) == 6 and all(j["n"] == measured and j["missing"] == 2 - measured for j in joints)
                if measured == 2:
                    assert all(j["ci95"][0] <= j["mean"] <= j["ci95"][1] for j in joints)
            assert sc["stats"][m]["power"]["total"]["n"] == measured
            if m != "pm-paper-weights":  # the tuned ones run their whole trajectory here
                assert measured == 2, (name, m, [r["verdict_reasons"] for r in sc["runs"][m]])
        for b in ("pm-paper-weights", "tde"):
            comp = sc["pm_versus"][b]["linf"]
            assert len(comp["per_joint"]) == 6 and comp["total"]["n"] + comp["total"]["excluded"] == 2
            assert {"a_lower", "ratio_of_means", "t_test_p", "wilcoxon_p"} <= set(comp["total"])
    assert report.count("### Verdict") == 2 and "The paper's claims" in report
    for fig in ("fig_distribution_ideal.png", "fig_distribution_realistic.png", "fig_uncertainty_ideal.png",
                "fig_tracking_error_ideal.png", "fig_tracking_error_realistic.png"):
        assert (out / fig).stat().st_size > 10_000


def test_every_tuned_method_has_its_tuning_record(study: tuple[Path, dict, Path]) -> None:
    """pm is tuned like the baselines (its synthesis weights); every trial is recorded; the
    paper's own weights stay as a variant; the kept tuning is used, nothing tuned again."""
    _, s, cfg_path = study
    for sc in s["scenarios"].values():
        assert set(sc["tuning"]) == {"pm", "tde"}  # pm-paper-weights is not tuned
        for m, rec in sc["tuning"].items():
            assert rec["source"] == f"tuned earlier, kept in {load(cfg_path).tuning_file}", rec["source"]
            trials = [t for r in rec["rounds"] for t in r["trials"]]
            assert len(trials) == rec["trials_run"] and all("knobs" in t and "objective" in t for t in trials)
            assert rec["best_by_objective"]["objective"] == min(t["objective"] for t in trials)
            assert rec["status"] in ("converged", "capped") and len(rec["best_so_far"]) == rec["trials_run"]
            assert rec["validation"]["seeds"] == load(study[2]).validation_seeds
        assert set(sc["tuning"]["pm"]["knobs"]) == {"form", "wn", "zeta", "H", "f_bw"}
        assert sc["tuning"]["pm"]["design_text"].startswith('description = "tuned:')
    assert s["tuning_procedure"].startswith("Optuna TPE")


def test_report_numbers_recompute_from_the_logs(study: tuple[Path, dict, Path]) -> None:
    out, s, _ = study
    hold = s["hold_s"]
    sc = s["scenarios"]["ideal"]
    for m in ("pm", "tde"):
        log = read_log(out / "ideal" / m / "seed-1" / "telemetry.lcmlog")
        ctl = [c for c in log["ARM_CTL"].messages if c.state == 1 and c.t >= hold - 0.0005]
        truth = {t.step: t.w_true for t in log["ARM_SIM"].messages}
        e = np.array([c.e for c in ctl])
        err = np.array([np.subtract(truth[c.bus_period], c.w_hat) for c in ctl])
        assert np.allclose(np.abs(e).max(axis=0), sc["runs"][m][0]["tracking_max_abs_rad"])
        assert np.allclose(np.sqrt((err**2).mean(axis=0)), sc["runs"][m][0]["estimation_error_rms"])
        assert np.isclose(sc["stats"][m]["linf"]["per_joint"][0]["mean"],
                          np.mean([r["tracking_max_abs_rad"][0] for r in sc["runs"][m]]))


def test_same_numbers_whatever_jobs(study: tuple[Path, dict, Path], tmp_path: Path) -> None:
    """One job instead of two (the kept tuning, the same runs): identical statistics."""
    _, s2, cfg_path = study
    s1 = run_study(load(cfg_path), tmp_path, duration_s=0.5, jobs=1, figures=False)
    for name in s2["scenarios"]:
        assert s1["scenarios"][name]["stats"] == s2["scenarios"][name]["stats"]
        assert s1["scenarios"][name]["pm_versus"] == s2["scenarios"][name]["pm_versus"]


def test_tuning_is_the_same_whatever_jobs(tmp_path: Path) -> None:
    from tools.build.arm import DEFAULT_ARM
    from tools.study import setup_for
    from tools.study.tuning import tune_method

    cfg = load(small_config(tmp_path))
    recs = []
    for jobs in (2, 3):  # batches of min(batch, --jobs): the same at any --jobs of at least the batch (2)
        setup, _, _ = setup_for(cfg, DEFAULT_ARM, tmp_path / f"tune{jobs}", jobs, None)
        recs.append([tune_method(setup, cfg.scenarios["ideal"], "pm", trials=3)])  # one pair, a short budget
    for a, b in zip(*recs):
        assert a["knobs"] == b["knobs"] and a["objective"] == b["objective"]
        assert [t["objective"] for t in a["rounds"][0]["trials"]] == [t["objective"] for t in b["rounds"][0]["trials"]]


def test_an_interrupted_study_resumes_and_redoes_only_what_is_missing(study: tuple[Path, dict, Path],
                                                                     tmp_path: Path) -> None:
    out, s, cfg_path = study
    copy = tmp_path / "resume"
    shutil.copytree(out, copy)
    lost = copy / "realistic" / "tde" / "seed-2"
    (lost / "run.json").unlink()
    kept = copy / "ideal" / "pm" / "seed-1" / "run.json"
    before = kept.stat().st_mtime_ns
    again = run_study(load(cfg_path), copy, duration_s=0.5, jobs=2, figures=False)
    assert kept.stat().st_mtime_ns == before  # not run again
    assert (lost / "run.json").exists()
    assert again["scenarios"]["realistic"]["stats"] == s["scenarios"]["realistic"]["stats"]


ARMCTL = str(REPO / "tools" / "armctl")


def _study_cmd(out: Path) -> list[str]:
    # The bundled arm's kept tuning of pd and usde-smc: nothing is tuned, and no design is built into a
    # run slot (stopping a build is not what these tests do). 8 s runs in lockstep HIL: at least 0.8 s
    # each (about 10x real time at best; in software in the loop 0.1 s), long enough to be stopped
    # in the middle of one; three processes a run, each of which must end with armctl.
    return [ARMCTL, "study", "--methods", "pd,usde-smc", "--scenarios", "ideal", "--seeds", "2", "--duration", "8",
            "--jobs", "1", "--bus", "udp", "--no-figures", "--out", str(out)]


def _left_running(out: Path) -> list[str]:
    """This study's processes still alive (their command lines name its folder)."""
    r = subprocess.run(["pgrep", "-af", str(out)], capture_output=True, text=True)
    return [ln for ln in r.stdout.splitlines() if "pgrep" not in ln]


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory: pytest.TempPathFactory) -> tuple[subprocess.CompletedProcess[str], dict]:
    """2 methods, 1 scenario, 2 seeds, run through once."""
    whole = tmp_path_factory.mktemp("resume") / "whole"
    r = subprocess.run(_study_cmd(whole), cwd=REPO, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0 and (whole / "study.json").exists(), r.stderr[-3000:]
    return r, json.loads((whole / "study.json").read_text())


@pytest.mark.parametrize(("sig", "nth"), [(signal.SIGINT, 1), (signal.SIGKILL, 2)], ids=["SIGINT", "SIGKILL"])
def test_a_study_stopped_by_a_signal_resumes_to_the_same_numbers(uninterrupted, tmp_path: Path,  # noqa: ANN001
                                                                 sig: signal.Signals, nth: int) -> None:
    """Stopped in the middle of usde-smc's nth run, then run again: the stopped run is not kept, is run
    again, and study.json has the numbers of the study run through once; after SIGKILL, which
    armctl cannot catch, its controller, simulator and logger end too (PR_SET_PDEATHSIG)."""
    whole, ref = uninterrupted
    out = tmp_path / "study"
    p = subprocess.Popen(_study_cmd(out), cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    stopped: Path | None = None
    while time.monotonic() < deadline and p.poll() is None and stopped is None:
        # --jobs 1: usde-smc's nth run in flight (started, no run.json yet) once nth - 1 are done (its runs
        # last 0.8 s to 2 s); a folder's mtime would not do, since a run that is finishing touches its
        # folder last
        try:
            runs = list(out.glob("*/usde-smc/seed-*"))
        except FileNotFoundError:  # armctl's check of --out makes the folder and removes it again
            runs = []
        done = [r for r in runs if (r / "spec.json").exists()]
        flying = [r for r in runs if (r / "controller.log").exists() and not (r / "run.json").exists()]
        if len(done) >= nth - 1 and flying:
            stopped = flying[0]
        else:
            time.sleep(0.01)
    assert stopped is not None, "the study never reached its run in flight"
    time.sleep(0.3)  # into the run
    p.send_signal(sig)
    _, err = p.communicate(timeout=120)
    assert p.returncode == (128 + sig if sig != signal.SIGKILL else -sig), err
    assert "Traceback" not in err
    deadline = time.monotonic() + 5  # they stop in about 1 s (the controller waits for the dead simulator)
    while _left_running(out) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _left_running(out)
    assert not (stopped / "spec.json").exists()  # never taken for done
    r = subprocess.run(_study_cmd(out), cwd=REPO, capture_output=True, text=True, timeout=900)
    assert r.returncode == whole.returncode, r.stderr[-3000:]
    assert f"{stopped}: running it again" in r.stderr
    again = json.loads((out / "study.json").read_text())
    for name, sc in ref["scenarios"].items():
        for part in ("runs", "stats", "pm_versus"):
            assert again["scenarios"][name][part] == sc[part], (name, part)


def _fake_runs_falling_with_wn(monkeypatch: pytest.MonkeyPatch) -> None:
    """An in-process stand-in for the HIL runs whose objective keeps falling as wn grows."""
    from tools.study import tuning

    def fake_run_all(specs, jobs, cluster):  # noqa: ANN001, ANN202
        out = []
        for sp in specs:
            wn, zeta = sp.labels["knobs"]["wn"], sp.labels["knobs"]["zeta"]
            out.append({"results": {"result": "ok", "tracking_max_abs_rad": [math.exp(-wn / 5) * (1 + abs(zeta - 1))] * 6}})
        return out

    monkeypatch.setattr(tuning, "run_all", fake_run_all)


def test_tuning_widens_a_range_whose_best_is_at_its_edge(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An objective that keeps falling as wn grows, on an arm without a resonance to stop it: the
    best lands on the range's top, the range is widened tenfold and the budget runs again, and the
    record says so."""
    from dataclasses import replace

    from tools.study import setup_for, tuning
    from tools.build.arm import DEFAULT_ARM

    _fake_runs_falling_with_wn(monkeypatch)
    cfg = load(small_config(tmp_path))
    cfg.widen, cfg.plateau = 1, 12
    cfg.validation_seeds = []
    setup, _, _ = setup_for(cfg, DEFAULT_ARM, tmp_path / "t", 1, None)
    setup = replace(setup, resonance_hz=math.inf)
    setup.cfg.spaces["pd"] = replace(setup.cfg.spaces["pd"], ranges={"wn": (2.0, 300.0), "zeta": (0.1, 2.0)},
                                     ceilings={})
    rec = tuning.tune_method(setup, setup.cfg.scenarios["ideal"], "pd", trials=60)
    assert len(rec["rounds"]) == 2
    assert rec["rounds"][0]["at_edge"] == {"wn": "high"} and rec["rounds"][1]["ranges"]["wn"] == [2.0, 3000.0]
    assert rec["knobs"]["wn"] > 300 and "still at the edge" in rec["edge_note"]


def test_tuning_never_widens_past_the_arms_first_resonance(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The same objective on the bundled arm: wn's range ends at the first resonance, a best at
    that end is not widened, and no pick's closed-loop bandwidth reaches the resonance."""
    from tools.study import setup_for, tuning
    from tools.build.arm import DEFAULT_ARM

    _fake_runs_falling_with_wn(monkeypatch)
    cfg = load(small_config(tmp_path))
    cfg.widen, cfg.plateau = 1, 12
    cfg.validation_seeds = []
    setup, info, _ = setup_for(cfg, DEFAULT_ARM, tmp_path / "t", 1, None)
    omega = 2 * math.pi * info["first_resonance_hz"]
    assert setup.cfg.spaces["pd"].ranges["wn"] == (2.0, omega)
    rec = tuning.tune_method(setup, setup.cfg.scenarios["ideal"], "pd", trials=40)
    assert len(rec["rounds"]) == 1 and "wn" not in rec["rounds"][0]["at_edge"]
    assert rec["bandwidth_hz"] < info["first_resonance_hz"] == rec["resonance_hz"]
    refused = [t for r in rec["rounds"] for t in r["trials"] if (t["failed"] or "").startswith("its closed-loop")]
    assert refused and all(t["bandwidth_hz"] >= info["first_resonance_hz"] for t in refused)


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
def test_a_killed_process_ends_the_run_in_a_named_state(tmp_path: Path, controller_bin: Path, victim: str,
                                                        slot: Slot) -> None:
    port = slot.can_port  # the killer's pattern names this run's processes alone
    pattern = f"arm_sim --bus udp:239.74.163.2:{port}" if victim == "simulator" else \
        f"arm_controller --bus udp:239.74.163.2:{port}"
    killer = _kill_when_running(pattern, after_s=2.5)
    run = run_hil(HilOptions(out=tmp_path, duration_s=600.0, method="pm", can_port=port, lcm_port=slot.lcm_port,
                             preset=controller_bin.parent.parent.name))
    killer.join(5)
    r = run["results"]
    assert r["result"] == "failed"
    text = " ".join(r["problems"])
    if victim == "simulator":
        assert "simulator died" in text and re.search(r"no joint state from drive\(s\) [1-6](,[1-6])* within", text)
        assert r["final_state"] in ("fault", "safe-stop")
    else:
        # the drives' word for it: the arm protocol's "controller silent", CANopen's "master silent"
        assert "controller died" in text and ("controller silent" in text or "master silent" in text)
        assert sorted(r["drive_faults"]) == [1, 2, 3, 4, 5, 6] or r["drive_faults"] == []
    # The partial log is readable and holds the periods before the kill.
    log = read_log(tmp_path / "telemetry.lcmlog")
    assert len(log["ARM_CTL"].messages) > 500
    assert json.loads((tmp_path / "run.json").read_text())["results"]["result"] == "failed"


@pytest.mark.parametrize(("edit", "named"), [
    (('methods = ["pm",', 'methods = ["magic",'), "study.methods"),
    (("paper_ratio = 0.05, paper_knot_s = 0.05 }\ndrives = \"ideal\"", "paper_ratio = 1.5 }\ndrives = \"ideal\""),
     "scenario.ideal.uncertainty.paper_ratio"),
    (('drives = "ideal"', 'drives = "fancy"'), "scenario.ideal.drives"),
    (('drives = "ideal"', "drives = { encoder_bits = 99 }"), "scenario.ideal.drives.encoder_bits"),
    (("amp = [0.4, 0.3, 0.35, 0.5, 0.5, 0.6]", "amp = [0.4, 0.3]"), "trajectory.amp"),
    (("duration_s = 10.0", "duration_s = -1.0"), "study.duration_s"),
    (('wn = [2.0, "first_resonance"]', "wn = []"), "tuning.space.pm.wn"),
    (('wn = [2.0, "first_resonance"]', 'wn = ["first_resonance", 2.0]'), "tuning.space.pm.wn"),
    (("robust_stiffness = [0.8, 1.2]", "robust_stiffness = [0.8, 3.0]"), "tuning.robust_stiffness[1]"),
    (('payload_kg = "rated"', 'payload_kg = "heavy"'), "uncertainty.payload_kg"),
    (("zeta = [1.0, 2.0]", "zeta = [0.5, 2.0]"), "tuning.space.usde-smc.zeta"),
    (("H = [0.05, 5.0]", "H = [5.0, 0.05]"), "tuning.space.pm.H"),
    (("cap = 400", "cap = 0"), "tuning.cap"),
    (("study_tuning_cap = 24", "study_tuning_cap = 0"), "study.study_tuning_cap"),
    (("seeds = [1001, 1002, 1003, 1004]", "seeds = [1, 1002]"), "tuning.seeds"),
    (("validation_seeds = [2001, 2002]", "validation_seeds = [1001]"), "tuning.validation_seeds"),
    (('scenarios = ["ideal",', 'scenarios = ["windy",'), "study.scenarios"),
    (("seed = 1 ", "colour = 1\nseed = 1 "), "study: unknown field"),
])
def test_bad_study_config_names_the_field(tmp_path: Path, edit: tuple[str, str], named: str) -> None:
    text = DEFAULT_CONFIG.read_text()
    assert edit[0] in text, edit[0]
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace(edit[0], edit[1], 1))
    with pytest.raises(StudyConfigError, match=re.escape(named)):
        load(bad)


def test_default_config_tunes_every_method_but_the_papers_weights() -> None:
    cfg = load(DEFAULT_CONFIG)
    assert set(cfg.methods) == set(METHODS)
    assert set(cfg.spaces) == {m for m in METHODS if m != "pm-paper-weights"}
    assert list(cfg.scenarios) == ["ideal", "realistic", "realistic+payload", "realistic+friction+parameter-error"]
    assert cfg.scenarios["ideal"].drives.ideal and not cfg.scenarios["realistic"].drives.ideal
    # a real arm's: flexible joints, CiA 402, a payload the model lacks; the paper's own: rigid, ideal
    assert all(sc.protocol == "canopen" for sc in cfg.scenarios.values())
    assert [bool(sc.uncertainty.get("flexible")) for sc in cfg.scenarios.values()] == [False, True, True, True]
    assert cfg.scenarios["realistic+payload"].per_joint["payload_kg"] == "rated"
    assert all(sp.to_resonance == ({"wn", "f_bw"} if "f_bw" in sp.ranges else {"wn"}) for sp in cfg.spaces.values())
    with pytest.raises(StudyConfigError, match="tuning seed"):
        cfg.seed_list(2000)


def test_the_kept_tuning_serves_this_checkout(tmp_path: Path) -> None:
    """The committed tuning is reused by `armctl demo` and `study` on any clone, wherever it lies
    (its key once held the checkout's path, and a fresh clone retuned for 20 minutes)."""
    from tools.build.arm import DEFAULT_ARM, build_arm
    from tools.study import setup_for, tuning_file, tuning_key

    build_arm("release", DEFAULT_ARM)
    cfg = load(DEFAULT_CONFIG)
    setup, info, _ = setup_for(cfg, DEFAULT_ARM, tmp_path, 1, None)
    kept = json.loads(tuning_file(cfg, DEFAULT_ARM).read_text())["scenarios"]
    for s in cfg.scenarios:
        for m in cfg.methods:
            if METHODS[m][1] is None:
                continue
            assert kept[s][m]["key"] == tuning_key(cfg, info, setup, s, m), \
                f"the kept tuning of {m} in {s} does not match this checkout: run tools/armctl tune"
            assert kept[s][m]["cap"] == cfg.cap
    moved = setup.base_design.replace(str(REPO), "/elsewhere/checkout")
    assert moved != setup.base_design  # the design's header comment names the checkout's path ...
    setup.base_design = moved
    assert tuning_key(cfg, info, setup, "ideal", "pm") == kept["ideal"]["pm"]["key"]  # ... and the key ignores it


def test_a_study_reuses_a_longer_kept_tuning_and_tunes_what_is_missing_with_its_own_cap(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`armctl tune` tunes to [tuning] cap (400); a study takes any kept tuning of at least
    study_tuning_cap trials and tunes only what is missing, with study_tuning_cap (a new arm's study
    then finishes in minutes). tune_method is replaced: only the choice of what to tune is tested."""
    import tools.study.pairs as pairs_mod
    from tools.build.arm import DEFAULT_ARM, build_arm
    from tools.study import keep_tuning, setup_for, tuned, tuning_file, tuning_key

    build_arm("release", DEFAULT_ARM)
    cfg_path = tmp_path / "paper.toml"
    cfg_path.write_text(DEFAULT_CONFIG.read_text().replace("study_tuning_cap = 24", "study_tuning_cap = 3"))
    cfg = load(cfg_path)
    assert (cfg.cap, cfg.study_cap) == (400, 3)
    setup, info, _ = setup_for(cfg, DEFAULT_ARM, tmp_path / "tune", 1, None)
    path = tuning_file(cfg, DEFAULT_ARM)
    keep_tuning(path, "ideal", "pm", {"key": tuning_key(cfg, info, setup, "ideal", "pm"), "cap": cfg.cap,
                                      "knobs": {"wn": 1.0}, "trials_run": 100}, {})
    asked: list[tuple[str, int | None]] = []

    def fake_tune(setup_, scenario, method, trials=None, progress=None, key=""):  # noqa: ANN001, ANN202
        asked.append((method, trials))
        return {"cap": trials, "trials_run": trials, "knobs": {"wn": 2.0}}

    monkeypatch.setattr(pairs_mod, "tune_method", fake_tune)
    got = tuned(cfg, DEFAULT_ARM, setup, info, ["ideal"], ["pm", "tde"], in_study=True)
    assert asked == [("tde", 3)] and got["ideal"]["pm"]["knobs"] == {"wn": 1.0}
    asked.clear()
    got = tuned(cfg, DEFAULT_ARM, setup, info, ["ideal"], ["pm", "tde"])  # armctl tune: the config's cap
    assert asked == [("tde", cfg.cap)] and got["ideal"]["pm"]["cap"] == cfg.cap


def test_a_failed_trial_scores_by_how_much_it_ran() -> None:
    """No ties: failed trials rank by what they achieved (coverage, tracking over the part they
    ran, time at the limit, failed seeds), always behind any trial that ended well."""
    from tools.study.tuning import FAILED_SCORE, REFUSED_SCORE, objective

    def run(result: str, ran: int, err: float = 0.01, sat: float = 0.0) -> dict:
        return {"results": {"result": result, "tracking_max_abs_rad": [err] * 6, "trajectory_periods": 4000,
                            "periods_running": ran, "saturated_fraction": [sat] * 6,
                            "verdict_reasons": [f"{result}: why"]}}

    good, _ = objective([run("ok", 4000), run("tracking-bound-exceeded", 4000, 0.6)])
    assert good == pytest.approx(3.6)  # the worst seed's: gains that hold on one seed only do not win
    late, why = objective([run("ok", 4000), run("failed", 3000)])
    early, _ = objective([run("failed", 1000), run("ok", 4000)])
    assert FAILED_SCORE <= late < early < REFUSED_SCORE and good < FAILED_SCORE and why == "failed: why"
    # torque-limited over the whole trajectory: the better tracker, then the less saturated, scores better
    tl = [objective([run("torque-limited", 4000, err, sat), run("ok", 4000)])[0]
          for err, sat in ((0.40, 0.3), (0.39, 0.3), (0.39, 0.2), (0.39, 0.1))]
    assert FAILED_SCORE < tl[3] < tl[2] < tl[1] < tl[0] < early
    assert len(set(tl)) == len(tl)
    # fewer failed seeds is better; a diverged (non-finite) error still ranks, below REFUSED_SCORE
    one = objective([run("torque-limited", 4000, 0.1, 0.1), run("ok", 4000, 0.1, 0.1)])[0]
    both = objective([run("torque-limited", 4000, 0.1, 0.1), run("torque-limited", 4000, 0.1, 0.1)])[0]
    assert one < both
    nan = objective([run("diverged", 10, float("nan")), run("diverged", 10, float("inf"))])[0]
    assert early < nan < REFUSED_SCORE
    # 200 random failed trials: distinct achievements, distinct scores
    rng = np.random.default_rng(0)
    scores = {objective([run(str(rng.choice(["torque-limited", "failed", "diverged"])), int(rng.integers(1, 4001)),
                             float(rng.uniform(0, 2)), float(rng.uniform(0, 1))), run("ok", 4000)])[0]
              for _ in range(200)}
    assert len(scores) == 200 and min(scores) > FAILED_SCORE


def test_tuning_runs_to_a_plateau_or_the_cap_and_validates_its_pick(tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """One rule: stop when the best improved by <= 1 % over the last `plateau` trials, else at the
    cap; batches no larger than --jobs; the best-so-far curve kept; a pick that fails a validation
    seed gives way to the next best, and the record says so; the SQLite storage resumes."""
    import optuna

    from tools.study import tuning
    from tools.build.arm import DEFAULT_ARM
    from tools.study import setup_for

    batches: list[int] = []

    def fake_run_all(specs, jobs, cluster):  # noqa: ANN001, ANN202
        batches.append(len({json.dumps(sp.labels["knobs"], sort_keys=True) for sp in specs}))
        out = []
        for sp in specs:
            wn, zeta = sp.labels["knobs"]["wn"], sp.labels["knobs"]["zeta"]
            bad = sp.labels["seed"] >= 2000 and wn > 250  # the best (highest wn) fails a validation seed
            out.append({"results": {"result": "torque-limited" if bad else "ok",
                                    "tracking_max_abs_rad": [1.0 / wn + abs(zeta - 1) / 100] * 6}})
        return out

    monkeypatch.setattr(tuning, "run_all", fake_run_all)
    cfg = load(small_config(tmp_path))
    cfg.widen, cfg.plateau, cfg.batch, cfg.cap = 0, 5, 4, 40
    cfg.validation_seeds = [2001, 2002]
    setup, _, _ = setup_for(cfg, DEFAULT_ARM, tmp_path / "t", 3, None)
    rec = tuning.tune_method(setup, cfg.scenarios["ideal"], "pd", key="k1")
    assert rec["batch"] == 3 and max(batches[:-3]) <= 3  # batches: at most --jobs
    curve = rec["best_so_far"]
    assert len(curve) == rec["trials_run"] <= 40 and all(a >= b for a, b in zip(curve, curve[1:]))
    if rec["status"] == "converged":
        assert curve[-6] - curve[-1] <= 0.01 * curve[-6]
    else:
        assert rec["trials_run"] == 40
    v = rec["validation"]
    assert v["seeds"] == [2001, 2002] and v["tried"]
    if rec["best_by_objective"]["knobs"]["wn"] > 250:
        assert v["picked_rank"] >= 1 and "next best" in v["note"] and rec["knobs"]["wn"] <= 250
    # the storage holds the study; tuning again resumes it: no new trial runs, the same record
    db = tmp_path / "t" / tuning.STORAGE
    assert db.exists()
    names = [s.study_name for s in optuna.get_all_study_summaries(storage=f"sqlite:///{db}")]
    assert any(n.startswith("ideal/pd/k1/") for n in names)
    batches.clear()
    again = tuning.tune_method(setup, cfg.scenarios["ideal"], "pd", key="k1")
    assert again["best_so_far"] == curve and again["knobs"] == rec["knobs"]
    assert sum(batches) == len(v["tried"])  # only the validation runs ran again
    # a cap the rule cannot reach: capped
    cfg.plateau = 1000
    capped = tuning.tune_method(setup, cfg.scenarios["ideal"], "pd", trials=7, key="k2")
    assert capped["status"] == "capped" and capped["trials_run"] == 7 and capped["cap"] == 7


def _keep_many(path: str, method: str, n: int) -> None:
    from tools.study import keep_tuning

    for i in range(n):
        keep_tuning(Path(path), f"scenario-{i}", method, {"knobs": {"k": i}, "pad": "x" * 20000}, {"procedure": method})


def test_two_tunings_at_once_keep_both(tmp_path: Path) -> None:
    """Two `armctl tune` of different methods at once, at the level where they share the file:
    each keeps its method in every scenario, merged under the lock, and neither loses the other's."""
    import multiprocessing

    path = tmp_path / "paper.tuning.json"
    ctx = multiprocessing.get_context("spawn")
    procs = [ctx.Process(target=_keep_many, args=(str(path), m, 40)) for m in ("pd", "tde")]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
        assert p.exitcode == 0
    doc = json.loads(path.read_text())
    assert sorted(doc["scenarios"]) == sorted(f"scenario-{i}" for i in range(40))
    assert all(set(s) == {"pd", "tde"} and s["pd"]["knobs"] == s["tde"]["knobs"] for s in doc["scenarios"].values())
    assert not list(tmp_path.glob(".*.tmp.*"))


def test_a_second_study_on_the_same_out_is_refused_in_one_line(tmp_path: Path) -> None:
    """Another study holds --out (its lock, taken here as that study would): this one waits
    OUT_LOCK_WAIT_S for it (a study killed a moment ago holds it while its workers end), then exits
    with one line naming the folder, and leaves the other's files alone."""
    from gen.lib.locks import flocked
    from tools.study import OUT_LOCK

    out = tmp_path / "out"
    cfg = small_config(tmp_path / "cfg", methods='["pd"]', scenarios='["ideal"]')
    (out / "ideal").mkdir(parents=True)
    with flocked(out / OUT_LOCK):
        r = subprocess.run([ARMCTL, "study", "--config", str(cfg), "--out", str(out), "--duration", "0.5"], cwd=REPO,
                           capture_output=True, text=True, timeout=300)
    assert r.returncode != 0
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and str(out) in lines[0] and "another study" in lines[0], r.stderr
    assert sorted(p.name for p in out.iterdir()) == [OUT_LOCK, "ideal"]
# ---- n joints everywhere ---------------------------------------------------------------------
FRICTION = "realistic+friction+parameter-error"
BUNDLED_VISCOUS = [2.0, 2.0, 1.5, 0.5, 0.5, 0.5]  # the recorded headline was made with these
BUNDLED_COULOMB = [3.0, 3.0, 2.0, 0.8, 0.8, 0.8]


def fake_arm(name: str, limits: list[float], rated_kg: float = 5.0, resonance_hz: float = 22.8) -> dict:
    """What for_arm reads of arm.json."""
    return {"name": name, "n_joints": len(limits), "joints": [{"torque_limit": x} for x in limits],
            "payload": {"rated_kg": rated_kg}, "first_resonance_hz": resonance_hz}


def test_the_payload_and_the_gain_ranges_are_made_for_the_arm() -> None:
    """payload "rated": uniform from 0 to the arm's rated payload; a range up to the first
    resonance ends at the arm's (rad/s), a ceiling no widening passes."""
    from tools.study.config import for_arm

    cfg = for_arm(load(DEFAULT_CONFIG), fake_arm("x", [50.0] * 6, rated_kg=3.0, resonance_hz=10.0))
    assert cfg.scenarios["realistic+payload"].uncertainty["payload_kg"] == [0.0, 3.0]
    assert "payload_kg" not in cfg.scenarios["realistic"].uncertainty
    assert cfg.spaces["pd"].ranges["wn"] == (2.0, pytest.approx(20 * math.pi))
    assert cfg.spaces["pd"].ceilings == {"wn": pytest.approx(20 * math.pi)}
    with pytest.raises(StudyConfigError, match="range .* is empty on this arm"):
        for_arm(load(DEFAULT_CONFIG), fake_arm("x", [50.0] * 6, resonance_hz=0.2))


def test_a_pick_must_hold_in_every_robust_corner() -> None:
    """The variants a pick is validated in: the scenario, then each gear stiffness with each end
    of the payload's range, only where the scenario has them."""
    from tools.study.config import for_arm
    from tools.study.tuning import robust_variants

    cfg = for_arm(load(DEFAULT_CONFIG), fake_arm("x", [50.0] * 6))
    assert robust_variants(cfg, cfg.scenarios["ideal"]) == [{}]
    assert robust_variants(cfg, cfg.scenarios["realistic"]) == [
        {}, {"gear_stiffness_scale": 0.8}, {"gear_stiffness_scale": 1.2}]
    assert robust_variants(cfg, cfg.scenarios["realistic+payload"]) == [
        {}, *[{"gear_stiffness_scale": k, "payload_kg": [p]} for k in (0.8, 1.2) for p in (0.0, 5.0)]]


def test_scenario_per_joint_values_take_n_from_the_arm(tmp_path: Path) -> None:
    from tools.study.config import for_arm

    cfg = load(DEFAULT_CONFIG)
    bundled = for_arm(cfg, fake_arm("ur5e_arm", [150, 150, 150, 28, 28, 28])).scenarios[FRICTION].uncertainty
    assert bundled["viscous"] == BUNDLED_VISCOUS and bundled["coulomb"] == BUNDLED_COULOMB
    panda = for_arm(cfg, fake_arm("panda", [87, 87, 87, 87, 12, 12, 12])).scenarios[FRICTION].uncertainty
    assert panda["viscous"] == pytest.approx([0.015 * x for x in [87] * 4 + [12] * 3])
    assert panda["coulomb"] == pytest.approx([0.02 * x for x in [87] * 4 + [12] * 3])
    with pytest.raises(RuntimeError, match="per-joint values are for an arm"):
        cfg.scenarios[FRICTION].as_dict()  # never run (or keyed) without them
    text = DEFAULT_CONFIG.read_text()
    old = "viscous = { for_arm = { ur5e_arm = [2.0, 2.0, 1.5, 0.5, 0.5, 0.5] }, torque_limit_fraction = 0.015 }"
    assert old in text
    for new, want in (("viscous = { each = 0.25 }", [0.25] * 7),
                      ("viscous = [1, 2, 3, 4, 5, 6, 7]", [1, 2, 3, 4, 5, 6, 7])):
        f = tmp_path / "c.toml"
        f.write_text(text.replace(old, new))
        assert for_arm(load(f), fake_arm("panda", [87] * 7)).scenarios[FRICTION].uncertainty["viscous"] == want


@pytest.mark.parametrize(("new", "where", "named"), [
    ("viscous = [2.0, 2.0, 1.5, 0.5, 0.5, 0.5]", "arm",
     "scenario.realistic+friction+parameter-error.uncertainty.viscous: 6 values, but arm 'panda' has 7 joints"),
    ("viscous = { for_arm = { panda = [1.0, 1.0] } }", "arm",
     "uncertainty.viscous.for_arm.panda: 2 values, but arm 'panda' has 7 joints"),
    ("viscous = { for_arm = { ur5e_arm = [1.0] } }", "arm", "uncertainty.viscous: no values for arm 'panda'"),
    ("viscous = { each = 1, torque_limit_fraction = 0.1 }", "config", "uncertainty.viscous: one rule"),
    ("viscous = { fraction = 0.1 }", "config", "uncertainty.viscous: unknown field(s) ['fraction']"),
    ("viscous = { torque_limit_fraction = 2 }", "config", "uncertainty.viscous.torque_limit_fraction: must be"),
    ("viscous = 3", "config", "uncertainty.viscous: give one value per joint, or a rule"),
])
def test_a_per_joint_value_that_does_not_fit_the_arm_is_named(tmp_path: Path, new: str, where: str,
                                                             named: str) -> None:
    """A malformed value when the config loads; one that does not fit this arm before any run
    (study.setup_for): the scenario, the field, and both lengths."""
    from tools.study.config import for_arm

    old = "viscous = { for_arm = { ur5e_arm = [2.0, 2.0, 1.5, 0.5, 0.5, 0.5] }, torque_limit_fraction = 0.015 }"
    f = tmp_path / "c.toml"
    f.write_text(DEFAULT_CONFIG.read_text().replace(old, new))
    with pytest.raises(StudyConfigError, match=re.escape(named)):
        cfg = load(f)
        assert where == "arm", "the config should have been refused as it loaded"
        for_arm(cfg, fake_arm("panda", [87] * 7))


def test_the_report_shows_a_run_that_failed_and_never_crashes_on_it(tmp_path: Path) -> None:
    """Every run of a scenario failed before it measured (the 7-joint arm's friction scenario
    once): the report has the arm's joints, says failed and why, and exits normally."""
    from tools.study.report import write_report
    from tools.study import scenario_result

    n, methods = 7, ["pm", "pd"]
    failed = {"result": "failed", "verdict_reasons": ["failed: the simulator refused its arguments: need 7 values"]}
    ok = {"result": "ok", "verdict_reasons": [], "tracking_max_abs_rad": [0.01] * n, "tracking_rms_rad": [0.005] * n,
          "estimation_error_rms": [0.1] * n, "torque_power_w": 3.0}
    definition = {"name": "s", "description": "", "uncertainty": {}, "drives": {}, "bus_timing": False}
    study = {"description": "t", "config": "c", "seeds": [1], "duration_s": 1.0, "hold_s": 0.5, "methods": methods,
             "tuning_procedure": "-", "notes": [],
             "arm": {"name": "panda", "n_joints": n, "joint_names": [f"j{i}" for i in range(n)], "model": "m",
                     "model_hash": "0", "is_default": False, "buses": []},
             "scenarios": {"all-failed": scenario_result(definition, {}, {m: [failed] for m in methods}, methods, n),
                           "mixed": scenario_result(definition, {}, {"pm": [ok], "pd": [failed]}, methods, n)}}
    write_report(tmp_path, study)
    report = (tmp_path / "report.md").read_text()
    assert "## Scenario `all-failed`" in report and "## Scenario `mixed`" in report
    assert "- pd: 1 of 1 runs did not end ok (failed on seed(s) 1; the first failure: failed: the simulator" in report
    assert "1 failed" in (tmp_path / "summary.txt").read_text()
    assert all(len(study["scenarios"][s]["stats"]["pm"]["linf"]["per_joint"]) == n for s in study["scenarios"])


def test_the_report_gives_the_studys_own_loop_rate(tmp_path: Path) -> None:
    """A study run at 500 Hz (an arm whose design is discretised for it) says 0.5 kHz in its report,
    not the registry's default 1 kHz."""
    from tools.study.report import write_report
    from tools.study import scenario_result

    n, methods = 6, ["pd"]
    ok = {"result": "ok", "verdict_reasons": [], "tracking_max_abs_rad": [0.01] * n, "tracking_rms_rad": [0.005] * n,
          "estimation_error_rms": [0.1] * n, "torque_power_w": 3.0}
    definition = {"name": "s", "description": "", "uncertainty": {}, "drives": {}, "bus_timing": False}
    study = {"description": "t", "config": "c", "seeds": [1], "duration_s": 1.0, "hold_s": 0.5, "methods": methods,
             "tuning_procedure": "-", "notes": [], "rate_hz": 500.0,
             "arm": {"name": "slow", "n_joints": n, "joint_names": [f"j{i}" for i in range(n)], "model": "m",
                     "model_hash": "0", "is_default": False, "buses": []},
             "scenarios": {"s": scenario_result(definition, {}, {"pd": [ok]}, methods, n)}}
    write_report(tmp_path, study, figures=False)
    report = (tmp_path / "report.md").read_text()
    assert " at 0.5 kHz." in report and " at 1 kHz." not in report, report[:800]


def test_a_study_on_a_seven_joint_arm_runs_every_scenario(tmp_path: Path) -> None:
    """The README's `study --arm tests/arms/panda.toml`, short: every scenario (friction values
    from the torque limits), one seed, two methods; every run measured, a report naming every
    scenario, and each run.json saying when, from which commit and where it ran."""
    import argparse

    from tools.build.arm import arm_from_args, build_arm

    text = DEFAULT_CONFIG.read_text()
    text = re.sub(r"(?m)^methods = .*$", 'methods = ["pm-paper-weights", "pd"]', text)
    text = re.sub(r"(?m)^seeds = \d+ .*$", "seeds = 1", text)
    text = with_tuning(text, duration_s=0.5, cap=2, batch=2, widen=0)
    cfg_path = tmp_path / "seven.toml"
    cfg_path.write_text(text)
    # the arm as the CLI makes it (an arm file names its model): the build folder the other
    # Panda tests and the docs' command use, not a second one
    arm = arm_from_args(argparse.Namespace(arm=REPO / "tests" / "arms" / "panda.toml", model=None, design=None))
    build_arm("release", arm)
    out = tmp_path / "study"
    s = run_study(load(cfg_path), out, duration_s=1.0, arm=arm, jobs=2)
    assert s["arm"]["n_joints"] == 7 and list(s["scenarios"]) == list(load(cfg_path).scenarios)
    assert FRICTION in s["scenarios"] and "realistic+payload" in s["scenarios"]
    friction = s["scenarios"][FRICTION]["definition"]["uncertainty"]
    assert len(friction["viscous"]) == len(friction["coulomb"]) == 7
    report = (out / "report.md").read_text()
    for name, sc in s["scenarios"].items():
        assert f"## Scenario `{name}`" in report
        for m in ("pm-paper-weights", "pd"):
            r = sc["runs"][m][0]
            assert r["result"] != "failed" or r.get("final_state") in ("safe-stop", "fault"), r["verdict_reasons"]
            assert len(sc["stats"][m]["linf"]["per_joint"]) == 7
    run = json.loads((out / FRICTION / "pd" / "seed-1" / "run.json").read_text())
    prov = run["provenance"]
    head = subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()
    assert prov["commit"] == head and isinstance(prov["dirty"], bool)
    started = datetime.fromisoformat(prov["date_utc"])
    assert started.utcoffset() == timedelta(0) and abs(datetime.now(timezone.utc) - started) < timedelta(hours=1)
    assert prov["hostname"] == socket.gethostname() and prov["platform"] == platform.platform()


def test_a_list_for_another_arm_stops_the_study_before_any_run(tmp_path: Path) -> None:
    """The old config's six friction values on the 7-joint Panda: a one-line error, exit 2, and
    nothing run (the CLI, as a user meets it)."""
    old = "viscous = { for_arm = { ur5e_arm = [2.0, 2.0, 1.5, 0.5, 0.5, 0.5] }, torque_limit_fraction = 0.015 }"
    cfg = tmp_path / "six.toml"
    cfg.write_text(DEFAULT_CONFIG.read_text().replace(old, "viscous = [2.0, 2.0, 1.5, 0.5, 0.5, 0.5]"))
    out = tmp_path / "study"
    r = subprocess.run([str(REPO / "tools" / "armctl"), "study", "--arm", "tests/arms/panda.toml", "--config", str(cfg),
                        "--seeds", "1", "--out", str(out)], cwd=REPO, capture_output=True, text=True, timeout=900)
    assert r.returncode == 2, r.stdout[-2000:] + r.stderr[-2000:]
    errors = [ln for ln in r.stderr.splitlines() if ln.startswith("armctl study: scenario.")]
    assert errors == ["armctl study: scenario.realistic+friction+parameter-error.uncertainty.viscous: 6 values, but "
                      "arm 'panda' has 7 joints; give one value per joint, or a rule: { each = x }, "
                      "{ torque_limit_fraction = f }, optionally with for_arm = { ARM = [...] }"], r.stderr
    assert "Traceback" not in r.stderr and not any(out.glob("*/*/seed-*"))
    assert "armctl study: panda: locked (not controlled): panda_finger_joint1" in r.stderr  # what the import assumed


def test_a_study_confirms_its_designs_over_the_bus_with_the_files_its_sil_runs_loaded(tmp_path: Path) -> None:
    """A SIL study's confirmation repeats a run of a tuned design (pm) and one of gains (pd) in
    lockstep HIL over a bus; the design run loads the very file its SIL run loaded (no build of
    its own), and every result is the same."""
    cfg = load(kept_config(tmp_path / "cfg", seeds=1, methods='["pm", "pd"]', scenarios='["ideal"]'))
    study = run_study(cfg, tmp_path / "study", duration_s=0.3, jobs=2, confirm=2, figures=False)
    conf = study["confirmation"]
    assert conf["all_match"] and [(r["method"], r["match"]) for r in conf["runs"]] == [("pm", True), ("pd", True)]
    assert all(r["bus"].split(" ")[2] in ("udp", "vcan") for r in conf["runs"]), conf
    sil = json.loads((tmp_path / "study" / "ideal" / "pm" / "seed-1" / "run.json").read_text())
    bus = json.loads((tmp_path / "study" / "confirm" / "ideal" / "pm" / "seed-1" / "run.json").read_text())
    assert bus["results"]["design"] == sil["results"]["design"]
    assert bus["results"]["design"]["why"] == "loaded at run time (--design-file)"
    assert sil["environment"]["bus_choice"].startswith("sil") and not bus["environment"]["bus_choice"].startswith("sil")


def _quick_study_cmd(out: Path) -> list[str]:
    """A study of seconds that ends in lockstep runs over the bus: pd (the kept tuning) in software
    in the loop, then one run repeated over UDP to confirm it."""
    return [ARMCTL, "study", "--methods", "pd", "--scenarios", "ideal", "--seeds", "1", "--duration", "1",
            "--confirm", "1", "--no-figures", "--out", str(out)]


KILLS = 10


def test_a_study_killed_at_any_moment_and_resumed_at_once_ends_with_the_same_numbers(tmp_path: Path) -> None:
    """SIGKILL at KILLS moments spread over the study (its software-in-the-loop runs, the runs that
    confirm them over the bus, the report), each followed at once by the same command: every
    resumed study exits 0 with the numbers of one run through. A killed run's processes stop the
    arm first and hold their run slot until they have (tools/run/slots.py), so the resumed run
    never shares their ports."""
    whole = tmp_path / "whole"
    t0 = time.monotonic()
    r = subprocess.run(_quick_study_cmd(whole), cwd=REPO, capture_output=True, text=True, timeout=600)
    span = time.monotonic() - t0
    assert r.returncode == 0, r.stderr[-3000:]
    ref = json.loads((whole / "study.json").read_text())
    for i in range(KILLS):
        out = tmp_path / f"killed-{i}"
        p = subprocess.Popen(_quick_study_cmd(out), cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(span * (0.1 + 0.85 * i / (KILLS - 1)))
        p.kill()
        p.wait()
        again = subprocess.run(_quick_study_cmd(out), cwd=REPO, capture_output=True, text=True, timeout=600)
        assert again.returncode == 0, f"kill {i} at {span * (0.1 + 0.85 * i / (KILLS - 1)):.2f} s: " + again.stderr[-2000:]
        got = json.loads((out / "study.json").read_text())
        for name, sc in ref["scenarios"].items():
            for part in ("runs", "stats"):
                assert got["scenarios"][name][part] == sc[part], (i, name, part)
        assert got["confirmation"]["all_match"], i
