"""Stage 6, limits: each controlled joint's torque limit, the one value the simulator's drives and the
firmware's safety layer share. The arm file's, else the tightest the model gives (the joint's
actuatorfrcrange; every motor or fixed-gain actuator on it: |gear| x |gain| x ctrlrange and
|gear| x forcerange), else assumed from the arm's own needs with a warning. An arm whose limit
cannot hold it at home against gravity is refused, naming the torque it needs."""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np

from gen.arm.arm_file import ArmFile
from gen.arm.chain import Chain
from gen.arm.errors import ArmError
from gen.drive_check import MAX_PERMILLE
from gen.arm.home import MID_RANGE, Pose
from gen.arm.reference import (RANGE_MARGIN, REF_MAX_ACCELERATION, REF_TORQUE_FRACTION, default_reference,
                               reference_torque)

GRAVITY_SAMPLES = 256  # poses within the joint ranges at which an assumed limit must hold the arm


def torque_limits(m0: mujoco.MjModel, m1: mujoco.MjModel, chain: Chain, pose: Pose, af: ArmFile, path: Path,
                  warnings: list[str]) -> list[tuple[float, str]]:
    """(limit N m, where it came from) for each controlled joint. m0: the model as compiled (its
    actuators); m1: the prepared dynamics, one dof per controlled joint."""
    limits = [model_limit(m0, j, af.torque_limits.get(name)) for j, name in zip(chain.joints, chain.names)]
    missing = [i for i, (lim, _) in enumerate(limits) if lim is None]
    if missing:
        needs = arm_needs(m1, pose)
        notes = []
        for i in missing:
            lim = _round_up(needs[i] / REF_TORQUE_FRACTION)
            limits[i] = (lim, "assumed: no limit in the model")
            notes.append(f"{chain.names[i]} {lim:g} N m")
        warnings.append("torque limits assumed (the model gives none: no actuatorfrcrange, no actuator with a "
                        "ctrlrange or forcerange, in URDF no <limit effort>): " + ", ".join(notes) +
                        f"; each is {1 / REF_TORQUE_FRACTION:g} x what the joint needs to hold the arm anywhere in "
                        f"its ranges while accelerating at {REF_MAX_ACCELERATION:g} rad/s^2, and to follow the default "
                        "reference; give your drives' limits in an arm file (torque_limits)")
    out = [(float(lim), src) for lim, src in limits if lim is not None]
    if pose.source == MID_RANGE:
        _lighter_home(m1, chain, pose, [lim for lim, _ in out], warnings)
    _check_gravity_at_home(m1, chain, pose, out, path)
    return out


def _gravity_fraction(m: mujoco.MjModel, q: np.ndarray, limits: np.ndarray, d: mujoco.MjData) -> np.ndarray:
    return np.abs(holding_torque(m, q, d)) / limits


def _lighter_home(m1: mujoco.MjModel, chain: Chain, pose: Pose, limits: list[float], warnings: list[str]) -> None:
    """A home the importer chose (mid-range: neither the model nor the arm file gives one) where
    holding the arm against gravity takes more than REF_TORQUE_FRACTION of a joint's torque limit
    leaves the controller no room to follow a reference or reject a disturbance: it moves, inside
    the ranges, to the pose nearby where gravity asks least of the limits (the arm let down).
    A home the user gave is never moved."""
    lim = np.asarray(limits, float)
    d = mujoco.MjData(m1)
    home = np.asarray(pose.home, float)
    before = _gravity_fraction(m1, home, lim, d)
    if before.max() <= REF_TORQUE_FRACTION:
        return
    bounds = [(r[0] + RANGE_MARGIN, r[1] - RANGE_MARGIN) if r else (h - math.pi, h + math.pi)
              for h, r in zip(home, pose.ranges)]
    from scipy.optimize import minimize

    found = minimize(lambda q: float(np.sum(_gravity_fraction(m1, q, lim, d) ** 2)), home, method="L-BFGS-B",
                     bounds=bounds)
    q = np.clip(found.x, [b[0] for b in bounds], [b[1] for b in bounds])
    after = _gravity_fraction(m1, q, lim, d)
    if after.max() >= before.max():
        return
    worst = int(np.argmax(before))
    pose.home = [round(float(x), 4) for x in q]
    pose.source = f"mid-range moved to where gravity asks less (at most {after.max():.0%} of a torque limit)"
    warnings.append(f"home pose: at mid-range, holding the arm against gravity takes {before[worst]:.0%} of "
                    f"{chain.names[worst]}'s torque limit, more than the {REF_TORQUE_FRACTION:.0%} that leaves the "
                    f"controller room; moved to where it takes at most {after.max():.0%}: "
                    + ", ".join(f"{n} {h:g}" for n, h in zip(chain.names, pose.home))
                    + " rad (give the arm's own home in an arm file, home = [...])")


def model_limit(m: mujoco.MjModel, j: int, override: float | None) -> tuple[float | None, str]:
    """The tightest of the joint's actuatorfrcrange and each actuator on it (motor or general:
    |gear| x |gain| x ctrlrange, |gear| x forcerange); the arm file's value replaces them all."""
    if override is not None:
        return override, "arm file"
    cands: list[tuple[float, str]] = []
    if m.jnt_actfrclimited[j]:
        cands.append((float(np.max(np.abs(m.jnt_actfrcrange[j]))), "joint actuatorfrcrange"))
    for a in range(m.nu):
        if m.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT or m.actuator_trnid[a, 0] != j:
            continue
        gear = abs(float(m.actuator_gear[a, 0]))
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a) or f"actuator{a}"
        plain = (m.actuator_gaintype[a] == mujoco.mjtGain.mjGAIN_FIXED
                 and m.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_NONE)
        if plain and m.actuator_ctrllimited[a]:
            cands.append((gear * abs(float(m.actuator_gainprm[a, 0])) * float(np.max(np.abs(m.actuator_ctrlrange[a]))),
                          f"actuator {name} ctrlrange x gear"))
        if m.actuator_forcelimited[a]:
            cands.append((gear * float(np.max(np.abs(m.actuator_forcerange[a]))), f"actuator {name} forcerange x gear"))
    cands = [c for c in cands if c[0] > 0]
    if not cands:
        return None, ""
    return min(cands)


def holding_torque(m: mujoco.MjModel, q: np.ndarray, d: mujoco.MjData | None = None) -> np.ndarray:
    """What each joint must give to hold the arm still at q: gravity and springs (mj_inverse at rest,
    constraints off)."""
    d = d or mujoco.MjData(m)
    d.qvel[:] = 0.0
    d.qacc[:] = 0.0
    flags = m.opt.disableflags
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    try:
        d.qpos[:] = q
        mujoco.mj_inverse(m, d)
        return d.qfrc_inverse.copy()
    finally:
        m.opt.disableflags = flags


def arm_needs(m: mujoco.MjModel, pose: Pose) -> np.ndarray:
    """Each joint's largest |torque| to hold the arm anywhere in its ranges while accelerating the
    joint at REF_MAX_ACCELERATION (home and GRAVITY_SAMPLES poses drawn in the ranges; an unlimited
    joint anywhere in a turn: |gravity| + M_jj a), and to follow the default reference from home
    (frictionloss included). The acceleration gives a joint that gravity does not load (a base
    turning about the vertical) a drive that can move its links, not one sized for the reference
    alone: the joints beyond it pass their motion through it."""
    rng = np.random.default_rng(0)
    lo = np.array([r[0] if r else -math.pi for r in pose.ranges])
    hi = np.array([r[1] if r else math.pi for r in pose.ranges])
    d = mujoco.MjData(m)
    mass = np.zeros((m.nv, m.nv))
    worst = np.zeros(m.nv)
    for q in [np.asarray(pose.home, float)] + [rng.uniform(lo, hi) for _ in range(GRAVITY_SAMPLES)]:
        hold = np.abs(holding_torque(m, q, d))
        mujoco.mj_fullM(m, d, mass)
        worst = np.maximum(worst, hold + np.diag(mass) * REF_MAX_ACCELERATION)
    ref = default_reference(pose.home, pose.ranges)
    worst = np.maximum(worst, reference_torque(m, pose.home, ref["amp"], ref["freq_hz"]))
    return worst


def _round_up(x: float) -> float:
    """Up to two significant digits (a limit a person would write), never 0."""
    x = max(float(x), 1e-3)
    scale = 10.0 ** (math.floor(math.log10(x)) - 1)
    return round(math.ceil(x / scale - 1e-9) * scale, 12)


def _check_gravity_at_home(m1: mujoco.MjModel, chain: Chain, pose: Pose, limits: list[tuple[float, str]],
                           path: Path) -> None:
    need = np.abs(holding_torque(m1, np.asarray(pose.home, float)))
    for i, (lim, src) in enumerate(limits):
        if need[i] > lim:
            raise ArmError(f"model {path}: joint '{chain.names[i]}': its torque limit {lim:.3g} N m ({src}) cannot "
                           f"hold the arm at home ({pose.source}) against gravity (needs {need[i]:.3g} N m): give "
                           "the drive's real limit (arm file torque_limits) or a home pose where gravity asks less "
                           "(arm file home)")


# CiA 402 commands torque in steps of 1 per mille of the motor's rated torque (0x6071). The emulated
# drives' motor gives the joint's torque limit at its rated torque (firmware/protocol/drives.toml:
# "joint_torque_limit / gear"): a step of a thousandth of the limit at the joint. One step that
# changes a joint's speed by more than MAX_STEP_SPEED within one loop period leaves the loop
# nothing finer to hold it with: it cycles between steps, up to the safety layer's 2 pi rad/s stop
# (a light last link on a limit sized for a heavy one: SO-100's gripper, 1.6 rad/s a step; SO-101's,
# 0.6, runs). There the importer sizes the motor as an integrator would: rated at the joint so that
# a step changes the speed by SIZED_STEP_SPEED, and its max torque 0x6072 (per-mille of the rated,
# up to an INTEGER16's 32767) gives the joint's limit; only a joint that even 32767 per-mille
# cannot serve stays a limitation.
TORQUE_STEP = 1e-3
MAX_STEP_SPEED = 1.0  # rad/s
SIZED_STEP_SPEED = 0.25  # rad/s: a quarter of MAX_STEP_SPEED, SO-101's gripper's half


def _round_down(x: float) -> float:
    """Down to two significant digits (a motor's rating as a catalogue gives it)."""
    scale = 10.0 ** (math.floor(math.log10(x)) - 1)
    return round(math.floor(x / scale + 1e-9) * scale, 12)


def size_drives(names: list[str], limits: list[float], inertia_at_home: np.ndarray,
                period: float) -> tuple[list[float | None], list[dict[str, object]], list[str]]:
    """Per joint, the rated torque at the joint of a motor sized below the limit (None: the limit's
    own motor, whose step is fine enough), where one torque step of a drive rated at the limit
    changes the joint's speed within one period by more than MAX_STEP_SPEED (M_jj at home); the
    joints no motor can serve (arm.json's limitations, each with what to change); and a warning
    per sized joint."""
    sized: list[float | None] = []
    out: list[dict[str, object]] = []
    notes: list[str] = []
    for name, lim, mjj in zip(names, limits, inertia_at_home):
        step = TORQUE_STEP * lim
        speed = step / float(mjj) * period
        if speed <= MAX_STEP_SPEED:
            sized.append(None)
            continue
        rated = _round_down(SIZED_STEP_SPEED * float(mjj) / period / TORQUE_STEP)
        if lim / rated * 1000 <= MAX_PERMILLE:
            sized.append(rated)
            notes.append(f"joint '{name}': a motor rated at its {lim:g} N m limit is too coarse for the {float(mjj):.2g} "
                         f"kg m^2 it moves (one CiA 402 step, 1 per mille of the rated torque, would change its speed "
                         f"by {speed:.2g} rad/s within a {period * 1e3:g} ms period): its emulated drive's motor is "
                         f"rated {rated:g} N m at the joint (a step of {rated * TORQUE_STEP:.3g} N m, "
                         f"{SIZED_STEP_SPEED:g} rad/s), its max torque (0x6072) gives the limit; give the real "
                         "drive's in an arm file (drives)")
            continue
        sized.append(None)
        out.append({"joint": name, "kind": "torque-step", "text": (
            f"joint '{name}': one torque step of a drive whose rated torque gives its {lim:g} N m limit "
            f"(CiA 402 commands 1 per mille of the rated torque: {step:.3g} N m at the joint) changes its "
            f"speed by {speed:.2g} rad/s within a {period * 1e3:g} ms period (it moves {float(mjj):.2g} kg m^2 "
            f"at home), more than {MAX_STEP_SPEED:g} rad/s, and a motor fine enough would need more than "
            f"{MAX_PERMILLE} per-mille (0x6072) for the limit: the loop has nothing finer to hold it with; give "
            "it a drive with a finer step (the arm file's drives: a lower rated_torque_nm, or more gear) or "
            "its drive's real torque limit (torque_limits)")})
    return sized, out, notes
