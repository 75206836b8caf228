"""A design loaded at run time (--design-file, gen.synth's pm_design.txt) runs bit for bit like the
same design compiled into the firmware: the same run.json results and the same torques, period by
period; the runner's software-in-the-loop path (the design synthesised in-process, the arm's own
arm_sil) matches the slot build it replaces; and a bad design file is refused in one line, exit 2."""

from __future__ import annotations

import json
import subprocess
from dataclasses import asdict
from pathlib import Path
from typing import Any

import pytest

from tools.build.arm import DEFAULT_ARM, arm_build_dir, arm_info, build_arm
from tools.study.design_knobs import design_text
from tools.run.hil import HilOptions, run_hil
from tools.run.runner import RunSpec, SIL_DESIGNS, execute, slot_arm, slot_has_design
from tools.run.slots import acquire_slot
from tools.study import DEFAULT_CONFIG
from tools.study.config import for_arm, load
from tools.run.telemetry_log import read_log

CFG = load(DEFAULT_CONFIG)
SCENARIO = "realistic+friction+parameter-error"  # drives, friction and model error: every path of the loop
HOLD = ("--ref-hold", "0.1")
DURATION = 1.4


def _scenario(bdir: Path) -> Any:
    return for_arm(CFG, arm_info(bdir)).scenarios[SCENARIO]


def _same_telemetry(a: Path, b: Path, what: str) -> None:
    logs = [read_log(d / "telemetry.lcmlog") for d in (a, b)]
    for channel, field in (("ARM_CTL", "tau"), ("ARM_CTL", "u_o"), ("ARM_CTL", "w_hat"), ("ARM_SIM", "tau_applied")):
        series = [[list(getattr(m, field)) for m in log[channel].messages] for log in logs]
        assert series[0] and series[0] == series[1], f"{what}: {channel}.{field} differs"


@pytest.mark.parametrize("method,numeric", [("pm", "float"), ("pm", "fixed"), ("pm-paper", "float"), ("gh2", "float")])
def test_built_in_and_loaded_design_run_bit_for_bit_alike(tmp_path: Path, controller_bin: Path, method: str,
                                                          numeric: str) -> None:
    preset = controller_bin.parent.parent.name
    bdir = arm_build_dir(preset, DEFAULT_ARM)
    info, sc = arm_info(bdir), _scenario(bdir)
    loaded = bdir / "generated" / "design" / "pm_design.txt"

    def run(name: str, **design: Any) -> dict[str, Any]:
        return run_hil(HilOptions(out=tmp_path / name, duration_s=DURATION, method=method, preset=preset, bus="sil",
                                  controller_args=(*HOLD, "--numeric", numeric),
                                  uncertainty={**sc.uncertainty, "seed": 5}, drives=sc.drives,
                                  bus_timing=sc.bus_timing, **design))

    built_in = run("built-in")
    from_file = run("loaded", design_file=loaded, design_record=info["design"])
    # (a method the safety layer stops in this scenario must stop the same way from the file)
    assert built_in["results"]["steps"] > 500 and built_in["results"]["design_hash"], built_in["results"]
    differ = {k: (built_in["results"].get(k), from_file["results"].get(k))
              for k in set(built_in["results"]) | set(from_file["results"])
              if built_in["results"].get(k) != from_file["results"].get(k)}
    assert not differ, differ
    _same_telemetry(tmp_path / "built-in", tmp_path / "loaded", f"{method} {numeric}")


def test_the_runner_s_sil_path_matches_the_slot_build(tmp_path: Path) -> None:
    """A tuning trial's design (split form: a dynamic controller) through tools/run/runner.py execute
    in software in the loop (synthesised in-process, loaded by the arm's own arm_sil) against the
    per-slot build the HIL path still makes: the same design hash, results and torques."""
    bdir = build_arm("release", DEFAULT_ARM, targets=["arm_sil"])
    sc = _scenario(bdir)
    base = (bdir / "generated" / "arm" / "design.toml").read_text()
    text = design_text(base, {"form": "split", "wn": 22.0, "zeta": 0.9, "f_bw": 3.0, "H": 0.4})
    spec = RunSpec(out=str(tmp_path / "runtime"), method="pm", duration_s=DURATION, controller_args=HOLD,
                   uncertainty={**sc.uncertainty, "seed": 3}, drives=sc.drives.to_dict(), bus_timing=sc.bus_timing,
                   design_text=text, bus="sil")
    runtime = execute(asdict(spec))
    assert runtime["environment"]["build"] == str(bdir)  # the arm's own build: nothing built for the design
    assert runtime["results"]["design"]["why"] == "loaded at run time (--design-file)"
    assert Path(runtime["results"]["design"]["config"]).is_relative_to(SIL_DESIGNS)
    with acquire_slot() as slot:
        arm = slot_arm(DEFAULT_ARM, slot.index, text)
        build_arm("release", arm, targets=["arm_sil"])
        built = run_hil(HilOptions(out=tmp_path / "slot", duration_s=DURATION, method="pm", arm=arm, bus="sil",
                                   controller_args=HOLD, uncertainty={**sc.uncertainty, "seed": 3},
                                   drives=sc.drives, bus_timing=sc.bus_timing, brakes="released"))  # as the runner's
    a, b = runtime["results"], built["results"]
    assert a["design_hash"] and a["design_hash"] == b["design_hash"]
    own = json.loads((bdir / "generated" / "design" / "manifest.json").read_text())["content_hash"][:16]
    assert a["design_hash"] != own and a["steps"] > 1000  # the trial's design ran, not the build's
    # everything but where the design's config came from (a slot's file, or the runner's cache)
    differ = {k: (a.get(k), b.get(k)) for k in set(a) | set(b) if k != "design" and a.get(k) != b.get(k)}
    assert not differ, differ
    _same_telemetry(tmp_path / "runtime", tmp_path / "slot", "runner SIL path vs slot build")
    # the four seeds of a trial synthesise once: a second run finds the design made
    folder = Path(runtime["results"]["design"]["config"]).parent
    made = (folder / "pm_design.txt").stat().st_mtime_ns
    execute(asdict(RunSpec(**{**asdict(spec), "out": str(tmp_path / "again"), "controller_args": HOLD})))
    assert (folder / "pm_design.txt").stat().st_mtime_ns == made


def test_a_slot_built_design_is_recorded_the_same_whichever_slot_ran_it(tmp_path: Path) -> None:
    """Over a bus a run of a design of its own is built into its run slot's folder; which slot it
    gets depends on what runs beside it. run.json names the design by a copy kept by its content,
    the same from every slot and never rewritten, not by the slot's file (which the slot's next
    design overwrites). Found when the test suite first ran its tests side by side."""
    bdir = build_arm("release", DEFAULT_ARM, targets=["arm_sil"])
    base = (bdir / "generated" / "arm" / "design.toml").read_text()
    text = design_text(base, {"form": "split", "wn": 21.0, "zeta": 0.9, "f_bw": 3.0, "H": 0.4})
    spec = RunSpec(out="", method="pm", duration_s=0.3, controller_args=HOLD, uncertainty={}, design_text=text,
                   bus="udp")
    first = execute(asdict(RunSpec(**{**asdict(spec), "out": str(tmp_path / "a")})))
    with acquire_slot(prefer=lambda i: slot_has_design(DEFAULT_ARM, i, text)):  # the slot that built it, held
        second = execute(asdict(RunSpec(**{**asdict(spec), "out": str(tmp_path / "b")})))
    assert first["environment"]["build"] != second["environment"]["build"]  # two slots' folders
    a, b = first["results"]["design"], second["results"]["design"]
    assert a == b and Path(a["config"]).read_text() == text, (a, b)
    assert first["results"]["design_hash"] == second["results"]["design_hash"]


def _bad_files(good: Path, tmp_path: Path) -> list[tuple[Path, str]]:
    lines = good.read_text().splitlines(keepends=True)
    est_b = next(i for i, ln in enumerate(lines) if ln.startswith("est_b "))
    n_joints = next(i for i, ln in enumerate(lines) if ln.startswith("n_joints "))
    short = tmp_path / "short.txt"  # one number of est_b lost
    short.write_text("".join(lines[:est_b]) + lines[est_b].rsplit(" ", 1)[0] + "\n" + "".join(lines[est_b + 1:]))
    seven = tmp_path / "seven.txt"
    seven.write_text("".join(lines[:n_joints]) + "n_joints 7\n" + "".join(lines[n_joints + 1:]))
    return [(short, f"{short}:{est_b + 1}: est_b: 2 values expected, found 1"),
            (seven, f"{seven}:{n_joints + 1}: n_joints: 7 joints; this build's arm has 6")]


def test_a_bad_design_file_is_refused_in_one_line(tmp_path: Path, controller_bin: Path) -> None:
    good = controller_bin.parent.parent / "generated" / "design" / "pm_design.txt"
    sil = controller_bin.parent.parent / "host_sim" / "native" / "arm_sil"
    for path, message in _bad_files(good, tmp_path):
        for argv in ([str(controller_bin), "--design-file", str(path)],
                     [str(sil), "--controller", "--design-file", str(path), "--simulator"]):
            r = subprocess.run(argv, capture_output=True, text=True, timeout=60)
            assert r.returncode == 2, (argv, r.stderr)
            assert r.stderr.count("\n") == 1 and message in r.stderr, r.stderr
