"""Moved to gen/lib/outdir.py (the library layer); this name stays for branches in flight."""

from gen.lib.outdir import *  # noqa: F401,F403
