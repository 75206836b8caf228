"""Moved to gen/lib/atomic_output.py (the library layer); this name stays for branches in flight."""

from gen.lib.atomic_output import *  # noqa: F401,F403
