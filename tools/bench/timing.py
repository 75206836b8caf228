"""armctl timing: the controller's real-time loop measured against cyclictest in the same run.

One realtime HIL run (run_hil, mode "realtime": the controller's clock drives the bus, the
simulator answers over the loopback UDP transport) and, while its loop runs, cyclictest (rt-tests)
at the same interval and SCHED_FIFO priority. Written to DIR:

- timing.json: per-period figures from the controller's ARM_TIMING telemetry (every period):
  wake-up latency (actual wake-up minus the absolute deadline of clock_nanosleep(TIMER_ABSTIME)),
  compute time (arm_ctl_step alone), cycle time (SYNC sent -> all six commands sent: the CAN
  round trip SYNC -> joint states -> commands, including the compute time and the simulator's
  response time), overruns; cyclictest's wake-up latency from its histogram; the controller's
  figures relative to cyclictest's; what the bus lost (late or missing joint states, commands the
  simulator missed); which side was late where states missed the wait (run.json's
  environment.lateness: the controller's account by side, a stop's, and the simulator's answer
  times). Percentiles p50, p99, p99.9, max.
- timing.png: histograms and time series.
- hil/: the HIL run itself (run.json, telemetry.lcmlog, logs).

Nothing here is compared with a fixed number: the machine (a shared VM, stock kernel) decides the
figures; cyclictest measured in the same window is the reference.

The simulator (arm_sim, C) runs SCHED_FIFO below the loop on the loop's CPU, and cyclictest is
pinned there too (--cpu, default the last CPU): the loop and its reference measured under the same
conditions, and a stall of that vCPU (this VM stops one for 1-6 ms every few seconds) pauses the
whole rig instead of silencing the drives under a running loop. Nothing is relaxed: late states are
counted and discarded, and more than 3 periods in a row without states safe-stop the loop (the
watchdog), which ends the measurement early. A run that ends early is not "ok": timing.json's
verdict says "incomplete" with the reason, and the command exits 1.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import signal
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

from tools.run import procs

HISTMAX_US = 20000  # cyclictest histogram range (1 us buckets); beyond it: overflows


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--duration", type=float, default=10.0, help="seconds of control loop to measure")
    p.add_argument("--out", type=Path, default=Path("runs/timing"))
    p.add_argument("--rate", type=float, default=1000.0, help="control rate, Hz (cyclictest interval = 1/rate)")
    p.add_argument("--rt-priority", type=int, default=80, help="SCHED_FIFO priority of both loops")
    p.add_argument("--cpu", type=int, default=None,
                   help="the CPU of the controller's loop, the simulator and cyclictest [the last one]")
    p.add_argument("--method", default="pd")
    p.add_argument("--repeat", type=int, default=1,
                   help="runs of the same measurement, each to OUT/RUN/, and OUT/repeat.json: how many ran to their "
                        "end and what stopped the others (tools/bench/timing_repeat.py) [1]")
    p.add_argument("--record", action="store_true",
                   help="also keep timing.json (with --repeat, repeat.json) for the docs (docs/results/timing.json, "
                        "timing-repeat.json), which tools/armctl docs renders")


def _stats(values_us: list[float]) -> dict[str, float | int]:
    import numpy as np

    if not values_us:
        return {"n": 0}
    a = np.asarray(values_us, dtype=float)
    return {"n": int(a.size), "min": float(a.min()), "mean": float(a.mean()),
            "p50": float(np.percentile(a, 50)), "p99": float(np.percentile(a, 99)),
            "p99.9": float(np.percentile(a, 99.9)), "max": float(a.max())}


def _hist_stats(hist: dict[int, int], overflows: int, max_us: float | None, min_us: float | None,
                avg_us: float | None) -> dict[str, Any]:
    total = sum(hist.values()) + overflows
    out: dict[str, Any] = {"n": total, "overflows_beyond_us": HISTMAX_US, "overflows": overflows}
    if total == 0:
        return out
    for name, q in (("p50", 0.5), ("p99", 0.99), ("p99.9", 0.999)):
        need, acc, val = q * total, 0, None
        for us in sorted(hist):
            acc += hist[us]
            if acc >= need:
                val = float(us)
                break
        out[name] = val if val is not None else float(HISTMAX_US)  # in the overflow: a lower bound
    out.update({"min": min_us, "mean": avg_us, "max": max_us})
    return out


def parse_cyclictest(text: str) -> dict[str, Any]:
    hist: dict[int, int] = {}
    summary: dict[str, float] = {}
    for line in text.splitlines():
        parts = line.split()
        if len(parts) == 2 and parts[0].isdigit() and parts[1].isdigit():
            if int(parts[1]):
                hist[int(parts[0])] = int(parts[1])
        elif line.startswith("# ") and ":" in line:
            key, _, val = line[2:].partition(":")
            val = val.strip().split()[0] if val.strip() else ""
            if val.lstrip("-").isdigit():
                summary[key.strip()] = float(val)
    return {
        "histogram_us": hist,
        "stats": _hist_stats(hist, int(summary.get("Histogram Overflows", 0)), summary.get("Max Latencies"),
                             summary.get("Min Latencies"), summary.get("Avg Latencies")),
    }


def _first_timing_message(log: Path) -> bool:
    """True once the loop's first ARM_TIMING message is in the (growing) log."""
    import lcm

    if not log.exists() or log.stat().st_size == 0:
        return False
    try:
        ev_log = lcm.EventLog(str(log), "r")
    except (OSError, ValueError):
        return False
    try:
        while True:
            try:
                ev = ev_log.read_next_event()
            except (ValueError, OSError):
                return False
            if ev is None:
                return False
            if ev.channel == "ARM_TIMING":
                return True
    finally:
        ev_log.close()


def _plot(path: Path, ctl_wake: list[float], cyc_hist: dict[int, int], compute: list[float],
          cycle: list[float], period_us: float, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(2, 2, figsize=(12, 8))
    hi = max([*ctl_wake, *cyc_hist.keys(), 1.0])
    bins = np.linspace(0, hi * 1.02 + 1, 80)
    if ctl_wake:
        ax[0, 0].hist(ctl_wake, bins=bins, alpha=0.6, label=f"controller (n={len(ctl_wake)})")
    if cyc_hist:
        us = np.array(sorted(cyc_hist), dtype=float)
        ax[0, 0].hist(us, bins=bins, weights=[cyc_hist[int(u)] for u in us], alpha=0.6,
                      label=f"cyclictest (n={sum(cyc_hist.values())})")
    ax[0, 0].set_yscale("log")
    ax[0, 0].set_xlabel("wake-up latency (us)")
    ax[0, 0].set_ylabel("periods")
    ax[0, 0].legend()
    ax[0, 0].set_title("wake-up latency, same run")
    ax[0, 1].plot(ctl_wake, ".", ms=2)
    ax[0, 1].set_xlabel("period")
    ax[0, 1].set_ylabel("controller wake-up latency (us)")
    ax[0, 1].set_title("controller wake-up latency over the run")
    if compute:
        ax[1, 0].hist(compute, bins=60)
    ax[1, 0].set_yscale("log")
    ax[1, 0].set_xlabel("compute time per step, arm_ctl_step (us)")
    ax[1, 0].set_title("compute time")
    ax[1, 1].plot(cycle, ".", ms=2, label="cycle: SYNC sent -> commands sent")
    ax[1, 1].axhline(period_us, color="r", lw=1, label=f"period {period_us:g} us")
    ax[1, 1].set_xlabel("period")
    ax[1, 1].set_ylabel("us")
    ax[1, 1].legend()
    ax[1, 1].set_title("CAN round trip + compute per period")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def measure(out: Path, duration_s: float, rate_hz: float, rt_priority: int, cpu: int | None,
            method: str = "pd", preset: str = "release") -> dict[str, Any]:
    """The measurement itself (the command and the tests call this). Returns timing.json's data."""
    from gen.lib.atomic_output import write_json_atomic
    import numpy as np

    from tools.run.hil import HilError, HilOptions, realtime_cpu, run_hil
    from tools.run.telemetry_log import read_log

    out.mkdir(parents=True, exist_ok=True)
    for stale in ("timing.json", "timing.png", "cyclictest.txt"):
        (out / stale).unlink(missing_ok=True)
    period_us = 1e6 / rate_hz
    hil_dir = out / "hil"
    (hil_dir / "telemetry.lcmlog").unlink(missing_ok=True)  # a previous run's log must not start cyclictest
    ctl_args = ["--rate", f"{rate_hz:g}", "--rt-priority", str(rt_priority)]
    opts = HilOptions(out=hil_dir, duration_s=duration_s, method=method, mode="realtime", preset=preset,
                      controller_args=tuple(ctl_args), cpu=cpu)
    cpu = realtime_cpu(opts)  # the loop, the simulator and cyclictest: one CPU, the same conditions
    result: dict[str, Any] = {}

    def hil() -> None:
        try:
            result["run"] = run_hil(opts)
        except HilError as exc:  # noqa: PERF203
            result["error"] = str(exc)
        except Exception as exc:  # noqa: BLE001 - reported in timing.json, never swallowed silently
            result["error"] = f"{type(exc).__name__}: {exc}"

    t = threading.Thread(target=hil, daemon=True)
    t.start()
    # cyclictest measures while the control loop runs: it starts at the loop's first period.
    log = hil_dir / "telemetry.lcmlog"
    while t.is_alive() and not _first_timing_message(log):
        time.sleep(0.05)
    # No loop count: it runs exactly while the loop does and is stopped (SIGINT: it prints its
    # histogram) when the controller has finished (its summary is written).
    cyc_cmd = ["cyclictest", "-m", "-q", "-t", "1", "--policy=fifo", "-p", str(rt_priority),
               "-i", str(int(round(period_us))), "-h", str(HISTMAX_US), "-a", str(cpu)]
    cyc: dict[str, Any] = {"command": cyc_cmd}
    if shutil.which("cyclictest") is None:
        cyc["error"] = "cyclictest not found: apt-get install rt-tests (tools/armctl does as root)"
    elif not t.is_alive() and "run" not in result and "error" in result:
        cyc["error"] = "not run: the HIL run failed before its loop started"
    else:
        proc = subprocess.Popen(cyc_cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        done = hil_dir / "controller_summary.json"
        while t.is_alive() and not done.exists() and proc.poll() is None:
            time.sleep(0.02)
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        stdout, stderr = procs.communicate_or_kill(proc, 30)
        (out / "cyclictest.txt").write_text(stdout + stderr)
        parsed = parse_cyclictest(stdout)
        if proc.returncode not in (0, -signal.SIGINT) or not parsed["histogram_us"]:
            cyc["error"] = f"cyclictest exited {proc.returncode}: {(stderr or stdout).strip()[-300:]}"
        cyc.update(parsed)
    t.join()

    run = result.get("run", {})
    timing: Any = []
    if log.exists():
        timing = read_log(log, channels=("ARM_TIMING",))["ARM_TIMING"].messages
    wake = (np.asarray(timing.wake_latency_ns) / 1e3).tolist() if len(timing) else []
    compute = (np.asarray(timing.compute_ns) / 1e3).tolist() if len(timing) else []
    cycle = (np.asarray(timing.cycle_ns) / 1e3).tolist() if len(timing) else []
    summary = json.loads((hil_dir / "controller_summary.json").read_text()) \
        if (hil_dir / "controller_summary.json").exists() else {}
    sim = json.loads((hil_dir / "sim_summary.json").read_text()) if (hil_dir / "sim_summary.json").exists() else {}
    frames = summary.get("frames", {})
    rt_line = ""
    ctl_log = hil_dir / "controller.log"
    if ctl_log.exists():
        rt_line = next((ln.split("rt: ", 1)[1] for ln in ctl_log.read_text().splitlines() if " rt: " in ln), "")
    periods = len(timing)
    overruns = int(timing[-1].overruns) if len(timing) else int(summary.get("overruns", 0))
    ctl_stats = _stats(wake)
    cyc_stats = cyc.get("stats", {})
    relative = {}
    for k in ("p50", "p99", "p99.9", "max"):
        a, b = ctl_stats.get(k), cyc_stats.get(k)
        if isinstance(a, float) and isinstance(b, (int, float)) and b:
            relative[k] = {"controller_us": a, "cyclictest_us": float(b), "ratio": a / float(b),
                           "difference_us": a - float(b)}
    data: dict[str, Any] = {
        "config": {"duration_s": duration_s, "rate_hz": rate_hz, "period_us": period_us,
                   "rt_priority": rt_priority, "cpu": cpu, "method": method, "mode": "realtime",
                   "controller_args": ctl_args, "cyclictest": cyc_cmd},
        "controller_rt_setup": rt_line,
        "simulator_scheduling": run.get("environment", {}).get("simulator_scheduling", "unknown"),
        "run": {"ok": bool(run) and run["results"]["result"] == "ok",
                "result": run.get("results", {}).get("result", "failed"),
                "problems": run.get("results", {}).get("problems", []) + ([result["error"]] if "error" in result else []),
                "final_state": run.get("results", {}).get("final_state"),
                "steps": run.get("results", {}).get("steps", 0)},
        "controller": {
            "periods_measured": periods,
            "wake_latency_us": ctl_stats,
            "compute_us": _stats(compute),
            "cycle_us": _stats(cycle),
            "overruns": overruns,
            "overrun_fraction": overruns / periods if periods else None,
        },
        "cyclictest": {k: v for k, v in cyc.items() if k != "histogram_us"} |
                      {"histogram_us": {str(k): v for k, v in sorted(cyc.get("histogram_us", {}).items())}},
        "relative_to_cyclictest": relative,
        # which side was late, wherever states missed the wait: the controller's account and the
        # simulator's own times, beside cyclictest's figures of the same window (docs/runs.md,
        # Which side was late)
        "lateness": run.get("environment", {}).get("lateness") or {
            "late_periods": (summary.get("lateness") or {}).get("late_periods"),
            "stop": (summary.get("lateness") or {}).get("stop") or None},
        "bus": {
            "joint_states_in_time": frames.get("rx_state"),
            "joint_states_late": frames.get("rx_wrong_counter"),
            "simulator_periods": sim.get("periods"),
            "commands_missed_by_simulator": sim.get("commands_missed"),
            "note": "late = a state for an earlier SYNC, arriving after that period's wait (0.8 period) "
                    "and discarded; more than --watchdog-periods (3) in a row safe-stop the loop",
        },
        "definitions": {
            "wake_latency": "actual wake-up minus the absolute deadline (clock_nanosleep TIMER_ABSTIME, "
                            "CLOCK_MONOTONIC); cyclictest measures the same quantity",
            "compute": "arm_ctl_step alone (inverse dynamics + method + safety layer)",
            "cycle": "SYNC sent -> six commands sent: CAN round trip to the drives (simulator) + compute",
            "overrun": "a period whose deadline passed before its cycle finished (missed deadlines "
                       "are skipped, the schedule never drifts)",
        },
    }
    # The verdict: every period the controller was asked for ran, and cyclictest ran beside it.
    requested, done = summary.get("steps_requested"), summary.get("steps_done")
    if not summary:
        verdict, why = "failed", "the controller wrote no summary: " + "; ".join(data["run"]["problems"])
    elif done != requested:
        verdict, why = "incomplete", (f"the loop ran {done} of {requested} periods: "
                                      + ("; ".join(data["run"]["problems"]) or summary.get("reason", "")))
    elif "error" in cyc:
        verdict, why = "incomplete", f"cyclictest did not measure beside the loop: {cyc['error']}"
    elif not data["run"]["ok"]:
        verdict, why = "failed", "; ".join(data["run"]["problems"]) or "the HIL run failed"
    else:
        verdict, why = "ok", ""
    data["verdict"], data["verdict_reason"] = verdict, why
    data["controller"]["periods_requested"] = requested
    if periods or cyc.get("histogram_us"):
        _plot(out / "timing.png", wake, cyc.get("histogram_us", {}), compute, cycle, period_us,
              f"controller vs cyclictest, {rate_hz:g} Hz, SCHED_FIFO {rt_priority}, {duration_s:g} s")
    write_json_atomic(out / "timing.json", data)
    return data


def _fmt(v: Any) -> str:
    return f"{v:10.1f}" if isinstance(v, (int, float)) and not (isinstance(v, float) and math.isnan(v)) else f"{'-':>10}"


def table(d: dict[str, Any]) -> str:
    c, cy = d["controller"], d["cyclictest"].get("stats", {})
    rows = [f"{'us':<34}{'p50':>10}{'p99':>10}{'p99.9':>10}{'max':>10}"]
    for name, s in (("controller wake-up latency", c["wake_latency_us"]), ("cyclictest wake-up latency", cy),
                    ("compute (arm_ctl_step)", c["compute_us"]), ("cycle (SYNC -> commands sent)", c["cycle_us"])):
        rows.append(f"{name:<34}" + "".join(_fmt(s.get(k)) for k in ("p50", "p99", "p99.9", "max")))
    cfg = d["config"]
    rows.append(f"{c['periods_measured']} periods at {cfg['rate_hz']:g} Hz; overruns {c['overruns']}"
                + (f" ({100 * c['overrun_fraction']:.2f} %)" if c["overrun_fraction"] is not None else ""))
    b = d["bus"]
    rows.append(f"joint states in time {b['joint_states_in_time']}, late {b['joint_states_late']}; "
                f"commands the simulator missed {b['commands_missed_by_simulator']}")
    late = d.get("lateness") or {}
    if late.get("late_periods"):
        lp = late["late_periods"]
        rows.append(f"periods whose states missed the wait: {lp.get('plant', 0)} the plant's answer, "
                    f"{lp.get('controller', 0)} the controller's wake-up, {lp.get('bus', 0)} the bus")
    if late.get("stop"):
        rows.append(f"the stop: {late['stop']}")
    rows.append(f"controller rt set-up: {d['controller_rt_setup'] or '?'}")
    if "error" in d["cyclictest"]:
        rows.append(f"cyclictest: {d['cyclictest']['error']}")
    if d["run"]["problems"]:
        rows.append("run: " + "; ".join(d["run"]["problems"]))
    return "\n".join(rows)


def add_subparser(sub: argparse._SubParsersAction) -> None:
    tm = sub.add_parser("timing", help="real-time loop latency vs cyclictest in the same run")
    add_arguments(tm)
    tm.set_defaults(run=run)


def run(ns: argparse.Namespace) -> int:
    from tools.build import build
    from tools.errors import UsageError

    if not ns.duration > 0:
        raise UsageError(f"--duration: must be > 0, got {ns.duration}")
    if not 10 <= ns.rate <= 20000:
        raise UsageError(f"--rate: must be in [10, 20000] Hz, got {ns.rate}")
    from tools.build.packages import ensure

    if ns.repeat < 1:
        raise UsageError(f"--repeat: must be 1 or more, got {ns.repeat}")
    ensure("timing")
    build("release")
    if ns.repeat > 1:
        return _run_repeated(ns)
    d = measure(ns.out, ns.duration, ns.rate, ns.rt_priority, ns.cpu, ns.method)
    print(table(d))
    print(f"verdict: {d['verdict']}" + (f": {d['verdict_reason']}" if d["verdict_reason"] else ""))
    print(f"results: {ns.out / 'timing.json'}  plot: {ns.out / 'timing.png'}")
    if ns.record:
        from tools.bench.record import record

        record("timing", d, f"tools/armctl timing --duration {ns.duration:g} --rate {ns.rate:g} --record")
    return 0 if d["verdict"] == "ok" else 1


def _run_repeated(ns: argparse.Namespace) -> int:
    from tools.bench.timing_repeat import repeat, table as repeat_table

    d = repeat(ns.out, ns.repeat, ns.duration, ns.rate, ns.rt_priority, ns.cpu, ns.method)
    print(repeat_table(d))
    print(f"verdict: {d['verdict']}" + (f": {d['verdict_reason']}" if d["verdict_reason"] else ""))
    print(f"results: {ns.out / 'repeat.json'}")
    if ns.record:
        from tools.bench.record import record

        record("timing-repeat", d, f"tools/armctl timing --repeat {ns.repeat} --duration {ns.duration:g} "
                                   f"--rate {ns.rate:g} --record")
    return 0 if d["verdict"] == "ok" else 1
