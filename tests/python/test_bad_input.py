"""Bad values fail fast and in one line (issue 15): before any process starts or any solve runs,
naming the option, with exit 2 and no traceback."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import pytest

from gen.lib.paths import REPO

ARMCTL = str(REPO / "tools" / "armctl")


@pytest.fixture()
def a_file(tmp_path: Path) -> Path:
    f = tmp_path / "a_file"
    f.write_text("x")
    return f


@pytest.mark.parametrize("args,named", [
    (["hil", "--duration", "1", "--out", "{file}"], "--out"),
    (["study", "--seeds", "1", "--out", "{file}"], "--out"),
    (["tune", "--out", "{file}"], "--out"),
    (["synth", "--out", "{file}"], "--out"),
    (["synth", "--config", "{dir}", "--out", "{dir}/o"], "is a directory"),
    (["synth", "--config", "{binary}", "--out", "{dir}/o"], "not valid TOML"),
    (["hil", "--duration", "0.0001"], "--duration"),
    (["hil", "--duration", "inf"], "--duration"),
    (["hil", "--ref-hold", "-1"], "--ref-hold"),
    (["hil", "--can-port", "80"], "--can-port"),
    (["study", "--seeds", "0"], "--seeds"),
    (["study", "--jobs", "0"], "--jobs"),
    (["study", "--scenarios", "windy"], "--scenarios"),
    (["hil", "--model", "{file}"], "--model"),
])
def test_bad_values_are_one_line_errors(tmp_path: Path, a_file: Path, args: list[str], named: str) -> None:
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"\x00\xff\xfe")
    argv = [a.format(file=a_file, dir=tmp_path, binary=binary) for a in args]
    t0 = time.monotonic()
    r = subprocess.run([ARMCTL, *argv], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert named in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert time.monotonic() - t0 < 60  # nothing waited for a timeout


@pytest.mark.parametrize("drives,named", [
    ("{ gear_ratio = 101.0 }", "drives.gear_ratio: only with motor_encoder_bits"),
    ("{ motor_encoder_bits = 17 }", "drives.gear_ratio: a motor encoder needs the gear ratio"),
    ("{ motor_encoder_bits = 17.5, gear_ratio = 101.0 }", "drives.motor_encoder_bits: must be a whole number"),
    ("{ motor_encoder_bits = 40, gear_ratio = 101.0 }", "drives.motor_encoder_bits: must be a number in [0, 32]"),
    ('{ velocity_source = "tacho" }', "drives.velocity_source: must be one of joint, motor"),
    ('{ position_source = "motor" }', "drives.position_source: 'motor' needs motor_encoder_bits"),
    ('{ motor_encoder_bits = 17, gear_ratio = 101.0, velocity_source = "motor" }',
     "drives.velocity_source: 'motor' needs velocity_filter_hz"),
])
def test_bad_drive_fields_are_one_line_errors(tmp_path: Path, drives: str, named: str) -> None:
    text = (REPO / "tools" / "studies" / "paper.toml").read_text()
    assert 'drives = "ideal"' in text
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace('drives = "ideal"', f"drives = {drives}", 1))
    r = subprocess.run([ARMCTL, "study", "--config", str(bad), "--seeds", "1", "--out", str(tmp_path / "o")],
                       cwd=REPO, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert f"scenario.ideal.{named}" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "o").exists()  # nothing half-written


@pytest.mark.parametrize("args,named", [
    (["--gear-ratio", "101"], "--motor-encoder-bits/--gear-ratio: give both"),
    (["--motor-encoder-bits", "17"], "--motor-encoder-bits/--gear-ratio: give both"),
    (["--motor-encoder-bits", "17.5", "--gear-ratio", "101"], "--motor-encoder-bits: '17.5' is not a whole number"),
    (["--gear-ratio", "0.5", "--motor-encoder-bits", "17"], "--gear-ratio: '0.5' is not a number in [1, 10000]"),
    (["--velocity-source", "tacho"], "--velocity-source: 'tacho' is not joint or motor"),
    (["--position-source", "motor"], "--position-source motor: give --motor-encoder-bits"),
    (["--motor-encoder-bits", "17", "--gear-ratio", "101", "--velocity-source", "motor"],
     "--velocity-source motor: give --velocity-filter-hz"),
    (["--debug-late-answer", "60:4500"], "--debug-late-answer: '60:4500' is not PERIOD[-LAST]:command"),
    (["--debug-late-answer", "62-60:command"], "--debug-late-answer: '62-60:command' is not PERIOD[-LAST]:command"),
    (["--debug-late-answer", "60-63:burst"], "--debug-late-answer: '60-63:burst' is not PERIOD[-LAST]:command"),
])
def test_bad_arm_sim_drive_options_are_one_line_errors(args: list[str], named: str) -> None:
    arm_sim = REPO / "build" / "release" / "host_sim" / "native" / "arm_sim"
    if not arm_sim.exists():
        subprocess.run(["cmake", "--build", str(REPO / "build" / "release"), "--target", "arm_sim"], check=True,
                       capture_output=True)
    r = subprocess.run([str(arm_sim), *args], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert r.returncode != 0 and named in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
