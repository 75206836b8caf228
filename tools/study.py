"""`armctl study`: every method on the same trajectory, uncertainty and seed, then the report.
`armctl tune`: the baselines' gains, by a grid search on the tuning seed and trajectory."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from tqdm import tqdm

from tools.build import build
from tools.hil import HilError, HilOptions, run_hil, write_json_atomic
from tools.paths import REPO
from tools.study_config import (TUNED, StudyConfig, StudyConfigError, gain_args, grid_points, load,
                                load_gains)

DEFAULT_CONFIG = REPO / "tools" / "studies" / "paper.toml"


def run_method(cfg: StudyConfig, method: str, out: Path, gains: dict[str, float], *, seed: int,
               duration_s: float, trajectory_args: list[str], preset: str) -> dict[str, Any]:
    args = [*gain_args(method, gains), *trajectory_args, "--ref-hold", f"{cfg.hold_s:g}"]
    return run_hil(HilOptions(out=out, duration_s=duration_s, method=method, preset=preset,
                              controller_args=tuple(args), uncertainty=cfg.uncertainty_for(seed),
                              labels={"seed": seed, "gains": gains}, bus_timing=cfg.bus_timing))


def run_study(cfg: StudyConfig, out: Path, duration_s: float | None = None, preset: str = "release",
              methods: list[str] | None = None) -> dict[str, Any]:
    gains = load_gains(cfg)
    duration = duration_s or cfg.duration_s
    runs: dict[str, Any] = {}
    bar = tqdm(methods or cfg.methods, desc="study", unit="method")
    for method in bar:
        bar.set_postfix_str(method)
        runs[method] = run_method(cfg, method, out / method, gains.get("methods", {}).get(method, {}),
                                  seed=cfg.seed, duration_s=duration, trajectory_args=cfg.trajectory.args(),
                                  preset=preset)
    study = {
        "config": str(cfg.path.relative_to(REPO) if cfg.path.is_relative_to(REPO) else cfg.path),
        "description": cfg.description,
        "seed": cfg.seed,
        "duration_s": duration,
        "hold_s": cfg.hold_s,
        "bus_timing": cfg.bus_timing,
        "uncertainty": cfg.uncertainty_for(cfg.seed),
        "trajectory": {"amp": cfg.trajectory.amp, "freq_hz": cfg.trajectory.freq_hz},
        "tuning": gains,
        "runs": {m: r["results"] for m, r in runs.items()},
        "transport": {m: r["transport"] for m, r in runs.items()},
    }
    write_json_atomic(out / "study.json", study)
    from tools.report import write_report  # matplotlib: only when there is a report to draw

    write_report(out, study)
    return study


def tune(cfg: StudyConfig, out: Path, preset: str = "release") -> dict[str, Any]:
    """Grid search per baseline on the tuning seed and trajectory (never the study's)."""
    if cfg.tuning_seed == cfg.seed:
        raise StudyConfigError("tuning.seed must differ from the study's seed")
    jobs = [(m, g) for m in TUNED for g in grid_points(cfg.grid.get(m, {}))]
    scores: dict[str, list[dict[str, Any]]] = {m: [] for m in TUNED}
    for i, (method, gains) in enumerate(tqdm(jobs, desc="tune", unit="run")):
        run = run_method(cfg, method, out / f"{method}-{i}", gains, seed=cfg.tuning_seed,
                         duration_s=cfg.tuning_duration_s, trajectory_args=cfg.tuning_trajectory.args(),
                         preset=preset)
        r = run["results"]
        ok = r["result"] == "ok" and r.get("periods_running", 0) > 0
        score = sum(r["tracking_max_abs_rad"]) if ok else float("inf")
        scores[method].append({"gains": gains, "objective": score, "result": r["result"]})
    best = {m: min(s, key=lambda x: x["objective"]) for m, s in scores.items() if s}
    result = {
        "procedure": (f"grid search per baseline on seed {cfg.tuning_seed} and the tuning trajectory "
                      f"({cfg.tuning_duration_s:g} s), objective: {cfg.tuning_objective}; "
                      "pm, pm-paper and gh2 are not tuned: their gains come from the LMI design"),
        "tuning_seed": cfg.tuning_seed,
        "tuning_trajectory": {"amp": cfg.tuning_trajectory.amp, "freq_hz": cfg.tuning_trajectory.freq_hz},
        "methods": {m: b["gains"] for m, b in best.items()},
        "objective": {m: b["objective"] for m, b in best.items()},
        "all_scores": scores,
    }
    write_json_atomic(cfg.gains_file, result)
    return result


def add_study_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, default=DEFAULT_CONFIG)
    p.add_argument("--out", type=Path, default=REPO / "runs" / "study")
    p.add_argument("--duration", type=float, default=None, help="override the config's trajectory length")
    p.add_argument("--methods", default=None, help="comma-separated subset of the config's methods")


def add_tune_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, default=DEFAULT_CONFIG)
    p.add_argument("--out", type=Path, default=REPO / "runs" / "tune")


def cmd_study(ns: argparse.Namespace) -> int:
    try:
        cfg = load(ns.config)
        methods = ns.methods.split(",") if ns.methods else None
        if methods and any(m not in cfg.methods for m in methods):
            raise StudyConfigError(f"--methods: {ns.methods!r} is not a subset of {cfg.methods}")
        if ns.duration is not None and not ns.duration > 0:
            raise StudyConfigError(f"--duration: must be > 0, got {ns.duration}")
        build("release")
        study = run_study(cfg, ns.out, ns.duration, methods=methods)
    except (StudyConfigError, HilError) as exc:
        print(f"armctl study: {exc}", file=sys.stderr)
        return 2 if isinstance(exc, StudyConfigError) else 1
    print((ns.out / "summary.txt").read_text())
    print(f"report: {ns.out / 'report.md'}")
    return 0 if all(r["result"] == "ok" for r in study["runs"].values()) else 1


def cmd_tune(ns: argparse.Namespace) -> int:
    try:
        cfg = load(ns.config)
        build("release")
        result = tune(cfg, ns.out)
    except (StudyConfigError, HilError) as exc:
        print(f"armctl tune: {exc}", file=sys.stderr)
        return 2 if isinstance(exc, StudyConfigError) else 1
    print(json.dumps({"methods": result["methods"], "objective": result["objective"]}, indent=2))
    print(f"gains: {cfg.gains_file}")
    return 0
