"""armctl lock: requirements.lock from requirements.txt, every pinned package with the sha256 of each
of its artifacts (every wheel and sdist of that version), written by pip-tools' pip-compile.
tools/armctl installs the lock with `pip install --require-hashes`: an artifact replaced under the
same version is refused.

    tools/armctl lock                  the pins kept, a new requirement resolved in, every hash
    tools/armctl lock --upgrade PKG    PKG (and what it needs) moved to its newest version
    tools/armctl lock --check          exit 1 if requirements.lock is not what the first writes

It asks PyPI for the hashes (a few minutes the first time; hashes already in the lock are kept)."""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from gen.lib.atomic_output import write_text_atomic
from gen.lib.paths import REPO
from tools.commands import CommandError

LOCK = REPO / "requirements.lock"
REQUIREMENTS = REPO / "requirements.txt"
# the one way the lock is made: also what its header names (CUSTOM_COMPILE_COMMAND)
PIP_COMPILE = ["-m", "piptools", "compile", "--generate-hashes", "--allow-unsafe", "--strip-extras",
               "--no-emit-find-links", "--quiet"]


def add_subparser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("lock", help="requirements.lock from requirements.txt, every artifact by its hash (pip-tools)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--upgrade", action="append", default=[], metavar="PKG",
                   help="move this package to its newest version allowed (repeatable) [every pin kept]")
    p.add_argument("--check", action="store_true", help="write nothing; exit 1 if the lock differs from what this "
                                                        "command writes")
    p.set_defaults(run=run)


def locked(upgrade: list[str] | None = None) -> str:
    """The lock pip-compile makes from requirements.txt, starting from the current lock (its pins and
    hashes kept, but for the packages to upgrade)."""
    with tempfile.TemporaryDirectory(prefix="armctl-lock-") as tmp:
        out = Path(tmp) / "requirements.lock"
        shutil.copyfile(LOCK, out)
        env = {**os.environ, "CUSTOM_COMPILE_COMMAND": "tools/armctl lock"}
        env.pop("PIP_FIND_LINKS", None)  # a machine's local wheels are no part of the lock
        args = [sys.executable, *PIP_COMPILE, *[a for pkg in upgrade or [] for a in ("--upgrade-package", pkg)],
                "--output-file", str(out), REQUIREMENTS.name]
        r = subprocess.run(args, cwd=REPO, env=env, capture_output=True, text=True)
        if r.returncode != 0:
            lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
            raise CommandError(f"pip-compile failed (exit {r.returncode}): {lines[-1] if lines else 'no message'}", 1)
        return out.read_text()


def run(ns: argparse.Namespace) -> int:
    if ns.check and ns.upgrade:
        raise CommandError("--check with --upgrade: a check writes nothing and moves nothing", 2)
    text = locked(ns.upgrade)
    if ns.check:
        if text != LOCK.read_text():
            raise CommandError(f"{LOCK.name} is not what `tools/armctl lock` makes from {REQUIREMENTS.name}: run it", 1)
        print(f"armctl lock: {LOCK.name} is what {REQUIREMENTS.name} makes, every artifact hashed")
        return 0
    if text != LOCK.read_text():
        write_text_atomic(LOCK, text)
        print(f"armctl lock: {LOCK.name} written")
    else:
        print(f"armctl lock: {LOCK.name} unchanged")
    return 0
