"""armctl busload: worst-case CAN bus load of the drive protocol per control period, per bus,
against a budget; exits 2 above it and names a wiring that fits. The frame lengths and their
arithmetic are gen/lib/busload.py's (shared with gen/ and host_sim/)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from gen.lib import busload as lib
from gen.lib.params import constant, default, param
from gen.lib.busload import (DEFAULT_DBC, DEFAULT_TOPOLOGY, BusLoad, ConfigError, Protocol, drives_arg,
                             rate_arg, compute, even_split, load_topology, parse_bus, topology_drives)

EXIT_OVER_BUDGET = 2


def report(loads: list[BusLoad], budget: float) -> str:
    lines = []
    for bl in loads:
        b = bl.bus
        lines.append(f"{b.name}: {b.describe()}, drives {','.join(map(str, b.drives))}, {bl.rate_hz:g} Hz loop")
        lines.append(f"  {'message':<22}{'frames/period':>14}{'bits (nom+data)':>17}{'us/frame':>10}")
        for f in bl.frames:
            bits = f"{f.nominal_bits}+{f.data_bits}" if f.data_bits else f"{f.nominal_bits}"
            per = f"{f.per_period * f.frames:g}" if f.per_period >= 1 else f"{f.frames}/{1 / f.per_period:g}"
            lines.append(f"  {f.message:<22}{per:>14}{bits:>17}{f.time_s * 1e6:>10.1f}")
        lines.append(f"  per period {bl.periodic_s * 1e6:.1f} us + heartbeats {bl.background_load * 100:.2f}% "
                     f"-> load {bl.load * 100:.1f}% (budget {budget * 100:g}%); "
                     f"highest loop rate within budget: {math.floor(bl.max_rate_hz(budget))} Hz")
    return "\n".join(lines)


def json_doc(loads: list[BusLoad], rate_hz: float, budget: float, max_rate: int, **extra: object) -> str:
    over = any(bl.load > budget for bl in loads)
    return json.dumps({
        **extra, "rate_hz": rate_hz, "budget": budget, "fits": not over, "max_rate_hz": max_rate,
        "buses": [{"name": bl.bus.name, "kind": bl.bus.describe(), "drives": bl.bus.drives,
                   "load": bl.load, "periodic_us": bl.periodic_s * 1e6,
                   "max_rate_hz": math.floor(bl.max_rate_hz(budget)),
                   "frames": [f.__dict__ for f in bl.frames]} for bl in loads]}, indent=2)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--bus", action="append", default=[], metavar="SPEC",
                   help="[NAME=]fd:NOMINAL[/DATA]:DRIVES or [NAME=]classic:RATE:DRIVES, repeatable "
                        "[the buses of --topology]")
    p.add_argument("--topology", type=Path, default=None,
                   help="bus topology file used when no --bus is given [arm: firmware/protocol/buses.toml; "
                        "canopen: the fewest classic 1 Mbit/s buses that fit]")
    proto = param("hil", "protocol")
    p.add_argument("--protocol", choices=("arm", "canopen"), default=proto.default,
                   help="arm: the DBC's frames; canopen: the CiA 402 drives' SYNC, PDOs (the drive table's "
                        f"mapping and transmission types) and heartbeats [{proto.default}]")
    p.add_argument("--drive-config", type=Path, default=None, metavar="FILE",
                   help="canopen: the drive table whose PDO transmission types count "
                        "[firmware/protocol/drives.toml]")
    rate, budget, heartbeat = default("controller", "rate"), 100 * constant("bus-budget"), lib.HEARTBEAT_MS
    p.add_argument("--rate", type=float, default=rate, help=f"control loop rate, Hz [{rate:g}]")
    p.add_argument("--budget", type=float, default=budget, help=f"highest acceptable bus load, %% [{budget:g}]")
    p.add_argument("--heartbeat-ms", type=float, default=heartbeat, help=f"drive heartbeat period [{heartbeat:g}]")
    p.add_argument("--drives", type=int, default=None,
                   help="the arm's drives, 1..N [the highest drive the buses name]")
    p.add_argument("--dbc", type=Path, default=DEFAULT_DBC)
    p.add_argument("--json", action="store_true", help="print the result as JSON")


def add_subparser(sub: argparse._SubParsersAction) -> None:
    formulas = (lib.__doc__ or "").split("\n\n", 1)[1]  # the library's: what is counted, and how
    bl = sub.add_parser("busload", help="worst-case CAN bus load per control period from the DBC; refuses > budget",
                        description=__doc__ + "\n\n" + formulas, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(bl)
    bl.set_defaults(run=run)


def run(ns: argparse.Namespace) -> int:
    """armctl busload (a ConfigError exits 2: tools/cli.py)."""
    if not 0 < ns.budget <= 100:
        raise ConfigError(f"--budget {ns.budget:g}: must be in (0, 100] %")
    if not ns.rate > 0 or not ns.heartbeat_ms > 0:
        raise ConfigError("--rate and --heartbeat-ms must be > 0")
    if ns.protocol == "canopen":
        return run_canopen(ns)
    if ns.drive_config is not None:
        raise ConfigError("--drive-config: the CiA 402 drive table, for --protocol canopen")
    ns.topology = ns.topology or DEFAULT_TOPOLOGY
    proto = Protocol(ns.dbc)
    if ns.drives is not None and not 1 <= ns.drives <= proto.n_drives:
        raise ConfigError(f"--drives {ns.drives}: the DBC has drive slots 1..{proto.n_drives}")
    if ns.bus:
        buses = [parse_bus(s, i) for i, s in enumerate(ns.bus)]
    else:
        buses = load_topology(ns.topology, ns.drives or topology_drives(ns.topology))
    n_drives = ns.drives or max(d for b in buses for d in b.drives)
    loads = compute(buses, ns.rate, ns.heartbeat_ms, proto, n_drives)
    budget = ns.budget / 100.0
    over = [bl for bl in loads if bl.load > budget]
    max_rate = math.floor(min(bl.max_rate_hz(budget) for bl in loads))
    if ns.json:
        print(json_doc(loads, ns.rate, budget, max_rate))
    else:
        print(report(loads, budget))
    if not over:
        if not ns.json:
            print(f"fits: every bus within {ns.budget:g}% at {ns.rate:g} Hz (highest rate that fits: {max_rate} Hz)")
        return 0
    worst = max(over, key=lambda bl: bl.load)
    msg = (f"armctl busload: bus {worst.bus.name} ({worst.bus.describe()}) is at {worst.load * 100:.1f}% "
           f"at {ns.rate:g} Hz, above the {ns.budget:g}% budget; the highest loop rate that fits is "
           f"{max_rate} Hz")
    if len(buses) == 1 and n_drives > 1:
        for k in range(2, n_drives + 1):
            split = even_split(buses[0], n_drives, k)
            if all(bl.load <= budget for bl in compute(split, ns.rate, ns.heartbeat_ms, proto, n_drives)):
                msg += (f"; {k} such buses fit at {ns.rate:g} Hz ("
                        + " ".join(f"--bus {'fd' if b.fd else 'classic'}:{rate_arg(b)}:{drives_arg(b)}"
                                   for b in split) + ")")
                break
    print(msg, file=sys.stderr)
    return EXIT_OVER_BUDGET


def run_canopen(ns: argparse.Namespace) -> int:
    """The CiA 402 drives' load: the buses given, else the fewest classic 1 Mbit/s buses that
    carry them; above the budget, or when no wiring fits, exits 2 and says what does."""
    from gen import drives as drives_mod

    table = ns.drive_config or drives_mod.DEFAULT_DRIVES
    try:
        every = drives_mod.load_transmission(table)
    except drives_mod.DrivesError as exc:
        raise ConfigError(f"--drive-config: {exc}") from None
    budget = ns.budget / 100.0
    n_drives = ns.drives
    if ns.bus:
        buses = [parse_bus(s, i) for i, s in enumerate(ns.bus)]
    elif ns.topology is not None:
        buses = load_topology(ns.topology, n_drives or topology_drives(ns.topology))
    else:
        n_drives = n_drives or 6
        fits = lib.canopen_wiring(n_drives, ns.rate, every, budget, ns.heartbeat_ms)
        if fits is None:
            print(f"armctl busload: {n_drives} CiA 402 drives at {ns.rate:g} Hz do not fit {lib.MAX_BUSES} classic "
                  f"1 Mbit/s buses within {ns.budget:g}%; " + _classic_rates(n_drives, every, budget, ns.heartbeat_ms),
                  file=sys.stderr)
            return EXIT_OVER_BUDGET
        buses = fits
    n_drives = n_drives or max(d for b in buses for d in b.drives)
    loads = lib.canopen_compute(buses, ns.rate, ns.heartbeat_ms, every, n_drives)
    over = [bl for bl in loads if bl.load > budget]
    max_rate = math.floor(min(bl.max_rate_hz(budget) for bl in loads))
    if ns.json:
        print(json_doc(loads, ns.rate, budget, max_rate, protocol="canopen", transmission=every))
    else:
        print(f"CiA 402 drives, PDO transmission types {every} (drive table {table})")
        print(report(loads, budget))
    if not over:
        if not ns.json:
            print(f"fits: every bus within {ns.budget:g}% at {ns.rate:g} Hz (highest rate that fits: {max_rate} Hz)"
                  + ("" if ns.bus or ns.topology else "; " + " ".join(
                      f"--bus classic:{rate_arg(b)}:{drives_arg(b)}" for b in buses)))
        return 0
    worst = max(over, key=lambda bl: bl.load)
    print(f"armctl busload: bus {worst.bus.name} ({worst.bus.describe()}) is at {worst.load * 100:.1f}% at "
          f"{ns.rate:g} Hz, above the {ns.budget:g}% budget; the highest loop rate that fits is {max_rate} Hz; "
          + _classic_rates(n_drives, every, budget, ns.heartbeat_ms), file=sys.stderr)
    return EXIT_OVER_BUDGET


def _classic_rates(n_drives: int, every: dict[str, int], budget: float, heartbeat_ms: float) -> str:
    """The highest loop rate at which 1..MAX_BUSES classic 1 Mbit/s buses carry the drives."""
    parts = []
    for k in range(1, min(lib.MAX_BUSES, n_drives) + 1):
        split = even_split(lib.CLASSIC_1M, n_drives, k)
        rate = math.floor(min(bl.max_rate_hz(budget) for bl in lib.canopen_compute(split, 1.0, heartbeat_ms, every,
                                                                                   n_drives)))
        parts.append(f"{k} bus{'es' if k > 1 else ''} up to {rate} Hz")
    return "classic 1 Mbit/s: " + ", ".join(parts)

