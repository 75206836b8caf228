"""A controller session's task on the arm's own buses (armctl run, and identify's excitation):
arm_controller's task options checked before anything starts, what the session will do said
before it does it, and its end (OUT/session.json, one line, the exit code); commission says what
it will do the same way."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from gen.lib.params import constant, param
from tools.errors import CommandError, UsageError

OPEN_ENDED_S = param("controller", "duration").max  # hold and stream: until Ctrl-C
REFERENCE_S = 10.0  # the built-in reference's length unless --duration says otherwise
JOG_MAX_DEG = math.degrees(param("controller", "jog").max)
EXIT_INTERRUPTED: int = constant("controller-exit")["interrupted"]  # arm_controller's: stopped by a signal


def _jog(text: str, names: list[str]) -> tuple[int, float]:
    joint, sep, deg_s = text.partition("=")
    if not sep:
        raise UsageError(f"--jog {text}: expected JOINT=DEG (e.g. elbow=5 or 3=-2.5)")
    j = names.index(joint) if joint in names else (int(joint) - 1 if joint.isdigit() else -1)
    if not 0 <= j < len(names):
        raise UsageError(f"--jog {text}: no joint '{joint}' (the arm's: {', '.join(names)}, or 1..{len(names)})")
    try:
        deg = float(deg_s)
    except ValueError:
        raise UsageError(f"--jog {text}: '{deg_s}' is not a number of degrees") from None
    if not (math.isfinite(deg) and abs(deg) <= JOG_MAX_DEG + 1e-9):
        raise UsageError(f"--jog {text}: at most {JOG_MAX_DEG:.0f} deg either way")
    return j, math.radians(deg)


def task_args(ns: argparse.Namespace, setup: object, out: Path) -> tuple[list[str], str]:
    """arm_controller's task options and one line saying what the arm will do."""
    from tools.run.hil import reference_args

    info = setup.info  # type: ignore[attr-defined]
    names = [j["name"] for j in info["joints"]]
    if ns.trajectory is not None:
        from gen.lib.atomic_output import OutputError
        from tools.build.arm import prepared_model
        from tools.run.trajectory import TrajectoryError, check, write_knots

        try:
            model = prepared_model(setup.bdir)  # type: ignore[attr-defined]
            traj = check(ns.trajectory, info, model, info["loop_rate_hz"])
            out.mkdir(parents=True, exist_ok=True)
            write_knots(traj, out / "trajectory.knots", ns.trajectory)
        except TrajectoryError as exc:
            raise UsageError(str(exc)) from None
        except OutputError as exc:
            raise CommandError(str(exc)) from None
        speeds = ", ".join(f"{v:.2g}" for v in traj.peak_speed)
        return (["--task", "trajectory", "--trajectory", str(out / "trajectory.knots")],
                f"the trajectory {ns.trajectory} ({len(traj.t)} rows, {traj.duration_s:g} s; peak speeds {speeds} "
                f"rad/s; at most {100 * max(traj.peak_torque_fraction):.0f} % of a joint's torque by the model), "
                "after a bounded move to its first row")
    if ns.jog is not None:
        j, rad = _jog(ns.jog, names)
        return (["--task", "jog", "--jog", f"{j + 1}:{rad!r}"],
                f"jog {names[j]} by {math.degrees(rad):+g} deg at "
                f"{math.degrees(param('controller', 'jog-speed').default):.0f} deg/s, the other joints held, then hold "
                "it a moment")
    if ns.hold:
        d = ns.duration if ns.duration is not None else OPEN_ENDED_S
        return (["--task", "hold", "--duration", f"{d:g}"],
                "hold the pose the arm is in, with gravity compensation, " +
                (f"for {d:g} s" if ns.duration is not None else "until Ctrl-C"))
    if ns.stream is not None:
        d = ns.duration if ns.duration is not None else OPEN_ENDED_S
        return (["--task", "stream", "--stream-url", ns.stream, "--duration", f"{d:g}"],
                f"follow the planner's stream on {ns.stream} (ARM_PLAN): the first plan is moved to, a stale stream "
                "holds the pose, " + (f"for {d:g} s" if ns.duration is not None else "until Ctrl-C"))
    d = ns.duration if ns.duration is not None else REFERENCE_S
    return (["--task", "reference", "--reference-origin", "home", "--duration", f"{d:g}",
             *reference_args(info, ())],
            f"the built-in reference: a bounded move home, then the arm's reference for {d:g} s")


def describe(setup: object, mode: str, task: str, prog: str, method: str = "pm") -> None:
    """What the command will do, before it does it."""
    s = setup  # ArmOnBus
    info = s.info  # type: ignore[attr-defined]
    design = info.get("design") or {}
    lims = ", ".join(f"{j['torque_limit']:g}" for j in info["joints"])
    rt = "" if mode != "realtime" else " (SCHED_FIFO, the last CPU; as root)"
    print(f"{prog}: arm {info['name']} ({info['n_joints']} joints: {', '.join(j['name'] for j in info['joints'])}), "
          f"build {s.bdir}, design {design.get('config', 'built in')}; method {method}")  # type: ignore[attr-defined]
    print(f"  drive table: {s.table.path} ({Path(s.table.eds).name}); wiring: {s.wiring}")  # type: ignore[attr-defined]
    for line in s.describe_buses():  # type: ignore[attr-defined]
        print(f"  bus {line}")
    how = ("lockstep: a rehearsal against armctl plant, each period waits for the plant's answer" if mode == "lockstep"
           else "realtime")
    print(f"  mode: {how} at {info['loop_rate_hz']:g} Hz{rt}")
    print(f"  task: {task}")
    print(f"  limits: torque {lims} N m; speed {param('controller', 'max-velocity').default:.3g} rad/s; following "
          f"error {param('controller', 'max-following-error').default:g} rad; each joint's range + "
          f"{param('controller', 'position-margin').default:g} rad; bounded moves at "
          f"{param('controller', 'move-speed').default:g} rad/s, {param('controller', 'move-accel').default:g} rad/s^2")
    print("  stop: Ctrl-C (a controlled stop); a fault stops the arm the same way and says why")
    sys.stdout.flush()


def tracking(summary: dict, names: list[str]) -> dict:
    """How closely each joint followed the task (the controller's own count: |q_d - q| while it ran
    the task), in degrees."""
    t = (summary.get("task") or {}).get("tracking") or {}
    if not t.get("periods"):
        return {"periods": 0}
    return {"periods": t["periods"],
            "max_abs_deg": {n: round(math.degrees(x), 4) for n, x in zip(names, t["max_abs_rad"])},
            "rms_deg": {n: round(math.degrees(x), 4) for n, x in zip(names, t["rms_rad"])}}


def finish(res: object, setup: object, task: str, prog: str) -> int:
    """The session's end: its record (OUT/session.json: the task, how it ended, how closely each joint
    followed), one line, and the command's exit code: 0 when the task ended or the user stopped it
    (Ctrl-C), else the controller's."""
    from gen.lib.atomic_output import write_json_atomic

    summary = res.summary  # type: ignore[attr-defined]
    code = res.code  # type: ignore[attr-defined]
    out = res.out  # type: ignore[attr-defined]
    reason = summary.get("reason") or f"the controller ended with exit code {code}"
    user_stop = res.interrupted is not None and code == EXIT_INTERRUPTED  # type: ignore[attr-defined]
    follow = tracking(summary, setup.joint_names)  # type: ignore[attr-defined]
    write_json_atomic(out / "session.json", {
        "task": task, "controller_exit": code, "stopped_by_user": user_stop, "reason": reason,
        "final_state": summary.get("final_state"), "stop": summary.get("stop"), "task_report": summary.get("task"),
        "buses": setup.buses, "tracking": follow})  # type: ignore[attr-defined]
    if follow.get("periods"):
        worst = max(follow["max_abs_deg"].items(), key=lambda kv: kv[1])
        print(f"{prog}: followed within {worst[1]:.3g} deg ({worst[0]}) over {follow['periods']} periods "
              f"(each joint: {out / 'session.json'})")
    stop = summary.get("stop") or {}
    if (code == 0 or user_stop) and stop.get("cause", "none") != "none" and not stop.get("braked"):
        raise CommandError(f"{reason}; the stop did not end braked: {stop.get('safe_state', '?')} (log "
                           f"{out / 'controller.log'})", 1)
    if code == 0 or user_stop:
        print(f"{prog}: {'stopped by you' if user_stop else 'done'}: {reason}; final state "
              f"{summary.get('final_state', '?')}; {stop.get('safe_state', 'nothing to stop')}")
        return 0
    raise CommandError(f"{reason} (controller exit {code}; log {out / 'controller.log'})", 1)
