"""One run of the controller against the simulated arm: hardware in the loop (logger, simulator and
controller as separate processes on a CAN bus), or software in the loop (--bus sil: arm_sil, the
same controller and drive code in one process, frames in memory, telemetry straight to the log)."""

from __future__ import annotations

import functools
import json
import os
import platform
import socket
import subprocess
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any


from gen.lib.atomic_output import OutputError, write_json_atomic, write_text_atomic
from host_sim.drive_model import DriveModel
from host_sim.launch import sim_argv
from gen.lib import busload
from tools.build.arm import DEFAULT_ARM, ArmChoiceError, ArmRef, arm_build_dir, arm_info, prepared_model
from gen.lib.params import constant, default as param_default, param
from gen.lib.paths import REPO, controller_binary, logger_binary
from tools.run import procs as procs_mod
from tools.run.processes import (LOGGER_READY_S, USAGE_ERROR, HilError, ProcessPlan, last_line, plan_json,
                                 run_processes)
from tools.run.slots import CAN_GROUP, LCM_GROUP, acquire_slot
from tools.run.verdict import Bounds

CONTROLLER_DEFAULT_HOLD_S: float = param_default("controller", "ref-hold")


# Lockstep: both sides poll the bus this long before they sleep on it. A period's answer comes
# within tens of microseconds, sooner than a sleeping process is woken on a VM: measured on this
# 2-core machine, 10-11x real time without, 11-14x with (host_sim/README.md).
LOCKSTEP_SPIN_US = 50
BRAKES = ("engaged", "released", "none")  # HilOptions.brakes


# What the drives speak (docs/drives.md): this project's frames, or CANopen CiA 402. The one
# definition of the default is the registry's (firmware/params/params.toml [hil.protocol]): every
# run passes --protocol to both programs.
PROTOCOLS = ("arm", "canopen")
DEFAULT_PROTOCOL: str = param("hil", "protocol").default


@dataclass
class HilOptions:
    out: Path
    duration_s: float = param_default("controller", "duration")  # arm_controller's defaults (the registry's)
    method: str = param_default("controller", "method")
    mode: str = "lockstep"
    preset: str = "release"
    # udp | vcan | auto (vcan if this kernel has SocketCAN and vcan0.., else udp) | sil (one process)
    # | vm (the logger, simulator and controller inside the qemu VM, on its vcan buses)
    bus: str = "udp"
    can_port: int | None = None  # None: the run slot's (tools/run/slots.py): no concurrent run shares it; bus i: port + i
    # The arm (tools/build/arm.py: --model / --arm); its build folder holds the binaries and arm.json.
    arm: ArmRef = DEFAULT_ARM
    # Which drive is on which bus (a topology file; None: the arm's wiring, arm.json).
    topology: Path | None = None
    lcm_port: int | None = None
    # Another controller binary (default: the arm build folder's), a command it runs under
    # (e.g. ("qemu-aarch64-static",) for a cross-compiled one) and extra controller arguments.
    controller: Path | None = None
    controller_cmd_prefix: tuple[str, ...] = ()
    controller_args: tuple[str, ...] = ()
    sim_args: tuple[str, ...] = ()  # extra arm_sim arguments (e.g. --profile)
    # host_sim.uncertainty.UncertaintyConfig fields (None: the simulated arm is the nominal one).
    uncertainty: dict[str, Any] | None = None
    # Recorded in run.json's results, e.g. the study's seed and trajectory.
    labels: dict[str, Any] = field(default_factory=dict)
    # Realtime: the CPU the controller's loop and the simulator share (default: the last one).
    cpu: int | None = None
    # Emulate each bus's bit timing in the simulator (host_sim/bus_timing.py) with the topology's
    # physical layers: virtual in lockstep, wallclock in realtime.
    bus_timing: bool = False
    # The drives' holding brakes, from the arm's drive table (gen/drives.py): "engaged" at power-on
    # as on the arm, "released" (the arm starts held by its drives: the study's runs, recorded so; a
    # brake that held the arm through its release delay would make other runs), or "none".
    brakes: str = "engaged"
    # What the run must meet to be "ok" (tools/run/verdict.py).
    bounds: Bounds = field(default_factory=Bounds)
    # The emulated drives' sensing and torque path (host_sim/drive_model.py; default: ideal).
    drives: DriveModel = field(default_factory=DriveModel)
    # Every frame on the buses, from the simulator's side, in candump's log format: DIR/bus.log
    # (CAPTURE_FILE), or DIR/bus.log.gz once the run is over when compress is asked for.
    capture: bool = False
    compress_capture: bool = False
    # Lockstep over a bus: each side polls this long before it sleeps (lockstep_spin_us).
    spin_us: float = LOCKSTEP_SPIN_US
    # A design loaded at run time (the controller's --design-file: gen.synth's pm_design.txt)
    # instead of the build's own; and what run.json records as its design (default: the build's
    # own record, which names the config the build was made from).
    design_file: Path | None = None
    design_record: dict[str, Any] | None = None
    protocol: str = DEFAULT_PROTOCOL
    # canopen: the arm's CiA 402 drive configuration (a drives.toml; None: the arm's, gen/drives.py)
    drive_config: Path | None = None
    # Processor in the loop (docs/pil.md): the Cortex-M preset whose image runs the controller in
    # qemu-system-arm (tools/build/cortex_m.py MACHINES), its buses SLCAN links on the image's UARTs;
    # None: the controller runs here.
    target: str | None = None


def spin_args(mode: str, spin_us: float = LOCKSTEP_SPIN_US) -> list[str]:
    return ["--spin-us", f"{spin_us:g}"] if mode == "lockstep" else []


def lockstep_spin_us(jobs: int) -> float:
    """A lockstep run spins only while it has the cores to itself: two runs that both spin on two
    cores slow each other (armctl bench study: --jobs 2 gave 0.95x --jobs 1 with spinning)."""
    return LOCKSTEP_SPIN_US if 2 * jobs <= (os.cpu_count() or 1) else 0.0


# Realtime: a next-period SYNC that overtook this period's commands on another bus is held back
# at most this long (arm_sim --reorder-wait-us). Loopback UDP keeps no order between the buses'
# sockets only for microseconds; holding a SYNC back longer makes its states late, and three
# late periods in a row trip the controller's watchdog (lockstep waits up to 0.2 s: nothing is
# timed there).
REALTIME_REORDER_WAIT_US = 200


def sim_mode_args(mode: str, spin_us: float = LOCKSTEP_SPIN_US) -> list[str]:
    return spin_args(mode, spin_us) + (["--reorder-wait-us", str(REALTIME_REORDER_WAIT_US)] if mode == "realtime" else [])


def realtime_cpu(opt: "HilOptions") -> int:
    """The CPU a realtime run's loop and simulator share (HilOptions.cpu; default the last one)."""
    return opt.cpu if opt.cpu is not None else (os.cpu_count() or 1) - 1


def _load_json(path: Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def _git(*args: str) -> str | None:
    try:
        r = subprocess.run(["git", "-C", str(REPO), *args], capture_output=True, text=True, timeout=20)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return r.stdout if r.returncode == 0 else None


@functools.cache
def _checkout_state() -> tuple[str | None, str | None]:
    """HEAD and the tracked files' status, once per process: its runs run the binaries it built
    (tools/run/runner.py prepare_build), and two git calls cost 8 ms a run."""
    return _git("rev-parse", "HEAD"), _git("status", "--porcelain", "--untracked-files=no")


def provenance(started: datetime | None = None) -> dict[str, Any]:
    """When, from which code and on which machine a run was made (run.json `provenance`): a
    result can then be traced to its commit. `dirty`: tracked files differ from that commit
    (untracked ones, such as run folders, do not count); both null outside a git checkout."""
    head, status = _checkout_state()
    return {"date_utc": (started or datetime.now(timezone.utc)).isoformat(timespec="seconds"),
            "commit": head.strip() if head else None,
            "dirty": bool(status.strip()) if status is not None and head else None,
            "hostname": socket.gethostname(), "platform": platform.platform()}


def check_loopback_route(group: str) -> None:
    """Refuse to run unless the group is routed to lo: every membership then stays on lo."""
    r = subprocess.run(["ip", "route", "get", group], capture_output=True, text=True)
    if r.returncode != 0 or " dev lo " not in f" {r.stdout} ":
        net = "239.255.76.67/32" if group.startswith("239.255.") else "239.74.163.0/24"
        raise HilError(f"multicast group {group} is not routed to lo (route: {r.stdout.strip() or r.stderr.strip()}); "
                       f"run as root: ip route replace {net} dev lo (tools/armctl does this when run as root)")


def load_topology(path: Path | None, info: dict[str, Any]) -> list[busload.Bus]:
    """The buses: the topology file's, else the arm's wiring (arm.json), for the arm's drives."""
    if path is None:
        return [busload.Bus(b["name"], b["kind"] == "fd", b["nominal"], b["data"], list(b["drives"]))
                for b in info["buses"]]
    try:
        return busload.load_topology(path, info["n_joints"])
    except busload.ConfigError as exc:
        raise HilError(f"bus topology: {exc}") from exc


def canopen_topology(path: Path | None, info: dict[str, Any], rate_hz: float,
                     transmission: dict[str, int], timed: bool = False) -> tuple[list[busload.Bus], str]:
    """The CiA 402 drives' buses and where they come from. A topology file's, if its load (from the
    drive table's PDOs and transmission types) is within the budget, or at any load with bus
    timing (timed: what an overload does is then emulated); else classic CAN, the field's wire:
    the fewest 1 Mbit/s buses that carry the arm's drives (busload.canopen_wiring); else, when
    even the controller's limit of buses does not, the arm's CAN FD wiring (arm.json)."""
    budget, hb = constant("bus-budget"), constant("heartbeat-ms")
    n = info["n_joints"]
    if path is not None:
        topology = load_topology(path, info)
        for b in topology:
            load = busload.canopen_load(b, len(b.drives), rate_hz, hb, transmission)
            if load > budget and not timed:
                fits = busload.canopen_wiring(n, rate_hz, transmission)
                raise HilError(f"--topology {path}: bus {b.name} ({b.describe()}, drives "
                               f"{','.join(map(str, b.drives))}) would carry {100 * load:.1f} % at {rate_hz:g} Hz "
                               f"with these CiA 402 PDOs, above the {100 * budget:g} % budget; "
                               + (f"{len(fits)} classic 1 Mbit/s buses fit (omit --topology)" if fits else
                                  "spread the drives over more buses, use CAN FD or a lower --rate")
                               + " (with --bus-timing the overload is emulated instead)")
        return topology, str(path)
    classic = busload.canopen_wiring(n, rate_hz, transmission)
    if classic is not None:
        return classic, (f"classic CAN: the fewest 1 Mbit/s buses ({len(classic)}) that carry {n} CiA 402 drives "
                         f"at {rate_hz:g} Hz within the {100 * budget:g} % budget (gen/lib/busload.py canopen_wiring)")
    fd = load_topology(None, info)
    worst = max(busload.canopen_load(b, len(b.drives), rate_hz, hb, transmission) for b in fd)
    if worst > budget:
        raise HilError(f"{n} CiA 402 drives at {rate_hz:g} Hz fit neither {busload.MAX_BUSES} classic 1 Mbit/s "
                       f"buses nor the arm's CAN FD wiring ({100 * worst:.1f} %, budget {100 * budget:g} %): "
                       "give --topology, a lower --rate, or a drive table with slower TPDO2 (transmission tpdo2 = n)")
    return fd, (f"the arm's CAN FD wiring (arm.json): {n} CiA 402 drives at {rate_hz:g} Hz do not fit "
                f"{busload.MAX_BUSES} classic 1 Mbit/s buses within the {100 * budget:g} % budget")


def reference_args(info: dict[str, Any], controller_args: tuple[str, ...]) -> list[str]:
    """The arm's default reference (arm.json: inside the joint ranges), unless the run gives one."""
    if "--ref-amp" in controller_args:
        return []
    ref = info["reference"]
    return ["--ref-amp", ",".join(f"{a:g}" for a in ref["amp"]), "--ref-freq", ",".join(f"{f:g}" for f in ref["freq_hz"])]


def sim_substeps(info: dict[str, Any], rate_hz: float) -> int:
    """MuJoCo steps per control period at this rate: the simulated time of a period is the
    controller's period (a controller run at 200 Hz on a 1 kHz arm gets 5 ms a period, not 1 ms)."""
    dt = 1.0 / (info["loop_rate_hz"] * info["substeps"])
    k = 1.0 / (rate_hz * dt)
    if round(k) < 1 or abs(k - round(k)) > 1e-6 * k:
        raise HilError(f"--rate {rate_hz:g}: the period {1e3 / rate_hz:g} ms is not a whole number of the "
                       f"simulator's {dt * 1e3:g} ms steps (the arm's loop rate {info['loop_rate_hz']:g} Hz, "
                       f"{info['substeps']} step(s) a period); use a rate that divides {1.0 / dt:g} Hz")
    return int(round(k))


def _arg_value(args: tuple[str, ...], name: str, default: float) -> float:
    return float(args[args.index(name) + 1]) if name in args else default


def vcan_names(n: int) -> list[str]:
    return [f"vcan{i}" for i in range(n)]


SIL = "sil"  # --bus: software in the loop
# --bus: the run's three programs inside the qemu VM (tools/vm), on its vcan buses; the host builds,
# plans and analyses as for any run (tools/run/processes.py runs there)
VM = "vm"
CAPTURE_FILE = "bus.log"  # a run's capture of its buses (candump -l format)
CANOPEN_DBC_FILE = "canopen.dbc"  # a CANopen run's frames, derived from its drive table (gen/canopen_dbc.py)
CANOPEN_OD_FILE = "canopen_od.txt"  # the emulated drives' dictionary, from the drive table's EDS/DCF (gen/eds.py)
VM_FILES = ("vm_plan.json", "vm_result.json", "vm.log")  # --bus vm: the plan in, the exit codes out, the VM's output


PIL = "pil"  # the buses of a processor-in-the-loop run: SLCAN on the MCU image's UARTs
PIL_UARTS = 4  # uart:0 .. uart:3 (the image's fifth UART carries its telemetry)


def bus_args(kind: str, can_port: int, topology: list[busload.Bus], side: str = "controller") -> list[str]:
    """SPEC@DRIVES per bus of the topology: udp on port can_port + i, vcan0, vcan1, ..., the
    in-process bus's lines mem:0, mem:1, ... (software in the loop), or (processor in the loop) the
    image's uart:i, which the simulator reaches as slcan:127.0.0.1:can_port + i."""
    out = []
    for i, b in enumerate(topology):
        pil = f"uart:{i}" if side == "controller" else f"slcan:127.0.0.1:{can_port + i}"
        spec = {"udp": f"udp:239.74.163.2:{can_port + i}", SIL: f"mem:{i}", PIL: pil}.get(kind, f"socketcan:vcan{i}")
        out.append(f"{spec}@{','.join(map(str, b.drives))}")
    return out


_LOADS: dict[str, dict[str, float]] = {}  # by the arguments: the runs of a tuning share a few wirings


def topology_load_pct(topology: list[busload.Bus], rate_hz: float = param_default("controller", "rate"),
                      protocol: str = DEFAULT_PROTOCOL, every: dict[str, int] | None = None) -> dict[str, float]:
    """Worst-case load of each bus of the topology at the loop rate (tools/armctl busload; CANopen:
    busload.canopen_load from the contract's PDO mapping and the PDOs' transmission types).
    Computed once per process and arguments (6 ms, a tenth of a tuning run's own Python)."""
    key = repr((topology, rate_hz, protocol, sorted((every or {}).items())))
    if key not in _LOADS:
        _LOADS[key] = _load_pct(topology, rate_hz, protocol, every)
    return dict(_LOADS[key])


def _load_pct(topology: list[busload.Bus], rate_hz: float, protocol: str,
              every: dict[str, int] | None) -> dict[str, float]:
    if protocol == "canopen":
        return {b.name: round(busload.canopen_load(b, len(b.drives), rate_hz, constant("heartbeat-ms"), every) * 100.0,
                              2) for b in topology}
    loads = busload.compute(topology, rate_hz, constant("heartbeat-ms"), busload.default_protocol(),
                            max(d for b in topology for d in b.drives))
    return {bl.bus.name: round(bl.load * 100.0, 2) for bl in loads}


def bus_timing_mode(mode: str) -> str:
    """host_sim's bus timing for a run mode: lockstep has no wall clock to delay frames on."""
    return "virtual" if mode == "lockstep" else "wallclock"


def resolve_bus(choice: str, n_buses: int = 1) -> tuple[str, str]:
    """(udp|vcan, why): auto takes vcan when the kernel has SocketCAN and vcan0..vcan<n-1> are up."""
    from tools.vcan import can_interfaces, kernel_has_can

    if choice in ("udp", SIL):
        return choice, "asked for" if choice == "udp" else "one process: the controller and the drives, frames in memory"
    if choice == VM:
        from tools.vm.run import VCAN_IFACES

        if n_buses > len(VCAN_IFACES):
            raise HilError(f"--bus vm: the topology has {n_buses} buses; the VM has {len(VCAN_IFACES)} "
                           f"({', '.join(VCAN_IFACES)})")
        return "vcan", f"inside the qemu VM, whose kernel has {', '.join(vcan_names(n_buses))} (tools/vm)"
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
        raise HilError(f"--bus: unknown bus '{choice}' (auto, udp, vcan, {VM}, sil)")
    if has_vcan:
        return "vcan", f"this kernel has SocketCAN and {', '.join(names)}"
    return "udp", why or f"no {', '.join(missing)} interface"


# Bounds of a hung process inside the VM, which emulates the machine: programs run 20-260x slower
# there (tools/vm/README.md), so a period's work takes up to a quarter of a second.
VM_DEADLINE_S = (3000.0, 600.0)  # + this per simulated second
VM_LOGGER_READY_S = 120.0


def _run_processes_in_vm(opt: HilOptions, plan: ProcessPlan) -> tuple[dict[str, int | None], float, str]:
    """run_processes(plan), inside the VM: the plan and the result pass through the run's folder."""
    import sys

    from gen.lib.paths import env_with_repo
    from tools.vm.run import run_in_vm

    plan_file, result_file, log_file = (opt.out / name for name in VM_FILES)
    write_text_atomic(plan_file, plan_json(plan))
    with open(log_file, "w") as log:
        res = run_in_vm([sys.executable, "-m", "tools.run.processes", str(plan_file), str(result_file)], cwd=REPO,
                        env=env_with_repo(), timeout=plan.deadline_s + 600.0, stdout=log, stderr=log,
                        log=lambda m: print(m, file=log, flush=True))
    result = _load_json(result_file)
    if res.timed_out or res.returncode != 0 or not result:
        why = "timed out" if res.timed_out else f"exit {res.returncode}"
        raise HilError(f"the run inside the VM ended without a result ({why}): {last_line(log_file)}; see {log_file}")
    if "error" in result:
        raise HilError(result["error"])
    codes = {k: (None if v is None else int(v)) for k, v in result["exit_codes"].items()}
    return codes, float(result["wall_s"]), f"{result['simulator_scheduling']} (in the VM)"


def run_hil(opt: HilOptions) -> dict[str, Any]:
    """One HIL run in a run slot of its own (its bus and telemetry ports, unless given); a
    software-in-the-loop run needs no ports."""
    if opt.bus == SIL:
        return _run_hil(opt, 0, 0)
    if opt.can_port is not None and opt.lcm_port is not None:
        return _run_hil(opt, opt.can_port, opt.lcm_port)
    with acquire_slot(quiet_ports=True) as slot:
        return _run_hil(opt, opt.can_port or slot.can_port, opt.lcm_port or slot.lcm_port)


def _run_sil(opt: HilOptions, exe: Path, ctl_args: list[str], sim_args: list[str],
             log_path: Path) -> tuple[dict[str, int | None], float, str]:
    """arm_sil: the controller and the simulator in one process, one thread."""
    t0 = time.monotonic()
    with open(opt.out / "sil.log", "w") as log:
        try:
            p = procs_mod.spawn("controller", [str(exe), "--telemetry-log", str(log_path), "--controller", *ctl_args,
                                               "--simulator", *sim_args],
                                watches_parent=True, cwd=REPO, stdout=log, stderr=subprocess.STDOUT)
        except InterruptedError as exc:
            raise HilError(str(exc)) from None
        try:
            _wait_sil(opt, p, log)
        finally:
            if p.poll() is None:
                p.kill()
                p.wait()
            procs_mod.forget(p)
    return {"sil": p.returncode}, time.monotonic() - t0, "one thread with the controller (software in the loop)"


def capture_args(opt: HilOptions) -> list[str]:
    if not opt.capture:
        return []
    return ["--capture", str(opt.out / CAPTURE_FILE), *(["--capture-clock", "wall"] if opt.mode == "realtime" else [])]


def _compress(path: Path) -> Path:
    """path.gz (python-can's LogReader reads it as it is; zcat it for canplayer and cantools)."""
    import gzip
    import shutil

    gz = path.with_name(path.name + ".gz")
    with open(path, "rb") as src, gzip.open(gz, "wb", compresslevel=1) as dst:  # fast: 4-5x smaller still
        shutil.copyfileobj(src, dst, 1 << 20)
    path.unlink()
    return gz


def _wait_sil(opt: HilOptions, sil: subprocess.Popen[bytes], log: Any) -> None:
    """Until arm_sil has ended; a refused argument ends the run with its message. A timer kills a
    hung one: Popen.wait with a timeout polls (up to 50 ms late), and a SIL run takes 0.1 s."""
    import threading

    hung = threading.Event()

    def kill() -> None:
        hung.set()
        sil.kill()

    timer = threading.Timer(120.0 + 60.0 * opt.duration_s, kill)
    timer.start()
    try:
        sil.wait()
    finally:
        timer.cancel()
    if hung.is_set():
        raise HilError(f"{sil.args[0]} did not finish in time; killed")
    if sil.returncode == USAGE_ERROR:
        log.flush()
        raise HilError(f"arm_sil refused its arguments: {last_line(opt.out / 'sil.log')}")


def canopen_args(info: dict[str, Any], drive_config: Path | None) -> tuple[list[str], list[str], Any]:
    """From the arm's drive table (gen/drives.py): arm_controller's --node per joint (joint order),
    the PDOs' transmission types, the heartbeats and the master's id; arm_sim's --node presets (the
    same specs and the max torque of a motor the importer sized: its drives start with the table's
    scaling, as drives commissioned for this arm); and the table itself."""
    from gen import drives as drives_mod

    try:
        cfg = drives_mod.load(info, drive_config)
    except drives_mod.DrivesError as exc:
        raise HilError(f"drive configuration: {exc}") from None
    node_args = [a for d in sorted(cfg.drives, key=lambda d: d.drive) for a in ("--node", d.node_spec())]
    sim_node_args = [a for d in sorted(cfg.drives, key=lambda d: d.drive) for a in ("--node", d.node_spec(sim=True))]
    t = cfg.transmission
    ctl = [*node_args, *(["--rpdo-type", str(t["rpdo1"])] if t["rpdo1"] != 1 else []),
           *(["--tpdo2-type", str(t["tpdo2"])] if t["tpdo2"] != 1 else []),
           "--heartbeat-ms", str(cfg.heartbeat_ms), "--consumer-ms", str(cfg.consumer_ms),
           "--master-id", str(cfg.master_id)]
    return ctl, sim_node_args, cfg


_CANOPEN_MEMO: dict[str, tuple[list[str], list[str], Any, str, str]] = {}


def canopen_of(info: dict[str, Any], drive_config: Path | None) -> tuple[list[str], list[str], Any, str, str]:
    """canopen_args(), the DBC that decodes a capture of these drives (gen/canopen_dbc.py) and the
    emulated drives' dictionary from the table's EDS or DCF (gen/eds.py), made once per arm and
    drive file in a process: a study's runs all share them, and making them took 0.9 s of a 0.4 s run."""
    from gen import canopen_dbc
    from gen import eds as eds_mod

    files = [drive_config] if drive_config is not None else []
    key = json.dumps([info, [(str(f), f.stat().st_mtime_ns) for f in files if f.exists()]], sort_keys=True, default=str)
    if key not in _CANOPEN_MEMO:
        ctl, node, table = canopen_args(info, drive_config)
        try:
            dbc = canopen_dbc.dbc_text(table)
            od_table = eds_mod.table_text(eds_mod.load(Path(table.eds)))
        except (canopen_dbc.DbcError, eds_mod.EdsError) as exc:
            raise HilError(str(exc)) from None
        _CANOPEN_MEMO[key] = (ctl, node, table, dbc, od_table)
    return _CANOPEN_MEMO[key]


def canopen_record(controller: dict[str, Any]) -> dict[str, Any] | None:
    """run.json's record of the CANopen boot: its time, first fault, every SDO write per node, and
    each joint's drive's units as the boot read them."""
    co = controller.get("canopen")
    if co is None:
        return None
    per_node: dict[str, list[dict[str, Any]]] = {}
    for w in co.get("sdo_writes", []):
        per_node.setdefault(str(w["node"]), []).append(
            {"object": f"0x{w['index']:04X}:{w['sub']:02X}", "index": w["index"], "sub": w["sub"],
             "value": w["value"], "bytes": w["bytes"]})
    return {"boot_s": co.get("boot_s"), "fault": co.get("fault"), "sdo_writes": per_node,
            "units": co.get("units"), "q_first_rad": co.get("q_first_rad")}


PIL_FILE = "pil.json"  # what the image measured in the loop (tools/pil_bridge)
# Bounds of a hung PIL run: the emulated MCU runs its loop 50-100x slower than real time here
# (docs/pil.md: QEMU hands it its UARTs' bytes one at a time), slower still on a loaded machine.
PIL_DEADLINE_S = (600.0, 600.0)  # + this per simulated second


def _pil_bus(opt: HilOptions, n_buses: int) -> tuple[str, str]:
    from tools.build.cortex_m import MACHINES

    if opt.target not in MACHINES:
        raise HilError(f"--target {opt.target}: expected one of {', '.join(MACHINES)}")
    if opt.mode != "lockstep":
        raise HilError("--target: the MCU image runs lockstep (SysTick paces its SYNC; QEMU counts instructions, "
                       "not the host's time): --mode lockstep")
    if n_buses > PIL_UARTS:
        raise HilError(f"--target: the topology has {n_buses} buses; the image has {PIL_UARTS} SLCAN UARTs")
    return PIL, (f"processor in the loop: SLCAN on the {opt.target} image's UARTs (QEMU {MACHINES[opt.target]}, "
                 f"-icount shift=0), the simulator on 127.0.0.1 TCP")


def pil_numeric(opt: HilOptions) -> list[str]:
    """The Cortex-M3 has no FPU: its image runs a method's fixed-point variant where it has one."""
    from tools.methods import firmware_methods

    if opt.target != "cortex-m3" or "--numeric" in opt.controller_args or not firmware_methods().get(opt.method):
        return []
    return ["--numeric", "fixed"]


def pil_bridge_argv(opt: HilOptions, bdir: Path, can_port: int) -> list[str]:
    """arm_pil_bridge's own arguments: the image of the target's build folder for this arm."""
    from tools.build.cortex_m import MACHINES, pil_image

    assert opt.target is not None
    image = pil_image(arm_build_dir(opt.target, opt.arm), opt.target)
    if not image.exists():
        raise HilError(f"{image} is missing: run tools/armctl build --target {opt.target}")
    bridge = bdir / "tools" / "pil_bridge" / "arm_pil_bridge"
    if not bridge.exists():
        raise HilError(f"{bridge} is missing: run tools/armctl build")
    return [str(bridge), "--machine", MACHINES[opt.target], "--image", str(image), "--port-base", str(can_port),
            "--pil-summary", str(opt.out / PIL_FILE)]


def pil_record(opt: HilOptions, rate_hz: float) -> dict[str, Any]:
    """run.json's `target`: the MCU, and what its image measured in the loop (pil.json), with the
    share of the period the control step takes at the stated clock."""
    from tools.build.cortex_m import MACHINES, STATED_CLOCK

    assert opt.target is not None
    measured = _load_json(opt.out / PIL_FILE)
    clock_hz, part = STATED_CLOCK[opt.target]
    steps = measured.get("step_instructions")
    cycles_per_period = clock_hz / rate_hz
    share = ({k: steps[k] / cycles_per_period for k in ("min", "median", "max")} if steps else None)
    return {"name": opt.target, "machine": MACHINES[opt.target], "stated_clock_hz": clock_hz, "stated_part": part,
            "step_instructions": steps,
            "step_share_of_period_at_stated_clock": share,
            "what": ("the control step (arm_ctl_step) measured on every period of the run, in instructions: SysTick "
                     "ticks under QEMU -icount shift=0, from a tick's edge to the next after the step; the share "
                     "assumes one instruction a cycle at the stated clock (no wait states, caches or stalls)"),
            "stack_high_water_bytes": measured.get("stack_high_water_bytes"),
            "slcan": measured.get("slcan"), "mcu_telemetry": measured.get("telemetry"),
            "link_frames_refused": measured.get("link_frames_refused")}


def _run_hil(opt: HilOptions, can_port: int, lcm_port: int) -> dict[str, Any]:
    started = datetime.now(timezone.utc)
    sil = opt.bus == SIL
    if sil and (opt.mode != "lockstep" or opt.controller_cmd_prefix or opt.controller is not None):
        raise HilError("--bus sil: software in the loop runs the arm's own controller build, in lockstep only")
    for group in () if sil or opt.bus == VM else (LCM_GROUP, CAN_GROUP):  # the VM routes its own (processes.py)
        check_loopback_route(group)
    bdir = arm_build_dir(opt.preset, opt.arm)
    try:
        info = arm_info(bdir)
    except ArmChoiceError as exc:
        raise HilError(str(exc)) from exc
    if opt.protocol not in PROTOCOLS:
        raise HilError(f"--protocol {opt.protocol}: expected one of {', '.join(PROTOCOLS)}")
    canopen = opt.protocol == "canopen"
    if canopen and opt.bus_timing and opt.mode != "lockstep":
        raise HilError("--bus-timing with --protocol canopen: lockstep only (the CiA 402 drives' frames are timed "
                       "virtually)")
    if opt.drive_config is not None and not canopen:
        raise HilError("--drive-config: a CiA 402 drive configuration, for --protocol canopen")
    node_args, sim_node_args, drive_table, dbc, od_table = (canopen_of(info, opt.drive_config) if canopen
                                                            else ([], [], None, "", ""))
    if opt.brakes not in BRAKES:
        raise HilError(f"brakes: {opt.brakes!r}: expected one of {', '.join(BRAKES)}")
    brakes = opt.brakes != "none"
    brake_table = drive_table if drive_table is not None or not brakes else canopen_args(info, opt.drive_config)[2]
    brake_args = [a for d in brake_table.drives if d.brake_spec() for a in ("--brake", d.brake_spec())] \
        if brakes and brake_table is not None else []
    if brake_args and opt.brakes == "released":
        brake_args += ["--brakes-at-start", "released"]
    transmission = drive_table.transmission if drive_table is not None else None
    rate_hz = _arg_value(opt.controller_args, "--rate", info["loop_rate_hz"])
    if canopen:
        assert transmission is not None
        if opt.bus_timing and transmission["rpdo1"] >= 254:
            raise HilError(f"--bus-timing: RPDO1 is event-driven (transmission type {transmission['rpdo1']}); the "
                           "bus timing of the CiA 402 drives models synchronous RPDOs (1-240)")
        topology, wiring = canopen_topology(opt.topology, info, rate_hz, transmission, opt.bus_timing)
    else:
        topology, wiring = load_topology(opt.topology, info), str(opt.topology or "the arm's wiring (arm.json)")
    substeps = sim_substeps(info, rate_hz)
    if opt.target is not None:
        bus_kind, bus_why = _pil_bus(opt, len(topology))
    else:
        bus_kind, bus_why = resolve_bus(opt.bus, len(topology))
    binary = opt.controller or controller_binary(bdir)
    logger_exe = logger_binary(bdir)
    sim_exe = bdir / "host_sim" / "native" / "arm_sim"
    sil_exe = bdir / "host_sim" / "native" / "arm_sil"
    for exe in (sil_exe,) if sil else (binary, logger_exe, sim_exe):
        if not exe.exists():
            raise HilError(f"{exe} is missing: run tools/armctl build")
    opt.out.mkdir(parents=True, exist_ok=True)
    for stale in ("telemetry.lcmlog", "controller_summary.json", "sim_summary.json", "run.json", "uncertainty.json", PIL_FILE,
                  CAPTURE_FILE, CAPTURE_FILE + ".gz", CANOPEN_DBC_FILE, CANOPEN_OD_FILE, *VM_FILES):
        (opt.out / stale).unlink(missing_ok=True)
    if drive_table is not None:  # what decodes a capture of this run, in SI units (gen/canopen_dbc.py)
        try:
            write_text_atomic(opt.out / CANOPEN_DBC_FILE, dbc)
            # the emulated drives are the drive table's drives: their dictionary from its EDS or DCF
            write_text_atomic(opt.out / CANOPEN_OD_FILE, od_table)
        except OutputError as exc:
            raise HilError(str(exc)) from None
        sim_node_args = [*sim_node_args, "--od", str(opt.out / CANOPEN_OD_FILE)]
    buses = bus_args(bus_kind, can_port, topology)
    bus_argv = [a for spec in buses for a in ("--bus", spec)]
    sim_buses = bus_args(bus_kind, can_port, topology, "simulator") if bus_kind == PIL else buses
    url = "" if sil else f"udpm://{LCM_GROUP}:{lcm_port}?ttl=0&recv_buf_size=8388608"
    log_path = opt.out / "telemetry.lcmlog"
    if opt.uncertainty is not None:
        try:
            write_json_atomic(opt.out / "uncertainty.json", opt.uncertainty)  # the record of what ran
        except OutputError as exc:
            raise HilError(str(exc)) from None
    sim_args = sim_argv(sim_exe, sim_buses, lcm_url=url, summary=opt.out / "sim_summary.json",
                        uncertainty=opt.uncertainty, timing=bus_timing_mode(opt.mode) if opt.bus_timing else "off",
                        phys=topology, model=prepared_model(bdir), drives=opt.drives, canopen=canopen,
                        extra=["--substeps", str(substeps), *([] if sil else sim_mode_args(opt.mode, opt.spin_us)),
                               *capture_args(opt), "--protocol", opt.protocol, *sim_node_args, *brake_args,
                               *opt.sim_args])
    ctl_args = [*opt.controller_cmd_prefix, str(binary), *bus_argv, "--lcm-url", url,
                "--duration", f"{opt.duration_s:g}", "--method", opt.method, "--mode", opt.mode,
                "--summary", str(opt.out / "controller_summary.json"), *([] if sil or opt.target else spin_args(opt.mode, opt.spin_us)),
                *(["--cpu", str(realtime_cpu(opt))] if opt.mode == "realtime" else []),
                "--protocol", opt.protocol, *node_args,
                *reference_args(info, opt.controller_args),
                *(["--design-file", str(opt.design_file)] if opt.design_file is not None else []), *opt.controller_args]
    if bus_kind == PIL:  # the bridge stands for the controller: it runs the image and relays it
        ctl_args = [*pil_bridge_argv(opt, bdir, can_port), "--", *ctl_args[1:], *pil_numeric(opt)]
    if sil:
        exit_codes, wall, sim_scheduling = _run_sil(opt, sil_exe, ctl_args[1:], sim_args[1:], log_path)
    else:
        in_vm = opt.bus == VM
        base_s, per_s = VM_DEADLINE_S if in_vm else PIL_DEADLINE_S if opt.target else (120.0, 60.0)
        plan = ProcessPlan(out=str(opt.out), mode=opt.mode, cpu=realtime_cpu(opt),
                           deadline_s=base_s + per_s * opt.duration_s,
                           logger=[str(logger_exe), "--lcm-url", url, str(log_path)], simulator=sim_args,
                           controller=ctl_args, cwd=str(REPO),
                           logger_ready_s=VM_LOGGER_READY_S if in_vm else LOGGER_READY_S,
                           multicast_routes=(f"{LCM_GROUP}/32",) if in_vm else ())
        exit_codes, wall, sim_scheduling = _run_processes_in_vm(opt, plan) if in_vm else run_processes(plan)

    # A process that died wrote no summary: the run still ends in a defined, named state and
    # the partial log is analysed.
    ctl_code = exit_codes.get("controller", exit_codes.get("sil"))
    sim_code = exit_codes.get("simulator", exit_codes.get("sil"))
    controller = _load_json(opt.out / "controller_summary.json") or {
        "result": ctl_code, "reason": f"controller died (exit code {ctl_code}); see {'sil' if sil else 'controller'}.log"}
    simulator = _load_json(opt.out / "sim_summary.json") or {
        "result": "died", "reason": f"simulator died (exit code {sim_code}); see {'sil' if sil else 'simulator'}.log"}
    config = {"method": opt.method, "mode": opt.mode, "duration_s": opt.duration_s,
              "joint_names": [j["name"] for j in info["joints"]],
              "arm": {"name": info["name"], "model": info["model"], "arm_file": info["arm_file"],
                      "model_hash": info["model_hash"], "n_joints": info["n_joints"], "warnings": info["warnings"]},
              "design": opt.design_record if opt.design_record is not None else info.get("design"),
              "ref_hold_s": _arg_value(opt.controller_args, "--ref-hold", CONTROLLER_DEFAULT_HOLD_S),
              "rate_hz": rate_hz,
              "controller_args": list(opt.controller_args),
              "uncertainty": opt.uncertainty, "drives": opt.drives.to_dict(),
              "bus_timing": bus_timing_mode(opt.mode) if opt.bus_timing else "off", "protocol": opt.protocol,
              **({"target": opt.target, "numeric": "fixed" if pil_numeric(opt) else "float"} if opt.target else {}),
              **opt.labels}
    from tools.run.run_analysis import analyse  # numpy: here, not for every importer of this module

    run = analyse(opt.out, controller, simulator, config, {
        "protocol": opt.protocol, "canopen": canopen_record(controller),
        # what the drive table fills for its drive's file, and what the boot skips (gen/drive_check.py)
        "canopen_drive_notes": sorted({f"{Path(drive_table.eds).name}: {n}" for d in drive_table.drives
                                       for n in d.notes}) if drive_table is not None else [],
        "bus": " ".join(buses), "bus_choice": f"{opt.bus} -> {bus_kind} ({bus_why})",
        "topology": {"source": wiring,
                     "buses": [{"name": b.name, "spec": spec.rpartition("@")[0], "kind": b.describe(),
                                "drives": b.drives} for b, spec in zip(topology, buses)]},
        "bus_load_pct": topology_load_pct(topology, rate_hz,
                                          opt.protocol, transmission),
        "canopen_transmission": transmission,
        "dbc": str(opt.out / CANOPEN_DBC_FILE) if canopen else str(busload.DEFAULT_DBC),
        "lcm_url": url, "wall_s": wall, "simulator_scheduling": sim_scheduling,
        # the simulator's speed: simulated seconds per wall second after boot, and its CPU time
        # per period (arm_sim measures both)
        "realtime_factor": simulator.get("realtime_factor"),
        "simulator_period_cost_us": simulator.get("period_cost_us"),
        "build": str(bdir),
        # the firmware's model (built in) and the one the simulator loaded: the controller refuses
        # to boot unless they agree (SIM_IDENTITY frame)
        "model_hash": {"firmware": info["model_hash"], "simulator": simulator.get("model_hash")},
        "exit_codes": exit_codes,
        "capture": str(_compress(opt.out / CAPTURE_FILE) if opt.compress_capture else opt.out / CAPTURE_FILE)
                   if opt.capture and (opt.out / CAPTURE_FILE).exists() else None},
        opt.bounds)
    if opt.target is not None:
        run["target"] = pil_record(opt, rate_hz)
    try:
        run["provenance"] = provenance(started)
        write_json_atomic(opt.out / "run.json", run)
    except OutputError as exc:
        raise HilError(str(exc)) from None
    return run
