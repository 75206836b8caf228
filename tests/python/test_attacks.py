"""The attacks of issue 51, each as an attacker made it, through the command a user runs: a model
file whose joint name carries C (`armctl hil --model evil.xml`: a constructor that touches a marker
file at every start of every program), a joint name carrying a script into the study's report.html,
and a study config whose scenario (its name breaks out of the code span the report put it in) and
description carry markup. Each failed on the code before gen/lib/escape.py; a report is opened in
headless Chromium as the person it was mailed to would."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import Any

import pytest

from gen.lib.paths import REPO
from headless_browser import Browser, page_facts
from hil_procs import armctl
from hostile_names import SCRIPT_NAME, SCRIPT_TITLE, STABLE, c_injection, renamed_model
from tools.build.arm import ArmRef, arm_build_dir

pytestmark = pytest.mark.long  # one arm built (a minute or two), a run and two small studies

EVIL = STABLE / "evil.xml"
MARKER = STABLE / "evil.marker"  # what the joint name's constructor touches, if it ever runs


def one_line_refusal(r: subprocess.CompletedProcess[str]) -> str:
    assert r.returncode == 2 and "Traceback" not in r.stderr, (r.returncode, r.stderr[-3000:])
    lines = [ln for ln in r.stderr.splitlines() if ln.strip() and not ln.startswith("armctl: ")]
    assert len(lines) == 1, r.stderr
    return lines[0]


@pytest.fixture(scope="module")
def evil() -> Path:
    """The bundled arm's MJCF with two joints renamed, as an attacker would ship it: the elbow's name
    carries C, the shoulder lift's a script (at a fixed path: one build folder for every session)."""
    MARKER.unlink(missing_ok=True)
    return renamed_model(EVIL, {"elbow": c_injection(MARKER), "shoulder_lift": SCRIPT_NAME})


def test_a_joint_name_carrying_c_runs_nothing_and_is_kept_as_data(evil: Path, tmp_path: Path) -> None:
    r = armctl("hil", "--model", str(evil), "--duration", "1", "--out", str(tmp_path / "run"), timeout=900)
    assert not MARKER.exists(), "the joint name's constructor ran: the model file ran code on this machine"
    # kept as data: the arm is built and runs with the name as it is (a refusal of the name would pass
    # the marker's check above and keep nothing)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-3000:]
    bdir = arm_build_dir("release", ArmRef(evil.resolve()))
    header = (bdir / "generated" / "arm_robot_model_data.h").read_text()
    assert '"a\\"}; extern int system(const char *);' in header  # the name's quote escaped: one string literal
    for exe in ("firmware/arm_controller", "host_sim/native/arm_sim", "host_sim/native/arm_sil"):
        syms = subprocess.run(["nm", str(bdir / exe)], capture_output=True, text=True, check=True).stdout
        assert "injected_ctor" not in syms and "injected_tail" not in syms, exe
    run = json.loads((tmp_path / "run" / "run.json").read_text())
    assert run["results"]["joint_names"][2] == c_injection(MARKER)


def _page_facts(page: Path) -> dict[str, Any]:
    b = Browser()
    try:
        return page_facts(b, page)
    finally:
        b.close()


def test_b_a_joint_name_carrying_a_script_stays_text_in_the_report(evil: Path, tmp_path: Path) -> None:
    out = tmp_path / "study"
    r = armctl("study", "--model", str(evil), "--methods", "pm-paper-weights", "--scenarios", "ideal", "--seeds",
               "1", "--duration", "0.5", "--confirm", "0", "--out", str(out), timeout=900)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-3000:]
    facts = _page_facts(out / "report.html")
    assert facts["title"] != SCRIPT_TITLE, "the joint name's script ran in the report"
    assert not MARKER.exists()
    assert facts["scripts"] <= 2  # plotly.js and the page's own drawing of its figures
    assert facts["foreign_images"] == facts["handlers"] == facts["links"] == facts["svg_links"] == 0, facts
    assert SCRIPT_NAME in facts["text"]  # shown, as text, where the report names the joints
    assert SCRIPT_NAME in facts["svg_text"]  # and in the figures' labels


def _config_with_scenario(name: str, description: str) -> str:
    """The default study config with its scenario `ideal` renamed and described anew (TOML strings
    written as JSON writes them: the same escapes)."""
    text = (REPO / "tools" / "studies" / "paper.toml").read_text()
    text = text.replace('"ideal", ', f"{json.dumps(name)}, ", 1).replace("[scenario.ideal]",
                                                                       f"[scenario.{json.dumps(name)}]", 1)
    old = next(ln for ln in text.splitlines() if ln.startswith("description = \"the paper's simulation"))
    return text.replace(old, f"description = {json.dumps(description)}", 1)


C_SCENARIO = "x`<img src=x onerror=\"document.title='C3'\">`"
C_DESCRIPTION = "<script>document.title='C3'</script> [click](javascript:alert(1))"


def test_c_a_study_configs_names_bring_no_element_into_the_report(tmp_path: Path) -> None:
    cfg = tmp_path / "study.toml"
    cfg.write_text(_config_with_scenario(C_SCENARIO, C_DESCRIPTION))
    out = tmp_path / "study"
    r = armctl("study", "--config", str(cfg), "--methods", "pm-paper-weights", "--scenarios", C_SCENARIO, "--seeds",
               "1", "--duration", "0.5", "--confirm", "0", "--out", str(out))
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-3000:]
    assert (out / C_SCENARIO / "pm-paper-weights" / "seed-1" / "run.json").is_file()
    facts = _page_facts(out / "report.html")
    assert facts["title"] != "C3", "the study config's markup ran in the report"
    assert facts["foreign_images"] == facts["handlers"] == facts["links"] == 0, facts
    assert facts["scripts"] <= 2
    assert C_SCENARIO in facts["text"] and "<script>document.title='C3'</script> [click](javascript:alert(1))" \
        in facts["text"]


def test_c_a_scenario_that_names_a_place_outside_the_study_is_refused_in_one_line(tmp_path: Path) -> None:
    cfg = tmp_path / "study.toml"
    cfg.write_text(_config_with_scenario("../../outside", "x"))
    r = armctl("study", "--config", str(cfg), "--methods", "pm-paper-weights", "--scenarios", "../../outside",
               "--seeds", "1", "--duration", "0.5", "--confirm", "0", "--out", str(tmp_path / "a" / "b" / "study"))
    line = one_line_refusal(r)
    assert "../../outside" in line and "folder" in line
    assert not (tmp_path / "outside").exists()
