"""Stages 5 and 8, the prepared model: first nothing but the controlled chain's dynamics (every
body's mass and inertia explicit, the model's own actuators, sensors, tendons, equalities,
keyframes and, unless the arm file keeps contacts, geometry removed, the timestep the loop period);
then, with the torque limits, one motor per joint and the keyframe "home", written to XML and read
back, with the checks only the written model can answer."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from gen.arm.arm_file import ArmFile
from gen.arm.assets import ASSET_KINDS, remove_assets
from gen.arm.chain import Chain
from gen.arm.compile import compile_spec
from gen.arm.errors import ArmError, float32
from gen.lib import mjcf_defaults
from gen.lib.one_line import joined_lines

MIN_JOINT_INERTIA = 1e-7   # kg m^2: a joint that moves less than this cannot be controlled
LIGHT_LINK_KG = 1e-6       # a link lighter than this (its children may still be heavy): a warning
WRITTEN_TOLERANCE = 1e-4   # relative change of the inverse dynamics that writing to XML may cost
OWN_KINDS = ("actuator", "site")  # the kinds of element the importer adds to arm.xml


@dataclass
class Dynamics:
    model: mujoco.MjModel  # the chain's dynamics alone, no actuators yet
    timestep: float
    substeps: int


@dataclass
class Written:
    xml: str
    model: mujoco.MjModel
    inertia_at_home: np.ndarray  # M_jj at the home pose, kg m^2
    written_error: float


def dynamics_only(spec: mujoco.MjSpec, m0: mujoco.MjModel, af: ArmFile, path: Path, rate: float,
                  classes: list[mujoco.MjsDefault], warnings: list[str]) -> Dynamics:
    for b in range(1, m0.nbody):
        body = spec.body(mujoco.mj_id2name(m0, mujoco.mjtObj.mjOBJ_BODY, b))
        body.explicitinertial = True
        body.mass = float(m0.body_mass[b])
        body.ipos = m0.body_ipos[b].copy()
        body.iquat = m0.body_iquat[b].copy()
        body.inertia = m0.body_inertia[b].copy()
        body.fullinertia = [math.nan, 0, 0, 0, 0, 0]  # unset: inertia + iquat are the ones
    _drop_gravity_compensation(spec, m0, warnings)
    for elist in (spec.actuators, spec.sensors, spec.tendons, spec.equalities, spec.keys, spec.excludes, spec.pairs):
        for e in list(elist):
            spec.delete(e)
    # the motors and the payload site the importer adds take nothing from the model's classes (a
    # class that makes every `general` a position servo); the model's own sites keep their values
    mjcf_defaults.reset_to_builtin(classes, OWN_KINDS)
    if not af.contacts:
        for g in list(spec.geoms):
            spec.delete(g)
        remove_assets(spec, set(ASSET_KINDS), classes)  # nothing left draws them
        spec.option.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    else:
        spec.meshdir = str((path.parent / (spec.meshdir or "")).resolve())
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    period = 1.0 / rate
    model_dt = float(m0.opt.timestep)
    if af.timestep == "model":
        k = period / model_dt
        if abs(k - round(k)) > 1e-9 * k or round(k) < 1:
            raise ArmError(f"model {path}: timestep {model_dt:g} s does not divide the loop period {period:g} s "
                           "(arm file timestep = \"model\"): make it period / k for an integer k, or use "
                           "timestep = \"loop\"")
        substeps, dt = int(round(k)), model_dt
    else:
        substeps, dt = 1, period
        if abs(model_dt - period) > 1e-12:
            warnings.append(f"timestep: the model's {model_dt:g} s replaced by the loop period {period:g} s "
                            "(arm file timestep = \"model\" keeps it when it divides the period)")
    spec.option.timestep = dt
    spec.compiler.fusestatic = True
    return Dynamics(compile_spec(spec, path, "preparing it"), dt, substeps)


def _drop_gravity_compensation(spec: mujoco.MjSpec, m0: mujoco.MjModel, warnings: list[str]) -> None:
    """MuJoCo's body gravcomp is a force from nowhere that holds a body up (a simulation's stand-in
    for a robot's own gravity compensation). On a real arm the drives carry gravity, and this
    controller's model compensates it itself: with gravcomp the simulated arm would float and the
    assumed torque limits would leave gravity out."""
    held = [mujoco.mj_id2name(m0, mujoco.mjtObj.mjOBJ_BODY, b) for b in range(1, m0.nbody) if m0.body_gravcomp[b]]
    for name in held:
        spec.body(name).gravcomp = 0.0
    if held:
        warnings.append(f"gravcomp (MuJoCo's gravity compensation, a force no drive gives) removed from "
                        f"{len(held)} bodies ({', '.join(held[:3])}{' ...' if len(held) > 3 else ''}): the drives "
                        "carry the arm's weight, as on the real arm, and the controller's model compensates it")


def write(spec: mujoco.MjSpec, dyn: Dynamics, chain: Chain, home: list[float], limits: list[tuple[float, str]],
          armname: str, path: Path, warnings: list[str]) -> Written:
    for name, (lim, _) in zip(chain.names, limits):
        spec.add_actuator(name=name, target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT,
                          ctrllimited=mujoco.mjtLimited.mjLIMITED_TRUE, ctrlrange=[-lim, lim], gear=[1, 0, 0, 0, 0, 0])
    spec.modelname = armname
    m1 = compile_spec(spec, path, "preparing it")
    _check_float32(m1, path, chain.names, limits, home)
    n = chain.n
    spec.add_key(name="home", qpos=home, ctrl=[0.0] * n)
    xml = spec.to_xml()
    try:
        m = mujoco.MjModel.from_xml_string(xml)
    except Exception as exc:  # noqa: BLE001
        raise ArmError(f"model {path}: the prepared model does not load back: {joined_lines(str(exc))}") from exc
    if m.nq != n or m.nv != n or m.nu != n or m1.nbody != m.nbody:
        raise ArmError(f"model {path}: the prepared model has nq={m.nq}, nv={m.nv}, nu={m.nu} for {n} joints")
    written_error = inverse_dynamics_difference(m1, m)
    if written_error > WRITTEN_TOLERANCE:
        raise ArmError(f"model {path}: written to arm.xml (MuJoCo writes 6 significant digits) its inverse dynamics "
                       f"change by {written_error:.2g} relative: more than {WRITTEN_TOLERANCE:g}")
    inertia = _check_inertia(m, chain.names, home, path, warnings)
    return Written(xml, m, inertia, written_error)


def _check_inertia(m: mujoco.MjModel, names: list[str], home: list[float], path: Path,
                   warnings: list[str]) -> np.ndarray:
    """M_jj at home: a joint that moves (almost) nothing is refused, a light link noted."""
    n = len(names)
    d = mujoco.MjData(m)
    d.qpos[:] = home
    mujoco.mj_forward(m, d)
    mass = np.zeros((n, n))
    mujoco.mj_fullM(m, d, mass)
    for i, name in enumerate(names):
        b = int(m.jnt_bodyid[i])
        if mass[i, i] < MIN_JOINT_INERTIA:
            raise ArmError(f"model {path}: joint '{name}' moves almost no inertia (M[{i},{i}] = {mass[i, i]:.3g} kg m^2 "
                           f"at the home pose, below {MIN_JOINT_INERTIA:g}): any torque gives an unbounded "
                           "acceleration; give the links beyond it their real mass and inertia")
        if m.body_mass[b] < LIGHT_LINK_KG:
            warnings.append(f"link of joint '{name}' weighs {m.body_mass[b]:.3g} kg ({_inertia_carrier(m, i)})")
    return np.diag(mass).copy()


def _check_float32(m: mujoco.MjModel, path: Path, names: list[str], limits: list[tuple[float, str]],
                   home: list[float]) -> None:
    """Every number the firmware's model takes (gen/robot_model.py) fits in float32."""
    for b in range(1, m.nbody):
        body = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"
        for field_, vals in (("pos", m.body_pos[b]), ("quat", m.body_quat[b]), ("mass", [m.body_mass[b]]),
                             ("inertia", m.body_inertia[b]), ("ipos", m.body_ipos[b]), ("iquat", m.body_iquat[b])):
            for v in vals:
                float32(float(v), f"model {path}: body '{body}': {field_}")
    for i, name in enumerate(names):
        where = f"model {path}: joint '{name}'"
        for field_, vals in (("pos", m.jnt_pos[i]), ("axis", m.jnt_axis[i]), ("armature", [m.dof_armature[i]]),
                             ("damping", [m.dof_damping[i]]), ("frictionloss", [m.dof_frictionloss[i]]),
                             ("range", m.jnt_range[i] if m.jnt_limited[i] else []), ("home", [home[i]])):
            for v in vals:
                float32(float(v), f"{where}: {field_}")
        float32(limits[i][0], f"{where}: torque limit (from {limits[i][1]})")


def _inertia_carrier(m: mujoco.MjModel, i: int) -> str:
    """What gives joint i of a link without mass the inertia it moves (it passed MIN_JOINT_INERTIA):
    the links beyond it, its rotor armature, or both."""
    b = int(m.jnt_bodyid[i])
    beyond = float(m.body_subtreemass[b] - m.body_mass[b])
    armature = float(m.dof_armature[i])
    parts = []
    if beyond >= LIGHT_LINK_KG:
        parts.append(f"{beyond:.3g} kg of links beyond it")
    if armature > 0:
        parts.append(f"its rotor armature of {armature:.3g} kg m^2")
    if not parts:
        return "its own rotational inertia is all it moves: no link beyond it, no armature"
    return " and ".join(parts) + (" carry" if len(parts) > 1 else " carries") + " the inertia" + \
        ("" if beyond >= LIGHT_LINK_KG else "; no link beyond it")


def inverse_forces(models: tuple[mujoco.MjModel, ...], q: np.ndarray, qd: np.ndarray,
                   qdd: np.ndarray) -> list[np.ndarray]:
    """mj_inverse of each model at the one state (q, qd, qdd): the generalised forces each needs."""
    out = []
    for m in models:
        d = mujoco.MjData(m)
        d.qpos[:], d.qvel[:], d.qacc[:] = q, qd, qdd
        mujoco.mj_inverse(m, d)
        out.append(d.qfrc_inverse.copy())
    return out


def inverse_dynamics_difference(a: mujoco.MjModel, b: mujoco.MjModel, samples: int = 20) -> float:
    """The largest relative difference of two models' rigid-body inverse dynamics (constraints
    and springs off) over random states: what writing the model to XML cost."""
    rng = np.random.default_rng(0)
    worst = 0.0
    off = int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT) | int(mujoco.mjtDisableBit.mjDSBL_SPRING)
    for m in (a, b):
        m.opt.disableflags |= off
    try:
        for _ in range(samples):
            q, qd, qdd = rng.uniform(-3, 3, a.nv), rng.uniform(-2, 2, a.nv), rng.uniform(-5, 5, a.nv)
            out = inverse_forces((a, b), q, qd, qdd)
            scale = np.max(np.abs(out[0])) + 1e-9
            worst = max(worst, float(np.max(np.abs(out[0] - out[1])) / scale))
    finally:
        for m in (a, b):
            m.opt.disableflags &= ~off
    return worst


def info_joints(m: mujoco.MjModel, names: list[str], limits: list[tuple[float, str]], ranges: list[Any],
                home: list[float], sized: list[float | None]) -> list[dict[str, Any]]:
    """arm.json's joints: limits, ranges, home, the armature, damping and friction the model gives,
    and where the importer sized a joint's motor below its limit (limits.size_drives), its rated
    torque at the joint (gen/drives.py: "joint_torque_limit / gear" takes it)."""
    return [{"name": jname, "torque_limit": limits[i][0], "torque_limit_from": limits[i][1], "range": ranges[i],
             "home": home[i], "armature": float(m.dof_armature[i]), "damping": float(m.dof_damping[i]),
             "frictionloss": float(m.dof_frictionloss[i]),
             **({} if sized[i] is None else {"motor_rated_torque_at_joint_nm": sized[i]})}
            for i, jname in enumerate(names)]
