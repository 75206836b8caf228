"""Moved to gen/lib/paths.py (the library layer); this name stays for branches in flight."""

from gen.lib.paths import *  # noqa: F401,F403
