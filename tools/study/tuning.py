"""Every method tuned alike: Optuna's TPE sampler under one rule, the same tuning seeds and tuning
trajectory for each method, per scenario.

A trial is a set of knobs: a method's gains (pd, tde, usde-smc), or its synthesis weights (pm,
pm-paper, gh2: each candidate is synthesised, refused designs score REFUSED_SCORE, and accepted
ones are built into the firmware the trial runs). A candidate whose closed-loop bandwidth
(tools/study/bandwidth.py) is not below the arm's first joint resonance is refused too: no real
arm survives it. Its score is the objective over the tuning seeds, the worst seed's (no ties: a
failed trial scores by what it achieved).

Each method and scenario runs until its best has improved by no more than [tuning] tolerance
(1 %) over its last `plateau` trials, or until `cap` trials, the same cap for every method.
Trials are asked in batches of min([tuning] batch, --jobs) and told in order. A best value within
2 % (on the log scale) of a range's edge when the round ends (converged, or `plateau` trials run
with the best at the edge) widens the range tenfold on that side and starts a new round (up to
`widen` times), whose trials count against the same cap. The pick is the best trial
that also runs ok on every validation seed (held out); else the next best, and the record says
so. The record keeps every trial, the best-so-far curve and whether it converged or was capped.
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

from tools.run import procs
from tools.run.cluster import Cluster
from tools.build.code_identity import code_identity
from tools.study.design_knobs import design_text
from tools.run.runner import SYNTH_LOCK, RunSpec, run_all, synthesize_cached
from tools.study.bandwidth import bandwidth_hz, method_loop
from tools.study.config import ESTIMATING, KNOB_FLOOR, METHODS, Scenario, Space, StudyConfig, gain_args

FAILED_SCORE = 1e3  # rad: what a trial with a run that failed, diverged or hit its torque limit scores at least
ACHIEVED_CAP = 30.0   # rad: one joint's error in a failed run counts at most this much (so a failed trial < 3000)
REFUSED_SCORE = 4 * FAILED_SCORE  # a design the synthesis refused: nothing ran
EDGE = 0.02         # a best value this close to a range's end (fraction of its log width) is at the edge
SCORED = ("ok", "tracking-bound-exceeded")  # a run that ended well scores its tracking error


def _read_tuning(path: Path) -> dict[str, Any]:
    """The kept tuning file; an absent or unreadable one is empty (everything is tuned again)."""
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError):
        doc = {}
    if not isinstance(doc, dict) or not isinstance(doc.get("scenarios"), dict):
        doc = {**(doc if isinstance(doc, dict) else {}), "scenarios": {}}
    return doc


@dataclass
class TuneSetup:
    cfg: StudyConfig
    arm_args: dict[str, str | None]   # RunSpec's model, arm_file, design
    base_design: str                  # the arm's design config text: what the synthesis knobs replace
    trajectory_args: list[str]
    out: Path
    jobs: int = 1
    cluster: Cluster | None = None
    bus: str = "sil"                  # every run's bus (tools/run/hil.py --bus)
    resonance_hz: float = float("inf")  # the arm's first joint resonance: every pick's bandwidth stays below it
    period_s: float = 1e-3            # the loop period


def objective(results: list[dict[str, Any]]) -> tuple[float, str]:
    """A trial's score over its tuning seeds, lower is better, never tied unless the runs are.

    Every seed's run ended well (ok, or tracking bound exceeded): the worst seed's sum over joints
    of the L-infinity tracking error (rad), the paper's Table 2 measure: gains that hold on most
    seeds but not all (at the edge of stability) lose to gains that hold on all.

    Otherwise (failed, diverged, torque-limited, ...) the trial scores by what it achieved:
        FAILED_SCORE * (1 + the mean share of the trajectory the runs did not cover)
        + the mean over seeds of the sum over joints of the L-inf error over the periods each ran
        + the mean over seeds of the sum over joints of the share of the time at the torque limit
        + the share of the seeds that did not end well
    so it is always at least FAILED_SCORE (behind any trial that ended well: they score less),
    at most ~3 * FAILED_SCORE (a synthesis refusal, REFUSED_SCORE, scores more), and a trial that
    ran longer, tracked better or sat at its limit less scores better."""
    if results and all(_ended_well(r.get("results", {})) for r in results):
        return max(sum(r["results"]["tracking_max_abs_rad"]) for r in results), ""
    res_all = [r.get("results", {}) for r in results]
    n = max(1, len(res_all))
    uncovered = sum(1.0 - _covered(res) for res in res_all) / n
    tracking = sum(_achieved(res) for res in res_all) / n
    saturated = sum(sum(_finite(x, 1.0) for x in (res.get("saturated_fraction") or [])) for res in res_all) / n
    failed_share = sum(not _ended_well(res) for res in res_all) / n
    first = next((res for res in res_all if not _ended_well(res)), {})
    why = (first.get("verdict_reasons") or [first.get("result", "failed")])[0]
    return FAILED_SCORE * (1.0 + uncovered) + tracking + saturated + failed_share, str(why)


def _ended_well(res: dict[str, Any]) -> bool:
    e = res.get("tracking_max_abs_rad")
    return res.get("result") in SCORED and bool(e) and all(isinstance(x, (int, float)) and math.isfinite(x) for x in e)


def _finite(x: Any, cap: float) -> float:
    """x, or cap where it is not a finite number (a diverged run's error), never more than cap."""
    return min(float(x), cap) if isinstance(x, (int, float)) and math.isfinite(x) else cap


def _achieved(res: dict[str, Any]) -> float:
    """The sum over joints of the L-inf tracking error of the periods a run has (rad), each joint's
    capped at ACHIEVED_CAP (a diverged joint's error is not a number worth ranking by)."""
    return sum(_finite(x, ACHIEVED_CAP) for x in (res.get("tracking_max_abs_rad") or []))


def _covered(res: dict[str, Any]) -> float:
    """The share of the trajectory a run's metrics cover, 0..1."""
    want, have = res.get("trajectory_periods"), res.get("periods_running")
    if not want or have is None:
        return 0.0
    return max(0.0, min(1.0, have / want))


def synthesized(text: str) -> tuple[Any, str]:
    """The design the synthesis makes of this config, or None and why it refused it (in-process:
    about 0.1 s)."""
    from gen.synth.config import ConfigError, load_config
    from gen.synth.lmi import SynthesisError

    with tempfile.NamedTemporaryFile("w", suffix=".toml") as fh, SYNTH_LOCK:
        fh.write(text)
        fh.flush()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return synthesize_cached(load_config(Path(fh.name))), ""  # its SIL runs reuse the design
        except (ConfigError, SynthesisError, ValueError, ArithmeticError) as exc:
            return None, f"synthesis refused it: {str(exc).splitlines()[0][:300]}"


def controller_values(method: str, knobs: dict[str, Any]) -> dict[str, float]:
    """A gain method's firmware options for these knobs ({"kp": .., "kd": .., ...})."""
    args = gain_args(method, knobs)
    return {args[i][2:].replace("-", "_"): float(args[i + 1]) for i in range(0, len(args), 2)}


def method_bandwidth(setup: TuneSetup, method: str, knobs: dict[str, Any]) -> float | None:
    """A study method's closed-loop bandwidth (Hz) with these knobs; an untuned one's with its fixed
    weights (the arm's design config); None when the synthesis refuses the design."""
    if METHODS[method][1] is None:
        design, _ = synthesized(setup.base_design)
        return None if design is None else bandwidth_hz(
            method_loop(METHODS[method][0], {}, design, setup.period_s), setup.period_s)
    return candidate_check(setup, method, knobs)[1]


def candidate_check(setup: TuneSetup, method: str, knobs: dict[str, Any]) -> tuple[str, float | None]:
    """('', its closed-loop bandwidth in Hz) for a candidate the tuning may run, else (why not, the
    bandwidth when it has one): the synthesis refused its weights, or its bandwidth is not below
    the arm's first resonance."""
    design = None
    if METHODS[method][1] == "design":
        design, why = synthesized(design_text(setup.base_design, knobs, with_estimator=method in ESTIMATING))
        if design is None:
            return why, None
    bw = bandwidth_hz(method_loop(
        METHODS[method][0], controller_values(method, knobs) if design is None else {}, design, setup.period_s),
        setup.period_s)
    if not bw < setup.resonance_hz:
        return (f"its closed-loop bandwidth {bw:.3g} Hz is not below the arm's first resonance "
                f"{setup.resonance_hz:.3g} Hz"), bw
    return "", bw


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
               duration_s: float, trajectory_args: list[str], keep_log: bool,
               overrides: dict[str, Any] | None = None) -> RunSpec:
    """The run of one method with these knobs (tuning or the study itself); overrides: uncertainty
    fields changed from the scenario's (the robust pick's variants)."""
    if scenario.per_joint and not scenario.resolved:  # it would run without its per-joint values
        raise RuntimeError(f"scenario {scenario.name}: per-joint values not made for the arm (study.setup_for)")
    firmware, how = METHODS[method]
    args = [*trajectory_args, "--ref-hold", f"{setup.cfg.hold_s:g}"]
    text = None
    if how == "gains":
        args = [*gain_args(method, knobs), *args]
    elif how == "design":
        text = design_text(setup.base_design, knobs, with_estimator=method in ESTIMATING)
    return RunSpec(out=str(out), method=firmware, duration_s=duration_s, controller_args=tuple(args),
                   uncertainty={**scenario.uncertainty, **(overrides or {}), "seed": seed},
                   drives=scenario.drives.to_dict(),
                   bus_timing=scenario.bus_timing, design_text=text, keep_log=keep_log,
                   labels={"method": method, "scenario": scenario.name, "seed": seed, "knobs": knobs},
                   code=code_identity(), bus=setup.bus, protocol=scenario.protocol, **setup.arm_args)


STORAGE = "optuna.db"  # in the tuning's output folder: optuna-dashboard sqlite:///.../optuna.db


def storage_url(out: Path) -> str:
    out.mkdir(parents=True, exist_ok=True)
    return f"sqlite:///{(out / STORAGE).resolve()}"


def open_storage(out: Path) -> Any:
    """The tuning's Optuna storage. Pairs tuned side by side (tools/study/pairs.py) share its file:
    a writer waits up to a minute for the other's transaction instead of SQLite's 5 s."""
    import optuna

    return optuna.storages.RDBStorage(storage_url(out), engine_kwargs={"connect_args": {"timeout": 60}})


def batch_size(cfg: StudyConfig, jobs: int) -> int:
    """Trials asked at once: [tuning] batch, never more than --jobs."""
    return max(1, min(cfg.batch, jobs))


def best_so_far(scores: list[float]) -> list[float]:
    out: list[float] = []
    for v in scores:
        out.append(v if not out else min(out[-1], v))
    return out


def plateaued(curve: list[float], since: int, plateau: int, tolerance: float) -> bool:
    """The best-so-far curve's last `plateau` trials (all after index `since`, the round's start)
    improved it by no more than `tolerance` (relative), and its best ended well."""
    n = len(curve)
    if n - since < plateau or n <= plateau or curve[-1] >= FAILED_SCORE:
        return False
    before = curve[n - plateau - 1]
    return before - curve[-1] <= tolerance * abs(before)


def _edges(method: str, recorded: list[dict[str, Any]], ranges: dict[str, tuple[float, float]],
           ceilings: dict[str, float]) -> dict[str, str]:
    """The knobs whose best value (of these trials) sits at an edge of its range it may widen past
    (never below a structure's floor, never above the arm's first resonance)."""
    top = min(recorded, key=lambda x: x["objective"])
    return {k: e for k, (lo, hi) in ranges.items() if (e := _at_edge(top["knobs"][k], lo, hi))
            and not (e == "low" and KNOB_FLOOR.get((method, k)) == lo)
            and not (e == "high" and ceilings.get(k) == hi)}


def _record_of(t: Any) -> dict[str, Any] | None:
    rec = t.user_attrs.get("record")
    return json.loads(rec) if isinstance(rec, str) else None


def _trial_runs(setup: TuneSetup, method: str, scenario: Scenario, knob_sets: list[dict[str, Any]],
                seeds: list[int], names: list[str], variants: list[dict[str, Any]] | None = None) -> list[
        tuple[float, str, list[dict[str, Any]], float | None]]:
    """Every knob set run on every seed (refused candidates not run): (score, why, runs, bandwidth)
    each, the runs of every variant of the scenario in turn (variants: uncertainty overrides, by
    default the scenario as it is)."""
    variants = variants or [{}]
    specs: list[RunSpec] = []
    refused: dict[int, tuple[str, float | None]] = {}
    bws: dict[int, float | None] = {}
    for i, knobs in enumerate(knob_sets):
        why, bws[i] = candidate_check(setup, method, knobs)
        if why:
            refused[i] = (why, bws[i])
            continue
        for v, over in enumerate(variants):
            for s in seeds:
                tag = "" if not over else "-" + "-".join(f"{k}{x}" for k, x in sorted(over.items()))
                specs.append(trial_spec(setup, method, scenario, knobs, s,
                                        setup.out / scenario.name / method / f"{names[i]}-s{s}{tag}",
                                        setup.cfg.tuning_duration_s, setup.trajectory_args, keep_log=False,
                                        overrides=over))
    runs = run_all(specs, setup.jobs, setup.cluster)
    if procs.interrupted is not None:  # the methods tuned so far are kept
        raise procs.Interrupted(procs.interrupted)
    it = iter(runs)
    out = []
    for i in range(len(knob_sets)):
        if i in refused:
            why, bw = refused[i]
            # ranked among themselves: the nearer the resonance, the nearer a candidate that may run
            score = REFUSED_SCORE + (bw / setup.resonance_hz if bw is not None and setup.resonance_hz > 0 else 1e3)
            out.append((score, why, [], bw))
        else:
            per_seed = [next(it) for _ in seeds * len(variants)]
            score, why = objective(per_seed)
            out.append((score, why, per_seed, bws[i]))
    return out


def _run_summary(seeds: list[int], runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [{"seed": s, "result": r["results"].get("result"),
             "tracking_max_abs_deg": r["results"].get("tracking_max_abs_deg")} for s, r in zip(seeds, runs)]


def _resumed_trials(study: Any, best: dict[str, Any] | None, scores: list[float]) -> list[dict[str, Any]]:
    """What an earlier run of this round told (its scores appended to `scores`); a trial asked and
    never told is failed, to be asked again. A new round's trial 0 is the previous round's best."""
    import optuna

    recorded: list[dict[str, Any]] = []
    for t in study.get_trials(deepcopy=False):
        rec = _record_of(t) if t.state == optuna.trial.TrialState.COMPLETE else None
        if rec is not None:
            recorded.append(rec)
            scores.append(rec["objective"])
        elif t.state == optuna.trial.TrialState.RUNNING:
            study.tell(t.number, state=optuna.trial.TrialState.FAIL)
    if not study.trials and best is not None:  # the previous round's best, inside the widened ranges
        study.enqueue_trial(best["knobs"])
    return recorded


@dataclass
class _Round:
    """One round of a method's tuning: its number, its ranges, and where its Optuna study is kept."""
    number: int
    ranges: dict[str, tuple[float, float]]
    name: str
    cap: int
    batch: int


def _run_round(setup: TuneSetup, scenario: Scenario, method: str, rnd: _Round, study: Any,
               recorded: list[dict[str, Any]], scores: list[float], progress: Any) -> bool:
    """Asks and runs batches of trials until the best-so-far plateaus, the cap, or the best sits at an
    edge (widen now, within the same cap). True when it converged."""
    cfg, space = setup.cfg, setup.cfg.spaces[method]
    since = len(scores) - len(recorded)
    converged = plateaued(best_so_far(scores), since, cfg.plateau, cfg.tolerance)
    while not converged and len(scores) < rnd.cap:
        asked = [study.ask() for _ in range(min(rnd.batch, rnd.cap - len(scores)))]
        knob_sets = [_suggest(t, rnd.ranges, space.choices) for t in asked]
        names = [f"r{rnd.number}-t{len(recorded) + i:03d}" for i in range(len(asked))]
        for t, knobs, (score, why, per_seed, bw) in zip(asked, knob_sets, _trial_runs(
                setup, method, scenario, knob_sets, cfg.tuning_seeds, names)):
            rec = {"trial": len(recorded), "round": rnd.number, "knobs": knobs, "objective": score,
                   "failed": why or None, "bandwidth_hz": bw, "runs": _run_summary(cfg.tuning_seeds, per_seed)}
            t.set_user_attr("record", json.dumps(rec))
            study.tell(t, score)
            recorded.append(rec)
            scores.append(score)
            if progress:
                progress()
        converged = plateaued(best_so_far(scores), since, cfg.plateau, cfg.tolerance)
        if rnd.number < cfg.widen and len(recorded) >= cfg.plateau and _edges(method, recorded, rnd.ranges,
                                                                              space.ceilings):
            break
    return converged


def _widened(method: str, ranges: dict[str, tuple[float, float]], edges: dict[str, str]) -> None:
    """Each range whose best sits at an edge, ten times wider on that side (not below its floor)."""
    for k, side in edges.items():
        lo, hi = ranges[k]
        floor = KNOB_FLOOR.get((method, k))
        ranges[k] = (max(lo / 10, floor or 0.0), hi) if side == "low" else (lo, hi * 10)


def _edge_note(rounds: list[dict[str, Any]], capped: bool) -> str:
    last = rounds[-1]
    if last["at_edge"]:
        return (f"the best value of {', '.join(last['at_edge'])} is still at the edge of its range after "
                f"{len(rounds) - 1} widening(s)" + (" (the cap ended the tuning)" if capped else "")
                + f": the optimum may lie beyond {last['ranges']}")
    if len(rounds) > 1:
        return "ranges widened: " + "; ".join(f"round {r['round']}: {r['at_edge']}" for r in rounds[:-1])
    return ""


def tune_method(setup: TuneSetup, scenario: Scenario, method: str, trials: int | None = None,
                progress: Any = None, key: str = "") -> dict[str, Any]:
    """One method in one scenario, to convergence or the cap (`trials` overrides [tuning] cap);
    then the pick checked on the validation seeds. The Optuna study lives in an SQLite storage in
    the tuning's output folder, one study per round, named by scenario, method, the tuning key and
    the batch: a tuning stopped part way resumes there (its told trials are kept, its untold ones
    asked again), and optuna-dashboard can open it."""
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    cfg = setup.cfg
    space: Space = cfg.spaces[method]
    cap = trials or cfg.cap
    batch = batch_size(cfg, setup.jobs)
    storage = open_storage(setup.out)
    ranges = dict(space.ranges)
    rounds: list[dict[str, Any]] = []
    scores: list[float] = []  # every trial of every round, in order: the best-so-far curve's source
    best: dict[str, Any] | None = None
    status = "capped"
    for number in range(cfg.widen + 1):
        if len(scores) >= cap:
            break
        rnd = _Round(number, ranges, f"{scenario.name}/{method}/{key or 'nokey'}/cap{cap}/b{batch}/r{number}", cap, batch)
        sampler = optuna.samplers.TPESampler(seed=_sampler_seed(method, scenario.name, number),
                                             n_startup_trials=max(1, min(cfg.startup, cap // 2)))
        study = optuna.create_study(direction="minimize", sampler=sampler, storage=storage, study_name=rnd.name,
                                    load_if_exists=True)
        recorded = _resumed_trials(study, best, scores)
        converged = _run_round(setup, scenario, method, rnd, study, recorded, scores, progress)
        if not recorded:
            break
        top = min(recorded, key=lambda x: x["objective"])
        edges = _edges(method, recorded, ranges, space.ceilings)
        rounds.append({"round": number, "ranges": {k: list(v) for k, v in ranges.items()}, "trials": recorded,
                       "best": top, "at_edge": edges, "converged": converged, "storage_study": rnd.name})
        if best is None or top["objective"] <= best["objective"]:
            best = top
        status = "converged" if converged else "capped"
        if not edges or top["objective"] >= FAILED_SCORE:
            break
        _widened(method, ranges, edges)
    assert best is not None
    everything = [t for r in rounds for t in r["trials"]]
    pick, validation = validate(setup, scenario, method, everything, best)
    return {"method": method, "scenario": scenario.name, "space": space.as_dict(), "cap": cap,
            "plateau": cfg.plateau, "tolerance": cfg.tolerance, "batch": batch, "status": status,
            "trials_run": len(scores), "best_so_far": best_so_far(scores), "best_by_objective": best,
            "rounds": rounds, "knobs": pick["knobs"], "objective": pick["objective"],
            "failed": pick["failed"], "edge_note": _edge_note(rounds, len(scores) >= cap), "validation": validation,
            "bandwidth_hz": pick.get("bandwidth_hz"), "resonance_hz": setup.resonance_hz,
            "storage": storage_url(setup.out),
            "design_text": design_text(setup.base_design, pick["knobs"], with_estimator=method in ESTIMATING)
            if METHODS[method][1] == "design" else None}


def _tried_text(x: dict[str, Any]) -> str:
    where = f" ({'; '.join(x['failed_in'])})" if x.get("failed_in") else ""
    return f"round {x['round']} trial {x['trial']}: {', '.join(map(str, x['results']))}{where}"


def robust_variants(cfg: StudyConfig, scenario: Scenario) -> list[dict[str, Any]]:
    """The scenario as it is, then every corner a pick must also run ok in: each gear stiffness of
    [tuning] robust_stiffness (a flexible scenario) with each end of the payload's range (a
    scenario with a drawn payload)."""
    unc = scenario.uncertainty
    stiff = [{"gear_stiffness_scale": k} for k in cfg.robust_stiffness] if unc.get("flexible") else [{}]
    pk = unc.get("payload_kg") or []
    loads = [{"payload_kg": [x]} for x in dict.fromkeys(pk)] if len(pk) == 2 and pk[1] > pk[0] else [{}]
    corners = [{**a, **b} for a in stiff for b in loads]
    return [{}] + [c for c in corners if c]


def _variant_text(v: dict[str, Any]) -> str:
    return ", ".join(f"gears x{x}" if k == "gear_stiffness_scale" else f"payload {x[0]:g} kg" for k, x in v.items()) \
        or "as the scenario is"


def validate(setup: TuneSetup, scenario: Scenario, method: str, trials: list[dict[str, Any]],
             best: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """The pick: the best trial that ran ok on every tuning seed and also runs ok on every
    validation seed, in the scenario as it is and in every robust corner (robust_variants),
    trying the best [tuning] validation_tries such trials (distinct knobs) in turn; none does: the
    best by objective, and the record says so."""
    cfg = setup.cfg
    seeds = cfg.validation_seeds
    variants = robust_variants(cfg, scenario)
    if not seeds:
        return best, {"seeds": [], "note": "no validation seeds: the best by objective"}
    seen: set[str] = set()
    ranked = []
    for t in sorted(trials, key=lambda x: x["objective"]):
        k = json.dumps(t["knobs"], sort_keys=True)
        if t["objective"] < FAILED_SCORE and all(r["result"] == "ok" for r in t["runs"]) and k not in seen:
            seen.add(k)
            ranked.append(t)
    tried = []
    for rank, t in enumerate(ranked[:cfg.validation_tries]):
        (_, why, runs, _), = _trial_runs(setup, method, scenario, [t["knobs"]], seeds,
                                         [f"validate-r{t.get('round', 0)}-t{t['trial']:03d}"], variants)
        results = [r["results"].get("result") for r in runs] or ["refused"]
        ok = bool(runs) and all(x == "ok" for x in results)
        failed_in = sorted({_variant_text(v) for i, v in enumerate(variants)
                            for r in results[i * len(seeds):(i + 1) * len(seeds)] if r != "ok"})
        tried.append({"rank": rank, "round": t.get("round", 0), "trial": t["trial"], "objective": t["objective"],
                      "results": results, "ok": ok, "failed_in": failed_in,
                      "runs": _run_summary([s for _ in variants for s in seeds], runs)})
        if ok:
            note = ("the best by objective ran ok on every validation seed and robust corner" if rank == 0 else
                    f"the best {rank} trial(s) by objective did not run ok on every validation seed and robust corner "
                    f"({'; '.join(_tried_text(x) for x in tried[:-1])}); "
                    f"picked the next best, round {t.get('round', 0)} trial {t['trial']}")
            return t, {"seeds": seeds, "variants": variants, "picked_rank": rank, "tried": tried, "note": note}
    note = (f"none of the best {len(tried)} trial(s) ran ok on every validation seed {seeds} and robust corner: "
            "kept the best by objective, which is not robust" if tried else
            "no trial ran ok on every tuning seed: nothing to validate; kept the best by objective, which is not robust")
    return best, {"seeds": seeds, "variants": variants, "picked_rank": None, "tried": tried, "note": note}
