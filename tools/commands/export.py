"""armctl export: a run's telemetry (every LCM channel) and its bus capture (every frame, decoded
with the run's DBC) in one MCAP file, on the run's timeline (tools/run/mcap_export.py)."""

from __future__ import annotations

import argparse
from pathlib import Path

from tools.commands import CommandError


def add_subparser(sub: argparse._SubParsersAction) -> None:
    e = sub.add_parser("export", help="a run's telemetry and CAN capture as MCAP (Foxglove, Lichtblick, PlotJuggler)")
    e.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="a run's folder (armctl hil --out, or a study's "
                                                                 "SCENARIO/METHOD/seed-N)")
    e.add_argument("--mcap", action="store_true", required=True, help="write MCAP (the one format so far)")
    e.add_argument("--out", type=Path, default=None, metavar="FILE", help="the file [RUN_DIR/telemetry.mcap]")
    e.set_defaults(run=run)


def run(ns: argparse.Namespace) -> int:
    from tools.run.mcap_export import ExportError, export_mcap

    if ns.out is not None and not ns.out.parent.is_dir():
        raise CommandError(f"--out {ns.out}: no folder {ns.out.parent}", 2)
    try:
        r = export_mcap(ns.run_dir, ns.out, progress=lambda s: print(f"armctl export: {s}"))
    except ExportError as exc:
        raise CommandError(str(exc), 2) from None
    lcm = sum(r.lcm.values())
    print(f"mcap: {r.path}: {lcm} LCM messages on {len(r.lcm)} channels ("
          + ", ".join(f"{ch} {k}" for ch, k in sorted(r.lcm.items())) + ")"
          + (f"; {sum(r.can.values())} CAN frames of {r.capture.name} on {len(r.can)} topics, decoded by {r.dbc}"
             if r.capture else "; no capture (armctl hil --capture records one)")
          + f"; timeline: {r.timeline}")
    for ch, k in sorted(r.undecodable.items()):
        print(f"armctl export: {ch}: {k} message(s) no telemetry type decodes, left out")
    damaged = [d for d in (f"{ns.run_dir / 'telemetry.lcmlog'}: {r.log_damage.describe()} (the export holds "
                           f"{lcm} of them)" if r.log_damage else None,
                           r.capture_damage) if d]
    if damaged:  # exported as far as it reads: said, and not a success
        raise CommandError("damaged input, exported as far as it reads: " + " | ".join(damaged), 1)
    return 0
