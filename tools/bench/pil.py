"""`armctl bench pil`: the figures of docs/pil.md. It runs the documented processor-in-the-loop
run (the Cortex-M4 image, pm, 3 s, over CiA 402) twice and the software-in-the-loop run of the same
method, and takes the step's instruction counts from `armctl bench step`'s results file
(runs/bench/step_instructions.json: run that first; `--quick`, which checks that the runs go,
takes the recorded ones without it). `--record` keeps them in
docs/results/bench-pil.json, which `armctl docs` renders into docs/pil.md (render)."""

from __future__ import annotations

import json
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

from gen.lib.paths import REPO

STEP_RESULTS = REPO / "runs" / "bench" / "step_instructions.json"
RECORDED_STEP = REPO / "docs" / "results" / "bench-step.json"  # `bench step --record`'s
TARGET, METHOD, DURATION_S = "cortex-m4", "pm", 3.0


class PilBenchError(RuntimeError):
    pass


QUICK_DURATION_S = 0.2  # --quick: the same runs, short: that the benchmark runs, not its figures


def _step_results(quick: bool) -> dict[str, Any]:
    """`armctl bench step`'s results (not --quick: the documented figures). --quick only checks
    that the runs go: without such a file here it takes the recorded step figures."""
    for source in (STEP_RESULTS, RECORDED_STEP) if quick else (STEP_RESULTS,):
        try:
            step = json.loads(source.read_text())
        except (OSError, ValueError):
            continue
        if "cortex_m" in step and (quick or not step.get("quick")):
            return step
    raise PilBenchError(f"{STEP_RESULTS}: missing, unreadable or a --quick run: run tools/armctl bench step "
                        "(without --quick) first")


def measure(duration_s: float = DURATION_S, quick: bool = False) -> dict[str, Any]:
    from tools.build.cortex_m import pil_sil_differences
    from tools.run.hil import HilOptions, run_hil

    step = _step_results(quick)
    plan = (("pil", {"target": TARGET}), ("pil_again", {"target": TARGET}), ("sil", {"bus": "sil"}))
    # --quick: the three side by side (lockstep results do not depend on the wall clock; each run
    # holds a run slot of its own); the figures' runs one after another, for the run's wall time
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(max_workers=len(plan) if quick else 1) as pool:
        futs = {name: pool.submit(run_hil, HilOptions(out=Path(tmp) / name, duration_s=duration_s, method=METHOD,
                                                      protocol="canopen", **opts)) for name, opts in plan}
        runs = {name: f.result() for name, f in futs.items()}
    for name, run in runs.items():
        if run["results"]["result"] != "ok":
            raise PilBenchError(f"{name} run: {run['results']['verdict_reasons']}")
    pil, again, sil = (runs[n]["results"] for n in ("pil", "pil_again", "sil"))
    diff = pil_sil_differences(pil, sil)
    t = runs["pil"]["target"]
    return {
        "step_bench": {"x86_64_builtin": step["methods"]["pm"]["float"],
                       "x86_64_loaded": step["design_read_at_run_time"]["methods"]["pm"]["float"],
                       "cortex_m4": step["cortex_m"]["cortex-m4"]["pm step (float)"],
                       "cortex_m7": step["cortex_m"]["cortex-m7"]["pm step (float)"]},
        "pil": {"target": TARGET, "method": METHOD, "duration_s": duration_s, "periods": pil["steps"],
                "step_instructions": t["step_instructions"], "stated_clock_hz": t["stated_clock_hz"],
                "stated_part": t["stated_part"], "share": t["step_share_of_period_at_stated_clock"],
                "stack_high_water_bytes": t["stack_high_water_bytes"],
                "wall_s": runs["pil"]["environment"]["wall_s"],
                "tracking_max_abs_deg": max(pil["tracking_max_abs_deg"]),
                "twice_bit_identical": {k: v for k, v in pil.items() if k != "problems"} ==
                                       {k: v for k, v in again.items() if k != "problems"},
                "sil_worst_relative_difference": diff["relative"][0], "sil_worst_in": diff["relative"][1],
                "sil_worst_peak_difference": diff["peak"][0], "sil_worst_peak_in": diff["peak"][1],
                "sil_estimation_difference_over_w": diff["estimation_over_w"][0]},
    }


def render(record: dict[str, Any]) -> str:
    s, p = record["step_bench"], record["pil"]
    si = p["step_instructions"]
    return "\n".join([
        "| the pm step (float), instructions | built-in design | design read at run time |",
        "| --- | --- | --- |",
        f"| x86-64 (`bench step`, callgrind) | {s['x86_64_builtin']:.0f} | {s['x86_64_loaded']:.0f} |",
        f"| Cortex-M4 (`bench step`, golden image, QEMU) | {s['cortex_m4']:.0f} | - |",
        f"| Cortex-M7 (`bench step`, golden image, QEMU) | {s['cortex_m7']:.0f} | - |",
        "",
        f"The documented run (`tools/armctl hil --target {p['target']} --duration {p['duration_s']:g}`, "
        f"{p['method']} over CiA 402, {p['periods']} periods): the control step took {si['min']} / "
        f"{si['median']:g} / {si['max']} instructions (min / median / max over every period), "
        f"{100 * p['share']['median']:.2f} % of the 1 ms period at {p['stated_clock_hz'] / 1e6:g} MHz "
        f"({100 * p['share']['max']:.2f} % at most; {p['stated_part']}, one instruction a cycle); stack "
        f"high-water mark {p['stack_high_water_bytes']} bytes; its largest tracking error "
        f"{p['tracking_max_abs_deg']:.4f} deg. Run twice: "
        f"{'the same results bit for bit' if p['twice_bit_identical'] else 'DIFFERENT results'}. Against "
        f"software in the loop: every result within {p['sil_worst_relative_difference']:.1e} of itself (the "
        f"worst: {p['sil_worst_in']}), every peak within {p['sil_worst_peak_difference']:.1e} (the worst: "
        f"{p['sil_worst_peak_in']}), the estimation error's RMS within "
        f"{p['sil_estimation_difference_over_w']:.1e} of w's RMS. It took {p['wall_s']:.0f} s of wall time on "
        f"the machine below.",
    ])


def bench_pil(quick: bool = False) -> dict[str, Any]:
    return {"quick": quick, **measure(QUICK_DURATION_S if quick else DURATION_S, quick)}
