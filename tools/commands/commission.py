"""armctl commission: check the arm before it moves (docs/run-on-your-arm.md).

The controller holds the arm where it stands and tests each joint in turn, the others held, never
letting any joint leave its start pose by more than 2 deg: a small torque pulse each way (a few %
of its limit, above its friction) and a slow sweep across its start pose. Against the arm's model:
its direction (a reversed motor or encoder), its scale (a gear or torque unit wrong by 2x or more)
and the gravity torque at the start pose (a zero offset, a payload the model lacks). The record,
tied to the drive table's content, is what armctl run asks for."""

from __future__ import annotations

import argparse
from pathlib import Path

from gen.lib.paths import REPO
from tools.build.arm import add_arm_arguments
from tools.commands import CommandError
from tools.run.arm_session import add_session_arguments
from tools.run.run_files import CONTROLLER_SUMMARY

END_HOLD_S = 0.5


def add_subparser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("commission", help="check each joint of your arm before it moves: direction, scale, gravity "
                                          "(docs/run-on-your-arm.md)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_session_arguments(p, "where the commissioning record goes [runs/commission/ARM-HASH.json, where armctl run looks]")
    p.add_argument("--out", type=Path, default=REPO / "runs" / "commission", metavar="DIR",
                   help="the controller's log, summary and telemetry [runs/commission]")
    add_arm_arguments(p)
    p.set_defaults(run=run)


def run(ns: argparse.Namespace) -> int:
    from tools.run.arm_task import describe
    from tools.run.arm_session import arm_on_bus, run_controller, table_digest
    from tools.run.commissioning import default_record, judge, pulses, write_record

    setup = arm_on_bus(ns, "armctl commission")
    info = setup.info
    record = ns.record or default_record(info)
    pulse = pulses(info)
    mode = ns.mode or ("lockstep" if setup.rehearsal else "realtime")
    describe(setup, mode, "commission each joint in turn, the others held, none leaving its start pose by more than "
             f"2 deg: pulses of {', '.join(f'{x:.3g}' for x in pulse)} N m, a 1.5 deg sweep", "armctl commission",
             method="pd (a plain hold: no estimator adds to the torques measured)")
    res = run_controller(setup, ["--method", "pd", "--task", "commission", "--end-hold", f"{END_HOLD_S:g}",
                                 "--commission-pulse", ",".join(f"{x!r}" for x in pulse)], ns.out, mode)
    summary = res.summary
    cm = summary.get("task", {}).get("commission")
    if res.interrupted is not None or cm is None:
        why = (f"stopped by signal {res.interrupted}" if res.interrupted is not None
               else summary.get("reason") or f"the controller ended with exit code {res.code}")
        raise CommandError(f"no verdict: {why}; no record written (log {ns.out / 'controller.log'})", 1)
    verdicts = judge(summary, info)
    findings = [f for v in verdicts for f in v.findings]
    if cm["status"] != "done" and not findings:
        findings.append(f"the sequence ended {cm['status']}: {summary.get('reason', '')}")
    if res.code not in (0,) and cm["status"] == "done":
        findings.append(f"the controller ended: {summary.get('reason', '')}")
    passed = not findings
    print(f"{'joint':<16}{'direction':>12}{'gravity N m':>14}{'model':>10}{'friction':>10}{'inertia':>10}{'model':>10}")
    for v in verdicts:
        def num(x: float | None) -> str:
            return "-" if x is None else f"{x:.3g}"
        print(f"{v.name:<16}{v.direction:>12}{num(v.gravity_nm):>14}{num(v.gravity_model_nm):>10}"
              f"{num(v.friction_nm):>10}{num(v.inertia):>10}{num(v.inertia_model):>10}")
    write_record(record, passed=passed, info=info, table=setup.table, digest=table_digest(setup.table),
                 verdicts=verdicts, findings=findings, bus=" ".join(setup.buses),
                 summary_path=ns.out / CONTROLLER_SUMMARY)
    if passed:
        print(f"armctl commission: passed: every joint turns its way, at the model's scale, under the model's "
              f"gravity; record {record}")
        return 0
    for f in findings:
        print(f"armctl commission: {f}")
    raise CommandError(f"not passed: {findings[0]} (record {record}: armctl run refuses this arm until it passes)", 1)
