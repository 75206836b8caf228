"""One hardware-in-the-loop run: logger, simulator and controller as separate processes."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import lcm

from tools import busload
from tools.paths import REPO, controller_binary, env_with_repo, logger_binary
from tools.run_analysis import analyse

JOINT_NAMES = ["shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3"]


@dataclass
class HilOptions:
    out: Path
    duration_s: float = 5.0
    method: str = "pd"
    mode: str = "lockstep"
    preset: str = "release"
    bus: str = "udp"  # udp | vcan | auto (vcan if this kernel has SocketCAN and vcan0.., else udp)
    can_port: int | None = None  # None: pick one, so concurrent runs do not share a bus; bus i: port + i
    # Which drive is on which bus (firmware/protocol/buses.toml; None: that default file).
    topology: Path | None = None
    lcm_port: int | None = None
    # Another controller binary (default: controller_binary(preset)), a command it runs under
    # (e.g. ("qemu-aarch64-static",) for a cross-compiled one) and extra controller arguments.
    controller: Path | None = None
    controller_cmd_prefix: tuple[str, ...] = ()
    controller_args: tuple[str, ...] = ()
    # host_sim.uncertainty.UncertaintyConfig fields (None: the simulated arm is the nominal one).
    uncertainty: dict[str, Any] | None = None
    # Recorded in run.json's results, e.g. the study's seed and trajectory.
    labels: dict[str, Any] = field(default_factory=dict)
    # Emulate each bus's bit timing in the simulator (host_sim/bus_timing.py) with the topology's
    # physical layers: virtual in lockstep, wallclock in realtime.
    bus_timing: bool = False


class HilError(RuntimeError):
    pass


def _ports(opt: HilOptions) -> tuple[int, int]:
    rng = random.Random()
    return opt.can_port or rng.randint(43200, 43990), opt.lcm_port or rng.randint(7700, 7999)


def _logger_priority() -> None:
    """The logger mostly waits for messages, so a real-time priority costs the others little and
    keeps a busy machine from delaying it (its queue has no limit, so a delay costs no data)."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
    except (PermissionError, OSError):
        pass  # not root: ordinary priority; any loss shows up as sequence gaps in run.json


SIM_RT_PRIORITY = 70  # realtime runs: below the controller's loop (80) and above the logger (10)


def _simulator_priority() -> None:
    """In a realtime run the simulator is the other half of the loop: at ordinary priority a
    2-core machine delays it by more than the watchdog's 3 periods within a second or two."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(SIM_RT_PRIORITY))
    except (PermissionError, OSError):
        pass  # not root: ordinary priority; run.json's environment says which


def _scheduling(pid: int) -> str:
    try:
        policy = os.sched_getscheduler(pid)
        prio = os.sched_getparam(pid).sched_priority
    except OSError as exc:
        return f"unknown ({exc.strerror})"
    return f"SCHED_FIFO {prio}" if policy == os.SCHED_FIFO else "SCHED_OTHER"


def _wait_for_logger(url: str, log_path: Path, proc: subprocess.Popen[bytes], timeout: float = 10.0) -> None:
    """The logger is ready once a probe message has reached its file."""
    probe = lcm.LCM(url)
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if proc.poll() is not None:
            raise HilError(f"the telemetry logger exited with {proc.returncode}; see logger.log")
        probe.publish("ARM_PROBE", b"ready?")
        time.sleep(0.15)
        if log_path.exists() and log_path.stat().st_size > 0:
            return
    raise HilError(f"the telemetry logger did not start writing {log_path} within {timeout:g} s")


def _load_json(path: Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def write_json_atomic(path: Path, data: dict[str, Any]) -> None:
    tmp = path.with_name(f".{path.name}.tmp.{os.getpid()}")
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    os.replace(tmp, path)


def check_loopback_route(group: str) -> None:
    """Refuse to run unless the group is routed to lo: every membership then stays on lo."""
    r = subprocess.run(["ip", "route", "get", group], capture_output=True, text=True)
    if r.returncode != 0 or " dev lo " not in f" {r.stdout} ":
        net = "239.255.76.67/32" if group.startswith("239.255.") else "239.74.163.0/24"
        raise HilError(f"multicast group {group} is not routed to lo (route: {r.stdout.strip() or r.stderr.strip()}); "
                       f"run as root: ip route replace {net} dev lo (tools/armctl does this when run as root)")


def load_topology(path: Path | None = None) -> list[busload.Bus]:
    """The buses of the topology file (name, kind, rates, drives)."""
    try:
        return busload.load_topology(path or busload.DEFAULT_TOPOLOGY, len(JOINT_NAMES))
    except busload.ConfigError as exc:
        raise HilError(f"bus topology: {exc}") from exc


def vcan_names(n: int) -> list[str]:
    return [f"vcan{i}" for i in range(n)]


def bus_args(kind: str, can_port: int, topology: list[busload.Bus]) -> list[str]:
    """SPEC@DRIVES per bus of the topology: udp on port can_port + i, or vcan0, vcan1, ..."""
    out = []
    for i, b in enumerate(topology):
        spec = f"udp:239.74.163.2:{can_port + i}" if kind == "udp" else f"socketcan:vcan{i}"
        out.append(f"{spec}@{','.join(map(str, b.drives))}")
    return out


def topology_load_pct(topology: list[busload.Bus], rate_hz: float = 1000.0) -> dict[str, float]:
    """Worst-case load of each bus of the topology at the loop rate (tools/armctl busload)."""
    loads = busload.compute(topology, rate_hz, 100.0, busload.Protocol())
    return {bl.bus.name: round(bl.load * 100.0, 2) for bl in loads}


def bus_timing_mode(mode: str) -> str:
    """host_sim's bus timing for a run mode: lockstep has no wall clock to delay frames on."""
    return "virtual" if mode == "lockstep" else "wallclock"


def bus_timing_args(mode: str, topology: list[busload.Bus]) -> list[str]:
    """host_sim arguments that emulate the topology's bit timing (one --bus-phy per bus, in order)."""
    args = ["--bus-timing", bus_timing_mode(mode)]
    for b in topology:
        args += ["--bus-phy", busload.phy_spec(b)]
    return args


def resolve_bus(choice: str, n_buses: int = 1) -> tuple[str, str]:
    """(udp|vcan, why): auto takes vcan when the kernel has SocketCAN and vcan0..vcan<n-1> are up."""
    from tools.vcan import can_interfaces, kernel_has_can

    if choice == "udp":
        return "udp", "asked for"
    ok, why = kernel_has_can()
    names = vcan_names(n_buses)
    present = {i.get("name") for i in can_interfaces()} if ok else set()
    missing = [n for n in names if n not in present]
    has_vcan = ok and not missing
    if choice == "vcan":
        if not has_vcan:
            raise HilError(f"--bus vcan: {why or 'no ' + ', '.join(missing) + ' interface'} (the topology has "
                           f"{n_buses} bus(es): {', '.join(names)}; tools/armctl vcan up --iface NAME, or --bus vm "
                           "to run inside the VM that has them)")
        return "vcan", "asked for"
    if choice != "auto":
        raise HilError(f"--bus: unknown bus '{choice}' (auto, udp, vcan, vm)")
    if has_vcan:
        return "vcan", f"this kernel has SocketCAN and {', '.join(names)}"
    return "udp", why or f"no {', '.join(missing)} interface"


def run_hil(opt: HilOptions) -> dict[str, Any]:
    for group in ("239.255.76.67", "239.74.163.2"):
        check_loopback_route(group)
    topology = load_topology(opt.topology)
    bus_kind, bus_why = resolve_bus(opt.bus, len(topology))
    binary = opt.controller or controller_binary(opt.preset)
    logger_exe = logger_binary(opt.preset)
    for exe in (binary, logger_exe):
        if not exe.exists():
            raise HilError(f"{exe} is missing: run tools/armctl build")
    opt.out.mkdir(parents=True, exist_ok=True)
    for stale in ("telemetry.lcmlog", "controller_summary.json", "sim_summary.json", "run.json", "uncertainty.json"):
        (opt.out / stale).unlink(missing_ok=True)
    can_port, lcm_port = _ports(opt)
    buses = bus_args(bus_kind, can_port, topology)
    bus_argv = [a for spec in buses for a in ("--bus", spec)]
    url = f"udpm://239.255.76.67:{lcm_port}?ttl=0&recv_buf_size=8388608"
    log_path = opt.out / "telemetry.lcmlog"
    logs = {name: open(opt.out / f"{name}.log", "w") for name in ("controller", "simulator", "logger")}

    # Not lcm-logger: its subscription queue of 30 messages drops telemetry whenever it falls
    # behind for a moment (tools/lcm_logger/arm_lcm_logger.c).
    logger = subprocess.Popen([str(logger_exe), "--lcm-url", url, str(log_path)],
                              stdout=logs["logger"], stderr=subprocess.STDOUT, preexec_fn=_logger_priority)
    procs: list[subprocess.Popen[bytes]] = [logger]
    t0 = time.monotonic()
    try:
        _wait_for_logger(url, log_path, logger)
        sim_args = bus_timing_args(opt.mode, topology) if opt.bus_timing else []
        if opt.uncertainty is not None:
            write_json_atomic(opt.out / "uncertainty.json", opt.uncertainty)
            sim_args += ["--uncertainty", str(opt.out / "uncertainty.json")]
        sim = subprocess.Popen(
            [sys.executable, "-m", "host_sim", *bus_argv, "--lcm-url", url,
             "--summary", str(opt.out / "sim_summary.json"), *sim_args],
            cwd=REPO, env=env_with_repo(), stdout=logs["simulator"], stderr=subprocess.STDOUT,
            preexec_fn=_simulator_priority if opt.mode == "realtime" else None)
        procs.append(sim)
        sim_scheduling = _scheduling(sim.pid)
        ctl = subprocess.Popen(
            [*opt.controller_cmd_prefix, str(binary), *bus_argv, "--lcm-url", url,
             "--duration", f"{opt.duration_s:g}", "--method", opt.method, "--mode", opt.mode,
             "--summary", str(opt.out / "controller_summary.json"), *opt.controller_args],
            stdout=logs["controller"], stderr=subprocess.STDOUT)
        procs.append(ctl)
        # Generous: the run is deterministic, not timed; this only bounds a hung process.
        deadline = time.monotonic() + 120.0 + 60.0 * opt.duration_s
        while time.monotonic() < deadline and (ctl.poll() is None or sim.poll() is None):
            time.sleep(0.05)
        for p in (ctl, sim):
            if p.poll() is None:
                p.kill()
                raise HilError(f"{p.args[0]} did not finish in time; killed")
        wall = time.monotonic() - t0
        time.sleep(0.3)  # telemetry still on its way reaches the logger; SIGINT then drains and flushes it
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
                try:
                    p.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    p.kill()
        for f in logs.values():
            f.close()

    # A process that died wrote no summary: the run still ends in a defined, named state and
    # the partial log is analysed.
    controller = _load_json(opt.out / "controller_summary.json") or {
        "result": ctl.returncode, "reason": f"controller died (exit code {ctl.returncode}); see controller.log"}
    simulator = _load_json(opt.out / "sim_summary.json") or {
        "result": "died", "reason": f"simulator died (exit code {sim.returncode}); see simulator.log"}
    config = {"method": opt.method, "mode": opt.mode, "duration_s": opt.duration_s,
              "joint_names": JOINT_NAMES, "controller_args": list(opt.controller_args),
              "uncertainty": opt.uncertainty,
              "bus_timing": bus_timing_mode(opt.mode) if opt.bus_timing else "off", **opt.labels}
    run = analyse(opt.out, controller, simulator, config, {
        "bus": " ".join(buses), "bus_choice": f"{opt.bus} -> {bus_kind} ({bus_why})",
        "topology": {"file": str(opt.topology or busload.DEFAULT_TOPOLOGY),
                     "buses": [{"name": b.name, "spec": spec.rpartition("@")[0], "kind": b.describe(),
                                "drives": b.drives} for b, spec in zip(topology, buses)]},
        "bus_load_pct": topology_load_pct(topology),
        "lcm_url": url, "wall_s": wall, "simulator_scheduling": sim_scheduling,
        "exit_codes": {"controller": ctl.returncode, "simulator": sim.returncode}})
    write_json_atomic(opt.out / "run.json", run)
    return run
