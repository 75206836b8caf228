"""The kept tuning is verified by what it does (tools/study/verify.py, `armctl tune --verify`): its
picks' recorded runs reproduce number for number on the code at HEAD, a pair stamped with other
code is verified and restamped, a recorded number that differs is named with the pair and its
rank against the runner-up, and a number that matters (a drive's rated torque) moves the pairs
it reaches."""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import pytest

from gen.lib.paths import REPO
from tools.build.arm import DEFAULT_ARM
from tools.build.code_identity import code_identity
from tools.study import DEFAULT_CONFIG, _read_tuning, setup_for, tuning_file
from tools.study import verify
from tools.study.config import METHODS, load

ARMCTL = str(REPO / "tools" / "armctl")
KEPT = json.loads(load(DEFAULT_CONFIG).tuning_file.read_text())


def _pairs() -> list[tuple[str, str]]:
    cfg = load(DEFAULT_CONFIG)
    return [(s, m) for s in cfg.scenarios for m in cfg.methods if METHODS[m][1] is not None]


def test_the_committed_tuning_is_stamped_with_the_code_at_head() -> None:
    """Every kept pair was tuned or verified on this very code: main never ships a tuning that
    `armctl tune --verify` did not find equal (the stamp is written only by a tuning or an equal
    verification; the test below reruns a sample of it)."""
    head = code_identity()
    stale = [f"{s}/{m}" for s, m in _pairs() if KEPT["scenarios"][s][m].get("code") != head]
    assert not stale, (f"the kept tuning of {', '.join(stale)} is not stamped with HEAD's code {head}: "
                       "run `tools/armctl tune --verify` (it restamps what reproduces, and names what moved)")


def test_a_sample_of_every_pick_reruns_number_for_number_at_head(tmp_path: Path) -> None:
    """The first recorded validation run of every kept pick, run again on this code: the same
    result and the same L-infinity error per joint, to the last bit."""
    cfg = load(DEFAULT_CONFIG)
    setup, _, _ = setup_for(cfg, DEFAULT_ARM, tmp_path, 2, None)
    specs, recorded, labels = [], [], []
    for s, m in _pairs():
        rec = KEPT["scenarios"][s][m]
        variants, seeds, runs = verify.recorded_runs(rec, setup.cfg.tuning_seeds)
        specs += verify._specs(setup, s, m, rec["knobs"], seeds[:1], variants[:1], tmp_path / s / m)
        recorded.append(runs[0])
        labels.append(f"{s}/{m} seed {seeds[0]}")
    check = verify.PairCheck("sample", "all")
    verify.compare(check, labels, recorded, verify.run_all(specs, 2, None, forked=True))
    assert check.equal, "\n".join(check.results_changed + check.moved[:20])


def _made_here(rec: dict, scenario: str, method: str, out: Path) -> None:
    """rec's recorded validation runs replaced by the same runs on this code: a record that verifies
    here whatever the committed tuning's state (the test of that is the one above)."""
    setup, _, _ = setup_for(load(DEFAULT_CONFIG), DEFAULT_ARM, out, 2, None)
    variants, seeds, recorded = verify.recorded_runs(rec, setup.cfg.tuning_seeds)
    here = verify.run_all(verify._specs(setup, scenario, method, rec["knobs"], seeds, variants, out), 2, None,
                          forked=True)
    for r, run in zip(recorded, here):
        r["result"], r["tracking_max_abs_deg"] = run["results"]["result"], run["results"]["tracking_max_abs_deg"]


def _config_with_tuning_file(tmp_path: Path, doc: dict) -> tuple[Path, Path]:
    """The default study config with its kept tuning a copy in tmp_path (the same key: [tuning] file
    is not in it), so a test may restamp and edit it."""
    text, n = re.subn(r'(?m)^file = "[^"]*"', 'file = "kept.json"', DEFAULT_CONFIG.read_text())
    assert n == 1, "the default config's [tuning] file"
    cfg = tmp_path / "paper.toml"
    cfg.write_text(text)
    (tmp_path / "kept.json").write_text(json.dumps(doc))
    return cfg, tmp_path / "kept.json"


def test_verify_restamps_a_pair_that_reproduces_and_names_one_that_moved(tmp_path: Path) -> None:
    """`armctl tune --verify` on a copy of the kept tuning: ideal/pd stamped with other code is
    verified equal and restamped; with one recorded number of its validation changed it is named as
    moved, with the joint, the change and its pick's rank against the runner-up, exit 1, and its
    stamp is left alone."""
    doc = json.loads(json.dumps(KEPT))
    _made_here(doc["scenarios"]["ideal"]["pd"], "ideal", "pd", tmp_path / "here")
    doc["scenarios"]["ideal"]["pd"]["code"] = "0123456789abcdef"
    cfg, kept = _config_with_tuning_file(tmp_path, doc)
    base = [ARMCTL, "tune", "--config", str(cfg), "--verify", "--scenarios", "ideal", "--methods", "pd", "--jobs", "2"]
    r = subprocess.run([*base, "--out", str(tmp_path / "v1")], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr[-2000:]
    assert "ideal/pd: 2 runs, every number as recorded" in r.stdout
    rec = json.loads(kept.read_text())["scenarios"]["ideal"]["pd"]
    assert rec["code"] == code_identity()
    assert rec["tuned_code"] == KEPT["scenarios"]["ideal"]["pd"].get("tuned_code", "0123456789abcdef")
    assert rec["verified"]["code"] == code_identity() and rec["verified"]["runs"] == 2

    moved = json.loads(kept.read_text())
    mrec = moved["scenarios"]["ideal"]["pd"]
    mrec["code"] = "fedcba9876543210"
    run0 = next(t for t in mrec["validation"]["tried"] if t["rank"] == mrec["validation"]["picked_rank"])["runs"][0]
    run0["tracking_max_abs_deg"][2] *= 1.01
    kept.write_text(json.dumps(moved))
    r = subprocess.run([*base, "--out", str(tmp_path / "v2")], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert r.returncode == 1, r.stdout + r.stderr[-2000:]
    line = next(ln for ln in r.stdout.splitlines() if ln.startswith("ideal/pd: moved"))
    assert f"seed {run0['seed']}: joint 3" in line and "-0.99" in line, line
    assert "the pick scores" in line and "runner-up" in line and "still ranks ahead" in line, line
    assert "tools/armctl tune --retune ideal/pd" in r.stdout
    assert json.loads(kept.read_text())["scenarios"]["ideal"]["pd"]["code"] == "fedcba9876543210"

    # --accept-moved keeps the pick that still ranks ahead: its runs become this code's, stamped
    r = subprocess.run([*base, "--accept-moved", "--out", str(tmp_path / "v3")], cwd=REPO, capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr[-2000:]
    assert "their picks kept, their runs recorded anew on this code and stamped: ideal/pd" in r.stdout, r.stdout
    arec = json.loads(kept.read_text())["scenarios"]["ideal"]["pd"]
    assert arec["code"] == code_identity() and arec["knobs"] == mrec["knobs"]
    assert arec["verified"]["accepted_move"]["largest_change"] > 0.009
    arun0 = next(t for t in arec["validation"]["tried"] if t["rank"] == arec["validation"]["picked_rank"])["runs"][0]
    assert arun0["tracking_max_abs_deg"][2] == run0["tracking_max_abs_deg"][2] / 1.01, "this code's number"
    r = subprocess.run([*base, "--out", str(tmp_path / "v4")], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0 and "ideal/pd: 2 runs, every number as recorded" in r.stdout, r.stdout



def test_a_drives_rated_torque_moves_the_pairs_it_reaches(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The bundled arm's drives with another rated torque on joint 2 (0x6076: the unit of the torque
    command's per-mille): the pair's pick moves, and verify names it, by how much, and whether it
    still ranks ahead of its runner-up. The record is first made this code's own (its validation
    runs run here), so that only the rated torque can move it: with the bundled drives it verifies."""
    from gen import drives
    from tools.run import hil

    cfg = load(DEFAULT_CONFIG)
    setup, _, _ = setup_for(cfg, DEFAULT_ARM, tmp_path / "v", 2, None)
    rec = json.loads(json.dumps(_read_tuning(tuning_file(cfg, DEFAULT_ARM))["scenarios"]["realistic"]["pd"]))
    _made_here(rec, "realistic", "pd", tmp_path / "here")
    recs = {("realistic", "pd"): rec}
    assert verify.verify_pairs(setup, recs, tmp_path / "same")[0].equal

    table = drives.DEFAULT_DRIVES.read_text()
    assert 'rated_torque_nm = "joint_torque_limit / gear"' in table
    (tmp_path / "drives.toml").write_text(table + "\n[joint.shoulder_lift]\nrated_torque_nm = 2.0\n")
    (tmp_path / "cia402_servo.eds").write_bytes((drives.DEFAULT_DRIVES.parent / "cia402_servo.eds").read_bytes())
    monkeypatch.setattr(drives, "DEFAULT_DRIVES", tmp_path / "drives.toml")
    monkeypatch.setattr(hil, "_CANOPEN_MEMO", {})
    [check] = verify.verify_pairs(setup, recs, tmp_path / "other")
    assert not check.equal and check.moved, "a 2.0 N m motor instead of 1.486 N m on joint 2 moved nothing"
    assert check.rank.startswith("the pick scores") and "runner-up" in check.rank, check.rank
    note = verify.moved_note([check], tuning_file(cfg, DEFAULT_ARM))
    assert note is not None and "realistic/pd: moved" in note, note
