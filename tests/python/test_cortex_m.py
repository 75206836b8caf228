"""The bare-metal Cortex-M images: built with arm-none-eabi (newlib-nano), run under
qemu-system-arm with semihosting, pass their golden vectors (MuJoCo's RNEA, the host build's
closed loop for every method), and fit the part's flash, RAM and stack budget."""

from __future__ import annotations

import json
import re
import shutil
import subprocess

import pytest

from tools.build import build, toolchain_missing
from tools.build.cortex_m import MACHINES, run_image, step_costs
from gen.lib.paths import build_dir


def _image(preset: str):
    missing = toolchain_missing(preset)
    if missing:
        pytest.skip(f"{preset}: {missing}")
    if shutil.which("qemu-system-arm") is None:
        pytest.skip("qemu-system-arm not found: apt-get install qemu-system-arm (tools/armctl does as root)")
    build(preset)
    return build_dir(preset) / "firmware" / "port" / "cortex_m"


@pytest.fixture(scope="module", params=list(MACHINES))
def image_run(request: pytest.FixtureRequest) -> tuple[str, dict, subprocess.CompletedProcess[str]]:
    preset = request.param
    d = _image(preset)
    report = json.loads((d / "memory_report.json").read_text())
    return preset, report, run_image(preset)


def test_image_passes_its_golden_vectors(image_run) -> None:
    preset, _, run = image_run
    out = run.stdout + run.stderr
    assert run.returncode == 0, out
    assert f"golden vectors on {preset}" in out
    assert "RESULT: PASS" in out
    assert re.search(r"rnea: 200 states vs mj_inverse, worst relative error \S+ ok", out), out
    assert re.search(r"rnea kernel: 200 states vs mj_inverse, worst relative error \S+ ok", out), out
    loops = re.findall(r"^closed loop: (\S+) (float|fixed), .* ok$", out, re.M)
    assert len(loops) >= 6 and {"pd", "pm"} <= {m for m, _ in loops}, out
    assert "FAIL" not in out


def test_memory_fits_the_part_and_the_static_stack_bound_covers_the_measured_one(image_run) -> None:
    preset, report, run = image_run
    assert report["ok"] and not report["problems"] and not report["over_budget"], report
    assert 0 < report["flash_bytes"] <= report["flash_budget"]
    assert 0 < report["ram_bytes"] <= report["ram_budget"]
    assert report["stack_worst_case_bytes"] <= report["stack_reserved_bytes"] <= report["stack_budget"]
    assert report["stack_main_path"][:2] == ["Reset_Handler", "main"]
    measured = int(re.search(r"stack high-water mark \(measured\): (\d+) bytes", run.stdout + run.stderr).group(1))
    # The call-graph sum is an upper bound of what any run can use; the painted stack is one run.
    assert 0 < measured <= report["stack_worst_case_bytes"], (measured, report["stack_worst_case_bytes"])


def test_step_cost_is_counted_in_instructions(image_run) -> None:
    """Under -icount shift=0 a SysTick tick is a whole number of instructions (the calibration);
    the step, the kernel and the general RNEA each cost what their parts say."""
    _, _, run = image_run
    out = run.stdout + run.stderr
    per_tick = float(re.search(r"instructions per SysTick tick \(calibrated .*\) (\S+)", out).group(1))
    assert per_tick >= 1 and abs(per_tick - round(per_tick)) < 0.05, out
    cost = step_costs(out)
    assert set(cost) == {"pm step (float)", "rnea kernel", "rnea general"}, out
    assert 0 < cost["rnea kernel"] < cost["rnea general"], cost
    assert cost["rnea kernel"] < cost["pm step (float)"], cost  # the step runs the kernel, and more
