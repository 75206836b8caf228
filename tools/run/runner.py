"""Many HIL runs: in parallel on this machine (--jobs), or as tasks on a Dask cluster (--cluster).

A run is a RunSpec: everything that decides its result (the arm, the design when it is not the
arm's own, the method and its arguments, the scenario, the seed). The same spec gives the same
run.json in lockstep, whichever worker runs it and whatever else runs beside it: each run holds a
run slot (tools/run/slots.py) for its own bus and telemetry ports, and a design other than the arm's
is built in a build folder of that slot, except in software in the loop: there it is synthesised
in this process (once per design, in a folder under build/sil-designs) and the arm's own arm_sil
loads it at run time (--design-file), so a tuning builds no firmware per design.

A finished run's folder holds its run.json and, written last, spec.json: the spec and the
checksum of that run.json. A resumed study reuses it only when both are there, the spec is this
one, the checksum holds, run.json itself says it ran this spec (method, seed, scenario, arm, ...)
and its metrics are numbers; anything else is run again, and the log says why. A run that armctl
stopped (a signal) gets no spec.json, so it is never taken for done.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import threading
import warnings
from collections import OrderedDict
from collections.abc import Callable
from concurrent.futures import CancelledError, ThreadPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from host_sim.drive_model import DriveModel
from tools.run import procs
from tools.build.arm import HIL_TARGETS, ArmChoiceError, targets_for, ArmRef, arm_build_dir, arm_info, build_arm
from tools.build import BuildError, build_lock
from gen.lib.locks import flocked
from tools.run.cluster import Cluster
from gen.lib.paths import BUILD
from gen.lib.atomic_output import write_json_atomic, write_text_atomic
from tools.run.hil import DEFAULT_PROTOCOL, LOCKSTEP_SPIN_US, SIL, HilError, HilOptions, lockstep_spin_us, provenance, run_hil
from tools.run.run_files import RUN_RECORD, TELEMETRY_LOG
from tools.run.slots import Slot, acquire_slot
from tools.run.workers import ForkedWorkers

# metric -> the run.json results field a study computes with (per joint, or one number for the arm)
METRICS = {"linf": "tracking_max_abs_rad", "rms": "tracking_rms_rad", "est": "estimation_error_rms",
           "power": "torque_power_w"}
DONE = "spec.json"  # written last in a run's folder: the run is done
SIL_DESIGNS = BUILD / "sil-designs"  # designs synthesised in-process for software-in-the-loop runs
# One synthesis at a time in this process: runs execute in threads, and cvxpy (its expression ids
# and canonicalisation caches) and warnings.catch_warnings are not thread-safe.
SYNTH_LOCK = threading.Lock()
_DESIGNS: OrderedDict[str, Any] = OrderedDict()  # the last designs synthesised, by their expanded inputs
_KEEP_DESIGNS = 16

UNKEYED_PROTOCOL = "arm"  # RunSpec.key leaves it out: runs kept before --protocol existed spoke it


def synthesize_cached(cfg: Any) -> Any:
    """gen.synth's synthesize(cfg), remembering the last few designs: a tuning checks a trial's
    design (tools/study/tuning.py synthesized) and then its software-in-the-loop runs emit the same one,
    so it is solved once. The key is the config's fully expanded inputs (what the manifest records
    and hashes), so equal keys are the same design. Call with SYNTH_LOCK held."""
    from gen.synth.pipeline import synthesize

    key = json.dumps(cfg.to_json(), sort_keys=True)
    if key in _DESIGNS:
        _DESIGNS.move_to_end(key)
        return _DESIGNS[key]
    design = synthesize(cfg)
    _DESIGNS[key] = design
    while len(_DESIGNS) > _KEEP_DESIGNS:
        _DESIGNS.popitem(last=False)
    return design


@dataclass(frozen=True)
class RunSpec:
    out: str
    method: str                        # the firmware's --method
    duration_s: float
    controller_args: tuple[str, ...]   # gains, trajectory, hold
    uncertainty: dict[str, Any]
    drives: dict[str, Any] = field(default_factory=dict)
    bus_timing: bool = False
    model: str | None = None           # the arm (tools/build/arm.py ArmRef), as paths
    arm_file: str | None = None
    design: str | None = None          # the arm's design config, or None
    design_text: str | None = None     # a design built for this run alone (tuning, tuned designs)
    keep_log: bool = True              # tuning runs drop their telemetry log once analysed
    labels: dict[str, Any] = field(default_factory=dict)
    code: str = ""                     # tools/build/code_identity.py: a kept run of other code is run again
    bus: str = "udp"                   # tools/run/hil.py's --bus: sil (one process) or a CAN bus
    protocol: str = DEFAULT_PROTOCOL   # what the drives speak (tools/run/hil.py PROTOCOLS)
    # design_text loaded at run time over a bus too (--design-file), not built into a run slot: a
    # study's confirmation then runs the very file its software-in-the-loop run ran, so what it
    # compares is the bus alone (tests/python/test_design_file.py: loaded and built give the same)
    design_loaded: bool = False

    def key(self) -> dict[str, Any]:
        """What decides the result (not where it is written, nor the bus it ran on: software in the
        loop and lockstep HIL give the same results, tests/python/test_sil.py). The arm protocol,
        the only one before the protocol was a choice, is left out, so the keys of runs kept then
        still match."""
        d = asdict(self)
        for k in ("out", "keep_log", "labels", "bus", "design_loaded"):
            d.pop(k)
        if d["protocol"] == UNKEYED_PROTOCOL:
            d.pop("protocol")
        return d

    def arm(self) -> ArmRef:
        return ArmRef(Path(self.model) if self.model else None, Path(self.arm_file) if self.arm_file else None,
                      Path(self.design) if self.design else None)


def spec_from_dict(d: dict[str, Any]) -> RunSpec:
    return RunSpec(**{**d, "controller_args": tuple(d["controller_args"])})


def _slot_design_path(base: ArmRef, slot: int) -> Path:
    arm_key = base.key() if not base.is_default else "default"
    return BUILD / "slot-designs" / arm_key / f"slot-{slot}.toml"


def slot_has_design(base: ArmRef, slot: int, design_text: str) -> bool:
    """Slot `slot`'s build folder was last built with this design (a run there rebuilds nothing)."""
    try:
        return _slot_design_path(base, slot).read_text() == design_text
    except OSError:
        return False


def kept_design_copy(base: ArmRef, design_text: str) -> Path:
    """A copy of the design a slot build ran, named by its content and never rewritten: what the
    run records as its design. The slot's own file holds whichever design that slot built last,
    and which slot a run gets depends on what else runs beside it."""
    digest = hashlib.sha256(design_text.encode()).hexdigest()[:16]
    path = _slot_design_path(base, 0).parent / "by-content" / f"{digest}.toml"
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(path, design_text)
    return path


def slot_arm(base: ArmRef, slot: int, design_text: str) -> ArmRef:
    """The arm with this design, in the slot's own build folder: one design file per slot and
    arm, rewritten only when the design changes, so a slot rebuilds only what a new design
    changes (the synthesis and the controller, about 2 s)."""
    path = _slot_design_path(base, slot)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text() != design_text:
        write_text_atomic(path, design_text)
    return ArmRef(base.model, base.arm_file, path)


def sil_design(base: ArmRef, design_text: str, n_joints: int) -> Path:
    """The folder holding this design synthesised for the arm (gen.synth's pm_design.txt and
    manifest.json, from the design.toml a slot build would synthesise: the same design hash),
    made once per design text, arm and synthesis code: the seeds of a trial share it. A design the synthesis
    refuses raises BuildError, as its slot build would."""
    from gen.arm import design_for
    from gen.synth.manifest import DESIGN_FILE
    from tools.build.code_identity import synthesis_identity

    # the synthesis's code in the key: a design text made into a design by other code is made again
    digest = hashlib.sha256(f"{design_text}\0{synthesis_identity()}".encode()).hexdigest()[:16]
    folder = SIL_DESIGNS / (base.key() if not base.is_default else "default") / digest
    config = folder / "design.toml"
    text = design_for(design_text, n_joints, config)
    with SYNTH_LOCK, flocked(folder.with_name(f"{digest}.lock")):  # and armctl processes sharing build/
        try:
            if config.read_text() == text and (folder / DESIGN_FILE).exists() and (folder / "manifest.json").exists():
                return folder
        except OSError:
            pass
        # the solver's imports only when it must solve (cvxpy: 2-4 s of a worker's first run)
        from gen.synth.cli import synth_to_dir
        from gen.synth.config import ConfigError
        from gen.synth.lmi import SynthesisError

        write_text_atomic(config, text)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                synth_to_dir(config, folder, synthesize_cached)
        except (ConfigError, SynthesisError, ValueError, ArithmeticError) as exc:
            raise BuildError(f"armctl: synthesis of {config} refused it: {str(exc).splitlines()[0][:300]}") from None
    return folder


_BUILT: dict[ArmRef, Path] = {}
_BUILT_LOCK = threading.Lock()


def prepare_build(arm: ArmRef) -> Path:
    """The arm's release build, brought up to date once per process: every run of a tuning or a
    study then runs the same binaries (a source edited meanwhile is the next command's), and a
    run does not pay ninja's check of the whole tree (35 ms, a quarter of a 4 s SIL run)."""
    with _BUILT_LOCK:
        if arm not in _BUILT:
            _BUILT[arm] = build_arm("release", arm, targets=HIL_TARGETS)
        return _BUILT[arm]


def _json(x: Any) -> Any:
    return json.loads(json.dumps(x))  # as JSON keeps it: tuples are lists


def _number_or_numbers(v: Any) -> bool:
    def num(x: Any) -> bool:
        return isinstance(x, (int, float)) and not isinstance(x, bool)
    return v is None or num(v) or (isinstance(v, list) and all(num(x) for x in v))


def _identity(spec: RunSpec) -> dict[str, Any]:
    """What a run.json's results record of the spec they ran (tools/run/hil.py: its config, labels)."""
    drives = (DriveModel(**spec.drives) if spec.drives else DriveModel()).to_dict()
    return {"method": spec.method, "duration_s": spec.duration_s, "controller_args": list(spec.controller_args),
            "uncertainty": spec.uncertainty, "drives": drives, **spec.labels}


def _disagreement(spec: RunSpec, res: dict[str, Any]) -> list[str]:
    """The fields where a run.json's own record of what ran differs from the spec."""
    bad = [k for k, v in _identity(spec).items() if _json(res.get(k)) != _json(v)]
    if (res.get("bus_timing", "off") != "off") != spec.bus_timing:
        bad.append("bus_timing")
    return bad


def _arm_hash(spec: RunSpec) -> str | None:
    """The model hash of the spec's arm as built now (building it when it is not)."""
    arm = spec.arm()
    try:
        return arm_info(arm_build_dir("release", arm))["model_hash"]
    except ArmChoiceError:
        prepare_build(arm)
        return arm_info(arm_build_dir("release", arm))["model_hash"]


def kept_run(out: Path, spec: RunSpec) -> tuple[dict[str, Any] | None, str]:
    """(run.json, "") when `out` holds this spec's finished run, unchanged; else (None, why it is
    run again; "" when there is nothing there)."""
    if not out.exists():
        return None, ""
    try:
        done = json.loads((out / DONE).read_text())
    except FileNotFoundError:
        return None, f"no {DONE}: the run did not finish (interrupted or killed)"
    except (OSError, ValueError) as exc:
        return None, f"{DONE} unreadable ({exc})"
    if not isinstance(done, dict) or not isinstance(done.get("spec"), dict) or "run_json_sha256" not in done:
        return None, f"{DONE} has no checksum of run.json (written by an older armctl)"
    want = _json(spec.key())
    if done["spec"] != want:
        diff = sorted(k for k in set(want) | set(done["spec"]) if done["spec"].get(k) != want.get(k))
        return None, f"kept for another spec (differs in {', '.join(diff)})"
    try:
        raw = (out / RUN_RECORD).read_bytes()
        res = json.loads(raw)["results"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        return None, f"run.json missing or unreadable ({exc})"
    if not isinstance(res, dict):
        return None, "run.json has no results"
    if bad := _disagreement(spec, res):
        return None, f"run.json was not made by this spec (its {', '.join(bad)} differ)"
    if hashlib.sha256(raw).hexdigest() != done["run_json_sha256"]:
        return None, "run.json was changed after the run (its checksum in spec.json does not match)"
    if res.get("result") in (None, "interrupted"):
        return None, f"the run ended {res.get('result') or 'without a verdict'}"
    if bad := [f for f in METRICS.values() if not _number_or_numbers(res.get(f))]:
        return None, f"run.json: {', '.join(bad)} not numbers"
    arm = res.get("arm")
    if isinstance(arm, dict) and arm.get("model_hash") != _arm_hash(spec):
        return None, "run.json is of another build of the arm (its model hash differs)"
    return json.loads(raw), ""


def execute(spec_d: dict[str, Any], spin_us: float = LOCKSTEP_SPIN_US) -> dict[str, Any]:
    """One run (in this process: a thread of `armctl study`, or a Dask worker). Returns run.json.
    spin_us: a lockstep run's polling (tools/run/hil.py lockstep_spin_us), which never changes a result."""
    spec = spec_from_dict(spec_d)
    out = Path(spec.out)
    key = spec.key()
    kept, why = kept_run(out, spec)
    if kept is not None:
        return kept
    if procs.interrupted is not None:  # armctl is stopping: not run (a resumed study runs it)
        return _not_run(procs.interrupted)
    if why:
        print(f"armctl: {out}: running it again: {why}", file=sys.stderr)
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    slot_build = spec.design_text is not None and spec.bus != SIL and not spec.design_loaded
    prefer = (lambda i: slot_has_design(spec.arm(), i, spec.design_text)) if slot_build else None
    with acquire_slot(prefer=prefer, quiet_ports=spec.bus != SIL) as slot:
        arm = spec.arm()
        try:
            if spec.design_text is not None and not slot_build:
                # the arm's own build loads the design at run time (software in the loop, design_loaded)
                bdir = prepare_build(arm)
                design = sil_design(arm, spec.design_text, arm_info(bdir)["n_joints"])
                run = _run(spec, arm, slot, out, spin_us, design)
            elif spec.design_text is not None:
                record = {"config": str(kept_design_copy(arm, spec.design_text)),
                          "why": "a design of its own, built into a run slot's folder"}
                arm = slot_arm(arm, slot.index, spec.design_text)
                # held through the run: its binaries are this build's (a checkout shared between
                # hosts has slot i of each host in the same folder)
                with build_lock(arm_build_dir("release", arm)):
                    build_arm("release", arm, targets=targets_for(spec.bus))
                    run = _run(spec, arm, slot, out, spin_us, record=record)
            else:
                prepare_build(arm)  # a no-op when built (a Dask worker on another machine may not be)
                run = _run(spec, arm, slot, out, spin_us)
        except HilError as exc:
            write_json_atomic(out / RUN_RECORD, {"results": {**_identity(spec), "bus_timing": "on" if spec.bus_timing
                                                             else "off", "result": "failed",
                                                             "verdict_reasons": [f"failed: {exc}"]},
                                                 "transport": {}, "environment": {}, "provenance": provenance()})
    if not spec.keep_log:
        (out / TELEMETRY_LOG).unlink(missing_ok=True)
    raw = (out / RUN_RECORD).read_bytes()
    if procs.interrupted is None:  # a run armctl stopped is not done: a resumed study runs it again
        write_json_atomic(out / DONE, {"spec": key, "run_json_sha256": hashlib.sha256(raw).hexdigest()})
    return json.loads(raw)  # what a resumed study reads back, exactly


def _not_run(signum: int) -> dict[str, Any]:
    """What a run armctl was stopped before (or, its worker killed, while) running returns."""
    return {"results": {"result": "interrupted", "verdict_reasons": [f"interrupted: signal {signum}"]},
            "transport": {}, "environment": {}}


def _run(spec: RunSpec, arm: ArmRef, slot: Slot, out: Path, spin_us: float,
         design: Path | None = None, record: dict[str, Any] | None = None) -> dict[str, Any]:
    """design: a sil_design folder, loaded at run time (else the build's own design); record:
    what run.json says of the build's own design (else the build's record)."""
    from gen.synth.manifest import DESIGN_FILE

    loaded = {"design_record": record} if design is None else {
        "design_file": design / DESIGN_FILE,
        "design_record": {"config": str(design / "design.toml"), "why": "loaded at run time (--design-file)"}}
    return run_hil(HilOptions(out=out, duration_s=spec.duration_s, method=spec.method, arm=arm,
                              controller_args=spec.controller_args, uncertainty=spec.uncertainty,
                              drives=DriveModel(**spec.drives) if spec.drives else DriveModel(),
                              bus_timing=spec.bus_timing, can_port=slot.can_port, lcm_port=slot.lcm_port,
                              labels=dict(spec.labels), bus=spec.bus, protocol=spec.protocol,
                              # the runs that keep their telemetry keep their bus too (gzip: 0.6 MB a 10 s run)
                              capture=spec.keep_log, compress_capture=True, spin_us=spin_us,
                              # the study's runs start with the arm held by its drives, as recorded
                              brakes="released", **loaded))


def spec_digest(spec: RunSpec) -> str:
    return hashlib.sha256(json.dumps(spec.key(), sort_keys=True).encode()).hexdigest()[:12]


def _design_lanes(specs: list[RunSpec], jobs: int) -> list[int]:
    """The order to hand runs to `jobs` workers so that each works through designs of its own: the
    runs of one design go to one lane, lanes take turns. A worker then finds its design built in the
    slot it just left (acquire_slot's preference), instead of every worker building every design."""
    groups: dict[str | None, list[int]] = {}
    for i, s in enumerate(specs):
        groups.setdefault(s.design_text, []).append(i)
    lanes: list[list[int]] = [[] for _ in range(max(1, jobs))]
    for idx in groups.values():
        min(lanes, key=len).extend(idx)
    order: list[int] = []
    for k in range(max(map(len, lanes))):
        order += [lane[k] for lane in lanes if k < len(lane)]
    return order


def run_all(specs: list[RunSpec], jobs: int = 1, cluster: Cluster | None = None,
            progress: Callable[[RunSpec, dict[str, Any]], None] | None = None,
            forked: bool = False) -> list[dict[str, Any]]:
    """Every spec's run.json, in the specs' order. Local: `jobs` threads, each run in a run slot.
    forked: software-in-the-loop runs in `jobs` forked worker processes instead (tools/run/workers.py):
    a run's own Python (its start, the analysis of its log) then runs on every core, which a study's
    long list of runs gains from (1.7x -> 1.9x at --jobs 2 here); a tuning's batches of eight
    would pay the forks each time, and keep the threads.
    cluster: a Dask scheduler (tools/run/cluster.py); each run is one task on a worker (the workers see this
    checkout at the same path, and the out folders on a shared file system)."""
    if not specs:
        return []
    # The arms' own builds first, once each (a design of a run's own is built in its slot, except
    # in software in the loop, which runs it on the arm's own build).
    for arm in {s.arm() for s in specs if s.design_text is None or s.bus == SIL or s.design_loaded}:
        prepare_build(arm)
    results: list[dict[str, Any] | None] = [None] * len(specs)
    if cluster is not None:
        from distributed import Client, as_completed as dask_completed

        with Client(cluster.address, security=cluster.security()) as client:
            futures = {client.submit(execute, asdict(s), pure=False, key=f"hil-{spec_digest(s)}-{i}"): i
                       for i, s in enumerate(specs)}
            for fut in dask_completed(futures):
                i = futures[fut]
                results[i] = fut.result()
                if progress:
                    progress(specs[i], results[i])
    elif forked and jobs > 1 and all(s.bus == SIL for s in specs):
        with ForkedWorkers(jobs) as workers:
            futs = {workers.submit(execute, asdict(s), 0.0): i for i, s in enumerate(specs)}
            for fut in as_completed(futs):
                i = futs[fut]
                try:
                    results[i] = fut.result()
                except (BrokenProcessPool, CancelledError):  # a second signal killed the workers
                    if procs.interrupted is None:
                        raise
                    results[i] = _not_run(procs.interrupted)
                if progress:
                    progress(specs[i], results[i])
    else:
        with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
            spin = lockstep_spin_us(jobs)
            futs = {pool.submit(execute, asdict(specs[i]), spin): i for i in _design_lanes(specs, jobs)}
            for fut in as_completed(futs):
                i = futs[fut]
                results[i] = fut.result()
                if progress:
                    progress(specs[i], results[i])
    return [r for r in results if r is not None]
