"""Every method tuned alike: Optuna's TPE sampler, the same trial budget, tuning seeds and tuning
trajectory for each method, per scenario.

A trial is a set of knobs: a method's gains (pd, tde, usde-smc), or its synthesis weights (pm,
pm-paper, gh2: each candidate is synthesised, refused designs score as failed, and accepted ones
are built into the firmware the trial runs). Its score is the objective over the tuning seeds.
Trials are asked in batches of a fixed size and told in order, so the result does not depend on
how many run at once. A best value within 2 % (on the log scale) of a range's edge is reported,
the range is widened tenfold on that side, and the same budget runs again, up to `widen` times;
every trial of every round is recorded.
"""

from __future__ import annotations

import hashlib
import json
import math
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tools import procs
from tools.cluster import Cluster
from tools.code_identity import code_identity
from tools.design_knobs import design_text
from tools.runner import RunSpec, run_all
from tools.study_config import METHODS, Scenario, Space, StudyConfig, gain_args

FAILED_SCORE = 1e3  # rad: what a run that failed, diverged or hit its torque limit scores at least
EDGE = 0.02         # a best value this close to a range's end (fraction of its log width) is at the edge
SCORED = ("ok", "tracking-bound-exceeded")  # a run that ended well scores its tracking error


@dataclass
class TuneSetup:
    cfg: StudyConfig
    arm_args: dict[str, str | None]   # RunSpec's model, arm_file, design
    base_design: str                  # the arm's design config text: what the synthesis knobs replace
    trajectory_args: list[str]
    out: Path
    jobs: int = 1
    cluster: Cluster | None = None
    bus: str = "sil"                  # every run's bus (tools/hil.py --bus)


def objective(results: list[dict[str, Any]]) -> tuple[float, str]:
    """The mean over the tuning seeds of the sum over joints of the L-infinity tracking error
    (rad), the paper's Table 2 measure. A run that did not end well scores FAILED_SCORE or more:
    up to twice that as the share of the trajectory it covered falls (a method the safety layer
    stopped early is worse than one stopped late, so the search can still climb where every
    trial fails; a synthesis refusal scores the most)."""
    total = 0.0
    for r in results:
        res = r.get("results", {})
        if res.get("result") not in SCORED or not res.get("tracking_max_abs_rad"):
            why = (res.get("verdict_reasons") or [res.get("result", "failed")])[0]
            return FAILED_SCORE * (2.0 - min(_covered(x.get("results", {})) for x in results)), str(why)
        total += sum(res["tracking_max_abs_rad"])
    return total / len(results), ""


def _covered(res: dict[str, Any]) -> float:
    """The share of the trajectory a run's metrics cover, 0..1."""
    want, have = res.get("trajectory_periods"), res.get("periods_running")
    if not want or have is None:
        return 0.0
    return max(0.0, min(1.0, have / want))


def design_check(text: str) -> str:
    """'' if the synthesis accepts this design, else why not (in-process: about 0.1 s)."""
    from gen.synth.config import ConfigError, load_config
    from gen.synth.lmi import SynthesisError
    from gen.synth.pipeline import synthesize

    with tempfile.NamedTemporaryFile("w", suffix=".toml") as fh:
        fh.write(text)
        fh.flush()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                synthesize(load_config(Path(fh.name)))
        except (ConfigError, SynthesisError, ValueError, ArithmeticError) as exc:
            return f"synthesis refused it: {str(exc).splitlines()[0][:300]}"
    return ""


def _suggest(trial: Any, ranges: dict[str, tuple[float, float]], choices: dict[str, list[str]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, opts in sorted(choices.items()):
        out[k] = trial.suggest_categorical(k, opts)
    for k, (lo, hi) in sorted(ranges.items()):
        out[k] = trial.suggest_float(k, lo, hi, log=True)
    return out


def _at_edge(v: float, lo: float, hi: float) -> str | None:
    pos = (math.log(v) - math.log(lo)) / (math.log(hi) - math.log(lo))
    return "low" if pos < EDGE else "high" if pos > 1 - EDGE else None


def _sampler_seed(*parts: Any) -> int:
    return int(hashlib.sha256(json.dumps(parts).encode()).hexdigest()[:8], 16)


def trial_spec(setup: TuneSetup, method: str, scenario: Scenario, knobs: dict[str, Any], seed: int, out: Path,
               duration_s: float, trajectory_args: list[str], keep_log: bool) -> RunSpec:
    """The run of one method with these knobs (tuning or the study itself)."""
    if scenario.per_joint and not scenario.resolved:  # it would run without its per-joint values
        raise RuntimeError(f"scenario {scenario.name}: per-joint values not made for the arm (study.setup_for)")
    firmware, how = METHODS[method]
    args = [*trajectory_args, "--ref-hold", f"{setup.cfg.hold_s:g}"]
    text = None
    if how == "gains":
        args = [*gain_args(method, knobs), *args]
    elif how == "design":
        text = design_text(setup.base_design, knobs, with_estimator=method != "gh2")
    return RunSpec(out=str(out), method=firmware, duration_s=duration_s, controller_args=tuple(args),
                   uncertainty={**scenario.uncertainty, "seed": seed}, drives=scenario.drives.to_dict(),
                   bus_timing=scenario.bus_timing, design_text=text, keep_log=keep_log,
                   labels={"method": method, "scenario": scenario.name, "seed": seed, "knobs": knobs},
                   code=code_identity(), bus=setup.bus, **setup.arm_args)


def tune_method(setup: TuneSetup, scenario: Scenario, method: str, trials: int | None = None,
                progress: Any = None) -> dict[str, Any]:
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    cfg = setup.cfg
    space: Space = cfg.spaces[method]
    budget = trials or cfg.trials
    ranges = dict(space.ranges)
    rounds: list[dict[str, Any]] = []
    best: dict[str, Any] | None = None
    for rnd in range(cfg.widen + 1):
        sampler = optuna.samplers.TPESampler(seed=_sampler_seed(method, scenario.name, rnd),
                                             n_startup_trials=max(1, min(8, budget // 2)))
        study = optuna.create_study(direction="minimize", sampler=sampler)
        if best is not None:  # the previous round's best, inside the widened ranges, is trial 0
            study.enqueue_trial(best["knobs"])
        recorded: list[dict[str, Any]] = []
        while len(recorded) < budget:
            asked = [study.ask() for _ in range(min(cfg.batch, budget - len(recorded)))]
            knob_sets = [_suggest(t, ranges, space.choices) for t in asked]
            specs: list[RunSpec] = []
            refused: dict[int, str] = {}
            for i, knobs in enumerate(knob_sets):
                n = len(recorded) + i
                if METHODS[method][1] == "design":
                    why = design_check(design_text(setup.base_design, knobs, with_estimator=method != "gh2"))
                    if why:
                        refused[i] = why
                        continue
                for s in cfg.tuning_seeds:
                    specs.append(trial_spec(setup, method, scenario, knobs, s,
                                            setup.out / scenario.name / method / f"r{rnd}-t{n:03d}-s{s}",
                                            cfg.tuning_duration_s, setup.trajectory_args, keep_log=False))
            runs = run_all(specs, setup.jobs, setup.cluster)
            if procs.interrupted is not None:  # the methods tuned so far are kept
                raise procs.Interrupted(procs.interrupted)
            by_trial = iter(runs)
            for i, (t, knobs) in enumerate(zip(asked, knob_sets)):
                if i in refused:
                    score, why, per_seed = 2.0 * FAILED_SCORE, refused[i], []
                else:
                    per_seed = [next(by_trial) for _ in cfg.tuning_seeds]
                    score, why = objective(per_seed)
                study.tell(t, score)
                recorded.append({"trial": len(recorded), "knobs": knobs, "objective": score, "failed": why or None,
                                 "runs": [{"seed": s, "result": r["results"].get("result"),
                                           "tracking_max_abs_deg": r["results"].get("tracking_max_abs_deg")}
                                          for s, r in zip(cfg.tuning_seeds, per_seed)]})
                if progress:
                    progress()
        top = min(recorded, key=lambda x: x["objective"])
        edges = {k: e for k, (lo, hi) in ranges.items() if (e := _at_edge(top["knobs"][k], lo, hi))}
        rounds.append({"round": rnd, "ranges": {k: list(v) for k, v in ranges.items()}, "trials": recorded,
                       "best": top, "at_edge": edges})
        if best is None or top["objective"] <= best["objective"]:
            best = top
        if not edges or top["objective"] >= FAILED_SCORE:
            break
        for k, side in edges.items():
            lo, hi = ranges[k]
            ranges[k] = (lo / 10, hi) if side == "low" else (lo, hi * 10)
    assert best is not None
    last = rounds[-1]
    note = ""
    if last["at_edge"] and len(rounds) > cfg.widen:
        note = (f"the best value of {', '.join(last['at_edge'])} is still at the edge of its range after "
                f"{cfg.widen} widenings: the optimum may lie beyond {last['ranges']}")
    elif len(rounds) > 1:
        note = "ranges widened: " + "; ".join(f"round {r['round']}: {r['at_edge']}" for r in rounds[:-1])
    return {"method": method, "scenario": scenario.name, "space": space.as_dict(), "budget_per_round": budget,
            "rounds": rounds, "knobs": best["knobs"], "objective": best["objective"],
            "failed": best["failed"], "edge_note": note,
            "design_text": design_text(setup.base_design, best["knobs"], with_estimator=method != "gh2")
            if METHODS[method][1] == "design" else None}
