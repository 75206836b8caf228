"""armctl plant: the simulated arm alone on the bus, standing in for your arm (docs/run-on-your-arm.md).

arm_sim with the arm's emulated CiA 402 drives (built from the drive table's EDS/DCF), for any
number of controllers one after another (armctl commission, armctl run): each boots the drives, runs
its SYNCs (the arm moves on them: a rehearsal is the same whatever the machine's latency) and stops
them; between controllers the arm's physics goes on, on the wall clock, its drives disabled and
their brakes closed. --truth FILE says how the arm differs from its model (friction, rotor inertia,
stiffness, payload; a reversed joint, an offset encoder, a wrong gear): a controller never sees it.
It runs until Ctrl-C."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from gen.lib.paths import REPO
from tools.build.arm import add_arm_arguments
from tools.commands import CommandError, UsageError
from tools.run.arm_session import add_bus_arguments


def add_subparser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plant", help="the simulated arm alone on the bus, for armctl commission and run to "
                                     "rehearse against (docs/run-on-your-arm.md)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--truth", type=Path, default=None, metavar="FILE",
                   help="how the arm differs from its model (host_sim/truth.py: friction, rotor inertia, stiffness, "
                        "payload, a reversed joint, an offset encoder, a wrong gear, the start pose) [the model's arm]")
    add_bus_arguments(p, "udp", " [udp]")
    p.add_argument("--out", type=Path, default=REPO / "runs" / "plant", metavar="DIR",
                   help="its log and sessions.json: each controller's session and how far each joint moved in the "
                        "2 s after its stop [runs/plant]")
    add_arm_arguments(p)
    p.set_defaults(run=run)


def run(ns: argparse.Namespace) -> int:
    from gen import eds as eds_mod
    from gen.lib.atomic_output import OutputError, write_text_atomic
    from host_sim.launch import sim_argv
    from host_sim.truth import TruthError, load
    from tools.build.arm import prepared_model
    from tools.run import procs
    from tools.run.arm_session import CAN_GROUP, arm_on_bus
    from tools.run.hil import check_loopback_route

    if ns.truth is not None and not ns.truth.is_file():
        raise UsageError(f"--truth {ns.truth}: no such file")
    setup = arm_on_bus(ns, "armctl plant")
    info = setup.info
    try:
        truth = load(ns.truth, info, setup.table)
    except TruthError as exc:
        raise UsageError(str(exc)) from None
    if setup.kind == "udp":
        check_loopback_route(CAN_GROUP)
    out = ns.out
    out.mkdir(parents=True, exist_ok=True)
    for stale in ("sessions.json", "plant.log", "plant_summary.json"):
        (out / stale).unlink(missing_ok=True)
    try:  # the emulated drives: the drive table's EDS/DCF as the simulator's table (gen/eds.py)
        write_text_atomic(out / "canopen_od.txt", eds_mod.table_text(eds_mod.load(Path(setup.table.eds))))
    except eds_mod.EdsError as exc:
        raise UsageError(str(exc)) from None
    except OutputError as exc:
        raise CommandError(str(exc)) from None
    substeps = info["substeps"]
    # the drives' holding brakes, from the drive table (engaged at power-on, as a real arm's)
    brakes = [a for d in setup.table.drives if d.brake_spec() for a in ("--brake", d.brake_spec())]
    exe = setup.bdir / "host_sim" / "native" / "arm_sim"
    argv = sim_argv(exe, setup.buses, lcm_url="", summary=out / "plant_summary.json",
                    uncertainty=truth.uncertainty.to_dict(), model=prepared_model(setup.bdir),
                    extra=["--substeps", str(substeps), "--protocol", "canopen", *setup.sim_node_args,
                           "--od", str(out / "canopen_od.txt"), "--serve", "--sessions", str(out / "sessions.json"),
                           *truth.args, *brakes])
    print(f"armctl plant: the arm {info['name']} on the bus, for controllers one after another; Ctrl-C ends it")
    for line in setup.describe_buses():
        print(f"  bus {line}")
    print(f"  drives: {setup.table.path} ({Path(setup.table.eds).name}), as configured there")
    print(f"  truth: {ns.truth or 'the model'}" + (": " + "; ".join(truth.notes) if truth.notes else ""))
    print(f"  sessions: {out / 'sessions.json'}")
    sys.stdout.flush()
    with open(out / "plant.log", "w") as log:
        try:
            p = procs.spawn("simulator", argv, watches_parent=True, cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT)
        except InterruptedError as exc:
            raise CommandError(str(exc)) from None
        assert p.stdout is not None
        for raw in iter(p.stdout.readline, b""):
            line = raw.decode(errors="replace")
            log.write(line)
            log.flush()
            sys.stdout.write(line)
            sys.stdout.flush()
        p.wait()
        procs.forget(p)
    if p.returncode == 2:
        raise UsageError(f"the simulator refused its arguments: see {out / 'plant.log'}")
    if procs.interrupted is not None:
        print(f"armctl plant: stopped (sessions in {out / 'sessions.json'})")
        return 0
    raise CommandError(f"the simulator ended by itself (exit {p.returncode}): see {out / 'plant.log'}", 1)
