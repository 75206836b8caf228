"""The compatibility matrix (docs/arm-compatibility.md): the page equals what its results file says,
the results file holds what issue 38 asks (30+ arms from 5+ sets, 90 % ok, every other one refused
in one line, the unedited dm_control Jaco ok), one arm of each model set imports here (tests/arms,
copied from each set), and `armctl arms` itself runs a set end to end. The matrix is a benchmark
(`tools/armctl arms` writes runs/bench/arms.json); no test times anything."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from gen.arm import ArmError, ArmFile, load_arm_file, prepare
from gen.lib.paths import REPO
from tools.bench import arms, arms_page

LOCAL_SETS = REPO / "tests" / "arms" / "sets.toml"
DOC = json.loads(arms_page.RESULTS.read_text())


def test_the_page_is_rendered_from_the_results_file() -> None:
    page = arms_page.PAGE.read_text()
    assert arms_page.with_generated(page, arms_page.render(DOC)) == page, \
        "docs/arm-compatibility.md differs from runs/bench/arms.json: python -m tools.bench.arms_page"


def test_the_matrix_is_large_and_every_row_says_what_happened() -> None:
    s = arms_page.summary(DOC)
    assert s["arms"] >= 30 and s["sets"] >= 5
    for row in DOC["arms"]:
        if row["result"] == "ok":
            assert row["max_error_deg"] <= DOC["bound_deg"], row
        else:  # one line naming what is wrong (the importer's refusal, or the run's verdict): never a traceback
            assert row["reason"] and "\n" not in row["reason"] and "Traceback" not in row["reason"], row
    jaco = [r for r in DOC["arms"] if r["model"].endswith("third_party/kinova/jaco_arm.xml")]
    assert len(jaco) == 1 and jaco[0]["set"] == "dm_control" and jaco[0]["result"] == "ok", jaco


# Every arm of the committed matrix that is not ok, and how it ended: the floor the matrix holds
# (one more arm not ok, or another outcome, fails here until this list says so; an arm made ok
# fails too, so that the list shrinks with the fixes). The 90 % target is the xfail below.
MATRIX_NOT_OK = {
    "dm-robotics-panda/dm_robotics/panda/assets/panda/panda.xml": "failed",
    "example-robot-data/cmeel.prefix/share/example-robot-data/robots/baxter_description/urdf/baxter.urdf#left_s0":
        "tracking-bound-exceeded",
    "example-robot-data/cmeel.prefix/share/example-robot-data/robots/baxter_description/urdf/baxter.urdf#right_s0":
        "tracking-bound-exceeded",
    "example-robot-data/cmeel.prefix/share/example-robot-data/robots/finger_edu_description/robots/finger_edu.urdf":
        "refused",
    "example-robot-data/cmeel.prefix/share/example-robot-data/robots/so_arm_description/urdf/so100.urdf": "failed",
    "example-robot-data/cmeel.prefix/share/example-robot-data/robots/talos_data/robots/talos_left_arm.urdf":
        "tracking-bound-exceeded",
    "gymnasium-robotics/gymnasium_robotics/envs/assets/adroit_hand/adroit_hammer.xml": "refused",
    "robosuite-models/robosuite_models/assets/robots/aloha/robot.xml#left/waist": "refused",
    "robosuite-models/robosuite_models/assets/robots/aloha/robot.xml#right/waist": "refused",
    "robosuite/robosuite/models/assets/robots/jaco/robot.xml": "tracking-bound-exceeded",
    "rtb-data/rtbdata/xacro/abb_irb140_description/urdf/irb140.urdf": "refused",
    "rtb-data/rtbdata/xacro/kuka_description/kuka_lbr_iiwa/urdf/lbr_iiwa_14_r820.urdf": "refused",
    "rtb-data/rtbdata/xacro/lynxmotion_al5d_description/urdf/al5d_robot.urdf": "refused",
    "rtb-data/rtbdata/xacro/unimation_puma560_description/urdf/puma560_robot.urdf": "refused",
}


def test_every_arm_not_ok_is_known_and_the_rest_are_ok() -> None:
    """The floor: the matrix's arms that are not ok are exactly the known ones, each ending as it
    did (51 of 65 ok); any other arm is ok."""
    got = {r["id"]: r["result"] for r in DOC["arms"] if r["result"] != "ok"}
    assert got == MATRIX_NOT_OK, {"newly not ok": {k: v for k, v in got.items() if MATRIX_NOT_OK.get(k) != v},
                                  "no longer as listed": {k: v for k, v in MATRIX_NOT_OK.items() if got.get(k) != v}}
    s = arms_page.summary(DOC)
    assert s["ok"] == s["arms"] - len(MATRIX_NOT_OK) and s["arms"] >= 65


@pytest.mark.xfail(strict=True, reason="issue 38's 90 %: 51 of 65 ok on the committed matrix; 4 runs over the 2 deg "
                                       "bound (robosuite Jaco, Baxter x2, TALOS arm) and 2 failed runs (SO-100, "
                                       "dm_robotics Panda) are open")
def test_nine_in_ten_arms_are_ok_and_the_others_refused_with_a_physical_reason() -> None:
    s = arms_page.summary(DOC)
    assert s["ok_fraction"] >= 0.9
    assert all(r["result"] in ("ok", "refused") for r in DOC["arms"])


def _local_arms() -> list[tuple[str, Path, arms.Candidate]]:
    sets, _ = arms.load_sets(LOCAL_SETS)
    out = []
    for ms in sets:
        found, _, _ = arms.find_arms(ms, ms.folder)
        out += [(ms.name, ms.folder, c) for c in found]
    return out


LOCAL = _local_arms()


def test_every_model_set_has_an_arm_here() -> None:
    sets, _ = arms.load_sets(arms.SETS_FILE)
    assert {name for name, _, _ in LOCAL} == {ms.name for ms in sets}


@pytest.mark.parametrize("name,folder,cand", LOCAL, ids=[c.id for _, _, c in LOCAL])
def test_one_arm_of_each_set_imports(name: str, folder: Path, cand: arms.Candidate, tmp_path: Path) -> None:
    """Each copied arm imports as the matrix ran it (an arm file for one arm of two), with the joints
    the finder saw; where the matrix ran the same file from the set's package, it was ok too."""
    af = (load_arm_file(arms.arm_file_for(cand, folder / cand.model, tmp_path)) if cand.arm_file
          else ArmFile(None, None, folder / cand.model))
    try:
        info = prepare(af).info
    except ArmError as exc:
        pytest.fail(f"{cand.id}: {exc}")
    assert [j["name"] for j in info["joints"]] == cand.joints
    same = [r for r in DOC["arms"] if r["set"] == name and r["model"].endswith(cand.model.split("/", 1)[-1])
            and r["joints"] == cand.joints]
    not_ok = {r["id"]: r["result"] for r in same if r["result"] != "ok"}
    assert not_ok == {r["id"]: NOT_YET_OK[r["id"]] for r in same if r["id"] in NOT_YET_OK}, same


# Copied arms the matrix (runs/bench/arms.json) records as not ok, each with why: the product's
# open failures on public arms (docs/arm-compatibility.md), kept here so that one more, or a fix,
# fails this test until this list says so.
NOT_YET_OK = {
    # no actuators in the file: the torque limits are assumed from the inertials (meshes absent),
    # and joint 4's 4.4 N m cannot follow the reference (torque-limited, then the following error)
    "dm-robotics-panda/dm_robotics/panda/assets/panda/panda.xml": "failed",
}


@pytest.mark.long
def test_armctl_arms_runs_a_set_end_to_end(tmp_path: Path) -> None:
    """The command itself on the unedited dm_control Jaco (with its common.xml, whose default class
    gives every site a material): found, imported, built, run in SIL, written, rendered."""
    page = tmp_path / "page.md"
    page.write_text(f"# t\n\n{arms_page.BEGIN}\n{arms_page.END}\n")
    out = tmp_path / "arms.json"
    r = subprocess.run([str(REPO / "tools" / "armctl"), "arms", "--sets-file", str(LOCAL_SETS), "--sets", "dm_control",
                        "--out", str(out), "--page", str(page)], cwd=REPO, capture_output=True, text=True,
                       timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    doc = json.loads(out.read_text())
    [row] = doc["arms"]
    assert row["result"] == "ok" and row["max_error_deg"] <= doc["bound_deg"] and len(row["joints"]) == 6, row
    assert "jaco_arm.xml" in page.read_text() and arms_page.render(doc) in page.read_text()


def test_a_sets_file_that_is_not_one_is_named(tmp_path: Path) -> None:
    bad = tmp_path / "sets.toml"
    bad.write_text('[[set]]\nname = "x"\nlicence = "MIT"\nsearch = ["."]\n')
    r = subprocess.run([str(REPO / "tools" / "armctl"), "arms", "--sets-file", str(bad), "--list"], cwd=REPO,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and r.stderr.strip().count("\n") == 0, r.stderr
    assert "set x: give a requirement (name==version) or a path" in r.stderr
