"""armctl: synthesise, build, run hardware-in-the-loop, test. One entry point, subcommands."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable

from gen.lib.one_line import one_line
from gen.lib.paths import REPO


# Which module registers each command (its add_subparser), in the order `armctl --help` lists them.
# `armctl CMD` imports CMD's module alone: a command pays for its own imports, not every command's
# (MuJoCo, cvxpy, numpy: half a second here, tens of seconds inside the qemu VM). test_cli checks
# this table against what the modules register.
COMMAND_MODULES = {
    "setup": "tools.commands.setup", "build": "tools.commands.build", "cluster-certs": "tools.run.cluster",
    "timing": "tools.bench.timing", "hil": "tools.commands.hil", "plant": "tools.commands.plant",
    "commission": "tools.commands.commission", "run": "tools.commands.run", "identify": "tools.commands.identify", "demo": "tools.commands.demo",
    "test": "tools.commands.test", "synth": "tools.commands.synth", "vcan": "tools.vcan",
    "busload": "tools.busload", "drive": "tools.commands.drive", "study": "tools.study", "tune": "tools.study",
    "faults": "tools.bench.faults", "fuzz": "tools.bench.fuzz", "bench": "tools.bench", "docs": "tools.commands.docs",
    "arms": "tools.commands.arms", "render": "tools.commands.render", "export": "tools.commands.export",
    "lock": "tools.commands.lock",
}


def _commands(command: str | None = None) -> list:
    """The command modules, in the order `armctl --help` lists them (only `command`'s when it names
    one): each has add_subparser(sub) and a run(ns) -> int that its parser names
    (set_defaults(run=...)); tools/commands/__init__.py."""
    import importlib

    names = [COMMAND_MODULES[command]] if command in COMMAND_MODULES else list(dict.fromkeys(COMMAND_MODULES.values()))
    return [importlib.import_module(name) for name in names]


def _errors() -> list[tuple[tuple[type[BaseException], ...], int | Callable[[BaseException], int], str]]:
    """The one map from exception to exit code and message: (types, exit code, message), first match
    wins; a command raises and never prints its own error. {prefix} is `armctl <command>` (or the
    command's set_defaults(prefix=...)); a command may change a code with set_defaults(exit_codes=...)."""
    from gen.arm import ArmError
    from gen.lib.busload import ConfigError as BusConfigError
    from gen.lib.escape import EscapeError
    from gen.lib.outdir import OutDirError
    from tools.run import procs
    from tools.build.arm import ArmChoiceError
    from tools.build import BuildError
    from tools.build.packages import PackagesMissing
    from tools.run.cluster import ClusterError
    from tools.commands import CommandError
    from tools.bench.fuzz import FuzzError
    from tools.bench.pil import PilBenchError
    from tools.bench.record import RecordError
    from tools.run.hil import HilError
    from tools.study.config import StudyConfigError
    from tools.vm.image import VmError

    return [
        ((procs.Interrupted,), lambda exc: 128 + exc.signum,
         "armctl {command}: interrupted ({exc}); no process of this command is left running"),
        ((CommandError,), lambda exc: exc.code, "{prefix}: {exc}"),
        ((BuildError,), 1, "{exc}"),  # it names the build and its log itself
        # Bad input: a value, a file it names, the arm, the output folder, the cluster.
        ((StudyConfigError, ArmChoiceError, ArmError, OutDirError, ClusterError, BusConfigError, RecordError,
          EscapeError), 2, "{prefix}: {exc}"),
        # The run or the machine: a run that cannot run, the VM, a compiler, a full disk (OutputError is an OSError).
        ((HilError, VmError, FuzzError, PilBenchError, PackagesMissing, OSError), 1, "{prefix}: {exc}"),
    ]


def exit_code(exc: BaseException, ns: argparse.Namespace) -> int | None:
    """Print exc's message as the map says and return its exit code; None: not in the map (a bug)."""
    overrides = getattr(ns, "exit_codes", None) or {}
    for types, code, how in _errors():
        if isinstance(exc, types):
            code = next((c for t, c in overrides.items() if isinstance(exc, t)), code)
            command = getattr(ns, "command", None) or "?"
            prefix = getattr(ns, "prefix", None) or f"armctl {command}"
            # bad input (a ValueError) is one line, whatever line breaks the user's names hold
            shown = one_line(str(exc)) if isinstance(exc, ValueError) else exc
            print(how.format(command=command, prefix=prefix, exc=shown), file=sys.stderr)
            return code(exc) if callable(code) else code
    return None


def run_command(ns: argparse.Namespace) -> int:
    """ns.run(ns), its exceptions turned into exit codes and messages by the one map."""
    from tools.run import procs

    procs.install()
    try:
        code = int(ns.run(ns))
        # results kept for the docs (--record, a flag): their figures at once; not a --record FILE
        # (run, commission, identify: the commissioning record), which renders nothing
        if code == 0 and getattr(ns, "record", None) is True:
            from tools.commands.docs import render

            skipped: list[str] = []  # regions of other results files that cannot be rendered yet
            render(skipped=skipped)
            for why in skipped:
                print(f"armctl {ns.command}: not rendered: {why}", file=sys.stderr)
        return code
    except (Exception, KeyboardInterrupt) as exc:
        code = exit_code(exc, ns)
        if code is None:
            raise
        return code


def parser(command: str | None = None) -> argparse.ArgumentParser:
    """armctl's parser: every command's, or only `command`'s when it names one (its module alone is
    imported; a module that registers more than one command, registers them all)."""
    p = argparse.ArgumentParser(prog="armctl", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)
    for module in _commands(command):
        module.add_subparser(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    from tools.run import procs

    # First: a signal while the commands' modules import (a second or more on a loaded machine) is
    # then a one-line exit (128 + N), not Python's default death or a traceback.
    procs.install()
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        ns = parser(argv[0] if argv else None).parse_args(argv)
    except procs.Interrupted as exc:
        return exit_code(exc, argparse.Namespace(command=argv[0] if argv else "armctl"))
    return run_command(ns)


if __name__ == "__main__":
    os.chdir(REPO)
    sys.exit(main())
