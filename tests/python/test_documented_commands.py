"""Every command in the README's command table runs, in a short form, through tools/armctl itself
(the bash bootstrap and the CLI, exactly as a user types it), so a documented command cannot rot
unseen. EXERCISED says where each one runs; the first test holds the table and EXERCISED equal."""

from __future__ import annotations

import ast
import json
import re
import shutil
import subprocess
import tomllib
from pathlib import Path

import pytest

from tools.paths import REPO

ARMCTL = str(REPO / "tools" / "armctl")

# Documented command -> the test that runs it through the CLI ("file::function"), or "CI".
EXERCISED: dict[str, str] = {
    "demo": "test_documented_commands.py::test_demo",
    "test": "CI",  # .ci/run is exactly `tools/armctl test`
    "hil": "test_documented_commands.py::test_hil",
    "hil --bus vm": "test_vcan_vm.py::test_hil_in_the_vm_through_the_cli",
    "study": "test_documented_commands.py::test_study",
    "tune": "test_documented_commands.py::test_tune",
    "synth": "test_documented_commands.py::test_synth",
    "build": "test_documented_commands.py::test_build",
    "bench step": "test_documented_commands.py::test_bench",
    "bench synth": "test_documented_commands.py::test_bench",
    "bench sim": "test_documented_commands.py::test_bench",
    "timing": "test_timing.py::timing_run",
    "busload": "test_documented_commands.py::test_busload",
    "vcan status": "test_documented_commands.py::test_vcan_status_and_up",
    "vcan up": "test_documented_commands.py::test_vcan_status_and_up",
    "vcan setup": "test_vcan_vm.py::test_vcan_setup_run_and_up_in_the_vm",
    "vcan run": "test_vcan_vm.py::test_vcan_setup_run_and_up_in_the_vm",
    "hil --model|--arm": "test_arm_hil.py::test_lockstep_hil_run_is_ok_within_stated_bounds",
    "build --model|--arm": "test_arm_hil.py::built_arm",
    "synth --model|--arm": "test_arm_hil.py::built_arm",
    "study --model|--arm": "test_documented_commands.py::test_tune_and_study_on_another_arm",
    "tune --model|--arm": "test_documented_commands.py::test_tune_and_study_on_another_arm",
    "demo --model|--arm": "test_documented_commands.py::test_demo_on_another_arm",
}


def documented_commands() -> set[str]:
    """The README's command table: `tools/armctl SUB ...`, with alternatives of a first
    positional word (`bench step|synth`) and of --bus's vm form expanded."""
    text = (REPO / "README.md").read_text()
    section = text.split("\n## Commands", 1)[1].split("\n## ", 1)[0]
    out: set[str] = set()
    for cell in re.findall(r"^\| `tools/armctl ([^`]+)`", section, re.M):
        words = cell.replace("\\|", "|").split()
        sub = words[0]
        if len(words) > 1 and re.fullmatch(r"[a-z]+(\|[a-z]+)+", words[1]):
            out.update(f"{sub} {alt}" for alt in words[1].split("|"))
        else:
            out.add(sub)
        if sub == "hil" and "vm" in cell:
            out.add("hil --bus vm")
        if "--model FILE" in cell or "--arm FILE" in cell:  # one code path for both (tools/arm.py)
            out.add(f"{sub} --model|--arm")
    return out


def armctl(*args: str, timeout: float = 900.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([ARMCTL, *args], cwd=REPO, capture_output=True, text=True, timeout=timeout)


def test_every_documented_command_is_exercised() -> None:
    documented = documented_commands()
    assert documented, "no command table found in README.md"
    assert documented == set(EXERCISED), (f"documented but not exercised: {sorted(documented - set(EXERCISED))}; "
                                          f"exercised but not documented: {sorted(set(EXERCISED) - documented)}")
    here = Path(__file__).parent
    for command, where in EXERCISED.items():
        if where == "CI":
            assert "tools/armctl test" in (REPO / ".ci" / "run").read_text()
            continue
        file, func = where.split("::")
        tree = ast.parse((here / file).read_text())
        fn = next((n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef) and n.name == func), None)
        assert fn is not None, f"{command}: {where} does not exist"
        body = ast.unparse(fn)
        assert "armctl" in body or "tools.cli" in body, f"{command}: {where} does not go through the CLI"


def test_demo(tmp_path: Path) -> None:
    r = armctl("demo", "--duration", "0.2", "--out", str(tmp_path))
    assert r.returncode == 0, r.stdout + r.stderr
    study = json.loads((tmp_path / "study.json").read_text())
    assert set(study["runs"]) == {"pm", "pm-paper", "pd", "gh2", "tde", "usde-smc"}
    assert (tmp_path / "report.md").is_file()


def test_hil(tmp_path: Path) -> None:
    r = armctl("hil", "--duration", "0.3", "--method", "tde", "--out", str(tmp_path))
    assert r.returncode == 0, r.stdout + r.stderr
    run = json.loads((tmp_path / "run.json").read_text())
    assert run["results"]["result"] == "ok" and run["results"]["method"] == "tde"
    assert "result ok" in r.stdout


def test_study(tmp_path: Path) -> None:
    r = armctl("study", "--duration", "0.2", "--methods", "pm,tde", "--out", str(tmp_path))
    assert r.returncode == 0, r.stdout + r.stderr
    assert set(json.loads((tmp_path / "study.json").read_text())["runs"]) == {"pm", "tde"}


def test_tune(tmp_path: Path) -> None:
    """A two-point grid per baseline on a 0.2 s tuning run; the gains file lands next to the config."""
    cfg = tomllib.loads((REPO / "tools" / "studies" / "paper.toml").read_text())
    text = (REPO / "tools" / "studies" / "paper.toml").read_text()
    text = re.sub(r"(\[tuning\][^\[]*?)duration_s = [0-9.]+", r"\1duration_s = 0.2", text, flags=re.S)
    text = text.split("[tuning.grid.pd]")[0] + (
        "[tuning.grid.pd]\nwn = [10.0, 20.0]\n[tuning.grid.tde]\nwn = [20.0]\ncutoff_hz = [50.0]\n"
        "[tuning.grid.usde-smc]\nk = [0.01]\nlambda = [20.0]\n")
    (tmp_path / "tune.toml").write_text(text)
    assert tomllib.loads(text)["tuning"]["duration_s"] == 0.2 and cfg["tuning"]["seed"] != cfg["seed"]
    r = armctl("tune", "--config", str(tmp_path / "tune.toml"), "--out", str(tmp_path / "runs"))
    assert r.returncode == 0, r.stdout + r.stderr
    gains = json.loads((tmp_path / cfg["tuning"]["gains_file"]).read_text())
    assert set(gains["methods"]) == {"pd", "tde", "usde-smc"}
    assert len(gains["all_scores"]["pd"]) == 2


def test_tune_and_study_on_another_arm(tmp_path: Path) -> None:
    """tune on a 7-DOF arm keeps its gains in the arm's build folder; the study then uses them."""
    text = (REPO / "tools" / "studies" / "paper.toml").read_text()
    text = re.sub(r"(\[tuning\][^\[]*?)duration_s = [0-9.]+", r"\1duration_s = 0.2", text, flags=re.S)
    text = text.split("[tuning.grid.pd]")[0] + (
        "[tuning.grid.pd]\nwn = [20.0]\n[tuning.grid.tde]\nwn = [20.0]\ncutoff_hz = [50.0]\n"
        "[tuning.grid.usde-smc]\nk = [0.01]\nlambda = [20.0]\n")
    cfg = tmp_path / "tune7.toml"
    cfg.write_text(text)
    model = str(REPO / "tests" / "arms" / "robosuite" / "iiwa.xml")
    r = armctl("tune", "--model", model, "--config", str(cfg), "--out", str(tmp_path / "runs"))
    assert r.returncode == 0, r.stdout + r.stderr
    gains_path = Path(r.stdout.strip().splitlines()[-1].removeprefix("gains: "))
    assert gains_path.is_relative_to(REPO / "build" / "arms") and gains_path.name == "tune7.tuned_gains.json"
    assert not (tmp_path / "tuned_gains.json").exists()  # never next to the config: that is the bundled arm's
    r = armctl("study", "--model", model, "--config", str(cfg), "--duration", "0.2", "--methods", "pm,tde",
               "--out", str(tmp_path / "study"))
    assert r.returncode == 0, r.stdout + r.stderr
    study = json.loads((tmp_path / "study" / "study.json").read_text())
    assert study["tuning"]["source"] == f"tuned on this arm ({gains_path})"
    assert len(study["runs"]["tde"]["tracking_max_abs_deg"]) == 7


def test_demo_on_another_arm(tmp_path: Path) -> None:
    r = armctl("demo", "--arm", str(REPO / "tests" / "arms" / "panda.toml"), "--duration", "0.2",
               "--out", str(tmp_path))
    assert r.returncode == 0, r.stdout + r.stderr
    study = json.loads((tmp_path / "study.json").read_text())
    assert study["arm"]["name"] == "panda" and study["arm"]["n_joints"] == 7
    assert all(res["result"] == "ok" for res in study["runs"].values())


def test_synth(tmp_path: Path) -> None:
    r = armctl("synth", "--config", str(REPO / "gen" / "configs" / "paper.toml"), "--out", str(tmp_path))
    assert r.returncode == 0, r.stdout + r.stderr
    assert {"manifest.json", "pm_design_float.h", "pm_design_fixed.h"} <= {p.name for p in tmp_path.iterdir()}


@pytest.mark.parametrize("args", [["--preset", "debug"], ["--preset", "release"], ["--target", "host"],
                                  ["--target", "aarch64"], ["--target", "cortex-m4"], ["--target", "cortex-m7"],
                                  ["--target", "cortex-m3"]])
def test_build(args: list[str]) -> None:
    r = armctl("build", *args)
    assert r.returncode == 0, r.stdout + r.stderr


def test_bench(tmp_path: Path) -> None:
    r = armctl("bench", "step", "--quick", "--out", str(tmp_path / "step.json"))
    assert r.returncode == 0, r.stdout + r.stderr
    step = json.loads((tmp_path / "step.json").read_text())
    assert step["quick"] and step["methods"]["pm"]["float"] > 0
    r = armctl("bench", "synth", "--quick", "--out", str(tmp_path / "synth.json"))
    assert r.returncode == 0, r.stdout + r.stderr
    assert json.loads((tmp_path / "synth.json").read_text())["synth_n6"][0]["wall_time_median_s"] > 0
    r = armctl("bench", "sim", "--quick", "--out", str(tmp_path / "sim.json"))
    assert r.returncode == 0, r.stdout + r.stderr
    sim = json.loads((tmp_path / "sim.json").read_text())
    assert sim["quick"] and sim["realtime_factor_median"] > 0 and sim["bare_mj_step_us"] > 0
    assert set(sim["breakdown_us_per_period"]) == {"physics", "bus_tx", "bus_rx", "telemetry", "drives_and_rest",
                                                   "total"}


def test_busload() -> None:
    r = armctl("busload")
    assert r.returncode == 0, r.stdout + r.stderr
    r = armctl("busload", "--bus", "fd:1M/5M:1-6")
    assert r.returncode != 0 and "531" in r.stdout + r.stderr  # one FD bus: over budget, names the rate that fits


def test_vcan_status_and_up() -> None:
    """status always answers; up creates vcan0 where the kernel has CAN, else says why and fails."""
    from tools.vcan import kernel_has_can

    r = armctl("vcan", "status")
    assert r.returncode == 0 and "kernel SocketCAN" in r.stdout, r.stdout + r.stderr
    has_can, _ = kernel_has_can()
    if not has_can:
        r = armctl("vcan", "up")
        assert r.returncode == 1 and "no SocketCAN" in r.stderr and "vcan run" in r.stderr, r.stderr
    elif shutil.which("ip"):
        r = armctl("vcan", "up", "--iface", "vcan0")
        assert r.returncode == 0, r.stdout + r.stderr
