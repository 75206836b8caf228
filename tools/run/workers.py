"""Worker processes of armctl's own, forked, that its signals reach as they reach any child.

Python runs one thread at a time in a process: runs or tuning pairs whose own Python (starting a
run, analysing its log, a synthesis, Optuna) is a good part of their cost scale with the cores
only in processes of their own. The workers are forks (what armctl imported, they have), each in
a process group of its own (a Ctrl-C reaches armctl alone); armctl passes a signal on to them
(tools/run/procs.py adopt), each stops its own runs in order, and a worker whose armctl died gets
a SIGTERM. Leaving the block by an exception cancels what has not begun and stops the workers.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from types import TracebackType
from typing import Any

from tools.run import procs


class ForkedWorkers:
    def __init__(self, n: int) -> None:
        # fork: a forkserver or spawn would import the caller's __main__ again
        self._pool = ProcessPoolExecutor(max_workers=n, mp_context=multiprocessing.get_context("fork"),
                                         initializer=procs.as_child_of, initargs=(os.getpid(),))
        self._adopted: dict[int, Any] = {}
        self._futures: list[Future[Any]] = []

    def submit(self, fn: Callable[..., Any], *args: Any) -> Future[Any]:
        f = self._pool.submit(fn, *args)
        self._futures.append(f)
        # a fork pool forks every worker at its first submit; _processes is its only list of them
        for pid in list(self._pool._processes):
            if pid not in self._adopted:
                self._adopted[pid] = procs.adopt("worker", pid)
        return f

    def __enter__(self) -> ForkedWorkers:
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        if kind is not None:
            for f in self._futures:
                f.cancel()
            for w in self._adopted.values():
                w.send_signal(signal.SIGTERM)
        try:
            self._pool.shutdown(wait=True)
        finally:
            for w in self._adopted.values():
                procs.forget(w)
