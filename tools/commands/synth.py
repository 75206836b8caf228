"""armctl synth: LMI synthesis of the estimator and controller, emitted as C (gen/synth/cli.py), for
the design config as given or for an arm's joint count."""

from __future__ import annotations

import argparse
from pathlib import Path

from gen.synth import cli as synth_cli


def add_subparser(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("synth", help="LMI synthesis of the estimator and controller, emitted as C")
    synth_cli.add_arguments(s)
    s.add_argument("--model", type=Path, default=None, metavar="FILE", help="design for this arm's joint count")
    s.add_argument("--arm", type=Path, default=None, metavar="FILE", help="design for this arm file's arm")
    s.set_defaults(run=run)


def run(ns: argparse.Namespace) -> int:
    """The design config as given, or (with --model/--arm) for that arm's joint count; says how the
    firmware gets this design (a design in DIR alone is only for looking at)."""
    import tempfile

    from tools.build.arm import arm_from_args, print_arm_warnings

    arm = arm_from_args(ns)
    arm_opts = (f" --arm {arm.arm_file}" if arm.arm_file else f" --model {arm.model}" if arm.model else "")
    if arm.model is None and arm.arm_file is None:
        rc = synth_cli.run(ns)
    else:
        from gen.arm import load_arm_file, prepare

        prep = prepare(load_arm_file(arm.arm_file, arm.model), ns.config)
        print_arm_warnings(prep.info, "armctl synth")
        with tempfile.TemporaryDirectory() as tmp:
            cfg = Path(tmp) / "design.toml"
            cfg.write_text(prep.design_text)
            ns_arm = argparse.Namespace(**{**vars(ns), "config": cfg})
            rc = synth_cli.run(ns_arm)
    if rc == 0 and not ns.quiet:
        print(f"  the firmware builds with this design: tools/armctl build --design {ns.config}{arm_opts} "
              "(hil, study, tune and demo take the same options)")
    return rc
