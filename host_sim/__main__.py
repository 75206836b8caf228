"""python -m host_sim: run the simulated arm and its drives on a CAN bus until the controller stops it."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from host_sim.arm import DEFAULT_MJCF, Arm
from host_sim.canbus import BusSpecError, open_bus
from host_sim.simulator import SimConfig, Simulator, write_summary
from host_sim.uncertainty import UncertaintyConfig


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="host_sim", description=__doc__)
    p.add_argument("--bus", default="udp", help="udp | udp:GROUP:PORT | socketcan:IFACE")
    p.add_argument("--mjcf", type=Path, default=DEFAULT_MJCF)
    p.add_argument("--lcm-url", default="udpm://239.255.76.67:7667?ttl=0")
    p.add_argument("--boot-timeout", type=float, default=60.0, help="s to wait for the controller")
    p.add_argument("--idle-timeout", type=float, default=5.0, help="s of silence that faults the drives")
    p.add_argument("--command-timeout-periods", type=int, default=3)
    p.add_argument("--summary", default="", help="write a JSON summary here (atomically)")
    p.add_argument("--uncertainty", type=Path, default=None,
                   help="JSON file of host_sim.uncertainty.UncertaintyConfig fields (default: none)")
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
    try:
        bus = open_bus(ns.bus)
    except BusSpecError as exc:
        p.error(str(exc))
    try:
        cfg = SimConfig(bus=ns.bus, lcm_url=ns.lcm_url, boot_timeout_s=ns.boot_timeout,
                        idle_timeout_s=ns.idle_timeout, command_timeout_periods=ns.command_timeout_periods,
                        summary_path=ns.summary)
        report = Simulator(cfg, bus, Arm(ns.mjcf, uncertainty=ucfg)).run()
    finally:
        bus.shutdown()
    if ns.summary:
        write_summary(ns.summary, report)
    if report.result != "ok":
        print(f"host_sim: {report.reason}", file=sys.stderr)
        return 3
    print(f"host_sim: {report.periods} periods, {report.frames_tx} frames sent, {report.frames_rx} received")
    return 0


if __name__ == "__main__":
    sys.exit(main())
