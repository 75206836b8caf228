"""armctl's commands, one pattern: each command module has `add_subparser(sub)`, which makes its
parser (help text and `set_defaults(run=...)`), and `run(ns) -> int`, its exit code.

A command raises instead of printing an error and returning a code: tools/cli.py main() holds the
one map from exception to exit code and message (`armctl <command>: <message>`). The two
exceptions here are for a command's own conditions, which no library exception names."""

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
