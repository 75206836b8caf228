"""armctl's commands, one pattern: each command module has `add_subparser(sub)`, which makes its
parser (help text and `set_defaults(run=...)`), and `run(ns) -> int`, its exit code.

A command raises instead of printing an error and returning a code: tools/cli.py main() holds the
one map from exception to exit code and message (`armctl <command>: <message>`). The two
exceptions of tools/errors.py are for a command's own conditions, which no library exception names."""

from __future__ import annotations

from tools.errors import CommandError, UsageError

__all__ = ["CommandError", "UsageError"]
