"""Many HIL runs: in parallel on this machine (--jobs), or as tasks on a Dask cluster (--cluster).

A run is a RunSpec: everything that decides its result (the arm, the design when it is not the
arm's own, the method and its arguments, the scenario, the seed). The same spec gives the same
run.json in lockstep, whichever worker runs it and whatever else runs beside it: each run holds a
run slot (tools/slots.py) for its own bus and telemetry ports, and a design other than the arm's
is built in a build folder of that slot. A run whose folder already holds its spec and its
run.json is not run again: an interrupted study resumes where it stopped.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import shutil
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from host_sim.drive_model import DriveModel
from tools import procs
from tools.arm import HIL_TARGETS, ArmRef, arm_build_dir, build_arm
from tools.paths import BUILD
from tools.hil import HilError, HilOptions, provenance, run_hil, write_json_atomic
from tools.slots import Slot, acquire_slot


@dataclass(frozen=True)
class RunSpec:
    out: str
    method: str                        # the firmware's --method
    duration_s: float
    controller_args: tuple[str, ...]   # gains, trajectory, hold
    uncertainty: dict[str, Any]
    drives: dict[str, Any] = field(default_factory=dict)
    bus_timing: bool = False
    model: str | None = None           # the arm (tools/arm.py ArmRef), as paths
    arm_file: str | None = None
    design: str | None = None          # the arm's design config, or None
    design_text: str | None = None     # a design built for this run alone (tuning, tuned designs)
    keep_log: bool = True              # tuning runs drop their telemetry log once analysed
    labels: dict[str, Any] = field(default_factory=dict)
    code: str = ""                     # tools/code_identity.py: a kept run of other code is run again

    def key(self) -> dict[str, Any]:
        """What decides the result (not where it is written)."""
        d = asdict(self)
        for k in ("out", "keep_log", "labels"):
            d.pop(k)
        return d

    def arm(self) -> ArmRef:
        return ArmRef(Path(self.model) if self.model else None, Path(self.arm_file) if self.arm_file else None,
                      Path(self.design) if self.design else None)


def spec_from_dict(d: dict[str, Any]) -> RunSpec:
    return RunSpec(**{**d, "controller_args": tuple(d["controller_args"])})


@contextmanager
def _dir_lock(path: Path) -> Iterator[None]:
    """One builder per build folder (two ninjas in one folder corrupt it)."""
    path.mkdir(parents=True, exist_ok=True)
    fd = os.open(path / ".armctl-build.lock", os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)


def slot_arm(base: ArmRef, slot: int, design_text: str) -> ArmRef:
    """The arm with this design, in the slot's own build folder: one design file per slot and
    arm, rewritten only when the design changes, so a slot rebuilds only what a new design
    changes (the synthesis and the controller, about 2 s)."""
    arm_key = base.key() if not base.is_default else "default"
    path = BUILD / "slot-designs" / arm_key / f"slot-{slot}.toml"
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text() != design_text:
        tmp = path.with_name(f".{path.name}.tmp.{os.getpid()}")
        tmp.write_text(design_text)
        os.replace(tmp, path)
    return ArmRef(base.model, base.arm_file, path)


def prepare_build(arm: ArmRef) -> Path:
    bdir = arm_build_dir("release", arm)
    with _dir_lock(bdir):
        build_arm("release", arm, targets=HIL_TARGETS)
    return bdir


def _cached(out: Path, key: dict[str, Any]) -> dict[str, Any] | None:
    try:
        if json.loads((out / "spec.json").read_text()) == json.loads(json.dumps(key)):  # tuples are lists in JSON
            run = json.loads((out / "run.json").read_text())
            if run.get("results", {}).get("result") is not None:
                return run
    except (OSError, ValueError):
        pass
    return None


def execute(spec_d: dict[str, Any]) -> dict[str, Any]:
    """One run (in this process: a thread of `armctl study`, or a Dask worker). Returns run.json."""
    spec = spec_from_dict(spec_d)
    out = Path(spec.out)
    key = spec.key()
    cached = _cached(out, key)
    if cached is not None:
        return cached
    if procs.interrupted is not None:  # armctl is stopping: not run (a resumed study runs it)
        return {"results": {"result": "interrupted", "verdict_reasons": [f"interrupted: signal {procs.interrupted}"]},
                "transport": {}, "environment": {}}
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    with acquire_slot() as slot:
        arm = spec.arm()
        try:
            if spec.design_text is not None:
                arm = slot_arm(arm, slot.index, spec.design_text)
                with _dir_lock(arm_build_dir("release", arm)):
                    build_arm("release", arm, targets=HIL_TARGETS)
                    run = _run(spec, arm, slot, out)
            else:
                prepare_build(arm)  # a no-op when built (a Dask worker on another machine may not be)
                run = _run(spec, arm, slot, out)
        except HilError as exc:
            write_json_atomic(out / "run.json", {"results": {"result": "failed", "verdict_reasons": [f"failed: {exc}"]},
                                                 "transport": {}, "environment": {}, "provenance": provenance()})
    if not spec.keep_log:
        (out / "telemetry.lcmlog").unlink(missing_ok=True)
    write_json_atomic(out / "spec.json", key)  # last: a spec beside a run.json marks the run done
    return json.loads((out / "run.json").read_text())  # what a resumed study reads back, exactly


def _run(spec: RunSpec, arm: ArmRef, slot: Slot, out: Path) -> dict[str, Any]:
    return run_hil(HilOptions(out=out, duration_s=spec.duration_s, method=spec.method, arm=arm,
                              controller_args=spec.controller_args, uncertainty=spec.uncertainty,
                              drives=DriveModel(**spec.drives) if spec.drives else DriveModel(),
                              bus_timing=spec.bus_timing, can_port=slot.can_port, lcm_port=slot.lcm_port,
                              labels=dict(spec.labels)))


def spec_digest(spec: RunSpec) -> str:
    return hashlib.sha256(json.dumps(spec.key(), sort_keys=True).encode()).hexdigest()[:12]


def run_all(specs: list[RunSpec], jobs: int = 1, cluster: str | None = None,
            progress: Callable[[RunSpec, dict[str, Any]], None] | None = None) -> list[dict[str, Any]]:
    """Every spec's run.json, in the specs' order. Local: `jobs` threads, each run in a run slot.
    cluster: a Dask scheduler's address; each run is one task on a worker (the workers see this
    checkout at the same path, and the out folders on a shared file system)."""
    if not specs:
        return []
    # The arms' own builds first, once each (a design of a run's own is built in its slot).
    for arm in {s.arm() for s in specs if s.design_text is None}:
        prepare_build(arm)
    results: list[dict[str, Any] | None] = [None] * len(specs)
    if cluster is not None:
        from distributed import Client, as_completed as dask_completed

        with Client(cluster) as client:
            futures = {client.submit(execute, asdict(s), pure=False, key=f"hil-{spec_digest(s)}-{i}"): i
                       for i, s in enumerate(specs)}
            for fut in dask_completed(futures):
                i = futures[fut]
                results[i] = fut.result()
                if progress:
                    progress(specs[i], results[i])
    else:
        with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
            futs = {pool.submit(execute, asdict(s)): i for i, s in enumerate(specs)}
            for fut in as_completed(futs):
                i = futs[fut]
                results[i] = fut.result()
                if progress:
                    progress(specs[i], results[i])
    return [r for r in results if r is not None]
