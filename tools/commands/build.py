"""armctl build: the firmware and tests with a CMake preset, for the default arm or another."""

from __future__ import annotations

import argparse
import subprocess

from tools.build.arm import add_arm_arguments
from tools.build import PRESETS, TARGETS
from tools.commands import CommandError


def add_subparser(sub: argparse._SubParsersAction) -> None:
    b = sub.add_parser("build", help="build the firmware and tests with a CMake preset")
    b.add_argument("--preset", choices=PRESETS, default="release")
    b.add_argument("--target", choices=tuple(TARGETS),
                   help="cross target (host = release; aarch64; cortex-m4/m7/m3 images); overrides --preset")
    add_arm_arguments(b)
    b.set_defaults(run=run)


def run(ns: argparse.Namespace) -> int:
    from tools.build.arm import arm_from_args, arm_info, build_arm, print_arm_warnings

    arm = arm_from_args(ns)
    bdir = build_arm(TARGETS[ns.target] if ns.target else ns.preset, arm, quiet=False)
    info = arm_info(bdir)
    print(f"arm: {info['name']}, {info['n_joints']} joints ({', '.join(j['name'] for j in info['joints'])}), "
          f"model hash {info['model_hash']} -> {bdir}")
    print_arm_warnings(info, "armctl build")
    check = bdir / "firmware" / "arm_rnea_check"
    if check.exists():  # host builds: the firmware's inverse dynamics against MuJoCo's on this arm
        r = subprocess.run([str(check)], capture_output=True, text=True)
        for line in [ln for ln in r.stdout.splitlines() if "vs mj_inverse" in ln] or ["?"]:
            print(f"arm: {line}")  # the general RNEA, then the arm's generated kernel
        if r.returncode != 0:
            raise CommandError(f"the firmware's RNEA disagrees with MuJoCo on this arm:\n{r.stderr[-2000:]}")
    return 0
