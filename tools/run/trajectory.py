"""A user's trajectory file (armctl run FILE.csv), checked against the arm before anything is
enabled, and the knots the controller follows (arm_controller --trajectory).

The file: one row per point, `t, q1, ..., qn` (s, rad, the arm's joints in order), t strictly
increasing; a first line that is not numbers is a header; `#` lines are comments. The trajectory is
the cubic spline through the rows, at rest at the first and the last (clamped: C2, its velocities at
the rows from one tridiagonal system, clamped_slopes): the controller follows the same curve, cubic
Hermite between the rows with those velocities (firmware/core/src/reference.c arm_traj_eval), and
the check samples exactly that (hermite). It is checked at the loop rate, every sample, against each joint's range, speed
(REF_MAX_VELOCITY: half the safety layer's stop), acceleration (REF_MAX_ACCELERATION) and torque:
the nominal model's inverse dynamics with its friction within TORQUE_FRACTION of the joint's limit,
the rest left to the controller. The first violation is one line naming the file, the row, the
joint and the value (TrajectoryError)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gen.lib.one_line import one_line

TORQUE_FRACTION = 0.8  # of each joint's limit: what the trajectory may take, the rest the controller's
MAX_ROWS = 32768       # the controller's room for knots (firmware/port/linux/traj_file.h TRAJ_FILE_MAX_KNOTS)
MAX_BYTES = 64 << 20


class TrajectoryError(ValueError):
    pass


@dataclass
class Trajectory:
    t: list[float]
    q: list[list[float]]
    qd: list[list[float]]
    duration_s: float
    peak_speed: list[float]         # rad/s per joint
    peak_torque_fraction: list[float]


def read_csv(path: Path, n: int) -> tuple[list[float], list[list[float]], list[int]]:
    """(times shifted to start at 0, rows of n positions, each row's line number)."""
    try:
        if path.stat().st_size > MAX_BYTES:
            raise TrajectoryError(f"{path}: {path.stat().st_size} bytes: larger than {MAX_BYTES >> 20} MB")
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise TrajectoryError(f"{path}: {one_line(str(exc))}") from None
    times: list[float] = []
    rows: list[list[float]] = []
    lines: list[int] = []
    for ln, raw in enumerate(text.splitlines(), 1):
        s = raw.strip()
        if not s or s.startswith("#"):
            continue
        cells = [c.strip() for c in s.split(",")]
        try:
            vals = [float(c) for c in cells]
        except ValueError:
            if not rows and not lines:  # a header
                lines.append(0)
                continue
            raise TrajectoryError(f"{path}: row {ln}: not numbers: {one_line(s[:80])}") from None
        if len(vals) != n + 1:
            raise TrajectoryError(f"{path}: row {ln}: {len(vals)} columns; t and one per joint ({n}) are {n + 1}")
        if not all(math.isfinite(v) for v in vals):
            raise TrajectoryError(f"{path}: row {ln}: a value that is not a finite number")
        if times and not vals[0] > times[-1]:
            raise TrajectoryError(f"{path}: row {ln}: t = {vals[0]:g} s does not increase (the row before has "
                                  f"{times[-1]:g} s)")
        times.append(vals[0])
        rows.append(vals[1:])
        lines.append(ln)
    lines = [x for x in lines if x]
    if len(rows) < 2:
        raise TrajectoryError(f"{path}: {len(rows)} row(s) of t, q1..q{n}: a trajectory needs at least 2")
    if len(rows) > MAX_ROWS:
        raise TrajectoryError(f"{path}: {len(rows)} rows: the controller takes at most {MAX_ROWS} (resample it)")
    t0 = times[0]
    return [t - t0 for t in times], rows, lines


def clamped_slopes(t: Any, q: Any) -> Any:
    """The velocities at the rows of the cubic spline through them that is at rest at both ends
    (a C2 curve): the tridiagonal system h[i] m[i-1] + 2 (h[i-1] + h[i]) m[i] + h[i-1] m[i+1] =
    3 (h[i] d[i-1] + h[i-1] d[i]), d the slopes of the chords, solved by the Thomas algorithm for
    every joint at once (numpy; 32768 rows in milliseconds)."""
    import numpy as np

    n = len(t)
    h = np.diff(t)
    d = np.diff(q, axis=0) / h[:, None]
    m = np.zeros_like(q)
    if n < 3:
        return m
    lower = h[1:]          # m[i-1]'s coefficient, i = 1..n-2
    diag = 2 * (h[:-1] + h[1:])
    upper = h[:-1]         # m[i+1]'s
    rhs = 3 * (h[1:, None] * d[:-1] + h[:-1, None] * d[1:])
    c = np.zeros(n - 2)
    r = np.zeros((n - 2, q.shape[1]))
    c[0], r[0] = upper[0] / diag[0], rhs[0] / diag[0]
    for i in range(1, n - 2):  # forward sweep (m[0] = m[n-1] = 0 drop out)
        den = diag[i] - lower[i] * c[i - 1]
        c[i] = upper[i] / den
        r[i] = (rhs[i] - lower[i] * r[i - 1]) / den
    m[n - 2] = r[n - 3]
    for i in range(n - 4, -1, -1):
        m[i + 1] = r[i] - c[i] * m[i + 2]
    return m


def hermite(t: Any, q: Any, m: Any, at: Any) -> tuple[Any, Any, Any]:
    """Position, velocity and acceleration at the times `at` of the cubic Hermite curve through
    (t, q) with slopes m: arm_traj_eval's formulas."""
    import numpy as np

    k = np.clip(np.searchsorted(t, at, side="right") - 1, 0, len(t) - 2)
    h = (t[k + 1] - t[k])[:, None]
    u = ((at - t[k])[:, None]) / h
    qa, qb, ma, mb = q[k], q[k + 1], m[k], m[k + 1]
    u2, u3 = u * u, u * u * u
    pos = (2 * u3 - 3 * u2 + 1) * qa + (u3 - 2 * u2 + u) * h * ma + (-2 * u3 + 3 * u2) * qb + (u3 - u2) * h * mb
    vel = ((6 * u2 - 6 * u) * qa + (3 * u2 - 4 * u + 1) * h * ma + (-6 * u2 + 6 * u) * qb + (3 * u2 - 2 * u) * h * mb) / h
    acc = ((12 * u - 6) * qa + (6 * u - 4) * h * ma + (-12 * u + 6) * qb + (6 * u - 2) * h * mb) / (h * h)
    return pos, vel, acc


def check(path: Path, info: dict[str, Any], model_xml: Path, rate_hz: float) -> Trajectory:
    """The trajectory in path, checked against the arm (arm.json, its prepared model) at rate_hz."""
    import mujoco
    import numpy as np

    from gen.arm.reference import REF_MAX_ACCELERATION, REF_MAX_VELOCITY

    joints = info["joints"]
    n = len(joints)
    names = [j["name"] for j in joints]
    t, rows, lines = read_csv(path, n)
    q = np.asarray(rows)
    for i, j in enumerate(joints):
        lo, hi = j["range"]
        bad = np.nonzero((q[:, i] < lo) | (q[:, i] > hi))[0]
        if bad.size:
            k = int(bad[0])
            raise TrajectoryError(f"{path}: row {lines[k]}: joint {i + 1} ({names[i]}) at {q[k, i]:.6g} rad is outside "
                                  f"its range [{lo:g}, {hi:g}]")
    ts = np.asarray(t)
    slopes = clamped_slopes(ts, q)
    samples = np.append(np.arange(0.0, ts[-1], 1.0 / rate_hz), ts[-1])
    pos, vel, acc = hermite(ts, q, slopes, samples)
    row_of = np.searchsorted(ts, samples, side="right") - 1  # the row each sample follows

    def where(k: int) -> str:
        r = int(min(max(row_of[k], 0), len(lines) - 1))
        return f"row {lines[r]} (t = {samples[k]:.4g} s, on the spline after it)"

    for i, j in enumerate(joints):
        lo, hi = j["range"]
        bad = np.nonzero((pos[:, i] < lo) | (pos[:, i] > hi))[0]
        if bad.size:
            k = int(bad[0])
            raise TrajectoryError(f"{path}: {where(k)}: joint {i + 1} ({names[i]}) at {pos[k, i]:.6g} rad leaves its "
                                  f"range [{lo:g}, {hi:g}] between the rows")
    for what, arr, lim, unit in (("speed", vel, REF_MAX_VELOCITY, "rad/s"), ("acceleration", acc,
                                                                              REF_MAX_ACCELERATION, "rad/s^2")):
        over = np.abs(arr) > lim
        if over.any():
            k, i = (int(x) for x in np.argwhere(over)[0])
            raise TrajectoryError(f"{path}: {where(k)}: joint {i + 1} ({names[i]}) {what} {abs(arr[k, i]):.4g} {unit}, "
                                  f"above the {lim:.4g} {unit} a trajectory may ask")
    m = mujoco.MjModel.from_xml_path(str(model_xml))
    d = mujoco.MjData(m)
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    limits = np.asarray([j["torque_limit"] for j in joints])
    worst = np.zeros(n)
    for k in range(samples.size):
        d.qpos[:n], d.qvel[:n], d.qacc[:n] = pos[k], vel[k], acc[k]
        mujoco.mj_inverse(m, d)
        tau = np.abs(d.qfrc_inverse[:n] + m.dof_frictionloss[:n] * np.sign(vel[k]))
        frac = tau / limits
        worst = np.maximum(worst, frac)
        if (frac > TORQUE_FRACTION).any():
            i = int(np.argmax(frac))
            raise TrajectoryError(f"{path}: {where(k)}: joint {i + 1} ({names[i]}) needs {tau[i]:.4g} N m by the "
                                  f"model, {100 * frac[i]:.0f} % of its {limits[i]:g} N m limit (a trajectory may "
                                  f"take {100 * TORQUE_FRACTION:.0f} %)")
    return Trajectory(list(map(float, ts)), q.tolist(), slopes.tolist(), float(ts[-1]),
                      np.max(np.abs(vel), axis=0).tolist(), worst.tolist())


def write_knots(traj: Trajectory, path: Path, source: Path) -> None:
    """The controller's --trajectory file: t, q1..qn, qd1..qdn per knot (firmware/port/linux/traj_file.h)."""
    from gen.lib.atomic_output import write_text_atomic

    lines = [f"# arm_controller --trajectory: knots of {one_line(str(source))} (t, q1..qn, qd1..qdn; s, rad, rad/s), "
             "checked by armctl run"]
    for t, q, qd in zip(traj.t, traj.q, traj.qd):
        lines.append(",".join(repr(float(x)) for x in (t, *q, *qd)))
    write_text_atomic(path, "\n".join(lines) + "\n")
