"""`armctl bench study`: how many HIL runs a study gets through per minute at --jobs 1 and 2,
and how many simulated seconds per wall second that is (runs/bench/study.json).

The runs are a study's: pd and tde (gains, so no design is built inside the timing; both run the
whole trajectory), the realistic scenario (drives and bus timing emulated), distinct seeds, each
in its own run slot, through tools/runner.py exactly as `armctl study` runs them; the wall time
covers them all, start-up and analysis included.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Any

from tools.arm import DEFAULT_ARM
from tools.runner import run_all
from tools.study import DEFAULT_CONFIG, setup_for
from tools.study_config import load
from tools.tuning import trial_spec


def bench_study(out: Path, quick: bool = False) -> dict[str, Any]:
    cfg = load(DEFAULT_CONFIG)
    n_runs, duration = (4, 0.5) if quick else (12, 5.0)
    scenario = cfg.scenarios["realistic"]
    result: dict[str, Any] = {"what": (f"{n_runs} HIL runs of {duration:g} s (+ {cfg.hold_s:g} s hold), pd and tde "
                                       "alternating (wn 40 rad/s), scenario realistic, lockstep, through "
                                       "tools/runner.py"),
                              "quick": quick, "runs": n_runs, "trajectory_s": duration, "jobs": {}}
    with tempfile.TemporaryDirectory() as tmp:
        setup, _, _ = setup_for(cfg, DEFAULT_ARM, Path(tmp), 1, None)
        for jobs in (1, 2):
            specs = [trial_spec(setup, "pd" if i % 2 == 0 else "tde", scenario,
                                {"wn": 40.0} if i % 2 == 0 else {"wn": 40.0, "cutoff_hz": 50.0}, 100 + i,
                                Path(tmp) / f"j{jobs}" / str(i), duration, setup.trajectory_args, keep_log=False)
                     for i in range(n_runs)]
            run_all(specs[:1], jobs)  # the builds, outside the timing
            (Path(tmp) / f"j{jobs}" / "0").rename(Path(tmp) / f"j{jobs}" / "warm")
            t0 = time.monotonic()
            runs = run_all(specs, jobs)
            wall = time.monotonic() - t0
            bad = [r["results"].get("result") for r in runs
                   if r["results"].get("periods_running") != r["results"].get("trajectory_periods")]
            if bad:  # a run stopped early would make the throughput look better than it is
                raise RuntimeError(f"bench study: {len(bad)} run(s) did not run to the end: {bad}")
            simulated = n_runs * (duration + cfg.hold_s)
            result["jobs"][str(jobs)] = {"wall_s": wall, "runs_per_minute": 60.0 * n_runs / wall,
                                         "simulated_s_per_wall_s": simulated / wall}
    one, two = result["jobs"]["1"], result["jobs"]["2"]
    result["speedup_2_over_1"] = two["runs_per_minute"] / one["runs_per_minute"]
    from tools.bench import _write_json

    _write_json(out, result)
    return result


def table(r: dict[str, Any]) -> str:
    lines = [f"{r['what']}"]
    for jobs, x in r["jobs"].items():
        lines.append(f"--jobs {jobs}: {x['runs_per_minute']:.1f} runs/min, {x['simulated_s_per_wall_s']:.1f} simulated "
                     f"s per wall s ({x['wall_s']:.1f} s)")
    lines.append(f"--jobs 2 over --jobs 1: {r['speedup_2_over_1']:.2f}x")
    return "\n".join(lines)
