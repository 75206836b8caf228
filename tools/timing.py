"""armctl timing: being written (issue 7)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--duration", type=float, default=10.0)
    p.add_argument("--out", type=Path, default=Path("runs/timing"))


def run(ns: argparse.Namespace) -> int:
    print("armctl timing: not implemented yet", file=sys.stderr)
    return 1
