"""Benchmarks that write results files (never timed tests).

`armctl bench step`: instructions per control step (callgrind, which counts instructions, not
seconds, so the figure repeats on a busy machine) for every method, float32 and fixed point,
next to the dense double-precision Eigen reference of the same step.
`armctl bench synth`: wall time of the synthesis (gen.synth.bench).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from tqdm import tqdm

from tools.build import build
from tools.paths import REPO, build_dir

METHODS = ("pd", "pm", "pm-paper", "gh2", "tde", "usde-smc")
STEPS = 2000
WARMUP = 1000  # the measured count is (N2 - N1) / (STEPS2 - STEPS1): start-up cost cancels


def _instructions(exe: Path, method: str, numeric: str, steps: int) -> int:
    fn = "bench_eigen_step*" if numeric == "eigen" else "bench_firmware_step"
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "callgrind.out"
        subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", f"--toggle-collect={fn}",
                        str(exe), method, numeric, str(steps)], check=True, capture_output=True)
        m = re.search(r"^summary:\s+(\d+)", out.read_text(), re.M)
        if m is None:
            raise RuntimeError(f"no callgrind summary for {method} {numeric}")
        return int(m.group(1))


def per_step(exe: Path, method: str, numeric: str, steps: int = STEPS) -> float:
    a = _instructions(exe, method, numeric, WARMUP)
    b = _instructions(exe, method, numeric, WARMUP + steps)
    return (b - a) / steps


def bench_step(out: Path, quick: bool = False) -> dict[str, Any]:
    """quick: pm only, 200 measured steps (a check that the benchmark runs, not a figure)."""
    build("release")
    exe = build_dir("release") / "tests" / "bench" / "bench_step"
    methods = ("pm",) if quick else METHODS
    steps = 200 if quick else STEPS
    jobs = [(m, n) for m in methods for n in ("float", "fixed") if n == "float" or m in ("pm", "pm-paper", "gh2")]
    jobs += [(m, "eigen") for m in methods if m in ("pd", "pm", "pm-paper", "gh2")]
    rows: dict[str, dict[str, float]] = {}
    for method, numeric in tqdm(jobs, desc="callgrind", unit="run"):
        rows.setdefault(method, {})[numeric] = per_step(exe, method, numeric, steps)
    for method, r in rows.items():
        if "eigen" in r:
            r["eigen_over_float"] = r["eigen"] / r["float"]
    result = {
        "what": "instructions per control step (callgrind Ir inside the step function), n = 6, release build",
        "compiler": subprocess.run(["cc", "--version"], capture_output=True, text=True).stdout.splitlines()[0],
        "steps_measured": steps,
        "quick": quick,
        "methods": rows,
    }
    tmp = out.with_name(f".{out.name}.tmp.{os.getpid()}")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp.write_text(json.dumps(result, indent=2) + "\n")
    tmp.replace(out)
    return result


def table(result: dict[str, Any]) -> str:
    lines = [f"{'method':<10}{'float':>10}{'fixed':>10}{'eigen ref':>12}{'ref/float':>11}"]
    for m, r in result["methods"].items():
        f = lambda k: f"{r[k]:>10.0f}" if k in r else f"{'-':>10}"  # noqa: E731
        ratio = f"{r['eigen_over_float']:>10.1f}x" if "eigen_over_float" in r else f"{'-':>11}"
        eigen = f"{r['eigen']:>12.0f}" if "eigen" in r else f"{'-':>12}"
        lines.append(f"{m:<10}{f('float')}{f('fixed')}{eigen}{ratio}")
    return "\n".join(lines)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("what", choices=("step", "synth"))
    p.add_argument("--out", type=Path, default=None, help="results file (JSON)")
    p.add_argument("--quick", action="store_true",
                   help="a short form that checks the benchmark runs (step: pm only; synth: one repeat, "
                        "no coupled solve, n = 1 comparison); its figures are not the documented ones")


def run(ns: argparse.Namespace) -> int:
    if ns.what == "step":
        out = ns.out or REPO / "runs" / "bench" / "step_instructions.json"
        result = bench_step(out, ns.quick)
        print(table(result))
        print(f"results: {out}")
        return 0
    out = ns.out or REPO / "runs" / "bench" / "synth.json"
    quick = ["--repeats", "1", "--skip-coupled", "--quick"] if ns.quick else []
    return subprocess.run([sys.executable, "-m", "gen.synth.bench", "--out", str(out), *quick],
                          cwd=REPO).returncode
