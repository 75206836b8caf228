"""Stage 4, home: the home pose (the arm file's, else the model's keyframe, else mid-range), and
every joint that is not controlled locked at its value (the arm file's, else the keyframe's),
its body fixed where the joint held it."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from gen.arm.arm_file import ArmFile
from gen.arm.chain import Chain, joint_name
from gen.arm.errors import ArmError
from gen.arm.reference import RANGE_MARGIN


MID_RANGE = "mid-range (no keyframe 'home' in the model, none in the arm file)"


@dataclass
class Pose:
    home: list[float]
    source: str                          # where home came from, for arm.json and the warnings
    ranges: list[list[float] | None]     # each controlled joint's range (None: unlimited)
    qpos_key: np.ndarray                 # the keyframe's qpos (else qpos0): the locked joints' values


def home_pose(m0: mujoco.MjModel, chain: Chain, af: ArmFile, path: Path, warnings: list[str],
              spec_degrees: bool = False) -> Pose:
    """spec_degrees: the file gives its angles in degrees (MuJoCo's default for MJCF), for the hint
    when a range is too narrow to move in."""
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
        source = MID_RANGE
        warnings.append(f"home pose: {source}")
    for name, h, r in zip(names, home, ranges):
        if r and r[1] - r[0] < 2 * RANGE_MARGIN:
            raise ArmError(f"model {path}: joint '{name}': its range [{r[0]:.4g}, {r[1]:.4g}] rad "
                           f"({math.degrees(r[1] - r[0]):.2g} deg) leaves it no room to move {RANGE_MARGIN} rad inside "
                           f"it{_degrees_hint(spec_degrees)}; give its real range, or hold it (arm file: locked)")
        if r and not (r[0] + RANGE_MARGIN <= h <= r[1] - RANGE_MARGIN):
            raise ArmError(f"model {path}: home pose ({source}): joint '{name}' at {h:g} rad is not inside its range "
                           f"[{r[0]:g}, {r[1]:g}] by {RANGE_MARGIN} rad")
    return Pose(home, source, ranges, np.array(qpos_key, dtype=float))


def lock_other_joints(spec: mujoco.MjSpec, m0: mujoco.MjModel, chain: Chain, pose: Pose, af: ArmFile,
                      path: Path, warnings: list[str]) -> list[dict[str, Any]]:
    """Each joint that is not controlled deleted from the spec, its body moved to where the joint's
    locked value puts it (a hinge or slide: the arm file's value, else the keyframe's; a ball or
    free joint, of a wrist or of an object in the scene: the keyframe's); the locked joints and
    their values."""
    locked: list[dict[str, Any]] = []
    frames: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # a body's pose after the joints locked so far
    for j in range(m0.njnt):
        if j in chain.joints:
            continue
        name = joint_name(m0, j)
        adr = int(m0.jnt_qposadr[j])
        t = m0.jnt_type[j]
        spec_joint = spec.joint(name)
        b = int(m0.jnt_bodyid[j])
        body = spec.body(mujoco.mj_id2name(m0, mujoco.mjtObj.mjOBJ_BODY, b))
        p0, q0 = frames.get(b, (m0.body_pos[b].copy(), m0.body_quat[b].copy()))  # joints of a body act in turn
        axis = m0.jnt_axis[j].copy()
        if t == mujoco.mjtJoint.mjJNT_FREE:  # an object of the scene: held where the keyframe puts it
            v = [float(x) for x in pose.qpos_key[adr:adr + 7]]
            body.pos = v[:3]
            body.quat = np.asarray(v[3:]) / (np.linalg.norm(v[3:]) or 1.0)
        elif t == mujoco.mjtJoint.mjJNT_BALL:  # its rotation about the joint's centre, as for a hinge
            v = [float(x) for x in pose.qpos_key[adr:adr + 4]]
            r = np.asarray(v) / (np.linalg.norm(v) or 1.0)
            c = m0.jnt_pos[j].copy()
            body.pos = p0 + _rotate(q0, c - _rotate(r, c))
            body.quat = _quat_mul(q0, r)
        elif t == mujoco.mjtJoint.mjJNT_HINGE:
            v = af.locked.get(name, float(pose.qpos_key[adr]))
            delta = v - float(m0.qpos0[adr])  # the body's frame in the model is the one at qpos0 (= ref)
            c = m0.jnt_pos[j].copy()
            r = _axis_quat(axis, delta)
            body.pos = p0 + _rotate(q0, c - _rotate(r, c))
            body.quat = _quat_mul(q0, r)
        else:
            v = af.locked.get(name, float(pose.qpos_key[adr]))
            body.pos = p0 + _rotate(q0, axis * (v - float(m0.qpos0[adr])))
            body.quat = q0
        body.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
        frames[b] = (np.array(body.pos, dtype=float), np.array(body.quat, dtype=float))
        spec.delete(spec_joint)
        locked.append({"name": name, "value": v})
    if locked:
        warnings.append("locked (not controlled): " + ", ".join(f"{x['name']} at {_value(x['value'])}" for x in locked))
    return locked


def _degrees_hint(degrees: bool) -> str:
    return (" (the file gives angles in degrees, MuJoCo's default without <compiler angle=\"radian\"/>: "
            "were its ranges meant as radians?)") if degrees else ""


def _value(v: float | list[float]) -> str:
    return f"{v:g}" if isinstance(v, float) else "(" + " ".join(f"{x:g}" for x in v) + ")"


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
