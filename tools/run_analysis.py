"""Turn a HIL run's log and the two processes' summaries into run.json."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tools.telemetry_log import ChannelLog, read_log

STATE_RUNNING = 1


def joint_errors(ctl: ChannelLog) -> dict[str, list[float]]:
    running = [m for m in ctl.messages if m.state == STATE_RUNNING]
    if not running:
        return {"max_abs_deg": [], "rms_deg": []}
    e = np.array([m.e for m in running], dtype=float)
    return {
        "max_abs_deg": np.degrees(np.abs(e).max(axis=0)).tolist(),
        "rms_deg": np.degrees(np.sqrt((e**2).mean(axis=0))).tolist(),
    }


def telemetry_accounting(log: dict[str, ChannelLog], sent: dict[str, int]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for ch, n_sent in sent.items():
        logged = len(log[ch].messages) if ch in log else 0
        out[ch] = {
            "sent": n_sent,
            "logged": logged,
            "lost": n_sent - logged,
            "sequence_gaps": log[ch].gaps if ch in log else 0,
        }
    return out


def analyse(out_dir: Path, controller: dict[str, Any], sim: dict[str, Any], extra: dict[str, Any]) -> dict[str, Any]:
    log = read_log(out_dir / "telemetry.lcmlog")
    sent = dict(controller.get("telemetry", {}).get("sent", {}))
    sent.update(sim.get("telemetry_sent", {}))
    errors = joint_errors(log["ARM_CTL"])
    tele = telemetry_accounting(log, sent)
    return {
        **extra,
        "result": "ok" if controller.get("result") == 0 and sim.get("result") == "ok" else "failed",
        "controller": {
            "result_code": controller.get("result"),
            "reason": controller.get("reason", ""),
            "final_state": controller.get("final_state"),
            "steps": controller.get("steps_done", 0),
            "wall_s": controller.get("wall_s"),
            "frames": controller.get("frames", {}),
        },
        "simulator": {
            "result": sim.get("result"),
            "reason": sim.get("reason", ""),
            "periods": sim.get("periods", 0),
            "frames_tx": sim.get("frames_tx", 0),
            "frames_rx": sim.get("frames_rx", 0),
            "commands_missed": sim.get("commands_missed", 0),
            "drive_faults": sim.get("drive_faults", []),
        },
        "tracking": errors,
        "telemetry": tele,
        "telemetry_lost_total": int(sum(v["lost"] for v in tele.values())),
    }


def table(run: dict[str, Any], joint_names: list[str]) -> str:
    lines = [f"{'joint':<14}{'max |e| (deg)':>15}{'RMS e (deg)':>14}"]
    tr = run["tracking"]
    for i, name in enumerate(joint_names[: len(tr["max_abs_deg"])]):
        lines.append(f"{name:<14}{tr['max_abs_deg'][i]:>15.4f}{tr['rms_deg'][i]:>14.4f}")
    c, s = run["controller"], run["simulator"]
    f = c["frames"]
    lines.append(
        f"result {run['result']}: controller {c['final_state']} after {c['steps']} periods"
        + (f" ({c['reason']})" if c["reason"] else "")
        + (f"; simulator: {s['reason']}" if s["reason"] else "")
    )
    lines.append(
        f"frames: controller sent {f.get('tx', 0)} / received {f.get('rx', 0)}, "
        f"simulator sent {s['frames_tx']} / received {s['frames_rx']}"
    )
    sent = sum(v["sent"] for v in run["telemetry"].values())
    logged = sum(v["logged"] for v in run["telemetry"].values())
    lines.append(f"telemetry: {sent} messages sent, {logged} logged, {run['telemetry_lost_total']} lost")
    if "wall_s" in run and run.get("duration_s"):
        lines.append(f"wall time {run['wall_s']:.1f} s for {run['duration_s']:g} s simulated "
                     f"({run['duration_s'] / run['wall_s']:.2f}x real time)")
    return "\n".join(lines)

