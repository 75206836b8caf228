"""armctl: synthesise, build, run hardware-in-the-loop, test. One entry point, subcommands."""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
from pathlib import Path

from tools.build import PRESETS, TARGETS, BuildError, build
from tools.paths import REPO, build_dir, env_with_repo


def cmd_setup(ns: argparse.Namespace) -> int:
    # tools/armctl has already installed the Debian packages and the venv; configure both builds.
    for preset in PRESETS:
        build(preset)
    print("armctl: set-up complete (.venv, build/debug, build/release)")
    return 0


def cmd_build(ns: argparse.Namespace) -> int:
    build(TARGETS[ns.target] if ns.target else ns.preset, quiet=False)
    return 0


def _print_run(run: dict) -> None:
    from tools.run_analysis import table

    print(table(run))


def cmd_hil(ns: argparse.Namespace) -> int:
    from tools.hil import HilError, HilOptions, run_hil

    if not ns.duration > 0:
        print(f"armctl hil: --duration: must be > 0, got {ns.duration}", file=sys.stderr)
        return 2
    if ns.bus == "vm":
        return _hil_in_vm(ns)
    build("release")
    try:
        run = run_hil(HilOptions(out=ns.out, duration_s=ns.duration, method=ns.method, mode=ns.mode,
                                 bus=ns.bus, topology=ns.topology, bus_timing=ns.bus_timing))
        print(f"bus: {run['environment']['bus_choice']}")
        for name, pct in run["environment"]["bus_load_pct"].items():
            if pct > 100.0:
                print(f"armctl hil: bus {name} needs {pct:g} % of its time at 1 kHz (tools/armctl busload): the "
                      "frames of a period do not fit in it" + (", so commands end late (--bus-timing)"
                                                               if ns.bus_timing else ""), file=sys.stderr)
    except HilError as exc:
        print(f"armctl hil: {exc}", file=sys.stderr)
        return 1
    _print_run(run)
    print(f"results: {ns.out / 'run.json'}  log: {ns.out / 'telemetry.lcmlog'}")
    return 0 if run["results"]["result"] == "ok" else 1


def _hil_in_vm(ns: argparse.Namespace) -> int:
    """The same HIL run inside the qemu VM whose kernel has vcan0 and vcan1 (tools/vm)."""
    from tools.vm.image import VmError
    from tools.vm.run import run_in_vm

    build("release")
    inner = ["tools/armctl", "hil", "--bus", "vcan", "--duration", f"{ns.duration:g}", "--method", ns.method,
             "--mode", ns.mode, "--out", str(ns.out.resolve()),
             *(["--topology", str(ns.topology.resolve())] if ns.topology else []),
             *(["--bus-timing"] if ns.bus_timing else [])]
    print("armctl hil: running inside the qemu VM (software emulation: minutes, not seconds)")
    try:
        return run_in_vm(inner, timeout=3600.0 + 600.0 * ns.duration, keep=False).returncode
    except VmError as exc:
        print(f"armctl hil --bus vm: {exc}", file=sys.stderr)
        return 1


def cmd_demo(ns: argparse.Namespace) -> int:
    from tools import study

    print(f"armctl demo: a short study, every method {ns.duration:g} s in lockstep HIL on the default arm "
          f"with the paper's 5 % uncertainty -> {ns.out}")
    ns.config, ns.methods = study.DEFAULT_CONFIG, None
    return study.cmd_study(ns)


def cmd_test(ns: argparse.Namespace) -> int:
    build("debug")
    build("release")
    failed = []
    r = subprocess.run(["ctest", "--preset", "debug", "--output-on-failure"], cwd=REPO)
    if r.returncode != 0:
        failed.append("ctest")
    env = env_with_repo()
    env["ARM_BUILD_DIR"] = str(build_dir("debug"))
    # As root on Debian, tools/armctl has installed every package: no test may skip for a missing one.
    if os.geteuid() == 0 and shutil.which("dpkg-query"):
        env["ARM_TEST_STRICT"] = "1"
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "tests/python", *ns.pytest_args], cwd=REPO, env=env)
    if r.returncode != 0:
        failed.append("pytest")
    if failed:
        print(f"armctl test: FAILED ({', '.join(failed)})", file=sys.stderr)
        return 1
    print("armctl test: all passed")
    return 0


def cmd_synth(ns: argparse.Namespace) -> int:
    from gen.synth import cli as synth_cli

    return synth_cli.run(ns)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="armctl", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)

    sub.add_parser("setup", help="install everything and configure the builds").set_defaults(fn=cmd_setup)

    b = sub.add_parser("build", help="build the firmware and tests with a CMake preset")
    b.add_argument("--preset", choices=PRESETS, default="release")
    b.add_argument("--target", choices=tuple(TARGETS),
                   help="cross target (host = release; aarch64; cortex-m4/m7/m3 images); overrides --preset")
    b.set_defaults(fn=cmd_build)

    from tools import timing

    tm = sub.add_parser("timing", help="real-time loop latency vs cyclictest in the same run")
    timing.add_arguments(tm)
    tm.set_defaults(fn=timing.run)

    h = sub.add_parser("hil", help="one hardware-in-the-loop run")
    h.add_argument("--duration", type=float, default=5.0, help="simulated seconds")
    h.add_argument("--method", default="pm", choices=("pm", "pm-paper", "gh2", "pd", "tde", "usde-smc"))
    h.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep")
    h.add_argument("--bus", choices=("auto", "udp", "vcan", "vm"), default="auto",
                   help="auto: vcan if this kernel has SocketCAN and vcan0, vcan1 (one per bus of "
                        "firmware/protocol/buses.toml), else udp (one port per bus; says which); "
                        "vm: the whole run inside the qemu VM that has vcan0, vcan1")
    h.add_argument("--topology", type=Path, default=None,
                   help="which drive is on which bus, and each bus's bit rates [firmware/protocol/buses.toml]")
    h.add_argument("--bus-timing", action="store_true",
                   help="emulate the buses' bit timing in the simulator (frame lengths, arbitration by id): "
                        "commands act when their frames would end on the bus")
    h.add_argument("--out", type=Path, default=REPO / "runs" / "hil")
    h.set_defaults(fn=cmd_hil)

    d = sub.add_parser("demo", help="the main job: set-up if needed, a short study of every method, the table")
    d.add_argument("--out", type=Path, default=REPO / "runs" / "demo")
    d.add_argument("--duration", type=float, default=3.0, help="trajectory seconds per method")
    d.set_defaults(fn=cmd_demo)

    t = sub.add_parser("test", help="every test: ctest (ASan/UBSan build) and pytest")
    t.add_argument("pytest_args", nargs="*", help="extra pytest arguments, e.g. -k hil")
    t.set_defaults(fn=cmd_test)

    from gen.synth import cli as synth_cli

    s = sub.add_parser("synth", help="LMI synthesis of the estimator and controller, emitted as C")
    synth_cli.add_arguments(s)
    s.set_defaults(fn=cmd_synth)

    from tools import busload, vcan

    vc = sub.add_parser("vcan", help="real SocketCAN: vcan interfaces natively, or a qemu VM that has them (status/up/setup/run)")
    vcan.add_arguments(vc)
    vc.set_defaults(fn=vcan.run)

    bl = sub.add_parser("busload", help="worst-case CAN bus load per control period from the DBC; refuses > budget")
    busload.add_arguments(bl)
    bl.set_defaults(fn=busload.run)

    from tools import study

    st = sub.add_parser("study", help="every method on the same trajectory, uncertainty and seed; the report")
    study.add_study_arguments(st)
    st.set_defaults(fn=study.cmd_study)
    tu = sub.add_parser("tune", help="the baselines' gains: grid search on the tuning seed and trajectory")
    study.add_tune_arguments(tu)
    tu.set_defaults(fn=study.cmd_tune)

    from tools import bench

    bn = sub.add_parser("bench", help="benchmarks that write results files (instructions per step; synthesis time)")
    bench.add_arguments(bn)
    bn.set_defaults(fn=bench.run)

    ns = p.parse_args(argv)
    try:
        return int(ns.fn(ns))
    except BuildError as exc:
        print(exc, file=sys.stderr)
        return 1


if __name__ == "__main__":
    os.chdir(REPO)
    sys.exit(main())
