"""Extract the nominal rigid-body model of the arm from its prepared MJCF (gen/arm) and emit it
as C headers.

The firmware's recursive Newton-Euler needs, per joint: the fixed transform from the parent link,
the joint axis, the link's mass, centre of mass and inertia, and the joint's armature and damping.
MuJoCo compiles the MJCF into exactly these (body_pos, body_quat, jnt_pos, jnt_axis, body_ipos,
body_iquat, body_inertia, dof_armature, dof_damping), so we read them from the compiled model
rather than parsing XML ourselves.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from gen.lib.escape import EscapeError, c_comment, c_string
from gen.lib.model_hash import fnv1a64
from gen.lib.one_line import one_line
from gen.lib.atomic_output import exit_on_output_error, write_files_atomically

REPO = Path(__file__).resolve().parent.parent
DEFAULT_MJCF = REPO / "host_sim" / "models" / "ur5e_arm.xml"
UNLIMITED = 1e30  # firmware ARM_UNLIMITED: a joint without a range


class ModelError(ValueError):
    """The MJCF is not a serial chain of torque-driven hinge joints the firmware can use."""


@dataclass(frozen=True)
class Link:
    name: str
    pos: np.ndarray  # parent link frame -> this link frame's origin (the joint's point), parent frame (3,)
    rot: np.ndarray  # parent -> link rotation at q = 0 (3, 3)
    axis: np.ndarray  # joint axis, link frame (3,)
    mass: float
    com: np.ndarray  # centre of mass, link frame (3,)
    inertia: np.ndarray  # about the COM, link frame (3, 3)
    torque_limit: float
    armature: float  # rotor inertia reflected to the joint, kg m^2 (adds armature * qdd)
    damping: float  # viscous joint damping, N m s/rad (adds damping * qd)
    q_min: float = -1e30  # the joint's range, rad (+-UNLIMITED: none)
    q_max: float = 1e30


@dataclass(frozen=True)
class RobotModel:
    links: list[Link]
    gravity: np.ndarray
    home: np.ndarray | None = None  # the keyframe "home" gen/arm writes (else qpos0), rad


def _quat_to_mat(q: np.ndarray) -> np.ndarray:
    out = np.zeros(9)
    mujoco.mju_quat2Mat(out, q)
    return out.reshape(3, 3)


def nominal_for_inverse(m: mujoco.MjModel) -> mujoco.MjModel:
    """The firmware's nominal model as MuJoCo sees it: rigid bodies, armature and joint damping; no
    constraints (joint limits, frictionloss, contacts) and no springs, which the firmware leaves to
    the estimator (gen/arm says which). mj_inverse on it is the RNEA's oracle."""
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT) | int(mujoco.mjtDisableBit.mjDSBL_SPRING)
    return m


def extract(mjcf: Path, mass_scale: float = 1.0, inertia_scale: float = 1.0) -> RobotModel:
    """The serial chain of a prepared arm model (gen/arm: one hinge per body, fused, one motor per
    joint); the scales give a nominal model deliberately off from the truth. Each link frame sits
    at its joint's point with its body's orientation."""
    if mass_scale <= 0 or inertia_scale <= 0:
        raise ModelError(f"mass_scale and inertia_scale must be > 0, got {mass_scale}, {inertia_scale}")
    m = mujoco.MjModel.from_xml_path(str(mjcf))
    if m.nv != m.njnt or m.nq != m.njnt or m.nu != m.njnt:
        raise ModelError(f"{mjcf}: expected a prepared arm (gen/arm): only hinge joints, one motor each "
                         f"(nq == nv == nu == njnt), got nq={m.nq} nv={m.nv} nu={m.nu} njnt={m.njnt}")
    links: list[Link] = []
    for j in range(m.njnt):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint{j}"
        if m.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE:
            raise ModelError(f"{mjcf}: joint '{name}' is not a hinge")
        b = int(m.jnt_bodyid[j])
        parent = int(m.body_parentid[b])
        expected_parent = 0 if j == 0 else int(m.jnt_bodyid[j - 1])
        if parent != expected_parent or m.body_jntnum[b] != 1:
            raise ModelError(f"{mjcf}: joint '{name}' breaks the serial chain (one hinge per body, in order): "
                             "prepare the model with gen/arm")
        a = int(np.flatnonzero((m.actuator_trntype == mujoco.mjtTrn.mjTRN_JOINT) & (m.actuator_trnid[:, 0] == j))[0]) \
            if m.nu else -1
        limit = float(m.actuator_ctrlrange[a][1]) if a >= 0 and m.actuator_ctrllimited[a] else 0.0
        if limit <= 0:
            raise ModelError(f"{mjcf}: joint '{name}' has no motor with a ctrlrange (the torque limit)")
        rot = _quat_to_mat(m.body_quat[b])
        c = m.jnt_pos[j]
        c_parent = m.jnt_pos[j - 1] if j > 0 else np.zeros(3)
        r_i = _quat_to_mat(m.body_iquat[b])
        links.append(
            Link(
                name=name,
                pos=m.body_pos[b] + rot @ c - c_parent,
                rot=rot,
                axis=m.jnt_axis[j].copy(),
                mass=float(m.body_mass[b]) * mass_scale,
                com=m.body_ipos[b] - c,
                inertia=r_i @ np.diag(m.body_inertia[b]) @ r_i.T * inertia_scale,
                torque_limit=limit,
                armature=float(m.dof_armature[j]),
                damping=float(m.dof_damping[j]),
                q_min=float(m.jnt_range[j, 0]) if m.jnt_limited[j] else -UNLIMITED,
                q_max=float(m.jnt_range[j, 1]) if m.jnt_limited[j] else UNLIMITED,
            )
        )
    k = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "home")
    home = m.key_qpos[k].copy() if k >= 0 else m.qpos0.copy()
    return RobotModel(links=links, gravity=m.opt.gravity.copy(), home=home)


def _c(v: float) -> str:
    s = f"{float(v):.9g}"
    if not any(ch in s for ch in ".en"):
        s += ".0"  # "150f" is not a C literal
    return s + "f"


def _vec(v: np.ndarray) -> str:
    return "{" + ", ".join(_c(x) for x in np.ravel(v)) + "}"


def _mat(a: np.ndarray) -> str:
    return "{" + ", ".join(_vec(r) for r in a) + "}"


def dims_header(model: RobotModel) -> str:
    return (
        "/* Generated by gen/robot_model.py from the arm's MJCF. Do not edit. */\n"
        "#ifndef ARM_ROBOT_DIMS_H\n#define ARM_ROBOT_DIMS_H\n\n"
        f"#define ARM_N_JOINTS {len(model.links)}\n\n#endif\n"
    )


def model_header(model: RobotModel, source: str, model_hash: int = 0) -> str:
    body = []
    for ln in model.links:
        body.append(
            f"        {{ /* {c_comment(ln.name)} */\n"
            f"            .pos = {_vec(ln.pos)},\n"
            f"            .rot = {_mat(ln.rot)},\n"
            f"            .axis = {_vec(ln.axis)},\n"
            f"            .mass = {_c(ln.mass)},\n"
            f"            .com = {_vec(ln.com)},\n"
            f"            .inertia = {_mat(ln.inertia)},\n"
            f"            .torque_limit = {_c(ln.torque_limit)},\n"
            f"            .armature = {_c(ln.armature)},\n"
            f"            .damping = {_c(ln.damping)},\n"
            f"            .q_min = {_c(ln.q_min)},\n"
            f"            .q_max = {_c(ln.q_max)},\n"
            "        },"
        )
    text = "\n".join(body)
    digest = hashlib.sha256(text.encode()).hexdigest()[:16]
    names = ", ".join(c_string(ln.name, f"joint {i + 1}'s name") for i, ln in enumerate(model.links))
    home = model.home if model.home is not None else np.zeros(len(model.links))
    return (
        f"/* Generated by gen/robot_model.py from {c_comment(source)}. Do not edit.\n"
        " * Nominal model: per link, the parent->link transform (pos, rot), the joint axis, mass,\n"
        " * centre of mass and inertia about it, all in the link frame, the joint's armature and\n"
        " * damping; SI units. */\n"
        "#ifndef ARM_ROBOT_MODEL_H\n#define ARM_ROBOT_MODEL_H\n\n"
        '#include "arm/robot_model.h"\n\n'
        f"#define ARM_ROBOT_MODEL_HASH {c_string(digest, 'the model hash')}\n"
        "/* FNV-1a 64 of the prepared model file: the simulator announces the same at boot\n"
        " * (SIM_IDENTITY), and a controller built for another arm refuses to start. */\n"
        f"#define ARM_MODEL_HASH64 0x{model_hash:016x}ull\n\n"
        f"static const char *const ARM_JOINT_NAMES[ARM_N_JOINTS] = {{{names}}};\n"
        "/* The arm's home pose (its model's keyframe \"home\", gen/arm), rad: where tests and the\n"
        " * MCU's closed-loop check start. Not part of ARM_ROBOT_MODEL_HASH (the dynamics). */\n"
        f"static const float ARM_HOME_Q[ARM_N_JOINTS] = {_vec(home)};\n\n"
        "static const arm_robot_model_t ARM_ROBOT_MODEL = {\n"
        f"    .gravity = {_vec(model.gravity)},\n"
        "    .link = {\n"
        f"{text}\n"
        "    },\n"
        "    .model_hash = ARM_MODEL_HASH64,\n"
        "};\n\n#endif\n"
    )


def rnea_golden_header(mjcf: Path, count: int, seed: int) -> str:
    """Random states and MuJoCo's own inverse dynamics for them: the firmware RNEA's test oracle."""
    m = nominal_for_inverse(mujoco.MjModel.from_xml_path(str(mjcf)))
    d = mujoco.MjData(m)
    rng = np.random.default_rng(seed)
    rows: list[tuple[np.ndarray, ...]] = []
    for _ in range(count):
        d.qpos[:] = rng.uniform(-np.pi, np.pi, m.nq)
        d.qvel[:] = rng.uniform(-2.0, 2.0, m.nv)
        d.qacc[:] = rng.uniform(-5.0, 5.0, m.nv)
        mujoco.mj_inverse(m, d)
        rows.append((d.qpos.copy(), d.qvel.copy(), d.qacc.copy(), d.qfrc_inverse.copy()))

    def arr(name: str, k: int) -> str:
        lines = ",\n".join("    {" + ", ".join(f"{x:.17g}" for x in r[k]) + "}" for r in rows)
        return f"static const double {name}[RNEA_GOLDEN_COUNT][ARM_N_JOINTS] = {{\n{lines}\n}};\n"

    return (
        f"/* Generated by gen/robot_model.py: {count} random states (seed {seed}) and MuJoCo's\n"
        " * mj_inverse torques for them (double precision). Do not edit. */\n"
        "#ifndef ARM_RNEA_GOLDEN_H\n#define ARM_RNEA_GOLDEN_H\n\n"
        f"#define RNEA_GOLDEN_COUNT {count}\n\n"
        + arr("RNEA_GOLDEN_Q", 0)
        + arr("RNEA_GOLDEN_QD", 1)
        + arr("RNEA_GOLDEN_QDD", 2)
        + arr("RNEA_GOLDEN_TAU", 3)
        + "\n#endif\n"
    )


@exit_on_output_error("gen.robot_model")
def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="gen.robot_model", description=__doc__)
    p.add_argument("--mjcf", type=Path, default=DEFAULT_MJCF)
    p.add_argument("--out", type=Path, required=True, help="directory for the generated headers")
    p.add_argument("--mass-scale", type=float, default=1.0, help="nominal masses = true x this")
    p.add_argument("--inertia-scale", type=float, default=1.0, help="nominal inertias = true x this")
    p.add_argument("--golden", type=int, default=0, help="also write N RNEA golden vectors")
    p.add_argument("--seed", type=int, default=1)
    ns = p.parse_args(argv)
    try:
        model = extract(ns.mjcf, ns.mass_scale, ns.inertia_scale)
        files = {
            "arm_robot_dims.h": dims_header(model),
            "arm_robot_model_data.h": model_header(model, ns.mjcf.name, fnv1a64(ns.mjcf.read_bytes())),
        }
    except (ModelError, EscapeError, ValueError) as exc:
        print(f"robot model error: {one_line(str(exc))}", file=sys.stderr)
        return 2
    if ns.golden > 0:
        files["rnea_golden.h"] = rnea_golden_header(ns.mjcf, ns.golden, ns.seed)
    write_files_atomically(ns.out, files)
    return 0


if __name__ == "__main__":
    sys.exit(main())
