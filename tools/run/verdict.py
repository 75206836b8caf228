"""A run's verdict: "ok" only when it met its stated bounds with every process well and every
metric covering the whole run; otherwise the first thing that went wrong, named.

The verdicts, in the order they are checked (a run gets the first that applies; every reason found
is listed in verdict_reasons):

- interrupted: a signal stopped the controller or the simulator;
- diverged: the simulation blew up (MuJoCo reset the arm), or a tracking error is not finite or
  beyond DIVERGED_DEG;
- failed: a process failed or died (boot failure, runtime fault, lost controller or simulator), or
  the drives simulated another number of periods than the controller ran (another master);
- incomplete: fewer periods than asked for, telemetry lost, foreign telemetry (messages logged
  beyond those sent, duplicate sequence numbers, numbers at or beyond what the sender sent, steps
  that contradict their number: tools/run/run_analysis.py telemetry_accounting), frames the kernel dropped on a full
  receive queue, the logger failed, or the metrics do not cover every period of the trajectory;
- tracking-bound-exceeded: a joint's L-infinity tracking error above bounds.max_error_deg (2 deg
  unless set); a run the safety layer stopped for its following error (0.5 rad, FOLLOWING_ERROR_STOP_DEG)
  is failed, and its reasons name both the stop and the bound it left;
- torque-limited: a joint at its torque limit (or its torque-rate limit, the safety layer's slew
  limit) longer than bounds.max_saturated_fraction of the time;
- commands-missed: the drives missed more commands than bounds.max_commands_missed, or got any late.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

DIVERGED_DEG = 180.0  # an error of half a turn: the arm is no longer where the controller thinks
from gen.lib.bounds import DEFAULT_MAX_ERROR_DEG  # noqa: E402 - the tracking bound a run must meet to be "ok"
from gen.lib.params import constant, default as param_default  # noqa: E402

EXIT: dict[str, int] = constant("controller-exit")  # arm_controller's exit codes (the registry's)
# The firmware safety layer's following-error stop (arm_controller --max-following-error's default
# in the registry, firmware/params/params.toml: 0.5 rad on every joint): a run whose error grows
# past it is stopped (safe-stop, verdict failed) before it can be seen larger. The tracking bound sits far below it, so a run the stop ended has left the bound first.
FOLLOWING_ERROR_STOP_DEG = math.degrees(param_default("controller", "max-following-error"))


def stopped_by_following_error(results: dict[str, Any]) -> bool:
    """The safety layer stopped this run because a joint's following error passed its stop."""
    return "following error" in str(results.get("final_fault") or "")


def left_tracking_bound(results: dict[str, Any]) -> bool:
    """The run lost track: it diverged, exceeded the tracking bound, or the safety layer stopped it
    for its following error (an error beyond FOLLOWING_ERROR_STOP_DEG, above any tracking bound)."""
    if results.get("result") in ("diverged", "tracking-bound-exceeded") or stopped_by_following_error(results):
        return True
    bound = (results.get("bounds") or {}).get("max_error_deg")
    errs = results.get("tracking_max_abs_deg") or []
    return bound is not None and any(not math.isfinite(e) or e > bound for e in errs)


@dataclass(frozen=True)
class Bounds:
    max_error_deg: float = DEFAULT_MAX_ERROR_DEG
    max_saturated_fraction: float = param_default("hil", "max-saturated-fraction")
    max_commands_missed: int = 0

    def as_dict(self) -> dict[str, Any]:
        return {**asdict(self), "diverged_beyond_deg": DIVERGED_DEG,
                "following_error_stop_deg": round(FOLLOWING_ERROR_STOP_DEG, 4),
                "also": "every period asked for ran, no telemetry lost, every process ended well"}


def judge(results: dict[str, Any], transport: dict[str, Any], controller: dict[str, Any], sim: dict[str, Any],
          exit_codes: dict[str, int | None], bounds: Bounds) -> tuple[str, list[str]]:
    found: list[tuple[str, str]] = []

    def add(kind: str, why: str) -> None:
        found.append((kind, why))

    ctl_result = controller.get("result")
    if ctl_result == EXIT["interrupted"] or sim.get("result") == "interrupted":
        add("interrupted", controller.get("reason") or sim.get("reason") or "stopped by a signal")
    if sim.get("result") == "diverged":
        add("diverged", sim.get("reason", "the simulation diverged"))
    errs = results.get("tracking_max_abs_deg") or []
    bad = [i for i, e in enumerate(errs) if not math.isfinite(e) or e > DIVERGED_DEG]
    if bad:
        names = results.get("joint_names") or []
        add("diverged", "tracking error beyond %g deg on %s" % (
            DIVERGED_DEG, ", ".join(names[i] if i < len(names) else f"joint {i + 1}" for i in bad)))
    if ctl_result not in (EXIT["ok"], EXIT["interrupted"]):
        why = controller.get('reason') or f'exit {ctl_result}'
        if "following error" in str(controller.get("final_fault") or why):
            why += (f" (the safety layer's stop at {FOLLOWING_ERROR_STOP_DEG:.3g} deg, beyond the tracking bound of "
                    f"{bounds.max_error_deg:g} deg)")
        add("failed", f"controller: {why}")
    if sim.get("result") not in ("ok", "interrupted", "diverged"):
        add("failed", f"simulator: {sim.get('reason') or sim.get('result')}")
    simulated, sent = results.get("simulated_periods"), results.get("controller_bus_periods")
    if simulated is not None and sent is not None and simulated != sent:
        add("failed", f"the drives simulated {simulated} periods, the controller ran {sent}: the arm followed "
                      "someone else's SYNCs")
    requested, done = controller.get("steps_requested"), controller.get("steps_done")
    if requested is None or done is None or done < requested:
        add("incomplete", f"{done if done is not None else 'an unknown number of'} of "
                          f"{requested if requested is not None else '?'} periods ran")
    drops = [(who, (transport.get(f"{who}_frames") or {}).get("rx_kernel_drops")) for who in ("controller", "simulator")]
    for who, n in drops:
        if n:
            add("incomplete", f"the kernel dropped {n} frames on the {who}'s full receive queue")
    lost = transport.get("telemetry_lost_total")
    if lost is None or lost > 0:
        add("incomplete", f"telemetry lost: {lost if lost is not None else 'unknown'} messages")
    foreign = transport.get("telemetry_foreign")
    if foreign:
        add("incomplete", f"foreign telemetry: {'; '.join(foreign)}")
    log = transport.get("telemetry_log") or {}
    if log.get("damaged"):
        add("incomplete", f"the telemetry log is damaged: {log.get('description')}")
    # Software in the loop writes its log in-process (no logger): what it lacks shows as lost above.
    if "sil" not in exit_codes and (exit_codes.get("logger") not in (0, None) or "logger" not in exit_codes):
        add("incomplete", f"the telemetry logger failed (exit {exit_codes.get('logger')}): the log may miss data")
    want = results.get("trajectory_periods")
    have = results.get("periods_running", 0)
    if want is not None and have < want:
        add("incomplete", f"the metrics cover {have} of the trajectory's {want} periods")
    est = results.get("estimation_periods")
    if want is not None and est is not None and est < have:
        add("incomplete", f"the estimation error covers {est} of {have} periods (simulator truth missing)")
    for i, e in enumerate(errs):
        if math.isfinite(e) and bounds.max_error_deg < e <= DIVERGED_DEG:
            add("tracking-bound-exceeded", f"{_joint(results, i)}: max |e| {e:.3g} deg > {bounds.max_error_deg:g} deg")
    for i, f in enumerate(results.get("saturated_fraction") or []):
        if f > bounds.max_saturated_fraction:
            add("torque-limited", f"{_joint(results, i)}: at its torque or torque-rate limit {100 * f:.1f} % of the time "
                                  f"(> {100 * bounds.max_saturated_fraction:g} %)")
    missed, late = results.get("commands_missed"), results.get("commands_late")
    if missed is None or missed > bounds.max_commands_missed or (late or 0) > 0:
        add("commands-missed", f"the drives missed {missed} commands and got {late} late "
                               f"(bound: {bounds.max_commands_missed} missed, 0 late)")
    if not found:
        return "ok", []
    order = ["interrupted", "diverged", "failed", "incomplete", "tracking-bound-exceeded", "torque-limited",
             "commands-missed"]
    first = min(found, key=lambda kw: order.index(kw[0]))[0]
    return first, [f"{k}: {w}" for k, w in found]


def _joint(results: dict[str, Any], i: int) -> str:
    names = results.get("joint_names") or []
    return names[i] if i < len(names) else f"joint {i + 1}"
