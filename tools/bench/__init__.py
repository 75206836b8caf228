"""Benchmarks that write results files (never timed tests).

`armctl bench step`: instructions per control step (callgrind, which counts instructions, not
seconds, so the figure repeats on a busy machine) for every method, float32 and fixed point,
next to the dense double-precision Eigen reference of the same step (the mass-matrix
formulation, a correctness model), and the inverse dynamics alone beside Pinocchio's RNEA.
`armctl bench synth`: wall time of the synthesis (gen.synth.bench).
`armctl bench pil`: docs/pil.md's figures (tools/bench/pil.py).
`armctl bench sim`: the simulator's speed: the default 10 s lockstep HIL run five times (real-time
factor after boot, wall time), one period's CPU broken down by activity, and MuJoCo's bare
mj_step on the same model beside it as the limit.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from tqdm import tqdm

from gen.lib.atomic_output import write_json_atomic
from tools.build import build
from gen.lib.paths import REPO, build_dir
from tools.methods import firmware_methods, method_names
from tools.run.run_files import SIM_SUMMARY

METHODS = method_names()
STEPS = 2000
WARMUP = 1000  # the measured count is (N2 - N1) / (STEPS2 - STEPS1): start-up cost cancels


def _callgrind(fn: str, argv: list[str]) -> int:
    """Instructions callgrind counts inside fn (a --toggle-collect pattern) over the whole run."""
    from tools.build.packages import ensure

    ensure("bench")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "callgrind.out"
        subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", f"--toggle-collect={fn}",
                        *argv], check=True, capture_output=True)
        m = re.search(r"^summary:\s+(\d+)", out.read_text(), re.M)
        if m is None:
            raise RuntimeError(f"no callgrind summary for {' '.join(argv[1:])}")
        return int(m.group(1))


def per_step(exe: Path, method: str, numeric: str, steps: int = STEPS, design_file: Path | None = None) -> float:
    """design_file: the same step with a design read at run time (its run-time-sized path)."""
    fn = "bench_eigen_step*" if numeric == "eigen" else "bench_firmware_step"
    design = [str(design_file)] if design_file is not None else []
    a = _callgrind(fn, [str(exe), method, numeric, str(WARMUP), *design])
    b = _callgrind(fn, [str(exe), method, numeric, str(WARMUP + steps), *design])
    return (b - a) / steps


# bench_rnea's variants and the function each is counted in
RNEA_VARIANTS = {"kernel": "bench_rnea_kernel", "ours": "bench_rnea_ours",
                 "pinocchio-double": "*bench_rnea_pinocchio*", "pinocchio-float": "*bench_rnea_pinocchio*"}


def per_rnea(exe: Path, variant: str, calls: int) -> float:
    fn = RNEA_VARIANTS[variant]
    a = _callgrind(fn, [str(exe), variant, str(WARMUP)])
    b = _callgrind(fn, [str(exe), variant, str(WARMUP + calls)])
    return (b - a) / calls


def bench_step(out: Path, quick: bool = False) -> dict[str, Any]:
    """quick: pm only, 200 measured steps (a check that the benchmark runs, not a figure)."""
    build("release", targets=["bench_step"])  # not in `all` (tests/bench/CMakeLists.txt)
    exe = build_dir("release") / "tests" / "bench" / "bench_step"
    methods = ("pm",) if quick else METHODS
    steps = 200 if quick else STEPS
    jobs = [(m, n) for m in methods for n in ("float", "fixed") if n == "float" or firmware_methods()[m]]
    jobs += [(m, "eigen") for m in methods if m in ("pd", "pm", "pm-paper", "gh2")]
    # the methods that run the synthesised design, once more with it read from the build's design
    # file (the Linux port's --design-file) instead of built in: the step's run-time-sized path
    design_file = build_dir("release") / "generated" / "design" / "pm_design.txt"
    loaded = [(m, n) for m, n in jobs if n != "eigen" and firmware_methods()[m]]
    rows: dict[str, dict[str, float]] = {}
    for method, numeric in tqdm(jobs, desc="callgrind", unit="run"):
        rows.setdefault(method, {})[numeric] = per_step(exe, method, numeric, steps)
    runtime: dict[str, dict[str, float]] = {}
    for method, numeric in tqdm(loaded, desc="callgrind, design read at run time", unit="run"):
        runtime.setdefault(method, {})[numeric] = per_step(exe, method, numeric, steps, design_file)
    for method, r in rows.items():
        if "eigen" in r:
            r["eigen_over_float"] = r["eigen"] / r["float"]
    result = {
        "what": "instructions per control step (callgrind Ir inside the step function), n = 6, release build",
        "compiler": subprocess.run(["cc", "--version"], capture_output=True, text=True).stdout.splitlines()[0],
        "steps_measured": steps,
        "quick": quick,
        "methods": rows,
        "design_read_at_run_time": {
            "what": ("the same steps with the same design read from the build's design file (the Linux port's "
                     "--design-file: its run-time-sized path) instead of the built-in one (compiled with its own "
                     "dimensions, the figures of `methods`); the MCU images have the built-in path alone"),
            "design_file": str(design_file),
            "methods": runtime,
        },
    }
    if not quick:  # quick: no Pinocchio comparison (compiling it alone takes about 2 minutes)
        result["rnea"] = rnea_costs(rows["pm"]["float"], steps)
        result["cortex_m"] = cortex_m_costs()
    write_json_atomic(out, result)
    return result


def rnea_agreement() -> tuple[Path, str]:
    """bench_rnea, built, and its check: Pinocchio's RNEA (given the arm's armature and damping)
    and ours, the general one and the arm's kernel, on 200 states of the bundled arm; the
    executable and the check's line. Nothing is counted before they agree (RuntimeError if not).
    Compiling it takes about 2 minutes and 4.7 GB (Pinocchio's headers)."""
    build("release", targets=["bench_rnea"])  # not in `all` (tests/bench/CMakeLists.txt)
    rnea_exe = build_dir("release") / "tests" / "bench" / "bench_rnea"
    check = subprocess.run([str(rnea_exe), "check"], capture_output=True, text=True)
    if check.returncode != 0:
        raise RuntimeError(f"bench_rnea check: {check.stdout}{check.stderr}")
    return rnea_exe, check.stdout.strip()


def rnea_costs(pm_step: float, calls: int) -> dict[str, Any]:
    """Our inverse dynamics against Pinocchio's on the same arm and inputs, once their torques agree."""
    rnea_exe, check = rnea_agreement()
    rnea = {v: per_rnea(rnea_exe, v, calls) for v in tqdm(RNEA_VARIANTS, desc="callgrind rnea", unit="run")}
    return {
        "what": ("instructions per inverse-dynamics call on the same arm and inputs: kernel = the arm's "
                 "generated arm_rnea_kernel (what the controller runs for this arm), ours = the general "
                 "arm_rnea (any other model), Pinocchio 4.1's rnea (the pin wheel's headers and "
                 "libpinocchio_default) in double and in float"),
        "instructions": rnea,
        "check": check,
        "pinocchio_double_over_kernel": rnea["pinocchio-double"] / rnea["kernel"],
        "pm_step_over_pinocchio_double_rnea": pm_step / rnea["pinocchio-double"],
    }


def cortex_m_costs() -> dict[str, Any]:
    """Instructions per call on the M4 and M7 images under QEMU (-icount shift=0: QEMU counts
    instructions; it does not model cycles, caches or the M7's dual issue). On silicon the same
    image prints SysTick ticks, which are core cycles."""
    from tools.build import toolchain_missing
    from tools.build.cortex_m import run_image, step_costs

    out: dict[str, Any] = {"what": "instructions per call under QEMU -icount shift=0, SysTick calibrated by a loop "
                                   "of known length (firmware/port/cortex_m/step_count.c); not cycles"}
    for preset in ("cortex-m4", "cortex-m7"):
        missing = toolchain_missing(preset)
        if missing:
            out[preset] = {"skipped": missing}
            continue
        build(preset)
        r = run_image(preset)
        costs = step_costs(r.stdout + r.stderr)
        if r.returncode != 0 or len(costs) != 3:
            raise RuntimeError(f"{preset} image: no step cost (exit {r.returncode}):\n{r.stdout}{r.stderr}")
        report = build_dir(preset) / "firmware" / "port" / "cortex_m" / "memory_report.json"
        out[preset] = {**costs, "memory": json.loads(report.read_text())}  # flash, RAM, stack vs the part
    return out


def table(result: dict[str, Any]) -> str:
    loaded = result.get("design_read_at_run_time", {}).get("methods", {})
    lines = [f"{'method':<10}{'float':>10}{'fixed':>10}{'eigen ref':>12}{'ref/float':>11}"
             f"{'loaded float':>14}{'loaded fixed':>14}"]
    for m, r in result["methods"].items():
        f = lambda k, row=r, w=10: f"{row[k]:>{w}.0f}" if k in row else f"{'-':>{w}}"  # noqa: E731
        ratio = f"{r['eigen_over_float']:>10.1f}x" if "eigen_over_float" in r else f"{'-':>11}"
        eigen = f"{r['eigen']:>12.0f}" if "eigen" in r else f"{'-':>12}"
        lr = loaded.get(m, {})
        lines.append(f"{m:<10}{f('float')}{f('fixed')}{eigen}{ratio}{f('float', lr, 14)}{f('fixed', lr, 14)}")
    if loaded:
        lines.append("loaded: the same design read from its file at run time (--design-file), the run-time-sized path")
    r = result.get("rnea")
    if r is None:
        return "\n".join(lines)
    lines.append("inverse dynamics alone, instructions per call: " +
                 ", ".join(f"{v} {n:.0f}" for v, n in r["instructions"].items()))
    lines.append(f"Pinocchio (double) / our kernel: {r['pinocchio_double_over_kernel']:.1f}x; the whole pm step is "
                 f"{r['pm_step_over_pinocchio_double_rnea']:.2f} of Pinocchio's RNEA alone")
    for preset, c in result.get("cortex_m", {}).items():
        if isinstance(c, dict) and "skipped" not in c:
            lines.append(f"{preset} (QEMU -icount, instructions): " +
                         ", ".join(f"{k} {v:.0f}" for k, v in c.items() if k != "memory"))
    return "\n".join(lines)


# The arm with flexible joints (gen/drivetrain.py) as a real one is run: its drives' velocity from
# the motor encoder (collocated: the paper's weights and a PD on link sensors alone ring its gears),
# and pd at the controller's default gains, whose bandwidth stays below the first resonance.
FLEXIBLE = {"flexible": True}


def _sim_runs(bus: str, repeats: int, duration: float, tmp: Path, flexible: bool = False,
              label: str = "") -> tuple[list[dict[str, Any]], dict[str, float]]:
    """The default run on this bus (or the flexible arm's, FLEXIBLE), repeated; one more with
    --profile (where a period's time goes)."""
    from host_sim.drive_model import REALISTIC, DriveModel
    from tools.run.hil import HilOptions, run_hil

    runs, breakdown = [], {}
    for i in tqdm(range(repeats + 1), desc=label or bus, unit="run"):
        profile = i == repeats  # the last run measures where the time goes (costs a little)
        d = tmp / f"{label or bus}-{i}"
        # the arm protocol: its simulator loop (sim_loop.c) is the one --profile breaks down
        run = run_hil(HilOptions(out=d, duration_s=duration, method="pd" if flexible else "pm", bus=bus, protocol="arm",
                                 uncertainty=FLEXIBLE if flexible else None,
                                 drives=REALISTIC if flexible else DriveModel(),
                                 sim_args=("--profile",) if profile else ()))
        if run["results"]["result"] != "ok":
            raise RuntimeError(f"bench run {i} ({bus}) failed: {run['results']['problems']}")
        sim = json.loads((d / SIM_SUMMARY).read_text())
        entry = {"realtime_factor": sim["realtime_factor"], "wall_s": run["environment"]["wall_s"],
                 "boot_s": sim["boot_s"], "period_cost_us": sim["period_cost_us"]}
        if profile:
            breakdown = sim["profile_us_per_period"]
        else:
            runs.append(entry)
    return runs, breakdown


def _bare_mj_step_us(plant: bool) -> float:
    """MuJoCo alone, mj_step on the arm (or its plant with flexible joints): the limit of a period."""
    from host_sim.launch import PLANT_FILE, sim_binary
    from tools.build.arm import prepared_model

    model = prepared_model(build_dir("release"))
    argv = [str(sim_binary("release")), "--model", str(model), "--bench-mj-step", "20000"]
    r = subprocess.run(argv + (["--plant", str(model.parent / PLANT_FILE)] if plant else []), capture_output=True,
                       text=True, check=True)
    return float(json.loads(r.stdout)["mj_step_ns"]) / 1e3


def bench_sim(out: Path, quick: bool = False) -> dict[str, Any]:
    """The default run in software in the loop (on the rigid arm and on the arm with flexible
    joints) and in lockstep HIL, repeated; the per-period breakdown of each; the bare-MuJoCo limit
    of a period on the same model."""
    import statistics

    build("release")
    repeats, duration = (1, 1.0) if quick else (5, 10.0)
    bare = {False: _bare_mj_step_us(False), True: _bare_mj_step_us(True)}
    modes: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for key, bus, flexible in (("sil", "sil", False), ("sil_flexible", "sil", True), ("udp", "udp", False)):
            mj_step_us = bare[flexible]
            runs, b = _sim_runs(bus, repeats, duration, Path(tmp), flexible, key)
            sim_side = sum(b[k] for k in ("physics", "bus_tx", "bus_rx", "telemetry"))
            cost = statistics.median(x["period_cost_us"]["mean"] for x in runs)
            factors = [x["realtime_factor"] for x in runs]
            # In SIL the thread is the whole loop: what the simulator's own parts leave is the
            # controller's step and the hand-offs between the two. Over the bus it is the drives'
            # state machines and the rest of the simulator (the controller is another process).
            rest = "controller_and_handoffs" if bus == "sil" else "drives_and_rest"
            breakdown = {**{k: b[k] for k in ("physics", "bus_tx", "bus_rx", "telemetry")},
                         rest: b["total"] - sim_side, "total": b["total"]}
            modes[key] = {
                "runs": runs,
                "bare_mj_step_us": mj_step_us,
                "realtime_factor_median": statistics.median(factors),
                "realtime_factor_min": min(factors),
                "period_cost_us_mean_median": cost,
                "breakdown_us_per_period": breakdown,
                "breakdown_over_bare_mj_step": {k: v / mj_step_us for k, v in breakdown.items()},
                "period_cost_over_bare_mj_step": cost / mj_step_us,
            }
    result = {
        "what": (f"the default run (pm, {duration:g} s after the 0.5 s hold), {repeats} time(s), in software in the "
                 "loop (arm_sil: one thread, telemetry written to the log; on the rigid arm, and on the arm with "
                 "flexible joints, where pd runs at its default gains with realistic drives) and in lockstep HIL over UDP (arm_sim, arm_controller and the logger): the "
                 "real-time factor after boot and the CPU time per period (in SIL the whole loop, over UDP the "
                 "simulator's); one more run each with --profile breaks a period down (thread CPU time); bare "
                 "mj_step: MuJoCo alone on the same model (the plant with flexible joints for those runs), the limit "
                 "of a period"),
        "quick": quick,
        "bare_mj_step_us": bare[False],
        "bare_mj_step_flexible_us": bare[True],
        "sil": modes["sil"],
        "sil_flexible": modes["sil_flexible"],
        "lockstep_udp": modes["udp"],
        "sil_over_lockstep": modes["sil"]["realtime_factor_median"] / modes["udp"]["realtime_factor_median"],
    }
    write_json_atomic(out, result)
    return result


def sim_table(r: dict[str, Any]) -> str:
    lines = [f"bare mj_step on the same model: {r['bare_mj_step_us']:.2f} us, with flexible joints "
             f"{r['bare_mj_step_flexible_us']:.2f} us (the limit of a period)"]
    for key, name in (("sil", "software in the loop"), ("sil_flexible", "software in the loop, flexible joints"),
                      ("lockstep_udp", "lockstep HIL over UDP")):
        m = r[key]
        lines.append(f"{name}: {m['realtime_factor_median']:.1f}x real time (median, min {m['realtime_factor_min']:.1f}x, "
                     f"{len(m['runs'])} run(s)); a period {m['period_cost_us_mean_median']:.2f} us = "
                     f"{m['period_cost_over_bare_mj_step']:.1f}x mj_step")
        lines.append("  per period (us, x mj_step): " + ", ".join(
            f"{k} {v:.2f} ({m['breakdown_over_bare_mj_step'][k]:.1f}x)" for k, v in m["breakdown_us_per_period"].items()))
    lines.append(f"software in the loop / lockstep HIL: {r['sil_over_lockstep']:.1f}x")
    return "\n".join(lines)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("what", choices=("step", "synth", "sim", "study", "pil"))
    p.add_argument("--out", type=Path, default=None, help="results file (JSON)")
    p.add_argument("--quick", action="store_true",
                   help="a short form that checks the benchmark runs (step: pm only; synth: one repeat, "
                        "no coupled solve, n = 1 comparison; sim: one 1 s run; study: 4 runs of 0.5 s; pil: "
                        "0.2 s runs); its figures are not the documented ones")
    p.add_argument("--record", action="store_true",
                   help="also keep the results for the docs (docs/results/bench-WHAT.json), which tools/armctl docs "
                        "renders into their figures")


def add_subparser(sub: argparse._SubParsersAction) -> None:
    bn = sub.add_parser("bench", help="benchmarks that write results files (instructions per step; synthesis time)")
    add_arguments(bn)
    bn.set_defaults(run=run)


def run(ns: argparse.Namespace) -> int:
    from tools.bench.record import RecordError, record

    if ns.record and ns.quick:
        raise RecordError("--record with --quick: a quick run checks that the benchmark runs; its figures are not "
                          "the documented ones")
    if ns.what == "step":
        out = ns.out or REPO / "runs" / "bench" / "step_instructions.json"
        result = bench_step(out, ns.quick)
        print(table(result))
    elif ns.what == "pil":
        from tools.bench.pil import bench_pil, render

        result = bench_pil(ns.quick)
        print(render(result))
        out = ns.out or REPO / "runs" / "bench" / "pil.json"
        write_json_atomic(out, result)
    elif ns.what == "study":
        from tools.bench.study import bench_study, table as study_table

        out = ns.out or REPO / "runs" / "bench" / "study.json"
        result = bench_study(out, ns.quick)
        print(study_table(result))
    elif ns.what == "sim":
        out = ns.out or REPO / "runs" / "bench" / "sim.json"
        result = bench_sim(out, ns.quick)
        print(sim_table(result))
    else:
        out = ns.out or REPO / "runs" / "bench" / "synth.json"
        quick = ["--repeats", "1", "--skip-coupled", "--quick"] if ns.quick else []
        rc = subprocess.run([sys.executable, "-m", "gen.synth.bench", "--out", str(out), *quick], cwd=REPO).returncode
        if rc != 0:
            return rc
        result = json.loads(out.read_text())
    print(f"results: {out}")
    if ns.record:
        record(f"bench-{ns.what}", result, f"tools/armctl bench {ns.what} --record")
    return 0
