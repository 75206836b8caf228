"""A command's own failures, for the conditions no library exception names. Here, below every
package of tools/, so that a module that is both library and command (tools/vcan.py,
tools/bench/fuzz.py, tools/bench/timing.py) raises them without importing the CLI's layer;
tools/cli.py maps them to exit codes (`armctl <command>: <message>`)."""

from __future__ import annotations


class CommandError(Exception):
    """The command failed: `armctl <command>: <message>`, exit `code` (1 unless told)."""

    def __init__(self, message: str, code: int = 1) -> None:
        super().__init__(message)
        self.code = code


class UsageError(CommandError):
    """A bad value on the command line (or in a file it names): exit 2."""

    def __init__(self, message: str) -> None:
        super().__init__(message, 2)
