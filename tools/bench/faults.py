"""`armctl faults`: every fault against a short lockstep run (realtime where the fault is about
the wall clock: a second master between the controller's periods), as a table.

For each fault a HIL run starts (pm, the default arm, its own run slot) with the arm held at its
most gravity-loaded pose (tools/bench/loaded_pose.py) and the drives' brakes of the arm's drive
table; once the controller is tracking, the fault is injected from outside: a signal to a process,
frames on a bus (garbage, spoofed joint states or torque commands, a flood), a drive reporting a
fault, a lost bus (the simulator's --debug-lose-bus test hook), a stalled logger. The table says,
from the bus and the run's own records: after how many periods the arm was stopped (the first
quick stop, disable or shutdown command or NMT stop, or the drives faulting), whether a safe state
was reached and which, how far each joint moved in the window after the stop (run.json's
results.stop, from the simulator's truth: the simulator runs the arm on after the controller stopped
or died), the run's verdict, and whether the telemetry is complete. A row whose arm moved more than
the bound after its stop fails the command; a row where it cannot be measured says why. One row's
fault is in the input itself (hostile-names: the arm's model names its joints with C, a script and
a shell command, as a downloaded file may): its arm is built and run like any other, its names are
data (gen/lib/escape.py), and the row fails if anything of the file ran. tests/python/test_faults.py
holds every row.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import can

from gen.lib.atomic_output import write_json_atomic
from gen.lib.multicast import CAN_GROUP, lcm_url
from host_sim.canbus import open_bus
from tools.run.hil import HilOptions, run_hil
from gen.lib.paths import REPO
from tools.run.run_files import SIM_SUMMARY
from tools.run.slots import acquire_slot
from gen.lib.params import constant, default as param_default

SYNC, NMT = 0x080, 0x000
LOST_BUS_PERIOD = 1500
# what a stop sends each drive first (CiA 402 controlwords, little-endian): quick stop, disable
# voltage, shutdown
STOP_CONTROLWORDS = (b"\x02\x00", b"\x00\x00", b"\x06\x00")
MOVED_BOUND_DEG = constant("max-moved-after-stop-deg")
# Where the arm's motion after a stop cannot be measured, and why (no truth after it).
UNMEASURED = {
    "kill-simulator": "the simulator is the arm: killed (SIGKILL), it simulates nothing after (a real arm's drives lose "
                      "their supply there, and their spring-applied brakes close: term-simulator runs that path)",
    "kill-logger": "the logger is the record: killed, the log holds no simulator truth of the stop (the simulator's "
                   "own account of the window after the controller fell silent is the row's stop.simulator.moved_deg)",
}
GROUP = CAN_GROUP


@dataclass
class Fault:
    name: str
    what: str                                  # what is done
    inject: Callable[["Injector"], None]
    expect_stop: bool                          # the arm must end stopped (a named fault, never ok)
    sim_args: tuple[str, ...] = ()
    mode: str = "lockstep"                     # the run's mode (tools/run/hil.py)
    arm: Callable[[], Any] | None = None       # the arm to run (a tools.build.arm.ArmRef): None, the bundled one


class Injector:
    """Watches the run's first bus (SYNC counts, commands) and injects the fault once tracking."""

    def __init__(self, can_port: int) -> None:
        self.port = can_port
        self.bus0 = open_bus(f"udp:{GROUP}:{can_port}")
        self.bus1 = open_bus(f"udp:{GROUP}:{can_port + 1}")
        self.syncs = 0
        self.counter = 0
        self.tracking_syncs: int | None = None
        self.injected_at: int | None = None
        self.stopped_at: int | None = None
        self.stop_event = threading.Event()
        self.frames_sent = 0
        self.lcm_port = 0
        self.problem: str | None = None        # why the watcher or the injection failed, if it did
        self.acted = False                     # a signal was sent or a frame injected (into a running arm)

    def pids(self, exe: str) -> list[int]:
        """The processes of this run (their command line names its bus port)."""
        r = subprocess.run(["pgrep", "-f", f"{exe} .*{GROUP}:{self.port}@"], capture_output=True, text=True)
        if exe == "arm_lcm_logger":
            # a pattern: the URL's '?' and '.' taken as they are written
            r = subprocess.run(["pgrep", "-f", f"arm_lcm_logger --lcm-url {re.escape(lcm_url(self.lcm_port))}"],
                               capture_output=True, text=True)
        return [int(x) for x in r.stdout.split()]

    def signal(self, exe: str, sig: int, then: int | None = None, after_s: float = 0.0) -> None:
        for pid in self.pids(exe):
            os.kill(pid, sig)
            self.acted = True
        if then is not None:
            time.sleep(after_s)
            for pid in self.pids(exe):
                os.kill(pid, then)

    def send(self, bus: can.BusABC, msgs: list[can.Message]) -> None:
        for m in msgs:
            bus.send(m)
            self.frames_sent += 1
            self.acted = True

    def on_each_sync(self, make: Callable[[int], list[can.Message]], bus: int = 0, periods: int = 200) -> None:
        """Answers the next `periods` SYNCs (with their counter) with make(counter)."""
        target = self.bus0 if bus == 0 else self.bus1
        seen = self.syncs
        while self.syncs < seen + periods and not self.stop_event.is_set():
            if self.syncs > seen:
                seen = self.syncs
                self.send(target, make(self.counter))
            time.sleep(0.0002)



def _state(drive: int, counter: int, q: int = 2**31 - 1, statusword: int = 0x0237) -> can.Message:
    data = struct.pack("<iiiHBB", q, q, q, statusword, counter, 0)
    return can.Message(arbitration_id=0x180 + drive, data=data, is_extended_id=False, is_fd=True, bitrate_switch=True)


FAULTS = [
    Fault("kill-controller", "SIGKILL to the controller", lambda i: i.signal("arm_controller", signal.SIGKILL), True),
    Fault("kill-simulator", "SIGKILL to the simulator", lambda i: i.signal("arm_sim", signal.SIGKILL), True),
    Fault("kill-logger", "SIGKILL to the telemetry logger", lambda i: i.signal("arm_lcm_logger", signal.SIGKILL),
          False),
    Fault("stop-controller", "SIGSTOP to the controller for 2 s (lockstep: the simulator waits)",
          lambda i: i.signal("arm_controller", signal.SIGSTOP, signal.SIGCONT, 2.0), False),
    Fault("stop-simulator", "SIGSTOP to the simulator for 2 s",
          lambda i: i.signal("arm_sim", signal.SIGSTOP, signal.SIGCONT, 2.0), True),
    Fault("term-controller", "SIGTERM to the controller", lambda i: i.signal("arm_controller", signal.SIGTERM), True),
    Fault("term-simulator", "SIGTERM to the simulator", lambda i: i.signal("arm_sim", signal.SIGTERM), True),
    Fault("garbage", "undecodable datagrams and wrongly typed frames on bus 0",
          lambda i: _garbage(i), False),
    Fault("spoofed-states", "DRIVE_1_STATE with INT32_MAX values and the right SYNC counter",
          lambda i: i.on_each_sync(lambda c: [_state(1, c)]), True),
    Fault("spoofed-commands", "DRIVE_4_CMD of 2147 Nm (enable operation) with the right counter, bus 1",
          lambda i: i.on_each_sync(lambda c: [can.Message(arbitration_id=0x204, is_extended_id=False,
                                                          data=struct.pack("<HiBx", 0x000F, 2**31 - 1, c))], bus=1),
          True),
    Fault("flood", "10,000 frames of an unknown id on bus 0", lambda i: i.send(
        i.bus0, [can.Message(arbitration_id=0x5AA, data=bytes(8), is_extended_id=False)] * 10000), False),
    Fault("drive-fault", "drive 2 reports fault (statusword 0x0218) and EMCY 0x2310 (overcurrent)",
          lambda i: _drive_fault(i), True),
    Fault("lost-bus", "bus 1 goes silent (the simulator's --debug-lose-bus test hook)", lambda i: None, True,
          ("--debug-lose-bus", f"1@{LOST_BUS_PERIOD}")),
    Fault("stalled-logger", "SIGSTOP to the telemetry logger for 0.5 s",
          lambda i: i.signal("arm_lcm_logger", signal.SIGSTOP, signal.SIGCONT, 0.5), False),
    Fault("forged-telemetry", "another process republishes 400 ARM_SIM messages (simulator truth, w_true = 0) "
          "on the run's telemetry port, with the simulator's own sequence numbers", lambda i: _forge_truth(i), False),
    Fault("second-master", "realtime: a second master sends its own SYNC periods on bus 1, each with a "
          "DRIVE_6_CMD of 0.2 N m, three times", lambda i: _second_master(i), True, mode="realtime"),
    Fault("hostile-names", "the model's joint names carry C (a constructor that touches a file), a script and a "
          "shell command substitution", lambda i: setattr(i, "acted", True), False, arm=lambda: _hostile_arm()),
]

# hostile-names: the model a user might have downloaded, and what its C would touch if it ever ran
HOSTILE_DIR = REPO / "build" / "faults"
HOSTILE_MARKER = HOSTILE_DIR / "hostile-names.ran"


def hostile_names() -> dict[str, str]:
    """The bundled arm's joint names as an attacker would set them (old name -> new)."""
    return {"elbow": ('a"}; extern int system(const char *); __attribute__((constructor)) static void '
                      f'hostile_ctor(void) {{ system("touch {HOSTILE_MARKER}"); }} static const char *const '
                      'hostile_tail[] __attribute__((used)) = {"b'),
            "shoulder_lift": "lift<script>document.title='hostile'</script>",
            "wrist_1": "w1*/ int hostile_c; /* $(touch /tmp/hostile) `id` %s%n",
            "wrist_2": "w2\\\" \\n ??/ é"}


def _hostile_arm() -> Any:
    """The bundled arm's MJCF with hostile_names(), at a fixed path (one build folder for every run)."""
    import xml.etree.ElementTree as ET

    from tools.build.arm import ArmRef

    names = hostile_names()
    root = ET.parse(REPO / "host_sim" / "models" / "ur5e_arm.xml").getroot()
    for el in root.iter():
        for attr in ("name", "joint"):
            if el.tag in ("joint", "motor") and el.get(attr) in names:
                el.set(attr, names[el.get(attr, "")])
    text = ET.tostring(root, encoding="unicode")
    path = HOSTILE_DIR / "hostile-names.xml"
    HOSTILE_DIR.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text() != text:
        path.write_text(text)
    return ArmRef(path.resolve())


def _forge_truth(i: Injector) -> None:
    """Telemetry that would make the estimation error look better than it was, had it gone unseen."""
    import lcm

    from gen import lcmtypes

    lc = lcm.LCM(lcm_url(i.lcm_port))
    m = lcmtypes.load().sim_truth_t()
    m.n = 6
    m.q = m.qd = m.tau_applied = m.w_true = [0.0] * 6
    for k in range(400):
        m.seq = m.step = k
        lc.publish("ARM_SIM", m.encode())
        i.frames_sent += 1
        i.acted = True


def _second_master(i: Injector) -> None:
    """Another master between the controller's periods: its own SYNC counter, and a command for it
    (a drive that followed it would apply the foreign torque)."""
    for burst in range(3):
        c = (i.counter + 128) & 0xFF
        i.send(i.bus1, [can.Message(arbitration_id=SYNC, data=bytes([c]), is_extended_id=False),
                        can.Message(arbitration_id=0x206, is_extended_id=False,
                                    data=struct.pack("<HiBx", 0x000F, 200_000, c))])
        time.sleep(0.05)


def _drive_fault(i: Injector) -> None:
    """The EMCY at once (it needs no SYNC, as on a real bus: the watcher here trails a lockstep run
    that goes 12x real time, and waiting for SYNCs could miss the run), then the fault statusword
    answering the next SYNCs."""
    emcy = can.Message(arbitration_id=0x082, is_extended_id=False, data=struct.pack("<HBi", 0x2310, 1, 0) + bytes(1))
    i.send(i.bus0, [emcy])
    i.on_each_sync(lambda c: [_state(2, c, q=0, statusword=0x0218), emcy], periods=3)


def _garbage(i: Injector) -> None:
    import socket

    import msgpack

    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
    s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
    junk = [b"", b"\xff" * 7, msgpack.packb({"arbitration_id": [128], "data": b"\x01", "dlc": 1}),
            msgpack.packb({"arbitration_id": "x"}), msgpack.packb([1, 2, 3])]
    for _ in range(200):
        for j in junk:
            s.sendto(j, (GROUP, i.port))
            i.frames_sent += 1
            i.acted = True
    s.close()


def _watch(inj: Injector) -> None:
    """Counts the SYNCs on bus 0 and notes when tracking began and when the controller stopped the drives."""
    while not inj.stop_event.is_set():
        try:
            m = inj.bus0.recv(0.05)
        except Exception as exc:  # noqa: BLE001 - python-can's decoder raises many kinds on odd datagrams
            inj.problem = inj.problem or f"watcher: {type(exc).__name__}: {exc}"
            continue
        if m is None:
            continue
        if m.arbitration_id == SYNC and m.dlc >= 1:
            inj.syncs += 1
            inj.counter = m.data[0]
        elif inj.injected_at is not None and inj.stopped_at is None and (
                (m.arbitration_id == NMT and m.data[:1] == b"\x02") or
                (0x201 <= m.arbitration_id <= 0x210 and bytes(m.data[:2]) in STOP_CONTROLWORDS)):
            inj.stopped_at = inj.syncs
        elif inj.tracking_syncs is None and 0x201 <= m.arbitration_id <= 0x210 and m.data[:2] == b"\x0f\x00":
            inj.tracking_syncs = inj.syncs


def _inject_after_tracking(f: Fault, inj: Injector) -> None:
    """The fault, injected after 0.3 s of tracking."""
    deadline = time.monotonic() + 60
    while (inj.tracking_syncs is None or inj.syncs < inj.tracking_syncs + 300) and time.monotonic() < deadline:
        if inj.stop_event.is_set():
            inj.problem = inj.problem or f"the run ended before tracking was seen ({inj.syncs} SYNCs seen)"
            return
        time.sleep(0.005)
    inj.injected_at = inj.syncs
    try:
        f.inject(inj)
    except (OSError, can.CanError) as exc:
        inj.problem = inj.problem or f"injection: {type(exc).__name__}: {exc}"


def _run_with_injector(f: Fault, out: Path, pose: list[float], arm: Any) -> tuple[dict[str, Any], Injector]:
    """One HIL run with the watcher and the injector beside it on the run slot's buses."""
    with acquire_slot() as slot:
        inj = Injector(slot.can_port)
        inj.lcm_port = slot.lcm_port
        threads = [threading.Thread(target=_watch, args=(inj,), daemon=True),
                   threading.Thread(target=_inject_after_tracking, args=(f, inj), daemon=True)]
        for t in threads:
            t.start()
        try:
            # the arm protocol's frames are what the injectors forge (its DBC); the CiA 402 drives'
            # faults are tests/python/test_canopen_hil.py's and test_canopen_master.py's
            # held at the most loaded pose the whole run: a zero reference (the default frequencies)
            zeros = ",".join("0" for _ in pose)
            run = run_hil(HilOptions(out=out, duration_s=8.0, method="pm", can_port=slot.can_port, protocol="arm",
                                     lcm_port=slot.lcm_port, mode=f.mode, arm=arm,
                                     sim_args=("--start-pose", ",".join(f"{x:.9g}" for x in pose), *f.sim_args),
                                     controller_args=("--ref-amp", zeros, "--ref-freq", ",".join("0.2" for _ in pose))))
        finally:
            inj.stop_event.set()
            for t in threads:
                t.join(5)
            inj.bus0.shutdown()
            inj.bus1.shutdown()
    return run, inj


def _unmeasured(f: Fault, stop: dict[str, Any]) -> str | None:
    """Why the arm's motion after the stop is not measured (None: it is)."""
    window = float(stop.get("window_s") or param_default("simulator", "post-stop"))
    covered = float(stop.get("after_stop_covered_s") or 0.0)
    if f.name in UNMEASURED:
        return UNMEASURED[f.name]
    if stop.get("moved_after_stop_deg") is None:
        return stop.get("after_stop_problem") or "no stop was found (neither the controller nor the simulator " \
                                                 "recorded one)"
    if covered + 1e-9 < window:
        return f"the simulator's truth covers {covered:.3f} s of the {window:g} s after the stop"
    return None


def run_fault(f: Fault, out: Path, pose: list[float]) -> dict[str, Any]:
    from tools.build.arm import DEFAULT_ARM, HIL_TARGETS, build_arm

    arm = f.arm() if f.arm is not None else DEFAULT_ARM
    if f.arm is not None:
        HOSTILE_MARKER.unlink(missing_ok=True)
        build_arm("release", arm, targets=HIL_TARGETS)
    run, inj = _run_with_injector(f, out, pose, arm)
    r = run["results"]
    sim = _load(out / SIM_SUMMARY)
    faulted = bool(sim.get("drive_fault_mask")) or bool(r.get("drive_faults"))
    if f.name == "lost-bus":
        inj.injected_at = LOST_BUS_PERIOD  # the simulator's period, counted like the SYNCs seen
        inj.acted = True  # the simulator's own hook
    stopped = r.get("final_state") in ("fault", "safe-stop") or faulted  # not the run's normal end
    detected = (inj.stopped_at - inj.injected_at) if stopped and inj.stopped_at is not None \
        and inj.injected_at is not None else None
    transport = run.get("transport", {})
    # messages that cannot come from the run's own senders (tools/run/run_analysis.py), summed over channels
    foreign = sum(a.get("foreign", 0) for a in (transport.get("telemetry") or {}).values())
    stop = r.get("stop") or {}
    moved = stop.get("moved_after_stop_deg")
    unmeasured = _unmeasured(f, stop)
    return {"fault": f.name, "what": f.what, "detected_after_periods": detected, "safe_state": stopped,
            "stop": {k: stop.get(k) for k in ("cause", "from_bus_period", "found_by", "safe_state", "braked",
                                              "simulator")},
            "moved_after_stop_deg": None if unmeasured else max(moved),
            "moved_after_stop_per_joint_deg": moved if not unmeasured else None,
            "moved_unmeasured": unmeasured,
            "final_state": r.get("final_state"), "drives_faulted": faulted, "verdict": r.get("result"),
            "reasons": r.get("verdict_reasons", []), "telemetry_lost": transport.get("telemetry_lost_total"),
            "telemetry_foreign": foreign, "expect_stop": f.expect_stop,
            "injected": inj.acted, "harness_problem": inj.problem or (None if inj.acted else
                                                                     "nothing sent while the arm ran"),
            # a file of the input's ran code on this machine (hostile-names: its constructor touched the marker)
            "input_ran_code": f.arm is not None and HOSTILE_MARKER.exists(),
            "counters": {"controller": transport.get("controller_frames", {}),
                         "simulator": transport.get("simulator_frames", {})}}


def _load(path: Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def _safe_state(x: dict[str, Any]) -> str:
    """Where the arm ended: braked by the controller's stop, braked by the drives' own reaction (the
    controller gone), or neither."""
    stop = x.get("stop") or {}
    sim = stop.get("simulator") or {}
    braked = bool(sim.get("braked")) and all(sim["braked"])
    if not x["safe_state"]:
        how = "no stop needed"
    elif stop.get("braked"):
        how = "braked (quick stop)"
    elif braked:
        how = "braked (drives' reaction)"
    else:
        how = "drives faulted, torque off" if x["drives_faulted"] else "stopped, brakes unconfirmed"
    return f"{how}, {x['final_state']}" if not x["safe_state"] else how


def table(rows: list[dict[str, Any]]) -> str:
    lines = [f"{'fault':<18}{'detected in':>12}  {'safe state':<28}{'moved after':>12}  {'verdict':<26}{'telemetry':<12}",
             f"{'':<18}{'(periods)':>12}  {'':<28}{'stop (deg)':>12}"]
    for x in rows:
        det = "-" if x["detected_after_periods"] is None else str(x["detected_after_periods"])
        tel = f"{x['telemetry_foreign']} foreign" if x.get("telemetry_foreign") else \
            "complete" if x["telemetry_lost"] == 0 else f"{x['telemetry_lost']} lost" \
            if x["telemetry_lost"] is not None else "unknown"
        moved = x.get("moved_after_stop_deg")
        mv = "n/a" if moved is None else f"{moved:.3f}"
        verdict = "the input ran code" if x.get("input_ran_code") else str(x["verdict"])
        lines.append(f"{x['fault']:<18}{det:>12}  {_safe_state(x):<28}{mv:>12}  {verdict:<26}{tel:<12}")
    return "\n".join(lines)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--only", default=None, help="comma-separated faults [all: " + ", ".join(f.name for f in FAULTS) + "]")
    p.add_argument("--out", type=Path, default=REPO / "runs" / "faults")
    p.add_argument("--record", action="store_true",
                   help="also keep faults.json for the docs (docs/results/faults.json; the whole matrix only), "
                        "which tools/armctl docs renders")


def add_subparser(sub: argparse._SubParsersAction) -> None:
    fl = sub.add_parser("faults", help="every fault against a short lockstep run: detected, safe state, verdict")
    add_arguments(fl)
    fl.set_defaults(run=run)


def run(ns: argparse.Namespace) -> int:
    from tools.build.arm import build_arm
    from gen.lib.outdir import OutDirError, check_out_dir

    names = [f.name for f in FAULTS] if ns.only is None else ns.only.split(",")
    bad = [n for n in names if n not in {f.name for f in FAULTS}]
    if bad:
        raise OutDirError(f"--only: unknown fault(s) {', '.join(bad)}")
    if ns.record and ns.only is not None:
        from tools.bench.record import RecordError

        raise RecordError("--record with --only: the docs show the whole matrix")
    check_out_dir(ns.out)
    bdir = build_arm("release")
    from tools.bench.loaded_pose import most_loaded_pose

    pose = most_loaded_pose(bdir / "generated" / "arm" / "arm.xml")
    print(f"armctl faults: the arm held at its most gravity-loaded pose, q = "
          f"[{', '.join(f'{x:.3f}' for x in pose.q)}] rad ({max(pose.load):.0%} of a joint's torque limit against "
          "gravity)")
    rows = []
    for f in [f for f in FAULTS if f.name in names]:
        row = run_fault(f, ns.out / f.name, pose.q)
        if not row["injected"]:  # the harness missed its moment (not the arm's doing): once more, said so
            print(f"armctl faults: {f.name}: not injected ({row['harness_problem']}); running it again",
                  file=sys.stderr)
            first = row["harness_problem"]
            row = run_fault(f, ns.out / f.name, pose.q)
            row["retried_after"] = first
        rows.append(row)
    doc = {"pose": {"q_rad": pose.q, "gravity_nm": pose.gravity_nm, "load": pose.load},
           "moved_after_stop_bound_deg": MOVED_BOUND_DEG, "rows": rows}
    write_json_atomic(ns.out / "faults.json", doc)
    print(table(rows))
    print(f"results: {ns.out / 'faults.json'}")
    if ns.record:
        from tools.bench.record import record

        record("faults", doc, "tools/armctl faults --record")
    # The matrix's promise: every fault that must stop the arm stopped it, under a named verdict.
    broken = [x["fault"] for x in rows if x["expect_stop"] and (not x["safe_state"] or x["verdict"] == "ok")]
    broken += [f"{x['fault']} (the input ran code)" for x in rows if x.get("input_ran_code")]
    broken += [f"{x['fault']} (never injected: {x['harness_problem']})" for x in rows
               if not x["injected"] and x["fault"] not in broken]
    # And the stop's: no joint moved more than the bound after it, where that can be measured.
    moved = [f"{x['fault']} ({x['moved_after_stop_deg']:.3f} deg > {MOVED_BOUND_DEG:g})" for x in rows
             if x["moved_after_stop_deg"] is not None and x["moved_after_stop_deg"] > MOVED_BOUND_DEG]
    for x in rows:
        if x["moved_unmeasured"]:
            print(f"armctl faults: {x['fault']}: motion after the stop not measured: {x['moved_unmeasured']}",
                  file=sys.stderr)
    if broken:
        print(f"armctl faults: not stopped safely: {', '.join(broken)}", file=sys.stderr)
    if moved:
        print(f"armctl faults: the arm moved after the stop: {', '.join(moved)}", file=sys.stderr)
    return 1 if broken or moved else 0

