"""armctl timing --repeat N: the same realtime measurement N times, and what stopped each run.

One run of `armctl timing` says how late this machine woke the loop in one window. An arm that
stops once in twenty runs stops in the middle of a move, so the question a user asks before trusting
the loop is how often a run stops and why. Each run goes to DIR/RUN/ as `armctl timing` writes it;
DIR/repeat.json gives every run's verdict, which side was late when it stopped (the plant's answer,
the controller's wake-up or the bus: run.json's environment.lateness), the stop's reason as the
controller said it, and the controller's and cyclictest's wake-up figures of the same window, so a
stop for lateness is shown against the machine's own latency. A stop that names another node on a
drive's id, with nothing injected, is the controller's misreading: it is counted apart."""

from __future__ import annotations

from pathlib import Path
from typing import Any

ANOTHER_NODE = "another node uses its id"  # the controller's reason for a second TPDO in one period


def run_row(run: int, d: dict[str, Any]) -> dict[str, Any]:
    """One run of timing.json's data, as repeat.json keeps it."""
    late = d.get("lateness") or {}
    cyc = (d.get("cyclictest") or {}).get("stats") or {}
    wake = (d.get("controller") or {}).get("wake_latency_us") or {}
    return {"run": run, "verdict": d["verdict"], "reason": d.get("verdict_reason", ""),
            "stop_side": late.get("stop_side") or "none", "stop": late.get("stop"),
            "late_periods": late.get("late_periods"),
            "controller_wake_us": {k: wake.get(k) for k in ("p99.9", "max")},
            "cyclictest_wake_us": {k: cyc.get(k) for k in ("p99.9", "max")},
            "another_node": ANOTHER_NODE in d.get("verdict_reason", "")}


def summarise(rows: list[dict[str, Any]], duration_s: float, rate_hz: float) -> dict[str, Any]:
    """repeat.json: every run, and the counts a user reads first. Its verdict is ok only when every
    run ran to its end."""
    by_side: dict[str, int] = {}
    for r in rows:
        if r["verdict"] != "ok":
            side = "another node (misread)" if r["another_node"] else r["stop_side"]
            by_side[side] = by_side.get(side, 0) + 1
    ok = sum(r["verdict"] == "ok" for r in rows)
    return {"config": {"runs": len(rows), "duration_s": duration_s, "rate_hz": rate_hz},
            "runs_ok": ok, "stopped_by_side": by_side,
            "another_node": sum(r["another_node"] for r in rows), "runs": rows,
            "verdict": "ok" if ok == len(rows) else "stopped",
            "verdict_reason": "" if ok == len(rows) else f"{len(rows) - ok} of {len(rows)} runs stopped before their end"}


def repeat(out: Path, runs: int, duration_s: float, rate_hz: float, rt_priority: int, cpu: int | None,
           method: str) -> dict[str, Any]:
    """`runs` measurements in a row, each to out/RUN/; repeat.json's data (also written)."""
    from gen.lib.atomic_output import write_json_atomic
    from tools.bench.timing import measure, table as run_table

    rows = []
    for i in range(1, runs + 1):
        d = measure(out / str(i), duration_s, rate_hz, rt_priority, cpu, method)
        rows.append(run_row(i, d))
        print(run_table(d))
        print(f"armctl timing: run {i} of {runs}: {d['verdict']}"
              + (f": {d['verdict_reason']}" if d["verdict_reason"] else ""), flush=True)
    data = summarise(rows, duration_s, rate_hz)
    write_json_atomic(out / "repeat.json", data)
    return data


def _us(v: Any) -> str:
    return f"{v:.0f}" if isinstance(v, (int, float)) else "-"


def table(d: dict[str, Any]) -> str:
    """A row per run: its verdict, the side late at its stop, and the wake-up figures beside it."""
    cfg = d["config"]
    lines = [f"{cfg['runs']} realtime runs of {cfg['duration_s']:g} s at {cfg['rate_hz']:g} Hz, nothing injected: "
             f"{d['runs_ok']} ran to their end; runs stopped as a drive's id used by another node: {d['another_node']}",
             f"{'run':>4} {'verdict':<11} {'late at the stop':<18} {'wake p99.9/max us (controller)':>31} "
             f"{'(cyclictest)':>14}"]
    for r in d["runs"]:
        c, y = r["controller_wake_us"], r["cyclictest_wake_us"]
        side = "another node" if r["another_node"] else r["stop_side"]
        lines.append(f"{r['run']:>4} {r['verdict']:<11} {side:<18} {_us(c['p99.9']) + ' / ' + _us(c['max']):>31} "
                     f"{_us(y['p99.9']) + ' / ' + _us(y['max']):>14}")
    return "\n".join(lines)
