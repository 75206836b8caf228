"""Processor in the loop (docs/pil.md): the Cortex-M4 image runs the controller in qemu-system-arm
against the simulated arm over SLCAN.

- The image counts and drops what its SLCAN decoder refuses and goes on: a replay of a drive's
  SLCAN stream with garbage, too-long lines and bad DLCs among its frames
  (tests/c/transport/slcan_replay.txt), fed to the image's CAN UART through arm_pil_bridge.
- A PIL run ends ok, records the target and what the image measured in the loop, repeats bit for
  bit, and equals the software-in-the-loop run of the same method within the stated tolerances
  (tools/build/cortex_m.py).
- The documented command, `tools/armctl hil --target cortex-m4 --duration 3`, ends ok (every run
  here is made through it, in its short form)."""

from __future__ import annotations

import json
import shutil
import socket
import subprocess
import time
from pathlib import Path

import pytest

from gen.lib.paths import REPO, build_dir
from tools.build import build, toolchain_missing
from tools.build.cortex_m import (MACHINES, PIL_SIL_KINDS, PIL_SIL_PEAK_TOL, PIL_SIL_REL_TOL, PIL_SIL_W_TOL,
                                  STEP_INSTRUCTIONS_SPREAD, pil_image, pil_sil_differences)

# QEMU's vCPU polls its UARTs while it waits for the drives: a whole core for minutes; alone.
pytestmark = [pytest.mark.long, pytest.mark.serial]

REPLAY = REPO / "tests" / "c" / "transport" / "slcan_replay.txt"
DURATION_S = 0.3


def _need_target() -> None:
    missing = toolchain_missing("cortex-m4")
    if missing:
        pytest.skip(f"cortex-m4: {missing}")
    if shutil.which("qemu-system-arm") is None:
        pytest.skip("qemu-system-arm not found")
    build("cortex-m4")
    build("release")


def test_refused_slcan_lines_are_counted_and_dropped_by_the_image(tmp_path: Path) -> None:
    """The replay's frames reach the image's decoder with the refused lines among them: each refused
    one is counted under its kind, the frames are decoded, and the image ends its run as it would
    without them (here: no drive answers the boot; a boot failure, reported, not a fault)."""
    _need_target()
    base = 44600
    bridge = build_dir("release") / "tools" / "pil_bridge" / "arm_pil_bridge"
    proc = subprocess.Popen([str(bridge), "--machine", MACHINES["cortex-m4"], "--image",
                             str(pil_image(build_dir("cortex-m4"), "cortex-m4")), "--port-base", str(base),
                             "--pil-summary", str(tmp_path / "pil.json"), "--",
                             "--bus", "uart:0", "--protocol", "canopen", "--boot-timeout", "1",
                             "--summary", str(tmp_path / "controller_summary.json")],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        for _ in range(500):  # QEMU listens once it started
            try:
                peer = socket.create_connection(("127.0.0.1", base), timeout=1)
                break
            except OSError:
                time.sleep(0.02)
        else:
            pytest.fail("the image's UART 0 never listened")
        lines = [ln.rstrip("\n") for ln in REPLAY.read_text().splitlines() if ln and not ln.startswith("#")]
        peer.sendall(b"O\r" + "".join(ln + "\r" for ln in lines).encode())
        time.sleep(3.0)  # the image's boot gives up on the silent drives, then it waits for C
        peer.sendall(b"C\r")
        out, _ = proc.communicate(timeout=120)
        peer.close()
    finally:
        if proc.poll() is None:
            proc.kill()
    expect = dict(kv.split("=") for kv in
                  next(ln for ln in REPLAY.read_text().splitlines() if ln.startswith("# expect")).split()[2:])
    pil = json.loads((tmp_path / "pil.json").read_text())
    uart0 = pil["slcan"][0]
    assert pil["report"], out
    assert (uart0["garbage"], uart0["too_long"], uart0["bad_dlc"]) == (
        int(expect["garbage"]), int(expect["too_long"]), int(expect["bad_dlc"])), (uart0, out)
    assert uart0["frames"] >= int(expect["frames"]), (uart0, out)  # the replay's, and any answer after it
    summary = json.loads((tmp_path / "controller_summary.json").read_text())
    assert summary["result"] == 3 and summary["reason"].startswith("boot: canopen"), summary  # not a fault
    assert "cortex-m: FAULT" not in out, out


def _armctl_hil(out: Path, *args: str) -> subprocess.CompletedProcess:
    """The documented command's form: `tools/armctl hil ... --duration DURATION_S --out OUT`."""
    return subprocess.run([str(REPO / "tools" / "armctl"), "hil", *args, "--duration", str(DURATION_S), "--out",
                           str(out)], cwd=REPO, capture_output=True, text=True, timeout=3000)


@pytest.fixture(scope="module")
def commands(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[subprocess.CompletedProcess, dict | None]]:
    """The two M4 runs, the M7's and the SIL twin, each through the documented command and side by
    side: each QEMU keeps a core busy polling its UARTs, and a lockstep run's results do not depend
    on the wall clock (each run in a run slot of its own: its own ports). Each run's exit and its
    run.json (None when it wrote none)."""
    from concurrent.futures import ThreadPoolExecutor

    _need_target()
    build("cortex-m7")
    plan = (("pil_a", ("--target", "cortex-m4")), ("pil_b", ("--target", "cortex-m4")),
            ("m7", ("--target", "cortex-m7")), ("sil", ("--bus", "sil")))
    dirs = {name: tmp_path_factory.mktemp(name) for name, _ in plan}
    with ThreadPoolExecutor(max_workers=len(plan)) as pool:
        futs = {name: pool.submit(_armctl_hil, dirs[name], *args) for name, args in plan}
        done = {name: f.result() for name, f in futs.items()}
    return {name: (r, json.loads((dirs[name] / "run.json").read_text()) if (dirs[name] / "run.json").exists()
                   else None) for name, r in done.items()}


@pytest.fixture(scope="module")
def runs(commands: dict[str, tuple[subprocess.CompletedProcess, dict | None]]) -> dict[str, dict]:
    for name, (r, run) in commands.items():
        assert run is not None, f"{name}: no run.json (exit {r.returncode}):\n{r.stdout[-3000:]}{r.stderr[-3000:]}"
    return {name: run for name, (_, run) in commands.items()}


def test_pil_run_is_ok_and_records_what_the_image_measured(runs: dict[str, dict]) -> None:
    r = runs["pil_a"]
    assert r["results"]["result"] == "ok", r["results"]["verdict_reasons"]
    assert r["results"]["target"] == "cortex-m4" and r["results"]["numeric"] == "float"
    t = r["target"]
    steps = t["step_instructions"]
    assert steps["periods"] == r["results"]["steps"] and 1000 < steps["min"] <= steps["median"] <= steps["max"]
    assert t["stated_clock_hz"] == 168e6
    share = t["step_share_of_period_at_stated_clock"]
    assert share["median"] == pytest.approx(steps["median"] / 168e3)
    assert 1000 < t["stack_high_water_bytes"] < 8192
    assert all(b["garbage"] == b["too_long"] == b["bad_dlc"] == 0 for b in t["slcan"])
    assert r["transport"]["telemetry_lost_total"] == 0


def _deterministic(run: dict) -> dict:
    return {k: v for k, v in run["results"].items() if k not in ("problems",)}


def test_the_same_pil_run_twice_gives_the_same_results_bit_for_bit(runs: dict[str, dict]) -> None:
    a, b = _deterministic(runs["pil_a"]), _deterministic(runs["pil_b"])
    assert a == b
    sa, sb = runs["pil_a"]["target"]["step_instructions"], runs["pil_b"]["target"]["step_instructions"]
    assert sa["periods"] == sb["periods"]
    assert all(abs(sa[k] - sb[k]) <= STEP_INSTRUCTIONS_SPREAD for k in ("min", "median", "max")), (sa, sb)


def test_pil_equals_sil_within_the_stated_tolerance(runs: dict[str, dict]) -> None:
    """newlib's sinf/cosf and glibc's differ in the last bit (the RNEA kernel's joint rotations):
    the closed loop carries that along without amplifying it (docs/pil.md)."""
    pil, sil = runs["pil_a"]["results"], runs["sil"]["results"]
    assert sil["result"] == "ok"
    for key in ("steps", "final_state", "trajectory_periods", "method", "design_hash"):
        assert pil[key] == sil[key], key
    diff = pil_sil_differences(pil, sil)
    assert diff["relative"][0] <= PIL_SIL_REL_TOL and diff["peak"][0] <= PIL_SIL_PEAK_TOL, diff
    assert diff["estimation_over_w"][0] <= PIL_SIL_W_TOL, diff
    assert pil["tracking_rms_deg"] != sil["tracking_rms_deg"] or pil == sil  # compared, not skipped


def test_the_cortex_m7_equals_sil_bit_for_bit(runs: dict[str, dict]) -> None:
    """The M7's newlib gives the same sines and cosines as glibc on these runs' angles: its PIL run's
    results are the SIL run's, bit for bit (docs/pil.md)."""
    m7 = runs["m7"]
    assert m7["results"]["result"] == "ok", m7["results"]["verdict_reasons"]
    sil = runs["sil"]["results"]
    diff = pil_sil_differences(m7["results"], sil)
    assert diff == {kind: (0.0, "") for kind in PIL_SIL_KINDS}, diff


def test_documented_command_ends_ok(commands: dict[str, tuple[subprocess.CompletedProcess, dict | None]]) -> None:
    """docs/pil.md: `tools/armctl hil --target cortex-m4 --duration 3`, through the CLI, in its short
    form (3 s take QEMU 190 s: `tools/armctl bench pil` runs that one, twice): the fixture's first
    M4 run."""
    r, run = commands["pil_a"]
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert run is not None and run["results"]["result"] == "ok" and run["target"]["name"] == "cortex-m4"


def test_the_recorded_figures_are_within_the_budget() -> None:
    """docs/pil.md's figures are rendered from docs/results/bench-pil.json (tools/armctl bench pil
    --record; test_docs.py holds the page to it): the record's numbers are within the issue's budget."""
    record = json.loads((REPO / "docs" / "results" / "bench-pil.json").read_text())
    assert record["step_bench"]["x86_64_builtin"] <= 2509 and record["step_bench"]["cortex_m4"] <= 2920
    assert record["pil"]["twice_bit_identical"]
    assert record["pil"]["sil_worst_relative_difference"] <= PIL_SIL_REL_TOL
    assert record["pil"]["sil_worst_peak_difference"] <= PIL_SIL_PEAK_TOL
    assert record["pil"]["sil_estimation_difference_over_w"] <= PIL_SIL_W_TOL


def test_bench_pil_runs_in_its_short_form() -> None:
    """`tools/armctl bench pil --quick`: the benchmark's runs, short, through the CLI (its documented
    figures are `bench pil --record`'s: test_docs.py holds the page to them)."""
    _need_target()
    r = subprocess.run([str(REPO / "tools" / "armctl"), "bench", "pil", "--quick"], cwd=REPO, capture_output=True,
                       text=True, timeout=1800)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert "the same results bit for bit" in r.stdout
