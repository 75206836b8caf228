"""armctl setup: tools/armctl has already installed the Debian packages and the venv; configure both builds."""

from __future__ import annotations

import argparse

from tools.build import PRESETS, build


def add_subparser(sub: argparse._SubParsersAction) -> None:
    sub.add_parser("setup", help="install everything and configure the builds").set_defaults(run=run)


def run(ns: argparse.Namespace) -> int:
    for preset in PRESETS:
        build(preset)
    print("armctl: set-up complete (.venv, build/debug, build/release)")
    return 0
