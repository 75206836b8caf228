"""The processes armctl starts, and what a signal to armctl does to them.

Every child runs in a process group of its own, so a Ctrl-C at the terminal reaches armctl alone,
and armctl stops the children in order: the controller first (SIGTERM: it ends the period, sends
zero torque with controlword shutdown and NMT stop, and writes its summary), then the simulator
(which stops on that NMT stop) and the telemetry logger (which writes what it has queued). The
run then ends as always, with a run.json whose verdict is `interrupted`; nothing is left running.
A second signal kills what is still alive.

A SIGKILL of armctl cannot be caught, so each child also asks the kernel for a SIGTERM when
armctl goes (PR_SET_PDEATHSIG): the controller then stops the arm as above and the others
follow. That takes them a while (the controller's safe stop), so each child also holds the run
slot's lock (its file descriptor, inherited: tools/run/slots.py): the slot is free again only when
the last process of the run on it has ended, never while one still uses its ports.
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
from typing import Any

from gen.lib.parent_death import dies_with_parent

_live: list[tuple[str, subprocess.Popen[Any]]] = []
# Re-entrant: the signal handlers below take it in the thread they interrupt, which may hold it
# (a worker stopped inside spawn() or forget() waited for itself forever)
_lock = threading.RLock()
_held = threading.local()  # .fds: the run slot locks this thread holds (hold_for_children)
interrupted: int | None = None  # the signal that stopped this armctl, if one did


PARENT_PID_ENV = "ARM_PARENT_PID"  # firmware/port/linux/stop_signals.h ARM_PARENT_PID_ENV


def spawn(role: str, args: list[str], watches_parent: bool = False, **kw: Any) -> subprocess.Popen[Any]:
    """Popen in a process group of its own, known to the signal handler until it has exited.
    role: "controller", "simulator" or "logger". watches_parent: the program asks for its SIGTERM
    itself (PARENT_PID_ENV: arm_controller, arm_sim, arm_sil), so no Python runs between fork and
    exec and subprocess can vfork (a fork of armctl, with the solver loaded, cost 20 ms a run)."""
    if interrupted is not None:
        raise InterruptedError(f"armctl was stopped by signal {interrupted}: not starting the {role}")
    kw.setdefault("process_group", 0)
    kw["pass_fds"] = (*kw.get("pass_fds", ()), *getattr(_held, "fds", ()))
    if watches_parent and kw.get("preexec_fn") is None:
        kw.pop("preexec_fn", None)
        kw["env"] = {**(kw.get("env") or os.environ), PARENT_PID_ENV: str(os.getpid())}
    else:
        kw["preexec_fn"] = dies_with_parent(os.getpid(), kw.get("preexec_fn"))
    p = subprocess.Popen(args, **kw)
    with _lock:
        _live.append((role, p))
    return p


def hold_for_children(fd: int) -> None:
    """Every child this thread spawns from now on holds fd (a run slot's lock) until it exits."""
    os.set_inheritable(fd, True)
    _held.fds = (*getattr(_held, "fds", ()), fd)


def release_for_children(fd: int) -> None:
    _held.fds = tuple(x for x in getattr(_held, "fds", ()) if x != fd)


class _Process:
    """A process of armctl's own (a multiprocessing worker), signalled as a child is. Its pool
    reaps it: poll() only asks whether it is there."""

    def __init__(self, pid: int) -> None:
        self.pid = pid

    def poll(self) -> int | None:
        try:
            os.kill(self.pid, 0)
        except ProcessLookupError:
            return 0
        return None

    def send_signal(self, sig: int) -> None:
        try:
            os.kill(self.pid, sig)
        except ProcessLookupError:
            pass


def adopt(role: str, pid: int) -> Any:
    """A worker process of armctl's own, known to the signal handler until forget()."""
    p = _Process(pid)
    with _lock:
        _live.append((role, p))
    return p


ORPHAN_STOP_S = 10.0  # a worker whose armctl died: its runs' safe stops take about a second
_parent: int | None = None  # in a forked worker: the armctl it works for


def as_child_of(parent: int) -> None:
    """In a forked worker (tools/run/workers.py): a process group of its own; on a signal it stops
    its own runs, not its parent's children (the list it inherited), and notes the signal for the
    code it runs to stop at its next check, never raising where it stands (a worker that waits
    for work would die of it); a SIGTERM when armctl dies, after which it ends (_end_as_orphan)."""
    global _parent
    _parent = parent
    os.setpgid(0, 0)
    with _lock:
        _live.clear()
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, _on_signal_in_worker)
    dies_with_parent(parent)()
    threading.Thread(target=_end_as_orphan, name="orphan-watch", daemon=True).start()


def _on_signal_in_worker(signum: int, frame: Any) -> None:
    global interrupted
    first = interrupted is None
    interrupted = interrupted or signum
    _stop(signal.SIGTERM if first else signal.SIGKILL)


def _end_as_orphan() -> None:
    """A pool's worker whose armctl has died waits for work that never comes, holding what it
    inherited (the lock on the study's --out folder). Watched here, not by the death signal alone:
    that comes when the thread that forked the worker ends, which may be long before armctl does.
    Once orphaned, it stops its runs, and once they have stopped (their safe stop) or ORPHAN_STOP_S
    have passed, it ends. What it was writing is written atomically or not at all, and the resumed
    study redoes that run."""
    while os.getppid() == _parent:
        time.sleep(0.1)
    _stop(signal.SIGTERM)
    deadline = time.monotonic() + ORPHAN_STOP_S
    while time.monotonic() < deadline:
        with _lock:
            if all(p.poll() is not None for _, p in _live):
                break
        time.sleep(0.05)
    else:
        _stop(signal.SIGKILL)
    os._exit(128 + signal.SIGTERM)


def communicate_or_kill(p: subprocess.Popen[Any], timeout: float) -> tuple[Any, Any]:
    """p's (stdout, stderr) once it has ended: within timeout on its own, else after a SIGKILL
    (which it cannot ignore, so this always returns)."""
    try:
        return p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        p.kill()
        return p.communicate()


def forget(p: Any) -> None:
    with _lock:
        _live[:] = [(r, q) for r, q in _live if q is not p]


def interrupt_and_reap(p: subprocess.Popen[Any], timeout: float) -> None:
    """SIGINT to p if it still runs (a logger writes what it has queued, a simulator its summary),
    a SIGKILL if it has not ended within timeout; then forgotten."""
    if p.poll() is None:
        p.send_signal(signal.SIGINT)
        try:
            p.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
    forget(p)


def _stop(sig: int) -> None:
    with _lock:
        alive = [(r, p) for r, p in _live if p.poll() is None]
    controllers = [p for r, p in alive if r == "controller"]
    # The controller first: the simulator and the logger follow its NMT stop. Without a
    # controller yet, there is no arm to stop safely: the others stop at once.
    for p in controllers or [p for _, p in alive]:
        p.send_signal(sig)


class Interrupted(KeyboardInterrupt):
    """A signal while no child was running: the command stops where it is (armctl exits 128 + N)."""

    def __init__(self, signum: int) -> None:
        super().__init__(f"stopped by signal {signum}")
        self.signum = signum


def _on_signal(signum: int, frame: Any) -> None:
    global interrupted
    with _lock:
        running = any(p.poll() is None for _, p in _live)
    first = interrupted is None
    interrupted = interrupted or signum
    if not running:
        raise Interrupted(signum)
    _stop(signal.SIGTERM if first else signal.SIGKILL)


def install() -> None:
    """In the main thread: SIGINT, SIGTERM and SIGHUP stop the children in order."""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, _on_signal)
