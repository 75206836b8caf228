"""`armctl bench study`: how many runs a study gets through per minute at --jobs 1 and 2, in
software in the loop and in lockstep HIL over UDP, and how many simulated seconds per wall second
that is (runs/bench/study.json).

The runs are a study's: pd and tde (gains, so no design is built inside the timing; both run the
whole trajectory), the realistic scenario (drives and bus timing emulated), distinct seeds, each
in its own run slot, through tools/run/runner.py exactly as `armctl study` runs them; the wall time
covers them all, start-up and analysis included.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Any

from gen.lib.atomic_output import write_json_atomic
from tools.build.arm import DEFAULT_ARM
from tools.run.runner import run_all
from tools.study import DEFAULT_CONFIG, setup_for
from tools.study.config import load
from tools.study.tuning import trial_spec


def _throughput(bus: str, jobs: int, n_runs: int, duration: float, tmp: Path) -> dict[str, float]:
    cfg = load(DEFAULT_CONFIG)
    scenario = cfg.scenarios["realistic"]
    setup, _, _ = setup_for(cfg, DEFAULT_ARM, tmp, 1, None, bus)
    where = tmp / f"{bus}-j{jobs}"
    specs = [trial_spec(setup, "pd" if i % 2 == 0 else "tde", scenario,
                        {"wn": 40.0} if i % 2 == 0 else {"wn": 40.0, "cutoff_hz": 50.0}, 100 + i,
                        where / str(i), duration, setup.trajectory_args, keep_log=False)
             for i in range(n_runs)]
    run_all(specs[:1], jobs)  # the builds, outside the timing
    (where / "0").rename(where / "warm")
    t0 = time.monotonic()
    runs = run_all(specs, jobs, forked=True)  # as run_study runs a study's runs
    wall = time.monotonic() - t0
    bad = [r["results"].get("result") for r in runs
           if r["results"].get("periods_running") != r["results"].get("trajectory_periods")]
    if bad:  # a run stopped early would make the throughput look better than it is
        raise RuntimeError(f"bench study: {len(bad)} run(s) did not run to the end: {bad}")
    simulated = n_runs * (duration + cfg.hold_s)
    return {"wall_s": wall, "runs_per_minute": 60.0 * n_runs / wall, "simulated_s_per_wall_s": simulated / wall}


def bench_study(out: Path, quick: bool = False) -> dict[str, Any]:
    duration = 0.5 if quick else 5.0
    counts = {"sil": 4 if quick else 48, "udp": 4 if quick else 12}  # SIL runs are ~10x shorter: more of them
    result: dict[str, Any] = {"what": (f"runs of {duration:g} s (+ 0.5 s hold), pd and tde alternating (wn 40 rad/s), "
                                       f"scenario realistic, through tools/run/runner.py as a study runs them: "
                                       f"{counts['sil']} in software in the loop, {counts['udp']} in lockstep HIL "
                                       "over UDP"),
                              "quick": quick, "trajectory_s": duration, "buses": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for bus, n in counts.items():
            jobs = {str(j): _throughput(bus, j, n, duration, Path(tmp)) for j in (1, 2)}
            result["buses"][bus] = {"runs": n, "jobs": jobs,
                                    "speedup_2_over_1": jobs["2"]["runs_per_minute"] / jobs["1"]["runs_per_minute"]}
    write_json_atomic(out, result)
    return result


def table(r: dict[str, Any]) -> str:
    lines = [f"{r['what']}"]
    for bus, b in r["buses"].items():
        for jobs, x in b["jobs"].items():
            lines.append(f"{bus} --jobs {jobs}: {x['runs_per_minute']:.1f} runs/min, {x['simulated_s_per_wall_s']:.1f} "
                         f"simulated s per wall s ({x['wall_s']:.1f} s)")
        lines.append(f"{bus}: --jobs 2 over --jobs 1: {b['speedup_2_over_1']:.2f}x")
    return "\n".join(lines)
