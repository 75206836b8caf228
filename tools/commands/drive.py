"""armctl drive check FILE: can this controller run the CiA 402 drive an EDS or DCF describes?

Every object the CANopen master's boot reads or writes is checked against the file (present,
access, data type, limits, PDO mapping rules), its modes (cyclic synchronous torque, 0x6502 bit 9)
and its units (0x6076, the motor's rated torque, 0x608F, 0x6091, or the drive table's values where
it lacks them): one line per problem, exit 2 if there is one, else 0; then the file's harmless
mistakes, each naming its line (warnings: an object the master never uses left out, a limit that
limits nothing or contradicts CiA 301's definition of the object ignored), and what the boot will
skip or take from the drive table and the torque at the joint (notes). docs/drives-bring-up.md:
what the master needs from a drive."""

from __future__ import annotations

import argparse
from pathlib import Path

from gen.lib.one_line import one_line
from tools.commands import UsageError


def add_subparser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("drive", help="check a CiA 402 drive's EDS/DCF before you buy or wire it",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.set_defaults(run=run)
    actions = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    c = actions.add_parser("check", help="can this controller run the drive FILE describes? (exit 0 yes, 2 no)",
                           description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    c.add_argument("file", type=Path, metavar="FILE", help="the drive's EDS or DCF")
    c.add_argument("--drive-config", type=Path, default=None, metavar="TOML",
                   help="a drive table (firmware/protocol/drives.toml's fields): its [defaults] units, heartbeats, "
                        "master id and PDO transmission types are what the boot would use [none: the drive's own "
                        "units, the master's defaults]")
    c.set_defaults(run=run)


def run(ns: argparse.Namespace) -> int:
    from gen import drive_check, drives
    from gen import eds as eds_mod

    plan = None
    if ns.drive_config is not None:
        try:
            plan, _ = drives.table_plan(ns.drive_config)
        except drives.DrivesError as exc:
            raise UsageError(f"--drive-config: {exc}") from None
    try:
        d = eds_mod.load(ns.file)
    except eds_mod.EdsError as exc:
        raise UsageError(str(exc)) from None
    report = drive_check.check(d, plan)
    who = ", ".join(v for v in (d.device.get("VendorName", ""), d.device.get("ProductName", "")) if v) or "a drive"
    verdict = "this controller can run it" if report.ok else "this controller cannot run it"
    # the file's own strings (ProductName, ParameterName) reach a terminal: one line each, no control character
    print(one_line(f"{ns.file.name} ({who}): {verdict}"))
    for line in report.problems:
        print(f"  problem: {one_line(line)}")
    for line in report.warnings:  # the file's own harmless mistakes, by line: not a refusal
        print(f"  warning: {one_line(line)}")
    for line in report.notes:
        print(f"  note: {one_line(line)}")
    return 0 if report.ok else 2
