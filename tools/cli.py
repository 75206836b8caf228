"""armctl: synthesise, build, run hardware-in-the-loop, test. One entry point, subcommands."""

from __future__ import annotations

import argparse
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

from gen.lib.atomic_output import OutputError
from tools.arm import add_arm_arguments
from gen.lib.outdir import OutDirError, check_out_dir
from tools.methods import method_names
from tools.verdict import DEFAULT_MAX_ERROR_DEG, FOLLOWING_ERROR_STOP_DEG
from tools.build import PRESETS, TARGETS, BuildError, build
from gen.lib.paths import REPO, build_dir, env_with_repo


def cmd_setup(ns: argparse.Namespace) -> int:
    # tools/armctl has already installed the Debian packages and the venv; configure both builds.
    for preset in PRESETS:
        build(preset)
    print("armctl: set-up complete (.venv, build/debug, build/release)")
    return 0


def cmd_build(ns: argparse.Namespace) -> int:
    from tools.arm import ArmChoiceError, arm_from_args, arm_info, build_arm, print_arm_warnings

    try:
        arm = arm_from_args(ns)
    except ArmChoiceError as exc:
        print(f"armctl build: {exc}", file=sys.stderr)
        return 2
    bdir = build_arm(TARGETS[ns.target] if ns.target else ns.preset, arm, quiet=False)
    info = arm_info(bdir)
    print(f"arm: {info['name']}, {info['n_joints']} joints ({', '.join(j['name'] for j in info['joints'])}), "
          f"model hash {info['model_hash']} -> {bdir}")
    print_arm_warnings(info, "armctl build")
    check = bdir / "firmware" / "arm_rnea_check"
    if check.exists():  # host builds: the firmware's inverse dynamics against MuJoCo's on this arm
        r = subprocess.run([str(check)], capture_output=True, text=True)
        for line in [ln for ln in r.stdout.splitlines() if "vs mj_inverse" in ln] or ["?"]:
            print(f"arm: {line}")  # the general RNEA, then the arm's generated kernel
        if r.returncode != 0:
            print(f"armctl build: the firmware's RNEA disagrees with MuJoCo on this arm:\n{r.stderr[-2000:]}",
                  file=sys.stderr)
            return 1
    return 0


def _print_run(run: dict) -> None:
    from tools.run_analysis import table

    print(table(run))


def _float_list(text: str) -> list[float]:
    try:
        vals = [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a comma-separated list of numbers") from None
    if not all(math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError(f"'{text}': every value must be finite")
    return vals


def _hil_study_run(ns: argparse.Namespace) -> int:
    """hil --scenario: one run of a study, made as the study makes it (tools/study.py
    study_run_spec) and run as it runs it (tools/runner.py execute)."""
    import json
    from dataclasses import asdict

    from tools import study
    from tools.arm import ArmChoiceError, arm_from_args, arm_info, build_arm, print_arm_warnings
    from tools.hil import HilError
    from tools.runner import DONE, execute
    from tools.study_config import StudyConfigError, load

    try:
        if ns.tuned is not None and ns.knobs is not None:
            raise StudyConfigError("--tuned and --knobs: give one")
        if ns.tuned is not None:
            if ns.method not in (None, ns.tuned):
                raise StudyConfigError(f"--tuned {ns.tuned} with --method {ns.method}: give one method")
            ns.method = ns.tuned
        knobs = None
        if ns.knobs is not None:
            try:
                knobs = json.loads(ns.knobs)
            except ValueError as exc:
                raise StudyConfigError(f"--knobs: not JSON ({exc})") from None
            if not isinstance(knobs, dict):
                raise StudyConfigError("--knobs: a JSON object of knob: value")
        cfg = load(ns.config or study.DEFAULT_CONFIG)
        arm = arm_from_args(ns)
        check_out_dir(ns.out)
        if ns.bus not in study.BUSES:
            raise StudyConfigError(f"--scenario: --bus {ns.bus}: a study's run runs on {', '.join(study.BUSES)}")
        print_arm_warnings(arm_info(build_arm("release", arm)), "armctl hil")
        seed = cfg.seed if ns.seed is None else ns.seed
        spec, traj, notes = study.study_run_spec(cfg, arm, ns.scenario, ns.method or "pm", seed, ns.duration, knobs,
                                                 ns.tuned is not None, ns.out.resolve(), ns.bus)
    except (StudyConfigError, ArmChoiceError, OutDirError) as exc:
        print(f"armctl hil: {exc}", file=sys.stderr)
        return 2
    for n in notes:
        print(f"armctl hil: {n}", file=sys.stderr)
    print(f"armctl hil: {ns.method or 'pm'} in scenario {ns.scenario} of {cfg.path}, seed {seed}, "
          f"{spec.duration_s:g} s, knobs {json.dumps(spec.labels['knobs'])}; trajectory ({traj['from']}) amplitudes "
          f"{traj['amp']} rad, frequencies {traj['freq_hz']} Hz")
    (ns.out / DONE).unlink(missing_ok=True)  # run it, never take a kept one
    try:
        run = execute(asdict(spec))
    except HilError as exc:
        print(f"armctl hil: {exc}", file=sys.stderr)
        return 1
    _print_run(run)
    print(f"results: {ns.out / 'run.json'}  log: {ns.out / 'telemetry.lcmlog'}")
    from tools import procs

    if procs.interrupted is not None:
        return 128 + procs.interrupted
    return 0 if run["results"]["result"] == "ok" else 1


def cmd_hil(ns: argparse.Namespace) -> int:
    from tools.arm import ArmChoiceError, arm_from_args, arm_info, build_arm, print_arm_warnings, reference_for
    from tools.hil import HilError, HilOptions, run_hil
    from tools.study_config import DRIVE_PRESETS
    from tools.verdict import Bounds

    if ns.duration is not None and not (math.isfinite(ns.duration) and 0.001 <= ns.duration <= 86400):
        print(f"armctl hil: --duration: must be in [0.001, 86400] s, got {ns.duration}", file=sys.stderr)
        return 2
    if ns.scenario is not None:
        return _hil_study_run(ns)
    study_only = [o for o, v in (("--config", ns.config), ("--seed", ns.seed), ("--knobs", ns.knobs),
                                 ("--tuned", ns.tuned)) if v is not None]
    if study_only or ns.method == "pm-paper-weights":
        print(f"armctl hil: {', '.join(study_only) or '--method pm-paper-weights'}: one run of a study: give --scenario",
              file=sys.stderr)
        return 2
    ns.duration = 5.0 if ns.duration is None else ns.duration
    ns.method = ns.method or "pm"
    if not (math.isfinite(ns.duration) and 0.001 <= ns.duration <= 86400):
        print(f"armctl hil: --duration: must be in [0.001, 86400] s, got {ns.duration}", file=sys.stderr)
        return 2
    if not (0 <= ns.ref_hold <= 3600):
        print(f"armctl hil: --ref-hold: must be in [0, 3600] s, got {ns.ref_hold}", file=sys.stderr)
        return 2
    if (ns.ref_amp is None) != (ns.ref_freq is None):
        print("armctl hil: --ref-amp and --ref-freq go together", file=sys.stderr)
        return 2
    if not (math.isfinite(ns.max_error_deg) and ns.max_error_deg > 0):
        print(f"armctl hil: --max-error-deg: must be a number above 0, got {ns.max_error_deg}", file=sys.stderr)
        return 2
    if ns.max_error_deg >= FOLLOWING_ERROR_STOP_DEG:
        print(f"armctl hil: --max-error-deg {ns.max_error_deg:g}: the safety layer stops a run at "
              f"{FOLLOWING_ERROR_STOP_DEG:.3g} deg of following error first (verdict failed): the bound is never "
              "reached", file=sys.stderr)
    try:
        arm = arm_from_args(ns)
        check_out_dir(ns.out)
    except (ArmChoiceError, OutDirError) as exc:
        print(f"armctl hil: {exc}", file=sys.stderr)
        return 2
    if ns.topology is not None:  # the file itself, before the build; its drives against the arm's after it
        from gen.lib import busload

        try:
            busload.load_topology(ns.topology, busload.topology_drives(ns.topology))
        except busload.ConfigError as exc:
            print(f"armctl hil: --topology: {exc}", file=sys.stderr)
            return 2
    if ns.can_port is not None and not 1024 <= ns.can_port <= 65532:
        print(f"armctl hil: --can-port: must be in [1024, 65532], got {ns.can_port}", file=sys.stderr)
        return 2
    if ns.bus == "vm":
        return _hil_in_vm(ns)
    try:
        bdir = build_arm("release", arm)
        info = arm_info(bdir)
        amp, freq, warnings = reference_for(info, ns.ref_amp, ns.ref_freq, bdir)
    except ArmChoiceError as exc:
        print(f"armctl hil: {exc}", file=sys.stderr)
        return 2
    print_arm_warnings(info, "armctl hil")
    if info.get("design"):
        print(f"design: {info['design']['config']} ({info['design']['why']})")
    for w in warnings:
        print(f"armctl hil: {w}", file=sys.stderr)
    ref = ("--ref-amp", ",".join(f"{a:g}" for a in amp), "--ref-freq", ",".join(f"{f:g}" for f in freq),
           "--ref-hold", f"{ns.ref_hold:g}")
    try:
        run = run_hil(HilOptions(out=ns.out, duration_s=ns.duration, method=ns.method, mode=ns.mode, arm=arm,
                                 bus=ns.bus, topology=ns.topology, bus_timing=ns.bus_timing, controller_args=ref,
                                 capture=ns.capture,
                                 bounds=Bounds(ns.max_error_deg, ns.max_saturated_fraction),
                                 drives=DRIVE_PRESETS[ns.drives], can_port=ns.can_port))
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
    from tools import procs

    if procs.interrupted is not None:
        return 128 + procs.interrupted
    return 0 if run["results"]["result"] == "ok" else 1


def _hil_in_vm(ns: argparse.Namespace) -> int:
    """The same HIL run inside the qemu VM whose kernel has vcan0..vcan3 (tools/vm)."""
    from tools.arm import arm_from_args, build_arm
    from tools.vm.image import VmError
    from tools.vm.run import run_in_vm

    build_arm("release", arm_from_args(ns))
    inner = ["tools/armctl", "hil", "--bus", "vcan", "--duration", f"{ns.duration:g}", "--method", ns.method,
             "--mode", ns.mode, "--out", str(ns.out.resolve()), "--ref-hold", f"{ns.ref_hold:g}",
             "--max-error-deg", f"{ns.max_error_deg:g}", "--max-saturated-fraction", f"{ns.max_saturated_fraction:g}",
             "--drives", ns.drives]
    for opt, val in (("--topology", ns.topology), ("--model", ns.model), ("--arm", ns.arm), ("--design", ns.design)):
        if val is not None:
            inner += [opt, str(val.resolve())]
    if ns.ref_amp is not None:
        inner += ["--ref-amp", ",".join(map(repr, ns.ref_amp)), "--ref-freq", ",".join(map(repr, ns.ref_freq))]
    if ns.bus_timing:
        inner.append("--bus-timing")
    print("armctl hil: running inside the qemu VM (software emulation: minutes, not seconds)")
    try:
        return run_in_vm(inner, timeout=3600.0 + 600.0 * ns.duration, keep=False).returncode
    except VmError as exc:
        print(f"armctl hil --bus vm: {exc}", file=sys.stderr)
        return 1


def cmd_demo(ns: argparse.Namespace) -> int:
    from tools import study

    arm = "the default arm" if ns.model is None and ns.arm is None else (ns.arm or ns.model)
    how = "in software in the loop" if ns.bus == "sil" else f"in lockstep HIL over {ns.bus}"
    print(f"armctl demo: a short study on {arm}: every method, tuned alike, {ns.duration:g} s {how} in "
          f"each scenario of {study.DEFAULT_CONFIG.relative_to(REPO)}, one seed -> {ns.out}")
    ns.config, ns.methods, ns.seeds, ns.retune, ns.cluster = study.DEFAULT_CONFIG, None, 1, False, None
    ns.record = False  # the headline is the full study's (study --record)
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
    """The design config as given, or (with --model/--arm) for that arm's joint count; says how the
    firmware gets this design (a design in DIR alone is only for looking at)."""
    import tempfile

    from gen.synth import cli as synth_cli
    from tools.arm import ArmChoiceError, arm_from_args, print_arm_warnings

    try:
        arm = arm_from_args(ns)
    except ArmChoiceError as exc:
        print(f"armctl synth: {exc}", file=sys.stderr)
        return 2
    arm_opts = (f" --arm {arm.arm_file}" if arm.arm_file else f" --model {arm.model}" if arm.model else "")
    if arm.model is None and arm.arm_file is None:
        rc = synth_cli.run(ns)
    else:
        from gen.arm import ArmError, load_arm_file, prepare

        try:
            prep = prepare(load_arm_file(arm.arm_file, arm.model), ns.config)
        except ArmError as exc:
            print(f"armctl synth: {exc}", file=sys.stderr)
            return 2
        print_arm_warnings(prep.info, "armctl synth")
        with tempfile.TemporaryDirectory() as tmp:
            cfg = Path(tmp) / "design.toml"
            cfg.write_text(prep.design_text)
            ns_arm = argparse.Namespace(**{**vars(ns), "config": cfg})
            rc = synth_cli.run(ns_arm)
    if rc == 0 and not ns.quiet:
        print(f"  the firmware builds with this design: tools/armctl build --design {ns.config}{arm_opts} "
              "(hil, study, tune and demo take the same options)")
    return rc


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="armctl", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)

    sub.add_parser("setup", help="install everything and configure the builds").set_defaults(fn=cmd_setup)

    b = sub.add_parser("build", help="build the firmware and tests with a CMake preset")
    b.add_argument("--preset", choices=PRESETS, default="release")
    b.add_argument("--target", choices=tuple(TARGETS),
                   help="cross target (host = release; aarch64; cortex-m4/m7/m3 images); overrides --preset")
    add_arm_arguments(b)
    b.set_defaults(fn=cmd_build)

    from tools import cluster

    cc = sub.add_parser("cluster-certs", help="a CA and TLS certificates for a Dask cluster (study/tune --cluster tls://)")
    cc.add_argument("--out", type=Path, required=True, help="an empty folder for ca.pem and scheduler/worker/client .pem/.key")
    cc.set_defaults(fn=cluster.cmd_cluster_certs)

    from tools import timing

    tm = sub.add_parser("timing", help="real-time loop latency vs cyclictest in the same run")
    timing.add_arguments(tm)
    tm.set_defaults(fn=timing.run)

    h = sub.add_parser("hil", help="one hardware-in-the-loop run")
    h.add_argument("--duration", type=float, default=None, help="simulated seconds [5; with --scenario the config's]")
    from tools.study_config import METHODS as STUDY_METHODS

    h.add_argument("--method", default=None,
                   choices=(*method_names(), *(m for m in STUDY_METHODS if m not in method_names())),
                   help="the firmware's methods (the core's method table, firmware/core/src/methods.c), and the "
                        "study's variants [pm; pm-paper-weights (pm with the paper's design) with --scenario only]")
    g = h.add_argument_group("one run of a study, on its own (the same run.json results as the study's)")
    g.add_argument("--scenario", default=None, metavar="NAME",
                   help="the study config's scenario: its uncertainty, drives, bus timing, trajectory and hold")
    g.add_argument("--config", type=Path, default=None, metavar="FILE",
                   help="the study config [tools/studies/paper.toml]")
    g.add_argument("--seed", type=int, default=None, metavar="N", help="the uncertainty's seed [the config's first]")
    g.add_argument("--knobs", default=None, metavar="JSON",
                   help="the method's tuned knobs, as the study's report gives them (e.g. '{\"wn\": 40}')")
    g.add_argument("--tuned", default=None, metavar="METHOD",
                   help="the kept tuning's knobs of METHOD in the scenario (and --method METHOD)")
    h.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep")
    h.add_argument("--bus", choices=("auto", "udp", "vcan", "vm", "sil"), default="auto",
                   help="auto: vcan if this kernel has SocketCAN and vcan0, vcan1 (one per bus of "
                        "firmware/protocol/buses.toml), else udp (one port per bus; says which); "
                        "vm: the whole run inside the qemu VM that has vcan0, vcan1")
    h.add_argument("--topology", type=Path, default=None,
                   help="which drive is on which bus, and each bus's bit rates [firmware/protocol/buses.toml]")
    h.add_argument("--bus-timing", action="store_true",
                   help="emulate the buses' bit timing in the simulator (frame lengths, arbitration by id): "
                        "commands act when their frames would end on the bus")
    h.add_argument("--out", type=Path, default=REPO / "runs" / "hil")
    h.add_argument("--ref-amp", type=_float_list, default=None, metavar="A1,..,An",
                   help="reference amplitudes, rad, one per joint (q_d = home + A (1 - cos 2 pi F t)); clipped "
                        "to the joint ranges with a warning [the arm's default]")
    h.add_argument("--ref-freq", type=_float_list, default=None, metavar="F1,..,Fn", help="reference frequencies, Hz")
    h.add_argument("--ref-hold", type=float, default=0.5, help="hold the home pose this long first, s [0.5]")
    h.add_argument("--max-error-deg", type=float, default=DEFAULT_MAX_ERROR_DEG,
                   help=f"bound: any joint's L-infinity tracking error, deg; above it a run is not ok "
                        f"[{DEFAULT_MAX_ERROR_DEG:g}]; the safety layer stops a run at {FOLLOWING_ERROR_STOP_DEG:.3g} deg")
    h.add_argument("--max-saturated-fraction", type=float, default=0.05,
                   help="bound: time at the torque limit, per joint, fraction [0.05]")
    h.add_argument("--can-port", type=int, default=None, metavar="PORT",
                   help="UDP bus: buses on PORT, PORT+1, .. (to watch them with python-can) [the run slot's]")
    h.add_argument("--capture", action="store_true",
                   help="write every frame on the buses to DIR/bus.log, from the simulator's side, in candump's "
                        "log format (canplayer, python-can's LogReader, cantools decode)")
    h.add_argument("--drives", choices=("ideal", "realistic"), default="ideal",
                   help="the emulated drives' sensing and torque path (host_sim/README.md) [ideal]")
    add_arm_arguments(h)
    h.set_defaults(fn=cmd_hil)

    from tools.study import BUSES as SIL_OR_BUS, DEFAULT_CONFIRM

    d = sub.add_parser("demo", help="the main job: set-up if needed, a short study of every method, the table")
    d.add_argument("--out", type=Path, default=REPO / "runs" / "demo")
    d.add_argument("--duration", type=float, default=3.0, help="trajectory seconds per method")
    d.add_argument("--scenarios", default=None, help="comma-separated subset of the study's scenarios")
    d.add_argument("--bus", choices=SIL_OR_BUS, default="sil",
                   help="sil: software in the loop, a sample confirmed over the CAN bus; udp, vcan, auto: lockstep "
                        "HIL [sil]")
    d.add_argument("--jobs", type=int, default=None, help="runs at once [sil: every core; a CAN bus: half the cores]")
    d.add_argument("--confirm", type=int, default=DEFAULT_CONFIRM,
                   help="with --bus sil: runs repeated over the CAN bus, checked bit for bit")
    d.add_argument("--trials", type=int, default=None,
                   help="tuning budget per method and scenario, for an arm without a kept tuning [the config's]")
    add_arm_arguments(d)
    d.set_defaults(fn=cmd_demo)

    t = sub.add_parser("test", help="every test: ctest (ASan/UBSan build) and pytest")
    t.add_argument("pytest_args", nargs="*", help="extra pytest arguments, e.g. -k hil")
    t.set_defaults(fn=cmd_test)

    from gen.synth import cli as synth_cli

    s = sub.add_parser("synth", help="LMI synthesis of the estimator and controller, emitted as C")
    synth_cli.add_arguments(s)
    s.add_argument("--model", type=Path, default=None, metavar="FILE", help="design for this arm's joint count")
    s.add_argument("--arm", type=Path, default=None, metavar="FILE", help="design for this arm file's arm")
    s.set_defaults(fn=cmd_synth)

    from tools import busload, vcan

    vc = sub.add_parser("vcan", help="real SocketCAN: vcan interfaces natively, or a qemu VM that has them (status/up/setup/run)")
    vcan.add_arguments(vc)
    vc.set_defaults(fn=vcan.run)

    bl = sub.add_parser("busload", help="worst-case CAN bus load per control period from the DBC; refuses > budget")
    busload.add_arguments(bl)
    bl.set_defaults(fn=busload.run)

    from tools import study

    st = sub.add_parser("study", help="every method, tuned alike, in every scenario over seeds; the report")
    study.add_study_arguments(st)
    st.set_defaults(fn=study.cmd_study)
    tu = sub.add_parser("tune", help="tune every method alike (Optuna) per scenario; kept for the study")
    study.add_tune_arguments(tu)
    tu.set_defaults(fn=study.cmd_tune)

    from tools import faults

    fl = sub.add_parser("faults", help="every fault against a short lockstep run: detected, safe state, verdict")
    faults.add_arguments(fl)
    fl.set_defaults(fn=faults.run)

    from tools import fuzz

    fz = sub.add_parser("fuzz", help="libFuzzer (ASan/UBSan) on every C decoder, regression seeds first")
    fuzz.add_arguments(fz)
    fz.set_defaults(fn=fuzz.run)

    from tools import bench

    bn = sub.add_parser("bench", help="benchmarks that write results files (instructions per step; synthesis time)")
    bench.add_arguments(bn)
    bn.set_defaults(fn=bench.run)

    ns = p.parse_args(argv)
    from tools import procs

    procs.install()
    try:
        return int(ns.fn(ns))
    except procs.Interrupted as exc:
        print(f"armctl {ns.command}: interrupted ({exc}); no process of this command is left running", file=sys.stderr)
        return 128 + exc.signum
    except BuildError as exc:
        print(exc, file=sys.stderr)
        return 1
    except OutputError as exc:  # a full disk or a read-only mount under a command's own output
        print(f"armctl {ns.command}: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    os.chdir(REPO)
    sys.exit(main())
