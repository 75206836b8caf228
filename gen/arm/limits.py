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
from gen.arm.home import Pose
from gen.arm.reference import REF_TORQUE_FRACTION, default_reference, reference_torque

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
                        "its ranges and to follow the default reference; give your drives' limits in an arm file "
                        "(torque_limits)")
    out = [(float(lim), src) for lim, src in limits if lim is not None]
    _check_gravity_at_home(m1, chain, pose, out, path)
    return out


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
    """Each joint's largest |torque| to hold the arm still anywhere in its ranges (home and
    GRAVITY_SAMPLES poses drawn in them; an unlimited joint anywhere in a turn) and to follow the
    default reference from home (frictionloss included)."""
    rng = np.random.default_rng(0)
    lo = np.array([r[0] if r else -math.pi for r in pose.ranges])
    hi = np.array([r[1] if r else math.pi for r in pose.ranges])
    d = mujoco.MjData(m)
    worst = np.abs(holding_torque(m, np.asarray(pose.home, float), d))
    for _ in range(GRAVITY_SAMPLES):
        worst = np.maximum(worst, np.abs(holding_torque(m, rng.uniform(lo, hi), d)))
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
