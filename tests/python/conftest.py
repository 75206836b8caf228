"""Shared fixtures: the repo on sys.path, the built binaries, ports for bus and telemetry that no
other test or run uses at the same time."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from tools.run.slots import Slot

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))


@pytest.fixture(scope="session")
def build_dir() -> Path:
    return Path(os.environ.get("ARM_BUILD_DIR", REPO / "build" / "debug"))


def _firmware_program(build_dir: Path, name: str) -> Path:
    exe = build_dir / "firmware" / name
    if not exe.exists():
        pytest.skip(f"{exe} not built (run tools/armctl build --preset debug)")
    return exe


@pytest.fixture(scope="session")
def boot_bin(build_dir: Path) -> Path:
    return _firmware_program(build_dir, "arm_canopen_boot")


@pytest.fixture(scope="session")
def controller_bin(build_dir: Path) -> Path:
    return _firmware_program(build_dir, "arm_controller")


@pytest.fixture(scope="session")
def sim_exe(controller_bin: Path) -> Path:
    """arm_sim of the same build (tests that drive it frame by frame: sim_master.py)."""
    from host_sim.launch import sim_binary

    exe = sim_binary(controller_bin.parent.parent.name)
    if not exe.exists():
        pytest.skip(f"{exe} not built")
    return exe


@pytest.fixture()
def slot() -> Iterator[Slot]:
    """A run slot held for the test (tools/run/slots.py): its bus ports (slot.can_port + 0..7) and
    telemetry port are this test's alone, whatever else runs (armctl test runs tests side by side,
    each HIL run takes a slot of its own, a user's demo may be running)."""
    from tools.run.slots import acquire_slot

    with acquire_slot(quiet_ports=True) as s:
        yield s


@pytest.fixture()
def bus_spec(slot: Slot) -> str:
    """A bus of its own per test (its slot's first port; + 1 is the test's too)."""
    from tools.run.slots import CAN_GROUP

    return f"udp:{CAN_GROUP}:{slot.can_port}"


@pytest.hookimpl(trylast=True)  # after pytest's own reordering by fixture (a module's parametrized fixtures)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The files marked `long` first, each file's tests kept together and in order: side by side
    (armctl test), pytest-xdist hands out files in this order, and the pass ends when its last
    file does."""
    items.sort(key=lambda item: item.get_closest_marker("long") is None)


def _strict() -> bool:
    return os.environ.get("ARM_TEST_STRICT") == "1"


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector: pytest.Collector):  # noqa: ANN201 - pytest hook
    """ARM_TEST_STRICT=1 covers collection too: a test file that skips itself whole (a module-level
    importorskip of a package armctl installs, a missing build) fails, naming the file and why,
    instead of taking its tests out of the run unseen."""
    outcome = yield
    report = outcome.get_result()
    if _strict() and report.skipped:
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        report.outcome = "failed"
        report.longrepr = f"{collector.nodeid}: skipped whole under ARM_TEST_STRICT=1 (everything should be installed): {reason}"


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]):  # noqa: ANN201 - pytest hook
    """Under `armctl test` as root on Debian (ARM_TEST_STRICT=1), armctl has installed every
    package the tests need, so a test that skips for a missing tool is a failure, not a pass."""
    outcome = yield
    report = outcome.get_result()
    if _strict() and report.skipped and not hasattr(report, "wasxfail"):
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        report.outcome = "failed"
        report.longrepr = f"skipped under ARM_TEST_STRICT=1 (everything should be installed): {reason}"
