"""The Linux controller cross-compiled for aarch64 (static, LCM built for the target) runs a
lockstep HIL run under qemu-user against the native simulator on the loopback UDP bus, and its
run.json results match the native controller's within float tolerance."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

from tools.build import build, qemu_aarch64, toolchain_missing
from tools.run.hil import HilOptions, run_hil
from gen.lib.paths import build_dir

DURATION_S = 1.0
REL_TOL = 1e-4  # float32 on two ISAs and two libm's; measured: identical
ABS_TOL = 1e-7


def _diff(a: Any, b: Any, path: str = "results") -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        out = [f"{path}: key sets differ: {sorted(set(a) ^ set(b))}"] if set(a) != set(b) else []
        for k in sorted(set(a) & set(b)):
            out += _diff(a[k], b[k], f"{path}.{k}")
        return out
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{path}: lengths {len(a)} vs {len(b)}"]
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in _diff(x, y, f"{path}[{i}]")]
    if isinstance(a, float) or isinstance(b, float):
        if not math.isclose(float(a), float(b), rel_tol=REL_TOL, abs_tol=ABS_TOL):
            return [f"{path}: native {a!r} vs aarch64 {b!r}"]
        return []
    return [] if a == b else [f"{path}: native {a!r} vs aarch64 {b!r}"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, dict]:
    missing = toolchain_missing("aarch64")
    if missing:
        pytest.skip(f"aarch64 cross toolchain cannot be used: {missing}")
    build("release")
    build("aarch64")  # fetches the target's LCM source and glib from Debian on first use
    qemu = qemu_aarch64()  # QEMU 10 from backports: bookworm's 7.2 lacks IP_MULTICAST_IF
    a64_bin = build_dir("aarch64") / "firmware" / "arm_controller"
    native = run_hil(HilOptions(out=tmp_path_factory.mktemp("native"), duration_s=DURATION_S))
    a64 = run_hil(HilOptions(out=tmp_path_factory.mktemp("aarch64"), duration_s=DURATION_S,
                             controller=a64_bin, controller_cmd_prefix=(str(qemu),)))
    return native, a64


def test_the_aarch64_binary_is_a_static_aarch64_executable() -> None:
    if toolchain_missing("aarch64"):
        pytest.skip(str(toolchain_missing("aarch64")))
    build("aarch64")
    head = (build_dir("aarch64") / "firmware" / "arm_controller").read_bytes()[:64]
    assert head[:4] == b"\x7fELF" and head[4] == 2  # ELF64
    assert int.from_bytes(head[18:20], "little") == 183  # e_machine EM_AARCH64
    # Static: no program interpreter (PT_INTERP) in the program headers.
    data = (build_dir("aarch64") / "firmware" / "arm_controller").read_bytes()
    phoff = int.from_bytes(data[32:40], "little")
    phnum = int.from_bytes(data[56:58], "little")
    types = [int.from_bytes(data[phoff + 56 * i: phoff + 56 * i + 4], "little") for i in range(phnum)]
    assert 3 not in types


def test_aarch64_run_under_qemu_completes_like_the_native_one(runs: tuple[dict, dict]) -> None:
    native, a64 = runs
    for run in (native, a64):
        assert run["results"]["result"] == "ok", run["results"]["problems"]
        assert run["results"]["final_state"] == "running"
        assert run["transport"]["telemetry_lost_total"] == 0
    assert a64["results"]["steps"] == native["results"]["steps"] > 0


def test_aarch64_run_json_results_match_native_within_float_tolerance(runs: tuple[dict, dict]) -> None:
    native, a64 = runs
    diffs = _diff(native["results"], a64["results"])
    assert not diffs, "\n".join(diffs[:20])
