"""Moved to gen/lib/toml_input.py (the library layer); this name stays for branches in flight."""

from gen.lib.toml_input import *  # noqa: F401,F403
