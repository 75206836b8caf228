"""The importer holds for feature classes, not for examples: hypothesis builds MJCF and URDF arms
from the features real files use (tests/python/arm_features.py) and each either prepares a model
that loads back with the arm where the original put it, or, when it was given a physical defect,
is refused in one line naming the element. A refusal of anything else is the importer's limit,
and fails here."""

from __future__ import annotations

import tempfile
from pathlib import Path

import mujoco
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings

from arm_features import MjcfArm, UrdfArm, mjcf_arms, urdf_arms, write_mjcf, write_urdf
from gen.arm import ArmError, ArmFile, prepare
from gen.arm.assets import default_classes, strip_meshes
from gen.arm.compile import missing_asset_files
from gen.lib.paths import REPO

DESIGN = REPO / "gen" / "configs" / "paper.toml"
FEATURES = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _outcome(model: Path, defect: str | None, refusal: str, joints: list[str]) -> dict | None:
    """prepare()'s result checked against what the model was made to be."""
    try:
        p = prepare(ArmFile(None, None, model), DESIGN)
    except ArmError as exc:
        text = str(exc)
        assert "\n" not in text and str(model) in text, text
        assert defect is not None, f"a model with every feature right was refused: {text}"
        assert refusal in text, (defect, text)
        return None
    assert defect is None, f"the {defect} model was imported: {p.info['warnings']}"
    m = mujoco.MjModel.from_xml_string(p.xml)
    assert m.nq == m.nv == m.nu == len(joints)
    assert [j["name"] for j in p.info["joints"]] == joints
    assert all(j["torque_limit"] > 0 for j in p.info["joints"])
    return p.info | {"xml": p.xml}


def _same_arm_at_home(original: mujoco.MjModel, prepared_xml: str, joints: list[str], home: list[float]) -> None:
    """Every controlled link sits where the original model puts it at the home pose, with the
    joints that are not controlled (fingers, a scene's objects) where the model's keyframe holds them."""
    m = mujoco.MjModel.from_xml_string(prepared_xml)
    d = mujoco.MjData(m)
    d.qpos[:] = home
    mujoco.mj_kinematics(m, d)
    d0 = mujoco.MjData(original)
    key = mujoco.mj_name2id(original, mujoco.mjtObj.mjOBJ_KEY, "home")
    d0.qpos[:] = original.key_qpos[key] if key >= 0 else original.qpos0
    for name, q in zip(joints, home):
        d0.qpos[original.jnt_qposadr[mujoco.mj_name2id(original, mujoco.mjtObj.mjOBJ_JOINT, name)]] = q
    mujoco.mj_kinematics(original, d0)
    for name in joints:
        b = int(m.jnt_bodyid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)])
        b0 = int(original.jnt_bodyid[mujoco.mj_name2id(original, mujoco.mjtObj.mjOBJ_JOINT, name)])
        assert np.allclose(d.xpos[b], d0.xpos[b0], atol=1e-5), name
        assert np.allclose(d.xmat[b], d0.xmat[b0], atol=1e-5), name


def _original(model: Path) -> mujoco.MjModel:
    spec = mujoco.MjSpec.from_file(str(model))
    try:
        return spec.compile()
    except ValueError:  # a vendor's mesh that is not shipped: compared without it, as imported
        spec = mujoco.MjSpec.from_file(str(model))
        strip_meshes(spec, default_classes(spec, model), set(missing_asset_files(spec, model)))
        return spec.compile()


@FEATURES
@given(arm=mjcf_arms())
def test_an_mjcf_arm_made_of_real_files_features_imports_or_is_refused_by_name(arm: MjcfArm) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        model = write_mjcf(arm, Path(tmp))
        # MuJoCo compiles it (but for a massless link): the importer must take it or name the defect
        original = _original(model) if arm.defect != "massless" else None
        info = _outcome(model, arm.defect, arm.refusal, arm.arm_joints)
        if info is None:
            return
        home = [j["home"] for j in info["joints"]]
        if arm.keyframe:
            assert home == pytest.approx(arm.home)
        _same_arm_at_home(original, info["xml"], arm.arm_joints, home)
        if arm.actuators == "none":
            assert any(w.startswith("torque limits assumed") for w in info["warnings"])


@FEATURES
@given(arm=urdf_arms())
def test_a_urdf_arm_made_of_real_files_features_imports_or_is_refused_by_name(arm: UrdfArm) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        model = write_urdf(arm, Path(tmp))
        original = _original(model) if arm.defect is None else None
        joints = [f"joint{i}" for i in range(len(arm.joints))]
        info = _outcome(model, arm.defect, arm.refusal, joints)
        if info is None:
            return
        assert [x["name"] for x in info["locked"]] == (["finger_joint0", "finger_joint1"] if arm.gripper == "mimic"
                                                       else [])
        sources = {j["torque_limit_from"] for j in info["joints"]}
        assert sources == ({"joint actuatorfrcrange"} if arm.efforts else {"assumed: no limit in the model"})
        _same_arm_at_home(original, info["xml"], joints, [j["home"] for j in info["joints"]])
