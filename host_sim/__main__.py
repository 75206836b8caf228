"""python -m host_sim: the simulated arm and its drives on a CAN bus, until the controller stops it.

A launcher: it reads the configuration Python owns (the uncertainty file, the buses' physical
layers for bus timing), turns it into arguments and replaces itself with arm_sim
(host_sim/native), which does the per-period work. Exit codes are arm_sim's.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from host_sim.launch import TIMING_MODES, parse_phy, sim_argv, sim_binary
from host_sim.uncertainty import UncertaintyConfig
from gen.lib import busload
from gen.lib.multicast import LCM_PORT, lcm_url


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="host_sim", description=__doc__)
    p.add_argument("--bus", action="append", default=[], metavar="SPEC[@DRIVES]",
                   help="udp | udp:GROUP:PORT | socketcan:IFACE, optionally @DRIVES (e.g. @1-3, @4,5,6); "
                        "repeatable (up to 4 buses), every drive on exactly one bus [udp, all drives]")
    p.add_argument("--model", "--mjcf", dest="model", type=Path, default=None, help="the arm [the bundled UR5e]")
    p.add_argument("--lcm-url", default=lcm_url(LCM_PORT))
    p.add_argument("--boot-timeout", default="60", help="s to wait for the controller")
    p.add_argument("--idle-timeout", default="5", help="s of silence that faults the drives")
    p.add_argument("--command-timeout-periods", default="3")
    p.add_argument("--summary", type=Path, default=None, help="write a JSON summary here (atomically)")
    p.add_argument("--uncertainty", type=Path, default=None,
                   help="JSON file of host_sim.uncertainty.UncertaintyConfig fields (default: none)")
    p.add_argument("--bus-timing", choices=TIMING_MODES, default="off",
                   help="emulate CAN bit timing (vcan and UDP have none): virtual = commands act when their "
                        "frames would end on the bus (lockstep); wallclock = that, and state frames leave no "
                        "earlier than they would end (realtime) [off]")
    p.add_argument("--bus-phy", action="append", default=[], metavar="fd:NOMINAL[/DATA]|classic:RATE",
                   help="physical layer of each --bus, in order (one value: every bus) [fd:1M/5M]")
    p.add_argument("--controller-latency-us", type=float, default=0.0,
                   help="bus timing: last state frame in -> commands queued, in us [0]")
    p.add_argument("--binary", type=Path, default=None,
                   help="arm_sim to run [$ARM_BUILD_DIR/host_sim/native/arm_sim, else build/release's]")
    ns = p.parse_args(argv)
    buses = ns.bus or ["udp"]
    try:
        unc = UncertaintyConfig.from_file(ns.uncertainty) if ns.uncertainty else None
    except (OSError, ValueError, TypeError) as exc:
        p.error(f"--uncertainty: {exc}")
    phys: list[busload.Bus] = []
    if ns.bus_timing != "off":
        texts = ns.bus_phy or ["fd:1M/5M"]
        if len(texts) not in (1, len(buses)):
            p.error(f"--bus-phy: {len(texts)} given for {len(buses)} buses (give one, or one per --bus)")
        try:
            parsed = [parse_phy(t) for t in texts] * (len(buses) if len(texts) == 1 else 1)
        except busload.ConfigError as exc:
            p.error(f"--bus-phy: {exc}")
        phys = [busload.Bus(f"bus{i}", fd, nom, dat, []) for i, (fd, nom, dat) in enumerate(parsed)]
    elif ns.bus_phy:
        p.error("--bus-phy: only with --bus-timing virtual|wallclock")
    binary = ns.binary or (Path(os.environ["ARM_BUILD_DIR"]) / "host_sim" / "native" / "arm_sim"
                           if os.environ.get("ARM_BUILD_DIR") else sim_binary("release"))
    if not binary.exists():
        p.error(f"{binary} is missing: run tools/armctl build")
    argv_c = sim_argv(binary, buses, lcm_url=ns.lcm_url, summary=ns.summary,
                      uncertainty=unc.to_dict() if unc else None, timing=ns.bus_timing, phys=phys,
                      controller_latency_us=ns.controller_latency_us, model=ns.model,
                      extra=["--boot-timeout", ns.boot_timeout, "--idle-timeout", ns.idle_timeout,
                             "--command-timeout-periods", ns.command_timeout_periods])
    sys.stdout.flush()
    os.execv(argv_c[0], argv_c)
    return 127  # not reached


if __name__ == "__main__":
    sys.exit(main())
