"""The arm on its buses, for the commands that work with a real arm (armctl run, commission) or
stand in for one (armctl plant): which arm and build, its CiA 402 drive table, how the drives are
wired to the buses, and the buses themselves (--bus). And a controller session: the controller
alone on those buses, with the telemetry logger (no simulator: the arm is out there).

--bus, one syntax for the three commands:
  socketcan:IF[,IF...]  the interfaces, one per bus of the wiring, in order (real drives: can0, ...;
                        vcan0, ... to rehearse against armctl plant where the kernel has SocketCAN)
  vcan                  vcan0, vcan1, ... (a rehearsal: armctl plant --bus vcan on the same machine)
  udp[:PORT]            a rehearsal over UDP multicast on this host: bus i on PORT + i [43113]
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from gen.lib import busload
from gen.lib.params import param
from gen.lib.multicast import CAN_GROUP, LCM_GROUP, lcm_url
from gen.lib.paths import REPO, controller_binary, logger_binary
from tools.build.arm import ArmRef, arm_from_args, arm_info, build_arm, print_arm_warnings
from tools.errors import CommandError, UsageError
from tools.run import procs as procs_mod
from tools.run.processes import _logger_priority, _wait_for_logger
from tools.run.run_files import CONTROLLER_SUMMARY, TELEMETRY_LOG

ARPHRD_CAN = 280
IFF_UP = 0x1
DEFAULT_UDP_PORT = int(param("controller", "bus").default.rsplit(":", 1)[1])  # arm_controller's own default
LOGGER_READY_S = 120.0  # generous: in the qemu VM a program takes seconds to start (tools/vm/README.md)


@dataclass
class ArmOnBus:
    """Everything a controller (or the plant) needs to be the arm's on its buses."""
    arm: ArmRef
    bdir: Path
    info: dict[str, Any]
    table: Any                  # gen/drives.py DriveConfig
    node_args: list[str]        # arm_controller's --node ... --rpdo-type/--tpdo2-type (the table's)
    sim_node_args: list[str]    # arm_sim's --node presets
    topology: list[busload.Bus]
    wiring: str                 # where the wiring comes from
    kind: str                   # socketcan | vcan | udp
    interfaces: list[str]       # one per bus: IF names, or udp:GROUP:PORT specs
    rehearsal: bool             # udp or vcan: the arm is armctl plant, not a real one
    buses: list[str] = field(default_factory=list)  # --bus SPEC@DRIVES, one per bus

    @property
    def joint_names(self) -> list[str]:
        return [j["name"] for j in self.info["joints"]]

    def bus_args(self) -> list[str]:
        return [a for spec in self.buses for a in ("--bus", spec)]

    def describe_buses(self) -> list[str]:
        names = self.joint_names
        out = []
        for b, iface in zip(self.topology, self.interfaces):
            drives = ", ".join(f"{d} {names[d - 1]}" for d in b.drives)
            out.append(f"{iface} ({b.describe()}): drive(s) {drives}")
        return out


def add_bus_arguments(p: Any, default: str | None, prog_note: str) -> None:
    p.add_argument("--bus", default=default, metavar="SPEC",
                   help="socketcan:IF[,IF...] (one interface per bus of the wiring, in order), vcan (vcan0, vcan1, "
                        f"...) or udp[:PORT] (bus i on PORT + i; {DEFAULT_UDP_PORT} unless given){prog_note}")
    p.add_argument("--drive-config", type=Path, default=None, metavar="FILE",
                   help="the CiA 402 drive table (docs/drives-bring-up.md) [the arm's: its arm file's `drives`, "
                        "else firmware/protocol/drives.toml]")
    p.add_argument("--topology", type=Path, default=None, metavar="FILE",
                   help="which drive is on which bus and each bus's bit rate [the fewest classic 1 Mbit/s buses "
                        "that carry the drives at the loop rate, in drive order]")


def add_session_arguments(p: Any, record_help: str = "the arm's commissioning record [runs/commission/ARM-HASH.json, "
                                                     "where armctl commission keeps it]") -> None:
    """The arguments of a command that runs the controller on the arm's buses (run, commission,
    identify): the buses, the commissioning record (armctl commission writes it; run and identify
    read it) and the mode."""
    add_bus_arguments(p, None, "; the arm's interfaces [socketcan:can0,can1,...]")
    p.add_argument("--record", type=Path, default=None, metavar="FILE", help=record_help)
    add_mode_argument(p)


def add_mode_argument(p: Any) -> None:
    """--mode of a command that runs the controller on the arm's buses (run, commission, identify)."""
    p.add_argument("--mode", choices=("realtime", "lockstep"), default=None,
                   help="realtime on real interfaces; lockstep against armctl plant (udp, vcan), whose arm steps on "
                        "the controller's SYNC [by the bus]")


def parse_bus(text: str, n_buses: int) -> tuple[str, list[str]]:
    """(kind, one interface or UDP spec per bus) from --bus; UsageError naming the value."""
    if text == "vcan":
        return "vcan", [f"vcan{i}" for i in range(n_buses)]
    if text == "udp" or text.startswith("udp:"):
        port_s = text[4:] or str(DEFAULT_UDP_PORT)
        if not port_s.isdigit() or not 1024 <= int(port_s) <= 65535 - n_buses:
            raise UsageError(f"--bus {text}: udp:PORT with PORT in [1024, {65535 - n_buses}]")
        return "udp", [f"udp:{CAN_GROUP}:{int(port_s) + i}" for i in range(n_buses)]
    if text.startswith("socketcan:"):
        ifaces = text[len("socketcan:"):].split(",")
        if not all(ifaces) or len(set(ifaces)) != len(ifaces):
            raise UsageError(f"--bus {text}: socketcan:IF[,IF...], each interface once")
        if len(ifaces) != n_buses:
            raise UsageError(f"--bus {text}: {len(ifaces)} interface(s) for the wiring's {n_buses} bus(es)")
        return "socketcan", ifaces
    raise UsageError(f"--bus {text}: expected socketcan:IF[,IF...], vcan or udp[:PORT]")


def _sysfs(iface: str, name: str) -> str | None:
    try:
        return (Path("/sys/class/net") / iface / name).read_text().strip()
    except OSError:
        return None


def _link_details(iface: str) -> dict[str, Any]:
    """ip's view of the interface (its kind, its bit rate), {} where ip cannot say."""
    try:
        r = subprocess.run(["ip", "-details", "-json", "link", "show", iface], capture_output=True, text=True,
                           timeout=10)
        return json.loads(r.stdout)[0] if r.returncode == 0 else {}
    except (OSError, ValueError, IndexError, subprocess.TimeoutExpired):
        return {}


def check_interface(iface: str, bus: busload.Bus) -> bool:
    """That iface is a CAN interface, up, at the bus's bit rate; whether it is a virtual one (vcan).
    UsageError naming it otherwise, with the command that fixes it."""
    if not (Path("/sys/class/net") / iface).exists():
        from tools.vcan import can_interfaces

        have = ", ".join(i["name"] for i in can_interfaces()) or "none"
        raise UsageError(f"--bus socketcan:{iface}: no such interface (CAN interfaces here: {have})")
    if _sysfs(iface, "type") != str(ARPHRD_CAN):
        raise UsageError(f"--bus socketcan:{iface}: not a CAN interface (link type {_sysfs(iface, 'type')}, CAN is "
                         f"{ARPHRD_CAN})")
    info = _link_details(iface)
    kind = info.get("linkinfo", {}).get("info_kind", "")
    virtual = kind == "vcan" or (not kind and iface.startswith("vcan"))
    rate = int(bus.nominal_bps)
    flags = _sysfs(iface, "flags")
    if flags is not None and not int(flags, 16) & IFF_UP:
        fix = f"ip link set {iface} up" if virtual else f"ip link set {iface} up type can bitrate {rate}"
        raise UsageError(f"--bus socketcan:{iface}: the interface is down (as root: {fix})")
    have = info.get("linkinfo", {}).get("info_data", {}).get("bittiming", {}).get("bitrate")
    if not virtual and have is not None and int(have) != rate:
        raise UsageError(f"--bus socketcan:{iface}: its bit rate is {int(have)} bit/s, the wiring's {rate} bit/s "
                         f"(as root: ip link set {iface} down; ip link set {iface} up type can bitrate {rate})")
    return virtual


def arm_on_bus(ns: Any, prog: str) -> ArmOnBus:
    """The arm of --model/--arm, built (release), its drive table, wiring and buses, all checked
    before anything starts: bad input is UsageError (one line naming the file, object or value)."""
    from gen import drives as drives_mod
    from tools.run.hil import HilError, canopen_args, canopen_topology

    arm = arm_from_args(ns)
    bdir = build_arm("release", arm, targets=["arm_controller", "arm_sim", "arm_lcm_logger"])
    info = arm_info(bdir)
    print_arm_warnings(info, prog)
    if ns.drive_config is not None and not ns.drive_config.is_file():
        raise UsageError(f"--drive-config {ns.drive_config}: no such file")
    try:
        node_args, sim_node_args, table = canopen_args(info, ns.drive_config)
        topology, wiring = canopen_topology(ns.topology, info, info["loop_rate_hz"], table.transmission)
    except (HilError, drives_mod.DrivesError) as exc:
        raise UsageError(str(exc).removeprefix("drive configuration: ")) from None
    bus = ns.bus if ns.bus is not None else "socketcan:" + ",".join(f"can{i}" for i in range(len(topology)))
    kind, ifaces = parse_bus(bus, len(topology))
    rehearsal = kind != "socketcan"
    if kind == "socketcan":
        rehearsal = all([check_interface(i, b) for i, b in zip(ifaces, topology)])
    elif kind == "vcan":
        for i, b in zip(ifaces, topology):
            if not check_interface(i, b):
                raise UsageError(f"--bus vcan: {i} is not a vcan interface")
    setup = ArmOnBus(arm, bdir, info, table, node_args, sim_node_args, topology, wiring, kind,
                     [i.replace("udp:", "") if kind == "udp" else i for i in ifaces], rehearsal)
    specs = ifaces if kind == "udp" else [f"socketcan:{i}" for i in ifaces]
    setup.buses = [f"{spec}@{','.join(map(str, b.drives))}" for spec, b in zip(specs, topology)]
    return setup


def table_digest(table: Any) -> str:
    """sha256 of what the drives are configured from: the drive table's bytes and its EDS/DCF's."""
    h = hashlib.sha256()
    for p in (Path(table.path), Path(table.eds)):
        h.update(p.name.encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()


@dataclass
class SessionResult:
    code: int | None          # the controller's exit code
    summary: dict[str, Any]   # its summary ({} if it wrote none)
    out: Path
    interrupted: int | None   # the signal that stopped armctl (a user's Ctrl-C), if one did


def _echo(stream: Any, log: TextIO, prefix: str) -> None:
    for raw in iter(stream.readline, b""):
        line = raw.decode(errors="replace")
        log.write(line)
        log.flush()
        sys.stderr.write(prefix + line)
        sys.stderr.flush()


def brake_release_s(setup: ArmOnBus) -> float:
    """The drive table's longest brake release delay (s): a task holds the pose that long after the
    drives are enabled, so that nothing moves against a brake still closed."""
    return max((d.brake[2] / 1000 for d in setup.table.drives if d.brake is not None), default=0.0)


def run_controller(setup: ArmOnBus, ctl_args: list[str], out: Path, mode: str) -> SessionResult:
    """arm_controller alone on the arm's buses (and the telemetry logger), until it ends: the task
    ends, the arm faults, or a signal to armctl (Ctrl-C) makes it stop the arm. Its output is shown
    as it comes and kept in OUT/controller.log."""
    from tools.run.hil import check_loopback_route, spin_args
    from tools.run.slots import acquire_slot

    out.mkdir(parents=True, exist_ok=True)
    for stale in (CONTROLLER_SUMMARY, TELEMETRY_LOG, "controller.log", "logger.log"):
        (out / stale).unlink(missing_ok=True)
    check_loopback_route(LCM_GROUP)
    if setup.kind == "udp":
        check_loopback_route(CAN_GROUP)
    with acquire_slot(quiet_ports=True) as slot:
        url = lcm_url(slot.lcm_port, recv_buf=True)
        realtime = mode == "realtime"
        cpu = (os.cpu_count() or 1) - 1  # the loop's CPU, as a HIL run's (tools/run/hil.py realtime_cpu)
        ctl = [str(controller_binary(setup.bdir)), *setup.bus_args(), "--lcm-url", url, "--protocol", "canopen",
               *setup.node_args, "--mode", mode, "--summary", str(out / CONTROLLER_SUMMARY),
               *(["--cpu", str(cpu)] if realtime else spin_args(mode)), "--brake-release", f"{brake_release_s(setup):g}",
               *ctl_args]
        (out / "controller.argv").write_text(json.dumps(ctl) + "\n")
        print(f"  telemetry: {url} (ARM_CTL: q, q_d, tau; ARM_EVENT), logged to {out / 'telemetry.lcmlog'}")
        sys.stdout.flush()
        with open(out / "logger.log", "w") as llog, open(out / "controller.log", "w") as clog:
            try:
                logger = procs_mod.spawn("logger", [str(logger_binary(setup.bdir)), "--lcm-url", url,
                                                    str(out / TELEMETRY_LOG)], stdout=subprocess.PIPE,
                                         stderr=llog, preexec_fn=_logger_priority if realtime else None)
            except InterruptedError as exc:
                raise CommandError(str(exc)) from None
            try:
                from tools.run.processes import HilError

                try:
                    _wait_for_logger(logger, LOGGER_READY_S)
                except HilError as exc:
                    raise CommandError(str(exc)) from None
                try:
                    p = procs_mod.spawn("controller", ctl, watches_parent=True, cwd=REPO, stdout=subprocess.PIPE,
                                        stderr=subprocess.STDOUT)
                except InterruptedError as exc:
                    raise CommandError(str(exc)) from None
                reader = threading.Thread(target=_echo, args=(p.stdout, clog, ""), daemon=True)
                reader.start()
                p.wait()
                reader.join(timeout=5)
                procs_mod.forget(p)
            finally:
                procs_mod.interrupt_and_reap(logger, 10)
                if logger.stdout is not None:
                    logger.stdout.close()
    try:
        summary = json.loads((out / CONTROLLER_SUMMARY).read_text())
    except (OSError, ValueError):
        summary = {}
    return SessionResult(p.returncode, summary, out, procs_mod.interrupted)

