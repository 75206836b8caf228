"""armctl run: the controller alone on your arm's buses (docs/run-on-your-arm.md).

It starts nothing but arm_controller (and the telemetry logger): real time on real interfaces
(lockstep against armctl plant, whose arm steps on the controller's SYNC), CiA 402, the arm's own
build and design, its drive table, a commissioned arm only (armctl commission). What the arm does:
    (nothing)          the built-in reference: a bounded move home, then the arm's reference
    --hold             hold the pose the arm is in, with gravity compensation
    --jog JOINT=DEG    one bounded, slow move of one joint
    FILE.csv           a trajectory (t, q1..qn), checked before anything is enabled
    --stream [URL]     a planner's reference over LCM (channel ARM_PLAN)
Every task starts wherever the arm is: a bounded move from the measured pose to its first point.
Ctrl-C is a controlled stop."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from gen.lib.params import param
from gen.lib.paths import REPO
from tools.build.arm import add_arm_arguments
from tools.commands import CommandError, UsageError
from tools.run.arm_session import add_session_arguments
from tools.run.arm_task import JOG_MAX_DEG, OPEN_ENDED_S, REFERENCE_S, describe, finish, task_args


def add_subparser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="the controller alone on your arm's buses: hold, jog, a trajectory, a "
                                   "planner's stream or the built-in reference (docs/run-on-your-arm.md)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("trajectory", nargs="?", type=Path, default=None, metavar="FILE.csv",
                   help="a trajectory: t, q1..qn per row (s, rad), checked against the arm before anything is enabled")
    what = p.add_mutually_exclusive_group()
    what.add_argument("--hold", action="store_true", help="hold the pose the arm is in, with gravity compensation")
    what.add_argument("--jog", metavar="JOINT=DEG", default=None,
                      help=f"move one joint (name or number) by DEG (at most {JOG_MAX_DEG:.0f} deg either way), "
                           "slowly, the others held")
    what.add_argument("--stream", nargs="?", const=param("controller", "stream-url").default, default=None,
                      metavar="URL", help="follow a planner's reference over LCM (channel ARM_PLAN, armlcm.plan_t) "
                                          "[%(const)s]")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help=f"the built-in reference's length [{REFERENCE_S:g}]; --hold and --stream: until Ctrl-C "
                        "unless given")
    add_session_arguments(p)
    p.add_argument("--out", type=Path, default=REPO / "runs" / "run", metavar="DIR",
                   help="the controller's log, summary and telemetry [runs/run]")
    add_arm_arguments(p)
    p.set_defaults(run=run)


def run(ns: argparse.Namespace) -> int:
    from tools.run.arm_session import arm_on_bus, run_controller, table_digest
    from tools.run.commissioning import RecordError, check_record, default_record

    if ns.trajectory is not None and (ns.hold or ns.jog is not None or ns.stream is not None):
        raise UsageError(f"{ns.trajectory}: a trajectory file, or --hold, --jog or --stream: give one")
    if ns.duration is not None and not (math.isfinite(ns.duration) and 0 < ns.duration <= OPEN_ENDED_S):
        raise UsageError(f"--duration: must be in (0, {OPEN_ENDED_S:g}] s, got {ns.duration}")
    if ns.duration is not None and (ns.trajectory is not None or ns.jog is not None):
        raise UsageError("--duration: a trajectory and a jog have their own length")
    setup = arm_on_bus(ns, "armctl run")
    try:
        check_record(ns.record or default_record(setup.info), setup.info, setup.table, table_digest(setup.table))
    except RecordError as exc:
        raise CommandError(str(exc), 1) from None
    ctl, task = task_args(ns, setup, ns.out)
    mode = ns.mode or ("lockstep" if setup.rehearsal else "realtime")
    describe(setup, mode, task, "armctl run")
    res = run_controller(setup, ["--method", "pm", *ctl], ns.out, mode)
    return finish(res, setup, task, "armctl run")
