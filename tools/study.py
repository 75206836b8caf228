"""`armctl study`: every method on the same trajectory, uncertainty and seed, then the report.
`armctl tune`: the baselines' gains, by a grid search on the tuning seed and trajectory."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from tqdm import tqdm

from tools.arm import (DEFAULT_ARM, ArmChoiceError, ArmRef, add_arm_arguments, arm_build_dir, arm_from_args,
                       arm_info, build_arm, reference_for)
from tools.hil import HilError, HilOptions, run_hil, write_json_atomic
from tools.paths import REPO
from tools.study_config import (TUNED, StudyConfig, StudyConfigError, Trajectory, gain_args, grid_points,
                                load)

DEFAULT_CONFIG = REPO / "tools" / "studies" / "paper.toml"


def run_method(cfg: StudyConfig, method: str, out: Path, gains: dict[str, float], *, seed: int,
               duration_s: float, trajectory_args: list[str], preset: str, arm: ArmRef = DEFAULT_ARM) -> dict[str, Any]:
    args = [*gain_args(method, gains), *trajectory_args, "--ref-hold", f"{cfg.hold_s:g}"]
    return run_hil(HilOptions(out=out, duration_s=duration_s, method=method, preset=preset, arm=arm,
                              controller_args=tuple(args), uncertainty=cfg.uncertainty_for(seed),
                              labels={"seed": seed, "gains": gains}, bus_timing=cfg.bus_timing))


def trajectory_for(info: dict[str, Any], traj: Trajectory, what: str) -> tuple[list[str], dict[str, Any], list[str]]:
    """The config's trajectory on this arm: its amplitudes clipped to the joint ranges, or the arm's
    own default reference when the config's has another joint count. Controller arguments, the
    trajectory used, and what was changed."""
    notes: list[str] = []
    if len(traj.amp) != info["n_joints"]:
        amp, freq = None, None
        notes.append(f"{what}: the config's trajectory is for {len(traj.amp)} joints, this arm has "
                     f"{info['n_joints']}: the arm's default reference is used (arm.json)")
    else:
        amp, freq = traj.amp, traj.freq_hz
    try:
        amp_c, freq_c, clipped = reference_for(info, amp, freq)
    except ArmChoiceError as exc:
        raise StudyConfigError(f"{what}: {exc}") from exc
    notes += [f"{what}: {c}" for c in clipped]
    used = Trajectory(amp_c, freq_c)
    return used.args(), {"amp": amp_c, "freq_hz": freq_c}, notes


def gains_for(cfg: StudyConfig, arm: ArmRef, info: dict[str, Any], out: Path, preset: str) -> tuple[
        dict[str, Any], str]:
    """The baselines' gains tuned on this very arm: the config's gains file when it was tuned on
    it, else the arm's own gains file next to it, else a tuning run now (never another arm's)."""
    for path in (cfg.gains_file, gains_file_for(cfg, arm, preset)):
        if path.exists():
            g = json.loads(path.read_text())
            if g.get("arm", {}).get("model_hash") == info["model_hash"]:
                return g, f"tuned on this arm ({path})"
    why = (f"no baseline gains tuned on arm {info['name']} (model hash {info['model_hash']}) were found, and gains "
           f"tuned on another arm are not reused")
    print(f"armctl study: {why}: tuning them now (kept in {gains_file_for(cfg, arm, preset)} for the next study)",
          file=sys.stderr)
    tuned = tune(cfg, out / "tuning", preset, arm)
    return tuned, f"tuned in this study: {why}"


def gains_file_for(cfg: StudyConfig, arm: ArmRef, preset: str = "release") -> Path:
    """Where `armctl tune` keeps the gains: the config's gains file for the bundled arm, else
    the arm's build folder (next to everything else built for that arm, never in the sources)."""
    if arm.is_default:
        return cfg.gains_file
    return arm_build_dir(preset, arm) / "tuned_gains" / f"{cfg.path.stem}.{cfg.gains_file.name}"


def run_study(cfg: StudyConfig, out: Path, duration_s: float | None = None, preset: str = "release",
              methods: list[str] | None = None, arm: ArmRef = DEFAULT_ARM) -> dict[str, Any]:
    info = arm_info(arm_build_dir(preset, arm))
    gains, gains_source = gains_for(cfg, arm, info, out, preset)
    duration = duration_s or cfg.duration_s
    traj_args, traj_used, notes = trajectory_for(info, cfg.trajectory, "trajectory")
    for n in notes:
        print(f"armctl study: {n}", file=sys.stderr)
    runs: dict[str, Any] = {}
    bar = tqdm(methods or cfg.methods, desc="study", unit="method")
    for method in bar:
        bar.set_postfix_str(method)
        runs[method] = run_method(cfg, method, out / method, gains.get("methods", {}).get(method, {}),
                                  seed=cfg.seed, duration_s=duration, trajectory_args=traj_args, preset=preset,
                                  arm=arm)
    study = {
        "config": str(cfg.path.relative_to(REPO) if cfg.path.is_relative_to(REPO) else cfg.path),
        "description": cfg.description,
        "arm": {"name": info["name"], "model": info["model"], "arm_file": info["arm_file"],
                "n_joints": info["n_joints"], "joint_names": [j["name"] for j in info["joints"]],
                "model_hash": info["model_hash"], "is_default": arm.is_default, "buses": info["buses"]},
        "seed": cfg.seed,
        "duration_s": duration,
        "hold_s": cfg.hold_s,
        "bus_timing": cfg.bus_timing,
        "uncertainty": cfg.uncertainty_for(cfg.seed),
        "trajectory": traj_used,
        "notes": notes,
        "tuning": {**gains, "source": gains_source},
        "runs": {m: r["results"] for m, r in runs.items()},
        "transport": {m: r["transport"] for m, r in runs.items()},
    }
    write_json_atomic(out / "study.json", study)
    from tools.report import write_report  # matplotlib: only when there is a report to draw

    write_report(out, study)
    return study


def tune(cfg: StudyConfig, out: Path, preset: str = "release", arm: ArmRef = DEFAULT_ARM) -> dict[str, Any]:
    """Grid search per baseline on the tuning seed and trajectory (never the study's), on this arm;
    the gains go to the config's gains file for the config's own arm, else to the arm's file."""
    if cfg.tuning_seed == cfg.seed:
        raise StudyConfigError("tuning.seed must differ from the study's seed")
    info = arm_info(arm_build_dir(preset, arm))
    traj_args, traj_used, notes = trajectory_for(info, cfg.tuning_trajectory, "tuning trajectory")
    jobs = [(m, g) for m in TUNED for g in grid_points(cfg.grid.get(m, {}))]
    scores: dict[str, list[dict[str, Any]]] = {m: [] for m in TUNED}
    for i, (method, gains) in enumerate(tqdm(jobs, desc="tune", unit="run")):
        run = run_method(cfg, method, out / f"{method}-{i}", gains, seed=cfg.tuning_seed,
                         duration_s=cfg.tuning_duration_s, trajectory_args=traj_args, preset=preset, arm=arm)
        r = run["results"]
        ok = r["result"] == "ok" and r.get("periods_running", 0) > 0
        score = sum(r["tracking_max_abs_rad"]) if ok else float("inf")
        scores[method].append({"gains": gains, "objective": score, "result": r["result"]})
    best = {m: min(s, key=lambda x: x["objective"]) for m, s in scores.items() if s}
    result = {
        "procedure": (f"grid search per baseline on seed {cfg.tuning_seed} and the tuning trajectory "
                      f"({cfg.tuning_duration_s:g} s), objective: {cfg.tuning_objective}; "
                      "pm, pm-paper and gh2 are not tuned: their gains come from the LMI design"),
        "arm": {"name": info["name"], "model_hash": info["model_hash"], "model": info["model"]},
        "tuning_seed": cfg.tuning_seed,
        "tuning_trajectory": traj_used,
        "notes": notes,
        "methods": {m: b["gains"] for m, b in best.items()},
        "objective": {m: b["objective"] for m, b in best.items()},
        "all_scores": scores,
    }
    write_json_atomic(gains_file_for(cfg, arm, preset), result)
    return result


def add_study_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, default=DEFAULT_CONFIG)
    p.add_argument("--out", type=Path, default=REPO / "runs" / "study")
    p.add_argument("--duration", type=float, default=None, help="override the config's trajectory length")
    p.add_argument("--methods", default=None, help="comma-separated subset of the config's methods")
    add_arm_arguments(p)


def add_tune_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, default=DEFAULT_CONFIG)
    p.add_argument("--out", type=Path, default=REPO / "runs" / "tune")
    add_arm_arguments(p)


def cmd_study(ns: argparse.Namespace) -> int:
    try:
        cfg = load(ns.config)
        methods = ns.methods.split(",") if ns.methods else None
        if methods and any(m not in cfg.methods for m in methods):
            raise StudyConfigError(f"--methods: {ns.methods!r} is not a subset of {cfg.methods}")
        if ns.duration is not None and not (0.001 <= ns.duration <= 86400):
            raise StudyConfigError(f"--duration: must be in [0.001, 86400] s, got {ns.duration}")
        arm = arm_from_args(ns)
        build_arm("release", arm)
        study = run_study(cfg, ns.out, ns.duration, methods=methods, arm=arm)
    except (StudyConfigError, ArmChoiceError) as exc:
        print(f"armctl study: {exc}", file=sys.stderr)
        return 2
    except HilError as exc:
        print(f"armctl study: {exc}", file=sys.stderr)
        return 1
    print((ns.out / "summary.txt").read_text())
    print(f"report: {ns.out / 'report.md'}")
    return 0 if all(r["result"] == "ok" for r in study["runs"].values()) else 1


def cmd_tune(ns: argparse.Namespace) -> int:
    try:
        cfg = load(ns.config)
        arm = arm_from_args(ns)
        build_arm("release", arm)
        result = tune(cfg, ns.out, arm=arm)
    except (StudyConfigError, ArmChoiceError) as exc:
        print(f"armctl tune: {exc}", file=sys.stderr)
        return 2
    except HilError as exc:
        print(f"armctl tune: {exc}", file=sys.stderr)
        return 1
    print(json.dumps({"methods": result["methods"], "objective": result["objective"]}, indent=2))
    print(f"gains: {gains_file_for(cfg, arm)}")
    return 0
