"""Turn a HIL run's LCM log and the two processes' summaries into run.json.

run.json has three parts: `results` (everything a lockstep run determines: the same seed gives
the same numbers), `transport` (frame and telemetry accounting) and `environment` (ports, wall
time: what differs between two runs of the same configuration).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tools.telemetry_log import ChannelLog, read_log
from tools.verdict import Bounds, judge

STATE_NAMES = {0: "init", 1: "running", 2: "fault", 3: "safe-stop"}
STATE_RUNNING = 1


def _rms(x: np.ndarray) -> list[float]:
    return np.sqrt((x**2).mean(axis=0)).tolist() if len(x) else []


def control_metrics(ctl: ChannelLog, sim: ChannelLog, hold_s: float, rate_hz: float) -> dict[str, Any]:
    """Over the trajectory: running periods after the start-pose hold (t is the period's time as
    the controller logged it, float32: compared within half a period)."""
    running = [m for m in ctl.messages if m.state == STATE_RUNNING and m.t >= hold_s - 0.5 / rate_hz]
    if not running:
        return {"periods_running": 0}
    e = np.array([m.e for m in running], dtype=float)
    tau = np.array([m.tau for m in running], dtype=float)
    qd = np.array([m.qd for m in running], dtype=float)
    w_hat = {m.bus_period: np.array(m.w_hat, dtype=float) for m in running}
    w_true = {m.step: np.array(m.w_true, dtype=float) for m in sim.messages}
    paired = [(w_true[p], w_hat[p]) for p in sorted(w_hat) if p in w_true]
    out: dict[str, Any] = {
        "periods_running": len(running),
        "tracking_max_abs_rad": np.abs(e).max(axis=0).tolist(),
        "tracking_rms_rad": _rms(e),
        "tracking_max_abs_deg": np.degrees(np.abs(e).max(axis=0)).tolist(),
        "tracking_rms_deg": np.degrees(np.sqrt((e**2).mean(axis=0))).tolist(),
        "max_abs_torque_nm": np.abs(tau).max(axis=0).tolist(),
        # Mechanical power the joints deliver, |tau . qd| summed over joints, averaged in time.
        "torque_power_w": float(np.abs(tau * qd).sum(axis=1).mean()),
        "mean_sum_tau_squared_nm2": float((tau**2).sum(axis=1).mean()),
        "saturated_fraction": [float(np.mean([(m.saturated_mask >> j) & 1 for m in running]))
                               for j in range(e.shape[1])],
    }
    if paired:
        wt = np.array([p[0] for p in paired])
        wh = np.array([p[1] for p in paired])
        out["w_rms"] = _rms(wt)
        out["estimation_error_rms"] = _rms(wt - wh)
        out["estimation_periods"] = len(paired)
    return out


def telemetry_accounting(log: dict[str, ChannelLog], sent: dict[str, int]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for ch, n_sent in sent.items():
        logged = len(log[ch].messages) if ch in log else 0
        out[ch] = {"sent": n_sent, "logged": logged, "lost": n_sent - logged,
                   "sequence_gaps": log[ch].gaps if ch in log else 0}
    return out


def final_state(log: dict[str, ChannelLog], controller: dict[str, Any]) -> str:
    if controller.get("final_state"):
        return str(controller["final_state"])
    msgs = log["ARM_CTL"].messages
    return STATE_NAMES.get(msgs[-1].state, "?") if msgs else "unknown"


def analyse(out_dir: Path, controller: dict[str, Any], sim: dict[str, Any], config: dict[str, Any],
            environment: dict[str, Any], bounds: Bounds | None = None) -> dict[str, Any]:
    """run.json. config: the run's settings, with ref_hold_s and rate_hz the controller was given
    (a controller that died wrote no summary: these still say what the run was asked for)."""
    bounds = bounds or Bounds()
    log = read_log(out_dir / "telemetry.lcmlog")
    sent = dict(controller.get("telemetry", {}).get("sent", {}))
    sent.update(sim.get("telemetry_sent", {}))
    tele = telemetry_accounting(log, sent) if sent else {}
    problems = [s for s in (controller.get("reason"), sim.get("reason")) if s]
    hold = float(controller.get("ref_hold_s", config.get("ref_hold_s", 0.0)))
    rate = float(controller.get("rate_hz", config.get("rate_hz", 1000.0)))
    requested = controller.get("steps_requested", round((config["duration_s"] + hold) * rate))
    results = {
        **config,
        "problems": problems,
        "final_state": final_state(log, controller),
        "final_fault": controller.get("final_fault", "unknown"),
        # None where the process that knows died without saying: unknown, not zero
        "steps": controller.get("steps_done"),
        "steps_requested": requested,
        "trajectory_periods": requested - round(hold * rate),
        "simulated_periods": sim.get("periods"),
        "controller_bus_periods": controller.get("bus_periods"),
        "commands_missed": sim.get("commands_missed"),
        "commands_late": sim.get("commands_late"),
        "drive_faults": sim.get("drive_faults"),
        "ref_hold_s": hold,
        "design_hash": controller.get("design_hash", ""),
        **control_metrics(log["ARM_CTL"], log["ARM_SIM"], hold, rate),
    }
    transport = {
        "controller_frames": controller.get("frames", {}),
        "simulator_frames": {k: sim.get(k) for k in ("frames_tx", "frames_rx", "tx_dropped", "rx_foreign_drive",
                                                     "rx_unknown_id", "rx_bad_frame", "rx_undecodable",
                                                     "rx_kernel_drops", "rx_wrong_bus", "rx_duplicate_command",
                                                     "rx_sync_out_of_sequence")},
        "overruns": controller.get("overruns"),
        "bus_timing": sim.get("bus_timing", []),
        "telemetry": tele,
        "telemetry_lost_total": int(sum(v["lost"] for v in tele.values())) if tele else None,
        "telemetry_gaps_total": int(sum(v["sequence_gaps"] for v in tele.values())) if tele else None,
    }
    verdict, reasons = judge(results, transport, controller, sim, environment.get("exit_codes", {}), bounds)
    results["result"] = verdict
    results["verdict_reasons"] = reasons
    results["bounds"] = bounds.as_dict()
    return {"results": results, "transport": transport, "environment": environment}


def table(run: dict[str, Any]) -> str:
    r, t, env = run["results"], run["transport"], run["environment"]
    names = r.get("joint_names") or [f"joint{i + 1}" for i in range(len(r.get("tracking_max_abs_deg", [])))]
    lines = [f"{'joint':<14}{'max |e| (deg)':>15}{'RMS e (deg)':>14}{'RMS w-w_hat':>14}"]
    for i, name in enumerate(names[: len(r.get("tracking_max_abs_deg", []))]):
        est = r.get("estimation_error_rms")
        est_s = f"{est[i]:>14.4f}" if est else f"{'-':>14}"
        lines.append(f"{name:<14}{r['tracking_max_abs_deg'][i]:>15.4f}{r['tracking_rms_deg'][i]:>14.4f}{est_s}")
    lines.append(f"result {r['result']}: method {r['method']}, controller {r['final_state']} after {r['steps']} of "
                 f"{r['steps_requested']} periods")
    for why in r.get("verdict_reasons", []):
        lines.append(f"  {why}")
    cf, sf = t["controller_frames"], t["simulator_frames"]
    lines.append(f"frames: controller sent {cf.get('tx', '?')} / received {cf.get('rx', '?')}, "
                 f"simulator sent {sf['frames_tx']} / received {sf['frames_rx']}")
    if t["telemetry"]:
        sent = sum(v["sent"] for v in t["telemetry"].values())
        logged = sum(v["logged"] for v in t["telemetry"].values())
        lines.append(f"telemetry: {sent} messages sent, {logged} logged, {t['telemetry_lost_total']} lost")
    else:
        lines.append("telemetry: unknown (no process said what it sent)")
    for b in t.get("bus_timing", []):
        lines.append(f"bus timing ({r.get('bus_timing', '?')}), bus {b['bus']} ({b['phy']}, drives "
                     f"{','.join(map(str, b['drives']))}): SYNC -> last command {b['sync_to_last_cmd_mean_us']:.1f} us "
                     f"mean, {b['sync_to_last_cmd_max_us']:.1f} us max; {b['commands_late']} commands late")
    if env.get("realtime_factor"):
        cost = env.get("simulator_period_cost_us") or {}
        lines.append(f"wall time {env['wall_s']:.1f} s; after boot the simulation ran at {env['realtime_factor']:.1f}x "
                     f"real time (simulator CPU per period p50 {cost.get('p50', '?')} us, p99 {cost.get('p99', '?')} us)")
    return "\n".join(lines)
