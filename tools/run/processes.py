"""The processes of a HIL run over a CAN bus: the telemetry logger, the simulator and the controller,
started in that order and waited for (tools/run/hil.py plans them and analyses what they wrote).

Standard library only (and tools.run.procs), because the same code also runs inside the qemu VM
(`hil --bus vm`): there `python -m tools.run.processes PLAN RESULT` starts the three programs on
the guest's vcan buses and writes their exit codes to RESULT, and the host does everything else
(the build, the plan, the analysis). Inside the VM, where the machine is emulated, importing the
analysis' numpy and MuJoCo costs tens of seconds; this module, a fraction of one."""

from __future__ import annotations

import json
import os
import select
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from tools.run import procs as procs_mod

USAGE_ERROR = 2  # the controller's and the simulator's exit code for a bad argument
SIM_RT_PRIORITY = 70  # realtime runs: below the controller's loop (80) and above the logger (10)
LOGGER_READY_S = 10.0  # the logger says "ready" within this on the host (the VM's: tools/run/hil.py)


class HilError(RuntimeError):
    pass


@dataclass
class ProcessPlan:
    """What to start, where their output goes, and the bounds: all the host decided (JSON for the VM)."""
    out: str  # the run's folder: controller.log, simulator.log, logger.log
    mode: str  # lockstep | realtime
    cpu: int  # realtime: the CPU the controller's loop and the simulator share
    deadline_s: float  # bounds a hung process only: the run is deterministic, not timed
    logger: list[str]
    simulator: list[str]
    controller: list[str]
    cwd: str
    logger_ready_s: float = LOGGER_READY_S
    multicast_routes: tuple[str, ...] = ()  # inside the VM: routed to lo first (the guest's own kernel)


def _logger_priority() -> None:
    """Realtime runs: the logger mostly waits for messages, so a real-time priority costs the
    others little and keeps a busy machine from delaying it (the kernel socket buffer is its
    queue, seconds deep). Not in lockstep: there it would only preempt the run itself."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
    except (PermissionError, OSError):
        pass  # not root: ordinary priority; any loss shows up as sequence gaps in run.json


def _simulator_realtime(cpu: int):  # noqa: ANN202 - a preexec_fn
    """In a realtime run the simulator is the other half of the loop. It runs SCHED_FIFO below
    the loop (at ordinary priority a 2-core machine delays it past the watchdog's 3 periods within
    a second or two), on the loop's own CPU: this VM stops one vCPU now and then for 1-6 ms
    (measured: a spinning process sees such gaps every few seconds, on one CPU at a time). Drives
    on the other CPU would then fall silent while the loop runs, and the watchdog safe-stops it;
    on one CPU a stall pauses the whole rig, and the loop counts the deadlines it missed."""
    def setup() -> None:
        try:
            os.sched_setaffinity(0, {cpu})
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(SIM_RT_PRIORITY))
        except (PermissionError, OSError):
            pass  # not root: ordinary priority; run.json's environment says which
    return setup


def _scheduling(pid: int) -> str:
    try:
        policy = os.sched_getscheduler(pid)
        prio = os.sched_getparam(pid).sched_priority
    except OSError as exc:
        return f"unknown ({exc.strerror})"
    try:
        cpus = ",".join(map(str, sorted(os.sched_getaffinity(pid))))
    except OSError:
        cpus = "?"
    return (f"SCHED_FIFO {prio}" if policy == os.SCHED_FIFO else "SCHED_OTHER") + f" on CPU {cpus}"


def _wait_for_logger(proc: subprocess.Popen[bytes], timeout: float) -> None:
    """The logger says "ready" on stdout once it receives (tools/lcm_logger)."""
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], timeout)
    line = proc.stdout.readline() if ready else b""
    if b"ready" not in line:
        proc.poll()
        why = f"exited with {proc.returncode}" if proc.returncode is not None else f"not ready within {timeout:g} s"
        raise HilError(f"the telemetry logger {why}; see logger.log")


def last_line(path: Path) -> str:
    try:
        lines = [ln for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    return lines[-1][:400] if lines else ""


# A controller outlives the simulator by its lockstep timeout, or, on the emulated MCU, by the
# report it sends after the drives' NMT stop (seconds of wall time): past this it is hung.
SIMULATOR_GONE_GRACE_S = 120.0


def _wait_run(plan: ProcessPlan, ctl: subprocess.Popen[bytes], sim: subprocess.Popen[bytes],
              logs: dict[str, Any]) -> None:
    """Until the controller and then the simulator have ended. A child that refuses its
    arguments (exit 2) ends the run at once, with its message. The bound only catches a hung
    process. The controller ends first (or, when the simulator died, within its lockstep timeout);
    the simulator follows on the controller's NMT stop or after its idle timeout."""
    out = Path(plan.out)
    deadline = time.monotonic() + plan.deadline_s
    sim_ended: float | None = None
    while ctl.poll() is None:
        if sim.poll() == USAGE_ERROR:
            logs["simulator"].flush()
            raise HilError(f"the simulator refused its arguments: {last_line(out / 'simulator.log')}")
        if sim_ended is None and sim.poll() is not None:
            sim_ended = time.monotonic()
        if sim_ended is not None and time.monotonic() > sim_ended + SIMULATOR_GONE_GRACE_S:
            ctl.kill()
            raise HilError(f"{ctl.args[0]} did not end within {SIMULATOR_GONE_GRACE_S:g} s of the simulator's end "
                           f"({last_line(out / 'simulator.log')}); killed")
        if time.monotonic() > deadline:
            ctl.kill()
            raise HilError(f"{ctl.args[0]} did not finish in time; killed")
        time.sleep(0.01)
    if ctl.returncode == USAGE_ERROR:
        logs["controller"].flush()
        raise HilError(f"the controller refused its arguments: {last_line(out / 'controller.log')}")
    try:
        sim.wait(timeout=max(1.0, deadline - time.monotonic()))
    except subprocess.TimeoutExpired:
        sim.kill()
        raise HilError(f"{sim.args[0]} did not finish in time; killed") from None


def run_processes(plan: ProcessPlan) -> tuple[dict[str, int | None], float, str]:
    """The logger, the simulator and the controller as processes on the bus: their exit codes, the
    wall time from the simulator's start, and the simulator's scheduling."""
    out = Path(plan.out)
    logs = {name: open(out / f"{name}.log", "w") for name in ("controller", "simulator", "logger")}

    # Not lcm-logger: its subscription queue of 30 messages drops telemetry whenever it falls
    # behind for a moment (tools/lcm_logger/arm_lcm_logger.c).
    try:
        logger = procs_mod.spawn("logger", plan.logger, stdout=subprocess.PIPE, stderr=logs["logger"],
                                 preexec_fn=_logger_priority if plan.mode == "realtime" else None)
    except InterruptedError as exc:
        for f in logs.values():
            f.close()
        raise HilError(str(exc)) from None
    procs: list[subprocess.Popen[bytes]] = [logger]
    t0 = time.monotonic()
    try:
        _wait_for_logger(logger, plan.logger_ready_s)
        sim = procs_mod.spawn("simulator", plan.simulator, watches_parent=True, cwd=plan.cwd,
                              stdout=logs["simulator"], stderr=subprocess.STDOUT,
                              preexec_fn=_simulator_realtime(plan.cpu) if plan.mode == "realtime" else None)
        procs.append(sim)
        sim_scheduling = _scheduling(sim.pid)
        ctl = procs_mod.spawn("controller", plan.controller, watches_parent=True, stdout=logs["controller"],
                              stderr=subprocess.STDOUT)
        procs.append(ctl)
        _wait_run(plan, ctl, sim, logs)
        wall = time.monotonic() - t0
    except InterruptedError as exc:
        raise HilError(str(exc)) from None
    finally:
        for p in reversed(procs):
            procs_mod.interrupt_and_reap(p, 5)
        for f in logs.values():
            f.close()
        if logger.stdout is not None:
            logger.stdout.close()
    return ({"controller": ctl.returncode, "simulator": sim.returncode, "logger": logger.returncode}, wall,
            sim_scheduling)


def main(argv: list[str]) -> int:
    """Inside the VM: PLAN (JSON of a ProcessPlan) in, RESULT (JSON: exit_codes, wall_s,
    simulator_scheduling, or error) out. Exit 0 once RESULT is written, whatever the run did."""
    plan_path, result_path = Path(argv[0]), Path(argv[1])
    plan = ProcessPlan(**json.loads(plan_path.read_text()))
    result: dict[str, Any]
    try:
        for net in plan.multicast_routes:
            r = subprocess.run(["ip", "route", "replace", net, "dev", "lo"], capture_output=True, text=True)
            if r.returncode != 0:
                raise HilError(f"routing {net} to lo in the VM: {r.stderr.strip() or r.returncode}")
        codes, wall, scheduling = run_processes(plan)
        result = {"exit_codes": codes, "wall_s": wall, "simulator_scheduling": scheduling}
    except HilError as exc:
        result = {"error": str(exc)}
    result_path.write_text(json.dumps(result))
    return 0


def plan_json(plan: ProcessPlan) -> str:
    return json.dumps(asdict(plan))


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
