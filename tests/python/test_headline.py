"""The README's result tables are the recorded headline (tools/studies/paper.headline.json, written
by `tools/armctl study --record`), and a slice of that record reruns bit for bit at HEAD: one
scenario, the first seed, two methods, the full trajectory, in software in the loop. A change that
moves the numbers fails here until the tuning and the headline are made again in the same commit."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from tools.study import headline
from tools.study import DEFAULT_CONFIG, OUTCOMES, run_study
from tools.study.config import load

RECORD = json.loads(headline.RECORD.read_text())
SLICE = ("ideal", ("pd", "usde-smc"))


def test_the_readme_tables_are_the_record() -> None:
    assert headline.readme_block(headline.README.read_text()) == headline.render(RECORD)


def test_a_slice_of_the_record_reruns_bit_for_bit_at_head(tmp_path: Path, controller_bin: Path) -> None:
    scenario, methods = SLICE
    study = run_study(load(DEFAULT_CONFIG), tmp_path / "study", seeds=1, methods=list(methods),
                      scenarios=[scenario], confirm=0, figures=False)
    assert study["duration_s"] == RECORD["duration_s"] and study["seeds"] == RECORD["seeds"][:1]
    for m in methods:
        again = headline.record_of(study)["scenarios"][scenario]["runs"][m][0]
        assert again == RECORD["scenarios"][scenario]["runs"][m][0], f"{m} in {scenario}, seed 1"


def test_record_refuses_a_study_that_is_not_the_default(tmp_path: Path) -> None:
    import subprocess

    from gen.lib.paths import REPO

    r = subprocess.run([str(REPO / "tools" / "armctl"), "study", "--record", "--seeds", "1", "--out",
                        str(tmp_path / "s")], cwd=REPO, capture_output=True, text=True)
    assert r.returncode == 2 and "--record: the headline is the default study" in r.stderr, r.stderr


def _per_joint(v: object, n: int) -> bool:
    return isinstance(v, list) and len(v) == n and all(
        isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and x >= 0 for x in v)


# What each kept field must hold in every run (a record of Nones, or of empty lists, is no record).
def _holds(field: str, v: object, run: dict, n: int) -> bool:
    if field in ("tracking_max_abs_rad", "tracking_rms_rad", "estimation_error_rms", "saturated_fraction",
                 "tracking_max_abs_deg"):
        return _per_joint(v, n)
    if field == "result":
        return isinstance(v, str) and (v in OUTCOMES or v == "failed")  # failed: the safety layer stopped it
    if field == "steps":
        return isinstance(v, int) and not isinstance(v, bool) and v > 0
    if field == "torque_power_w":
        return isinstance(v, float) and math.isfinite(v) and v > 0
    if field == "verdict_reasons":  # none for an ok run, and each a line for any other
        return isinstance(v, list) and all(isinstance(x, str) and x for x in v) and (not v) == (run["result"] == "ok")
    if field == "final_fault":
        return isinstance(v, str) and bool(v)
    if field == "bounds":
        return isinstance(v, dict) and isinstance(v.get("max_error_deg"), (int, float)) and v["max_error_deg"] > 0
    raise AssertionError(f"RUN_FIELDS has {field}: say here what it must hold")


@pytest.mark.parametrize("field", headline.RUN_FIELDS)
def test_the_record_keeps_every_field_for_every_run(field: str) -> None:
    n = RECORD["arm"]["n_joints"]
    for s, sc in RECORD["scenarios"].items():
        for m, runs in sc["runs"].items():
            assert len(runs) == len(RECORD["seeds"]), (s, m)
            for seed, r in zip(RECORD["seeds"], runs):
                assert field in r and _holds(field, r[field], r, n), f"{m} in {s}, seed {seed}: {field} = {r.get(field)!r}"
