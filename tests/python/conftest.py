"""Shared fixtures: the repo on sys.path, the built binaries, free ports for bus and telemetry."""

from __future__ import annotations

import os
import random
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))


@pytest.fixture(scope="session")
def build_dir() -> Path:
    return Path(os.environ.get("ARM_BUILD_DIR", REPO / "build" / "debug"))


@pytest.fixture(scope="session")
def controller_bin(build_dir: Path) -> Path:
    exe = build_dir / "firmware" / "arm_controller"
    if not exe.exists():
        pytest.skip(f"{exe} not built (run tools/armctl build --preset debug)")
    return exe


@pytest.fixture()
def bus_spec() -> str:
    """A bus of its own per test, so tests and a running demo never hear each other."""
    return f"udp:239.74.163.2:{random.randint(44000, 44999)}"
