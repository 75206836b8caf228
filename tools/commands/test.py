"""armctl test: every test, ctest (ASan/UBSan build) and pytest."""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys

from gen.lib.paths import REPO, build_dir, env_with_repo
from tools.build import build
from tools.commands import CommandError


def add_subparser(sub: argparse._SubParsersAction) -> None:
    t = sub.add_parser("test", help="every test: ctest (ASan/UBSan build) and pytest")
    t.add_argument("pytest_args", nargs="*", help="extra pytest arguments, e.g. -k hil")
    t.set_defaults(run=run)


def run(ns: argparse.Namespace) -> int:
    build("debug")
    build("release")
    failed = []
    r = subprocess.run(["ctest", "--preset", "debug", "--output-on-failure"], cwd=REPO)
    if r.returncode != 0:
        failed.append("ctest")
    env = env_with_repo()
    env["ARM_BUILD_DIR"] = str(build_dir("debug"))
    # As root on Debian, tools/armctl has installed every package: no test may skip for a missing one.
    if os.geteuid() == 0 and shutil.which("dpkg-query"):
        env["ARM_TEST_STRICT"] = "1"
    # the slowest tests named at the end: the suite's time is a target (README, issue 19)
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "--durations=15", "tests/python", *ns.pytest_args],
                       cwd=REPO, env=env)
    if r.returncode != 0:
        failed.append("pytest")
    if failed:
        raise CommandError(f"FAILED ({', '.join(failed)})")
    print("armctl test: all passed")
    return 0
