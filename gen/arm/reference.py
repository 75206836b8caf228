"""Stage 7, reference: the arm's default reference, q_d = home + a (1 - cos 2 pi f t), fitted to the
arm so that every joint can follow it: along it, each joint's inverse-dynamics torque (rigid bodies,
armature, damping, the model's frictionloss and any friction a scenario adds) stays within
REF_TORQUE_FRACTION of its torque limit, the rest left to the controller; its speed and
acceleration within REF_MAX_VELOCITY and REF_MAX_ACCELERATION (the speed: half the safety layer's
2 pi rad/s stop). Amplitudes are scaled down per joint until it fits (fit_reference)."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from gen.lib.params import constant

RANGE_MARGIN = 0.05              # rad: the reference and the home pose stay this far inside joint ranges
REF_TORQUE_FRACTION = 0.5
REF_MAX_VELOCITY = math.pi       # rad/s
REF_MAX_ACCELERATION = 20.0      # rad/s^2


def arm_reference(m: mujoco.MjModel, home: list[float], ranges: list[list[float] | None], limits: list[float],
                  names: list[str], warnings: list[str]) -> dict[str, object]:
    """arm.json's reference: the default one fitted to the prepared model, with its rule and each
    joint's peak torque fraction; what fitting changed goes to the warnings."""
    reference = default_reference(home, ranges)
    fitted, notes = fit_reference(m, home, reference["amp"], reference["freq_hz"], limits, names)
    if notes:
        warnings.append("default reference: " + "; ".join(notes))
    peaks = reference_peak_fraction(m, home, fitted, reference["freq_hz"], limits)
    return {"amp": fitted, "freq_hz": reference["freq_hz"], "rule": reference_rule(),
            "peak_torque_fraction": [round(x, 4) for x in peaks]}


def default_reference(home: list[float], ranges: list[list[float] | None]) -> dict[str, list[float]]:
    """q_d = home + a (1 - cos 2 pi f t): the firmware's default amplitudes and distinct frequencies,
    each joint moving towards the side of its range with more room and staying RANGE_MARGIN inside."""
    rule = constant("default-reference")
    amp, freq = [], []
    for i, (h, r) in enumerate(zip(home, ranges)):
        a = round(rule["amp-base"] + rule["amp-step"] * i, 6)
        amp.append(clip_amplitude(a, h, r))
        freq.append(round(rule["freq-base-hz"] + rule["freq-step-hz"] * i, 6))
    return {"amp": amp, "freq_hz": freq}


def reference_rule(fraction: float = REF_TORQUE_FRACTION) -> str:
    return (f"inverse dynamics (rigid bodies, armature, damping, frictionloss, a scenario's friction) within "
            f"{100 * fraction:g} % of each joint's torque limit, speed within {REF_MAX_VELOCITY:.3g} rad/s, "
            f"acceleration within {REF_MAX_ACCELERATION:g} rad/s^2")


def reference_torque(m: mujoco.MjModel, home: list[float], amp: list[float], freq: list[float],
                     viscous: list[float] | None = None, coulomb: list[float] | None = None,
                     samples: int = 500) -> np.ndarray:
    """Each joint's largest |torque| along q = home + a (1 - cos 2 pi f t): MuJoCo's mj_inverse on the
    prepared model (armature and damping included; constraints off), plus the model's frictionloss and
    the viscous (per rad/s) and Coulomb friction a scenario adds, at the velocity's sign. Sampled over
    the slowest joint's period (every joint's peaks fall in it)."""
    n = m.nv
    a, f = np.asarray(amp, float), np.asarray(freq, float)
    w = 2 * np.pi * f
    slowest = float(np.min(f[f > 0])) if np.any(f > 0) else 1.0
    vis = np.asarray(viscous if viscous is not None else np.zeros(n), float)
    cou = np.asarray(coulomb if coulomb is not None else np.zeros(n), float) + m.dof_frictionloss
    d = mujoco.MjData(m)
    flags = m.opt.disableflags
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    worst = np.zeros(n)
    try:
        for t in np.linspace(0.0, 1.0 / slowest, samples):
            d.qpos[:] = np.asarray(home) + a * (1 - np.cos(w * t))
            d.qvel[:] = a * w * np.sin(w * t)
            d.qacc[:] = a * w * w * np.cos(w * t)
            mujoco.mj_inverse(m, d)
            tau = d.qfrc_inverse + vis * d.qvel + cou * np.sign(d.qvel)
            worst = np.maximum(worst, np.abs(tau))
    finally:
        m.opt.disableflags = flags
    return worst


def reference_peak_fraction(m: mujoco.MjModel, home: list[float], amp: list[float], freq: list[float],
                            limits: list[float], viscous: list[float] | None = None,
                            coulomb: list[float] | None = None) -> list[float]:
    return [float(x) for x in reference_torque(m, home, amp, freq, viscous, coulomb) / np.asarray(limits)]


def fit_reference(m: mujoco.MjModel, home: list[float], amp: list[float], freq: list[float], limits: list[float],
                  names: list[str], viscous: list[float] | None = None, coulomb: list[float] | None = None,
                  fraction: float = REF_TORQUE_FRACTION) -> tuple[list[float], list[str]]:
    """The amplitudes, each scaled down as little as needed (per joint, in steps of 10 %) so that the
    reference fits REF_TORQUE_FRACTION of every torque limit, REF_MAX_VELOCITY and
    REF_MAX_ACCELERATION; one note per joint changed, naming the torque the asked-for amplitude needs.
    A joint whose torque stays over with its own motion small is loaded by the joints beyond it: those
    are scaled then. What no amplitude can fix (gravity at home) is noted, amplitudes left as fitted."""
    out = [float(x) for x in amp]
    lim = np.asarray(limits, float)
    for i, f in enumerate(freq):  # speed and acceleration: closed form
        w = 2 * math.pi * f
        if w > 0:
            cap = min(REF_MAX_VELOCITY / w, REF_MAX_ACCELERATION / (w * w))
            if abs(out[i]) > cap:
                out[i] = math.copysign(math.floor(cap * 1e4) / 1e4, out[i])
    asked = reference_torque(m, home, amp, freq, viscous, coulomb)
    notes: list[str] = []
    stuck = False
    for _ in range(200):
        peak = reference_torque(m, home, out, freq, viscous, coulomb)
        over = [i for i in range(len(out)) if peak[i] > fraction * lim[i] * (1 + 1e-9)]
        if not over:
            break
        moved = False
        for i in over:
            if abs(out[i]) > 0.02 * abs(amp[i]) and abs(out[i]) > 1e-3:
                out[i] = math.copysign(math.floor(abs(out[i]) * 0.9 * 1e4) / 1e4, out[i])
                moved = True
            else:  # its own motion is small: the joints beyond it load it
                for k in range(i + 1, len(out)):
                    if abs(out[k]) > 1e-3:
                        out[k] = math.copysign(math.floor(abs(out[k]) * 0.9 * 1e4) / 1e4, out[k])
                        moved = True
        if not moved:
            stuck = True
            break
    peak = reference_torque(m, home, out, freq, viscous, coulomb)
    for i, name in enumerate(names):
        if out[i] != amp[i]:
            notes.append(f"{name}: amplitude {amp[i]:g} rad scaled to {out[i]:g} rad: at {amp[i]:g} rad it would "
                         f"need {asked[i]:.3g} N m of its {lim[i]:g} N m torque limit ({100 * asked[i] / lim[i]:.0f} %, "
                         f"{abs(amp[i]) * 2 * math.pi * freq[i]:.3g} rad/s, "
                         f"{abs(amp[i]) * (2 * math.pi * freq[i]) ** 2:.3g} rad/s^2); the reference keeps within "
                         f"{100 * fraction:g} %")
    if stuck:
        bad = [i for i in range(len(out)) if peak[i] > fraction * lim[i] * (1 + 1e-9)]
        notes += [f"{names[i]}: needs {peak[i]:.3g} N m of its {lim[i]:g} N m torque limit even with every amplitude "
                  f"small (gravity or the model's friction at home): over {100 * fraction:g} %" for i in bad]
    return out, notes


def clip_amplitude(a: float, home: float, r: list[float] | None) -> float:
    """The amplitude nearest the one asked for whose motion home .. home + 2a stays RANGE_MARGIN
    inside the range: its sign picks the direction, flipped when only the other side has room."""
    if r is None:
        return a
    up = r[1] - RANGE_MARGIN - home
    down = home - (r[0] + RANGE_MARGIN)
    room, other = (up, down) if a >= 0 else (down, up)
    if 2 * abs(a) > room and other > room:
        a, room = -a, other
    return math.copysign(min(abs(a), max(0.0, room / 2)), a)
