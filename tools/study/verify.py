"""A kept tuning verified by what it does: each kept pick's recorded validation runs (its knobs, the
validation seeds, every robust corner, the tuning trajectory) run again in software in the loop on
this code and compared with the record number for number (each run's result and L-infinity
tracking error per joint; the pick's closed-loop bandwidth).

Equal: the pick is what this code would run, and `armctl tune --verify` restamps the pair with
this code's identity (tools/build/code_identity.py). A study or a demo on code the kept tuning was
not stamped with verifies instead of warning, and keeps the verdict for this code in the build
folder (never in a tracked file), so it is not repeated.

Different: which runs moved and by how much; then the pick and its recorded runner-up (the next
distinct trial the validation would have taken) run again on the tuning seeds, and the record
says whether the pick still scores ahead of it on this code. Only a pair whose pick no longer
holds its place (or no longer runs ok) needs `armctl tune --retune SCENARIO/METHOD`.

The record a pair keeps (tools/studies/paper.tuning.json, docs/study.md "The kept tuning"):
`code`, the identity it was last tuned or verified on; `tuned_code`, the one it was tuned on;
`verified`, the last verification's runs and its time.
"""

from __future__ import annotations

import hashlib
import json
import math
import shutil
import sys
import time
from concurrent.futures import CancelledError, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from gen.lib.atomic_output import write_json_atomic
from gen.lib.locks import flocked
from gen.lib.paths import build_dir
from tools.build.code_identity import code_identity
from tools.run import procs
from tools.build import BuildError
from tools.build.arm import arm_info
from tools.run.runner import RunSpec, execute, prepare_build, run_all, sil_design
from tools.run.workers import ForkedWorkers
from tools.study.config import StudyConfigError
from tools.study.tuning import (FAILED_SCORE, TuneSetup, _read_tuning, _variant_text, candidate_check, objective,
                                robust_variants, trial_spec)

VERDICTS = "tuning-verified"  # build/release/VERDICTS/<code identity>.json: what this code found


class VerifyError(StudyConfigError):
    """A kept pair that cannot be verified (its record lacks what the runs need)."""


@dataclass
class PairCheck:
    """One pair's verification: equal, or what moved and whether its pick still holds."""
    scenario: str
    method: str
    runs: int = 0
    moved: list[str] = field(default_factory=list)  # "seed 2001 (gears x0.8): joint 3 0.4163 -> 0.4170 deg"
    worst_rel: float = 0.0         # the largest relative change of a recorded number
    results_changed: list[str] = field(default_factory=list)
    rank: str = ""                 # moved: the pick against its runner-up on this code
    retune: bool = False           # the pick no longer holds its place (or no longer runs ok)
    now: list[dict[str, Any]] = field(default_factory=list)  # the recorded runs' results on this code
    bandwidth_now: float | None = None

    @property
    def pair(self) -> str:
        return f"{self.scenario}/{self.method}"

    @property
    def equal(self) -> bool:
        return not self.moved and not self.results_changed

    def as_dict(self) -> dict[str, Any]:
        return {"scenario": self.scenario, "method": self.method, "runs": self.runs, "equal": self.equal,
                "moved": self.moved, "worst_rel": self.worst_rel, "results_changed": self.results_changed,
                "rank": self.rank, "retune": self.retune}

    def line(self) -> str:
        if self.equal:
            return f"{self.pair}: {self.runs} runs, every number as recorded"
        what = "; ".join((self.results_changed + self.moved)[:4]) + (" ..." if len(self.moved) > 4 else "")
        return (f"{self.pair}: moved (largest change {100 * self.worst_rel:.3g} %): {what}; {self.rank}")


def _trial_of(rec: dict[str, Any], rnd: int, trial: int) -> dict[str, Any] | None:
    for r in rec.get("rounds") or []:
        for t in r.get("trials") or []:
            if t.get("round", r.get("round", 0)) == rnd and t.get("trial") == trial:
                return t
    return None


def recorded_runs(rec: dict[str, Any], tuning_seeds: list[int]) -> tuple[list[dict[str, Any]], list[int],
                                                                          list[dict[str, Any]]]:
    """The pick's recorded runs to run again: (variants, seeds, runs in variant-major order). Its
    validation runs when it was validated (the tried entry it was picked as, or, none robust, the
    one of the best by objective); else its own trial's runs on the tuning seeds."""
    val = rec.get("validation") or {}
    tried = val.get("tried") or []
    entry = None
    if val.get("picked_rank") is not None:
        entry = next((t for t in tried if t.get("rank") == val["picked_rank"]), None)
    else:
        best = rec.get("best_by_objective") or {}
        entry = next((t for t in tried if (t.get("round", 0), t.get("trial")) == (best.get("round", 0), best.get("trial"))),
                     None)
    if entry is not None and entry.get("runs"):
        variants = val.get("variants") or [{}]
        seeds = val.get("seeds") or []
        runs = entry["runs"]
        if len(runs) != len(variants) * len(seeds):
            raise VerifyError(f"{rec.get('scenario')}/{rec.get('method')}: the record's validation has {len(runs)} "
                              f"runs for {len(variants)} variant(s) x {len(seeds)} seed(s)")
        return variants, seeds, runs
    pick = _pick_trial(rec)
    if pick is None or not pick.get("runs"):
        raise VerifyError(f"{rec.get('scenario')}/{rec.get('method')}: the record keeps no runs of its pick "
                          "(tuned by an older armctl?): `armctl tune --retune` records them")
    return [{}], list(tuning_seeds), pick["runs"]


def _pick_trial(rec: dict[str, Any]) -> dict[str, Any] | None:
    """The pick's own trial record (its knobs, objective and tuning-seed runs)."""
    val = rec.get("validation") or {}
    if val.get("picked_rank") is not None:
        entry = next((t for t in val.get("tried") or [] if t.get("rank") == val["picked_rank"]), None)
        if entry is not None:
            return _trial_of(rec, entry.get("round", 0), entry["trial"])
    best = rec.get("best_by_objective")
    return best if isinstance(best, dict) else None


def runner_up(rec: dict[str, Any]) -> dict[str, Any] | None:
    """The trial the validation would have taken next after the pick: the next best by objective
    with other knobs that ran ok on every tuning seed (tuning.validate's ranking)."""
    pick = _pick_trial(rec)
    if pick is None:
        return None
    seen: set[str] = set()
    ranked = []
    for t in sorted((t for r in rec.get("rounds") or [] for t in r.get("trials") or []), key=lambda x: x["objective"]):
        k = json.dumps(t["knobs"], sort_keys=True)
        if t["objective"] < FAILED_SCORE and all(r.get("result") == "ok" for r in t.get("runs") or []) and k not in seen:
            seen.add(k)
            ranked.append(t)
    mine = json.dumps(pick["knobs"], sort_keys=True)
    after = [t for t in ranked if t["objective"] >= pick["objective"] and json.dumps(t["knobs"], sort_keys=True) != mine]
    return after[0] if after else None


def _rel(a: float, b: float) -> float:
    if a == b:
        return 0.0
    if not (math.isfinite(a) and math.isfinite(b)):
        return math.inf
    return abs(a - b) / max(abs(a), abs(b), 1e-300)


def compare(check: PairCheck, labels: list[str], recorded: list[dict[str, Any]], now: list[dict[str, Any]]) -> None:
    """The recorded runs against the same runs on this code, number for number."""
    for label, rec, run in zip(labels, recorded, now, strict=True):
        res = run.get("results") or {}
        if res.get("result") != rec.get("result"):
            why = (res.get("verdict_reasons") or [""])[0]
            check.results_changed.append(f"{label}: {rec.get('result')} -> {res.get('result')}"
                                         + (f" ({why})" if why and res.get("result") != "ok" else ""))
            check.worst_rel = math.inf if res.get("result") != "ok" else check.worst_rel
        a, b = rec.get("tracking_max_abs_deg") or [], res.get("tracking_max_abs_deg") or []
        if len(a) != len(b):
            check.moved.append(f"{label}: {len(a)} joints recorded, {len(b)} now")
            check.worst_rel = math.inf
            continue
        for j, (x, y) in enumerate(zip(a, b)):
            if x != y:
                d = _rel(float(x), float(y))
                check.worst_rel = max(check.worst_rel, d)
                sign = "+" if y > x else "-"
                check.moved.append(f"{label}: joint {j + 1} {x:.6g} -> {y:.6g} deg ({sign}{100 * d:.3g} %)")


def _labels(seeds: list[int], variants: list[dict[str, Any]]) -> list[str]:
    return [f"seed {s}" + ("" if not v else f" ({_variant_text(v)})") for v in variants for s in seeds]


def _specs(setup: TuneSetup, scenario: str, method: str, knobs: dict[str, Any], seeds: list[int],
           variants: list[dict[str, Any]], out: Path) -> list[RunSpec]:
    sc = setup.cfg.scenarios[scenario]
    specs = []
    for v in variants:
        tag = "" if not v else "-" + "-".join(f"{k}{x}" for k, x in sorted(v.items()))
        for s in seeds:
            specs.append(trial_spec(setup, method, sc, knobs, s, out / f"s{s}{tag}", setup.cfg.tuning_duration_s,
                                    setup.trajectory_args, keep_log=False, overrides=v))
    return specs


def rank_checks(setup: TuneSetup, moved: list[tuple[PairCheck, dict[str, Any]]], out: Path) -> None:
    """The pairs that moved: each pick and its recorded runner-up on the tuning seeds on this code
    (all side by side), and whether the pick still scores ahead (lower) and still runs as recorded."""
    seeds = setup.cfg.tuning_seeds
    plan = []
    specs: list[RunSpec] = []
    for check, rec in moved:
        pick, second = _pick_trial(rec), runner_up(rec)
        if pick is None:
            check.rank, check.retune = "the record names no pick trial: retune", True
            continue
        trials = [pick] + ([second] if second else [])
        plan.append((check, pick, second, len(specs)))
        for i, t in enumerate(trials):
            specs += _specs(setup, check.scenario, check.method, t["knobs"], seeds, [{}],
                            out / check.scenario / check.method / f"rank{i}")
    runs = run_all(specs, setup.jobs, setup.cluster, forked=True)
    if procs.interrupted is not None:
        raise procs.Interrupted(procs.interrupted)
    n = len(seeds)
    for check, pick, second, at in plan:
        mine = objective(runs[at:at + n])[0]
        a = f"the pick scores {pick['objective']:.6g} -> {mine:.6g} on the tuning seeds"
        check.retune = bool(check.results_changed)
        if second is None:
            check.rank = a + " (no runner-up recorded)" + (": its validation results changed: retune"
                                                            if check.retune else "")
            continue
        theirs = objective(runs[at + n:at + 2 * n])[0]
        b = (f"its runner-up (round {second.get('round', 0)} trial {second['trial']}) "
             f"{second['objective']:.6g} -> {theirs:.6g}")
        if mine <= theirs and not check.retune:
            check.rank = f"{a}, {b}: the pick still ranks ahead"
        else:
            check.retune = True
            check.rank = f"{a}, {b}: " + ("the runner-up now ranks ahead" if mine > theirs else
                                          "the pick's validation results changed") + ": retune"


def pair_digest(rec: dict[str, Any]) -> str:
    """What a verification of a pair depends on in its record: its key (arm, settings), its knobs
    and its recorded runs; a retuned pair is verified again."""
    val = rec.get("validation") or {}
    doc = {"key": rec.get("key"), "knobs": rec.get("knobs"), "objective": rec.get("objective"),
           "bandwidth_hz": rec.get("bandwidth_hz"), "tried": val.get("tried"), "variants": val.get("variants"),
           "seeds": val.get("seeds"), "rounds": [(t.get("trial"), t.get("objective")) for r in rec.get("rounds") or []
                                                for t in r.get("trials") or []]}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _design_and_bandwidth(setup: TuneSetup, method: str, knobs: dict[str, Any], spec: RunSpec | None,
                          n_joints: int) -> float | None:
    """In a worker: a design method's design as its runs load it (runner.sil_design: solved here
    once, on disk for the runs), then the pick's closed-loop bandwidth from the same solve."""
    if spec is not None and spec.design_text is not None:
        try:
            sil_design(spec.arm(), spec.design_text, n_joints)
        except BuildError:
            pass  # refused: candidate_check says so, and so do its runs
    return candidate_check(setup, method, knobs)[1]


def _run_side_by_side(setup: TuneSetup, first: list[tuple[Any, tuple[Any, ...]]], specs: list[RunSpec],
                      progress: Any) -> tuple[list[Any], list[dict[str, Any]]]:
    """`first` (function, arguments) jobs, then every spec's run, on setup.jobs forked workers:
    the designs are solved side by side while the gain methods' runs go on."""
    for arm in {s.arm() for s in specs}:
        prepare_build(arm)
    firsts: list[Any] = [None] * len(first)
    runs: list[dict[str, Any] | None] = [None] * len(specs)
    with ForkedWorkers(max(1, setup.jobs)) as workers:
        jf = {workers.submit(fn, *args): i for i, (fn, args) in enumerate(first)}
        order = sorted(range(len(specs)), key=lambda i: specs[i].design_text is not None)
        rf = {workers.submit(execute, asdict(specs[i]), 0.0): i for i in order}
        for fut in as_completed([*jf, *rf]):
            try:
                value = fut.result()
            except (BrokenProcessPool, CancelledError):  # a second signal killed the workers
                if procs.interrupted is None:
                    raise
                raise procs.Interrupted(procs.interrupted) from None
            if fut in jf:
                firsts[jf[fut]] = value
            else:
                runs[rf[fut]] = value
                if progress:
                    progress(specs[rf[fut]], value)
    if procs.interrupted is not None:
        raise procs.Interrupted(procs.interrupted)
    return firsts, [r for r in runs if r is not None]


def verify_pairs(setup: TuneSetup, recs: dict[tuple[str, str], dict[str, Any]], out: Path,
                 progress: Any = None) -> list[PairCheck]:
    """Every pair's pick's recorded runs again on this code, all side by side (forked workers on
    setup.jobs cores), compared number for number, with its closed-loop bandwidth; a pair that
    moved also gets its rank check."""
    plan = []
    specs: list[RunSpec] = []
    checks: list[PairCheck] = []
    first: list[tuple[Any, tuple[Any, ...]]] = []
    n_joints = 0
    for (s, m), rec in recs.items():
        variants, seeds, recorded = recorded_runs(rec, setup.cfg.tuning_seeds)
        check = PairCheck(s, m, runs=len(recorded))
        part = _specs(setup, s, m, rec["knobs"], seeds, variants, out / s / m)
        if not n_joints:
            n_joints = arm_info(prepare_build(part[0].arm()))["n_joints"]
        plan.append((check, rec, _labels(seeds, variants), recorded, len(specs), len(part), len(first)))
        first.append((_design_and_bandwidth, (setup, m, rec["knobs"], part[0], n_joints)))
        specs += part
        checks.append(check)
    bws, runs = _run_side_by_side(setup, first, specs, progress)
    for check, rec, labels, recorded, start, n, b in plan:
        want, bw = rec.get("bandwidth_hz"), bws[b]
        if want is not None and bw != want:
            check.worst_rel = _rel(float(want), float(bw)) if bw is not None else math.inf
            check.moved.append(f"closed-loop bandwidth {want:.6g} -> {'none' if bw is None else f'{bw:.6g}'} Hz")
        compare(check, labels, recorded, runs[start:start + n])
        check.now, check.bandwidth_now = [r.get("results") or {} for r in runs[start:start + n]], bw
    rank_checks(setup, [(check, rec) for check, rec, *_ in plan if not check.equal], out)
    return checks


# --- the verdicts of this code, kept in the build folder (never a tracked file) -------------------

def verdicts_path(code: str | None = None) -> Path:
    return build_dir("release") / VERDICTS / f"{code or code_identity()}.json"


def kept_verdicts(path: Path) -> dict[str, Any]:
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return doc if isinstance(doc, dict) else {}


def keep_verdicts(path: Path, tuning: Path, checks: list[PairCheck], digests: dict[str, str]) -> None:
    """This code's verdicts into its file (merged under a lock); other codes' files are removed:
    a verdict is of one code only."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with flocked(path.with_name(f".{path.name}.lock")):
        doc = kept_verdicts(path)
        for c in checks:
            doc[f"{tuning}::{c.pair}"] = {"digest": digests[c.pair], **c.as_dict()}
        write_json_atomic(path, doc)
    for other in path.parent.glob("*.json"):
        if other != path:
            other.unlink(missing_ok=True)


def stale_pairs(tuning: dict[str, dict[str, Any]], code: str) -> dict[tuple[str, str], dict[str, Any]]:
    """The kept pairs (of a study's tuning, {scenario: {method: record}}) not stamped with this code."""
    return {(s, m): rec for s, recs in tuning.items() for m, rec in recs.items() if rec.get("code") != code}


def verify_for_study(setup: TuneSetup, tuning_path: Path, recs: dict[tuple[str, str], dict[str, Any]],
                     prefix: str = "armctl study") -> list[PairCheck]:
    """A study's kept pairs made on other code: their verdicts on this code, from the build folder
    when this code found them already, else found now (one line says so). Returns every pair's
    check; the caller notes those that moved."""
    code = code_identity()
    path = verdicts_path(code)
    kept = kept_verdicts(path)
    digests = {f"{s}/{m}": pair_digest(rec) for (s, m), rec in recs.items()}
    checks: list[PairCheck] = []
    todo: dict[tuple[str, str], dict[str, Any]] = {}
    for (s, m), rec in recs.items():
        v = kept.get(f"{tuning_path}::{s}/{m}")
        if isinstance(v, dict) and v.get("digest") == digests[f"{s}/{m}"]:
            checks.append(PairCheck(s, m, runs=v.get("runs", 0), moved=list(v.get("moved") or []),
                                    worst_rel=float(v.get("worst_rel") or 0.0),
                                    results_changed=list(v.get("results_changed") or []), rank=v.get("rank", ""),
                                    retune=bool(v.get("retune"))))
        else:
            todo[(s, m)] = rec
    if todo:
        started = time.monotonic()
        out = path.parent / code
        found = verify_pairs(setup, todo, out)
        keep_verdicts(path, tuning_path, found, digests)
        shutil.rmtree(out, ignore_errors=True)
        checks += found
        n_runs = sum(c.runs for c in found)
        moved = [c for c in found if not c.equal]
        print(f"{prefix}: the kept tuning ({len(found)} pairs) was stamped with other code; verified on this code in "
              f"{time.monotonic() - started:.0f} s ({n_runs} runs): "
              + ("every number as recorded" if not moved else
                 f"{len(moved)} pair(s) moved: {', '.join(c.pair for c in moved)}")
              + f" (kept in {path.relative_to(path.parents[2]) if len(path.parents) > 2 else path})",
              file=sys.stderr)
    return checks


def moved_note(checks: list[PairCheck], tuning_path: Path) -> str | None:
    """The study's note on the pairs whose picks moved on this code, None when none did."""
    moved = [c for c in checks if not c.equal]
    if not moved:
        return None
    retune = [c.pair for c in moved if c.retune]
    return (f"the kept tuning ({tuning_path.name}) moved on this code in {len(moved)} pair(s): "
            + "; ".join(c.line() for c in moved)
            + (f"; `armctl tune --retune {' '.join(retune)}` tunes those again" if retune else
               "; every pick still ranks ahead of its runner-up (`armctl tune --verify` says so in full)"))


def _stamp_pairs(path: Path, checks: list[PairCheck], update: Any) -> list[str]:
    """Each pair for which `update(check, record, stamp)` returns True, stamped with this code's
    identity in the kept tuning file (under its lock, merged with what other commands kept
    meanwhile; `stamp` is the `verified` entry to extend). Returns those pairs."""
    code = code_identity()
    done = []
    when = datetime.now(timezone.utc).isoformat(timespec="seconds")
    with flocked(path.with_name(f".{path.name}.lock")):
        doc = _read_tuning(path)
        for c in checks:
            rec = (doc["scenarios"].get(c.scenario) or {}).get(c.method)
            stamp = {"code": code, "runs": c.runs, "when": when}
            if not isinstance(rec, dict) or not update(c, rec, stamp):
                continue
            rec.setdefault("tuned_code", rec.get("code"))
            rec["code"], rec["verified"] = code, stamp
            done.append(c.pair)
        if done:
            write_json_atomic(path, doc)
    return done


def accept_moved(path: Path, checks: list[PairCheck], tuning_seeds: list[int]) -> list[str]:
    """The pairs that moved but whose pick still ranks ahead of its runner-up on this code (and
    still runs as recorded): their recorded runs and bandwidth replaced by this code's, stamped
    with this code, the verification saying by how much they moved (`armctl tune --verify
    --accept-moved`). The tuning's history (its trials) stays the tuning code's. Returns those pairs."""
    def update(c: PairCheck, rec: dict[str, Any], stamp: dict[str, Any]) -> bool:
        if c.equal or c.retune or not c.now:
            return False
        _, _, recorded = recorded_runs(rec, tuning_seeds)
        if len(recorded) != len(c.now):
            raise VerifyError(f"{c.pair}: {len(recorded)} recorded runs, {len(c.now)} verified")
        for r, res in zip(recorded, c.now, strict=True):
            r["result"], r["tracking_max_abs_deg"] = res.get("result"), res.get("tracking_max_abs_deg")
        if rec.get("bandwidth_hz") is not None:
            rec["bandwidth_hz"] = c.bandwidth_now
        stamp["accepted_move"] = {"largest_change": c.worst_rel, "rank": c.rank}
        return True
    return _stamp_pairs(path, checks, update)


def restamp(path: Path, checks: list[PairCheck]) -> list[str]:
    """The pairs that verified equal and are stamped with other code, stamped with this code."""
    return _stamp_pairs(path, checks, lambda c, rec, stamp: c.equal and rec.get("code") != stamp["code"])
