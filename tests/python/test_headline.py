"""The README's result tables are the recorded headline (tools/studies/paper.headline.json, written
by `tools/armctl study --record`), and a slice of that record reruns bit for bit at HEAD: one
scenario, the first seed, two methods, the full trajectory, in software in the loop. A change that
moves the numbers fails here until the tuning and the headline are made again in the same commit."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tools.study import headline
from tools.study import DEFAULT_CONFIG, run_study
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


@pytest.mark.parametrize("field", headline.RUN_FIELDS)
def test_the_record_keeps_every_field_for_every_run(field: str) -> None:
    for sc in RECORD["scenarios"].values():
        for runs in sc["runs"].values():
            assert len(runs) == len(RECORD["seeds"]) and all(field in r for r in runs)
