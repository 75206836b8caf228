"""Nothing of a model's default classes reaches what the importer writes, and everything they give the
arm's own elements is kept as MuJoCo applies it: hypothesis draws MJCF arms whose joints, geoms,
sites, tendons, actuators, cameras, lights, materials, meshes and equalities take random mixes of
attributes from nested classes and childclasses (tests/python/arm_defaults.py). For each:

- the prepared rigid arm (arm.xml) needs the same generalised forces as the source model with its
  actuators and tendons taken out (what the importer replaces and drops), at random states of the
  controlled joints (mj_inverse, constraints off), and its joints keep the source's limits,
  friction, armature, damping and springs;
- every actuator of arm.xml and plant.xml is the importer's motor: torque = ctrl on its joint, no
  bias, no gain or gear but 1, no dynamics, no armature or damping of its own;
- the plant's rotors and gears are what arm.json says: with each rotor moving with its link, the
  plant needs the rigid arm's forces, and no rotor or gear has a range, friction or spring that
  arm.json does not give it."""

from __future__ import annotations

import tempfile
from pathlib import Path

import mujoco
import numpy as np
from hypothesis import HealthCheck, example, given, settings

from arm_defaults import ATTRIBUTES, DefaultsArm, Klass, Link, defaults_arms, write_arm
from gen.arm import ArmFile, prepare
from gen.drivetrain import GEAR_PREFIX, ROTOR_PREFIX

OFF = int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
STATES = 8
# what writing the prepared model to XML may change (gen/arm/write.py WRITTEN_TOLERANCE)
RTOL = 1e-4


def _servo_main_class() -> DefaultsArm:
    """Issue 50's arm: the top-level class makes every `general` a stiff position servo (gain 2000),
    the model's own actuators are <position> elements."""
    servo = [i for i, a in enumerate(ATTRIBUTES) if a[1] == "general" and a[2] in ("biastype", "gainprm", "biasprm")]
    site_material = [i for i, a in enumerate(ATTRIBUTES) if a[1] == "site" and a[2] == "material"]
    links = [Link("0 0 1" if i == 0 else "0 1 0", "inertial", None, None, None, None, False, False) for i in range(3)]
    return DefaultsArm([Klass("main", None, servo + site_material)], links, "radian", "position", None, False, None,
                       False, None, True, [0.1, 0.2, 0.3])


def _without_actuators_and_tendons(model: Path) -> mujoco.MjModel:
    spec = mujoco.MjSpec.from_file(str(model))
    for e in list(spec.actuators) + list(spec.tendons):
        spec.delete(e)
    return spec.compile()


def _ids(m: mujoco.MjModel, names: list[str]) -> list[int]:
    return [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) for n in names]


def _inverse(m: mujoco.MjModel, qpos: np.ndarray, qvel: np.ndarray, qacc: np.ndarray) -> np.ndarray:
    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:], d.qacc[:] = qpos, qvel, qacc
    m.opt.disableflags |= OFF
    try:
        mujoco.mj_inverse(m, d)
    finally:
        m.opt.disableflags &= ~OFF
    return d.qfrc_inverse.copy()


def _close(a: np.ndarray, b: np.ndarray) -> bool:
    return bool(np.all(np.abs(a - b) <= RTOL * max(float(np.max(np.abs(a))), 1e-6)))


def _same_dynamics(source: mujoco.MjModel, arm: mujoco.MjModel, joints: list[str], home: list[float]) -> None:
    """mj_inverse of the prepared arm and of the source (its other joints where the importer locked
    them: the keyframe 'home', else qpos0) at random states of the controlled joints."""
    rng = np.random.default_rng(0)
    src = _ids(source, joints)
    key = mujoco.mj_name2id(source, mujoco.mjtObj.mjOBJ_KEY, "home")
    base = (source.key_qpos[key] if key >= 0 else source.qpos0).copy()
    qa, da = np.array([int(source.jnt_qposadr[j]) for j in src]), np.array([int(source.jnt_dofadr[j]) for j in src])
    n = len(joints)
    for _ in range(STATES):
        q = np.asarray(home) + rng.uniform(-0.5, 0.5, n)
        qd, qdd = rng.uniform(-2, 2, n), rng.uniform(-5, 5, n)
        qpos, qvel, qacc = base.copy(), np.zeros(source.nv), np.zeros(source.nv)
        qpos[qa], qvel[da], qacc[da] = q, qd, qdd
        want = _inverse(source, qpos, qvel, qacc)[da]
        got = _inverse(arm, q, qd, qdd)
        assert _close(want, got), (want, got)
    for field, at in (("jnt_limited", src), ("jnt_range", src), ("jnt_stiffness", src), ("jnt_margin", src),
                      ("jnt_actfrclimited", src), ("jnt_actfrcrange", src), ("dof_armature", da), ("dof_damping", da),
                      ("dof_frictionloss", da), ("qpos_spring", qa), ("qpos0", qa)):
        a, b = getattr(source, field)[at], getattr(arm, field)[:n]
        assert np.allclose(a, b, rtol=1e-5, atol=1e-9), (field, a, b)


def _only_the_importers_motors(m: mujoco.MjModel, targets: list[str], limits: list[float]) -> None:
    """Each actuator a motor on its joint, torque = ctrl, nothing of its own."""
    assert m.nu == len(targets)
    dofs = []
    for a, (target, limit) in enumerate(zip(targets, limits)):
        j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, target)
        what = f"actuator {a} on {target}"
        assert m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT and m.actuator_trnid[a, 0] == j, what
        assert m.actuator_gaintype[a] == mujoco.mjtGain.mjGAIN_FIXED, what
        assert list(m.actuator_gainprm[a]) == [1.0] + [0.0] * (len(m.actuator_gainprm[a]) - 1), (what, m.actuator_gainprm[a])
        assert m.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_NONE and not np.any(m.actuator_biasprm[a]), (
            what, m.actuator_biastype[a], m.actuator_biasprm[a])
        assert m.actuator_dyntype[a] == mujoco.mjtDyn.mjDYN_NONE, what
        assert list(m.actuator_gear[a]) == [1.0, 0, 0, 0, 0, 0], (what, m.actuator_gear[a])
        assert m.actuator_ctrllimited[a] and list(m.actuator_ctrlrange[a]) == [-limit, limit], (what, m.actuator_ctrlrange[a])
        assert not m.actuator_forcelimited[a] and not m.actuator_actlimited[a], what
        assert m.actuator_armature[a] == 0 and not np.any(m.actuator_damping[a]), what
        dofs.append(int(m.jnt_dofadr[j]))
    rng = np.random.default_rng(1)
    d = mujoco.MjData(m)
    for _ in range(3):
        d.qpos[:] = rng.uniform(-1, 1, m.nq)
        d.qvel[:] = rng.uniform(-2, 2, m.nv)
        d.ctrl[:] = rng.uniform(-1, 1, m.nu) * np.asarray(limits)
        mujoco.mj_forward(m, d)
        assert np.allclose(d.qfrc_actuator[dofs], d.ctrl, rtol=1e-12, atol=1e-12), (d.qfrc_actuator, d.ctrl)


def _plant_is_the_drive_trains(plant: mujoco.MjModel, arm: mujoco.MjModel, info: dict) -> None:
    """Rotors moving with their links: the plant needs the rigid arm's forces (link + rotor); no
    rotor joint or gear tendon carries anything arm.json does not give it."""
    n = info["n_joints"]
    flexible = [j for j in info["drivetrain"] if j["flexible"]]
    rotor_ids = _ids(plant, [ROTOR_PREFIX + j["name"] for j in flexible])
    link_of = [[j["name"] for j in info["drivetrain"]].index(f["name"]) for f in flexible]
    for f, r in zip(flexible, rotor_ids):
        dof = int(plant.jnt_dofadr[r])
        assert not plant.jnt_limited[r] and plant.jnt_stiffness[r] == 0 and plant.qpos0[plant.jnt_qposadr[r]] == 0, f
        assert np.isclose(plant.dof_armature[dof], f["rotor_inertia"], rtol=1e-5), f
        t = mujoco.mj_name2id(plant, mujoco.mjtObj.mjOBJ_TENDON, GEAR_PREFIX + f["name"])
        assert np.isclose(plant.tendon_stiffness[t], f["stiffness"], rtol=1e-5), f
        assert np.isclose(plant.tendon_damping[t], f["damping"], rtol=1e-5), f
        assert not plant.tendon_limited[t] and plant.tendon_frictionloss[t] == 0 and plant.tendon_armature[t] == 0, f
        assert not plant.tendon_actfrclimited[t], f
    rng = np.random.default_rng(2)
    for _ in range(STATES):
        q, qd, qdd = rng.uniform(-1, 1, n), rng.uniform(-2, 2, n), rng.uniform(-5, 5, n)
        ext = lambda x: np.concatenate([x, x[link_of]])  # noqa: E731 - each rotor with its link
        p = _inverse(plant, ext(q), ext(qd), ext(qdd))
        total = p[:n].copy()
        total[link_of] += p[n:]
        assert _close(_inverse(arm, q, qd, qdd), total)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(arm=defaults_arms())
@example(arm=_servo_main_class())
def test_nothing_of_a_models_defaults_reaches_what_the_importer_writes(arm: DefaultsArm) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        model = write_arm(arm, Path(tmp))
        source = _without_actuators_and_tendons(model)
        p = prepare(ArmFile(None, None, model))
        joints = [j["name"] for j in p.info["joints"]]
        assert joints == arm.joints
        limits = [j["torque_limit"] for j in p.info["joints"]]
        m = mujoco.MjModel.from_xml_string(p.xml)
        plant = mujoco.MjModel.from_xml_string(p.plant_xml)
        _same_dynamics(source, m, joints, [j["home"] for j in p.info["joints"]])
        _only_the_importers_motors(m, joints, limits)
        rotors = {j["name"] for j in p.info["drivetrain"] if j["flexible"]}
        _only_the_importers_motors(plant, [ROTOR_PREFIX + j if j in rotors else j for j in joints], limits)
        _plant_is_the_drive_trains(plant, m, p.info)
