"""Every command in the command table (docs/reference/commands.md) runs, in a short form, through tools/armctl itself
(the bash bootstrap and the CLI, exactly as a user types it), so a documented command cannot rot
unseen. EXERCISED says where each one runs; the first test holds the table and EXERCISED equal."""

from __future__ import annotations

import ast
import json
import math
import re
import shutil
import signal
import subprocess
import tomllib
from pathlib import Path

import pytest

from study_configs import with_tuning
from gen.lib.paths import DOCS, REPO
from tools.run.procs import communicate_or_kill

pytestmark = pytest.mark.long  # minutes: every documented command

ARMCTL = str(REPO / "tools" / "armctl")
COMMANDS_PAGE = DOCS / "reference" / "commands.md"

# Documented command -> the test that runs it through the CLI ("file::function"), or "CI".
EXERCISED: dict[str, str] = {
    "demo": "test_documented_commands.py::test_demo",
    "test": "CI",  # .ci/run is exactly `tools/armctl test`
    "hil": "test_documented_commands.py::test_hil",
    "hil --bus vm": "test_vcan_vm.py::test_hil_in_the_vm_through_the_cli",
    "hil --bus sil": "test_documented_commands.py::test_hil",
    "study": "test_documented_commands.py::test_study",
    "tune": "test_documented_commands.py::test_tune",
    "synth": "test_documented_commands.py::test_synth",
    "build": "test_documented_commands.py::test_build",
    "bench step": "test_documented_commands.py::test_bench",
    "bench synth": "test_documented_commands.py::test_bench",
    "bench sim": "test_documented_commands.py::test_bench",
    "bench study": "test_documented_commands.py::test_bench",
    "bench pil": "test_pil.py::test_bench_pil_runs_in_its_short_form",
    "hil --target": "test_pil.py::test_documented_command_ends_ok",
    "drive check": "test_canopen_vendor.py::test_drive_check_says_whether_this_controller_can_run_it",
    "plant": "test_run_on_arm.py::rehearsal",  # and every other test there: its arm is the plant
    "commission": "test_run_on_arm.py::rehearsal",
    "run": "test_run_on_arm.py::rehearsal",
    "identify": "test_identify.py::identified",  # and the bad-input test there
    "arms": "test_arm_matrix.py::test_armctl_arms_runs_a_set_end_to_end",
    "timing": "test_timing.py::timing_run",
    "busload": "test_documented_commands.py::test_busload",
    "vcan status": "test_documented_commands.py::test_vcan_status_and_up",
    "vcan up": "test_documented_commands.py::test_vcan_status_and_up",
    "vcan setup": "test_vcan_vm.py::test_vcan_setup_run_and_up_in_the_vm",
    "vcan run": "test_vcan_vm.py::vm_run",  # the fixture: the VM run every test of that file reads
    "fuzz": "test_fuzz.py::test_every_harness_runs_clean",
    "docs": "test_docs.py::test_armctl_docs_check_finds_every_figure_rendered_from_its_results_file",
    "faults": "test_faults.py::matrix",
    "cluster-certs": "test_runner.py::test_cluster_certs_make_a_ca_and_refuse_to_overwrite",
    "hil --model|--arm": "test_arm_hil.py::test_lockstep_hil_run_is_ok_within_stated_bounds",
    "build --model|--arm": "test_arm_hil.py::built_arm",
    "synth --model|--arm": "test_arm_hil.py::built_arm",
    "study --model|--arm": "test_documented_commands.py::test_tune_and_study_on_another_arm",
    "tune --model|--arm": "test_documented_commands.py::test_tune_and_study_on_another_arm",
    "demo --model|--arm": "test_documented_commands.py::test_demo_on_another_arm",
    "render": "test_seeing_runs.py::test_render_writes_the_video_and_strip_of_a_run",
    "export": "test_seeing_runs.py::test_mcap_export_reads_back_message_for_message",
    "lock": "test_lock.py::test_the_lock_is_what_armctl_lock_makes_from_the_requirements",
}


def documented_commands() -> set[str]:
    """The command table (docs/reference/commands.md): `tools/armctl SUB ...`, with alternatives of
    a first positional word (`bench step|synth`) and of --bus's vm form expanded."""
    section = COMMANDS_PAGE.read_text()
    out: set[str] = set()
    for cell in re.findall(r"^\| `tools/armctl ([^`]+)`", section, re.M):
        words = cell.replace("\\|", "|").split()
        sub = words[0]
        if len(words) > 1 and re.fullmatch(r"[a-z]+(\|[a-z]+)+", words[1]):
            out.update(f"{sub} {alt}" for alt in words[1].split("|"))
        elif len(words) > 1 and re.fullmatch(r"[a-z]+", words[1]):  # a subcommand (drive check)
            out.add(f"{sub} {words[1]}")
        elif sub == "hil" and len(words) > 1 and words[1] == "--target":  # processor in the loop
            out.add("hil --target")
            continue
        else:
            out.add(sub)
        if sub == "hil" and "vm" in cell:
            out.add("hil --bus vm")
        if sub == "hil" and "sil" in cell:
            out.add("hil --bus sil")
        if "--model FILE" in cell or "--arm FILE" in cell:  # one code path for both (tools/build/arm.py)
            out.add(f"{sub} --model|--arm")
    return out


def armctl(*args: str, timeout: float = 900.0) -> subprocess.CompletedProcess[str]:
    """armctl, stopped with SIGTERM on a timeout: it then stops its own children (tools/run/procs.py),
    so a hung command fails this test and leaves no process behind to fail the others."""
    p = subprocess.Popen([ARMCTL, *args], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        p.send_signal(signal.SIGTERM)
        out, err = communicate_or_kill(p, 60)
        raise AssertionError(f"armctl {' '.join(args)}: no end after {timeout:g} s\n{out}\n{err[-3000:]}") from None
    return subprocess.CompletedProcess(p.args, p.returncode, out, err)


def test_every_documented_command_is_exercised() -> None:
    documented = documented_commands()
    assert documented, f"no command table found in {COMMANDS_PAGE}"
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
    assert list(study["scenarios"]) == ["ideal", "realistic", "realistic+payload", "realistic+friction+parameter-error"]
    for sc in study["scenarios"].values():
        assert set(sc["runs"]) == {"pm", "pm-paper-weights", "pm-paper", "pd", "gh2", "tde", "usde-smc"}
        assert all(rec["source"].startswith("tuned earlier") for rec in sc["tuning"].values())  # the kept tuning
    assert (tmp_path / "report.md").is_file()
    page = (tmp_path / "report.html").read_text()  # the same report for a browser (test_seeing_runs.py opens one)
    assert page.count('<div class="figure" data-figure=') >= 5 * len(study["scenarios"]) and "Plotly.newPlot" in page


def test_hil(tmp_path: Path) -> None:
    r = armctl("hil", "--duration", "0.3", "--method", "tde", "--out", str(tmp_path))
    assert r.returncode == 0, r.stdout + r.stderr
    run = json.loads((tmp_path / "run.json").read_text())
    assert run["results"]["result"] == "ok" and run["results"]["method"] == "tde"
    assert "result ok" in r.stdout
    r = armctl("hil", "--duration", "0.3", "--method", "tde", "--drives", "realistic", "--out", str(tmp_path / "real"))
    run = json.loads((tmp_path / "real" / "run.json").read_text())
    assert r.returncode == 0 and run["results"]["result"] == "ok", (r.stderr, run["results"]["verdict_reasons"])
    assert run["results"]["drives"]["encoder_bits"] == 19  # the realistic drives ran, and tde runs them ok
    r = armctl("hil", "--bus", "sil", "--capture", "--duration", "0.3", "--method", "tde", "--out", str(tmp_path / "sil"))
    assert r.returncode == 0 and "bus: sil" in r.stdout, r.stdout + r.stderr
    sil = json.loads((tmp_path / "sil" / "run.json").read_text())
    assert sil["results"] == json.loads((tmp_path / "run.json").read_text())["results"]  # the same run over UDP
    assert (tmp_path / "sil" / "bus.log").stat().st_size > 0


def test_study(tmp_path: Path) -> None:
    """--no-figures: the report's tables alone, and no figure of an earlier study of its scenario
    left beside them (another scenario's is not this study's to remove). The figures themselves:
    test_demo and tests/python/test_study.py."""
    for stale in ("fig_tuning_ideal.png", "fig_tracking_error_ideal.png", "fig_tuning_realistic.png"):
        (tmp_path / stale).write_bytes(b"an earlier study's")
    r = armctl("study", "--duration", "0.2", "--methods", "pm,tde", "--scenarios", "ideal", "--seeds", "2",
               "--jobs", "2", "--no-figures", "--out", str(tmp_path))
    assert r.returncode == 0, r.stdout + r.stderr
    study = json.loads((tmp_path / "study.json").read_text())
    assert set(study["scenarios"]["ideal"]["runs"]) == {"pm", "tde"} and study["seeds"] == [1, 2]
    report = (tmp_path / "report.md").read_text()
    assert "Figures: not drawn (`--no-figures`)." in report and "![" not in report and "### Verdict" in report
    assert sorted(p.name for p in tmp_path.glob("*.png")) == ["fig_tuning_realistic.png"]


def small_tuning_config(dirpath: Path) -> Path:
    """The default config with 0.2 s tuning runs (the budget comes from --trials)."""
    text = with_tuning((REPO / "tools" / "studies" / "paper.toml").read_text(), duration_s=0.2, batch=2)
    cfg = dirpath / "tune7.toml"
    cfg.write_text(text)
    assert tomllib.loads(text)["tuning"]["duration_s"] == 0.2
    return cfg


def test_tune(tmp_path: Path) -> None:
    """One pair (--retune SCENARIO/METHOD), two trials on a 0.2 s tuning run; the tuning lands next
    to the config, and only that pair is tuned. (--verify: tests/python/test_tuning_verify.py.)"""
    cfg = small_tuning_config(tmp_path)
    r = armctl("tune", "--config", str(cfg), "--retune", "realistic/pd", "--trials", "2", "--out", str(tmp_path / "runs"))
    assert r.returncode == 0, r.stdout + r.stderr
    tuning = json.loads((tmp_path / "paper.tuning.json").read_text())
    assert list(tuning["scenarios"]) == ["realistic"] and list(tuning["scenarios"]["realistic"]) == ["pd"]
    assert len(tuning["scenarios"]["realistic"]["pd"]["rounds"][0]["trials"]) == 2
    r = armctl("tune", "--config", str(cfg), "--retune", "realistic/pm-paper-weights", "--out", str(tmp_path / "runs"))
    assert r.returncode == 2 and "--retune 'realistic/pm-paper-weights': not SCENARIO/METHOD" in r.stderr, r.stderr


def test_tune_and_study_on_another_arm(tmp_path: Path) -> None:
    """tune on a 7-DOF arm keeps its tuning in the arm's build folder; the study then uses it."""
    cfg = small_tuning_config(tmp_path)
    model = str(REPO / "tests" / "arms" / "robosuite" / "iiwa.xml")
    common = ["--model", model, "--config", str(cfg), "--scenarios", "ideal", "--methods", "pm", "--trials", "2"]
    r = armctl("tune", *common, "--out", str(tmp_path / "runs"))
    assert r.returncode == 0, r.stdout + r.stderr
    kept = Path(next(ln for ln in r.stdout.splitlines() if ln.startswith("tuning: ")).removeprefix("tuning: "))
    assert kept.is_relative_to(REPO / "build" / "arms") and kept.name == "tune7.paper.tuning.json"
    assert not (tmp_path / "paper.tuning.json").exists()  # never next to the config: that is the bundled arm's
    r = armctl("study", *common, "--duration", "0.2", "--no-figures", "--out", str(tmp_path / "study"))
    assert r.returncode == 0, r.stdout + r.stderr
    study = json.loads((tmp_path / "study" / "study.json").read_text())
    sc = study["scenarios"]["ideal"]
    assert sc["tuning"]["pm"]["source"] == f"tuned earlier, kept in {kept}"
    assert len(sc["runs"]["pm"][0]["tracking_max_abs_deg"]) == 7


def test_demo_on_another_arm(tmp_path: Path) -> None:
    r = armctl("demo", "--arm", str(REPO / "tests" / "arms" / "panda.toml"), "--duration", "0.2",
               "--scenarios", "ideal", "--trials", "2", "--no-figures", "--out", str(tmp_path))
    assert r.returncode == 0, r.stdout + r.stderr
    study = json.loads((tmp_path / "study.json").read_text())
    assert study["arm"]["name"] == "panda" and study["arm"]["n_joints"] == 7
    assert all(len(runs[0]["tracking_max_abs_deg"]) == 7 for runs in study["scenarios"]["ideal"]["runs"].values())


def test_synth(tmp_path: Path) -> None:
    r = armctl("synth", "--config", str(REPO / "gen" / "configs" / "paper.toml"), "--out", str(tmp_path))
    assert r.returncode == 0, r.stdout + r.stderr
    assert {"manifest.json", "pm_design_float.h", "pm_design_fixed.h", "pm_design.txt"} <= {p.name for p in tmp_path.iterdir()}


def _elf_machine(path: Path) -> int:
    """An ELF file's e_machine (62 x86-64, 183 AArch64, 40 ARM); 0 if it is no ELF."""
    head = path.read_bytes()[:20]
    return int.from_bytes(head[18:20], "little") if head[:4] == b"\x7fELF" else 0


# What each build leaves: (a file it built, its ELF machine).
BUILT = {"debug": ("build/debug/firmware/arm_controller", 62), "release": ("build/release/firmware/arm_controller", 62),
         "host": ("build/release/host_sim/native/arm_sil", 62),
         "aarch64": ("build/aarch64/firmware/arm_controller", 183),
         **{t: (f"build/{t}/firmware/port/cortex_m/pil_{t}.elf", 40) for t in ("cortex-m4", "cortex-m7", "cortex-m3")}}


@pytest.mark.parametrize("args", [["--preset", "debug"], ["--preset", "release"], ["--target", "host"],
                                  ["--target", "aarch64"], ["--target", "cortex-m4"], ["--target", "cortex-m7"],
                                  ["--target", "cortex-m3"]])
def test_build(args: list[str]) -> None:
    """Each preset or target builds, and what it built is there, for its machine, and newer than
    every firmware source (a build that said ok and built nothing fails)."""
    r = armctl("build", *args)
    assert r.returncode == 0, r.stdout + r.stderr
    path, machine = BUILT[args[1]]
    exe = REPO / path
    assert exe.is_file() and _elf_machine(exe) == machine, (path, _elf_machine(exe) if exe.exists() else "missing")
    # built from the sources as they are: no newer than it is any source of the controller's core
    newest = max((p for p in (REPO / "firmware").rglob("*.[ch]")), key=lambda p: p.stat().st_mtime)
    assert exe.stat().st_mtime >= newest.stat().st_mtime, f"{path} is older than {newest.relative_to(REPO)}"


def test_bench(tmp_path: Path) -> None:
    r = armctl("bench", "step", "--quick", "--out", str(tmp_path / "step.json"))
    assert r.returncode == 0, r.stdout + r.stderr
    step = json.loads((tmp_path / "step.json").read_text())
    assert step["quick"] and step["methods"]["pm"]["float"] > 0
    r = armctl("bench", "synth", "--quick", "--out", str(tmp_path / "synth.json"))
    assert r.returncode == 0, r.stdout + r.stderr
    assert json.loads((tmp_path / "synth.json").read_text())["synth_n6"][0]["wall_time_median_s"] > 0
    r = armctl("bench", "study", "--quick", "--out", str(tmp_path / "study.json"))
    assert r.returncode == 0, r.stdout + r.stderr
    study = json.loads((tmp_path / "study.json").read_text())
    for bus in ("sil", "udp"):
        b = study["buses"][bus]
        assert study["quick"] and b["jobs"]["1"]["runs_per_minute"] > 0 and b["jobs"]["2"]["simulated_s_per_wall_s"] > 0
    r = armctl("bench", "sim", "--quick", "--out", str(tmp_path / "sim.json"))
    assert r.returncode == 0, r.stdout + r.stderr
    sim = json.loads((tmp_path / "sim.json").read_text())
    assert sim["quick"] and sim["bare_mj_step_us"] > 0
    assert sim["sil"]["realtime_factor_median"] > 0 and sim["lockstep_udp"]["realtime_factor_median"] > 0
    for where, rest in (("sil", "controller_and_handoffs"), ("lockstep_udp", "drives_and_rest")):
        parts = sim[where]["breakdown_us_per_period"]
        assert set(parts) == {"physics", "bus_tx", "bus_rx", "telemetry", rest, "total"}
        # every part a time (none negative: the rest is what the measured parts leave of the total)
        assert all(isinstance(v, (int, float)) and math.isfinite(v) and v >= 0 for v in parts.values()), (where, parts)
        assert parts["total"] > 0 and math.isclose(sum(v for k, v in parts.items() if k != "total"), parts["total"],
                                                   rel_tol=1e-6, abs_tol=1e-3), (where, parts)


def test_busload() -> None:
    r = armctl("busload")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "--bus classic:1M:1-2 --bus classic:1M:3-4 --bus classic:1M:5-6" in r.stdout  # the CiA 402 drives'
    r = armctl("busload", "--protocol", "arm", "--bus", "fd:1M/5M:1-6")
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
        link = subprocess.run(["ip", "-details", "link", "show", "vcan0"], capture_output=True, text=True)
        assert link.returncode == 0 and "vcan" in link.stdout and ",UP" in link.stdout, link.stdout + link.stderr
