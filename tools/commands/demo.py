"""armctl demo: the main job, a short study of every method on the default config, and its table.

It installs nothing beyond every command's packages (tools/apt-packages.txt) and builds only the
programs its runs start."""

from __future__ import annotations

import argparse
from pathlib import Path

from gen.lib.paths import REPO
from tools.build.arm import add_arm_arguments, arm_from_args, targets_for
from tools.study import BUSES as SIL_OR_BUS, DEFAULT_CONFIRM, add_figures_argument


def add_subparser(sub: argparse._SubParsersAction) -> None:
    d = sub.add_parser("demo", help="the main job: set-up if needed, a short study of every method, the table")
    d.add_argument("--out", type=Path, default=REPO / "runs" / "demo")
    d.add_argument("--duration", type=float, default=3.0, help="trajectory seconds per method")
    d.add_argument("--scenarios", default=None, help="comma-separated subset of the study's scenarios")
    d.add_argument("--bus", choices=SIL_OR_BUS, default="sil",
                   help="sil: software in the loop, a sample confirmed over the CAN bus; udp, vcan, auto: lockstep "
                        "HIL [sil]")
    d.add_argument("--jobs", type=int, default=None, help="runs at once [sil: every core; a CAN bus: half the cores]")
    d.add_argument("--confirm", type=int, default=DEFAULT_CONFIRM,
                   help="with --bus sil: runs repeated over the CAN bus, checked bit for bit")
    d.add_argument("--trials", type=int, default=None,
                   help="tuning budget per method and scenario, for an arm without a kept tuning [the config's]")
    add_figures_argument(d)
    add_arm_arguments(d)
    d.set_defaults(run=run, prefix="armctl study")  # its errors are the study's, as they always were


def run(ns: argparse.Namespace) -> int:
    from tools import study
    from tools.study.config import load

    arm = "the default arm" if ns.model is None and ns.arm is None else (ns.arm or ns.model)
    how = "in software in the loop" if ns.bus == "sil" else f"in lockstep HIL over {ns.bus}"
    print(f"armctl demo: a short study on {arm}: every method, tuned alike, {ns.duration:g} s {how} in "
          f"each scenario of {study.DEFAULT_CONFIG.relative_to(REPO)}, one seed -> {ns.out}")
    cfg = load(study.DEFAULT_CONFIG)
    scenarios = None if ns.scenarios is None else study.subset(ns.scenarios, list(cfg.scenarios), "scenarios")
    # every method, one seed, each scenario's own drive protocol; the headline is the full study's
    # (study --record); the confirmation over the bus needs the HIL programs, SIL alone arm_sil
    return study.study_and_summary(cfg, arm_from_args(ns), ns.out, scenarios=scenarios, seeds=1,
                                   duration_s=ns.duration, jobs=ns.jobs, trials=ns.trials, bus=ns.bus,
                                   confirm=ns.confirm, figures=ns.figures, prefix="armctl demo",
                                   targets=targets_for("udp" if ns.confirm or ns.bus != "sil" else "sil"))
