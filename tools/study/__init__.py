"""`armctl study`: every method, tuned alike, in every scenario, on the same trajectory and seeds;
statistics over the seeds, paired comparisons, the report.
`armctl tune`: the tuning alone (tools/study/tuning.py), kept for later studies."""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time
from datetime import datetime, timezone
from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path
from typing import Any

from tqdm import tqdm

from gen.lib import toml_input
from gen.arm import DEFAULT_DESIGN
from tools.build.arm import (DEFAULT_ARM, ArmChoiceError, ArmRef, add_arm_arguments, arm_build_dir, arm_from_args,
                       arm_info, build_arm, print_arm_warnings, reference_for)
from tools.run import procs
from tools.run.cluster import Cluster, add_cluster_arguments, cluster_from_args
from tools.build.code_identity import code_identity
from gen.lib.atomic_output import write_json_atomic
from tools.run.hil import SIL
from gen.lib.locks import LockHeld, flocked
from gen.lib.one_line import one_line
from gen.lib.outdir import OutDirError, check_out_dir
from gen.lib.paths import REPO
from tools.run.runner import METRICS, RunSpec, run_all
from tools.run.slots import default_jobs
from tools.study.stats import paired, summary
from tools.study.config import METHODS, PROTOCOLS, StudyConfig, StudyConfigError, Trajectory, for_arm, load
from tools.study.pairs import pair_workers, tune_pairs
from tools.study.tuning import (REFUSED_SCORE, TuneSetup, _read_tuning, batch_size, method_bandwidth, storage_url,
                                trial_spec)

DEFAULT_CONFIG = REPO / "tools" / "studies" / "paper.toml"
BASELINES = ("tde", "usde-smc", "pd", "pm-paper-weights", "pm-paper", "gh2")
BUSES = (SIL, "udp", "vcan", "auto")  # a study's runs: software in the loop, or lockstep HIL on a CAN bus
CONFIRM_BUS = "auto"  # a software-in-the-loop study's sample, repeated over vcan where this kernel has it, else UDP
DEFAULT_CONFIRM = 3
# Fields of a run's results that say where it was built, not what it measured: a tuned design is
# built in whichever run slot the run got (results.design names that slot's file); design_hash,
# which is compared, says the design's content was the same.
NOT_RESULTS = ("design",)


def confirmation_sample(where: list[tuple[str, str, int]], count: int) -> list[int]:
    """Which runs a software-in-the-loop study repeats over the CAN bus: spread over the scenarios
    and the methods (scenario i with method i + d, diagonal d = 0, 1, ...: every pair once), each
    on its first seed."""
    scenarios = list(dict.fromkeys(s for s, _, _ in where))
    methods = list(dict.fromkeys(m for _, m, _ in where))
    first = {}
    for i, (s, m, _) in enumerate(where):
        first.setdefault((s, m), i)
    order = [(scenarios[i], methods[(i + d) % len(methods)]) for d in range(len(methods)) for i in range(len(scenarios))]
    return [first[pair] for pair in order if pair in first][:count]


def confirm_over_bus(specs: list[RunSpec], runs: list[dict[str, Any]], where: list[tuple[str, str, int]],
                     picks: list[int], out: Path) -> dict[str, Any]:
    """The picked runs again in lockstep HIL over a CAN bus, a design of their own loaded from the
    file their software-in-the-loop run loaded; their results must equal those runs' exactly."""
    again = [replace(specs[i], out=str(out / "confirm" / where[i][0] / where[i][1] / f"seed-{where[i][2]}"),
                     bus=CONFIRM_BUS, keep_log=False, design_loaded=True) for i in picks]
    bar = tqdm(total=len(again), desc="confirm over the bus", unit="run")
    hil = run_all(again, default_jobs("udp"), None, progress=lambda spec, run: bar.update(1))
    bar.close()
    rows = []
    for i, run in zip(picks, hil):
        a, b = runs[i]["results"], run["results"]
        differ = sorted(k for k in set(a) | set(b) if k not in NOT_RESULTS and a.get(k) != b.get(k))
        rows.append({"scenario": where[i][0], "method": where[i][1], "seed": where[i][2],
                     "bus": run.get("environment", {}).get("bus_choice", "?"), "match": not differ,
                     "differences": differ})
    return {"runs": rows, "all_match": all(r["match"] for r in rows)}


TUNING_SPEEDUP = 1.25  # another arm's tuning trajectory: its own reference this much faster (never the study's)


def scenario_friction(cfg: StudyConfig) -> dict[str, list[float]] | None:
    """The most friction any of the config's scenarios adds, joint by joint (their per-joint values
    on this arm: study_config.for_arm first): what a trajectory shared by the scenarios must fit."""
    out: dict[str, list[float]] = {}
    for sc in cfg.scenarios.values():
        for k in ("viscous", "coulomb"):
            v = sc.uncertainty.get(k)
            if isinstance(v, list):
                out[k] = [max(a, float(b)) for a, b in zip(out.get(k, [0.0] * len(v)), v)]
    return out or None


def trajectory_for(info: dict[str, Any], traj: Trajectory, what: str, bdir: Path | None = None,
                   friction: dict[str, list[float]] | None = None, speedup: float = 1.0) -> tuple[
        list[str], dict[str, Any], list[str]]:
    """The config's trajectory on this arm when the config gives one for it (by name, or for any
    arm), else the arm's own reference (arm.json; `speedup` times its frequencies). Either way
    clipped to the joint ranges and, given the build folder, fitted to the arm's torque limits with
    the scenarios' friction (tools/build/arm.py reference_for). Controller arguments, the trajectory used
    (amplitudes, frequencies, where from), and what was changed."""
    notes: list[str] = []
    if traj.arm is not None and traj.arm != info["name"]:
        amp, freq, source = None, None, f"the arm's own reference (the config's is for arm '{traj.arm}')"
    elif len(traj.amp) != info["n_joints"]:
        amp, freq, source = None, None, "the arm's own reference"
        notes.append(f"{what}: the config's trajectory is for {len(traj.amp)} joints, this arm has "
                     f"{info['n_joints']}: the arm's default reference is used (arm.json)")
    else:
        amp, freq, source = traj.amp, traj.freq_hz, f"the config's (for arm '{traj.arm}')" if traj.arm else "the config's"
    if amp is None and speedup != 1.0:
        amp = list(info["reference"]["amp"])
        freq = [round(f * speedup, 6) for f in info["reference"]["freq_hz"]]
        source += f", {speedup:g}x its frequencies"
    try:
        amp_c, freq_c, clipped = reference_for(info, amp, freq, bdir, friction)
    except ArmChoiceError as exc:
        raise StudyConfigError(f"{what}: {exc}") from exc
    notes += [f"{what}: {c}" for c in clipped]
    used = Trajectory(amp_c, freq_c)
    return used.args(), {"amp": amp_c, "freq_hz": freq_c, "from": source}, notes


def _arm_args(arm: ArmRef) -> dict[str, str | None]:
    return {"model": str(arm.model) if arm.model else None, "arm_file": str(arm.arm_file) if arm.arm_file else None,
            "design": str(arm.design) if arm.design else None}


def setup_for(cfg: StudyConfig, arm: ArmRef, out: Path, jobs: int, cluster: Cluster | None, bus: str = SIL,
              preset: str = "release") -> tuple[TuneSetup, dict[str, Any], list[str]]:
    """What tuning and the study's runs share on this arm. Its config (setup.cfg) is the one given
    with every scenario's per-joint values made for the arm, so a value list of the wrong length
    stops here, before anything runs."""
    bdir = arm_build_dir(preset, arm)
    info = arm_info(bdir)
    cfg = for_arm(cfg, info)
    traj_args, _, notes = trajectory_for(info, cfg.tuning_trajectory, "tuning trajectory", bdir,
                                         scenario_friction(cfg), TUNING_SPEEDUP)
    base = (bdir / "generated" / "arm" / "design.toml").read_text()
    return TuneSetup(cfg, _arm_args(arm), base, traj_args, out, jobs, cluster, bus,
                     resonance_hz=float(info["first_resonance_hz"]), period_s=1.0 / float(info["loop_rate_hz"])), info, notes


def tuning_file(cfg: StudyConfig, arm: ArmRef, preset: str = "release") -> Path:
    """The tuning record: next to the config for the bundled arm, else in the arm's build folder
    (next to everything else built for that arm, never in the sources)."""
    if arm.is_default:
        return cfg.tuning_file
    return arm_build_dir(preset, arm) / "tuning" / f"{cfg.path.stem}.{cfg.tuning_file.name}"


def tuning_key(cfg: StudyConfig, info: dict[str, Any], setup: TuneSetup, scenario: str, method: str) -> str:
    """What a tuning result depends on: the arm, its design, the scenario, the method's space,
    the tuning seeds, trajectory, length and budget, the hold."""
    # (`arm` names whom the tuning trajectory is for: the trajectory itself is in the key)
    t = {k: v for k, v in cfg.raw["tuning"].items() if k not in ("space", "file", "arm")}
    # the design's values, not its text (its header comment names the checkout's path); the
    # scenario with its per-joint values on this arm (setup_for)
    doc = {"arm": info["model_hash"], "design": toml_input.loads(setup.base_design),
           "scenario": setup.cfg.scenarios[scenario].as_dict(), "space": setup.cfg.spaces[method].as_dict(), "tuning": t,
           "trajectory": setup.trajectory_args, "hold_s": cfg.hold_s}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:16]


def keep_tuning(path: Path, scenario: str, method: str, rec: dict[str, Any], common: dict[str, Any]) -> None:
    """One method's tuning in one scenario into the kept tuning file, merged under a lock with what
    other commands kept meanwhile: two `armctl tune` of different methods at once keep both."""
    with flocked(path.with_name(f".{path.name}.lock")):
        doc = _read_tuning(path)  # read again under the lock: another tune may have written since
        scen = doc["scenarios"].get(scenario)
        doc["scenarios"][scenario] = {**(scen if isinstance(scen, dict) else {}), method: rec}
        doc.update(common)
        write_json_atomic(path, doc)


def keep_tuning_time(path: Path, record: dict[str, Any]) -> None:
    """The last tuning's time into the kept tuning file (under its lock, as keep_tuning)."""
    with flocked(path.with_name(f".{path.name}.lock")):
        doc = _read_tuning(path)
        doc["last_tuning"] = record
        write_json_atomic(path, doc)


def tuned(cfg: StudyConfig, arm: ArmRef, setup: TuneSetup, info: dict[str, Any], scenarios: list[str],
          methods: list[str], *, retune: bool = False, trials: int | None = None,
          in_study: bool = False, only: set[tuple[str, str]] | None = None) -> dict[str, dict[str, Any]]:
    """The tuning of every tuned method in every scenario: the kept one when it was made for the
    same arm, scenario and tuning settings, else tuned now (and kept, method by method, so an
    interrupted tuning resumes). `armctl tune` wants the config's cap (or --trials) exactly; a
    study takes any kept tuning of at least its cap, and tunes what is missing with
    `study_tuning_cap` trials (or --trials), so that a study on a new arm finishes in minutes."""
    path = tuning_file(cfg, arm)
    doc = _read_tuning(path)
    out: dict[str, dict[str, Any]] = {s: {} for s in scenarios}
    todo = []
    for s in scenarios:
        for m in methods:
            if METHODS[m][1] is None or (only is not None and (s, m) not in only):
                continue
            key = tuning_key(cfg, info, setup, s, m)
            scen = doc["scenarios"].get(s)
            rec = scen.get(m) if isinstance(scen, dict) else None
            rec = rec if isinstance(rec, dict) else None
            cap = trials or (cfg.study_cap if in_study else cfg.cap)
            long_enough = isinstance(rec.get("cap"), int) and rec["cap"] >= cap if in_study and rec else False
            if rec and rec.get("key") == key and (rec.get("cap") == cap or long_enough) and not retune:
                out[s][m] = {**rec, "source": f"tuned earlier, kept in {path}"}
            else:
                todo.append((s, m, key, "retune asked for" if retune and rec else
                             "no tuning kept for this arm, scenario and settings" if not rec or rec.get("key") != key
                             else f"the kept tuning had a cap of {rec.get('cap')} trials"))
    if todo:
        cap = trials or (cfg.study_cap if in_study else cfg.cap)
        print(f"armctl: tuning {len(todo)} method/scenario pairs ({', '.join(f'{m} in {s}' for s, m, _, _ in todo)}): "
              f"{todo[0][3]}; each to convergence (1 % over {cfg.plateau} trials) or at most {cap} trials; Optuna "
              f"storage {storage_url(setup.out)}", file=sys.stderr)
        bar = tqdm(total=cap * len(todo), desc="tune", unit="trial")
        started = time.monotonic()
        workers = pair_workers(setup, len(todo))
        if workers > 1:
            bar.set_postfix_str(f"{workers} pairs at a time")
        for s, m, key, rec in tune_pairs(setup, [(s, m, key) for s, m, key, _ in todo], cap,
                                         progress=lambda: bar.update(1)):
            bar.set_postfix_str(f"{m} / {s} done")
            bar.update(cap - rec["trials_run"])  # a converged tuning ends before its cap
            rec["key"] = key
            rec["code"] = rec["tuned_code"] = code_identity()  # tuned on it (verify.py restamps "code")
            keep_tuning(path, s, m, rec, {"arm": {"name": info["name"], "model_hash": info["model_hash"]},
                                          "procedure": procedure(cfg, cap, setup.jobs)})
            out[s][m] = {**rec, "source": f"tuned now, kept in {path}"}
        bar.close()
        # the tuning's own record of how long it took, and where: what the docs quote
        keep_tuning_time(path, {"wall_s": round(time.monotonic() - started, 1), "pairs": len(todo),
                                "trials": sum(out[s][m]["trials_run"] for s, m, _, _ in todo),
                                "jobs": setup.jobs, "cpus": os.cpu_count(),
                                "when": datetime.now(timezone.utc).isoformat(timespec="seconds")})
    # in the config's order, however the pairs finished
    return {s: {m: out[s][m] for m in methods if m in out[s]} for s in scenarios}


def verified_notes(setup: TuneSetup, path: Path, tuning: dict[str, dict[str, Any]],
                   prefix: str = "armctl study") -> list[str]:
    """The kept pairs stamped with other code, verified on this one (tools/study/verify.py: once per
    code, kept in the build folder); a note naming the pairs whose picks moved, none when none did."""
    from tools.study import verify

    stale = verify.stale_pairs(tuning, code_identity())
    if not stale:
        return []
    note = verify.moved_note(verify.verify_for_study(setup, path, stale, prefix), path)
    return [note] if note else []


def procedure(cfg: StudyConfig, trials: int | None = None, jobs: int | None = None) -> str:
    batch = cfg.batch if jobs is None else batch_size(cfg, jobs)
    tol = f"{100 * cfg.tolerance:g} %"
    return (f"Optuna TPE under one rule for every method and scenario: run until the best has improved by no more "
            f"than {tol} over the last {cfg.plateau} trials (converged), or {trials or cfg.cap} trials (capped; "
            f"the same cap for every method, widening rounds included), in batches of {batch} (at most --jobs); "
            f"tuning seeds {cfg.tuning_seeds} and the tuning trajectory ({cfg.tuning_duration_s:g} s), never the "
            f"study's; objective: {cfg.tuning_objective}; a candidate whose closed-loop bandwidth is not below the "
            f"arm's first joint resonance is refused like a design the synthesis refuses (scoring "
            f"{REFUSED_SCORE:g} plus its bandwidth over the resonance); a trial with a run that failed, diverged or was "
            f"torque-limited scores 1000 x (1 + the share of the trajectory not covered) plus the tracking error it "
            f"achieved, its share of time at the torque limit and its share of failed seeds (so failed trials rank, "
            f"always behind any that ended well; {REFUSED_SCORE:g} when the synthesis refused the weights); a best "
            f"value at the edge of its range widens that range tenfold in a new round (at most {cfg.widen}; never past "
            f"the arm's first resonance). The pick must have run ok on every tuning seed and must also run ok on the "
            f"held-out validation seed(s) {cfg.validation_seeds}, there also with the gears {cfg.robust_stiffness} "
            f"times as stiff (flexible scenarios) and the payload at both ends of its range (scenarios with one), "
            f"else the next best (of the best {cfg.validation_tries}) is taken. pm, pm-paper and gh2 are tuned through their synthesis "
            f"weights (each candidate synthesised: loaded at run time in SIL, built into the firmware over a CAN bus); pm-paper-weights is the paper's own weights, not tuned.")


def _study_specs(cfg: StudyConfig, setup: Any, info: dict[str, Any], out: Path, scen_names: list[str],
                 methods: list[str], seed_list: list[int], tuning: dict[str, Any], duration: float,
                 traj_args: Any, protocol: str | None) -> tuple[list[RunSpec], list[tuple[str, str, int]]]:
    """Every run of the study (scenario x method x seed) with its tuned knobs, and which it is."""
    paper_text = None if Path(info["design_config"]).resolve() == DEFAULT_DESIGN.resolve() else DEFAULT_DESIGN.read_text()
    specs: list[RunSpec] = []
    where: list[tuple[str, str, int]] = []
    for s in scen_names:
        scen = cfg.scenarios[s] if protocol is None else replace(cfg.scenarios[s], protocol=protocol)
        for m in methods:
            knobs = tuning[s][m]["knobs"] if m in tuning[s] else {}
            for i, seed in enumerate(seed_list):
                spec = trial_spec(setup, m, scen, knobs, seed, out / s / m / f"seed-{seed}", duration, traj_args,
                                  keep_log=i == 0)
                if m == "pm-paper-weights" and paper_text is not None:
                    spec = replace(spec, design_text=paper_text)
                specs.append(spec)
                where.append((s, m, seed))
    return specs, where


def _arm_record(info: dict[str, Any], arm: ArmRef) -> dict[str, Any]:
    return {"name": info["name"], "model": info["model"], "arm_file": info["arm_file"],
            "n_joints": info["n_joints"], "joint_names": [j["name"] for j in info["joints"]],
            "model_hash": info["model_hash"], "is_default": arm.is_default, "buses": info["buses"],
            "drivetrain": info["drivetrain"], "first_resonance_hz": info["first_resonance_hz"],
            "payload": info["payload"]}


def _per_scenario(cfg: StudyConfig, setup: Any, info: dict[str, Any], scen_names: list[str], methods: list[str],
                  tuning: dict[str, Any], where: list[tuple[str, str, int]],
                  runs: list[dict[str, Any]]) -> dict[str, Any]:
    """study.json's `scenarios`: each one's results per method, with each pick's closed-loop bandwidth."""
    per: dict[str, dict[str, list[dict[str, Any]]]] = {s: {m: [] for m in methods} for s in scen_names}
    for (s, m, _), run in zip(where, runs):
        per[s][m].append({**run["results"], "transport_telemetry_lost": run.get("transport", {}).get("telemetry_lost_total")})
    scenarios = {s: scenario_result({**cfg.scenarios[s].as_dict(), "per_joint_from": cfg.scenarios[s].per_joint},
                                    tuning[s], per[s], methods, info["n_joints"])
                 for s in scen_names}
    for s in scen_names:  # each pick's closed-loop bandwidth, beside the arm's first resonance
        scenarios[s]["bandwidth_hz"] = {
            m: method_bandwidth(setup, m, tuning[s][m]["knobs"] if m in tuning[s] else {}) for m in methods}
    return scenarios


def run_study(cfg: StudyConfig, out: Path, *, seeds: int | None = None, duration_s: float | None = None,
              methods: list[str] | None = None, scenarios: list[str] | None = None, arm: ArmRef = DEFAULT_ARM,
              jobs: int = 1, cluster: Cluster | None = None, retune: bool = False,
              trials: int | None = None, bus: str = SIL, confirm: int = DEFAULT_CONFIRM,
              figures: bool = True, protocol: str | None = None, prefix: str = "armctl study") -> dict[str, Any]:
    """protocol: every scenario's runs over this drive protocol instead of its own, with the picks
    tuned on its own (what the protocol alone changes); prefix: how its notes begin."""
    methods = methods or cfg.methods
    scen_names = scenarios or list(cfg.scenarios)
    seed_list = cfg.seed_list(seeds)
    setup, info, notes = setup_for(cfg, arm, out / "tuning", jobs, cluster, bus)
    cfg = setup.cfg  # the scenarios' per-joint values on this arm
    tuning = tuned(cfg, arm, setup, info, scen_names, methods, retune=retune, trials=trials, in_study=True)
    duration = duration_s or cfg.duration_s
    traj_args, traj_used, traj_notes = trajectory_for(info, cfg.trajectory, "trajectory", arm_build_dir("release", arm),
                                                      scenario_friction(cfg))
    notes += traj_notes
    notes += verified_notes(setup, tuning_file(cfg, arm), tuning, prefix)
    for n in notes:
        print(f"{prefix}: {one_line(n)}", file=sys.stderr)  # a file's names, to a terminal
    specs, where = _study_specs(cfg, setup, info, out, scen_names, methods, seed_list, tuning, duration, traj_args,
                                protocol)
    bar = tqdm(total=len(specs), desc="study", unit="run")
    runs = run_all(specs, jobs, cluster, progress=lambda spec, run: bar.update(1), forked=True)
    bar.close()
    if procs.interrupted is not None:  # the finished runs are kept: the same command resumes
        raise procs.Interrupted(procs.interrupted)
    confirmation = (confirm_over_bus(specs, runs, where, confirmation_sample(where, confirm), out)
                    if bus == SIL and confirm > 0 else None)
    if procs.interrupted is not None:
        raise procs.Interrupted(procs.interrupted)
    commands = {s: {m: run_command(cfg, arm, s, m, "SEED", duration, tuning[s][m]["knobs"] if m in tuning[s] else None,
                                   bus, f"runs/hil/{s}-{m}-seed-SEED".replace("+", "-"))
                    for m in methods} for s in scen_names}
    study = {
        "config": str(cfg.path.relative_to(REPO) if cfg.path.is_relative_to(REPO) else cfg.path),
        "description": cfg.description,
        "arm": _arm_record(info, arm),
        "seeds": seed_list,
        "rate_hz": info["loop_rate_hz"],
        "duration_s": duration,
        "hold_s": cfg.hold_s,
        "trajectory": traj_used,
        "methods": methods,
        "notes": notes,
        "tuning_procedure": procedure(cfg, trials, jobs),
        "bus": bus,
        "protocol": protocol,  # None: each scenario's own (its definition says which)
        "confirmation": confirmation,
        "commands": commands,
        "scenarios": _per_scenario(cfg, setup, info, scen_names, methods, tuning, where, runs),
    }
    write_json_atomic(out / "study.json", study)
    from tools.study.report import write_report

    write_report(out, study, figures=figures)
    return study


def run_command(cfg: StudyConfig, arm: ArmRef, scenario: str, method: str, seed: int | str, duration: float,
                knobs: dict[str, Any] | None, bus: str, out: str) -> str:
    """The `armctl hil` command that runs one run of a study again on its own (the same run.json
    results: tests/python/test_study_rerun.py)."""
    from gen.lib.escape import shell_command

    parts = ["tools/armctl", "hil", "--bus", bus, "--config", _rel(cfg.path), "--scenario", scenario,
             "--method", method, "--seed", str(seed), "--duration", f"{duration:g}"]
    if knobs:
        parts += ["--knobs", json.dumps(knobs, sort_keys=True)]
    for opt, p in (("--model", arm.model if not arm.arm_file else None), ("--arm", arm.arm_file),
                   ("--design", arm.design)):
        if p is not None:
            parts += [opt, _rel(p)]
    return shell_command([*parts, "--out", out])


def _rel(p: Path) -> str:
    p = Path(p)
    return str(p.relative_to(REPO)) if p.is_absolute() and p.is_relative_to(REPO) else str(p)


def kept_knobs(cfg: StudyConfig, arm: ArmRef, setup: TuneSetup, info: dict[str, Any], scenario: str,
               method: str) -> dict[str, Any]:
    """The kept tuning's knobs of a method in a scenario (hil --tuned), only when it was made for this
    arm, design, scenario and settings; never tunes."""
    path = tuning_file(cfg, arm)
    rec = (_read_tuning(path)["scenarios"].get(scenario) or {}).get(method)
    key = tuning_key(cfg, info, setup, scenario, method)
    if not isinstance(rec, dict) or rec.get("key") != key:
        raise StudyConfigError(f"--tuned {method}: no tuning of {method} in {scenario} kept in {path} for this arm and "
                               f"these settings{' (it was made for others)' if isinstance(rec, dict) else ''}: "
                               f"tools/armctl tune --scenarios {scenario} --methods {method} (with the same arm "
                               "options) keeps one")
    return dict(rec["knobs"])


def study_run_spec(cfg: StudyConfig, arm: ArmRef, scenario: str, method: str, seed: int, duration_s: float | None,
                   knobs: dict[str, Any] | None, tuned_knobs: bool, out: Path, bus: str) -> tuple[
        RunSpec, dict[str, Any], list[str]]:
    """One run of a study, exactly as run_study makes it (the same RunSpec: the same results), for
    `armctl hil --scenario`. The knobs: given, or the kept tuning's (tuned_knobs); none only for a
    method that is not tuned (its weights are fixed)."""
    if scenario not in cfg.scenarios:
        raise StudyConfigError(f"--scenario {scenario}: not in {cfg.path} (scenarios: {', '.join(cfg.scenarios)})")
    if method not in METHODS:
        raise StudyConfigError(f"--method {method}: not a study method ({', '.join(METHODS)})")
    if METHODS[method][1] is not None and knobs is None and not tuned_knobs:
        raise StudyConfigError(f"--scenario {scenario} --method {method}: {method} is tuned; give --tuned {method} "
                               "(the kept tuning's knobs, as the study runs it) or --knobs JSON")
    setup, info, notes = setup_for(cfg, arm, out.parent / f".{out.name}-tuning", 1, None, bus)
    rcfg = setup.cfg
    if tuned_knobs:
        if METHODS[method][1] is None:
            raise StudyConfigError(f"--tuned {method}: {method} is not tuned (its weights are fixed)")
        knobs = kept_knobs(cfg, arm, setup, info, scenario, method)
    traj_args, traj_used, traj_notes = trajectory_for(info, rcfg.trajectory, "trajectory", arm_build_dir("release", arm),
                                                      scenario_friction(rcfg))
    spec = trial_spec(setup, method, rcfg.scenarios[scenario], knobs or {}, seed, out, duration_s or cfg.duration_s,
                      traj_args, keep_log=True)
    if method == "pm-paper-weights" and Path(info["design_config"]).resolve() != DEFAULT_DESIGN.resolve():
        spec = replace(spec, design_text=DEFAULT_DESIGN.read_text())
    return spec, traj_used, notes + traj_notes


def _values(runs: list[dict[str, Any]], key: str, j: int | None) -> list[float]:
    out = []
    for r in runs:
        v = r.get(key)
        if v is None:
            out.append(float("nan"))
        elif j is None:
            out.append(float(v) if not isinstance(v, list) else float(sum(v)))
        else:
            out.append(float(v[j]) if j < len(v) else float("nan"))
    return out


def scenario_result(definition: dict[str, Any], tuning: dict[str, Any], per: dict[str, list[dict[str, Any]]],
                    methods: list[str], n: int) -> dict[str, Any]:
    """Per method: every run, the statistics of each metric per joint (the arm's n joints, also
    when no run measured any) and in total; PM against every other method on the same seeds."""
    stats: dict[str, Any] = {}
    for m, runs in per.items():
        stats[m] = {"results": [r.get("result") for r in runs]}
        for name, key in METRICS.items():
            if name == "power":
                stats[m][name] = {"total": summary(_values(runs, key, None))}
            else:
                stats[m][name] = {"per_joint": [summary(_values(runs, key, j)) for j in range(n)],
                                  "total": summary(_values(runs, key, None))}
    comparisons: dict[str, Any] = {}
    if "pm" in per:
        for b in [x for x in methods if x != "pm"]:
            comparisons[b] = {}
            for name, key in METRICS.items():
                joints = [] if name == "power" else [paired(_values(per["pm"], key, j), _values(per[b], key, j))
                                                     for j in range(n)]
                comparisons[b][name] = {"per_joint": joints,
                                        "total": paired(_values(per["pm"], key, None), _values(per[b], key, None))}
    return {"definition": definition, "tuning": tuning, "runs": per, "stats": stats, "pm_versus": comparisons}


def add_common_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, default=DEFAULT_CONFIG)
    p.add_argument("--scenarios", default=None, help="comma-separated subset of the config's scenarios")
    p.add_argument("--methods", default=None, help="comma-separated subset of the config's methods")
    p.add_argument("--bus", choices=BUSES, default=SIL,
                   help="sil: every run in software in the loop (one process, the same code, the same results); "
                        "udp, vcan, auto: lockstep HIL over that CAN bus [sil]")
    p.add_argument("--jobs", type=int, default=None,
                   help="runs at once on this machine [sil: every core; a CAN bus: half the cores, since a lockstep "
                        "run keeps two busy]")
    p.add_argument("--trials", type=int, default=None,
                   help="tuning cap per method and scenario: at most this many trials [the config's [tuning] cap]")
    add_cluster_arguments(p)
    add_arm_arguments(p)


def add_study_arguments(p: argparse.ArgumentParser) -> None:
    add_common_arguments(p)
    p.add_argument("--out", type=Path, default=REPO / "runs" / "study")
    p.add_argument("--seeds", type=int, default=None, help="seeds per method and scenario [the config's]")
    p.add_argument("--duration", type=float, default=None, help="override the config's trajectory length")
    p.add_argument("--retune", action="store_true", help="tune again even when a tuning is kept")
    p.add_argument("--record", action="store_true",
                   help="the default study only: keep its results as the headline (tools/studies/paper.headline.json) "
                        "and write the README's result tables from them; with --protocol arm, its record beside it "
                        "(the docs compare the two)")
    p.add_argument("--protocol", choices=PROTOCOLS, default=None,
                   help="run every scenario over this drive protocol, with the picks tuned on the scenario's own: "
                        "what the protocol alone changes [each scenario's: CiA 402]")
    p.add_argument("--confirm", type=int, default=DEFAULT_CONFIRM,
                   help=f"with --bus sil: repeat this many runs in lockstep HIL over the CAN bus and check that "
                        f"their results match bit for bit [{DEFAULT_CONFIRM}]")
    add_figures_argument(p)


def add_figures_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("--figures", action=argparse.BooleanOptionalAction, default=True,
                   help="draw the report's figures, up to five a scenario at about a second of CPU each "
                        "[yes]; --no-figures: the report's tables alone, for a sweep or a headless check")


def add_tune_arguments(p: argparse.ArgumentParser) -> None:
    add_common_arguments(p)
    p.add_argument("--out", type=Path, default=REPO / "runs" / "tune")
    what = p.add_mutually_exclusive_group()
    what.add_argument("--verify", action="store_true",
                      help="tune nothing: run each kept pick's recorded validation runs again on this code and "
                           "compare them number for number; equal: stamp the pair with this code's identity; "
                           "moved: say by how much and whether the pick still ranks ahead of its runner-up "
                           "(exit 1; the pairs to tune again are named)")
    what.add_argument("--retune", nargs="+", metavar="SCENARIO/METHOD", default=None,
                      help="tune these pairs alone (e.g. realistic/pm ideal/gh2), keeping every other pair's record")
    p.add_argument("--accept-moved", action="store_true",
                   help="with --verify: a pair that moved but whose pick still ranks ahead of its runner-up and "
                        "runs as recorded keeps its pick: its recorded runs become this code's, and it is "
                        "stamped with this code, the record saying by how much it moved")


def subset(text: str | None, allowed: list[str], what: str) -> list[str] | None:
    if text is None:
        return None
    items = [x for x in text.split(",") if x]
    bad = [x for x in items if x not in allowed]
    if bad or not items:
        raise StudyConfigError(f"--{what}: {bad or text!r} not in the config's {what} ({', '.join(allowed)})")
    return items


def _common(ns: argparse.Namespace) -> tuple[StudyConfig, ArmRef, list[str] | None, list[str] | None,
                                          Cluster | None]:
    cfg = load(ns.config)
    methods = subset(ns.methods, cfg.methods, "methods")
    scenarios = subset(ns.scenarios, list(cfg.scenarios), "scenarios")
    if ns.jobs is None:
        ns.jobs = default_jobs(ns.bus)
    cluster = cluster_from_args(ns)
    arm = arm_from_args(ns)
    prepare(arm, ns.out, ns.jobs, ns.trials, f"armctl {getattr(ns, 'command', 'study')}")
    return cfg, arm, methods, scenarios, cluster


def prepare(arm: ArmRef, out: Path, jobs: int, trials: int | None, prefix: str,
            targets: list[str] | None = None) -> None:
    """What a study or tuning checks before it runs: --jobs, --trials, --out; then the arm built
    (only `targets`, if given) and its warnings said."""
    if not 1 <= jobs <= 256:
        raise StudyConfigError(f"--jobs: must be in [1, 256], got {jobs}")
    if trials is not None and not 1 <= trials <= 100000:
        raise StudyConfigError(f"--trials: must be in [1, 100000], got {trials}")
    check_out_dir(out)
    print_arm_warnings(arm_info(build_arm("release", arm, targets=targets)), prefix)


OUT_LOCK = ".armctl-out.lock"  # in a study's or tuning's --out: held while the command writes there


# A study killed a moment ago still holds its --out while its workers stop their runs
# (tools/run/procs.py ORPHAN_STOP_S): the same command given again at once waits for that.
OUT_LOCK_WAIT_S = procs.ORPHAN_STOP_S + 5.0


def _hold_out(stack: ExitStack, out: Path) -> None:
    """--out for this command alone, until it ends: a second study there would delete and rewrite
    the first's run folders under it."""
    try:
        stack.enter_context(flocked(out / OUT_LOCK, timeout_s=OUT_LOCK_WAIT_S))
    except LockHeld:
        raise OutDirError(f"--out {out}: another study or tune holds this folder (lock {out / OUT_LOCK}); "
                          "wait for it to end or give another --out") from None


def add_subparser(sub: argparse._SubParsersAction) -> None:
    """The study module's two commands: study (run = cmd_study) and tune (run = cmd_tune)."""
    st = sub.add_parser("study", help="every method, tuned alike, in every scenario over seeds; the report")
    add_study_arguments(st)
    st.set_defaults(run=cmd_study)
    tu = sub.add_parser("tune", help="tune every method alike (Optuna) per scenario; kept for the study")
    add_tune_arguments(tu)
    tu.set_defaults(run=cmd_tune)


def cmd_study(ns: argparse.Namespace) -> int:
    """armctl study (a bad config, arm, --out or cluster exits 2; a run that cannot run, 1: tools/cli.py)."""
    cfg = load(ns.config)
    methods = subset(ns.methods, cfg.methods, "methods")
    scenarios = subset(ns.scenarios, list(cfg.scenarios), "scenarios")
    return study_and_summary(cfg, arm_from_args(ns), ns.out, methods=methods, scenarios=scenarios, seeds=ns.seeds,
                             duration_s=ns.duration, jobs=ns.jobs, cluster=cluster_from_args(ns), retune=ns.retune,
                             trials=ns.trials, bus=ns.bus, confirm=ns.confirm, figures=ns.figures,
                             protocol=ns.protocol, record=ns.record)


def study_and_summary(cfg: StudyConfig, arm: ArmRef, out: Path, *, methods: list[str] | None = None,
                      scenarios: list[str] | None = None, seeds: int | None = None, duration_s: float | None = None,
                      jobs: int | None = None, cluster: Cluster | None = None, retune: bool = False,
                      trials: int | None = None, bus: str = SIL, confirm: int = DEFAULT_CONFIRM, figures: bool = True,
                      protocol: str | None = None, record: bool = False, prefix: str = "armctl study",
                      targets: list[str] | None = None) -> int:
    """A study as `armctl study` runs it (and `armctl demo`): its options checked, the arm built
    (`targets` only, if given), the study run holding `out`, its summary printed; the exit code
    (1: a run measured nothing trustworthy, or SIL and the bus disagreed)."""
    if seeds is not None and not 1 <= seeds <= 1000:
        raise StudyConfigError(f"--seeds: must be in [1, 1000], got {seeds}")
    if duration_s is not None and not (0.001 <= duration_s <= 86400):
        raise StudyConfigError(f"--duration: must be in [0.001, 86400] s, got {duration_s}")
    if not 0 <= confirm <= 1000:
        raise StudyConfigError(f"--confirm: must be in [0, 1000], got {confirm}")
    jobs = default_jobs(bus) if jobs is None else jobs
    prepare(arm, out, jobs, trials, prefix, targets)
    if record and (cfg.path.resolve() != DEFAULT_CONFIG.resolve() or not arm.is_default or seeds or
                   duration_s or methods or scenarios or trials):
        raise StudyConfigError("--record: the headline is the default study as it stands (no --config, "
                               "--model/--arm, --seeds, --duration, --methods, --scenarios or --trials)")
    with ExitStack() as stack:
        _hold_out(stack, out)
        study = run_study(cfg, out, seeds=seeds, duration_s=duration_s, methods=methods,
                          scenarios=scenarios, arm=arm, jobs=jobs, cluster=cluster, retune=retune,
                          trials=trials, bus=bus, confirm=confirm, figures=figures, protocol=protocol, prefix=prefix)
    if record:
        from tools.study import headline

        headline.write(study)
        print(f"{prefix}: recorded in {headline.RECORD_BY_PROTOCOL[protocol]}" if protocol else
              f"{prefix}: the headline recorded in {headline.RECORD} and README.md's result tables")
    print((out / "summary.txt").read_text())
    print(f"report: {out / 'report.md'}")
    unmeasured = [f"{m} in {s} (seed {seed}): {r.get('result')}" for s, sc in study["scenarios"].items()
                  for m, runs in sc["runs"].items() for seed, r in zip(study["seeds"], runs) if not measured(r)]
    conf = study.get("confirmation")
    if conf is not None and not conf["all_match"]:
        bad = [f"{r['method']} in {r['scenario']} (seed {r['seed']}): {', '.join(r['differences'][:6])}"
               for r in conf["runs"] if not r["match"]]
        print(f"{prefix}: software in the loop and lockstep HIL disagree on {len(bad)} run(s): "
              + "; ".join(bad), file=sys.stderr)
        return 1
    if unmeasured:
        print(f"{prefix}: incomplete: {len(unmeasured)} run(s) measured nothing trustworthy: "
              + "; ".join(unmeasured[:8]) + (" ..." if len(unmeasured) > 8 else ""), file=sys.stderr)
    return 0 if not unmeasured else 1


def _cmd_verify(ns: argparse.Namespace, cfg: StudyConfig, arm: ArmRef, methods: list[str] | None,
                scenarios: list[str] | None, cluster: Cluster | None) -> int:
    """armctl tune --verify: every kept pair (of --scenarios, --methods) verified on this code
    (tools/study/verify.py); the equal ones restamped; exit 1 when any moved."""
    from tools.study import verify

    if ns.bus != SIL:
        raise StudyConfigError("--verify: the kept tuning's runs are software in the loop (--bus sil)")
    path = tuning_file(cfg, arm)
    with ExitStack() as stack:
        _hold_out(stack, ns.out)
        setup, info, _ = setup_for(cfg, arm, ns.out, ns.jobs, cluster, ns.bus)
        doc = _read_tuning(path)
        recs: dict[tuple[str, str], dict[str, Any]] = {}
        unkept = []
        for s in scenarios or list(cfg.scenarios):
            for m in methods or cfg.methods:
                if METHODS[m][1] is None:
                    continue
                rec = (doc["scenarios"].get(s) or {}).get(m)
                if not isinstance(rec, dict) or rec.get("key") != tuning_key(setup.cfg, info, setup, s, m):
                    unkept.append(f"{s}/{m}")
                else:
                    recs[(s, m)] = rec
        if unkept:
            raise StudyConfigError(f"--verify: {path} keeps no tuning of {', '.join(unkept)} for this arm and these "
                                   f"settings: `armctl tune --retune {' '.join(unkept)}` tunes them")
        bar = tqdm(total=sum(len(verify.recorded_runs(r, setup.cfg.tuning_seeds)[2]) for r in recs.values()),
                   desc="verify", unit="run")
        started = time.monotonic()
        checks = verify.verify_pairs(setup, recs, ns.out / "verify", progress=lambda spec, run: bar.update(1))
        bar.close()
        stamped = verify.restamp(path, checks)
        accepted = verify.accept_moved(path, checks, setup.cfg.tuning_seeds) if ns.accept_moved else []
    for c in checks:
        print(c.line())
    moved = [c for c in checks if not c.equal]
    retune = [c.pair for c in moved if c.retune]
    print(f"armctl tune --verify: {len(checks)} pair(s), {sum(c.runs for c in checks)} runs in "
          f"{time.monotonic() - started:.0f} s on {ns.jobs} core(s): {len(checks) - len(moved)} as recorded"
          + (f" (stamped with this code, {code_identity()}, in {_rel(path)})" if stamped else "")
          + (f"; {len(moved)} moved" if moved else ""))
    if retune:
        print(f"armctl tune --verify: the pick no longer holds in {len(retune)} pair(s): "
              f"tools/armctl tune --retune {' '.join(retune)}")
    if accepted:
        print(f"armctl tune --verify: {len(accepted)} moved pair(s) still rank ahead of their runner-up: their "
              f"picks kept, their runs recorded anew on this code and stamped: {', '.join(accepted)}")
    elif moved and not retune:
        print("armctl tune --verify: every moved pick still ranks ahead of its runner-up; its record's numbers are "
              f"another code's: tools/armctl tune --retune {' '.join(c.pair for c in moved)} tunes them again, "
              "or --verify --accept-moved keeps the picks and records this code's numbers")
    return 1 if retune or (moved and not accepted) else 0


# A method's own outcome, which the comparison reports: the run itself was complete.
OUTCOMES = ("ok", "tracking-bound-exceeded", "torque-limited", "diverged", "commands-missed")


def measured(r: dict[str, Any]) -> bool:
    """The run measured the method: it ended with one of the method's outcomes, or the method
    drove the arm into the safety layer's safe stop. A run that was interrupted, lost telemetry or
    whose processes failed measured nothing, and makes the study incomplete."""
    return r.get("result") in OUTCOMES or (r.get("result") == "failed" and r.get("final_state") in ("safe-stop", "fault"))


def _pairs(text: list[str], cfg: StudyConfig) -> list[tuple[str, str]]:
    """--retune's SCENARIO/METHOD pairs, each a tuned method of a scenario of the config."""
    out = []
    for item in text:
        s, _, m = item.rpartition("/")
        if s not in cfg.scenarios or m not in cfg.methods or METHODS[m][1] is None:
            tuned_methods = [x for x in cfg.methods if METHODS[x][1] is not None]
            raise StudyConfigError(f"--retune {item!r}: not SCENARIO/METHOD of the config (scenarios: "
                                   f"{', '.join(cfg.scenarios)}; tuned methods: {', '.join(tuned_methods)})")
        out.append((s, m))
    return list(dict.fromkeys(out))


def cmd_tune(ns: argparse.Namespace) -> int:
    """armctl tune (its errors as the study's); --verify: the kept tuning checked on this code."""
    cfg, arm, methods, scenarios, cluster = _common(ns)
    if getattr(ns, "accept_moved", False) and not getattr(ns, "verify", False):
        raise StudyConfigError("--accept-moved: only with --verify (it keeps picks that verified as still ahead)")
    if getattr(ns, "verify", False):
        return _cmd_verify(ns, cfg, arm, methods, scenarios, cluster)
    pairs = _pairs(ns.retune, cfg) if getattr(ns, "retune", None) else None
    with ExitStack() as stack:
        _hold_out(stack, ns.out)
        setup, info, _ = setup_for(cfg, arm, ns.out, ns.jobs, cluster, ns.bus)
        if pairs is None:
            result = tuned(setup.cfg, arm, setup, info, scenarios or list(cfg.scenarios), methods or cfg.methods,
                           retune=True, trials=ns.trials)
        else:  # the pairs side by side, as a whole tuning's (tools/study/pairs.py)
            result = tuned(setup.cfg, arm, setup, info, list(dict.fromkeys(s for s, _ in pairs)),
                           list(dict.fromkeys(m for _, m in pairs)), retune=True, trials=ns.trials, only=set(pairs))
            result = {s: recs for s, recs in result.items() if recs}
    for s, recs in result.items():
        for m, rec in recs.items():
            print(f"{one_line(s):<40} {m:<10} objective {rec['objective']:.4g}  {rec['status']} "
                  f"({rec['trials_run']} of at most {rec['cap']} trials)  {json.dumps(rec['knobs'])}"
                  + (f"  ({rec['edge_note']})" if rec["edge_note"] else "")
                  + (f"  validation: {rec['validation']['note']}" if rec.get("validation") else ""))
    from tools.study.figure_data import colour_of
    from tools.study.figures import convergence_figure

    colour = colour_of({"methods": cfg.methods})
    for s, recs in result.items():
        print(f"best-so-far curves: {ns.out / convergence_figure(ns.out, s, recs, colour)}")
    print(f"tuning: {tuning_file(cfg, arm)}")
    print(f"Optuna storage: {storage_url(ns.out)} (optuna-dashboard opens it)")
    return 0
