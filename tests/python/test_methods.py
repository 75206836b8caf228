"""One list of methods: the core's method table (firmware/core/src/methods.c). The controller's
usage and --method errors, armctl's --method choices, the benchmarks and the study's method map all
come from it; this holds them together without another list to keep."""

from __future__ import annotations

import subprocess
from pathlib import Path

from tools import bench
from tools.methods import TABLE, firmware_methods, method_names
from gen.lib.paths import REPO
from tools.study.config import METHODS as STUDY_METHODS


def test_the_table_is_read_in_its_order_with_its_design_flags() -> None:
    text = TABLE.read_text()
    names = method_names()
    assert names and len(set(names)) == len(names)
    positions = [text.index(f'"{n}"') for n in names]
    assert positions == sorted(positions)
    assert {n for n, design in firmware_methods().items() if design} == {"pm", "pm-paper", "gh2"}


def test_the_controller_lists_exactly_the_table(controller_bin: Path) -> None:
    usage = subprocess.run([str(controller_bin), "--help"], capture_output=True, text=True).stdout
    line = next(ln for ln in usage.splitlines() if "--method NAME" in ln)
    assert [w for w in line.split("NAME", 1)[1].split("[")[0].replace("|", " ").split()] == list(method_names())
    r = subprocess.run([str(controller_bin), "--method", "no-such"], capture_output=True, text=True)
    assert r.returncode == 2 and f"known: {', '.join(method_names())}" in r.stderr


def test_armctl_bench_and_the_study_take_the_table() -> None:
    r = subprocess.run([str(REPO / "tools" / "armctl"), "hil", "--help"], cwd=REPO, capture_output=True, text=True)
    choices = r.stdout.split("--method {", 1)[1].split("}", 1)[0].split(",")
    # the table's methods, then the study's variants of them (pm-paper-weights: pm with the paper's design)
    assert tuple(choices[:len(method_names())]) == method_names()
    assert set(choices[len(method_names()):]) == set(STUDY_METHODS) - set(method_names())
    assert bench.METHODS == method_names()
    # every study variant runs a firmware method of the table
    assert {fw for fw, _ in STUDY_METHODS.values()} <= set(method_names())
