"""python -m host_sim: run the simulated arm and its drives on a CAN bus until the controller stops it."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from host_sim.arm import DEFAULT_MJCF, Arm
from host_sim.bus_timing import MODES, parse_phy, timelines
from host_sim.canbus import BusSpecError, open_bus, parse_bus_assignments
from host_sim.simulator import SimConfig, Simulator, write_summary
from host_sim.uncertainty import UncertaintyConfig


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="host_sim", description=__doc__)
    p.add_argument("--bus", action="append", default=[], metavar="SPEC[@DRIVES]",
                   help="udp | udp:GROUP:PORT | socketcan:IFACE, optionally @DRIVES (e.g. @1-3, @4,5,6); "
                        "repeatable (up to 4 buses), every drive on exactly one bus [udp, all drives]")
    p.add_argument("--mjcf", type=Path, default=DEFAULT_MJCF)
    p.add_argument("--lcm-url", default="udpm://239.255.76.67:7667?ttl=0")
    p.add_argument("--boot-timeout", type=float, default=60.0, help="s to wait for the controller")
    p.add_argument("--idle-timeout", type=float, default=5.0, help="s of silence that faults the drives")
    p.add_argument("--command-timeout-periods", type=int, default=3)
    p.add_argument("--summary", default="", help="write a JSON summary here (atomically)")
    p.add_argument("--uncertainty", type=Path, default=None,
                   help="JSON file of host_sim.uncertainty.UncertaintyConfig fields (default: none)")
    p.add_argument("--bus-timing", choices=MODES, default="off",
                   help="emulate CAN bit timing (vcan and UDP have none): virtual = commands act when their "
                        "frames would end on the bus (lockstep); wallclock = that, and state frames leave no "
                        "earlier than they would end (realtime) [off]")
    p.add_argument("--bus-phy", action="append", default=[], metavar="fd:NOMINAL[/DATA]|classic:RATE",
                   help="physical layer of each --bus, in order (one value: every bus) [fd:1M/5M]")
    p.add_argument("--controller-latency-us", type=float, default=0.0,
                   help="bus timing: last state frame in -> commands queued, in us [0]")
    ns = p.parse_args(argv)
    if ns.lcm_url.startswith("udpm://") and "ttl=0" not in ns.lcm_url:
        p.error(f"--lcm-url: '{ns.lcm_url}' must set ttl=0 (telemetry stays on this host)")
    for name in ("boot_timeout", "idle_timeout"):
        if not getattr(ns, name) > 0:
            p.error(f"--{name.replace('_', '-')}: must be > 0")
    if ns.command_timeout_periods < 1:
        p.error("--command-timeout-periods: must be >= 1")
    try:
        ucfg = UncertaintyConfig.from_file(ns.uncertainty) if ns.uncertainty else UncertaintyConfig()
    except (OSError, ValueError, TypeError) as exc:
        p.error(f"--uncertainty: {exc}")
    n_drives = 6  # the arm's drives (host_sim/models/ur5e_arm.xml; checked against the model below)
    try:
        assignment = parse_bus_assignments(ns.bus or ["udp"], n_drives)
    except BusSpecError as exc:
        p.error(str(exc))
    timing = None
    if ns.bus_timing != "off":
        phys_text = ns.bus_phy or ["fd:1M/5M"]
        if len(phys_text) not in (1, len(assignment)):
            p.error(f"--bus-phy: {len(phys_text)} given for {len(assignment)} buses (give one, or one per --bus)")
        try:
            phys = [parse_phy(t) for t in phys_text] * (len(assignment) if len(phys_text) == 1 else 1)
        except ValueError as exc:
            p.error(f"--bus-phy: {exc}")
        if not 0.0 <= ns.controller_latency_us <= 1e6:
            p.error("--controller-latency-us: must be in 0..1e6")
        timing = timelines(phys, [drives for _, drives in assignment])
    elif ns.bus_phy:
        p.error("--bus-phy: only with --bus-timing virtual|wallclock")
    buses = []
    try:
        for spec, _ in assignment:
            buses.append(open_bus(spec))
    except BusSpecError as exc:
        for b in buses:
            b.shutdown()
        p.error(str(exc))
    bus_of = [next(i for i, (_, drives) in enumerate(assignment) if d in drives) for d in range(1, n_drives + 1)]
    try:
        cfg = SimConfig(bus=" ".join(ns.bus or ["udp"]), lcm_url=ns.lcm_url, boot_timeout_s=ns.boot_timeout,
                        idle_timeout_s=ns.idle_timeout, command_timeout_periods=ns.command_timeout_periods,
                        summary_path=ns.summary, bus_timing=ns.bus_timing,
                        controller_latency_s=ns.controller_latency_us * 1e-6)
        arm = Arm(ns.mjcf, uncertainty=ucfg)
        if arm.n != n_drives:
            p.error(f"--mjcf: the arm has {arm.n} joints; the drive protocol has {n_drives} drives")
        report = Simulator(cfg, buses, arm, bus_of, timing).run()
    finally:
        for b in buses:
            b.shutdown()
    if ns.summary:
        write_summary(ns.summary, report)
    if report.result != "ok":
        print(f"host_sim: {report.reason}", file=sys.stderr)
        return 3
    print(f"host_sim: {report.periods} periods, {report.frames_tx} frames sent, {report.frames_rx} received")
    return 0


if __name__ == "__main__":
    sys.exit(main())
