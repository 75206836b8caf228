"""Method/scenario pairs of a tuning side by side, in worker processes.

A pair's trials are still asked and told in order, in batches of min([tuning] batch, --jobs), each
batch's runs on --jobs threads: a pair's tuning is the same whichever worker tunes it and whatever
runs beside it (lockstep runs do not depend on the machine's speed). What the workers add is the
cores a single pair leaves idle: between its batches a pair synthesises its next designs, asks
Optuna and analyses its runs, all Python, which one process runs on one core at a time.

Software in the loop only: its runs never poll, so more runs than cores only share them; lockstep
runs over a bus poll and slow each other down, and a Dask cluster has workers of its own.

The workers are forks of armctl (tools/run/workers.py: the solver and Optuna imported once), and
armctl's signals reach them as any child: each stops its runs in order.
"""

from __future__ import annotations

import multiprocessing
import signal
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from tools.run import procs
from tools.run.hil import SIL
from tools.run.workers import ForkedWorkers
from tools.study.tuning import TuneSetup, open_storage, tune_method

# What a worker inherits by fork: the setup, and a count of trials told by every worker.
_SETUP: TuneSetup | None = None
_TOLD: Any = None


def pair_workers(setup: TuneSetup, pairs: int) -> int:
    """How many pairs at once: one per --jobs, in software in the loop on this machine."""
    if setup.bus != SIL or setup.cluster is not None:
        return 1
    return max(1, min(setup.jobs, pairs))


def _told() -> None:
    with _TOLD.get_lock():
        _TOLD.value += 1


def _tune_pair(scenario: str, method: str, cap: int, key: str) -> dict[str, Any]:
    assert _SETUP is not None
    if procs.interrupted is not None:
        return {"interrupted": procs.interrupted}
    try:
        return tune_method(_SETUP, _SETUP.cfg.scenarios[scenario], method, cap, progress=_told, key=key)
    except procs.Interrupted as exc:  # not pickled as itself: its signal number travels as data
        return {"interrupted": exc.signum}


def tune_pairs(setup: TuneSetup, pairs: list[tuple[str, str, str]], cap: int,
               progress: Callable[[], None]) -> Iterator[tuple[str, str, str, dict[str, Any]]]:
    """(scenario, method, key, record) of each (scenario, method, key) pair as it is tuned;
    progress() once per trial told. A signal stops every pair: procs.Interrupted once the pairs
    tuned by then have been yielded."""
    workers = pair_workers(setup, len(pairs))
    if workers <= 1:
        for s, m, key in pairs:
            yield s, m, key, tune_method(setup, setup.cfg.scenarios[s], m, cap, progress=progress, key=key)
        return
    global _SETUP, _TOLD
    import gen.synth.pipeline  # noqa: F401  (cvxpy: imported once, before the forks)

    open_storage(setup.out).engine.dispose()  # the tables made once: two workers would race to make them
    _SETUP, _TOLD = setup, multiprocessing.get_context("fork").Value("q", 0)
    shown = 0
    stopped: int | None = None
    with ForkedWorkers(workers) as pool:
        futs = {pool.submit(_tune_pair, s, m, cap, key): (s, m, key) for s, m, key in pairs}
        pending = set(futs)
        while pending:
            done, pending = wait(pending, timeout=0.25, return_when=FIRST_COMPLETED)
            if procs.interrupted is not None:  # the pairs not begun are not begun
                for f in pending:
                    f.cancel()
            for _ in range(_TOLD.value - shown):
                progress()
            shown = _TOLD.value
            for f in done:
                if f.cancelled():
                    continue
                try:
                    rec = f.result()
                except BrokenProcessPool:  # a worker killed (a second signal)
                    stopped = stopped or procs.interrupted or signal.SIGKILL
                    continue
                if "interrupted" in rec:
                    stopped = stopped or rec["interrupted"]
                else:
                    yield (*futs[f], rec)
    if stopped is not None or procs.interrupted is not None:
        raise procs.Interrupted(procs.interrupted or stopped or signal.SIGTERM)
