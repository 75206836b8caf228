"""armctl hil: one hardware-in-the-loop run; with --scenario, one run of a study on its own; with
--bus vm, the run's programs inside the qemu VM (tools/vm), on real SocketCAN buses."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from gen.lib.one_line import one_line
from gen.lib.outdir import check_out_dir
from gen.lib.params import param
from gen.lib.paths import REPO
from tools.build.arm import add_arm_arguments
from tools.commands import UsageError
from tools.methods import method_names
from tools.run.verdict import DEFAULT_MAX_ERROR_DEG, FOLLOWING_ERROR_STOP_DEG


def _float_list(text: str) -> list[float]:
    try:
        vals = [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a comma-separated list of numbers") from None
    if not all(math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError(f"'{text}': every value must be finite")
    return vals


def add_subparser(sub: argparse._SubParsersAction) -> None:
    from tools.study.config import METHODS as STUDY_METHODS

    h = sub.add_parser("hil", help="one hardware-in-the-loop run")
    h.add_argument("--duration", type=float, default=None,
                   help=f"simulated seconds [{param('hil', 'duration').default_text()}; with --scenario the config's]")
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
    mode = param("controller", "mode")  # arm_controller's --mode, passed on
    h.add_argument("--mode", choices=mode.choices, default=mode.default)
    h.add_argument("--bus", choices=("auto", "udp", "vcan", "vm", "sil"), default="auto",
                   help="auto: vcan if this kernel has SocketCAN and vcan0, vcan1 (one per bus of "
                        "firmware/protocol/buses.toml), else udp (one port per bus; says which); "
                        "vm: the logger, simulator and controller inside the qemu VM, on its vcan0..vcan3 (the "
                        "build and the analysis here)")
    h.add_argument("--topology", type=Path, default=None,
                   help="which drive is on which bus, and each bus's bit rates [canopen: the fewest classic 1 Mbit/s "
                        "buses that carry the drives (else the arm's CAN FD wiring); arm: the arm's wiring, "
                        "firmware/protocol/buses.toml for six drives]")
    h.add_argument("--bus-timing", action="store_true",
                   help="emulate the buses' bit timing in the simulator (frame lengths, arbitration by id): "
                        "commands act when their frames would end on the bus")
    h.add_argument("--out", type=Path, default=REPO / "runs" / "hil")
    h.add_argument("--ref-amp", type=_float_list, default=None, metavar="A1,..,An",
                   help="reference amplitudes, rad, one per joint (q_d = home + A (1 - cos 2 pi F t)); clipped "
                        "to the joint ranges with a warning [the arm's default]")
    h.add_argument("--ref-freq", type=_float_list, default=None, metavar="F1,..,Fn", help="reference frequencies, Hz")
    hold = param("hil", "ref-hold")
    h.add_argument("--ref-hold", type=float, default=hold.default,
                   help=f"{hold.help}, {hold.unit} [{hold.default_text()}]")
    h.add_argument("--max-error-deg", type=float, default=DEFAULT_MAX_ERROR_DEG,
                   help=f"bound: any joint's L-infinity tracking error, deg; above it a run is not ok "
                        f"[{DEFAULT_MAX_ERROR_DEG:g}]; the safety layer stops a run at {FOLLOWING_ERROR_STOP_DEG:.3g} deg")
    sat = param("hil", "max-saturated-fraction")
    h.add_argument("--max-saturated-fraction", type=float, default=sat.default,
                   help=f"{sat.help}, fraction [{sat.default_text()}]")
    h.add_argument("--can-port", type=int, default=None, metavar="PORT",
                   help="UDP bus: buses on PORT, PORT+1, .. (to watch them with python-can) [the run slot's]")
    h.add_argument("--capture", action="store_true",
                   help="write every frame on the buses to DIR/bus.log, from the simulator's side, in candump's "
                        "log format (canplayer, python-can's LogReader, cantools decode)")
    h.add_argument("--drives", choices=("ideal", "realistic"), default=param("hil", "drives").default,
                   help="the emulated drives' sensing and torque path (host_sim/README.md) [ideal]")
    from tools.run.hil import DEFAULT_PROTOCOL, PROTOCOLS

    h.add_argument("--protocol", choices=PROTOCOLS, default=DEFAULT_PROTOCOL,
                   help="what the drives speak: arm (this project's frames) or canopen (CiA 301/402 drives booted "
                        f"over SDO; docs/drives.md) [{DEFAULT_PROTOCOL}]")
    h.add_argument("--rate", type=float, default=None, metavar="HZ",
                   help="the loop rate (the controller's --rate; a design is discretised for one rate) [the arm's]")
    h.add_argument("--drive-config", type=Path, default=None, metavar="FILE",
                   help="canopen: the CiA 402 drive configuration, a file like firmware/protocol/drives.toml "
                        "[the arm's: its arm file's `drives`, else that file]")
    from tools.build.cortex_m import MACHINES

    h.add_argument("--target", choices=tuple(MACHINES), default=None,
                   help="processor in the loop (docs/pil.md): the controller is the Cortex-M image of this preset in "
                        "qemu-system-arm (-icount), its buses SLCAN on the image's UARTs; lockstep; the Cortex-M3 runs "
                        "a method's fixed-point variant where it has one [the controller runs here]")
    add_arm_arguments(h)
    h.set_defaults(run=run)


def _print_run(run: dict) -> None:
    from tools.run.run_analysis import table

    print(table(run))


def _ended(run: dict, out: Path) -> int:
    from tools.run import procs

    _print_run(run)
    t = run.get("target")
    if t and t.get("step_instructions"):
        s, share = t["step_instructions"], t["step_share_of_period_at_stated_clock"]
        print(f"{t['name']} ({t['machine']}): control step {s['min']}/{s['median']:g}/{s['max']} instructions "
              f"(min/median/max of {s['periods']} periods), {100 * share['median']:.1f} % of the period at "
              f"{t['stated_clock_hz'] / 1e6:g} MHz; stack high-water {t['stack_high_water_bytes']} bytes")
    print(f"results: {out / 'run.json'}  log: {out / 'telemetry.lcmlog'}")
    if procs.interrupted is not None:
        return 128 + procs.interrupted
    return 0 if run["results"]["result"] == "ok" else 1


def _check_duration(duration: float | None) -> None:
    p = param("hil", "duration")
    if duration is not None and not (math.isfinite(duration) and p.min <= duration <= p.max):
        raise UsageError(f"--duration: must be in {p.range_text()} s, got {duration}")


def _study_run(ns: argparse.Namespace) -> int:
    """hil --scenario: one run of a study, made as the study makes it (tools/study/__init__.py
    study_run_spec) and run as it runs it (tools/run/runner.py execute)."""
    import json
    import sys
    from dataclasses import asdict

    from tools import study
    from tools.build.arm import arm_from_args, arm_info, build_arm, print_arm_warnings
    from tools.run.runner import DONE, execute
    from tools.study.config import StudyConfigError, load

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
    method = ns.method or param("hil", "method").default
    spec, traj, notes = study.study_run_spec(cfg, arm, ns.scenario, method, seed, ns.duration, knobs,
                                             ns.tuned is not None, ns.out.resolve(), ns.bus)
    for n in notes:
        print(f"armctl hil: {one_line(n)}", file=sys.stderr)
    print(f"armctl hil: {method} in scenario {ns.scenario} of {cfg.path}, seed {seed}, "
          f"{spec.duration_s:g} s, knobs {json.dumps(spec.labels['knobs'])}; trajectory ({traj['from']}) amplitudes "
          f"{traj['amp']} rad, frequencies {traj['freq_hz']} Hz")
    (ns.out / DONE).unlink(missing_ok=True)  # run it, never take a kept one
    return _ended(execute(asdict(spec)), ns.out)


def run(ns: argparse.Namespace) -> int:
    import sys

    from tools.build.arm import (HIL_TARGETS, arm_from_args, arm_info, build_arm, print_arm_warnings, reference_for,
                                 targets_for)
    from tools.run.hil import HilOptions, run_hil
    from tools.study.config import DRIVE_PRESETS
    from tools.run.verdict import Bounds

    _check_duration(ns.duration)
    if ns.scenario is not None:
        return _study_run(ns)
    study_only = [o for o, v in (("--config", ns.config), ("--seed", ns.seed), ("--knobs", ns.knobs),
                                 ("--tuned", ns.tuned)) if v is not None]
    if study_only or ns.method == "pm-paper-weights":
        raise UsageError(f"{', '.join(study_only) or '--method pm-paper-weights'}: one run of a study: give --scenario")
    ns.duration = param("hil", "duration").default if ns.duration is None else ns.duration
    ns.method = ns.method or param("hil", "method").default
    _check_duration(ns.duration)
    if not (0 <= ns.ref_hold <= 3600):
        raise UsageError(f"--ref-hold: must be in [0, 3600] s, got {ns.ref_hold}")
    if (ns.ref_amp is None) != (ns.ref_freq is None):
        raise UsageError("--ref-amp and --ref-freq go together")
    if not (math.isfinite(ns.max_error_deg) and ns.max_error_deg > 0):
        raise UsageError(f"--max-error-deg: must be a number above 0, got {ns.max_error_deg}")
    if ns.max_error_deg >= FOLLOWING_ERROR_STOP_DEG:
        print(f"armctl hil: --max-error-deg {ns.max_error_deg:g}: the safety layer stops a run at "
              f"{FOLLOWING_ERROR_STOP_DEG:.3g} deg of following error first (verdict failed): the bound is never "
              "reached", file=sys.stderr)
    arm = arm_from_args(ns)
    check_out_dir(ns.out)
    if ns.topology is not None:  # the file itself, before the build; its drives against the arm's after it
        from gen.lib import busload

        try:
            busload.load_topology(ns.topology, busload.topology_drives(ns.topology))
        except busload.ConfigError as exc:
            raise UsageError(f"--topology: {exc}") from None
    if ns.can_port is not None and not 1024 <= ns.can_port <= 65532:
        raise UsageError(f"--can-port: must be in [1024, 65532], got {ns.can_port}")
    if ns.target is not None and ns.bus != "auto":
        raise UsageError(f"--target {ns.target} --bus {ns.bus}: a processor-in-the-loop run's buses are SLCAN links "
                         "to the image's UARTs (give no --bus)")
    # what the run needs (a software-in-the-loop run: arm_sil alone), not the tests and benches
    bdir = build_arm("release", arm, targets=targets_for(ns.bus) if ns.bus == "sil" else HIL_TARGETS)
    if ns.target is not None:
        build_arm(ns.target, arm)
    info = arm_info(bdir)
    amp, freq, warnings = reference_for(info, ns.ref_amp, ns.ref_freq, bdir)
    print_arm_warnings(info, "armctl hil")
    if info.get("design"):
        print(f"design: {info['design']['config']} ({info['design']['why']})")
    for w in warnings:
        print(f"armctl hil: {one_line(w)}", file=sys.stderr)  # a file's names, to a terminal
    ref = ("--ref-amp", ",".join(f"{a:g}" for a in amp), "--ref-freq", ",".join(f"{f:g}" for f in freq),
           "--ref-hold", f"{ns.ref_hold:g}", *(("--rate", f"{ns.rate:g}") if ns.rate is not None else ()))
    result = run_hil(HilOptions(out=ns.out, duration_s=ns.duration, method=ns.method, mode=ns.mode, arm=arm,
                             bus=ns.bus, topology=ns.topology, bus_timing=ns.bus_timing, controller_args=ref,
                             capture=ns.capture,
                             bounds=Bounds(ns.max_error_deg, ns.max_saturated_fraction),
                             drives=DRIVE_PRESETS[ns.drives], can_port=ns.can_port, protocol=ns.protocol,
                             drive_config=ns.drive_config, target=ns.target))
    print(f"bus: {result['environment']['bus_choice']}; wiring: {result['environment']['topology']['source']}")
    for note in result["environment"].get("canopen_drive_notes", []):
        print(f"drive table: {one_line(note)}")
    for name, pct in result["environment"]["bus_load_pct"].items():
        if pct > 100.0:
            print(f"armctl hil: bus {name} needs {pct:g} % of its time at 1 kHz (tools/armctl busload): the "
                  "frames of a period do not fit in it" + (", so commands end late (--bus-timing)"
                                                           if ns.bus_timing else ""), file=sys.stderr)
    if not arm.is_default:
        _first_run_strip(bdir, info, ns.out)
    return _ended(result, ns.out)


FIRST_RUN_MARK = ".first-run-strip"  # in the arm's prepared folder: the model hash whose strip a run offered


def _first_run_strip(bdir: Path, info: dict, out: Path) -> None:
    """An imported arm's first run draws the arm as it ran, beside its reference, so that a user
    sees the import is right (a flipped axis, a wrong frame) before reading any number."""
    import sys

    from tools.build.arm import prepared_model
    from tools.run.render import STRIP_FILE, RenderError, write_strip

    mark = prepared_model(bdir).with_name(FIRST_RUN_MARK)
    if mark.exists() and mark.read_text().strip() == info["model_hash"]:
        return
    try:
        write_strip(out)
    except RenderError as exc:
        print(f"armctl hil: no picture of the arm: {exc}", file=sys.stderr)
        return
    mark.write_text(info["model_hash"] + "\n")
    print(f"the arm as it ran, this arm's first run: {out / STRIP_FILE} (beside its reference at the start, the "
          f"middle, the worst tracking and the end: check that each joint turns where it should; tools/armctl "
          f"render {out} makes a video)")
