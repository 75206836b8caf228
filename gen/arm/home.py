"""Stage 4, home: the home pose (the arm file's, else the model's keyframe, else mid-range), and
every joint that is not controlled locked at its value (the arm file's, else the keyframe's),
its body fixed where the joint held it."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from gen.arm.arm_file import ArmFile
from gen.arm.chain import Chain, joint_name
from gen.arm.errors import ArmError
from gen.arm.reference import RANGE_MARGIN


@dataclass
class Pose:
    home: list[float]
    source: str                          # where home came from, for arm.json and the warnings
    ranges: list[list[float] | None]     # each controlled joint's range (None: unlimited)
    qpos_key: np.ndarray                 # the keyframe's qpos (else qpos0): the locked joints' values


def home_pose(m0: mujoco.MjModel, chain: Chain, af: ArmFile, path: Path, warnings: list[str]) -> Pose:
    key = -1
    if af.keyframe is not None:
        key = mujoco.mj_name2id(m0, mujoco.mjtObj.mjOBJ_KEY, af.keyframe)
        if key < 0:
            raise ArmError(f"arm file {af.path}: keyframe: no keyframe '{af.keyframe}' in {path.name}")
    else:
        key = mujoco.mj_name2id(m0, mujoco.mjtObj.mjOBJ_KEY, "home")
    qpos_key = m0.key_qpos[key] if key >= 0 else m0.qpos0
    ranges = [[float(m0.jnt_range[j, 0]), float(m0.jnt_range[j, 1])] if m0.jnt_limited[j] else None
              for j in chain.joints]
    names, n = chain.names, chain.n
    if af.home is not None:
        if isinstance(af.home, list):
            if len(af.home) != n:
                raise ArmError(f"arm file {af.path}: home: {len(af.home)} values for {n} joints ({', '.join(names)})")
            home = list(af.home)
        else:
            missing = [k for k in names if k not in af.home]
            extra = [k for k in af.home if k not in names]
            if missing or extra:
                raise ArmError(f"arm file {af.path}: home: " + (f"missing {missing}" if missing else f"unknown {extra}"))
            home = [af.home[k] for k in names]
        source = "arm file"
    elif key >= 0:
        home = [float(qpos_key[m0.jnt_qposadr[j]]) for j in chain.joints]
        source = f"keyframe '{mujoco.mj_id2name(m0, mujoco.mjtObj.mjOBJ_KEY, key)}'"
    else:
        home = [0.5 * (r[0] + r[1]) if r else float(m0.qpos0[m0.jnt_qposadr[j]])
                for j, r in zip(chain.joints, ranges)]
        source = "mid-range (no keyframe 'home' in the model, none in the arm file)"
        warnings.append(f"home pose: {source}")
    for name, h, r in zip(names, home, ranges):
        if r and not (r[0] + RANGE_MARGIN <= h <= r[1] - RANGE_MARGIN):
            raise ArmError(f"home pose ({source}): joint '{name}' at {h:g} rad is not inside its range "
                           f"[{r[0]:g}, {r[1]:g}] by {RANGE_MARGIN} rad")
    return Pose(home, source, ranges, np.array(qpos_key, dtype=float))


def lock_other_joints(spec: mujoco.MjSpec, m0: mujoco.MjModel, chain: Chain, pose: Pose, af: ArmFile,
                      path: Path, warnings: list[str]) -> list[dict[str, Any]]:
    """Each joint that is not controlled deleted from the spec, its body moved to where the joint's
    locked value puts it; the locked joints and their values."""
    locked: list[dict[str, Any]] = []
    for j in range(m0.njnt):
        if j in chain.joints:
            continue
        name = joint_name(m0, j)
        adr = int(m0.jnt_qposadr[j])
        t = m0.jnt_type[j]
        if t == mujoco.mjtJoint.mjJNT_BALL:
            raise ArmError(f"model {path}: joint '{name}' is a ball joint off the chain: lock it in the model "
                           "(the arm file locks hinge and slide joints)")
        v = af.locked.get(name, float(pose.qpos_key[adr]))
        spec_joint = spec.joint(name) if mujoco.mj_id2name(m0, mujoco.mjtObj.mjOBJ_JOINT, j) else None
        if spec_joint is None:
            raise ArmError(f"model {path}: joint {j} off the chain has no name: name it, or control it")
        b = int(m0.jnt_bodyid[j])
        body = spec.body(mujoco.mj_id2name(m0, mujoco.mjtObj.mjOBJ_BODY, b))
        q0 = m0.body_quat[b].copy()
        p0 = m0.body_pos[b].copy()
        axis = m0.jnt_axis[j].copy()
        delta = v - float(m0.qpos0[adr])  # the body's frame in the model is the one at qpos0 (= ref)
        if t == mujoco.mjtJoint.mjJNT_HINGE:
            c = m0.jnt_pos[j].copy()
            r = _axis_quat(axis, delta)
            body.pos = p0 + _rotate(q0, c - _rotate(r, c))
            body.quat = _quat_mul(q0, r)
        else:
            body.pos = p0 + _rotate(q0, axis * delta)
            body.quat = q0
        body.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
        spec.delete(spec_joint)
        locked.append({"name": name, "value": v})
    if locked:
        warnings.append("locked (not controlled): " + ", ".join(f"{x['name']} at {x['value']:g}" for x in locked))
    return locked


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    out = np.zeros(4)
    mujoco.mju_mulQuat(out, a, b)
    return out


def _axis_quat(axis: np.ndarray, angle: float) -> np.ndarray:
    out = np.zeros(4)
    mujoco.mju_axisAngle2Quat(out, axis, angle)
    return out


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    out = np.zeros(3)
    mujoco.mju_rotVecQuat(out, v, q)
    return out
