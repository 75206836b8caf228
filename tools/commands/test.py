"""armctl test: every test, ctest (ASan/UBSan build) and pytest.

pytest runs in two passes: first every test not marked `serial`, side by side on every core
(pytest-xdist, a test file to a worker: its module fixtures once, its own ports and folders), then
the `serial` ones alone (each says why at its mark: realtime runs, the qemu VM, wall-clock
deadlines). Side by side, tests hear nothing of each other: every bus and telemetry port a test
or run uses comes from a run slot it holds (tools/run/slots.py, tests/python/conftest.py)."""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

from gen.lib.paths import REPO, build_dir, env_with_repo
from tools.build import build
from tools.commands import CommandError, UsageError

SLOWEST_SHOWN = 15  # the slowest tests named at the end of each pass: the suite's time is a target (docs/quickstart.md)
NO_TESTS_COLLECTED = 5  # pytest's exit code when a pass selects nothing (e.g. `-k` names serial tests only)


def add_subparser(sub: argparse._SubParsersAction) -> None:
    t = sub.add_parser("test", help="every test: ctest (ASan/UBSan build) and pytest")
    t.add_argument("--workers", type=int, default=None,
                   help="pytest workers for the tests that may share the cores [the cores this process may use]")
    t.add_argument("--record", action="store_true",
                   help="keep the suite's time for the docs (docs/results/test.json; the whole suite, all passed)")
    t.add_argument("pytest_args", nargs="*", help="extra pytest arguments for both passes, e.g. -k hil")
    t.set_defaults(run=run)


def pytest_passes(workers: int) -> list[tuple[str, list[str]]]:
    """(name, pytest arguments) of each pass: side by side on `workers` workers, then alone."""
    # --no-loadscope-reorder: xdist would hand out the files with the most tests first; the suite's
    # own order (tests/python/conftest.py: the long files first) is the one that ends the pass evenly
    side = ["-n", str(workers), "--dist", "loadfile", "--no-loadscope-reorder"]
    shared = ["-m", "not serial", *(side if workers > 1 else [])]
    return [("side by side", shared), ("alone", ["-m", "serial"])]


def run(ns: argparse.Namespace) -> int:
    workers = ns.workers if ns.workers is not None else len(os.sched_getaffinity(0))
    if workers < 1:
        raise CommandError(f"--workers: {workers} is not a worker count (1 or more)")
    if ns.record and ns.pytest_args:
        raise UsageError("--record: the docs give the whole suite's time; a run with pytest arguments is part of it")
    started = time.monotonic()
    seconds: dict[str, float] = {}  # each phase's wall time, for --record

    def lap(phase: str, since: float) -> float:
        now = time.monotonic()
        seconds[phase] = round(now - since, 1)
        return now
    # side by side: the debug build ends on one long compile (the sanitized Eigen reference step)
    # while the other core would idle; the release build fills it
    with ThreadPoolExecutor(max_workers=2) as pool:
        for done in [pool.submit(build, preset) for preset in ("debug", "release")]:
            done.result()
    t = lap("builds (debug and release, side by side)", started)
    failed = []
    r = subprocess.run(["ctest", "--preset", "debug", "--output-on-failure"], cwd=REPO)
    if r.returncode != 0:
        failed.append("ctest")
    t = lap("ctest", t)
    env = env_with_repo()
    env["ARM_BUILD_DIR"] = str(build_dir("debug"))
    # As root on Debian, tools/armctl has installed every package: no test may skip for a missing one.
    if os.geteuid() == 0 and shutil.which("dpkg-query"):
        env["ARM_TEST_STRICT"] = "1"
    ran = 0
    for name, args in pytest_passes(workers):
        print(f"armctl test: pytest, the tests run {name}", flush=True)
        r = subprocess.run([sys.executable, "-m", "pytest", "-q", f"--durations={SLOWEST_SHOWN}", *args,
                            "tests/python", *ns.pytest_args], cwd=REPO, env=env)
        t = lap(f"pytest, {name}", t)
        if r.returncode == 0:
            ran += 1
        elif r.returncode != NO_TESTS_COLLECTED:
            failed.append(f"pytest ({name})")
    if not ran and not failed:
        failed.append("pytest (no test selected)")
    if failed:
        raise CommandError(f"FAILED ({', '.join(failed)})")
    print("armctl test: all passed")
    if ns.record:
        from tools.bench.record import record

        record("test", {"wall_s": round(time.monotonic() - started, 1), "phases_s": seconds, "workers": workers,
                        "strict": env.get("ARM_TEST_STRICT") == "1"}, "tools/armctl test --record")
    return 0
